//! The contact with a body read from one unsigned field (a body that did not change during
//! the frame, so there is no blend in time), [`LANES`] particles at a time: the bits of
//! [`contact::signed_sample`] followed by [`contact::respond`].
//!
//! One particle at a time, a field read is a chain of dependent steps (a division, the
//! cell's index, its loads, eight additions in order, a square root) and the response another
//! (a square root and a division), with branches on which side the particle is and whether it
//! touches that follow no order a predictor can learn (a cloth resting on a body jitters about
//! ε). Here the lanes go side by side ([`FieldView::sample_lanes`]), every case is computed
//! with the scalar code's operations in its order and selected, and the loops over the lanes
//! are compiled for AVX2 where the processor has it (decided once per process, as in
//! `imprint_core::closest`): the same bits, which the unit tests check.
//!
//! [`contact::signed_sample`]: super::contact::signed_sample
//! [`contact::respond`]: super::contact::respond

use super::lanes::LANES;
use super::sampler::FieldView;

type Lanes = [f32; LANES];

/// What the contact of [`LANES`] particles with one body reads.
#[derive(Clone, Copy, Debug, Default)]
pub struct Touch {
    /// The particles' new positions, and where they were at the substep's start.
    pub x: [Lanes; 3],
    pub from: [Lanes; 3],
    /// The particles' memory of this body: the outward direction at their last sample
    /// (xyz), and w = 1 when known.
    pub side: [Lanes; 4],
    /// The lanes that take part (a particle, not pinned).
    pub live: [bool; LANES],
}

/// What the contact did, lane by lane.
#[derive(Clone, Copy, Debug, Default)]
pub struct Touched {
    /// The new positions (unchanged where there was no hit).
    pub x: [Lanes; 3],
    /// The new memory (w = 1), where `remember` is set.
    pub side: [Lanes; 3],
    pub remember: [bool; LANES],
    /// Pushed out to ε; of those, found inside; and how deep (ε − signed distance).
    pub hit: [bool; LANES],
    pub inside: [bool; LANES],
    pub depth: Lanes,
}

/// Reads `view` at the lanes' new positions and responds, as
/// [`super::contact::signed_sample`] (an unsigned field, no blend) and then
/// [`super::contact::respond`] do one particle at a time.
#[inline]
pub fn touch_unsigned(view: &FieldView, t: &Touch, eps: f32, friction: f32) -> Touched {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { touch_avx2(view, t, eps, friction) };
    }
    touch_lanes(view, t, eps, friction)
}

/// [`touch_lanes`] compiled for AVX2: the same operations, eight lanes per instruction.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn touch_avx2(view: &FieldView, t: &Touch, eps: f32, friction: f32) -> Touched {
    touch_lanes(view, t, eps, friction)
}

#[inline(always)]
fn touch_lanes(view: &FieldView, t: &Touch, eps: f32, friction: f32) -> Touched {
    let (d, [vx, vy, vz]) = view.sample_lanes(&t.x);
    let ([x0, y0, z0], [fx, fy, fz]) = (&t.x, &t.from);
    let [sx, sy, sz, sw] = &t.side;
    let mut out = Touched::default();
    for m in 0..LANES {
        // `classify` without a sign: a vector and a finite distance, else no sample; the
        // particle crossed when the vector runs along its remembered outward direction and
        // the surface is within reach (its own step plus 2ε).
        let some = vx[m] != 0.0 || vy[m] != 0.0 || vz[m] != 0.0;
        let valid = t.live[m] & d[m].is_finite() & some;
        let (dx, dy, dz) = (x0[m] - fx[m], y0[m] - fy[m], z0[m] - fz[m]);
        let reach = 2.0 * eps + (dx * dx + dy * dy + dz * dz).sqrt();
        let along_memory = vx[m] * sx[m] + vy[m] * sy[m] + vz[m] * sz[m];
        let crossed = (sw[m] > 0.0) & (along_memory > 0.0) & (d[m] < reach);
        let distance = if crossed { -d[m] } else { d[m] };
        let (ox, oy, oz) = if crossed {
            (vx[m], vy[m], vz[m])
        } else {
            (-vx[m], -vy[m], -vz[m])
        };
        // `respond`: the memory, then a push to ε along the outward direction normalised
        // (`try_normalize`: none unless 1 / length is a positive finite number), friction.
        let rcp = 1.0 / (ox * ox + oy * oy + oz * oz).sqrt();
        let hit = valid & (distance < eps) & rcp.is_finite() & (rcp > 0.0);
        let (nx, ny, nz) = (ox * rcp, oy * rcp, oz * rcp);
        let push = eps - distance;
        let (mut px, mut py, mut pz) = (x0[m] + push * nx, y0[m] + push * ny, z0[m] + push * nz);
        if friction > 0.0 {
            let (qx, qy, qz) = (px - fx[m], py - fy[m], pz - fz[m]);
            let along = qx * nx + qy * ny + qz * nz;
            px -= friction * (qx - along * nx);
            py -= friction * (qy - along * ny);
            pz -= friction * (qz - along * nz);
        }
        out.x[0][m] = if hit { px } else { x0[m] };
        out.x[1][m] = if hit { py } else { y0[m] };
        out.x[2][m] = if hit { pz } else { z0[m] };
        (out.side[0][m], out.side[1][m], out.side[2][m]) = (ox, oy, oz);
        out.remember[m] = valid;
        out.hit[m] = hit;
        out.inside[m] = hit & (distance < 0.0);
        out.depth[m] = push;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloth::contact::{self, Collider};
    use glam::{UVec3, Vec3, Vec4};
    use imprint_core::{DistanceField, GridSpec};

    /// A deterministic generator of uniform numbers in [0, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        fn vec(&mut self) -> Vec3 {
            Vec3::new(self.next(), self.next(), self.next()) - 0.5
        }
    }

    /// Eight particles at a time give the per-particle contact's positions, memories and
    /// counts to the bit, and the field reads its samples: particles in the band on both
    /// sides of a sphere, at its band's edge, far, in the grid's outermost cells and off the
    /// grid, with and without a memory, pinned, with and without friction.
    #[test]
    fn same_bits_as_one_particle_at_a_time() {
        let (r, eps) = (0.3, 0.02);
        let spec = GridSpec::new(Vec3::splat(-0.39), 0.02, UVec3::splat(40)).unwrap();
        let field = DistanceField::from_closest_points(spec, 3.0, |p| {
            r * p.try_normalize().unwrap_or(Vec3::X)
        });
        let view = FieldView::new(&field);
        let collider = Collider {
            start: None,
            end: view,
            span: (0.0, 1.0),
        };
        let mut rng = Rng(0x9e3779b97f4a7c15);
        let (mut hits, mut crossed) = (0, 0);
        for round in 0..4000 {
            let mut t = Touch::default();
            for m in 0..LANES {
                // Mostly within the band around the sphere; some anywhere, some off the grid.
                let x = match round % 4 {
                    0 => rng.vec() * 1.2,
                    _ => rng.vec().normalize_or(Vec3::Y) * (r + 0.12 * (rng.next() - 0.5)),
                };
                let from = x + rng.vec() * 0.03;
                let side = rng.vec().extend((rng.next() > 0.3) as u32 as f32);
                for a in 0..3 {
                    (t.x[a][m], t.from[a][m]) = (x[a], from[a]);
                }
                for a in 0..4 {
                    t.side[a][m] = side[a];
                }
                t.live[m] = rng.next() > 0.1;
            }
            let (d, v) = view.sample_lanes(&t.x);
            let friction = if round % 2 == 0 { 0.3 } else { 0.0 };
            let lanes = touch_unsigned(&view, &t, eps, friction);
            // The build without AVX2 (the same loops, as the processor's baseline runs them).
            let plain = touch_lanes(&view, &t, eps, friction);
            let all_bits = |o: &Touched| {
                let f = |a: &[Lanes]| a.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
                (
                    f(&o.x),
                    f(&o.side),
                    o.remember,
                    o.hit,
                    o.inside,
                    f(&[o.depth]),
                )
            };
            assert_eq!(all_bits(&lanes), all_bits(&plain));
            for m in 0..LANES {
                let x = Vec3::new(t.x[0][m], t.x[1][m], t.x[2][m]);
                let from = Vec3::new(t.from[0][m], t.from[1][m], t.from[2][m]);
                let f = view.sample(x);
                assert_eq!(d[m].to_bits(), f.distance.to_bits(), "{x}");
                let bits = |v: Vec3| v.to_array().map(f32::to_bits);
                assert_eq!(bits(Vec3::new(v[0][m], v[1][m], v[2][m])), bits(f.vector));
                // The scalar path: sample, then respond.
                let mut side = Vec4::new(t.side[0][m], t.side[1][m], t.side[2][m], t.side[3][m]);
                let mut y = x;
                let sample = t.live[m]
                    .then(|| contact::signed_sample(&collider, x, from, 1.0, side, eps))
                    .flatten();
                let hit = sample.and_then(|s| {
                    crossed += (s.distance < 0.0) as u32;
                    contact::respond(&mut y, from, &s, &mut side, eps, friction)
                });
                assert_eq!(lanes.remember[m], sample.is_some(), "{x}");
                if lanes.remember[m] {
                    let got = Vec3::new(lanes.side[0][m], lanes.side[1][m], lanes.side[2][m]);
                    assert_eq!(bits(got), bits(side.truncate()), "{x}");
                }
                assert_eq!(lanes.hit[m], hit.is_some(), "{x}");
                let got = Vec3::new(lanes.x[0][m], lanes.x[1][m], lanes.x[2][m]);
                assert_eq!(bits(got), bits(y), "{x}");
                if let Some(h) = hit {
                    hits += 1;
                    assert_eq!(lanes.depth[m].to_bits(), h.depth.to_bits());
                    assert_eq!(lanes.inside[m], h.inside);
                }
            }
        }
        // The cases were met: contacts, and particles found across the surface.
        assert!(
            hits > 1000 && crossed > 100,
            "{hits} hits, {crossed} crossed"
        );
    }
}
