//! The GPU ground (`shaders/ground/step.wgsl`): [`GroundSim`]'s `Labelled` frame as compute
//! dispatches over heights kept in a GPU buffer, bit for bit the CPU's integers and metrics.
//!
//! One frame, and where each part runs:
//! 1. **Contact** (CPU side, as allowed by the design): [`contact::object_bottoms_with`] with
//!    any rasteriser (the GPU one is a closure over its context), against a CPU copy of the
//!    heights that the frame's end refreshes from the GPU. From it the CPU takes the contact's
//!    box and the work window, the bottoms over the window (uploaded), the removed volume, and
//!    each contact cell's carry `round(α · removed)` (f64 arithmetic, which WGSL lacks; it
//!    is uploaded as 64-bit integers).
//! 2. **Press** (GPU): contact cells drop to the bottom.
//! 3. **Contour maps** (GPU): the exact city-block distance as two separable passes (per
//!    row, the distance along the row to the nearest seed; per column, the minimum over the
//!    column of that plus |dy|, by a forward and a backward scan), so no iteration to a fixed
//!    point and no change flag: the inner map (seeds outside the contact) and the outer map
//!    (seeds on it, then `d − 1` up to the band). The deepest level and the labelled count
//!    come back with one small read-back.
//! 4. **Displacement** (GPU): one dispatch per level, deepest first; shares go to the next
//!    level with 64-bit atomic adds (two u32 words), which sum the same integers in any
//!    order; then the rim cells take what reached them.
//! 5. **Labelled slump** (GPU): En passes × `slump_band` rings × three dispatches (steep
//!    counts, flows from the snapshot, apply); every pass's moved units are summed with
//!    atomics. Passes are recorded in batches of 8, and the sums read back between batches:
//!    a pass that moves nothing leaves the heights as they were, so the passes after it move
//!    nothing either; the next batch is skipped, and the iteration count the CPU reports (it
//!    stops at the first such pass) is read from the per-pass sums.
//! 6. **Metrics**: `max_slope` by an atomic max on the GPU; the heights are read back once
//!    (the CPU copy for the next frame's contact) and the mass summed from them.
//!
//! With the GPU rasteriser, [`GpuGround::step_resident`] does step 1 on the GPU too
//! (`shaders/ground/contact.wgsl`): each object's depth map stays where it was rendered and
//! becomes bottoms there (the f64 conversions of the CPU done exactly in integers), the
//! contact's box (32 bytes, read back to size the work window) and the carries; no depth map
//! is read back and no bottom or carry uploaded, and the heights and metrics are the same.
//!
//! `Relaxation::Settle` (the default) runs steps 1-4 here, skips step 5, and settles on the
//! CPU: the heights are read back anyway (step 6), the frame's contact cells come back with
//! them (one `u32` per window cell), `ground::settle::settle_frame` runs on them exactly as
//! in [`GroundSim`], and the heights are uploaded again when it moved anything; `max_slope`
//! comes from the settle, as in [`GroundSim`]. Same integers and metrics as the CPU.
//!
//! Not ported: `Relaxation::Full` ([`GpuGround::new`] refuses it; use [`GroundSim`]), and
//! [`GroundSim::add_heights`] (move the ground to the CPU and back with
//! [`GpuGround::to_sim`] / [`GpuGround::from_sim`]).

use super::contact::{self, GroundGrid, NO_OBJECT, Window};
use super::cpu::{GroundSim, work_window};
use super::metrics::GroundFrameMetrics;
use super::params::{GroundParams, MaterialValues, Relaxation, invalid};
use crate::depth::HeightView;
use imprint_core::camera::Camera;
use imprint_core::raster::{DepthMap, RasterOptions};
use imprint_core::{Mesh, Result};
use imprint_gpu::raster::GpuRasterizer;
use imprint_gpu::{Dispatch, GpuContext, record_pass, shader, submit};
use std::path::Path;

/// Stats words (see the shader): deepest inner level, labelled cells, largest labelled
/// neighbour difference, then 64-bit sums: displaced units, and each slump pass's moved units.
const STAT_MAX_LEVEL: usize = 0;
const STAT_LABELLED: usize = 1;
const STAT_MAX_DIFF: usize = 2;
const STAT_DISPLACED: usize = 4;
const STAT_MOVED: usize = 8;

/// The shader's entry points.
const ENTRIES: [&str; 9] = [
    "press",
    "dist_rows",
    "dist_cols",
    "displace",
    "rim",
    "slump_steep",
    "slump_flow",
    "slump_apply",
    "slope",
];

/// Slump passes recorded between two looks at whether the last ones moved anything.
const SLUMP_CHUNK: u32 = 8;

/// The shader's `Params`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    nx: u32,
    i0: u32,
    k0: u32,
    w: u32,
    h: u32,
    band: u32,
    t: u32,
    level: u32,
    pass_index: u32,
    mode: u32,
    _pad: [u32; 2],
}

/// The ground on the GPU: its heights in a storage buffer (`i32` units, x fastest).
#[derive(Debug)]
pub struct GpuGround {
    grid: GroundGrid,
    material: MaterialValues,
    band: u32,
    /// T in units, or `None` (θ = 90°): no slump.
    threshold: Option<i64>,
    /// `Relaxation::Settle`: settle on the CPU after the GPU's press (else O's slump here).
    settle: bool,
    max_relax_iterations: u32,
    /// `Settle`: the cells the next frame's work list starts from (as in [`GroundSim`]).
    pending: Vec<u32>,
    /// `Settle`: the work list's buffers.
    scratch: super::settle::Scratch,
    frame: u32,
    heights: wgpu::Buffer,
    /// The heights as of the last frame's end, for the next frame's contact.
    mirror: Vec<i32>,
    /// The pipelines of [`ENTRIES`], in that order.
    pipelines: Vec<wgpu::ComputePipeline>,
}

/// The frame's buffers over its work window.
struct Frame {
    bottom: wgpu::Buffer,
    contact: wgpu::Buffer,
    tmp: wgpu::Buffer,
    inner: wgpu::Buffer,
    outer: wgpu::Buffer,
    carry: wgpu::Buffer,
    steep: wgpu::Buffer,
    delta: wgpu::Buffer,
    stats: wgpu::Buffer,
}

impl GpuGround {
    /// A ground as `params` state it (as [`GroundSim::new`]), on the GPU. `Full` relaxation
    /// is refused: it has no GPU port yet.
    pub fn new(ctx: &GpuContext, params: &GroundParams, base_dir: &Path) -> Result<Self> {
        Self::from_sim(ctx, &GroundSim::new(params, base_dir)?)
    }

    /// Uploads a CPU ground (its heights, parameters and frame count).
    pub fn from_sim(ctx: &GpuContext, sim: &GroundSim) -> Result<Self> {
        if sim.relaxation() == Relaxation::Full {
            return Err(invalid(
                "relaxation: Full has no GPU port yet; use relaxation: Labelled on the GPU, or \
                 the CPU ground"
                    .into(),
            ));
        }
        let grid = *sim.grid();
        ctx.check_grid("ground heights", [grid.dims.x, grid.dims.y, 1], 4)?;
        Ok(GpuGround {
            grid,
            material: sim.material(),
            band: sim.band(),
            threshold: sim.threshold_units(),
            settle: sim.relaxation() == Relaxation::Settle,
            max_relax_iterations: sim.max_relax_iterations(),
            pending: sim.pending().to_vec(),
            scratch: Default::default(),
            frame: sim.frame(),
            heights: ctx.storage_buffer("ground heights", sim.heights_units())?,
            mirror: sim.heights_units().to_vec(),
            pipelines: ENTRIES
                .iter()
                .map(|entry| {
                    ctx.pipeline(
                        "ground step",
                        &[shader!("common/dispatch.wgsl"), shader!("ground/step.wgsl")],
                        entry,
                    )
                })
                .collect::<Result<_>>()?,
        })
    }

    /// The heights (units, x fastest) as of the last frame's end.
    pub fn heights_units(&self) -> &[i32] {
        &self.mirror
    }

    /// The ground as a height field in metres (as [`GroundSim::to_height_field`]).
    pub fn to_height_field(&self) -> imprint_core::HeightField {
        self.grid.height_field(&self.mirror)
    }

    /// The heights' GPU buffer (`array<i32>`, x fastest), for renderers.
    pub fn heights_buffer(&self) -> &wgpu::Buffer {
        &self.heights
    }

    /// The cells, their place in the world and the height unit.
    pub fn grid(&self) -> &GroundGrid {
        &self.grid
    }

    /// Frames stepped so far.
    pub fn frame(&self) -> u32 {
        self.frame
    }

    /// As [`GroundSim::height_bounds_violation`], on the heights as of the last frame's end.
    pub fn height_bounds_violation(&self, lowest: f32, highest: f32) -> Option<(usize, f32)> {
        super::cpu::height_bounds_violation(&self.mirror, &self.grid, lowest, highest)
    }

    /// Σ heights, units.
    pub fn mass(&self) -> i64 {
        self.mirror.iter().map(|&h| h as i64).sum()
    }

    /// The same ground on the CPU, with `params` (its heights and frame count; the last
    /// frame's contour maps are not carried): e.g. to go on with `Full` relaxation.
    pub fn to_sim(&self, params: &GroundParams) -> Result<GroundSim> {
        let mut sim = GroundSim::from_units(params, self.mirror.clone())?;
        sim.set_frame(self.frame);
        Ok(sim)
    }

    /// One frame with the CPU rasteriser for the contact view (as [`GroundSim::step`]).
    pub fn step(&mut self, ctx: &GpuContext, objects: &[&Mesh]) -> Result<GroundFrameMetrics> {
        self.step_with(ctx, objects, imprint_core::raster::rasterize_depth_with)
    }

    /// One frame (as [`GroundSim::step_with`]): the same heights and metrics, bit for bit.
    pub fn step_with(
        &mut self,
        ctx: &GpuContext,
        objects: &[&Mesh],
        rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
    ) -> Result<GroundFrameMetrics> {
        let mut m = GroundFrameMetrics {
            frame: self.frame,
            ..Default::default()
        };
        let mut pressed = None;
        if let Some(b) = contact::object_bottoms_with(objects, &self.grid, &self.mirror, rasterize)?
        {
            pressed = self.press(ctx, &b, &mut m)?;
        }
        self.settle_after(ctx, objects, pressed, &mut m)?;
        m.mass_units = self.mass();
        m.mass_volume = m.mass_units as f64 * self.grid.unit_volume();
        self.frame += 1;
        Ok(m)
    }

    /// One frame (as [`GpuGround::step_with`] with `raster`'s depth maps), its contact found
    /// on the GPU: each object's depth map is read where it was rendered
    /// ([`GpuRasterizer::depth_map_resident`]) and turned there into bottoms, the contact's
    /// box and the carries (`shaders/ground/contact.wgsl`, integers only), so no depth map is
    /// read back and no bottom or carry is uploaded. Read back: the contact's box (32 bytes,
    /// which sizes the work window, when an object reaches below the ground under it), the
    /// frame's stats words, and the heights (the stage's output, as in
    /// [`GpuGround::step_with`]). The same heights and metrics as
    /// [`GpuGround::step_with`] with `raster`'s `depth_map`, bit for bit.
    pub fn step_resident(
        &mut self,
        ctx: &GpuContext,
        raster: &mut GpuRasterizer,
        objects: &[&Mesh],
    ) -> Result<GroundFrameMetrics> {
        let mut m = GroundFrameMetrics {
            frame: self.frame,
            ..Default::default()
        };
        let pressed = self.contact_resident(ctx, raster, objects, &mut m)?;
        self.settle_after(ctx, objects, pressed, &mut m)?;
        m.mass_units = self.mass();
        m.mass_volume = m.mass_units as f64 * self.grid.unit_volume();
        self.frame += 1;
        Ok(m)
    }

    /// Step 1 of the module doc on the GPU (see [`GpuGround::step_resident`]), then steps 2-6.
    fn contact_resident(
        &mut self,
        ctx: &GpuContext,
        raster: &mut GpuRasterizer,
        objects: &[&Mesh],
        m: &mut GroundFrameMetrics,
    ) -> Result<Option<Pressed>> {
        let grid = self.grid;
        let nx = grid.dims.x;
        // The objects to rasterise and where, as contact::object_bottoms_with chooses them.
        let mut parts = Vec::new();
        for &mesh in objects {
            let b = mesh.bounds();
            if b.is_empty() {
                continue;
            }
            let Some(w) = grid.window_under(&b) else {
                continue;
            };
            let top = (0..w.h)
                .flat_map(|y| (0..w.w).map(move |x| (x, y)))
                .map(|(x, y)| self.mirror[w.global(x, y, nx)])
                .max()
                .unwrap_or(0);
            if grid.to_units(b.min.y as f64) >= top as i64 {
                continue;
            }
            let cam = grid
                .region(&w)?
                .camera(HeightView::Below, (b.min.y, b.max.y))?;
            parts.push((mesh, w, cam));
        }
        let Some(bw) = parts.iter().map(|p| p.1).reduce(|a, b| a.union(&b)) else {
            return Ok(None);
        };
        let (unit_lo, unit_hi, unit_exp) = unit_parts(grid.unit)?;
        let base = ContactParams {
            nx,
            bi0: bw.i0,
            bk0: bw.k0,
            bw: bw.w,
            bh: bw.h,
            alpha: self.material.displace_ratio,
            unit_lo,
            unit_hi,
            unit_exp,
            ..bytemuck::Zeroable::zeroed()
        };
        let pipe = |entry: &str| {
            ctx.pipeline(
                "ground contact",
                &[
                    shader!("common/dispatch.wgsl"),
                    shader!("ground/contact.wgsl"),
                ],
                entry,
            )
        };
        let encoder = |label| {
            ctx.device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
        };
        let bottoms = ctx.zeroed_buffer("ground object bottoms", 4 * bw.len() as u64)?;
        let box_ = ctx.zeroed_buffer("ground contact box", 32)?;
        let mut enc = encoder("ground bottoms");
        ctx.fill_u32(&mut enc, &bottoms, NO_OBJECT as u32)?;
        submit(ctx, enc, None);
        let bottoms_pass = pipe("bottoms_pass")?;
        for (mesh, w, cam) in &parts {
            let map =
                raster.depth_map_resident(ctx, mesh, cam, w.w, w.h, &RasterOptions::default())?;
            let ub = ctx.uniform_buffer(
                "ground contact params",
                &ContactParams {
                    i0: w.i0,
                    k0: w.k0,
                    w: w.w,
                    h: w.h,
                    row_texels: map.row_texels,
                    eye_y: map.camera.eye.y,
                    ..base
                },
            );
            let mut enc = encoder("ground bottoms");
            record_pass(
                ctx,
                &mut enc,
                "ground bottoms",
                &bottoms_pass,
                &[(0, &ub), (2, map.texels()), (3, &bottoms), (4, &box_)],
                Dispatch::Threads(w.w * w.h),
                None,
            );
            submit(ctx, enc, None);
        }
        let ub = ctx.uniform_buffer("ground contact params", &base);
        let mut enc = encoder("ground contact box");
        record_pass(
            ctx,
            &mut enc,
            "ground contact box",
            &pipe("contact_box")?,
            &[(0, &ub), (1, &self.heights), (3, &bottoms), (4, &box_)],
            Dispatch::Threads(bw.w * bw.h),
            None,
        );
        submit(ctx, enc, None);
        let bx: Vec<u32> = ctx.read_buffer(&box_)?;
        if bx[7] != 0 {
            return Err(invalid(
                "a depth view of an object gave a height that is not finite".into(),
            ));
        }
        if bx[4] == 0 {
            return Ok(None);
        }
        m.contact_cells = bx[4];
        m.removed_units = (bx[5] as u64 | (bx[6] as u64) << 32) as i64;
        let (lo, hi) = ((u32::MAX - bx[0], u32::MAX - bx[1]), (bx[2], bx[3]));
        // As work_window: the contact's box grown by band + 1 cells, clipped to the field.
        let win = Window {
            i0: lo.0,
            k0: lo.1,
            w: hi.0 - lo.0 + 1,
            h: hi.1 - lo.1 + 1,
        }
        .grow(self.band + 1, grid.dims);
        let n = win.len() as u64;
        let bottom = ctx.zeroed_buffer("ground bottoms", 4 * n)?;
        let carry = ctx.zeroed_buffer("ground carry", 8 * n)?;
        let ub = ctx.uniform_buffer(
            "ground contact params",
            &ContactParams {
                wi0: win.i0,
                wk0: win.k0,
                ww: win.w,
                wh: win.h,
                ..base
            },
        );
        let mut enc = encoder("ground gather");
        record_pass(
            ctx,
            &mut enc,
            "ground gather",
            &pipe("gather")?,
            &[
                (0, &ub),
                (1, &self.heights),
                (3, &bottoms),
                (5, &bottom),
                (6, &carry),
            ],
            Dispatch::Threads(win.w * win.h),
            None,
        );
        submit(ctx, enc, None);
        self.press_window(ctx, win, bottom, carry, m)
    }

    /// Steps 1-6 of the module doc for one contact.
    fn press(
        &mut self,
        ctx: &GpuContext,
        b: &contact::Bottoms,
        m: &mut GroundFrameMetrics,
    ) -> Result<Option<Pressed>> {
        let nx = self.grid.dims.x;
        let Some((win, bottom)) = work_window(b, &self.mirror, self.grid.dims, self.band) else {
            return Ok(None);
        };
        let (w, n) = (win.w as usize, win.len());
        let alpha = self.material.displace_ratio as f64;
        let mut carry = vec![0u64; n];
        for (j, &bot) in bottom.iter().enumerate() {
            let h = self.mirror[win.global((j % w) as u32, (j / w) as u32, nx)];
            if bot < h {
                let removed = h as i64 - bot as i64;
                m.contact_cells += 1;
                m.removed_units += removed;
                carry[j] = (alpha * removed as f64).round() as u64;
            }
        }
        let bottom = ctx.storage_buffer("ground bottoms", &bottom)?;
        let carry = ctx.storage_buffer("ground carry", &carry)?;
        self.press_window(ctx, win, bottom, carry, m)
    }

    /// Steps 2-6 of the module doc over the work window `win`, from its bottoms and carries
    /// (GPU buffers: uploaded by [`GpuGround::press`], made on the GPU by
    /// [`GpuGround::step_resident`]).
    fn press_window(
        &mut self,
        ctx: &GpuContext,
        win: Window,
        bottom: wgpu::Buffer,
        carry: wgpu::Buffer,
        m: &mut GroundFrameMetrics,
    ) -> Result<Option<Pressed>> {
        let nx = self.grid.dims.x;
        let n = win.len();
        let passes = match self.threshold {
            Some(_) if !self.settle => self.material.slump_iterations,
            _ => 0,
        };
        let f = Frame {
            bottom,
            contact: ctx.zeroed_buffer("ground contact", 4 * n as u64)?,
            tmp: ctx.zeroed_buffer("ground distance rows", 4 * n as u64)?,
            inner: ctx.zeroed_buffer("ground inner map", 4 * n as u64)?,
            outer: ctx.zeroed_buffer("ground outer map", 4 * n as u64)?,
            carry,
            steep: ctx.zeroed_buffer("ground steep counts", 4 * n as u64)?,
            delta: ctx.zeroed_buffer("ground slump flows", 4 * n as u64)?,
            stats: ctx
                .zeroed_buffer("ground stats", 4 * (STAT_MOVED as u64 + 2 * passes as u64))?,
        };
        let base = Params {
            nx,
            i0: win.i0,
            k0: win.k0,
            w: win.w,
            h: win.h,
            band: self.band,
            t: self.threshold.unwrap_or(0).clamp(0, i32::MAX as i64) as u32,
            ..Default::default()
        };
        let pipes = &self.pipelines;
        let pipe = |entry: &str| {
            let i = ENTRIES
                .iter()
                .position(|&e| e == entry)
                .expect("a shader entry");
            &pipes[i]
        };
        let rec = |enc: &mut wgpu::CommandEncoder,
                   entry: &str,
                   params: Params,
                   bufs: &[(u32, &wgpu::Buffer)],
                   threads: u32|
         -> Result<()> {
            let ub = ctx.uniform_buffer("ground params", &params);
            let mut all = vec![(0, &ub)];
            all.extend_from_slice(bufs);
            record_pass(
                ctx,
                enc,
                entry,
                pipe(entry),
                &all,
                Dispatch::Threads(threads),
                None,
            );
            Ok(())
        };
        let encoder = |label| {
            ctx.device
                .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(label) })
        };
        let (hb, n32) = (&self.heights, n as u32);

        // Press and both contour maps, then read back the deepest level.
        let mut enc = encoder("ground press and contours");
        rec(
            &mut enc,
            "press",
            base,
            &[(1, hb), (2, &f.bottom), (3, &f.contact)],
            n32,
        )?;
        for mode in [0, 1] {
            let p = Params { mode, ..base };
            rec(
                &mut enc,
                "dist_rows",
                p,
                &[(3, &f.contact), (4, &f.tmp)],
                win.h,
            )?;
            rec(
                &mut enc,
                "dist_cols",
                p,
                &[
                    (3, &f.contact),
                    (4, &f.tmp),
                    (5, &f.inner),
                    (6, &f.outer),
                    (10, &f.stats),
                ],
                win.w,
            )?;
        }
        submit(ctx, enc, None);
        let stats: Vec<u32> = ctx.read_buffer(&f.stats)?;
        let max_level = stats[STAT_MAX_LEVEL];
        m.max_contour = max_level;
        m.labelled_cells = stats[STAT_LABELLED];

        // Displacement level by level, the rims, the slump, the slope.
        let mut enc = encoder("ground displace and slump");
        for l in (1..=max_level).rev() {
            let p = Params { level: l, ..base };
            rec(
                &mut enc,
                "displace",
                p,
                &[(5, &f.inner), (7, &f.carry)],
                n32,
            )?;
        }
        rec(
            &mut enc,
            "rim",
            base,
            &[(1, hb), (3, &f.contact), (7, &f.carry), (10, &f.stats)],
            n32,
        )?;
        let wide = |s: &[u32], at: usize| s[at] as u64 | (s[at + 1] as u64) << 32;
        for pass in 0..passes {
            // Every SLUMP_CHUNK passes, see whether one moved nothing (then neither would
            // the rest): a material with many passes stops early, as the CPU does.
            if pass > 0 && pass % SLUMP_CHUNK == 0 {
                submit(ctx, enc, None);
                let s: Vec<u32> = ctx.read_buffer(&f.stats)?;
                enc = encoder("ground slump");
                if (pass - SLUMP_CHUNK..pass).any(|q| wide(&s, STAT_MOVED + 2 * q as usize) == 0) {
                    break;
                }
            }
            for k in 0..self.band {
                let p = Params {
                    level: k,
                    pass_index: pass,
                    ..base
                };
                rec(
                    &mut enc,
                    "slump_steep",
                    p,
                    &[(1, hb), (6, &f.outer), (8, &f.steep)],
                    n32,
                )?;
                rec(
                    &mut enc,
                    "slump_flow",
                    p,
                    &[
                        (1, hb),
                        (6, &f.outer),
                        (8, &f.steep),
                        (9, &f.delta),
                        (10, &f.stats),
                    ],
                    n32,
                )?;
                rec(
                    &mut enc,
                    "slump_apply",
                    p,
                    &[(1, hb), (6, &f.outer), (9, &f.delta)],
                    n32,
                )?;
            }
        }
        rec(
            &mut enc,
            "slope",
            base,
            &[(1, hb), (6, &f.outer), (10, &f.stats)],
            n32,
        )?;
        submit(ctx, enc, None);
        let stats: Vec<u32> = ctx.read_buffer(&f.stats)?;
        let mut read: Vec<i32> = ctx.read_buffer(&self.heights)?;
        read.truncate(self.grid.len());
        let before = std::mem::replace(&mut self.mirror, read);

        let unit_volume = self.grid.unit_volume();
        m.removed_volume = m.removed_units as f64 * unit_volume;
        m.displaced_units = wide(&stats, STAT_DISPLACED) as i64;
        m.displaced_volume = m.displaced_units as f64 * unit_volume;
        for pass in 0..passes as usize {
            let moved = wide(&stats, STAT_MOVED + 2 * pass) as i64;
            m.slump_iterations += 1;
            m.slump_visits += m.labelled_cells as u64;
            m.slumped_units += moved;
            if moved == 0 {
                break;
            }
        }
        m.max_slope = stats[STAT_MAX_DIFF] as f32 * (self.grid.unit / self.grid.cell as f64) as f32;
        let changed = if self.settle {
            super::settle::changed_cells(&before, &self.mirror, win, nx)
        } else {
            Vec::new()
        };
        let contact = if self.settle {
            let c: Vec<u32> = ctx.read_buffer(&f.contact)?;
            let w = win.w as usize;
            (c.iter().take(n).enumerate())
                .filter(|c| *c.1 != 0)
                .map(|(j, _)| win.global((j % w) as u32, (j / w) as u32, nx) as u32)
                .collect()
        } else {
            Vec::new()
        };
        Ok(Some(Pressed { changed, contact }))
    }

    /// `Settle`: the CPU's settle on the heights read back (see the module doc), then the
    /// heights uploaded again when it moved anything. On an error the ground keeps the
    /// frame's press, unsettled (the CPU ground goes back to the frame's start).
    fn settle_after(
        &mut self,
        ctx: &GpuContext,
        objects: &[&Mesh],
        pressed: Option<Pressed>,
        m: &mut GroundFrameMetrics,
    ) -> Result<()> {
        if !self.settle {
            return Ok(());
        }
        let (changed, contact) = match pressed {
            Some(p) => (p.changed, p.contact),
            None => (Vec::new(), Vec::new()),
        };
        let mut held = vec![false; self.grid.len()];
        for &j in &contact {
            held[j as usize] = true;
        }
        // As the CPU ground: the slope over the cells the settle took (none at θ = 90°).
        m.max_slope = 0.0;
        if let Some(t) = self.threshold {
            let mut heights = self.mirror.clone();
            let tops = super::settle::Tops::of(objects, &self.grid);
            super::settle::settle_frame(
                &mut heights,
                &held,
                &self.grid,
                t,
                &tops,
                &self.pending,
                &changed,
                self.max_relax_iterations,
                self.frame,
                &mut self.scratch,
                m,
            )?;
            if m.slumped_units > 0 {
                ctx.queue
                    .write_buffer(&self.heights, 0, bytemuck::cast_slice(&heights));
                self.mirror = heights;
            }
        }
        self.pending = contact;
        Ok(())
    }
}

/// What a frame's press on the GPU leaves for `Settle` (ascending; empty unless settling):
/// the cells it changed and its contact cells.
struct Pressed {
    changed: Vec<u32>,
    contact: Vec<u32>,
}

/// The shader's `ContactParams` (`shaders/ground/contact.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct ContactParams {
    nx: u32,
    i0: u32,
    k0: u32,
    w: u32,
    h: u32,
    row_texels: u32,
    bi0: u32,
    bk0: u32,
    bw: u32,
    bh: u32,
    wi0: u32,
    wk0: u32,
    ww: u32,
    wh: u32,
    eye_y: f32,
    alpha: f32,
    unit_lo: u32,
    unit_hi: u32,
    unit_exp: i32,
    count: u32,
}

/// The height unit as the contact shader takes it: its 53-bit significand (low and high
/// words) and the power of two it is multiplied by.
fn unit_parts(unit: f64) -> Result<(u32, u32, i32)> {
    let bits = unit.to_bits();
    let e = ((bits >> 52) & 0x7ff) as i32;
    if !(unit.is_finite() && unit > 0.0) || e == 0 {
        return Err(invalid(format!(
            "the height unit {unit} m must be a normal positive number for the GPU contact"
        )));
    }
    let mant = (bits & ((1u64 << 52) - 1)) | (1u64 << 52);
    Ok((mant as u32, (mant >> 32) as u32, e - 1075))
}

/// Runs one of the contact shader's probes over `input` (for tests).
fn probe(
    ctx: &GpuContext,
    entry: &str,
    params: ContactParams,
    input: &[u32],
    words_out: u64,
) -> Result<Vec<u32>> {
    let pipeline = ctx.pipeline(
        "ground contact",
        &[
            shader!("common/dispatch.wgsl"),
            shader!("ground/contact.wgsl"),
        ],
        entry,
    )?;
    let count = u32::try_from(input.len())
        .map_err(|_| invalid(format!("{} values are too many to probe", input.len())))?;
    let ub = ctx.uniform_buffer("ground probe params", &ContactParams { count, ..params });
    let inp = ctx.storage_buffer("ground probe in", input)?;
    let out = ctx.zeroed_buffer("ground probe out", 4 * words_out * input.len() as u64)?;
    let mut enc = ctx.device.create_command_encoder(&Default::default());
    record_pass(
        ctx,
        &mut enc,
        entry,
        &pipeline,
        &[(0, &ub), (7, &inp), (8, &out)],
        Dispatch::Threads(count),
        None,
    );
    submit(ctx, enc, None);
    let mut v: Vec<u32> = ctx.read_buffer(&out)?;
    v.truncate(words_out as usize * input.len());
    Ok(v)
}

/// The contact shader's f64-free `GroundGrid::bottom_units` (without its `f32::MAX` case:
/// `((m as f64) / unit).round() as i64` clamped to `0..=i32::MAX - 1`) for each of `metres`,
/// run on the GPU. For tests, which hold it to the CPU's f64 arithmetic.
#[doc(hidden)]
pub fn units_on_gpu(ctx: &GpuContext, unit: f64, metres: &[f32]) -> Result<Vec<i32>> {
    let (unit_lo, unit_hi, unit_exp) = unit_parts(unit)?;
    let params = ContactParams {
        unit_lo,
        unit_hi,
        unit_exp,
        ..bytemuck::Zeroable::zeroed()
    };
    let bits: Vec<u32> = metres.iter().map(|m| m.to_bits()).collect();
    let out = probe(ctx, "probe_units", params, &bits, 1)?;
    Ok(out.into_iter().map(|u| u as i32).collect())
}

/// The contact shader's f64-free carry, `(alpha as f64 * removed as f64).round() as u64`, for
/// each of `removed`, run on the GPU. For tests.
#[doc(hidden)]
pub fn carry_on_gpu(ctx: &GpuContext, alpha: f32, removed: &[u32]) -> Result<Vec<u64>> {
    let params = ContactParams {
        alpha,
        ..bytemuck::Zeroable::zeroed()
    };
    let out = probe(ctx, "probe_carry", params, removed, 2)?;
    Ok(out
        .chunks_exact(2)
        .map(|w| w[0] as u64 | (w[1] as u64) << 32)
        .collect())
}
