//! `Relaxation::Settle`: the ground comes to rest wherever it changed, by a work list.
//!
//! A FIFO work list starts from the cells a frame may have left too steep (see
//! [`settle_frame`]: the cells the press changed, those the last frame's contact released,
//! and their neighbours). A cell taken from it, unless held (in contact this frame: the body
//! bears it), does two things.
//!
//! 1. **Slide.** While a free 4-neighbour is more than T + 1 unit lower, material slides
//!    from the cell down a path: the steepest free neighbour, then from there the lowest free
//!    neighbour not yet on the path (straight on where several are lowest), as long as the
//!    path can take material. The path is levelled in one move to a ramp of slope T from the
//!    top (`Ground::slide`): the cell drops to L, the k-th cell of the path rises to L − kT
//!    (the remainder of the integer division one unit each to the top cells, so consecutive
//!    differences are T or T + 1), L chosen so that mass is exact and every cell of the path
//!    rises. A path of one cell is the pair rule ⌊(d − T) / 2⌋ units. The long path is what
//!    makes the cost follow the cells that move: a heap that has to travel n cells goes in
//!    one move along n cells rather than as a diffusion of half-excesses between pairs (about
//!    n³ visits for a heap n cells long: the dragged box of BENCHMARKS §8 took 0.78 M visits
//!    a frame that way, 32 k with paths).
//! 2. **Spill.** A cell next to a held cell leans on a body; the body's top there is the
//!    highest top of the bodies whose bounds are over the held cell ([`Tops`]; the lowest
//!    such top over its held neighbours is its *cap*). Its slides build their ramp from at
//!    most the cap, and what is still above the cap afterwards runs over the body: along the
//!    row or column through the held neighbour, past the body's held cells and the rest of
//!    its extent, then down the far side onto the first free cells below the cap (each filled
//!    at most to it; another body or the field's edge ends the line). Why: a heightfield
//!    cannot keep material on a body, and the body does not feel the ground (one-way), so
//!    material pushed up against a body higher than the body itself can only fall over it to
//!    the other side, where a real heap would overflow it; without this, the heap a dragged
//!    box pushes grows without bound against its held face (0.38 m against a 0.27 m bound in
//!    `tests/ground_settle.rs`). Sliding first keeps what can rest on its own side there
//!    (a print's rim stays a rim), so only a heap that reaches the top spills. A cell next
//!    to a body gives by slides only below its cap and spills the rest, so no cell ends above
//!    the highest body top unless it was there before or neither side of the body had room
//!    (a buried body): with bodies pressed into the ground, no cell above the highest start
//!    height plus the body's height ([`super::GroundSim::height_bounds_violation`] checks).
//!
//! The path's cells and the landing cells go on the list (they rose, so they may now be too
//! steep toward their other neighbours), and so do the free neighbours the cell's fall left
//! more than T + 1 above it. Every move takes material from a cell to cells that end no
//! higher than it, which lowers Σh², so the list empties; when it does, no free pair differs
//! by more than T + 1 unit wherever the work reached (every pair a change could have made
//! steep has its higher cell on the list until it is settled). One thread, one fixed order:
//! the same input gives the same integers whatever the thread count, and the GPU ground calls
//! the same function on the heights it reads back.

use super::contact::{GroundGrid, Window};
use glam::UVec2;
use imprint_core::Mesh;
use std::collections::VecDeque;

/// The longest path one slide levels (cells). Paths are about (height over T) cells long;
/// the cap only matters for a very small T, where it splits a long slide into several.
const MAX_PATH: usize = 1024;

/// What one settle did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Settled {
    /// Cells taken from the work list.
    pub pops: u64,
    /// Units moved (slides and spills).
    pub moved: i64,
    /// The largest difference, units, between a cell the work list took and a free
    /// 4-neighbour, after the settle.
    pub max_difference: u64,
}

/// The work list's bound was hit after `pops` visits (see [`settle`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TooMuchWork {
    pub pops: u64,
}

/// The tops of the frame's bodies, units: each body's window of cells (as
/// [`GroundGrid::window_under`] gives it) and the top of its bounds. The top over a cell is
/// the highest top of the bodies whose window holds it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Tops {
    parts: Vec<(Window, i32)>,
    /// The lowest of the tops (`i32::MAX` without bodies): nothing at or below it spills.
    lowest: i32,
}

impl Default for Tops {
    fn default() -> Self {
        Tops {
            parts: Vec::new(),
            lowest: i32::MAX,
        }
    }
}

impl Tops {
    /// The tops of `objects` over `grid` (empty meshes and meshes off the field left out).
    pub(crate) fn of(objects: &[&Mesh], grid: &GroundGrid) -> Self {
        let parts = objects
            .iter()
            .filter_map(|m| {
                let b = m.bounds();
                if b.is_empty() {
                    return None;
                }
                let w = grid.window_under(&b)?;
                let top = grid.to_units(b.max.y as f64).clamp(0, i32::MAX as i64) as i32;
                Some((w, top))
            })
            .collect::<Vec<_>>();
        let lowest = parts.iter().map(|p| p.1).min().unwrap_or(i32::MAX);
        Tops { parts, lowest }
    }

    /// The highest body top over cell `j` of a grid `nx` cells wide; `None` when no body's
    /// window holds it.
    fn at(&self, j: usize, nx: usize) -> Option<i32> {
        let (i, k) = ((j % nx) as u32, (j / nx) as u32);
        self.parts
            .iter()
            .filter(|(w, _)| i >= w.i0 && i - w.i0 < w.w && k >= w.k0 && k - w.k0 < w.h)
            .map(|p| p.1)
            .max()
    }

    /// Whether cell (i, k) is under a body's window.
    fn covers(&self, i: i64, k: i64) -> bool {
        self.parts.iter().any(|(w, _)| {
            i >= w.i0 as i64
                && i < (w.i0 + w.w) as i64
                && k >= w.k0 as i64
                && k < (w.k0 + w.h) as i64
        })
    }
}

/// The work list's buffers, kept between frames (sized to the field on first use).
#[derive(Clone, Debug, Default)]
pub(crate) struct Scratch {
    /// On the list now.
    queued: Vec<bool>,
    /// Taken from the list this settle (for the largest difference).
    seen: Vec<bool>,
    seen_list: Vec<u32>,
    /// Path membership: the path's stamp.
    mark: Vec<u32>,
    stamp: u32,
    list: VecDeque<u32>,
    path: Vec<u32>,
    /// The grid the buffers are sized for, and per cell which of its 4-neighbours exist
    /// (bits −x, +x, −z, +z: no division by the row length on the hot path).
    dims: UVec2,
    sides: Vec<u8>,
}

impl Scratch {
    fn fit(&mut self, dims: UVec2) {
        if self.dims != dims || self.queued.len() != dims.x as usize * dims.y as usize {
            let (nx, nz) = (dims.x as usize, dims.y as usize);
            let n = nx * nz;
            self.queued = vec![false; n];
            self.seen = vec![false; n];
            self.mark = vec![0; n];
            self.stamp = 0;
            self.sides = (0..n)
                .map(|c| {
                    let (i, k) = (c % nx, c / nx);
                    (i > 0) as u8
                        | ((i + 1 < nx) as u8) << 1
                        | ((k > 0) as u8) << 2
                        | ((k + 1 < nz) as u8) << 3
                })
                .collect();
            self.dims = dims;
        }
        self.list.clear();
        self.seen_list.clear();
    }
}

/// Calls `f` on the 4-neighbours of cell `c` in the order −x, +x, −z, +z, from its `sides`
/// bits.
#[inline(always)]
fn each_neighbour(c: usize, sides: u8, nx: usize, mut f: impl FnMut(usize)) {
    if sides & 1 != 0 {
        f(c - 1);
    }
    if sides & 2 != 0 {
        f(c + 1);
    }
    if sides & 4 != 0 {
        f(c - nx);
    }
    if sides & 8 != 0 {
        f(c + nx);
    }
}

/// The grid and the rules of one settle.
struct Ground<'a> {
    heights: &'a mut [i32],
    held: &'a [bool],
    sides: &'a [u8],
    dims: UVec2,
    t: i64,
    tops: &'a Tops,
}

impl Ground<'_> {
    #[inline(always)]
    fn each_neighbour(&self, c: usize, f: impl FnMut(usize)) {
        each_neighbour(c, self.sides[c], self.dims.x as usize, f);
    }

    /// The lowest top of the bodies over the held neighbours of `c` (what material on `c`
    /// spills over first); `None` when no neighbour is held.
    fn cap(&self, c: usize) -> Option<i64> {
        let nx = self.dims.x as usize;
        let mut cap = None;
        self.each_neighbour(c, |n| {
            if self.held[n] {
                let t = self.tops.at(n, nx).map_or(i64::MAX, |t| t as i64);
                cap = Some(cap.map_or(t, |m: i64| m.min(t)));
            }
        });
        cap
    }

    /// Step 2 of the module doc: what `c` holds above `cap` goes over the body next to it
    /// (through each held neighbour in turn, −x, +x, −z, +z) to the first free cells below
    /// the cap beyond it; landing cells go on the list. Units moved.
    fn spill(&mut self, c: usize, cap: i64, mut push: impl FnMut(usize)) -> i64 {
        let mut excess = self.heights[c] as i64 - cap;
        if excess <= 0 {
            return 0;
        }
        let (nx, nz) = (self.dims.x as i64, self.dims.y as i64);
        let (i, k) = ((c as i64) % nx, (c as i64) / nx);
        let mut moved = 0;
        for (di, dk) in [(-1, 0), (1, 0), (0, -1), (0, 1)] {
            let (mut a, mut b) = (i + di, k + dk);
            let inside = |a: i64, b: i64| a >= 0 && a < nx && b >= 0 && b < nz;
            if !inside(a, b) || !self.held[(b * nx + a) as usize] {
                continue;
            }
            // Over the body: past its held cells and the rest of its extent (the cells behind
            // a face it has pressed are under it even where it only rests on them).
            while inside(a, b) && (self.held[(b * nx + a) as usize] || self.tops.covers(a, b)) {
                a += di;
                b += dk;
            }
            // Down the far side: the first free cells below the cap take it (another body or
            // the field's edge ends the line).
            while excess > 0 && inside(a, b) && !self.held[(b * nx + a) as usize] {
                let land = (b * nx + a) as usize;
                let room = self.cap(land).unwrap_or(i64::MAX).min(cap) - self.heights[land] as i64;
                let f = excess.min(room);
                if f > 0 {
                    self.heights[c] -= f as i32;
                    self.heights[land] += f as i32;
                    excess -= f;
                    moved += f;
                    push(land);
                }
                a += di;
                b += dk;
            }
            if excess == 0 {
                break;
            }
        }
        moved
    }

    /// The steepest free neighbour of `c` more than T + 1 below it.
    fn steepest(&self, c: usize) -> Option<usize> {
        let hc = self.heights[c] as i64;
        let mut best = None;
        let mut best_d = self.t + 1;
        self.each_neighbour(c, |n| {
            let d = hc - self.heights[n] as i64;
            if d > best_d && !self.held[n] {
                best = Some(n);
                best_d = d;
            }
        });
        best
    }

    /// Step 1 of the module doc: the path from `c` down through `n` (its steepest neighbour,
    /// more than T + 1 below it) levelled to a ramp of slope T, its top at most `cap` (the
    /// body top `c` leans on, else `i64::MAX`): below the top a ramp, what the path cannot
    /// take stays on `c` to spill. The path's cells are left in `path` (`c` first). Units
    /// moved (0 when `n` cannot rise under the capped ramp).
    fn slide(
        &mut self,
        c: usize,
        n: usize,
        cap: i64,
        path: &mut Vec<u32>,
        mark: &mut [u32],
        stamp: u32,
    ) -> i64 {
        let t = self.t;
        let nx = self.dims.x as usize;
        let (held, sides) = (self.held, self.sides);
        let h = &mut *self.heights;
        path.clear();
        path.push(c as u32);
        mark[c] = stamp;
        // Σ of the path's heights, and min over its cells k ≥ 1 of −kT − h_k (no cell falls
        // while the top's level plus it is ≥ 0).
        let mut sum = h[c] as i64;
        let mut slack = i64::MAX;
        let mut next = Some((n, h[n]));
        while let Some((x, hx)) = next {
            let k = path.len() as i64; // x's index on the path
            // With x the top's level is min(⌊total / (k + 1)⌋, cap); x must rise (level −
            // kT − h_x ≥ 1) and no cell fall (level + slack ≥ 0). ⌊a / m⌋ ≥ b ⟺ a ≥ b·m.
            let total = sum + hx as i64 + t * k * (k + 1) / 2;
            let s = -k * t - hx as i64;
            let need = (1 - s).max(slack.saturating_neg());
            if total < need * (k + 1) || cap < need {
                break;
            }
            path.push(x as u32);
            mark[x] = stamp;
            sum += hx as i64;
            slack = slack.min(s);
            if path.len() == MAX_PATH {
                break;
            }
            // The lowest free neighbour off the path; straight on wins a tie.
            let step = x as i64 - path[path.len() - 2] as i64;
            next = None;
            each_neighbour(x, sides[x], nx, |y| {
                if held[y] || mark[y] == stamp {
                    return;
                }
                let better = match next {
                    None => true,
                    Some((z, hz)) => {
                        h[y] < hz || (h[y] == hz && y as i64 - x as i64 == step && z != y)
                    }
                };
                if better {
                    next = Some((y, h[y]));
                }
            });
        }
        let k = path.len() as i64 - 1;
        if k == 0 {
            return 0;
        }
        let total = sum + t * k * (k + 1) / 2;
        let (l, r) = (total.div_euclid(k + 1), total.rem_euclid(k + 1));
        let before = h[c] as i64;
        if l <= cap {
            for (i, &p) in path.iter().enumerate() {
                let q = l - i as i64 * t + (r > i as i64) as i64;
                debug_assert!(
                    i == 0 || q >= h[p as usize] as i64,
                    "a path cell would fall"
                );
                h[p as usize] = q as i32;
            }
        } else {
            // The ramp from the cap; the rest stays on c (above the cap, to spill).
            let mut given = 0;
            for (i, &p) in path.iter().enumerate().skip(1) {
                let q = cap - i as i64 * t;
                debug_assert!(q >= h[p as usize] as i64, "a path cell would fall");
                given += q - h[p as usize] as i64;
                h[p as usize] = q as i32;
            }
            h[c] = (before - given) as i32;
            debug_assert!(h[c] as i64 >= cap);
        }
        debug_assert!((h[c] as i64) < before, "the slide moved nothing");
        before - h[c] as i64
    }
}

/// Settles `heights` (units, x fastest, a `dims` grid) to slope `t` units per cell (plus one
/// unit), starting from `seeds` and their 4-neighbours, in the seeds' order. Cells with
/// `held[j]` (under an object this frame) neither give nor receive; material next to them
/// above `tops` spills over them. Stops with `TooMuchWork` after `max_pops` visits; the
/// heights are then part-way (mass still exact).
#[allow(clippy::too_many_arguments)]
pub(crate) fn settle(
    heights: &mut [i32],
    held: &[bool],
    dims: UVec2,
    t: i64,
    tops: &Tops,
    seeds: impl IntoIterator<Item = usize>,
    max_pops: u64,
    scratch: &mut Scratch,
) -> Result<Settled, TooMuchWork> {
    debug_assert_eq!(heights.len(), held.len());
    scratch.fit(dims);
    let Scratch {
        queued,
        seen,
        seen_list,
        mark,
        stamp,
        list,
        path,
        sides,
        ..
    } = scratch;
    let nx = dims.x as usize;
    let push = |list: &mut VecDeque<u32>, queued: &mut [bool], j: usize| {
        if !held[j] && !queued[j] {
            queued[j] = true;
            list.push_back(j as u32);
        }
    };
    for s in seeds {
        push(list, queued, s);
        each_neighbour(s, sides[s], nx, |n| push(list, queued, n));
    }
    let mut g = Ground {
        heights,
        held,
        sides,
        dims,
        t,
        tops,
    };
    let mut done = Settled::default();
    let limit = t + 1;
    let result = loop {
        let Some(c) = list.pop_front() else {
            break Ok(());
        };
        let c = c as usize;
        queued[c] = false;
        if done.pops == max_pops {
            break Err(TooMuchWork { pops: done.pops });
        }
        done.pops += 1;
        if !seen[c] {
            seen[c] = true;
            seen_list.push(c as u32);
        }
        // Slides (below the cap of a body c leans on), then a spill of what is above the
        // cap, then slides again from the cap.
        // (At or below every body's top, no cap can bind: c only falls here.)
        let cap = if g.heights[c] > g.tops.lowest {
            g.cap(c).unwrap_or(i64::MAX)
        } else {
            i64::MAX
        };
        // When the spill finds no room (the far side of the body is at or above its top too:
        // a buried body), the cap cannot be kept, and the slides go on from c's own height
        // (uncapped) so that the slope rule still holds between free cells.
        let mut gave = false;
        let mut cap = cap;
        loop {
            while let Some(n) = g.steepest(c) {
                *stamp = stamp.wrapping_add(1);
                if *stamp == 0 {
                    mark.fill(0);
                    *stamp = 1;
                }
                let moved = g.slide(c, n, cap, path, mark, *stamp);
                if moved == 0 {
                    break;
                }
                done.moved += moved;
                gave = true;
                for &p in &path[1..] {
                    push(list, queued, p as usize);
                }
            }
            if cap == i64::MAX {
                break;
            }
            let spilt = g.spill(c, cap, |j| push(list, queued, j));
            if spilt == 0 {
                cap = i64::MAX;
                continue;
            }
            done.moved += spilt;
            gave = true;
        }
        if gave {
            let hc = g.heights[c] as i64;
            let h = &*g.heights;
            each_neighbour(c, sides[c], nx, |n| {
                if h[n] as i64 - hc > limit {
                    push(list, queued, n);
                }
            });
        }
    };
    // Leave the buffers clean for the next settle, and measure what the work covered.
    for &j in list.iter() {
        queued[j as usize] = false;
    }
    list.clear();
    let h = &*g.heights;
    let mut d = 0u64;
    for &c in seen_list.iter() {
        let c = c as usize;
        seen[c] = false;
        if held[c] {
            continue;
        }
        each_neighbour(c, sides[c], nx, |n| {
            if !held[n] {
                d = d.max((h[c] as i64 - h[n] as i64).unsigned_abs());
            }
        });
    }
    done.max_difference = d;
    result.map(|()| done)
}

/// The largest difference, units, between two 4-neighbours neither of which is held.
#[cfg(test)]
pub(crate) fn max_free_difference(heights: &[i32], held: &[bool], dims: UVec2) -> u64 {
    let nx = dims.x as usize;
    let diff = |a: usize, b: usize| (heights[a] as i64 - heights[b] as i64).unsigned_abs();
    let mut d = 0;
    for j in 0..heights.len() {
        if held[j] {
            continue;
        }
        if j % nx + 1 < nx && !held[j + 1] {
            d = d.max(diff(j, j + 1));
        }
        if j + nx < heights.len() && !held[j + nx] {
            d = d.max(diff(j, j + nx));
        }
    }
    d
}

/// The cells of `window` (a grid `nx` cells wide) whose height differs between `before` and
/// `after`, ascending: what a frame's press changed.
pub(crate) fn changed_cells(before: &[i32], after: &[i32], window: Window, nx: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for y in 0..window.h {
        let row = window.global(0, y, nx);
        let w = window.w as usize;
        for (x, (a, b)) in before[row..row + w]
            .iter()
            .zip(&after[row..row + w])
            .enumerate()
        {
            if a != b {
                out.push((row + x) as u32);
            }
        }
    }
    out
}

/// One frame's settle, shared by the CPU and GPU grounds so that both give the same integers:
/// seeds are `pending` (cells released or changed since the last frame, ascending), then
/// `changed` (the cells this frame's press changed, ascending), each with its neighbours. Fills the slump metrics (`max_slope` over the
/// cells the work list took, see [`super::GroundFrameMetrics::max_slope`]); past the bound
/// (`max_visits_per_cell` × the field's cells) an `Error::Numerical` naming the ground.
#[allow(clippy::too_many_arguments)]
pub(crate) fn settle_frame(
    heights: &mut [i32],
    held: &[bool],
    grid: &GroundGrid,
    t: i64,
    tops: &Tops,
    pending: &[u32],
    changed: &[u32],
    max_visits_per_cell: u32,
    frame: u32,
    scratch: &mut Scratch,
    m: &mut super::metrics::GroundFrameMetrics,
) -> imprint_core::Result<()> {
    let seeds = pending.iter().chain(changed).map(|&j| j as usize);
    let max_pops = max_visits_per_cell as u64 * heights.len() as u64;
    match settle(heights, held, grid.dims, t, tops, seeds, max_pops, scratch) {
        Ok(s) => {
            m.slump_visits += s.pops;
            m.slump_iterations += (s.pops > 0) as u32;
            m.slumped_units += s.moved;
            m.max_slope = s.max_difference as f32 * (grid.unit / grid.cell as f64) as f32;
            Ok(())
        }
        Err(e) => Err(imprint_core::Error::Numerical {
            node: "ground".into(),
            frame,
            message: format!(
                "settle (relaxation: Settle) still moving after {} work-list visits \
                 (max_relax_iterations = {max_visits_per_cell} per cell of the field)",
                e.pops
            ),
            hint: "raise max_relax_iterations".into(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(
        h: &mut [i32],
        held: &[bool],
        dims: UVec2,
        t: i64,
        tops: &Tops,
        seeds: &[usize],
        max: u64,
    ) -> Result<Settled, TooMuchWork> {
        settle(
            h,
            held,
            dims,
            t,
            tops,
            seeds.iter().copied(),
            max,
            &mut Scratch::default(),
        )
    }

    /// A spike spreads to rest: mass exact, every pair within T + 1, held cells untouched.
    #[test]
    fn a_spike_settles_with_mass_kept() {
        let dims = UVec2::new(16, 12);
        let n = 16 * 12;
        let mut h = vec![1000i32; n];
        h[5 * 16 + 7] = 200_000;
        let mut held = vec![false; n];
        held[5 * 16 + 8] = true;
        let before: i64 = h.iter().map(|&x| x as i64).sum();
        let none = Tops::default();
        let s = run(&mut h, &held, dims, 50, &none, &[5 * 16 + 7], u64::MAX).unwrap();
        assert!(s.moved > 0 && s.pops > 0);
        assert_eq!(h.iter().map(|&x| x as i64).sum::<i64>(), before);
        assert_eq!(h[5 * 16 + 8], 1000, "held cells are not moved into");
        assert!(max_free_difference(&h, &held, dims) <= 51);
        assert!(s.max_difference <= 51);
        let mut again = h.clone();
        let all: Vec<usize> = (0..n).collect();
        let s = run(&mut again, &held, dims, 50, &none, &all, u64::MAX).unwrap();
        assert_eq!((s.moved, again), (0, h), "at rest");
        let mut h = vec![0i32; n];
        h[0] = 10_000_000;
        assert!(run(&mut h, &held, dims, 50, &none, &[0], 100).is_err());
    }

    /// A path is a ramp of slope T from the top, T or T + 1 a step, with mass exact.
    #[test]
    fn a_slide_levels_its_path_to_a_ramp() {
        let dims = UVec2::new(40, 1);
        let mut h = vec![0i32; 40];
        h[0] = 1000;
        let held = vec![false; 40];
        let s = run(&mut h, &held, dims, 10, &Tops::default(), &[0], u64::MAX).unwrap();
        assert_eq!(h.iter().sum::<i32>(), 1000);
        assert!(
            h.windows(2).all(|w| w[0] >= w[1] && w[0] - w[1] <= 11),
            "{h:?}"
        );
        // Levelled in one slide: the cells it reached, about √(2 · 1000 / 10) + 1.
        assert!(s.pops < 40, "{s:?}: {h:?}");
    }

    /// Material next to a held wall that cannot slide away (the field's edge behind it) and
    /// stands above the body's top spills over the wall to the far side, mass exact, and
    /// nothing stands above the top; material that can slide away slides instead.
    #[test]
    fn material_above_a_body_spills_over_it() {
        let grid = GroundGrid {
            origin: glam::Vec2::ZERO,
            cell: 1.0,
            dims: UVec2::new(12, 1),
            unit: 1.0,
        };
        let mut body = imprint_core::mesh::primitives::cuboid(glam::Vec3::new(1.0, 5.0, 0.4), 1);
        body.transform(glam::Mat4::from_translation(glam::Vec3::new(1.5, 5.0, 0.0)));
        let tops = Tops::of(&[&body], &grid);
        let mut held = vec![false; 12];
        held[1] = true;
        held[2] = true;
        let mut h = vec![0i32; 12];
        h[0] = 30;
        let s = run(&mut h, &held, grid.dims, 2, &tops, &[0], u64::MAX).unwrap();
        assert_eq!(h.iter().sum::<i32>(), 30);
        assert!(s.moved > 0);
        assert_eq!(h[0], 10, "down to the top: {h:?}");
        assert!(h.iter().all(|&x| x <= 10), "{h:?}");
        assert_eq!(h[3..].iter().sum::<i32>(), 20, "over the body: {h:?}");
        // With room on its own side, the heap slides there first: a ramp from the top.
        let mut h = vec![0i32; 12];
        h[8] = 30;
        held.fill(false);
        held[9] = true;
        let mut body = imprint_core::mesh::primitives::cuboid(glam::Vec3::new(0.5, 5.0, 0.4), 1);
        body.transform(glam::Mat4::from_translation(glam::Vec3::new(9.0, 5.0, 0.0)));
        let tops = Tops::of(&[&body], &grid);
        run(&mut h, &held, grid.dims, 2, &tops, &[8], u64::MAX).unwrap();
        assert_eq!(h.iter().sum::<i32>(), 30);
        assert!(h[10..].iter().all(|&x| x == 0), "nothing over: {h:?}");
        assert!(h.iter().all(|&x| x <= 10), "{h:?}");
    }
}
