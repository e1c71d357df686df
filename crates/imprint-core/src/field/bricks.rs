//! Where a field's cells are all plainly far: the blocks of cells whose trilinear reads need
//! no cell loaded.
//!
//! A cloth over a body has most of its particles inside the body's grid but outside its band
//! (57% of the field reads in H's scene): each such read loaded eight far cells only to
//! blend the far distance with its weights. [`FarBricks`] says, per block of 4³ base cells,
//! whether every cell such a read can touch (the base cell and its +1 neighbours) holds
//! exactly `(0, 0, 0, -far)`; a reader then blends those values without loading them, the
//! same bits.

use crate::lanes::lanes_of;
use glam::{UVec3, Vec4};
use std::ops::Range;

/// Base cells per block side, and its log2.
const BRICK_LOG2: u32 = 2;

/// Per block of 4³ base cells, whether a read based there may touch a cell that is not
/// plainly far (see the module docs). A byte per block, not a bit: the cloth looks up eight
/// blocks per read, and a byte is one load where a bit added a shift, a mask and a division.
#[derive(Clone, Debug, Default)]
pub struct FarBricks {
    near: Vec<bool>,
    /// Blocks along x, and in an xy layer.
    bx: usize,
    bxy: usize,
}

impl FarBricks {
    /// From each row's (`y + ny z`) range of cells that are not plainly far (`None`: all are):
    /// a row may give more than those cells, never fewer.
    pub fn from_rows(dims: UVec3, rows: impl Iterator<Item = Option<Range<usize>>>) -> Self {
        let n = dims
            .to_array()
            .map(|d| (d as usize).div_ceil(1 << BRICK_LOG2));
        let mut b = FarBricks {
            near: vec![false; n[0] * n[1] * n[2]],
            bx: n[0],
            bxy: n[0] * n[1],
        };
        let ny = dims.y as usize;
        // A cell is read from the base cells at its own coordinates and one less on each axis.
        let blocks = |c: usize| [c.saturating_sub(1) >> BRICK_LOG2, c >> BRICK_LOG2];
        for (row, xs) in rows.enumerate() {
            let Some(xs) = xs.filter(|xs| !xs.is_empty()) else {
                continue;
            };
            let (by, bz) = (blocks(row % ny), blocks(row / ny));
            let (bx0, bx1) = (blocks(xs.start)[0], (xs.end - 1) >> BRICK_LOG2);
            for z in bz[0]..=bz[1] {
                for y in by[0]..=by[1] {
                    for x in bx0..=bx1 {
                        b.near[x + b.bx * y + b.bxy * z] = true;
                    }
                }
            }
        }
        b
    }

    /// Whether every cell a trilinear read based at cell `(x, y, z)` touches is plainly far.
    #[inline(always)]
    pub fn all_far(&self, [x, y, z]: [usize; 3]) -> bool {
        self.far_block(self.block([x, y, z].map(|c| c as u32)))
    }

    /// The block of base cell `(x, y, z)`, in the grid: in 32-bit arithmetic, which a loop
    /// over lanes takes eight at a time (a grid indexable by `u32`, as the field's cells are).
    #[inline(always)]
    pub fn block(&self, [x, y, z]: [u32; 3]) -> u32 {
        let (bx, bxy) = (self.bx as u32, self.bxy as u32);
        (x >> BRICK_LOG2) + bx * (y >> BRICK_LOG2) + bxy * (z >> BRICK_LOG2)
    }

    /// Whether every cell a read based at cell `(x[m], y[m], z[m])` (within the grid) touches
    /// is plainly far, for every lane `m` set in `lanes`: the lanes' blocks found side by
    /// side, then looked up in order until one is near. A cloth resting on a body reads
    /// near blocks mostly, whose first lane answers (the eight lookups were a tenth of its
    /// contact's instructions).
    #[inline(always)]
    pub fn all_far_lanes<const N: usize>(&self, [x, y, z]: &[[i32; N]; 3], lanes: u32) -> bool {
        // No blocks (a default value): nothing is known to be far.
        let Some(last) = self.near.len().checked_sub(1) else {
            return lanes == 0;
        };
        let mut block = [0u32; N];
        for m in 0..N {
            block[m] = self.block([x[m] as u32, y[m] as u32, z[m] as u32]);
        }
        // Cells within the grid have their block in `near`: the clamp changes none.
        lanes_of(lanes).all(|m| !self.near[(block[m] as usize).min(last)])
    }

    /// Whether every cell a read based in block `b` ([`FarBricks::block`]) touches is plainly
    /// far.
    #[inline(always)]
    pub fn far_block(&self, b: u32) -> bool {
        !self.near[b as usize]
    }
}

/// The cells of `row` from the first to the last that is not exactly `far_cell` (bit for bit).
pub fn not_far_span(row: &[Vec4], far_cell: Vec4) -> Option<Range<usize>> {
    let bits = |c: &Vec4| c.to_array().map(f32::to_bits);
    let far = bits(&far_cell);
    let lo = row.iter().position(|c| bits(c) != far)?;
    let hi = row.iter().rposition(|c| bits(c) != far)?;
    Some(lo..hi + 1)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lanes together say what [`FarBricks::all_far`] says of each lane's cell, for any
    /// set of lanes, cells all over a grid whose sides are not whole blocks; a default value
    /// knows nothing far.
    #[test]
    fn all_far_lanes_is_all_far_lane_by_lane() {
        let dims = UVec3::new(13, 9, 18);
        // A band through a few rows: near blocks around them, far ones elsewhere.
        let rows = (0..dims.y * dims.z).map(|r| match r % 61 {
            0 => Some(2..5),
            29 => Some(9..13),
            _ => None,
        });
        let bricks = FarBricks::from_rows(dims, rows);
        let mut seed = 5u32;
        let mut next = |n: u32| {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            ((seed >> 8) % n) as i32
        };
        let (mut far, mut near) = (0, 0);
        for round in 0..2000 {
            // Mostly cells close together (as a cloth's lanes are), some spread.
            let spread = if round % 4 == 0 { 1.0 } else { 0.2 };
            let centre = [dims.x, dims.y, dims.z].map(&mut next);
            let cells: [[i32; 8]; 3] = std::array::from_fn(|a| {
                let d = [dims.x, dims.y, dims.z][a] as i32;
                let r = ((d as f32 * spread) as i32).max(1);
                std::array::from_fn(|_| (centre[a] + next(2 * r as u32) - r).clamp(0, d - 1))
            });
            let lanes = next(256) as u32;
            let want =
                lanes_of(lanes).all(|m| bricks.all_far([0, 1, 2].map(|a| cells[a][m] as usize)));
            assert_eq!(
                bricks.all_far_lanes(&cells, lanes),
                want,
                "{cells:?} {lanes:b}"
            );
            (far, near) = (far + want as u32, near + !want as u32);
        }
        assert!(far > 100 && near > 100, "{far} far, {near} near");
        assert!(!FarBricks::default().all_far_lanes(&[[0; 8]; 3], 1));
        assert!(FarBricks::default().all_far_lanes(&[[0; 8]; 3], 0));
    }
}
