//! The ground simulator on the CPU, [`GroundSim`]: the reference path.
//!
//! Heights are `i32` multiples of `height_unit` in one flat array (x fastest), kept across
//! frames so tracks accumulate. Every pass is integer arithmetic in which a cell's new value
//! depends only on values read before the pass writes (each pass reads a snapshot and writes
//! after, or touches disjoint pairs), so the result does not depend on the order cells are
//! visited in, nor on the number of threads: the GPU port runs the same passes as dispatches.

use super::contact::{self, Bottoms, GroundGrid, NO_OBJECT, Window};
use super::contour::{ContourMaps, Levels, UNLABELLED, l1_distance, neighbours};
use super::metrics::GroundFrameMetrics;
use super::params::{GroundParams, Initial, MaterialValues, Relaxation, invalid};
use glam::UVec2;
use imprint_core::error::check_alloc;
use imprint_core::{Error, HeightField, Mesh, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// A threshold no height difference reaches: θ = 90°, no slump.
const NO_SLUMP: i64 = i64::MAX / 4;

/// The ground: its heights and everything a frame needs to move them. Serde writes all of it
/// (a checkpoint: loaded, it steps on to the same bytes as a sim that never stopped).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GroundSim {
    grid: GroundGrid,
    material: MaterialValues,
    relaxation: Relaxation,
    band: u32,
    max_relax_iterations: u32,
    /// T: the largest difference between 4-neighbours the slump leaves, units
    /// (⌊tan θ · cell / unit⌋), or [`NO_SLUMP`].
    threshold: i64,
    heights: Vec<i32>,
    frame: u32,
    /// The last frame's contour maps, when it had contact.
    maps: Option<ContourMaps>,
    /// `Full` and `Settle`: cells under an object this frame, which the relaxation leaves
    /// alone.
    held: Vec<bool>,
    /// `Settle`: cells to start the next frame's work list from (the last frame's contact
    /// cells, which it released, and the cells `add_heights` changed), ascending.
    #[serde(default)]
    pending: Vec<u32>,
    /// [`GroundSim::add_heights`]: the fraction of a unit each cell is owed (allocated on
    /// first use).
    residual: Vec<f64>,
    /// `Settle`: the work list's buffers, kept from frame to frame (not state).
    #[serde(skip)]
    scratch: super::settle::Scratch,
}

impl GroundSim {
    /// A ground as `params` state it; an `Initial::Image` path is relative to `base_dir`
    /// (the pipeline file's folder).
    pub fn new(params: &GroundParams, base_dir: &Path) -> Result<Self> {
        params.validate()?;
        let dims = UVec2::new(params.resolution[0], params.resolution[1]);
        let n = dims.x as u64 * dims.y as u64;
        check_alloc(&format!("a {} x {} ground", dims.x, dims.y), n * 16)?;
        let unit = params.height_unit;
        let heights = match &params.initial {
            Initial::Flat(h) => {
                params.check_height_range(*h as f64)?;
                vec![(*h as f64 / unit).round() as i32; n as usize]
            }
            Initial::Image { path, scale, base } => {
                let path = base_dir.join(path);
                let v = load_heightmap(&path, dims)?;
                params.check_height_range(*base as f64 + *scale as f64)?;
                v.iter()
                    .map(|&v| ((*base as f64 + *scale as f64 * v) / unit).round() as i32)
                    .collect()
            }
        };
        Self::from_units(params, heights)
    }

    /// A ground with the given heights in units (x fastest), for tests and for moving a
    /// ground between paths; `params.initial` is ignored.
    pub fn from_units(params: &GroundParams, heights: Vec<i32>) -> Result<Self> {
        params.validate()?;
        let dims = UVec2::new(params.resolution[0], params.resolution[1]);
        let grid = GroundGrid {
            origin: params.origin(),
            cell: params.cell(),
            dims,
            unit: params.height_unit,
        };
        if heights.len() != grid.len() {
            return Err(invalid(format!(
                "{} heights for a {} x {} field",
                heights.len(),
                dims.x,
                dims.y
            )));
        }
        if let Some(j) = heights.iter().position(|&h| h < 0) {
            return Err(invalid(format!(
                "height {} at cell ({}, {}) is below the base plane",
                heights[j],
                j % dims.x as usize,
                j / dims.x as usize
            )));
        }
        let max = heights.iter().copied().max().unwrap_or(0);
        params.check_height_range(max as f64 * params.height_unit)?;
        let material = params.material.values();
        let threshold = if material.repose_degrees >= 90.0 {
            NO_SLUMP
        } else {
            let t =
                (material.repose_degrees as f64).to_radians().tan() * grid.cell as f64 / grid.unit;
            t.floor().min(NO_SLUMP as f64) as i64
        };
        let held = match params.relaxation {
            Relaxation::Full | Relaxation::Settle => vec![false; grid.len()],
            Relaxation::Labelled => Vec::new(),
        };
        Ok(GroundSim {
            grid,
            material,
            relaxation: params.relaxation,
            band: params.slump_band,
            max_relax_iterations: params.max_relax_iterations,
            threshold,
            heights,
            frame: 0,
            maps: None,
            held,
            pending: Vec::new(),
            residual: Vec::new(),
            scratch: Default::default(),
        })
    }

    /// One frame: contact with `objects`, compression and displacement, then the slump.
    /// On an error (`Full` or `Settle` relaxation not at rest within `max_relax_iterations`)
    /// the ground is left as it was at the frame's start.
    pub fn step(&mut self, objects: &[&Mesh]) -> Result<GroundFrameMetrics> {
        self.step_with(objects, imprint_core::raster::rasterize_depth_with)
    }

    /// [`GroundSim::step`] with the contact view from any rasteriser with the signature of
    /// `imprint_core::raster::rasterize_depth_with` (the GPU one is a closure over its context).
    pub fn step_with(
        &mut self,
        objects: &[&Mesh],
        rasterize: impl FnMut(
            &Mesh,
            &imprint_core::camera::Camera,
            u32,
            u32,
            &imprint_core::raster::RasterOptions,
        ) -> Result<imprint_core::raster::DepthMap>,
    ) -> Result<GroundFrameMetrics> {
        let mut m = GroundFrameMetrics {
            frame: self.frame,
            ..Default::default()
        };
        self.maps = None;
        let start = (self.relaxation != Relaxation::Labelled).then(|| self.heights.clone());
        if let Some(b) =
            contact::object_bottoms_with(objects, &self.grid, &self.heights, rasterize)?
        {
            self.press(&b, &mut m);
        }
        let relaxed = match self.relaxation {
            Relaxation::Full => self.relax_full(&mut m),
            Relaxation::Settle => {
                let tops = super::settle::Tops::of(objects, &self.grid);
                let before = start.as_deref().expect("kept in Settle mode");
                self.settle(before, &tops, &mut m)
            }
            Relaxation::Labelled => Ok(()),
        };
        if let Err(e) = relaxed {
            self.heights = start.expect("kept but in Labelled mode");
            self.hold_contact(false);
            return Err(e);
        }
        if self.relaxation == Relaxation::Settle {
            self.pending = self.contact_cells();
        }
        m.mass_units = self.mass();
        m.mass_volume = m.mass_units as f64 * self.grid.unit_volume();
        if self.relaxation != Relaxation::Settle {
            m.max_slope = self.max_slope();
        }
        self.hold_contact(false);
        self.frame += 1;
        Ok(m)
    }

    /// Adds material: `rise[j]` metres on cell j (x fastest; negative takes away, never
    /// below the base plane). Fractions of a unit are carried per cell to the next call, so
    /// a slow accumulation (fresh snow a few µm a frame) is not rounded away.
    pub fn add_heights(&mut self, rise: &[f32]) -> Result<()> {
        if rise.len() != self.heights.len() {
            return Err(invalid(format!(
                "{} height changes for a {} x {} field",
                rise.len(),
                self.grid.dims.x,
                self.grid.dims.y
            )));
        }
        if let Some(j) = rise.iter().position(|r| !r.is_finite()) {
            let nx = self.grid.dims.x as usize;
            return Err(invalid(format!(
                "height change {} at cell ({}, {}) is not finite",
                rise[j],
                j % nx,
                j / nx
            )));
        }
        if self.residual.is_empty() {
            self.residual = vec![0.0; self.heights.len()];
        }
        let unit = self.grid.unit;
        let top = i32::MAX as i64;
        let before = (self.relaxation == Relaxation::Settle).then(|| self.heights.clone());
        (&mut self.heights, &mut self.residual, rise)
            .into_par_iter()
            .for_each(|(h, res, &r)| {
                let want = r as f64 / unit + *res;
                let add = want.round();
                *res = want - add;
                *h = (*h as i64 + add as i64).clamp(0, top) as i32;
            });
        if let Some(before) = before {
            // The next frame's settle starts from what changed here too.
            let changed = (before.iter().zip(&self.heights).enumerate())
                .filter(|(_, (b, h))| b != h)
                .map(|(j, _)| j as u32);
            self.pending.extend(changed);
            self.pending.sort_unstable();
            self.pending.dedup();
        }
        Ok(())
    }

    /// Σ heights, units: exact, and constant from frame to frame while α = 1.
    pub fn mass(&self) -> i64 {
        self.heights.par_iter().map(|&h| h as i64).sum()
    }

    /// The heights in units, x fastest.
    pub fn heights_units(&self) -> &[i32] {
        &self.heights
    }

    /// The first cell (x fastest) whose height is below `lowest` or above `highest` (metres,
    /// each rounded to the nearest height unit), with its height in metres; `None` when
    /// every cell is within. For a frame's self-check: `lowest` the base plane (0) and
    /// `highest` the highest start height plus the tallest body's height, which `Settle`
    /// keeps (material above a body spills over it; see the `settle` module).
    pub fn height_bounds_violation(&self, lowest: f32, highest: f32) -> Option<(usize, f32)> {
        height_bounds_violation(&self.heights, &self.grid, lowest, highest)
    }

    /// The cells, their place in the world and the height unit.
    pub fn grid(&self) -> &GroundGrid {
        &self.grid
    }

    /// The slump's threshold T in units (`None`: θ = 90°, no slump).
    pub fn threshold_units(&self) -> Option<i64> {
        (self.threshold < NO_SLUMP).then_some(self.threshold)
    }

    /// The material's values (for the GPU path).
    pub(crate) fn material(&self) -> MaterialValues {
        self.material
    }

    /// The slump's mode (for the GPU path).
    pub(crate) fn relaxation(&self) -> Relaxation {
        self.relaxation
    }

    /// `max_relax_iterations` (for the GPU path).
    pub(crate) fn max_relax_iterations(&self) -> u32 {
        self.max_relax_iterations
    }

    /// `Settle`: the cells the next frame's work list starts from (for the GPU path).
    pub(crate) fn pending(&self) -> &[u32] {
        &self.pending
    }

    /// The outer contour map's width in rings (for the GPU path).
    pub(crate) fn band(&self) -> u32 {
        self.band
    }

    /// Sets the frame count (a ground moved back from the GPU path).
    pub(crate) fn set_frame(&mut self, frame: u32) {
        self.frame = frame;
    }

    /// Frames stepped so far.
    pub fn frame(&self) -> u32 {
        self.frame
    }

    /// The contour maps of the last frame, when it had contact.
    pub fn maps(&self) -> Option<&ContourMaps> {
        self.maps.as_ref()
    }

    /// The heights in metres as a `HeightField`, for writers and renderers.
    pub fn to_height_field(&self) -> HeightField {
        self.grid.height_field(&self.heights)
    }

    /// O §2.1-2.5 for one contact: finds the contact cells, builds both contour maps over
    /// the contact's window, presses and displaces, then (`Labelled`) slumps.
    fn press(&mut self, b: &Bottoms, m: &mut GroundFrameMetrics) {
        let nx = self.grid.dims.x;
        let Some((win, bottom)) = work_window(b, &self.heights, self.grid.dims, self.band) else {
            return;
        };
        let (w, h) = (win.w as usize, win.h as usize);
        let contact: Vec<bool> = (0..win.len())
            .map(|j| bottom[j] < self.heights[win.global((j % w) as u32, (j / w) as u32, nx)])
            .collect();
        let mut inner = Vec::new();
        l1_distance(w, h, |j| !contact[j], &mut inner);
        let mut outer = Vec::new();
        l1_distance(w, h, |j| contact[j], &mut outer);
        for (d, &c) in outer.iter_mut().zip(&contact) {
            *d = if c || *d > self.band {
                UNLABELLED
            } else {
                *d - 1
            };
        }
        let maps = ContourMaps {
            window: win,
            contact,
            inner,
            outer,
        };
        m.contact_cells = maps.contact.iter().filter(|&&c| c).count() as u32;
        m.labelled_cells = maps.outer.iter().filter(|&&d| d != UNLABELLED).count() as u32;
        self.displace(&maps, &bottom, m);
        if self.relaxation == Relaxation::Labelled {
            self.slump_labelled(&maps, m);
        }
        self.maps = Some(maps);
        self.hold_contact(true);
    }

    /// O §2.3: every contact cell drops to the object's bottom; α of what it lost is pushed
    /// outward, level by level from the deepest contour value, each cell sharing what it
    /// holds (its own plus what it was given) equally among its neighbours one level lower,
    /// until level 1 hands it to the rim outside the contact.
    ///
    /// Equal shares are exact: a cell holding `c` units with `n` lower neighbours gives each
    /// ⌊c / n⌋, and the remainder `c mod n` one unit each to the first neighbours in the
    /// order −x, +x, −z, +z rotated by (i + k) mod n (so no direction is favoured). Nothing is
    /// rounded away, so with α = 1 mass is conserved exactly. Within a level, cells only give
    /// and the next level only receives, and integer sums do not depend on their order: the
    /// GPU runs a level as one dispatch with atomic adds and gets the same integers.
    fn displace(&mut self, maps: &ContourMaps, bottom: &[i32], m: &mut GroundFrameMetrics) {
        let nx = self.grid.dims.x;
        let win = maps.window;
        let (w, h) = (win.w as usize, win.h as usize);
        let alpha = self.material.displace_ratio as f64;
        let global = |j: usize| win.global((j % w) as u32, (j / w) as u32, nx);
        // Units each cell holds to pass on; on rim cells (level 0), what they receive.
        let mut carry = vec![0i64; win.len()];
        let mut max_level = 0;
        for j in (0..win.len()).filter(|&j| maps.contact[j]) {
            let g = global(j);
            let removed = self.heights[g] as i64 - bottom[j] as i64;
            m.removed_units += removed;
            carry[j] = (alpha * removed as f64).round() as i64;
            self.heights[g] = bottom[j];
            if maps.inner[j] != UNLABELLED {
                max_level = max_level.max(maps.inner[j]);
            }
        }
        m.max_contour = max_level;
        let levels = Levels::build(&maps.inner, 1, max_level);
        for l in (1..=max_level).rev() {
            for &j in levels.level(l) {
                let j = j as usize;
                let c = std::mem::take(&mut carry[j]);
                let mut lower = [0usize; 4];
                let mut n = 0;
                for nb in neighbours(j, w, h).into_iter().flatten() {
                    if maps.inner[nb] == l - 1 {
                        lower[n] = nb;
                        n += 1;
                    }
                }
                // Exact L1 levels: a cell at level l always has a neighbour at l - 1.
                debug_assert!(n > 0, "contour level {l} without a lower neighbour");
                let (q, r) = (c / n as i64, (c % n as i64) as usize);
                let first = (win.i0 as usize + j % w + win.k0 as usize + j / w) % n;
                for (t, &nb) in lower[..n].iter().enumerate() {
                    let extra = ((t + n - first) % n < r) as i64;
                    carry[nb] += q + extra;
                }
            }
        }
        for j in (0..win.len()).filter(|&j| !maps.contact[j] && carry[j] != 0) {
            let g = global(j);
            // Rims stay below the highest initial height plus the pressed-out volume; the
            // headroom `check_height_range` keeps covers any plausible print.
            self.heights[g] = (self.heights[g] as i64 + carry[j]).min(i32::MAX as i64) as i32;
            m.displaced_units += carry[j];
        }
        m.removed_volume = m.removed_units as f64 * self.grid.unit_volume();
        m.displaced_volume = m.displaced_units as f64 * self.grid.unit_volume();
    }

    /// O §2.5: up to En passes; each goes ring by ring from the rim outward (O's order), and
    /// step k relaxes the edges of ring k: between two ring-k cells, and between ring k and
    /// ring k + 1. Where a difference d exceeds T, ⌊(|d| − T) / (s_a + s_b)⌋ units flow
    /// downhill, with s the steep edges each end has in this step. Counts and flows are read
    /// from the heights before the step's flows are applied, so the step is order-free; a
    /// lone steep edge meets exactly at slope T, and in general no flow overshoots: Σh²
    /// strictly drops with every step that moves anything (Cauchy–Schwarz on the shares).
    ///
    /// O moves material only outward (ring k to k + 1). We also let it run along a ring and
    /// back inward where that is downhill: the displacement funnels material along the axes
    /// of the L1 map into a few rim cells, and outward-only slumping leaves those spikes (and
    /// inward-facing walls, e.g. of an older track) standing. A pass that moves nothing ends
    /// the slump early (the rest would not move anything either).
    fn slump_labelled(&mut self, maps: &ContourMaps, m: &mut GroundFrameMetrics) {
        let t = self.threshold;
        if self.material.slump_iterations == 0 || t >= NO_SLUMP {
            return;
        }
        let nx = self.grid.dims.x;
        let win = maps.window;
        let (w, h) = (win.w as usize, win.h as usize);
        let global = |j: usize| win.global((j % w) as u32, (j / w) as u32, nx);
        let levels = Levels::build(&maps.outer, 0, self.band - 1);
        // The edges of each step, fixed for the frame: from every ring-k cell to its ring
        // k + 1 neighbours, and to its ring-k neighbours once per pair.
        let mut edges: Vec<(u32, u32)> = Vec::new();
        let mut edge_start = vec![0usize];
        for k in 0..self.band {
            for &c in levels.level(k) {
                for n in neighbours(c as usize, w, h).into_iter().flatten() {
                    let l = maps.outer[n];
                    if l == k + 1 || (l == k && n > c as usize) {
                        edges.push((c, n as u32));
                    }
                }
            }
            edge_start.push(edges.len());
        }
        // The window's heights, copied in and back out: the passes touch them many times.
        let mut hl: Vec<i64> = (0..win.len())
            .map(|j| self.heights[global(j)] as i64)
            .collect();
        let mut steep = vec![0u8; win.len()];
        let mut delta = vec![0i64; win.len()];
        for _ in 0..self.material.slump_iterations {
            let mut moved = 0;
            for k in 0..self.band as usize {
                let ring = levels.level(k as u32);
                if ring.is_empty() {
                    break;
                }
                m.slump_visits += ring.len() as u64;
                let step = &edges[edge_start[k]..edge_start[k + 1]];
                for &(a, b) in step {
                    if (hl[a as usize] - hl[b as usize]).abs() > t {
                        steep[a as usize] += 1;
                        steep[b as usize] += 1;
                    }
                }
                for &(a, b) in step {
                    let (a, b) = (a as usize, b as usize);
                    let d = hl[a] - hl[b];
                    if d.abs() > t {
                        let f = d.signum() * ((d.abs() - t) / (steep[a] + steep[b]) as i64);
                        delta[a] -= f;
                        delta[b] += f;
                        moved += f.abs();
                    }
                }
                for &j in ring.iter().chain(levels.level(k as u32 + 1)) {
                    let j = j as usize;
                    hl[j] += delta[j];
                    delta[j] = 0;
                    steep[j] = 0;
                }
            }
            m.slump_iterations += 1;
            m.slumped_units += moved;
            if moved == 0 {
                break;
            }
        }
        for k in 0..self.band {
            for &j in levels.level(k) {
                self.heights[global(j as usize)] = hl[j as usize] as i32;
            }
        }
    }

    /// `Settle`: the work list from the cells the last frame released and the cells this
    /// frame's press changed (from `before`, the heights at the frame's start), to rest,
    /// material above the bodies' `tops` spilling over them (see [`super::settle`]).
    fn settle(
        &mut self,
        before: &[i32],
        tops: &super::settle::Tops,
        m: &mut GroundFrameMetrics,
    ) -> Result<()> {
        if self.threshold >= NO_SLUMP {
            return Ok(());
        }
        let changed = self.maps.as_ref().map_or_else(Vec::new, |maps| {
            super::settle::changed_cells(before, &self.heights, maps.window, self.grid.dims.x)
        });
        super::settle::settle_frame(
            &mut self.heights,
            &self.held,
            &self.grid,
            self.threshold,
            tops,
            &self.pending,
            &changed,
            self.max_relax_iterations,
            self.frame,
            &mut self.scratch,
            m,
        )
    }

    /// This frame's contact cells, ascending.
    fn contact_cells(&self) -> Vec<u32> {
        let Some(maps) = &self.maps else {
            return Vec::new();
        };
        let (win, w) = (maps.window, maps.window.w as usize);
        let nx = self.grid.dims.x;
        (maps.contact.iter().enumerate())
            .filter(|c| *c.1)
            .map(|(j, _)| win.global((j % w) as u32, (j / w) as u32, nx) as u32)
            .collect()
    }

    /// `Full`: the slope rule over the whole field, in every direction, until nothing moves.
    ///
    /// One iteration is four passes, each over a perfect matching of neighbour pairs (x
    /// pairs starting at even, then odd columns; z pairs starting at even, then odd rows), so
    /// every pass touches disjoint pairs and runs in parallel with no race. A pair whose
    /// difference d exceeds T exchanges ⌊(d − T) / 2⌋ units, which meets at slope T to within
    /// one unit and never reverses it, so Σh² drops with every exchange and the iteration
    /// ends. At rest, every difference is at most T + 1 unit. Cells under an object this
    /// frame are held (the object bears the walls); they slump once it has left. After the
    /// first iteration only the cells the last one changed, grown by one, are swept again:
    /// the same exchanges, fewer visits.
    fn relax_full(&mut self, m: &mut GroundFrameMetrics) -> Result<()> {
        let t = self.threshold;
        let dims = self.grid.dims;
        // θ = 90°: nothing can move.
        let mut region = (t < NO_SLUMP).then(|| Window::full(dims));
        let mut iterations = 0u32;
        let outcome = loop {
            let Some(r) = region else {
                break Ok(());
            };
            if iterations == self.max_relax_iterations {
                break Err(Error::Numerical {
                    node: "ground".into(),
                    frame: self.frame,
                    message: format!(
                        "full relaxation still moving after max_relax_iterations = {} \
                         iterations",
                        self.max_relax_iterations
                    ),
                    hint: "raise max_relax_iterations, or use relaxation: Labelled".into(),
                });
            }
            m.slump_visits += r.len() as u64;
            let mut changed = Changes::default();
            for (axis_z, parity) in [(false, 0), (false, 1), (true, 0), (true, 1)] {
                changed.merge(pair_pass(
                    &mut self.heights,
                    &self.held,
                    dims,
                    r,
                    axis_z,
                    parity,
                    t,
                ));
            }
            iterations += 1;
            m.slumped_units += changed.moved;
            region = changed.window().map(|c| c.grow(1, dims));
        };
        m.slump_iterations = iterations;
        outcome
    }

    /// Sets `held` (`Full` mode) to `value` on this frame's contact cells.
    fn hold_contact(&mut self, value: bool) {
        if let (Some(maps), false) = (&self.maps, self.held.is_empty()) {
            let (win, w) = (maps.window, maps.window.w as usize);
            for (j, _) in maps.contact.iter().enumerate().filter(|c| *c.1) {
                self.held[win.global((j % w) as u32, (j / w) as u32, self.grid.dims.x)] = value;
            }
        }
    }

    /// The steepest rise over run between 4-neighbours the slump is responsible for (see
    /// [`GroundFrameMetrics::max_slope`]).
    fn max_slope(&self) -> f32 {
        let nx = self.grid.dims.x as usize;
        let per_unit = (self.grid.unit / self.grid.cell as f64) as f32;
        let h = &self.heights;
        let diff = |a: usize, b: usize| (h[a] as i64 - h[b] as i64).unsigned_abs();
        let max = match self.relaxation {
            Relaxation::Full | Relaxation::Settle => {
                max_free_difference(h, &self.held, self.grid.dims)
            }
            Relaxation::Labelled => {
                let Some(maps) = &self.maps else {
                    return 0.0;
                };
                let win = maps.window;
                let (w, hh) = (win.w as usize, win.h as usize);
                let g = |j: usize| win.global((j % w) as u32, (j / w) as u32, nx as u32);
                let mut d = 0;
                for j in (0..win.len()).filter(|&j| maps.outer[j] != UNLABELLED) {
                    for n in neighbours(j, w, hh).into_iter().flatten() {
                        if n > j && maps.outer[n] != UNLABELLED {
                            d = d.max(diff(g(j), g(n)));
                        }
                    }
                }
                d
            }
        };
        max as f32 * per_unit
    }
}

/// The frame's work window (the contact's box grown by `band` + 1 cells, clipped to the
/// field) and the object bottoms over it ([`NO_OBJECT`] where none was rasterised); `None`
/// when no bottom is below the ground. Shared by the CPU and GPU paths.
pub(crate) fn work_window(
    b: &Bottoms,
    heights: &[i32],
    dims: UVec2,
    band: u32,
) -> Option<(Window, Vec<i32>)> {
    let nx = dims.x;
    let bw = b.window;
    let (mut lo, mut hi) = (UVec2::MAX, UVec2::ZERO);
    for y in 0..bw.h {
        for x in 0..bw.w {
            if b.bottom[(y * bw.w + x) as usize] < heights[bw.global(x, y, nx)] {
                lo = lo.min(UVec2::new(bw.i0 + x, bw.k0 + y));
                hi = hi.max(UVec2::new(bw.i0 + x, bw.k0 + y));
            }
        }
    }
    if lo.x > hi.x {
        return None;
    }
    // The outer map needs `band` rings; one more keeps the window's edge off them.
    let win = Window {
        i0: lo.x,
        k0: lo.y,
        w: hi.x - lo.x + 1,
        h: hi.y - lo.y + 1,
    }
    .grow(band + 1, dims);
    let w = win.w as usize;
    let bottom = (0..win.len())
        .map(|j| {
            let (i, k) = (win.i0 + (j % w) as u32, win.k0 + (j / w) as u32);
            let inside = i >= bw.i0 && i < bw.i0 + bw.w && k >= bw.k0 && k < bw.k0 + bw.h;
            if inside {
                b.bottom[((k - bw.k0) * bw.w + (i - bw.i0)) as usize]
            } else {
                NO_OBJECT
            }
        })
        .collect();
    Some((win, bottom))
}

/// [`GroundSim::height_bounds_violation`] over `heights` (units, x fastest).
pub(crate) fn height_bounds_violation(
    heights: &[i32],
    grid: &GroundGrid,
    lowest: f32,
    highest: f32,
) -> Option<(usize, f32)> {
    let (lo, hi) = (grid.to_units(lowest as f64), grid.to_units(highest as f64));
    let j = heights
        .iter()
        .position(|&h| (h as i64) < lo || h as i64 > hi)?;
    Some((j, grid.to_metres(heights[j] as i64) as f32))
}

/// The largest difference, units, between two 4-neighbours neither of which is held.
fn max_free_difference(heights: &[i32], held: &[bool], dims: UVec2) -> u64 {
    let nx = dims.x as usize;
    let free = |j: usize| !held[j];
    let diff = |a: usize, b: usize| (heights[a] as i64 - heights[b] as i64).unsigned_abs();
    (0..dims.y as usize)
        .into_par_iter()
        .map(|k| {
            let mut d = 0;
            for i in 0..nx {
                let j = k * nx + i;
                if !free(j) {
                    continue;
                }
                if i + 1 < nx && free(j + 1) {
                    d = d.max(diff(j, j + 1));
                }
                if j + nx < heights.len() && free(j + nx) {
                    d = d.max(diff(j, j + nx));
                }
            }
            d
        })
        .max()
        .unwrap_or(0)
}

/// What a relaxation pass moved, and the box of the cells it changed.
#[derive(Clone, Copy, Debug)]
struct Changes {
    moved: i64,
    lo: UVec2,
    hi: UVec2,
}

impl Default for Changes {
    fn default() -> Self {
        Changes {
            moved: 0,
            lo: UVec2::MAX,
            hi: UVec2::ZERO,
        }
    }
}

impl Changes {
    fn merge(&mut self, o: Changes) {
        self.moved += o.moved;
        self.lo = self.lo.min(o.lo);
        self.hi = self.hi.max(o.hi);
    }

    /// A flow `f` between cell `a` and cell `b` (b after a along x or z).
    fn touch(&mut self, a: UVec2, b: UVec2, f: i64) {
        if f != 0 {
            self.moved += f.abs();
            self.lo = self.lo.min(a);
            self.hi = self.hi.max(b + UVec2::ONE);
        }
    }

    /// The changed cells' box (pairs: both cells), `None` when nothing moved.
    fn window(&self) -> Option<Window> {
        (self.lo.x < self.hi.x).then(|| Window {
            i0: self.lo.x,
            k0: self.lo.y,
            w: self.hi.x - self.lo.x,
            h: self.hi.y - self.lo.y,
        })
    }
}

/// One neighbour pair toward slope T: moves ⌊(|d| − T) / 2⌋ units downhill, returns the
/// signed flow from `a` to `b`.
#[inline]
fn exchange(a: &mut i32, b: &mut i32, t: i64) -> i64 {
    let d = *a as i64 - *b as i64;
    let f = if d > t {
        (d - t) / 2
    } else if -d > t {
        -((-d - t) / 2)
    } else {
        0
    };
    *a = (*a as i64 - f) as i32;
    *b = (*b as i64 + f) as i32;
    f
}

/// One matching of `Full` relaxation over `region`: x pairs (i, i + 1) with i ≡ parity
/// (mod 2), or z pairs (k, k + 1) with k ≡ parity, both cells inside the region and free.
fn pair_pass(
    heights: &mut [i32],
    held: &[bool],
    dims: UVec2,
    r: Window,
    axis_z: bool,
    parity: u32,
    t: i64,
) -> Changes {
    let nx = dims.x as usize;
    let (i0, i1, k0, k1) = (r.i0, r.i0 + r.w, r.k0, r.k0 + r.h);
    let first = |lo: u32| lo + ((lo + parity) % 2);
    let merge = |mut a: Changes, b: Changes| {
        a.merge(b);
        a
    };
    if !axis_z {
        heights
            .par_chunks_mut(nx)
            .zip(held.par_chunks(nx))
            .enumerate()
            .skip(k0 as usize)
            .take(r.h as usize)
            .map(|(k, (row, hrow))| {
                let mut c = Changes::default();
                let mut i = first(i0);
                while i + 1 < i1 {
                    let iu = i as usize;
                    if !hrow[iu] && !hrow[iu + 1] {
                        let (a, b) = row.split_at_mut(iu + 1);
                        let f = exchange(&mut a[iu], &mut b[0], t);
                        let k = k as u32;
                        c.touch(UVec2::new(i, k), UVec2::new(i + 1, k), f);
                    }
                    i += 2;
                }
                c
            })
            .reduce(Changes::default, merge)
    } else {
        let off = parity as usize * nx;
        let kfirst = first(k0);
        heights[off..]
            .par_chunks_mut(2 * nx)
            .zip(held[off..].par_chunks(2 * nx))
            .enumerate()
            .map(|(p, (rows, hrows))| (parity + 2 * p as u32, rows, hrows))
            .filter(|(k, rows, _)| *k >= kfirst && k + 1 < k1 && rows.len() == 2 * nx)
            .map(|(k, rows, hrows)| {
                let mut c = Changes::default();
                let (top, bottom) = rows.split_at_mut(nx);
                for i in i0..i1 {
                    let iu = i as usize;
                    if !hrows[iu] && !hrows[nx + iu] {
                        let f = exchange(&mut top[iu], &mut bottom[iu], t);
                        c.touch(UVec2::new(i, k), UVec2::new(i, k + 1), f);
                    }
                }
                c
            })
            .reduce(Changes::default, merge)
    }
}

/// A grayscale PNG (8- or 16-bit, alpha ignored) as values in [0, 1], x fastest; its size
/// must be the field's resolution.
fn load_heightmap(path: &Path, dims: UVec2) -> Result<Vec<f64>> {
    let img =
        image::open(path).map_err(|e| invalid(format!("initial.path {}: {e}", path.display())))?;
    use image::ColorType as C;
    if !matches!(img.color(), C::L8 | C::La8 | C::L16 | C::La16) {
        return Err(invalid(format!(
            "initial.path {}: a heightmap must be 8- or 16-bit grayscale, this one is {:?}",
            path.display(),
            img.color()
        )));
    }
    if (img.width(), img.height()) != (dims.x, dims.y) {
        return Err(invalid(format!(
            "initial.path {}: the image is {} x {} pixels but resolution is {} x {}; one \
             pixel per cell",
            path.display(),
            img.width(),
            img.height(),
            dims.x,
            dims.y
        )));
    }
    Ok(img
        .to_luma16()
        .as_raw()
        .iter()
        .map(|&v| v as f64 / 65535.0)
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground::params::{Material, Preset};

    fn params(initial: Initial) -> GroundParams {
        let mut p = GroundParams::new([0.04, 0.03], [4, 3], Material::Preset(Preset::Snow));
        p.initial = initial;
        p
    }

    /// 16- and 8-bit grayscale PNGs give `base + scale * value / max` per cell, pixel
    /// (i, j) on cell (i, k = j); a wrong size or a colour image is an error naming
    /// `initial.path` and the file.
    #[test]
    fn heightmaps_load_one_pixel_per_cell() {
        let dir = std::env::temp_dir().join(format!("imprint-ground-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let wide =
            image::ImageBuffer::from_fn(4, 3, |i, j| image::Luma([(i + 4 * j) as u16 * 5000]));
        wide.save(dir.join("h16.png")).unwrap();
        let narrow = image::ImageBuffer::from_fn(4, 3, |i, j| {
            image::Luma([if (i, j) == (3, 2) { 255u8 } else { 0 }])
        });
        narrow.save(dir.join("h8.png")).unwrap();
        let image = |name: &str| Initial::Image {
            path: name.into(),
            scale: 0.655_35,
            base: 0.01,
        };
        let g = GroundSim::new(&params(image("h16.png")), &dir).unwrap();
        // 0.01 m + 0.65535 m * v / 65535 = 1000 + v units.
        let want: Vec<i32> = (0..12).map(|j| 1000 + 5000 * j).collect();
        assert_eq!(g.heights_units(), &want[..]);
        let g = GroundSim::new(&params(image("h8.png")), &dir).unwrap();
        assert_eq!(g.heights_units()[11], 1000 + 65535);
        assert_eq!(g.heights_units()[10], 1000);

        let e = GroundSim::new(&params(image("h16.png")), &dir.join("nowhere"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("initial.path") && e.contains("h16.png"), "{e}");
        let mut p = params(image("h16.png"));
        p.resolution = [8, 6];
        p.size = [0.08, 0.06];
        let e = GroundSim::new(&p, &dir).unwrap_err().to_string();
        assert!(e.contains("4 x 3 pixels") && e.contains("8 x 6"), "{e}");
        let rgb = image::RgbImage::new(4, 3);
        rgb.save(dir.join("rgb.png")).unwrap();
        let e = GroundSim::new(&params(image("rgb.png")), &dir)
            .unwrap_err()
            .to_string();
        assert!(e.contains("grayscale") && e.contains("rgb.png"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// 3 µm a frame (0.3 units) adds up to the right height over 100 frames, not to 0.
    #[test]
    fn added_heights_carry_their_fractions() {
        let mut g = GroundSim::new(&params(Initial::Flat(0.1)), Path::new(".")).unwrap();
        for _ in 0..100 {
            g.add_heights(&[3e-6; 12]).unwrap();
        }
        assert!(g.heights_units().iter().all(|&h| (h - 10_030).abs() <= 1));
        g.add_heights(&[-1.0; 12]).unwrap();
        assert!(
            g.heights_units().iter().all(|&h| h == 0),
            "the base plane holds"
        );
        let e = g.add_heights(&[0.0; 5]).unwrap_err().to_string();
        assert!(e.contains("5 height changes"), "{e}");
        let mut bad = [0.0; 12];
        bad[7] = f32::NAN;
        let e = g.add_heights(&bad).unwrap_err().to_string();
        assert!(e.contains("(3, 1)"), "{e}");
    }

    #[test]
    fn bad_heights_are_refused() {
        let p = params(Initial::Flat(0.1));
        let e = GroundSim::from_units(&p, vec![0; 5])
            .unwrap_err()
            .to_string();
        assert!(e.contains("5 heights"), "{e}");
        let mut h = vec![0; 12];
        h[5] = -1;
        let e = GroundSim::from_units(&p, h).unwrap_err().to_string();
        assert!(e.contains("(1, 1)") && e.contains("base plane"), "{e}");
    }
}
