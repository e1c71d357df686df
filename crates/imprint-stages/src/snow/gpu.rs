//! The snow stage's GPU parts: the ground's stabilisation ([`GpuSnowRelax`],
//! `shaders/snow/relax.wgsl`) and the arrival look-ups ([`GpuSnowArrival`],
//! `shaders/snow/arrival.wgsl`). The deposit stays on the CPU ([`super::SnowSim`]).
//!
//! **Stabilisation.** The passes of [`super::relax`] as two compute dispatches each (shed,
//! gather), with the same result to the bit: the quanta are u32, every pass reads a snapshot,
//! and the shader's f32 arithmetic is the CPU's in the same order with only correctly rounded
//! operations (its one division is done in integers), so [`GpuSnowRelax::relax`] leaves
//! exactly the `units` that [`super::relax::relax`] leaves, and the same [`RelaxReport`].
//!
//! *Passes in batches.* The CPU stops after the first pass that moves nothing. A pass that
//! moves nothing leaves the snow as it was, so every later pass moves nothing too: the GPU
//! records up to [`BATCH`] passes per submission, each adding what it moved to its own
//! counter (a u32 pair, low word and carries, so the count is exact), reads the counters back
//! once per batch and reports the passes up to the first that moved nothing, as the CPU does.
//! The snow is uploaded and read back once per call.
//!
//! **Arrival look-ups.** Per direction the depth map (from any rasteriser: the CPU's or
//! `imprint_gpu::raster::GpuRasterizer`) is uploaded and one invocation per receiver applies
//! [`super::arrival`]'s test. The counts are whole numbers, but from an f32 projection a
//! shader compiler may fuse, so a receiver exactly at a texel edge or the bias threshold may
//! come out the other way than on the CPU (none did in `tests/tests/gpu_snow.rs` on Mesa
//! lavapipe). [`GpuSnowArrival::arrival_resident`] takes the maps of a
//! `GpuRasterizer` where they were rendered instead: no map is read back or uploaded, and the
//! counts are the same (only they are read back, for the deposit on the CPU).
//!
//! **Use.** [`SnowSim::relax_with`](super::SnowSim::relax_with) takes
//! [`GpuSnowRelax::relaxer`]; [`SnowSim::step_with_parts`](super::SnowSim::step_with_parts)
//! takes an arrival (e.g. a closure over [`GpuSnowArrival::arrival_with`]) and a relaxer. The
//! CPU path ([`super::SnowSim::step`]) is unchanged.

use super::arrival::{Arrival, Lookup, Receivers, snow_camera};
use super::params::SnowParams;
use super::relax::{QUANTUM, RelaxReport, STENCIL};
use bytemuck::Zeroable;
use glam::{Vec3, Vec4};
use imprint_core::raster::{DepthMap, RasterOptions};
use imprint_core::{Camera, Error, HeightField, Mesh, Result};
use imprint_gpu::raster::GpuRasterizer;
use imprint_gpu::{Dispatch, GpuContext, record_pass, shader, submit};

/// Passes recorded per submission (the counters are read back once per batch).
pub const BATCH: u32 = 16;

/// Mirrors `RelaxParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct RelaxParams {
    nx: u32,
    nz: u32,
    slot: u32,
    _pad: u32,
    crit: [f32; 16],
}

/// Buffers for one grid size.
struct Buffers {
    n: usize,
    ground: wgpu::Buffer,
    /// The snow: `units[cur]` is the current snapshot, the other the next.
    units: [wgpu::Buffer; 2],
    flows: wgpu::Buffer,
    moved: wgpu::Buffer,
    /// One uniform per batch slot (the slot number differs).
    params: Vec<wgpu::Buffer>,
}

/// The stabilisation passes on the GPU; keeps its buffers between calls (reallocated when the
/// number of cells changes), so use one with one [`GpuContext`].
#[derive(Default)]
pub struct GpuSnowRelax {
    buffers: Option<Buffers>,
}

impl std::fmt::Debug for GpuSnowRelax {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GpuSnowRelax")
            .field("cells", &self.buffers.as_ref().map_or(0, |b| b.n))
            .finish()
    }
}

impl GpuSnowRelax {
    pub fn new() -> Self {
        Self::default()
    }

    /// As [`super::relax::relax`]: up to `passes` passes over the snow `units` on `ground`,
    /// stopping after the first that moves nothing; `units` is uploaded, relaxed on the GPU
    /// and read back.
    pub fn relax(
        &mut self,
        ctx: &GpuContext,
        ground: &HeightField,
        tan_repose: f32,
        units: &mut [u32],
        passes: u32,
    ) -> Result<RelaxReport> {
        let n = units.len();
        if n != ground.heights.len() {
            return Err(Error::Invalid(format!(
                "snow: {n} snow cells on a ground of {} cells",
                ground.heights.len()
            )));
        }
        let mut report = RelaxReport::default();
        if n == 0 || passes == 0 {
            return Ok(report);
        }
        let shed = ctx.pipeline(
            "snow shed",
            &[shader!("common/dispatch.wgsl"), shader!("snow/relax.wgsl")],
            "shed",
        )?;
        let gather = ctx.pipeline(
            "snow gather",
            &[shader!("common/dispatch.wgsl"), shader!("snow/relax.wgsl")],
            "gather",
        )?;
        let b = self.buffers(ctx, n)?;
        // As relax::relax computes it.
        let crit: [f32; 16] = std::array::from_fn(|t| {
            let (a, c) = STENCIL[t];
            tan_repose * ((a * a + c * c) as f32).sqrt() * ground.cell / QUANTUM
        });
        for (slot, buffer) in b.params.iter().enumerate() {
            let params = RelaxParams {
                nx: ground.dims.x,
                nz: ground.dims.y,
                slot: slot as u32,
                _pad: 0,
                crit,
            };
            ctx.queue
                .write_buffer(buffer, 0, bytemuck::bytes_of(&params));
        }
        ctx.queue
            .write_buffer(&b.ground, 0, bytemuck::cast_slice(&ground.heights));
        ctx.queue
            .write_buffer(&b.units[0], 0, bytemuck::cast_slice(units));
        let threads = n as u32;
        let mut cur = 0;
        let mut left = passes;
        while left > 0 && !report.settled {
            let batch = left.min(BATCH);
            let mut encoder = ctx
                .device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                    label: Some("snow relax"),
                });
            encoder.clear_buffer(&b.moved, 0, None);
            for slot in 0..batch as usize {
                let (from, to) = (&b.units[cur], &b.units[1 - cur]);
                let params = &b.params[slot];
                record_pass(
                    ctx,
                    &mut encoder,
                    "snow shed",
                    &shed,
                    &[
                        (0, params),
                        (1, &b.ground),
                        (2, from),
                        (3, &b.flows),
                        (5, &b.moved),
                    ],
                    Dispatch::Threads(threads),
                    None,
                );
                record_pass(
                    ctx,
                    &mut encoder,
                    "snow gather",
                    &gather,
                    &[(0, params), (2, from), (3, &b.flows), (4, to)],
                    Dispatch::Threads(threads),
                    None,
                );
                cur = 1 - cur;
            }
            submit(ctx, encoder, None);
            let counts: Vec<u32> = ctx.read_buffer(&b.moved)?;
            for pair in counts.chunks_exact(2).take(batch as usize) {
                let moved = pair[0] as u64 + ((pair[1] as u64) << 32);
                report.passes += 1;
                report.moved += moved;
                report.settled = moved == 0;
                if report.settled {
                    break;
                }
            }
            left -= batch;
        }
        let out: Vec<u32> = ctx.read_buffer(&b.units[cur])?;
        units.copy_from_slice(&out[..n]);
        Ok(report)
    }

    /// A closure over `ctx` for [`super::SnowSim::relax_with`] and
    /// [`super::SnowSim::step_with_parts`].
    pub fn relaxer<'a>(
        &'a mut self,
        ctx: &'a GpuContext,
    ) -> impl FnMut(&HeightField, f32, &mut Vec<u32>, u32) -> Result<RelaxReport> + 'a {
        move |ground, tan, units, passes| self.relax(ctx, ground, tan, units, passes)
    }

    fn buffers(&mut self, ctx: &GpuContext, n: usize) -> Result<&Buffers> {
        if self.buffers.as_ref().is_none_or(|b| b.n != n) {
            let cells = n as u64;
            ctx.check_storage("snow stabilisation shares", cells * 64)?;
            self.buffers = Some(Buffers {
                n,
                ground: ctx.zeroed_buffer("snow ground", cells * 4)?,
                units: [
                    ctx.zeroed_buffer("snow units", cells * 4)?,
                    ctx.zeroed_buffer("snow units next", cells * 4)?,
                ],
                flows: ctx.zeroed_buffer("snow shares", cells * 64)?,
                moved: ctx.zeroed_buffer("snow moved", BATCH as u64 * 8)?,
                params: (0..BATCH)
                    .map(|_| ctx.uniform_buffer("snow relax params", &RelaxParams::zeroed()))
                    .collect(),
            });
        }
        Ok(self.buffers.as_ref().expect("allocated above"))
    }
}

/// Mirrors `LookupParams` in `shaders/snow/arrival.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LookupParams {
    eye: [f32; 4],
    right: [f32; 4],
    up: [f32; 4],
    forward: [f32; 4],
    dir: [f32; 4],
    k: f32,
    centre: f32,
    texel: f32,
    bias_texels: f32,
    res: u32,
    receivers: u32,
    row_texels: u32,
    _pad: u32,
}

impl LookupParams {
    fn new(look: &Lookup, dir: Vec3, params: &SnowParams, receivers: u32, row_texels: u32) -> Self {
        let four = |v: Vec3| v.extend(0.0).to_array();
        let f = look.frame;
        LookupParams {
            eye: four(f.eye),
            right: four(f.right),
            up: four(f.up),
            forward: four(f.forward),
            dir: four(dir),
            k: look.k,
            centre: look.centre,
            texel: look.texel,
            bias_texels: params.bias_texels,
            res: look.res,
            receivers,
            row_texels,
            _pad: 0,
        }
    }
}

/// What one arrival call keeps on the GPU: the receivers, their counts, the look-up's
/// parameters and pipeline.
struct LookupRun {
    n: usize,
    threads: u32,
    pipeline: wgpu::ComputePipeline,
    points: wgpu::Buffer,
    normals: wgpu::Buffer,
    counts: wgpu::Buffer,
    uniform: wgpu::Buffer,
}

impl LookupRun {
    /// Uploads the receivers; `None` when there is nothing to look up (no receiver, an empty
    /// occluder or no direction).
    fn start(
        ctx: &GpuContext,
        occluder: &Mesh,
        receivers: &Receivers,
        directions: &[Vec3],
        entry: &str,
    ) -> Result<Option<Self>> {
        let n = receivers.points.len();
        if n == 0 || occluder.bounds().is_empty() || directions.is_empty() {
            return Ok(None);
        }
        let threads = u32::try_from(n)
            .map_err(|_| Error::Invalid(format!("snow: {n} receivers are too many for the GPU")))?;
        let pipeline = ctx.pipeline(
            "snow arrival",
            &[
                shader!("common/dispatch.wgsl"),
                shader!("snow/arrival.wgsl"),
            ],
            entry,
        )?;
        let four = |v: Vec3| v.extend(0.0);
        let points: Vec<Vec4> = receivers.points.iter().copied().map(four).collect();
        let normals: Vec<Vec4> = receivers.normals.iter().copied().map(four).collect();
        Ok(Some(LookupRun {
            n,
            threads,
            pipeline,
            points: ctx.storage_buffer("snow receivers", &points)?,
            normals: ctx.storage_buffer("snow receiver normals", &normals)?,
            counts: ctx.zeroed_buffer("snow arrival counts", n as u64 * 4)?,
            uniform: ctx.uniform_buffer("snow lookup params", &LookupParams::zeroed()),
        }))
    }

    /// Records and submits one direction's look-ups against the map bound at `map_binding`.
    fn look_up(
        &self,
        ctx: &GpuContext,
        params: &LookupParams,
        map_binding: u32,
        map: &wgpu::Buffer,
    ) {
        // Queue writes land before the next submission and after the previous one's work,
        // so one uniform (and one map buffer) serves every direction.
        ctx.queue
            .write_buffer(&self.uniform, 0, bytemuck::bytes_of(params));
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("snow arrival"),
            });
        record_pass(
            ctx,
            &mut encoder,
            "snow arrival",
            &self.pipeline,
            &[
                (0, &self.uniform),
                (1, &self.points),
                (2, &self.normals),
                (map_binding, map),
                (4, &self.counts),
            ],
            Dispatch::Threads(self.threads),
            None,
        );
        submit(ctx, encoder, None);
    }

    /// The counts, read back (the deposit that uses them runs on the CPU).
    fn finish(self, ctx: &GpuContext, directions: u32) -> Result<Arrival> {
        let mut out: Vec<u32> = ctx.read_buffer(&self.counts)?;
        out.truncate(self.n);
        Ok(Arrival {
            counts: out,
            directions,
        })
    }
}

/// The arrival look-ups on the GPU (`shaders/snow/arrival.wgsl`): for each direction, the
/// depth map (from any rasteriser, as [`super::arrival::arrival_with`]) is uploaded and one
/// invocation per receiver counts whether it is reached. Counts are whole numbers, but the
/// projection is f32 that a shader compiler may fuse or reorder, so a receiver exactly at the
/// bias threshold or a texel edge can come out the other way than on the CPU:
/// `tests/tests/gpu_snow.rs` measures how many.
///
/// With the GPU rasteriser, [`GpuSnowArrival::arrival_resident`] reads each map where it was
/// rendered instead: no map is read back or uploaded, and the counts are the same.
#[derive(Debug, Default)]
pub struct GpuSnowArrival;

impl GpuSnowArrival {
    pub fn new() -> Self {
        GpuSnowArrival
    }

    /// As [`super::arrival::arrival_with`], with the look-ups on the GPU.
    pub fn arrival_with(
        &mut self,
        ctx: &GpuContext,
        occluder: &Mesh,
        receivers: &Receivers,
        directions: &[Vec3],
        params: &SnowParams,
        mut rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
    ) -> Result<Arrival> {
        let directions_rendered = directions.len() as u32;
        let Some(run) = LookupRun::start(ctx, occluder, receivers, directions, "lookup")? else {
            return Ok(Arrival {
                counts: vec![0; receivers.points.len()],
                directions: directions_rendered,
            });
        };
        let bounds = occluder.bounds();
        let res = params.resolution;
        let map_buffer = ctx.zeroed_buffer("snow depth map", res as u64 * res as u64 * 4)?;
        let mut texels = Vec::new();
        for &dir in directions {
            let cam = snow_camera(&bounds, dir, res)?;
            let map = rasterize(occluder, &cam, res, res, &RasterOptions::default())?;
            if (map.width, map.height) != (res, res) {
                return Err(Error::Invalid(format!(
                    "snow: the rasteriser returned a {} x {} map for {res} x {res}",
                    map.width, map.height
                )));
            }
            let look = Lookup::new(&map);
            texels.clear();
            texels.extend(
                map.depth
                    .iter()
                    .zip(&map.coverage)
                    .map(|(&d, &c)| if c { d } else { f32::MAX }),
            );
            ctx.queue
                .write_buffer(&map_buffer, 0, bytemuck::cast_slice(&texels));
            let p = LookupParams::new(&look, dir, params, run.threads, 0);
            run.look_up(ctx, &p, 3, &map_buffer);
        }
        run.finish(ctx, directions_rendered)
    }

    /// [`GpuSnowArrival::arrival_with`] with `raster`'s depth maps, each read where it was
    /// rendered ([`GpuRasterizer::depth_map_resident`]): the same maps (the same render, the
    /// same floats: a texel the host path would upload as uncovered is read as uncovered),
    /// the same test, so the same counts, without a map's read-back (8 bytes a texel, rows
    /// padded) and upload (4 bytes a texel) per direction. The counts are read back: the
    /// deposit is on the CPU.
    pub fn arrival_resident(
        &mut self,
        ctx: &GpuContext,
        raster: &mut GpuRasterizer,
        occluder: &Mesh,
        receivers: &Receivers,
        directions: &[Vec3],
        params: &SnowParams,
    ) -> Result<Arrival> {
        let directions_rendered = directions.len() as u32;
        let Some(run) = LookupRun::start(ctx, occluder, receivers, directions, "lookup_resident")?
        else {
            return Ok(Arrival {
                counts: vec![0; receivers.points.len()],
                directions: directions_rendered,
            });
        };
        let bounds = occluder.bounds();
        let res = params.resolution;
        for &dir in directions {
            let cam = snow_camera(&bounds, dir, res)?;
            let map = raster.depth_map_resident(
                ctx,
                occluder,
                &cam,
                res,
                res,
                &RasterOptions::default(),
            )?;
            let look = Lookup::for_camera(&map.camera, map.height);
            let p = LookupParams::new(&look, dir, params, run.threads, map.row_texels);
            run.look_up(ctx, &p, 5, map.texels());
        }
        run.finish(ctx, directions_rendered)
    }

    /// A closure over `ctx` and `raster` for
    /// [`SnowSim::step_with_parts`](super::SnowSim::step_with_parts)'s arrival:
    /// [`GpuSnowArrival::arrival_resident`].
    pub fn resident<'a>(
        &'a mut self,
        ctx: &'a GpuContext,
        raster: &'a mut GpuRasterizer,
    ) -> impl FnMut(&Mesh, &Receivers, &[Vec3], &SnowParams) -> Result<Arrival> + 'a {
        move |occluder, receivers, directions, params| {
            self.arrival_resident(ctx, raster, occluder, receivers, directions, params)
        }
    }
}
