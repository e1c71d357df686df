//! Stabilisation of the snow on a ground height field: snow on a slope steeper than its angle
//! of repose slides to lower cells (T's particle-deposition stabilisation, docs/methods.md
//! §5), until every slope of the snow surface is at most the repose angle.
//!
//! **Units.** Snow is counted in whole quanta of [`QUANTUM`] metres of column height (u32 per
//! cell). A pass moves whole quanta from one cell to another and nothing else touches them,
//! so the total is conserved exactly, bit for bit, on any number of threads.
//!
//! **A pass** (Jacobi: everything read from the snapshot of the previous pass, so cells are
//! independent and the order does not matter; a WGSL port is two dispatches):
//! 1. *Outflows.* Each cell i with snow compares its snow surface H = ground + snow with each
//!    neighbour j of the 16-cell [`STENCIL`] (4 sides, 4 diagonals, 8 knight moves at
//!    distance d_ij): the excess is e_ij = H_i − H_j − tan θ · d_ij (in quanta). With m the
//!    largest excess, the cell sheds `min(snow_i, ⌊m / 2⌋)` quanta (half the largest excess:
//!    a lone pair is levelled to the repose slope in one pass), shared among the neighbours
//!    in proportion to their excess, each share rounded down and what rounding leaves going to
//!    the steepest neighbour, so the shares sum to exactly what is shed, never more than the
//!    cell holds. The shares are written per cell and stencil slot.
//! 2. *Gather.* Each cell's new snow = its snow − its outflows + the shares its neighbours
//!    sent it (read from their slots). Every share is subtracted once and added once.
//!
//! Why 16 neighbours: the steepest pile the rule allows is a cone in the metric of the
//! stencil's steps. With 4 neighbours it is a square pyramid, with 8 an octagonal one (3.6%
//! taller than the cone of the same volume); with the knight moves the base is a 16-gon whose
//! area is 97% of the circle's, so a point pour settles to within about 1% of the cone's
//! height (3V tan²θ / π)^(1/3).
//!
//! The border is closed: cells outside the field are not neighbours, so no snow leaves it.
//! Only snow moves; the ground under it is never changed (snow slides off a cliff steeper
//! than θ and leaves it bare).

use imprint_core::HeightField;
use rayon::prelude::*;

/// Metres of snow column per unit (2^-16 m, about 15 µm: far below a snow grain, and the
/// residual slope it leaves is below 2·QUANTUM per step). A u32 holds 65 km.
pub const QUANTUM: f32 = 1.0 / 65536.0;

/// Most snow a deposit or a pour may leave in one cell (2048 m): keeps a pass's gather,
/// which adds at most 16 neighbours' shares, far inside u32.
pub const MAX_CELL_UNITS: u32 = 1 << 27;

/// Neighbour offsets (di, dk): sides, diagonals, knight moves.
pub const STENCIL: [(i32, i32); 16] = [
    (1, 0),
    (-1, 0),
    (0, 1),
    (0, -1),
    (1, 1),
    (1, -1),
    (-1, 1),
    (-1, -1),
    (2, 1),
    (2, -1),
    (-2, 1),
    (-2, -1),
    (1, 2),
    (1, -2),
    (-1, 2),
    (-1, -2),
];

/// What a call to [`relax`] did.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RelaxReport {
    /// Passes run (the last one may have moved nothing).
    pub passes: u32,
    /// Quanta moved, summed over the passes.
    pub moved: u64,
    /// Whether the last pass moved nothing: every slope is at the repose angle or below
    /// (to within two quanta per stencil step).
    pub settled: bool,
}

/// Buffers kept between calls (per-cell stencil shares and the next snow).
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    flows: Vec<[u32; 16]>,
    next: Vec<u32>,
}

/// Runs up to `passes` passes over the snow `units` lying on `ground` (same cells), with
/// `tan_repose` = tan θ; stops after the first pass that moves nothing.
pub fn relax(
    ground: &HeightField,
    tan_repose: f32,
    units: &mut Vec<u32>,
    passes: u32,
    scratch: &mut Scratch,
) -> RelaxReport {
    let n = units.len();
    assert_eq!(n, ground.heights.len(), "snow and ground cells differ");
    let crit: [f32; 16] = std::array::from_fn(|t| {
        let (a, b) = STENCIL[t];
        tan_repose * ((a * a + b * b) as f32).sqrt() * ground.cell / QUANTUM
    });
    scratch.flows.resize(n, [0; 16]);
    scratch.next.resize(n, 0);
    let mut report = RelaxReport::default();
    for _ in 0..passes {
        let moved = pass(ground, &crit, units, scratch);
        std::mem::swap(units, &mut scratch.next);
        report.passes += 1;
        report.moved += moved;
        report.settled = moved == 0;
        if report.settled {
            break;
        }
    }
    report
}

/// One pass: shares from `units` into `scratch.flows`, gathered into `scratch.next`. Returns
/// the quanta moved.
fn pass(ground: &HeightField, crit: &[f32; 16], units: &[u32], scratch: &mut Scratch) -> u64 {
    let (nx, nz) = (ground.dims.x as i32, ground.dims.y as i32);
    let g = &ground.heights;
    let moved: u64 = scratch
        .flows
        .par_chunks_mut(nx as usize)
        .enumerate()
        .map(|(k, row)| {
            let mut sum = 0u64;
            for (i, out) in row.iter_mut().enumerate() {
                *out = outflows(i as i32, k as i32, nx, nz, g, units, crit);
                sum += out.iter().map(|&v| v as u64).sum::<u64>();
            }
            sum
        })
        .sum();
    let flows = &scratch.flows;
    scratch
        .next
        .par_chunks_mut(nx as usize)
        .enumerate()
        .for_each(|(k, row)| {
            let k = k as i32;
            for (i, next) in row.iter_mut().enumerate() {
                let i = i as i32;
                let c = (k * nx + i) as usize;
                let mut v = units[c] as u64;
                v -= flows[c].iter().map(|&f| f as u64).sum::<u64>();
                for (t, &(a, b)) in STENCIL.iter().enumerate() {
                    let (si, sk) = (i - a, k - b);
                    if si >= 0 && sk >= 0 && si < nx && sk < nz {
                        v += flows[(sk * nx + si) as usize][t] as u64;
                    }
                }
                // A cell fills at most to about its neighbours' snow surface: u32 (65 km of
                // snow) overflows only on ground spanning tens of kilometres.
                debug_assert!(v <= u32::MAX as u64);
                *next = v as u32;
            }
        });
    moved
}

/// The quanta cell (i, k) sends to each stencil neighbour (see the module doc).
#[inline]
fn outflows(
    i: i32,
    k: i32,
    nx: i32,
    nz: i32,
    g: &[f32],
    units: &[u32],
    crit: &[f32; 16],
) -> [u32; 16] {
    let mut out = [0u32; 16];
    let c = (k * nx + i) as usize;
    let s = units[c];
    if s == 0 {
        return out;
    }
    let mut excess = [0f32; 16];
    let (mut largest, mut sum) = (0f32, 0f32);
    for (t, &(a, b)) in STENCIL.iter().enumerate() {
        let (ni, nk) = (i + a, k + b);
        if ni < 0 || nk < 0 || ni >= nx || nk >= nz {
            continue;
        }
        let j = (nk * nx + ni) as usize;
        let e = (g[c] - g[j]) / QUANTUM + (s as i64 - units[j] as i64) as f32 - crit[t];
        if e > 0.0 {
            excess[t] = e;
            sum += e;
            largest = largest.max(e);
        }
    }
    let total = (s as f32).min((0.5 * largest).floor());
    if total < 1.0 {
        return out;
    }
    let mut left = total as u32;
    let mut steepest = 0;
    for (t, (o, &e)) in out.iter_mut().zip(&excess).enumerate() {
        if e > 0.0 {
            // Rounded down, and never more than is left: the shares sum to at most `total`.
            let share = ((total * (e / sum)).floor() as u32).min(left);
            *o = share;
            left -= share;
            if e > excess[steepest] {
                steepest = t;
            }
        }
    }
    // What rounding left over goes down the steepest slope, so that small excesses spread
    // over many neighbours still move.
    out[steepest] += left;
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec2, Vec2};

    /// A pile on one cell of a flat field spreads into neighbours, conserving every quantum,
    /// and settles with no slope steeper than θ (plus the rounding slack).
    #[test]
    fn a_spike_spreads_conserving_quanta() {
        let ground = HeightField::constant(Vec2::ZERO, 0.01, UVec2::new(15, 15), 0.0).unwrap();
        let mut units = vec![0u32; 225];
        units[7 * 15 + 7] = (0.05 / QUANTUM) as u32;
        let before: u64 = units.iter().map(|&u| u as u64).sum();
        let tan = 0.7;
        let r = relax(&ground, tan, &mut units, 10_000, &mut Scratch::default());
        assert!(r.settled && r.moved > 0, "{r:?}");
        assert_eq!(units.iter().map(|&u| u as u64).sum::<u64>(), before);
        for k in 0..15i32 {
            for i in 0..15i32 {
                for &(a, b) in &STENCIL {
                    let (ni, nk) = (i + a, k + b);
                    if ni < 0 || nk < 0 || ni >= 15 || nk >= 15 {
                        continue;
                    }
                    let d = ((a * a + b * b) as f32).sqrt() * 0.01;
                    let (h, hn) = (
                        units[(k * 15 + i) as usize] as f32 * QUANTUM,
                        units[(nk * 15 + ni) as usize] as f32 * QUANTUM,
                    );
                    if h > 0.0 {
                        assert!(
                            h - hn <= tan * d + 2.0 * QUANTUM,
                            "({i},{k})->({ni},{nk}): {h} {hn} {}",
                            tan * d
                        );
                    }
                }
            }
        }
    }

    /// Snow on a cliff steeper than θ leaves it for the foot; snow on a gentle slope stays.
    #[test]
    fn snow_slides_off_steep_ground_only() {
        let cell = 0.1;
        for (slope, moves) in [(0.3f32, false), (2.0, true)] {
            let ground = HeightField::from_fn(Vec2::ZERO, cell, UVec2::new(8, 4), |i, _| {
                -slope * i as f32 * cell
            })
            .unwrap();
            let mut units = vec![(0.01 / QUANTUM) as u32; 32];
            let r = relax(&ground, 1.0, &mut units, 1000, &mut Scratch::default());
            assert_eq!(r.moved > 0, moves, "slope {slope}: {r:?}");
            if moves {
                // The top column is bare, the foot holds more than it got.
                assert!(units[0] < units[7], "{units:?}");
            }
        }
    }
}
