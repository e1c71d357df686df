//! GPU voxelisation (`shaders/voxel/voxelize.wgsl`), the same boundary as [`super::cpu`].
//!
//! The decision for each (triangle, cell) pair is the CPU's, operation for operation: the
//! vertices go to grid coordinates on the CPU (`GridSpec::to_cell`, so they are the same bits),
//! the candidate cells are the triangle's box grown by [`CELL_HALF`], a pair is rejected beyond
//! the circumscribed sphere, accepted inside the inscribed one and tested by separating axes
//! in between, and each cell keeps the smallest (squared distance, triangle index). Three
//! passes make that minimum with 32-bit atomics in any thread order (see the shader).
//!
//! Each surface cell also keeps its owning triangle (the one that won the minimum, for both
//! variants, as on the CPU), which the field refines its distances with.
//!
//! The result stays on the GPU as dense per-cell buffers ([`GpuBoundary`]) that the field
//! stage reads directly; [`GpuBoundary::to_cpu`] compacts it into the CPU's [`Boundary`].

use super::cpu::CELL_HALF;
use glam::Vec3;
use imprint_core::{Boundary, BoundaryVariant, Error, GridSpec, Mesh, Result};
use imprint_gpu::{Dispatch, GpuContext, GpuTimer, record_pass, shader, submit};
use std::sync::Arc;

/// Bytes per cell of the voxeliser's largest buffer (the vec4 points; the limit is per binding).
const BYTES_PER_CELL: u64 = 16;
/// Marks a cell with no owning face.
const NONE: u32 = u32::MAX;

/// A discrete boundary on the GPU, dense rather than compacted so that the field stage finds a
/// cell's point by its index, and the order of surface cells is the linear cell order by
/// construction.
#[derive(Clone, Debug)]
pub struct GpuBoundary {
    pub spec: GridSpec,
    pub variant: BoundaryVariant,
    /// Per cell `vec4<f32>`: xyz the boundary point in grid coordinates (cell centres at
    /// integers), w = 1 for surface cells and 0 elsewhere.
    pub points: wgpu::Buffer,
    /// Per cell `u32`: index into `faces` of the cell's owning triangle, `u32::MAX` elsewhere.
    pub owner: wgpu::Buffer,
    /// Per face three `vec4<f32>`: its vertices in grid coordinates (`GridSpec::to_cell`).
    pub faces: wgpu::Buffer,
    /// The same faces in world units, kept on the CPU for [`GpuBoundary::to_cpu`].
    pub faces_world: Arc<Vec<[Vec3; 3]>>,
    /// [`Boundary::inside`]: the bitset of cells inside a closed mesh (`u32` words).
    pub inside: Option<wgpu::Buffer>,
}

/// Grid-coordinate vertices of faces, three `vec4`s each, as the shaders read them.
fn faces_in_grid(spec: &GridSpec, faces: &[[Vec3; 3]]) -> Vec<[f32; 4]> {
    faces
        .iter()
        .flat_map(|f| f.map(|v| spec.to_cell(v).extend(0.0).to_array()))
        .collect()
}

impl GpuBoundary {
    /// Uploads a CPU boundary (for a GPU field built from a CPU voxelisation). Points and faces
    /// go to grid coordinates with `GridSpec::to_cell`, as the CPU field takes them.
    pub fn from_cpu(ctx: &GpuContext, boundary: &Boundary) -> Result<GpuBoundary> {
        let spec = boundary.spec;
        ctx.check_grid("GPU boundary", spec.dims.to_array(), BYTES_PER_CELL)?;
        let n = boundary.len();
        if boundary.points.len() != n || !(boundary.faces.is_empty() || boundary.faces.len() == n) {
            return Err(Error::Invalid(format!(
                "boundary has {n} cells, {} points and {} faces",
                boundary.points.len(),
                boundary.faces.len()
            )));
        }
        if boundary.faces.is_empty() && boundary.variant == BoundaryVariant::Closest {
            return Err(Error::Invalid(
                "a Closest boundary needs the owning face of each point".into(),
            ));
        }
        let mut dense = vec![[0f32; 4]; spec.len()];
        let mut owner = vec![NONE; spec.len()];
        for (k, (&c, &p)) in boundary
            .cells
            .iter()
            .zip(boundary.points.iter())
            .enumerate()
        {
            let slot = dense
                .get_mut(c as usize)
                .ok_or_else(|| Error::Invalid(format!("boundary cell {c} is outside its grid")))?;
            *slot = spec.to_cell(p).extend(1.0).to_array();
            if !boundary.faces.is_empty() {
                owner[c as usize] = k as u32;
            }
        }
        Ok(GpuBoundary {
            spec,
            variant: boundary.variant,
            points: ctx.storage_buffer("boundary points", &dense)?,
            owner: ctx.storage_buffer("boundary owners", &owner)?,
            faces: ctx.storage_buffer("boundary faces", &faces_in_grid(&spec, &boundary.faces))?,
            faces_world: boundary.faces.clone(),
            inside: match &boundary.inside {
                Some(words) => Some(ctx.storage_buffer("boundary inside", words)?),
                None => None,
            },
        })
    }

    /// Reads the boundary back and compacts it: surface cells in increasing linear index,
    /// world points computed as the CPU does (`origin + q * cell`), owning faces in world units.
    pub fn to_cpu(&self, ctx: &GpuContext) -> Result<Boundary> {
        let dense: Vec<[f32; 4]> = ctx.read_buffer(&self.points)?;
        let owner: Vec<u32> = ctx.read_buffer(&self.owner)?;
        let mut cells = Vec::new();
        let mut points = Vec::new();
        let mut faces = Vec::new();
        for (i, p) in dense.iter().take(self.spec.len()).enumerate() {
            if p[3] != 0.0 {
                cells.push(i as u32);
                points.push(self.spec.origin + Vec3::new(p[0], p[1], p[2]) * self.spec.cell);
                if let Some(f) = self.faces_world.get(owner[i] as usize) {
                    faces.push(*f);
                }
            }
        }
        if faces.len() != cells.len() {
            // Only an uploaded Centre boundary that came without faces has none.
            faces.clear();
        }
        let inside = match &self.inside {
            Some(b) => {
                let mut words: Vec<u32> = ctx.read_buffer(b)?;
                words.truncate(self.spec.len().div_ceil(32));
                Some(Arc::new(words))
            }
            None => None,
        };
        Ok(Boundary {
            spec: self.spec,
            variant: self.variant,
            cells,
            points: Arc::new(points),
            faces: Arc::new(faces),
            inside,
        })
    }
}

/// Mirrors `VoxelParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct VoxelParams {
    dims: [u32; 4],
    half: f32,
    /// Squared radius of the sphere circumscribing the touching box, as the CPU computes it.
    outer2: f32,
    mode: u32,
    variant: u32,
    n_cells: u32,
    /// Always 0: the shaders' guard against fused multiply-adds (`rnd` in common/geom.wgsl).
    zero: u32,
    _pad: [u32; 2],
}

/// The discrete boundary of `mesh` on `spec`, computed on the GPU and left there, with its
/// inside cells when the mesh is closed ([`Mesh::is_closed`], which visits every edge: a caller
/// voxelising the same mesh every frame keeps a [`super::solid::ClosedCache`] and calls
/// [`voxelize_gpu_timed`]). The work is submitted, not waited for: reading it back (or the
/// next stage's submit) orders it.
pub fn voxelize_gpu(
    ctx: &GpuContext,
    mesh: &Mesh,
    spec: &GridSpec,
    variant: BoundaryVariant,
) -> Result<GpuBoundary> {
    voxelize_gpu_timed(ctx, mesh, spec, variant, mesh.is_closed(), None)
}

/// [`voxelize_gpu`], marking the inside cells when `signed` (give it only for a closed mesh),
/// with its passes timed by `timer` (which then submits; call [`GpuTimer::wait`] for the
/// timings).
pub fn voxelize_gpu_timed(
    ctx: &GpuContext,
    mesh: &Mesh,
    spec: &GridSpec,
    variant: BoundaryVariant,
    signed: bool,
    mut timer: Option<&mut GpuTimer>,
) -> Result<GpuBoundary> {
    let dims = spec.dims;
    ctx.check_grid("GPU voxelisation", dims.to_array(), BYTES_PER_CELL)?;
    let n_cells = spec.len() as u32;
    let n_tris = u32::try_from(mesh.triangles.len()).map_err(|_| {
        Error::Invalid(format!(
            "{} triangles are more than the GPU path takes",
            mesh.triangles.len()
        ))
    })?;
    ctx.check_storage(
        "GPU voxelisation triangles",
        mesh.triangles.len() as u64 * 48,
    )?;

    // Grid coordinates on the CPU, with the CPU's own function: the same bits on both paths.
    let faces_world: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
        .map(|t| mesh.triangle(t))
        .collect();
    let tri_buf = ctx.storage_buffer("voxel triangles", &faces_in_grid(spec, &faces_world))?;
    let best_d2 = ctx.zeroed_buffer("voxel best d2", spec.len() as u64 * 4)?;
    let best_tri = ctx.zeroed_buffer("voxel best triangle", spec.len() as u64 * 4)?;
    let points = ctx.zeroed_buffer("voxel points", spec.len() as u64 * 16)?;

    let sources = [
        shader!("common/dispatch.wgsl"),
        shader!("common/geom.wgsl"),
        shader!("voxel/voxelize.wgsl"),
    ];
    let touch = ctx.pipeline("voxelize", &sources, "touch")?;
    let finish = ctx.pipeline("voxelize", &sources, "finish")?;
    let params = |mode: u32| VoxelParams {
        dims: [dims.x, dims.y, dims.z, n_tris],
        half: CELL_HALF,
        outer2: 3.0 * CELL_HALF * CELL_HALF,
        mode,
        variant: match variant {
            BoundaryVariant::Centre => 0,
            BoundaryVariant::Closest => 1,
        },
        n_cells,
        zero: 0,
        _pad: [0; 2],
    };

    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("voxelize"),
        });
    ctx.fill_u32(&mut encoder, &best_d2, u32::MAX)?;
    ctx.fill_u32(&mut encoder, &best_tri, u32::MAX)?;
    // Mode 1 chooses the owning triangle (wanted for the Centre variant too: the CPU records it).
    for mode in [0, 1] {
        let p = ctx.uniform_buffer("voxel params", &params(mode));
        let label = if mode == 0 {
            "voxel touch (distance)"
        } else {
            "voxel touch (triangle)"
        };
        record_pass(
            ctx,
            &mut encoder,
            label,
            &touch,
            &[(0, &p), (1, &tri_buf), (2, &best_d2), (3, &best_tri)],
            Dispatch::Threads(n_tris),
            timer.as_deref_mut(),
        );
    }
    let p = ctx.uniform_buffer("voxel params", &params(0));
    record_pass(
        ctx,
        &mut encoder,
        "voxel points",
        &finish,
        &[
            (0, &p),
            (1, &tri_buf),
            (2, &best_d2),
            (3, &best_tri),
            (4, &points),
        ],
        Dispatch::Threads(n_cells),
        timer.as_deref_mut(),
    );
    let inside = if signed {
        Some(record_inside(
            ctx,
            &mut encoder,
            spec,
            &tri_buf,
            n_tris,
            timer.as_deref_mut(),
        )?)
    } else {
        None
    };
    submit(ctx, encoder, timer);
    Ok(GpuBoundary {
        spec: *spec,
        variant,
        points,
        owner: best_tri,
        faces: tri_buf,
        faces_world: Arc::new(faces_world),
        inside,
    })
}

/// Mirrors `SolidParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SolidParams {
    dims: [u32; 4],
    n_rows: u32,
    n_words: u32,
    n_cells: u32,
    zero: u32,
}

/// Records the passes of `shaders/voxel/solid.wgsl` (the CPU's [`super::solid::inside_cells`],
/// bit for bit) over the triangles `tris` (grid coordinates): the inside bitset.
fn record_inside(
    ctx: &GpuContext,
    encoder: &mut wgpu::CommandEncoder,
    spec: &GridSpec,
    tris: &wgpu::Buffer,
    n_tris: u32,
    mut timer: Option<&mut GpuTimer>,
) -> Result<wgpu::Buffer> {
    let dims = spec.dims;
    let n_cells = spec.len() as u32;
    let params = SolidParams {
        dims: [dims.x, dims.y, dims.z, n_tris],
        n_rows: dims.y * dims.z,
        n_words: n_cells.div_ceil(32),
        n_cells,
        zero: 0,
    };
    let marks = ctx.zeroed_buffer("solid marks", spec.len() as u64 * 4)?;
    let words = ctx.zeroed_buffer("boundary inside", params.n_words as u64 * 4)?;
    let p = ctx.uniform_buffer("solid params", &params);
    let sources = [
        shader!("common/dispatch.wgsl"),
        shader!("common/geom.wgsl"),
        shader!("voxel/solid.wgsl"),
    ];
    // Each entry binds what it uses (the layouts are derived from the shader).
    type Pass<'a> = (&'static str, u32, Vec<(u32, &'a wgpu::Buffer)>);
    let passes: [Pass; 3] = [
        ("mark", n_tris, vec![(0, &p), (1, tris), (2, &marks)]),
        ("rows", params.n_rows, vec![(0, &p), (2, &marks)]),
        (
            "pack",
            params.n_words,
            vec![(0, &p), (2, &marks), (3, &words)],
        ),
    ];
    for (entry, n, bind) in passes {
        let pipeline = ctx.pipeline("solid", &sources, entry)?;
        let label = format!("solid {entry}");
        record_pass(
            ctx,
            encoder,
            &label,
            &pipeline,
            &bind,
            Dispatch::Threads(n),
            timer.as_deref_mut(),
        );
    }
    Ok(words)
}
