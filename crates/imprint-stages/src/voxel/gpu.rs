//! GPU voxelisation (`shaders/voxel/voxelize.wgsl`), the same boundary as [`super::cpu`].
//!
//! The decision for each (triangle, cell) pair is the CPU's, operation for operation: the
//! vertices go to grid coordinates on the CPU (`GridSpec::to_cell`, so they are the same bits),
//! the candidate cells are the triangle's box grown by [`CELL_HALF`], a pair is rejected beyond
//! the circumscribed sphere, accepted inside the inscribed one and tested by separating axes
//! in between, and each cell keeps the smallest (squared distance, triangle index). Three
//! passes make that minimum with 32-bit atomics in any thread order (see the shader).
//!
//! The result stays on the GPU as a dense per-cell buffer ([`GpuBoundary`]) that the field
//! stage reads directly; [`GpuBoundary::to_cpu`] compacts it into the CPU's [`Boundary`].

use super::cpu::CELL_HALF;
use glam::Vec3;
use imprint_core::{Boundary, BoundaryVariant, Error, GridSpec, Mesh, Result};
use imprint_gpu::{GpuContext, GpuTimer, compute_pass, shader};

/// Bytes per cell of the voxeliser's largest buffer (the vec4 points; the limit is per binding).
const BYTES_PER_CELL: u64 = 16;

/// A discrete boundary on the GPU: one `vec4<f32>` per grid cell, xyz the boundary point in
/// grid coordinates (cell centres at integers) and w = 1 for surface cells, 0 elsewhere. Dense
/// rather than compacted so that the field stage can find a cell's point by its index, and
/// the order of surface cells is the linear cell order by construction.
#[derive(Clone, Debug)]
pub struct GpuBoundary {
    pub spec: GridSpec,
    pub variant: BoundaryVariant,
    pub points: wgpu::Buffer,
}

impl GpuBoundary {
    /// Uploads a CPU boundary (for a GPU field built from a CPU voxelisation). Points go to
    /// grid coordinates with `GridSpec::to_cell`.
    pub fn from_cpu(ctx: &GpuContext, boundary: &Boundary) -> Result<GpuBoundary> {
        let spec = boundary.spec;
        ctx.check_grid("GPU boundary", spec.dims.to_array(), 16)?;
        let mut dense = vec![[0f32; 4]; spec.len()];
        for (&c, &p) in boundary.cells.iter().zip(&boundary.points) {
            let slot = dense
                .get_mut(c as usize)
                .ok_or_else(|| Error::Invalid(format!("boundary cell {c} is outside its grid")))?;
            *slot = spec.to_cell(p).extend(1.0).to_array();
        }
        Ok(GpuBoundary {
            spec,
            variant: boundary.variant,
            points: ctx.storage_buffer("boundary points", &dense)?,
        })
    }

    /// Reads the boundary back and compacts it: surface cells in increasing linear index,
    /// world points computed as the CPU does (`origin + q * cell`).
    pub fn to_cpu(&self, ctx: &GpuContext) -> Result<Boundary> {
        let dense: Vec<[f32; 4]> = ctx.read_buffer(&self.points)?;
        let mut cells = Vec::new();
        let mut points = Vec::new();
        for (i, p) in dense.iter().take(self.spec.len()).enumerate() {
            if p[3] != 0.0 {
                cells.push(i as u32);
                points.push(self.spec.origin + Vec3::new(p[0], p[1], p[2]) * self.spec.cell);
            }
        }
        Ok(Boundary {
            spec: self.spec,
            variant: self.variant,
            cells,
            points,
            faces: Vec::new(),
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
    _pad: [u32; 3],
}

/// The discrete boundary of `mesh` on `spec`, computed on the GPU and left there. The work is
/// submitted, not waited for: reading it back (or the next stage's submit) orders it.
pub fn voxelize_gpu(
    ctx: &GpuContext,
    mesh: &Mesh,
    spec: &GridSpec,
    variant: BoundaryVariant,
) -> Result<GpuBoundary> {
    voxelize_gpu_timed(ctx, mesh, spec, variant, None)
}

/// [`voxelize_gpu`], with its passes timed by `timer` (which then submits; call
/// [`GpuTimer::wait`] for the timings).
pub fn voxelize_gpu_timed(
    ctx: &GpuContext,
    mesh: &Mesh,
    spec: &GridSpec,
    variant: BoundaryVariant,
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
    let verts: Vec<Vec3> = mesh.positions.iter().map(|&p| spec.to_cell(p)).collect();
    let tris: Vec<[f32; 4]> = mesh
        .triangles
        .iter()
        .flat_map(|t| t.map(|i| verts[i as usize].extend(0.0).to_array()))
        .collect();

    let tri_buf = ctx.storage_buffer("voxel triangles", &tris)?;
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
        _pad: [0; 3],
    };

    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("voxelize"),
        });
    ctx.fill_u32(&mut encoder, &best_d2, u32::MAX)?;
    ctx.fill_u32(&mut encoder, &best_tri, u32::MAX)?;
    // Mode 1 only chooses among triangles, which the Centre point does not depend on.
    let modes: &[u32] = match variant {
        BoundaryVariant::Centre => &[0],
        BoundaryVariant::Closest => &[0, 1],
    };
    for &mode in modes {
        let p = ctx.uniform_buffer("voxel params", &params(mode));
        let bind = ctx.bind_group(
            "voxel touch",
            &touch,
            &[(0, &p), (1, &tri_buf), (2, &best_d2), (3, &best_tri)],
        );
        let label = if mode == 0 {
            "voxel touch (distance)"
        } else {
            "voxel touch (triangle)"
        };
        let mut pass = compute_pass(&mut encoder, label, timer.as_deref_mut());
        pass.set_pipeline(&touch);
        pass.set_bind_group(0, &bind, &[]);
        ctx.dispatch_1d(&mut pass, n_tris);
    }
    {
        let p = ctx.uniform_buffer("voxel params", &params(0));
        let bind = ctx.bind_group(
            "voxel finish",
            &finish,
            &[
                (0, &p),
                (1, &tri_buf),
                (2, &best_d2),
                (3, &best_tri),
                (4, &points),
            ],
        );
        let mut pass = compute_pass(&mut encoder, "voxel points", timer.as_deref_mut());
        pass.set_pipeline(&finish);
        pass.set_bind_group(0, &bind, &[]);
        ctx.dispatch_1d(&mut pass, n_cells);
    }
    match timer {
        Some(t) => t.submit(ctx, encoder),
        None => {
            ctx.queue.submit([encoder.finish()]);
        }
    }
    Ok(GpuBoundary {
        spec: *spec,
        variant,
        points,
    })
}
