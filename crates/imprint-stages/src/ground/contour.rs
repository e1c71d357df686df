//! O §2.2 and §2.4: contour maps, the discrete distance of every cell from the edge of the
//! contact, inside it (where material is pushed from) and around it (where it slumps).
//!
//! **Metric: city-block (L1), 4-neighbours.** O labels by "cells next to the current
//! maximum get maximum + 1"; with "next to" meaning sharing an edge (the neighbours the
//! displacement and the slump exchange material with), that breadth-first labelling is
//! exactly the L1 distance to the nearest seed, and neighbouring cells differ by at most 1,
//! so every cell at level l > 0 has a neighbour at level l − 1 (where displaced material
//! goes). We compute it with Rosenfeld and Pfaltz's two raster passes (forward: left and up
//! neighbours + 1; backward: right and down + 1), exact for this metric, O(cells), with no
//! queue and no order-dependent result. On a GPU the same map is the fixed point of
//! `d = min(d, neighbours + 1)` iterated in ping-pong, which reaches the same integers.

use super::contact::Window;
use imprint_core::buckets::Buckets;
use serde::{Deserialize, Serialize};

/// Level of a cell the map does not label.
pub const UNLABELLED: u32 = u32::MAX;

/// The contour maps of one frame's contact, over the frame's work window (the contact's
/// bounding box grown by the slump band and one more cell, clipped to the field).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ContourMaps {
    pub window: Window,
    /// Whether an object's bottom was below the ground in the cell.
    pub contact: Vec<bool>,
    /// O §2.2: 0 outside the contact; inside, the L1 distance to the nearest cell outside it
    /// (≥ 1). [`UNLABELLED`] only when no cell of the field is outside the contact.
    pub inner: Vec<u32>,
    /// O §2.4: outside the contact, its L1 distance to the contact minus one (the rim, the
    /// ring touching the contact, is 0), for the `slump_band` rings nearest the contact;
    /// [`UNLABELLED`] elsewhere and on the contact itself.
    pub outer: Vec<u32>,
}

/// The exact L1 distance, over a `w × h` window (row-major, x fastest), from every cell to
/// the nearest cell `seed` says yes to; [`UNLABELLED`] everywhere when there is no seed.
pub fn l1_distance(w: usize, h: usize, seed: impl Fn(usize) -> bool, out: &mut Vec<u32>) {
    out.clear();
    out.extend((0..w * h).map(|j| if seed(j) { 0 } else { UNLABELLED }));
    let step = |d: u32| d.saturating_add(1);
    for y in 0..h {
        for x in 0..w {
            let j = y * w + x;
            let mut d = out[j];
            if x > 0 {
                d = d.min(step(out[j - 1]));
            }
            if y > 0 {
                d = d.min(step(out[j - w]));
            }
            out[j] = d;
        }
    }
    for y in (0..h).rev() {
        for x in (0..w).rev() {
            let j = y * w + x;
            let mut d = out[j];
            if x + 1 < w {
                d = d.min(step(out[j + 1]));
            }
            if y + 1 < h {
                d = d.min(step(out[j + w]));
            }
            out[j] = d;
        }
    }
}

/// The 4-neighbours of cell `j` of a `w × h` window, in the fixed order −x, +x, −z, +z
/// (`None` beyond the window). The order is part of the output: it decides who gets the
/// remainder of an equal share.
#[inline]
pub fn neighbours(j: usize, w: usize, h: usize) -> [Option<usize>; 4] {
    let (x, y) = (j % w, j / w);
    [
        (x > 0).then(|| j - 1),
        (x + 1 < w).then(|| j + 1),
        (y > 0).then(|| j - w),
        (y + 1 < h).then(|| j + w),
    ]
}

/// Cells grouped by level, each group in index order ([`Buckets`]): what lets the
/// displacement and the slump go level by level without scanning the window per level.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Levels {
    lo: u32,
    cells: Buckets,
}

impl Levels {
    /// The cells whose level is in `lo..=hi`.
    pub fn build(levels: &[u32], lo: u32, hi: u32) -> Self {
        let groups = if hi < lo { 0 } else { (hi - lo) as usize + 1 };
        let cells = Buckets::build(groups, || {
            let range = lo..=hi;
            levels
                .iter()
                .enumerate()
                .filter(move |&(_, l)| range.contains(l))
                .map(move |(j, &l)| ((l - lo) as usize, j as u32))
        });
        Levels { lo, cells }
    }

    /// The cells of level `l` (empty outside the built range).
    pub fn level(&self, l: u32) -> &[u32] {
        match l.checked_sub(self.lo) {
            Some(i) if (i as usize) < self.cells.groups() => self.cells.of(i as usize),
            _ => &[],
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute force: the smallest |dx| + |dy| to a seed.
    fn brute(w: usize, h: usize, seed: &[bool]) -> Vec<u32> {
        (0..w * h)
            .map(|j| {
                let (x, y) = ((j % w) as i64, (j / w) as i64);
                (0..w * h)
                    .filter(|&s| seed[s])
                    .map(|s| ((s % w) as i64 - x).abs() + ((s / w) as i64 - y).abs())
                    .min()
                    .map_or(UNLABELLED, |d| d as u32)
            })
            .collect()
    }

    #[test]
    fn two_passes_equal_the_brute_force_distance() {
        // A deterministic scatter of seeds (an LCG), sparse and dense, plus no seed at all.
        let mut s = 12345u64;
        for (w, h, density) in [(17, 11, 3), (9, 23, 40), (30, 30, 1), (5, 4, 0)] {
            let seed: Vec<bool> = (0..w * h)
                .map(|_| {
                    s = s
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    ((s >> 33) % 100) < density
                })
                .collect();
            let mut d = Vec::new();
            l1_distance(w, h, |j| seed[j], &mut d);
            assert_eq!(d, brute(w, h, &seed), "{w} x {h}, {density}%");
        }
    }

    #[test]
    fn levels_group_cells_in_index_order() {
        let l = Levels::build(&[2, 0, 1, 2, UNLABELLED, 1, 5], 1, 3);
        assert_eq!(l.level(1), &[2, 5]);
        assert_eq!(l.level(2), &[0, 3]);
        assert!(l.level(3).is_empty() && l.level(0).is_empty() && l.level(9).is_empty());
        assert!(Levels::build(&[1, 2], 3, 2).level(3).is_empty());
        assert_eq!(neighbours(0, 3, 2), [None, Some(1), None, Some(3)]);
    }
}
