//! GPU distance field (`shaders/sdf/field.wgsl`), the same field as [`super::cpu`].
//!
//! Each surface cell splats its point into the ball of `band` cells around it, keeping per
//! cell the smallest (squared distance, surface-cell index) with two passes of 32-bit
//! `atomicMin` (the order threads run in cannot change the result). Surface-cell order is
//! point order, so ties go to the smaller point index as on the CPU. The boundary point is
//! taken in grid units exactly as the CPU sees it (`to_cell` of the world point, rounding
//! included) and squared distances are summed in the CPU's order without fused multiply-adds,
//! so exact ties, which Centre boundaries make everywhere, are broken the same way.
//!
//! For a Closest boundary the last pass refines each band cell as the CPU does: the exact
//! distance to the best owning triangle of its own and its six neighbours' nearest points.
//!
//! The field stays on the GPU ([`GpuField::field`], one `vec4` per cell, H's RGBA layout) for
//! the stages that read it there; [`GpuField::to_cpu`] is for writers and tests.

use super::cpu::validate_band;
use crate::voxel::gpu::GpuBoundary;
use imprint_core::{BoundaryVariant, DistanceField, Error, Result};
use imprint_gpu::{Dispatch, GpuContext, GpuTimer, record_pass, shader, submit};

/// Bytes per cell of the field's largest buffer (the vec4 field; the limit is per binding).
const BYTES_PER_CELL: u64 = 16;

/// A narrow-band distance field on the GPU.
#[derive(Clone, Debug)]
pub struct GpuField {
    pub spec: imprint_core::GridSpec,
    /// Half-width of the band, in cells.
    pub band: f32,
    /// Per cell `vec4<f32>`: xyz = p - x toward the closest boundary point (on the owning
    /// triangle for a Closest boundary) and w = its distance, both in world units; far cells
    /// hold (0, 0, 0, band * cell).
    pub field: wgpu::Buffer,
    /// Per cell `u32`: the linear index of the surface cell whose point is nearest, or
    /// [`DistanceField::FAR`]. (Cell indices, not point indices: on the GPU the boundary is
    /// dense; `to_cpu` converts.)
    pub nearest_cell: wgpu::Buffer,
    /// The boundary the field was built from (its buffer is shared, not copied).
    pub boundary: GpuBoundary,
}

impl GpuField {
    /// Far value, world units (as [`DistanceField::far_value`]).
    pub fn far_value(&self) -> f32 {
        self.band * self.spec.cell
    }

    /// Reads the field back as the CPU's [`DistanceField`], `nearest` converted from surface
    /// cell indices to indices into the compacted boundary points: for writers, error
    /// measurement and CPU consumers (a GPU consumer takes the field where it is, e.g.
    /// `GpuCollider::from_gpu_field`). Counted as one field read-back
    /// ([`imprint_gpu::transfer`]), its bytes as read-backs.
    pub fn to_cpu(&self, ctx: &GpuContext) -> Result<DistanceField> {
        imprint_gpu::transfer::count_field_read_back();
        let boundary = self.boundary.to_cpu(ctx)?;
        let field: Vec<[f32; 4]> = ctx.read_buffer(&self.field)?;
        let cells: Vec<u32> = ctx.read_buffer(&self.nearest_cell)?;
        let n = self.spec.len();
        let dist = field.iter().take(n).map(|v| v[3]).collect();
        let nearest = cells
            .iter()
            .take(n)
            .map(|&c| match c {
                DistanceField::FAR => Ok(DistanceField::FAR),
                c => boundary
                    .cells
                    .binary_search(&c)
                    .map(|i| i as u32)
                    .map_err(|_| {
                        Error::Gpu(format!("field names cell {c}, which is not a surface cell"))
                    }),
            })
            .collect::<Result<Vec<u32>>>()?;
        Ok(DistanceField {
            spec: self.spec,
            band: self.band,
            dist,
            nearest,
            faces: (self.boundary.variant == BoundaryVariant::Closest).then_some(boundary.faces),
            points: boundary.points,
            inside: boundary.inside,
            cells: Default::default(),
        })
    }
}

/// Mirrors `FieldParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FieldParams {
    dims: [u32; 4],
    origin: [f32; 4],
    band: f32,
    band2: f32,
    far_value: f32,
    _pad3: u32,
    mode: u32,
    centre: u32,
    zero: u32,
    max_groups: u32,
    refine: u32,
    _pad: [u32; 3],
}

/// The narrow-band field of half-width `band` cells around `boundary`, on the GPU. Submitted,
/// not waited for.
pub fn build_field_gpu(ctx: &GpuContext, boundary: &GpuBoundary, band: f32) -> Result<GpuField> {
    build_field_gpu_timed(ctx, boundary, band, None)
}

/// [`build_field_gpu`], with its passes timed by `timer` (which then submits; call
/// [`GpuTimer::wait`] for the timings).
pub fn build_field_gpu_timed(
    ctx: &GpuContext,
    boundary: &GpuBoundary,
    band: f32,
    mut timer: Option<&mut GpuTimer>,
) -> Result<GpuField> {
    validate_band(band)?;
    let spec = boundary.spec;
    let dims = spec.dims;
    ctx.check_grid("GPU distance field", dims.to_array(), BYTES_PER_CELL)?;
    let n_cells = spec.len() as u32;

    // Grid coordinates of every cell centre as the CPU sees a Centre point:
    // to_cell(center(c)), per axis (each coordinate depends on its own index only).
    let axis = |o: f32, n: u32| (0..n).map(move |i| ((o + i as f32 * spec.cell) - o) / spec.cell);
    let axis_coords: Vec<f32> = axis(spec.origin.x, dims.x)
        .chain(axis(spec.origin.y, dims.y))
        .chain(axis(spec.origin.z, dims.z))
        .collect();

    let axis_buf = ctx.storage_buffer("field axis coordinates", &axis_coords)?;
    let best_d2 = ctx.zeroed_buffer("field best d2", spec.len() as u64 * 4)?;
    let splat_nearest = ctx.zeroed_buffer("field splat nearest", spec.len() as u64 * 4)?;
    let nearest_cell = ctx.zeroed_buffer("field nearest cell", spec.len() as u64 * 4)?;
    let field = ctx.zeroed_buffer("field", spec.len() as u64 * 16)?;
    let surface = ctx.zeroed_buffer("field surface cells", spec.len() as u64 * 4)?;
    let surface_count = ctx.zeroed_buffer("field surface count", 4)?;
    let dispatch_args = ctx.buffer("field dispatch", 12, wgpu::BufferUsages::INDIRECT)?;

    let sources = [
        shader!("common/dispatch.wgsl"),
        shader!("common/geom.wgsl"),
        shader!("sdf/field.wgsl"),
    ];
    // As on the CPU: Closest boundaries refine to their owning triangles, Centre ones do not.
    let refine = boundary.variant == BoundaryVariant::Closest;
    let compact = ctx.pipeline("field", &sources, "compact")?;
    let size_dispatch = ctx.pipeline("field", &sources, "size_dispatch")?;
    let scatter = ctx.pipeline("field", &sources, "scatter")?;
    let finish = ctx.pipeline("field", &sources, "finish")?;
    let params = |mode: u32| FieldParams {
        dims: [dims.x, dims.y, dims.z, n_cells],
        origin: spec.origin.extend(spec.cell).to_array(),
        band,
        band2: band * band,
        far_value: band * spec.cell,
        _pad3: 0,
        mode,
        centre: (boundary.variant == BoundaryVariant::Centre) as u32,
        zero: 0,
        max_groups: ctx.limits.max_compute_workgroups_per_dimension,
        refine: refine as u32,
        _pad: [0; 3],
    };

    let mut encoder = ctx
        .device
        .create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("distance field"),
        });
    ctx.fill_u32(&mut encoder, &best_d2, u32::MAX)?;
    ctx.fill_u32(&mut encoder, &splat_nearest, u32::MAX)?;
    let p0 = ctx.uniform_buffer("field params", &params(0));
    record_pass(
        ctx,
        &mut encoder,
        "field compact",
        &compact,
        &[
            (0, &p0),
            (1, &boundary.points),
            (6, &surface),
            (7, &surface_count),
        ],
        Dispatch::Threads(n_cells),
        timer.as_deref_mut(),
    );
    record_pass(
        ctx,
        &mut encoder,
        "field size dispatch",
        &size_dispatch,
        &[(0, &p0), (7, &surface_count), (8, &dispatch_args)],
        Dispatch::Groups(1, 1, 1),
        None,
    );
    for mode in [0, 1] {
        let p = ctx.uniform_buffer("field params", &params(mode));
        let label = if mode == 0 {
            "field splat (distance)"
        } else {
            "field splat (point)"
        };
        record_pass(
            ctx,
            &mut encoder,
            label,
            &scatter,
            &[
                (0, &p),
                (1, &boundary.points),
                (2, &best_d2),
                (3, &splat_nearest),
                (5, &axis_buf),
                (6, &surface),
                (7, &surface_count),
            ],
            Dispatch::Indirect(&dispatch_args),
            timer.as_deref_mut(),
        );
    }
    record_pass(
        ctx,
        &mut encoder,
        "field finish",
        &finish,
        &[
            (0, &p0),
            (1, &boundary.points),
            (2, &best_d2),
            (3, &splat_nearest),
            (4, &field),
            (9, &boundary.owner),
            (10, &boundary.faces),
            (11, &nearest_cell),
        ],
        Dispatch::Threads(n_cells),
        timer.as_deref_mut(),
    );
    submit(ctx, encoder, timer);
    Ok(GpuField {
        spec,
        band,
        field,
        nearest_cell,
        boundary: boundary.clone(),
    })
}
