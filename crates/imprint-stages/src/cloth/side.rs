//! The contacts' side memory (see [`super::contact`]): per particle and collider, the
//! outward direction at the particle's last sample (xyz) and w = 1 once known.
//!
//! Kept by blocks of [`LANES`] particles, each block's memory of a collider as four lanes
//! (x, y, z, w), the layout the block's contact reads and writes ([`super::contact_lanes`]):
//! one particle's `Vec4` at a time, moving it into the lanes and back cost a substep about
//! 16 instructions a particle, a twentieth of its work. The GPU cloth and the public API
//! keep one `Vec4` per particle and collider, particle-major ([`SideMemory::to_vec4s`]).

use super::lanes::{LANES, Lane};
use glam::Vec4;
use serde::{Deserialize, Serialize};

/// One block's memory of one collider: x, y, z, w, lane by lane.
pub type SideLanes = [Lane; 4];

/// The side memory of `n` particles and `colliders` colliders (at least one entry each).
#[derive(Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct SideMemory {
    /// The colliders it is laid out for (0 before any frame, which keeps one entry).
    colliders: usize,
    /// Block b's memory of collider c is `blocks[b * per_particle + c]`; lanes past the
    /// last particle stay zero.
    blocks: Vec<SideLanes>,
}

impl Clone for SideMemory {
    fn clone(&self) -> Self {
        SideMemory {
            colliders: self.colliders,
            blocks: self.blocks.clone(),
        }
    }

    /// Keeps the allocation (a frame saves the memory into a backup every time).
    fn clone_from(&mut self, source: &Self) {
        self.colliders = source.colliders;
        self.blocks.clone_from(&source.blocks);
    }
}

impl SideMemory {
    /// Nothing known, for `n` particles and `colliders` colliders.
    pub fn new(n: usize, colliders: usize) -> Self {
        SideMemory {
            colliders,
            blocks: vec![[[0.0; LANES]; 4]; n.div_ceil(LANES) * colliders.max(1)],
        }
    }

    /// From one `Vec4` per particle and collider, particle-major (as the GPU keeps it);
    /// `None` unless `side` holds `n × colliders.max(1)` of them.
    pub fn from_vec4s(side: &[Vec4], n: usize, colliders: usize) -> Option<Self> {
        let mut out = Self::new(n, colliders);
        if side.len() != n * out.per_particle() {
            return None;
        }
        for (i, entries) in side.chunks_exact(out.per_particle()).enumerate() {
            for (c, &v) in entries.iter().enumerate() {
                out.set(i, c, v);
            }
        }
        Some(out)
    }

    /// One `Vec4` per particle (of the first `n`) and collider, particle-major.
    pub fn to_vec4s(&self, n: usize) -> Vec<Vec4> {
        (0..n)
            .flat_map(|i| (0..self.per_particle()).map(move |c| self.get(i, c)))
            .collect()
    }

    /// Forgets everything (the layout stays).
    pub fn clear(&mut self) {
        self.blocks.iter_mut().for_each(|b| *b = [[0.0; LANES]; 4]);
    }

    /// Particle `i`'s memory of collider `c`.
    #[inline(always)]
    pub fn get(&self, i: usize, c: usize) -> Vec4 {
        let (b, m) = (&self.blocks[i / LANES * self.per_particle() + c], i % LANES);
        Vec4::new(b[0][m], b[1][m], b[2][m], b[3][m])
    }

    /// Sets particle `i`'s memory of collider `c`.
    #[inline(always)]
    pub fn set(&mut self, i: usize, c: usize, v: Vec4) {
        let at = i / LANES * self.per_particle() + c;
        let (b, m) = (&mut self.blocks[at], i % LANES);
        for (a, v) in v.to_array().into_iter().enumerate() {
            b[a][m] = v;
        }
    }

    /// Block `b`'s memory of collider `c`.
    #[inline(always)]
    pub fn block(&self, b: usize, c: usize) -> &SideLanes {
        &self.blocks[b * self.per_particle() + c]
    }

    /// The blocks, in runs of `blocks` blocks (each with all its colliders) for parallel
    /// chunks of particles: `blocks × LANES` particles a run.
    pub fn runs_mut(&mut self, blocks: usize) -> rayon::slice::ChunksMut<'_, SideLanes> {
        use rayon::prelude::*;
        let run = blocks * self.per_particle();
        self.blocks.par_chunks_mut(run)
    }

    /// Entries per particle (the colliders, at least one).
    pub fn per_particle(&self) -> usize {
        self.colliders.max(1)
    }

    /// The colliders it is laid out for (0 before any frame).
    pub fn colliders(&self) -> usize {
        self.colliders
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A distinct value per particle, collider and component.
    fn value(i: usize, c: usize) -> Vec4 {
        let b = (i * 10 + c) as f32;
        Vec4::new(b + 0.25, b + 0.5, -b, 1.0)
    }

    /// 21 particles (not whole blocks) and 3 colliders: each set entry reads back, the
    /// others stay zero, and the particle-major form goes there and back unchanged.
    #[test]
    fn entries_read_back_and_round_trip() {
        let (n, nf) = (21, 3);
        let mut side = SideMemory::new(n, nf);
        assert_eq!(side.per_particle(), 3);
        for i in (0..n).step_by(2) {
            for c in 0..nf {
                side.set(i, c, value(i, c));
            }
        }
        for i in 0..n {
            for c in 0..nf {
                let want = if i % 2 == 0 { value(i, c) } else { Vec4::ZERO };
                assert_eq!(side.get(i, c), want, "particle {i}, collider {c}");
            }
        }
        let flat = side.to_vec4s(n);
        assert_eq!(flat.len(), n * nf);
        assert_eq!(flat[4 * nf + 2], value(4, 2));
        assert_eq!(SideMemory::from_vec4s(&flat, n, nf), Some(side.clone()));
        // Lane 2 of block 2 is particle 18.
        assert_eq!(side.block(2, 1)[2][2], value(18, 1).z);
        side.clear();
        assert!(side.to_vec4s(n).iter().all(|v| *v == Vec4::ZERO));
    }

    /// No collider still keeps one entry a particle; a wrong length is refused.
    #[test]
    fn layout_counts() {
        let side = SideMemory::new(9, 0);
        assert_eq!((side.colliders(), side.per_particle()), (0, 1));
        assert_eq!(side.to_vec4s(9).len(), 9);
        assert!(SideMemory::from_vec4s(&[Vec4::ONE; 17], 9, 2).is_none());
        assert!(SideMemory::from_vec4s(&[Vec4::ONE; 18], 9, 2).is_some());
    }
}
