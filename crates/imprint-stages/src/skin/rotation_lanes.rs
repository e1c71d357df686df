//! Pass 0 of the particle skinning's substep eight particles at a time: each particle's
//! neighbourhood matrix A = Σ_j (x_j − x_i)(X_j − X_i)ᵀ, its rotation (one round of the
//! iteration from the last one) and its volume change det A / det B, with the same bits as
//! `particles::neighbourhood` and `particles::extract_rotation` one particle at a time.
//!
//! The particles go in blocks of eight, one per lane, and a block's neighbour entries in
//! *slots*: slot k holds entry k of each lane's list, so every lane sums its neighbours in the
//! order of its list. A lane whose list is shorter than the block's longest is padded with
//! itself at a zero rest offset: its term is +0, and adding +0 leaves a sum that started at +0
//! as it was, to the bit (such a sum is never −0).
//!
//! Each of glam's SSE2 operations that the per-particle code uses (cross and dot products,
//! the quaternion product, the normalisations, `Mat3A::from_quat`) is written out per lane
//! with its operations in glam's order, so the AVX2 build, eight lanes per instruction, gives
//! the per-particle bits (`tests::same_bits_as_one_particle_at_a_time`). Per particle and
//! substep this pass took about a third of the skinning's time one particle at a time, most
//! of it the 3-wide vector code of the neighbour sums and the iteration's shuffles.

use super::particles::JAC_RANGE;
use glam::{Mat3A, Quat, Vec3A};
#[cfg(target_arch = "x86_64")]
use imprint_core::lanes::avx::Avx;
use imprint_core::lanes::{F8, LANES, Lane, Wide, lanewise, mask};

/// The neighbour lists regrouped by blocks of eight particles (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct RotationLanes {
    /// The particles this was built for.
    particles: usize,
    /// Block b's slots are `others[offsets[b]..offsets[b + 1]]` (and `rest` alike).
    offsets: Vec<u32>,
    /// Per slot: each lane's neighbour (its own particle as padding).
    others: Vec<[u32; LANES]>,
    /// Per slot: each lane's rest offset X_j − X_i by axis (zero as padding).
    rest: Vec<[Lane; 3]>,
    /// Per block: each lane's rest determinant det B, and whether it has one (a
    /// neighbourhood that spans no volume at rest has J = 1).
    rest_det: Vec<(Lane, [bool; LANES])>,
}

/// Where a chunk of particles' results go (one entry per particle of the chunk).
pub struct Out<'a> {
    pub rot: &'a mut [Quat],
    pub half_rot: &'a mut [Mat3A],
    pub jac: &'a mut [f32],
}

/// One block's results, by lane.
struct Block<W> {
    rot: [W; 4],
    jac: W,
}

impl RotationLanes {
    /// The blocks of the CSR lists `nbr[start[i]..start[i + 1]]` with their rest offsets and
    /// the particles' rest determinants.
    pub fn build(start: &[u32], nbr: &[u32], rest_off: &[Vec3A], rest_det: &[Option<f32>]) -> Self {
        let n = start.len() - 1;
        let mut lanes = RotationLanes {
            particles: n,
            offsets: vec![0],
            ..Default::default()
        };
        for first in (0..n).step_by(LANES) {
            let own = |m: usize| (first + m).min(n - 1);
            let len = |m: usize| (start[own(m) + 1] - start[own(m)]) as usize;
            let slots = (0..LANES).map(len).max().unwrap_or(0);
            for k in 0..slots {
                let mut others = [0u32; LANES];
                let mut rest = [[0.0; LANES]; 3];
                for m in 0..LANES {
                    let i = own(m);
                    others[m] = i as u32;
                    if first + m < n && k < len(m) {
                        let e = start[i] as usize + k;
                        others[m] = nbr[e];
                        let r = rest_off[e];
                        (rest[0][m], rest[1][m], rest[2][m]) = (r.x, r.y, r.z);
                    }
                }
                lanes.others.push(others);
                lanes.rest.push(rest);
            }
            lanes.offsets.push(lanes.others.len() as u32);
            let det = |m: usize| rest_det[own(m)];
            lanes.rest_det.push((
                std::array::from_fn(|m| det(m).unwrap_or(1.0)),
                std::array::from_fn(|m| det(m).is_some()),
            ));
        }
        lanes
    }

    /// Whether this was built for `n` particles (a checkpoint leaves it empty).
    pub fn fits(&self, n: usize) -> bool {
        self.particles == n && self.offsets.len() == n.div_ceil(LANES) + 1
    }

    /// The particles `first..first + out.jac.len()` (`first` a whole number of blocks): their
    /// rotations one round on from `rot` (only with `corotated`; `out.rot` and
    /// `out.half_rot` are left as they are otherwise) and their volume changes, from the
    /// positions `x`. AVX2 instructions where the processor has them (decided once per
    /// process), the same bits either way.
    pub fn chunk(&self, first: usize, x: &[Vec3A], rot: &[Quat], corotated: bool, out: Out) {
        assert!(self.fits(x.len()) && rot.len() == x.len() && first.is_multiple_of(LANES));
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl") {
            // SAFETY: the CPU has AVX-512F and VL (checked just above), and so AVX2.
            return unsafe { self.chunk_avx512(first, x, rot, corotated, out) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { self.chunk_avx2(first, x, rot, corotated, out) };
        }
        self.chunk_by(F8([0.0; LANES]), first, x, rot, corotated, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn chunk_avx2(&self, first: usize, x: &[Vec3A], rot: &[Quat], corotated: bool, out: Out) {
        // SAFETY: compiled for (and called only on) a CPU with AVX2.
        let w = unsafe { Avx::first() };
        self.chunk_by(w, first, x, rot, corotated, out)
    }

    /// The AVX2 build's instructions with AVX-512's 32 vector registers: the nine sums of
    /// the neighbour loop and the iteration's terms spill from AVX2's 16.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl")]
    fn chunk_avx512(&self, first: usize, x: &[Vec3A], rot: &[Quat], corotated: bool, out: Out) {
        // SAFETY: as in `chunk_avx2`.
        let w = unsafe { Avx::first() };
        self.chunk_by(w, first, x, rot, corotated, out)
    }

    /// [`RotationLanes::chunk`] in lanes of `W` (`w`: any value of it).
    #[inline(always)]
    fn chunk_by<W: Wide>(
        &self,
        w: W,
        first: usize,
        x: &[Vec3A],
        rot: &[Quat],
        corotated: bool,
        out: Out,
    ) {
        for (k, jac) in out.jac.chunks_mut(LANES).enumerate() {
            let at = k * LANES;
            let b = self.block(w, first / LANES + k, x, rot, corotated);
            jac.copy_from_slice(&b.jac.lanes()[..jac.len()]);
            if !corotated {
                continue;
            }
            // ½ R, as `Mat3A::from_quat(q) * 0.5` (by columns).
            let mut half = from_quat(b.rot);
            for v in half.as_flattened_mut() {
                *v = *v * w.splat(0.5);
            }
            let (rot, half_rot) = (&mut out.rot[at..], &mut out.half_rot[at..]);
            if jac.len() == LANES {
                let (q, h) = (rot.as_mut_ptr(), half_rot.as_mut_ptr());
                // SAFETY: `rot` and `half_rot` hold this block's eight particles (a full
                // block), whose quaternions and columns are four floats.
                unsafe {
                    W::scatter(lanewise(|m| q.add(m).cast()), b.rot);
                    for (c, [hx, hy, hz]) in half.into_iter().enumerate() {
                        let col = lanewise(|m| (&raw mut *h.add(m)).cast::<f32>().add(4 * c));
                        W::scatter(col, [hx, hy, hz, w.splat(0.0)]);
                    }
                }
                continue;
            }
            let q = b.rot.map(W::lanes);
            let half = half.map(|c| c.map(W::lanes));
            for m in 0..jac.len() {
                rot[m] = Quat::from_array(q.map(|c| c[m]));
                half_rot[m] = Mat3A::from_cols_array_2d(&half.map(|c| c.map(|v| v[m])));
            }
        }
    }

    /// Block `b`'s rotations (`rot` where not `corotated`) and volume changes.
    #[inline(always)]
    fn block<W: Wide>(
        &self,
        w: W,
        b: usize,
        x: &[Vec3A],
        rot: &[Quat],
        corotated: bool,
    ) -> Block<W> {
        let n = self.particles;
        let own = lanewise(|m| (b * LANES + m).min(n - 1) as u32);
        // SAFETY (the gathers): every index is a particle's (the lists' neighbours and the
        // blocks' own particles, below `particles`, which `chunk` checked against the
        // arrays' lengths).
        let [px, py, pz, _] = unsafe { w.gather(x, &own, 0) };
        // Columns: a[c] = Σ_j (x_j − x_i) r_c.
        let zero = w.splat(0.0);
        let mut a = [[zero; 3]; 3];
        let slots = self.offsets[b] as usize..self.offsets[b + 1] as usize;
        for (others, r) in self.others[slots.clone()].iter().zip(&self.rest[slots]) {
            let [qx, qy, qz, _] = unsafe { w.gather(x, others, 0) };
            let d = [qx - px, qy - py, qz - pz];
            for (ac, rc) in a.iter_mut().zip(r) {
                let rc = w.load(rc);
                for (ack, dk) in ac.iter_mut().zip(d) {
                    *ack = *ack + dk * rc;
                }
            }
        }
        let q = unsafe { w.gather(rot, &own, 0) };
        let rot = if corotated {
            extract_one_round(a, q)
        } else {
            q
        };
        // det A / det B, bounded, as the per-particle pass (J = 1 without a det B).
        let (det, has) = &self.rest_det[b];
        let j = (dot(a[0], cross(a[1], a[2])) / w.load(det)).clamp(JAC_RANGE.0, JAC_RANGE.1);
        let has = w.mask(&lanewise(|m| mask(has[m])));
        Block {
            rot,
            jac: W::select(has, j, w.splat(1.0)),
        }
    }
}

/// glam's `Vec3A::cross`: `(a.y b.z − a.z b.y, …)`, each product then the difference.
#[inline(always)]
fn cross<W: Wide>(a: [W; 3], b: [W; 3]) -> [W; 3] {
    [
        a[1] * b[2] - b[1] * a[2],
        a[2] * b[0] - b[2] * a[0],
        a[0] * b[1] - b[0] * a[1],
    ]
}

/// glam's `Vec3A::dot`: `(x + y) + z` of the products.
#[inline(always)]
pub(super) fn dot<W: Wide>(a: [W; 3], b: [W; 3]) -> W {
    (a[0] * b[0] + a[1] * b[1]) + a[2] * b[2]
}

#[inline(always)]
fn add<W: Wide>(a: [W; 3], b: [W; 3]) -> [W; 3] {
    [a[0] + b[0], a[1] + b[1], a[2] + b[2]]
}

/// glam's `Mat3A::from_quat`, by columns.
#[inline(always)]
fn from_quat<W: Wide>([x, y, z, w]: [W; 4]) -> [[W; 3]; 3] {
    let one = x.splat(1.0);
    let (x2, y2, z2) = (x + x, y + y, z + z);
    let (xx, xy, xz) = (x * x2, x * y2, x * z2);
    let (yy, yz, zz) = (y * y2, y * z2, z * z2);
    let (wx, wy, wz) = (w * x2, w * y2, w * z2);
    [
        [one - (yy + zz), xy + wz, xz - wy],
        [xy - wz, one - (xx + zz), yz + wx],
        [xz + wy, yz - wx, one - (xx + yy)],
    ]
}

/// glam's `Vec4::normalize` (and so `Quat::normalize`): each component over the length,
/// the squares summed as `(x + z) + (y + w)`.
#[inline(always)]
fn normalize<W: Wide>(v: [W; 4]) -> [W; 4] {
    let len = ((v[0] * v[0] + v[2] * v[2]) + (v[1] * v[1] + v[3] * v[3])).sqrt();
    [v[0] / len, v[1] / len, v[2] / len, v[3] / len]
}

/// glam's SSE2 `Quat * Quat` (`l r`): per component, the sum of the `w` and `x` terms plus
/// the sum of the `y` and `z` terms, each pair in that order (a sign by ±1 is exact).
#[inline(always)]
fn quat_mul<W: Wide>([lx, ly, lz, lw]: [W; 4], [rx, ry, rz, rw]: [W; 4]) -> [W; 4] {
    [
        (lx * rw + lw * rx) + (ly * rz - lz * ry),
        (lw * ry - lx * rz) + (ly * rw + lz * rx),
        (lx * ry + lw * rz) + (lz * rw - ly * rx),
        (lw * rw - lx * rx) + (-(lz * rz) - ly * ry),
    ]
}

/// `particles::extract_rotation(a, q, 1)`: one round of the iteration from `q` (columns `a`).
#[inline(always)]
fn extract_one_round<W: Wide>(a: [[W; 3]; 3], q: [W; 4]) -> [W; 4] {
    let r = from_quat(q);
    let num = add(add(cross(r[0], a[0]), cross(r[1], a[1])), cross(r[2], a[2]));
    let den = ((dot(r[0], a[0]) + dot(r[1], a[1])) + dot(r[2], a[2])).abs() + q[0].splat(1e-20);
    let w = [num[0] / den, num[1] / den, num[2] / den];
    let half = q[0].splat(0.5);
    let step = normalize([half * w[0], half * w[1], half * w[2], q[0].splat(1.0)]);
    let next = normalize(quat_mul(step, q));
    // The iteration stops where the turn is negligible (`q` as it was).
    let stop = dot(w, w).lt(q[0].splat(1e-18));
    let pick = |k: usize| W::select(stop, q[k], next[k]);
    [pick(0), pick(1), pick(2), pick(3)]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skin::particles::{extract_rotation, neighbourhood};

    type Build = unsafe fn(&RotationLanes, usize, &[Vec3A], &[Quat], bool, Out);

    /// The builds of [`RotationLanes::chunk`] this processor can run.
    fn builds() -> Vec<Build> {
        let mut builds: Vec<Build> =
            vec![|s, f, x, r, c, o| s.chunk_by(F8([0.0; LANES]), f, x, r, c, o)];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                builds.push(RotationLanes::chunk_avx2);
            }
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl")
            {
                builds.push(RotationLanes::chunk_avx512);
            }
        }
        builds
    }

    /// Irregular lists (0 to 13 neighbours, a last block of 3 particles), positions turned
    /// and squeezed, rotations from all over the sphere: every lane gives the per-particle
    /// code's rotation, half matrix and volume change to the bit, in every build.
    #[test]
    fn same_bits_as_one_particle_at_a_time() {
        let n = 43;
        let h = |i: usize, k: usize| ((i * 7919 + k * 104729) % 1000) as f32 / 1000.0 - 0.5;
        let rest: Vec<Vec3A> = (0..n)
            .map(|i| Vec3A::new(h(i, 0), h(i, 1), h(i, 2)))
            .collect();
        let turn =
            Mat3A::from_rotation_y(0.7) * Mat3A::from_diagonal(glam::Vec3::new(1.1, 0.8, 1.0));
        let x: Vec<Vec3A> = rest
            .iter()
            .enumerate()
            .map(|(i, &p)| turn * p + 0.01 * Vec3A::new(h(i, 3), h(i, 4), h(i, 5)))
            .collect();
        let (mut start, mut nbr) = (vec![0u32], Vec::new());
        for i in 0..n {
            nbr.extend((1..=(i * 5) % 14).map(|k| ((i + 3 * k) % n) as u32));
            start.push(nbr.len() as u32);
        }
        let rest_off: Vec<Vec3A> = (0..n)
            .flat_map(|i| (start[i]..start[i + 1]).map(move |e| (i, e as usize)))
            .map(|(i, e)| rest[nbr[e] as usize] - rest[i])
            .collect();
        let list = |i: usize| start[i] as usize..start[i + 1] as usize;
        let rest_det: Vec<Option<f32>> = (0..n)
            .map(|i| {
                let b = neighbourhood(&rest, &nbr[list(i)], &rest_off[list(i)], i);
                (i % 5 != 0).then(|| b.determinant())
            })
            .collect();
        let rot: Vec<Quat> = (0..n)
            .map(|i| Quat::from_xyzw(h(i, 6), h(i, 7), h(i, 8), h(i, 9) + 0.2).normalize())
            .collect();
        let lanes = RotationLanes::build(&start, &nbr, &rest_off, &rest_det);
        for (build, corotated) in builds().into_iter().flat_map(|b| [(b, true), (b, false)]) {
            let mut q = vec![Quat::IDENTITY; n];
            let mut hr = vec![Mat3A::ZERO; n];
            let mut jac = vec![0.0; n];
            for (c, ((q, hr), jac)) in q
                .chunks_mut(16)
                .zip(hr.chunks_mut(16))
                .zip(jac.chunks_mut(16))
                .enumerate()
            {
                let out = Out {
                    rot: q,
                    half_rot: hr,
                    jac,
                };
                // SAFETY: `builds` lists only what the processor has.
                unsafe { build(&lanes, c * 16, &x, &rot, corotated, out) };
            }
            for i in 0..n {
                let a = neighbourhood(&x, &nbr[list(i)], &rest_off[list(i)], i);
                // Without corotated springs the rotations are left as they were.
                let (want, want_hr) = if corotated {
                    let q = extract_rotation(&a, rot[i], 1);
                    (q, Mat3A::from_quat(q) * 0.5)
                } else {
                    (Quat::IDENTITY, Mat3A::ZERO)
                };
                assert_eq!(
                    q[i].to_array().map(f32::to_bits),
                    want.to_array().map(f32::to_bits),
                    "particle {i}"
                );
                assert_eq!(
                    hr[i].to_cols_array().map(f32::to_bits),
                    want_hr.to_cols_array().map(f32::to_bits)
                );
                let want_j = match rest_det[i] {
                    Some(b) => (a.determinant() / b).clamp(JAC_RANGE.0, JAC_RANGE.1),
                    None => 1.0,
                };
                assert_eq!(jac[i].to_bits(), want_j.to_bits(), "particle {i}");
            }
        }
    }
}
