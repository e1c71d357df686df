//! The springs' forces eight particles at a time (`wide::f32x8`), with the same bits as
//! [`Links`] read one particle at a time.
//!
//! [`Links`] lists each particle's springs in quads, four springs per step. Here the
//! particles go in blocks of eight, one particle per lane, and a block's springs in *slots*:
//! slot `4q + l` holds spring `l` of quad `q` of each of the eight particles. Each lane thus
//! sees its particle's springs in the order [`Links`] has them, and sums them into four
//! accumulators (one per `l`) added up as `(a0 + a1) + (a2 + a3)`, the order the quad's
//! horizontal sum takes: same forces, to the bit, as the per-particle code.
//!
//! Positions are read from plain `x`, `y`, `z` arrays (structure of arrays). On a grid the
//! eight particles of a block away from the edges have their `k`-th neighbours side by side
//! too, so a slot's other ends are one load per axis (a *run*), not eight.

use super::springs::{Links, SpringLaw};
use wide::{CmpGe, CmpGt, f32x8};

/// Particles per block (lanes of `f32x8`).
pub const LANES: usize = 8;

/// Lengths below this count as zero when normalising a spring (as in `cpu`).
const TINY: f32 = 1e-20;

/// Spring `l` of quad `q` of the eight particles of a block.
#[derive(Clone, Copy, Debug)]
struct Slot {
    /// The other ends, one per lane.
    other: [u32; LANES],
    /// `other[0]` when the other ends are consecutive (one load per axis), else `u32::MAX`.
    run: u32,
    rest: f32x8,
    k_stretch: f32x8,
    k_compress: f32x8,
}

/// [`Links`] regrouped by blocks of eight particles (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct Blocks {
    law: SpringLaw,
    /// The particles this was built for (the arrays hold them rounded up to [`LANES`]).
    particles: usize,
    /// Block b's slots are `slots[offsets[b]..offsets[b + 1]]`.
    offsets: Vec<u32>,
    slots: Vec<Slot>,
}

/// Particle positions as structure of arrays, padded to a whole number of blocks.
#[derive(Clone, Debug, Default)]
pub struct Lanes {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
}

impl Lanes {
    /// The first `n` rounded up to [`LANES`], zero beyond `n`.
    pub fn resize(&mut self, n: usize) {
        let len = n.div_ceil(LANES) * LANES;
        for a in [&mut self.x, &mut self.y, &mut self.z] {
            a.clear();
            a.resize(len, 0.0);
        }
    }
}

#[inline(always)]
fn load(a: &[f32], at: usize) -> f32x8 {
    f32x8::new(a[at..at + LANES].try_into().expect("a block of 8"))
}

impl Blocks {
    /// Regroups `links` (padding lanes point at their own particle with rest length and
    /// constants 0, as [`Links`] pads its quads: they add exactly zero).
    pub fn build(links: &Links, n: usize) -> Self {
        let blocks = n.div_ceil(LANES);
        let mut offsets = Vec::with_capacity(blocks + 1);
        let mut slots = Vec::new();
        offsets.push(0);
        for b in 0..blocks {
            let first = b * LANES;
            let quads = |i: usize| if i < n { links.of(i) } else { &[] };
            let depth = (first..first + LANES)
                .map(|i| quads(i).len())
                .max()
                .unwrap_or(0);
            for q in 0..depth {
                for l in 0..4 {
                    let mut s = Slot {
                        other: std::array::from_fn(|m| (first + m) as u32),
                        run: u32::MAX,
                        rest: f32x8::ZERO,
                        k_stretch: f32x8::ZERO,
                        k_compress: f32x8::ZERO,
                    };
                    let (mut rest, mut ks, mut kc) = ([0.0; LANES], [0.0; LANES], [0.0; LANES]);
                    for m in 0..LANES {
                        if let Some(quad) = quads(first + m).get(q) {
                            s.other[m] = quad.other[l];
                            rest[m] = quad.rest[l];
                            ks[m] = quad.k_stretch[l];
                            kc[m] = quad.k_compress[l];
                        }
                    }
                    if (1..LANES).all(|m| s.other[m] == s.other[0] + m as u32)
                        && (s.other[0] as usize + LANES) <= blocks * LANES
                    {
                        s.run = s.other[0];
                    }
                    (s.rest, s.k_stretch, s.k_compress) = (rest.into(), ks.into(), kc.into());
                    slots.push(s);
                }
            }
            offsets.push(slots.len() as u32);
        }
        Blocks {
            law: links.law,
            particles: n,
            offsets,
            slots,
        }
    }

    /// Whether this was built for `n` particles (a checkpoint leaves it empty).
    pub fn fits(&self, n: usize) -> bool {
        self.particles == n && self.offsets.len() == n.div_ceil(LANES) + 1
    }

    /// The spring forces on block `b`'s particles (x, y, z, lane by lane), and a bit per
    /// lane whose particle has a spring longer than `max_stretch` times its rest length.
    #[inline(always)]
    pub fn forces(&self, b: usize, at: &Lanes, max_stretch: f32) -> ([[f32; LANES]; 3], u32) {
        if self.law == SpringLaw::Quadratic {
            self.forces_by::<true>(b, at, max_stretch)
        } else {
            self.forces_by::<false>(b, at, max_stretch)
        }
    }

    /// [`Blocks::forces`]; `QUAD` picks T eq. 1's law.
    #[inline(always)]
    fn forces_by<const QUAD: bool>(
        &self,
        b: usize,
        at: &Lanes,
        max_stretch: f32,
    ) -> ([[f32; LANES]; 3], u32) {
        let first = b * LANES;
        let (px, py, pz) = (load(&at.x, first), load(&at.y, first), load(&at.z, first));
        let mut acc = [[f32x8::ZERO; 3]; 4];
        let mut over = f32x8::ZERO;
        let limit = f32x8::splat(max_stretch);
        let slots = &self.slots[self.offsets[b] as usize..self.offsets[b + 1] as usize];
        for (s, slot) in slots.iter().enumerate() {
            let (ox, oy, oz) = if slot.run != u32::MAX {
                let o = slot.run as usize;
                (load(&at.x, o), load(&at.y, o), load(&at.z, o))
            } else {
                let gather = |a: &[f32]| {
                    let mut v = [0.0; LANES];
                    for (v, &o) in v.iter_mut().zip(&slot.other) {
                        *v = a[o as usize];
                    }
                    f32x8::new(v)
                };
                (gather(&at.x), gather(&at.y), gather(&at.z))
            };
            let (dx, dy, dz) = (ox - px, oy - py, oz - pz);
            let len = (dx * dx + dy * dy + dz * dz).sqrt();
            let e = len - slot.rest;
            let k = e.cmp_ge(f32x8::ZERO).blend(slot.k_stretch, slot.k_compress);
            let mut c = k * e / len.max(f32x8::splat(TINY));
            if QUAD {
                c *= e.abs();
            }
            let a = &mut acc[s % 4];
            a[0] += c * dx;
            a[1] += c * dy;
            a[2] += c * dz;
            over |= len.cmp_gt(slot.rest * limit);
        }
        let sum = |axis: usize| {
            ((acc[0][axis] + acc[1][axis]) + (acc[2][axis] + acc[3][axis])).to_array()
        };
        ([sum(0), sum(1), sum(2)], over.move_mask() as u32)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloth::{ClothParams, ClothSim, Material, Shape, StiffnessMode};
    use glam::Vec3;

    /// The blocks give the per-particle forces ([`ClothSim::forces`]) to the bit, on a grid
    /// whose rows do not fill whole blocks, for both laws, with the particles jostled.
    #[test]
    fn same_bits_as_one_particle_at_a_time() {
        for (material, mode) in [
            (
                Material::Harada {
                    k_structural: 1e4,
                    k_shear: 5e3,
                    k_bend: Some(10.0),
                },
                StiffnessMode::Strain,
            ),
            (
                Material::Tokoi {
                    a_compress: 3.0,
                    b_stretch: 40.0,
                    bend_c: 0.0,
                    anisotropy: None,
                },
                StiffnessMode::Force,
            ),
        ] {
            let mut params = ClothParams::new(
                Shape::Grid {
                    size: [1.0, 0.8],
                    resolution: [13, 7],
                    center: Vec3::ZERO,
                    normal: Vec3::Y,
                },
                material,
            );
            params.stiffness_mode = mode;
            let mut sim = ClothSim::from_assets(&params, &Default::default()).unwrap();
            let n = sim.len();
            let jostled: Vec<Vec3> = sim
                .positions()
                .iter()
                .enumerate()
                .map(|(i, p)| {
                    let h = |k: usize| ((i * 7 + k * 13) % 11) as f32 / 11.0 - 0.5;
                    *p + 0.02 * Vec3::new(h(0), h(1), h(2))
                })
                .collect();
            sim.set_positions(&jostled).unwrap();
            let blocks = Blocks::build(sim.links(), n);
            let mut at = Lanes::default();
            at.resize(n);
            for (i, p) in jostled.iter().enumerate() {
                (at.x[i], at.y[i], at.z[i]) = (p.x, p.y, p.z);
            }
            let want = sim.forces();
            for b in 0..n.div_ceil(LANES) {
                let ([fx, fy, fz], over) = blocks.forces(b, &at, 10.0);
                assert_eq!(over, 0);
                for m in 0..LANES.min(n - b * LANES) {
                    let f = want[b * LANES + m];
                    // Equal as numbers is equal bits here, but for the sign of a zero
                    // (`forces` adds the hinges' zero).
                    assert_eq!(
                        [fx[m], fy[m], fz[m]],
                        f.to_array(),
                        "particle {}",
                        b * LANES + m
                    );
                }
            }
        }
    }
}
