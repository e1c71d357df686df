//! `Relaxation::Settle`: the ground comes to rest wherever it changed, by a work list.
//!
//! A FIFO work list starts from the cells a frame may have left too steep (see
//! [`settle`]). A cell taken from it, unless held, gives whole height units to its steepest
//! free lower 4-neighbour while that difference exceeds T + 1 unit: ⌊(d − T) / 2⌋ units,
//! which leaves the pair at T or T + 1 and never reverses it. The receiver goes on the list
//! (it rose, so it may now be too steep toward its own neighbours), and so do the free
//! neighbours the giver's fall left more than T + 1 above it. Every transfer of f units over
//! a difference d lowers Σh² by 2f(d − f) > 0, so the list empties; when it does, no free
//! pair differs by more than T + 1 unit wherever the work reached (every pair a change could
//! have made steep has its higher cell on the list until it is settled). One thread, one
//! fixed order: the same input gives the same integers whatever the thread count, and the
//! GPU ground calls the same function on the heights it reads back.

use glam::UVec2;
use std::collections::VecDeque;

/// What one settle did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Settled {
    /// Cells taken from the work list.
    pub pops: u64,
    /// Units moved.
    pub moved: i64,
}

/// The work list's bound was hit after `pops` visits (see [`settle`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct TooMuchWork {
    pub pops: u64,
}

/// The 4-neighbours of cell `c` in the order −x, +x, −z, +z.
#[inline]
fn neighbours4(c: usize, dims: UVec2) -> [Option<usize>; 4] {
    let nx = dims.x as usize;
    let (i, k) = (c % nx, c / nx);
    [
        (i > 0).then(|| c - 1),
        (i + 1 < nx).then(|| c + 1),
        (k > 0).then(|| c - nx),
        (k + 1 < dims.y as usize).then(|| c + nx),
    ]
}

/// Settles `heights` (units, x fastest, a `dims` grid) to slope `t` units per cell (plus one
/// unit), starting from `seeds` and their 4-neighbours, in the seeds' order. Cells with
/// `held[j]` (under an object this frame) neither give nor receive. Stops with
/// `TooMuchWork` after `max_pops` visits; the heights are then part-way (mass still exact).
pub(crate) fn settle(
    heights: &mut [i32],
    held: &[bool],
    dims: UVec2,
    t: i64,
    seeds: impl IntoIterator<Item = usize>,
    max_pops: u64,
) -> Result<Settled, TooMuchWork> {
    debug_assert_eq!(heights.len(), held.len());
    let mut queued = vec![false; heights.len()];
    let mut list = VecDeque::new();
    let push = |list: &mut VecDeque<usize>, queued: &mut [bool], j: usize| {
        if !held[j] && !queued[j] {
            queued[j] = true;
            list.push_back(j);
        }
    };
    for s in seeds {
        push(&mut list, &mut queued, s);
        for n in neighbours4(s, dims).into_iter().flatten() {
            push(&mut list, &mut queued, n);
        }
    }
    let mut done = Settled::default();
    // A move needs d ≥ T + 2: then ⌊(d − T) / 2⌋ ≥ 1.
    let limit = t + 1;
    while let Some(c) = list.pop_front() {
        queued[c] = false;
        if done.pops == max_pops {
            return Err(TooMuchWork { pops: done.pops });
        }
        done.pops += 1;
        let nbs = neighbours4(c, dims);
        let mut gave = false;
        loop {
            let hc = heights[c] as i64;
            let mut best = None;
            let mut best_d = limit;
            for n in nbs.into_iter().flatten() {
                let d = hc - heights[n] as i64;
                if d > best_d && !held[n] {
                    best = Some(n);
                    best_d = d;
                }
            }
            let Some(n) = best else { break };
            let f = (best_d - t) / 2;
            heights[c] = (hc - f) as i32;
            heights[n] = (heights[n] as i64 + f) as i32;
            done.moved += f;
            gave = true;
            push(&mut list, &mut queued, n);
        }
        if gave {
            let hc = heights[c] as i64;
            for n in nbs.into_iter().flatten() {
                if heights[n] as i64 - hc > limit {
                    push(&mut list, &mut queued, n);
                }
            }
        }
    }
    Ok(done)
}

/// The largest difference, units, between two 4-neighbours neither of which is held.
pub(crate) fn max_free_difference(heights: &[i32], held: &[bool], dims: UVec2) -> u64 {
    use rayon::prelude::*;
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

/// One frame's settle, shared by the CPU and GPU grounds so that both give the same integers:
/// seeds are `pending` (cells released or changed since the last frame, ascending), then the
/// cells of `window` (this frame's work window, which holds every cell the press changed
/// and their neighbours) in raster order. Fills the slump metrics; past the bound
/// (`max_visits_per_cell` × the field's cells) an `Error::Numerical` naming the ground.
#[allow(clippy::too_many_arguments)]
pub(crate) fn settle_frame(
    heights: &mut [i32],
    held: &[bool],
    dims: UVec2,
    t: i64,
    pending: &[u32],
    window: Option<super::contact::Window>,
    max_visits_per_cell: u32,
    frame: u32,
    m: &mut super::metrics::GroundFrameMetrics,
) -> imprint_core::Result<()> {
    let nx = dims.x;
    let win_cells = window
        .into_iter()
        .flat_map(move |w| (0..w.h).flat_map(move |y| (0..w.w).map(move |x| w.global(x, y, nx))));
    let seeds = pending.iter().map(|&j| j as usize).chain(win_cells);
    let max_pops = max_visits_per_cell as u64 * heights.len() as u64;
    match settle(heights, held, dims, t, seeds, max_pops) {
        Ok(s) => {
            m.slump_visits += s.pops;
            m.slump_iterations += (s.pops > 0) as u32;
            m.slumped_units += s.moved;
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
        let s = settle(&mut h, &held, dims, 50, [5 * 16 + 7], u64::MAX).unwrap();
        assert!(s.moved > 0 && s.pops > 0);
        assert_eq!(h.iter().map(|&x| x as i64).sum::<i64>(), before);
        assert_eq!(h[5 * 16 + 8], 1000, "held cells are not moved into");
        assert!(max_free_difference(&h, &held, dims) <= 51);
        let mut again = h.clone();
        let s = settle(&mut again, &held, dims, 50, 0..n, u64::MAX).unwrap();
        assert_eq!((s.moved, again), (0, h), "at rest");
        let mut h = vec![0i32; n];
        h[0] = 10_000_000;
        assert!(settle(&mut h, &held, dims, 50, [0], 100).is_err());
    }
}
