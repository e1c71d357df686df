//! Pass 1 of the particle skinning's substep eight particles at a time: each pair's force
//! term from its lower end, with the same bits as `ParticleSkin::pair_forces` one pair at a
//! time.
//!
//! The particles go in blocks of eight, one per lane, and a block's own pairs (those with
//! j > i, in list order) in *slots*: slot k holds pair k of each lane. A lane with fewer pairs
//! than the block's most is padded with its own particle, and its result is written nowhere.
//! The operations per lane are glam's SSE2 ones in their order (as in [`super::rotation_lanes`]),
//! so the AVX2 builds give the per-pair bits (`tests::same_bits_as_one_pair_at_a_time`). One
//! pair at a time this pass took about a third of the skinning's time: a pair reads 16 floats
//! of its other end (position, velocity, half rotation, volume change) in 3-wide vectors.

use super::rotation_lanes::dot;
use glam::{Mat3A, Vec3A};
#[cfg(target_arch = "x86_64")]
use imprint_core::lanes::avx::Avx;
use imprint_core::lanes::{F8, LANES, Lane, Wide, lanewise};

/// The particles' own pairs regrouped by blocks of eight particles (see the module docs).
#[derive(Clone, Debug, Default)]
pub struct PairLanes {
    /// The particles this was built for.
    particles: usize,
    /// Block b's slots are `others[offsets[b]..offsets[b + 1]]` (and the others alike).
    offsets: Vec<u32>,
    /// Per slot: each lane's other end (its own particle as padding).
    others: Vec<[u32; LANES]>,
    /// Per slot: each lane's pair (its index in the pair forces; `u32::MAX` as padding).
    pairs: Vec<[u32; LANES]>,
    /// Per slot: each lane's rest offset X_j − X_i by axis, and rest length.
    rest: Vec<[Lane; 3]>,
    rest_len: Vec<Lane>,
}

/// The state a pair's force reads, one entry per particle.
#[derive(Clone, Copy)]
pub struct State<'a> {
    pub x: &'a [Vec3A],
    pub ve: &'a [Vec3A],
    pub half_rot: &'a [Mat3A],
    pub jac: &'a [f32],
}

/// The force's constants: stiffness, damping, pressure (k_v) and which spring.
#[derive(Clone, Copy)]
pub struct Law {
    pub ks: f32,
    pub cs: f32,
    pub kv: f32,
    pub corotated: bool,
}

impl PairLanes {
    /// The blocks of the CSR lists `nbr[start[i]..start[i + 1]]` (own pairs from
    /// `upper[i]`, numbered from `pair_start[i]`), with their rest offsets and lengths.
    pub fn build(
        [start, upper, pair_start, nbr]: [&[u32]; 4],
        rest_off: &[Vec3A],
        rest_len: &[f32],
    ) -> Self {
        let n = start.len() - 1;
        let mut lanes = PairLanes {
            particles: n,
            offsets: vec![0],
            ..Default::default()
        };
        for first in (0..n).step_by(LANES) {
            let own = |m: usize| (first + m).min(n - 1);
            let len = |m: usize| (start[own(m) + 1] - upper[own(m)]) as usize;
            for k in 0..(0..LANES).map(len).max().unwrap_or(0) {
                let mut others = [0u32; LANES];
                let mut pairs = [u32::MAX; LANES];
                let (mut rest, mut rl) = ([[0.0; LANES]; 3], [0.0; LANES]);
                for m in 0..LANES {
                    let i = own(m);
                    others[m] = i as u32;
                    if first + m < n && k < len(m) {
                        let e = upper[i] as usize + k;
                        (others[m], pairs[m], rl[m]) =
                            (nbr[e], pair_start[i] + k as u32, rest_len[e]);
                        let r = rest_off[e];
                        (rest[0][m], rest[1][m], rest[2][m]) = (r.x, r.y, r.z);
                    }
                }
                lanes.others.push(others);
                lanes.pairs.push(pairs);
                lanes.rest.push(rest);
                lanes.rest_len.push(rl);
            }
            lanes.offsets.push(lanes.others.len() as u32);
        }
        lanes
    }

    /// Whether this was built for `n` particles (a checkpoint leaves it empty).
    pub fn fits(&self, n: usize) -> bool {
        self.particles == n && self.offsets.len() == n.div_ceil(LANES) + 1
    }

    /// The own pairs of particles `first..first + count` (`first` a whole number of blocks)
    /// into `out`, which holds pairs `base..` (pair p at `out[p − base]`). AVX2 instructions
    /// where the processor has them (decided once per process), the same bits either way.
    pub fn chunk(&self, [first, count, base]: [usize; 3], s: State, law: Law, out: &mut [Vec3A]) {
        let n = s.x.len();
        assert!(self.fits(n) && s.ve.len() == n && s.half_rot.len() == n && s.jac.len() == n);
        assert!(first.is_multiple_of(LANES) && first + count <= n);
        let at = [first, count, base];
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl") {
            // SAFETY: the CPU has AVX-512F and VL (checked just above), and so AVX2.
            return unsafe { self.chunk_avx512(at, s, law, out) };
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { self.chunk_avx2(at, s, law, out) };
        }
        self.chunk_by(F8([0.0; LANES]), at, s, law, out)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn chunk_avx2(&self, at: [usize; 3], s: State, law: Law, out: &mut [Vec3A]) {
        // SAFETY: compiled for (and called only on) a CPU with AVX2.
        let w = unsafe { Avx::first() };
        self.chunk_by(w, at, s, law, out)
    }

    /// The AVX2 build's instructions with AVX-512's 32 vector registers (a pair's terms
    /// spill from AVX2's 16).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx512f,avx512vl")]
    fn chunk_avx512(&self, at: [usize; 3], s: State, law: Law, out: &mut [Vec3A]) {
        // SAFETY: as in `chunk_avx2`.
        let w = unsafe { Avx::first() };
        self.chunk_by(w, at, s, law, out)
    }

    /// [`PairLanes::chunk`] in lanes of `W` (`w`: any value of it).
    #[inline(always)]
    fn chunk_by<W: Wide>(
        &self,
        w: W,
        [first, count, base]: [usize; 3],
        s: State,
        law: Law,
        out: &mut [Vec3A],
    ) {
        let mut sink = [Vec3A::ZERO];
        let (sink, len, to) = (sink.as_mut_ptr(), out.len(), out.as_mut_ptr());
        for b in first / LANES..(first + count).div_ceil(LANES) {
            let own = lanewise(|m| (b * LANES + m).min(self.particles - 1) as u32);
            let end = Particle::gather(w, &s, &own, law);
            for k in self.offsets[b] as usize..self.offsets[b + 1] as usize {
                let [fx, fy, fz] = self.pair(w, k, &s, &end, law);
                let pairs = &self.pairs[k];
                let to = lanewise(|m| match pairs[m] {
                    u32::MAX => sink.cast(),
                    p => {
                        let i = p as usize - base;
                        assert!(i < len, "a lane's pair lies in `out`");
                        // SAFETY: `i` is in `out` (just checked).
                        unsafe { to.add(i) }.cast()
                    }
                });
                // SAFETY: every pointer is to a `Vec3A` (four floats) in `out` or `sink`.
                unsafe { W::scatter(to, [fx, fy, fz, w.splat(0.0)]) };
            }
        }
    }

    /// Slot `k`'s pair forces (the lower ends' `end`).
    #[inline(always)]
    fn pair<W: Wide>(&self, w: W, k: usize, s: &State, end: &Particle<W>, law: Law) -> [W; 3] {
        let others = &self.others[k];
        // SAFETY (the gathers): the other ends are particles (`build`), whose count `chunk`
        // checked against the arrays' lengths.
        let [xx, xy, xz, _] = unsafe { w.gather(s.x, others, 0) };
        let [vx, vy, vz, _] = unsafe { w.gather(s.ve, others, 0) };
        let dx = [xx - end.x[0], xy - end.x[1], xz - end.x[2]];
        let dv = [vx - end.v[0], vy - end.v[1], vz - end.v[2]];
        let jj = unsafe { w.gather1(s.jac, others) };
        let p = (end.p + w.splat(0.5 * law.kv) * jj) - w.splat(law.kv);
        let (ks, cs) = (w.splat(law.ks), w.splat(law.cs));
        let (f, zero) = if law.corotated {
            let d2 = dot(dx, dx);
            let inv = w.splat(1.0) / d2.sqrt();
            let nrm = [dx[0] * inv, dx[1] * inv, dx[2] * inv];
            // ½(R_i + R_j) (X_j − X_i), columns summed as `Mat3A::mul_vec3a` does.
            let mut off = [w.splat(0.0); 3];
            for (c, rc) in self.rest[k].iter().enumerate() {
                let rc = w.load(rc);
                let hj = unsafe { w.gather(s.half_rot, others, c) };
                for (o, (&hi, hj)) in off.iter_mut().zip(end.half_rot[c].iter().zip(hj)) {
                    let term = (hi + hj) * rc;
                    *o = if c == 0 { term } else { *o + term };
                }
            }
            let damp = cs * dot(dv, nrm);
            let f = |c: usize| (ks * (dx[c] - off[c]) + p * dx[c]) + damp * nrm[c];
            ([f(0), f(1), f(2)], d2.le(w.splat(0.0)))
        } else {
            let d = dot(dx, dx).sqrt();
            let nrm = [dx[0] / d, dx[1] / d, dx[2] / d];
            let sp = ks * (d - w.load(&self.rest_len[k])) + cs * dot(dv, nrm);
            let f = |c: usize| sp * nrm[c] + p * dx[c];
            ([f(0), f(1), f(2)], d.le(w.splat(0.0)))
        };
        // Coincident ends: no force (as one pair at a time).
        let z = |c: usize| W::select(zero, w.splat(0.0), f[c]);
        [z(0), z(1), z(2)]
    }
}

/// A block's lower ends: positions, velocities, their pressure term ½ k_v J_i and half
/// rotation matrices (by column; zero unless corotated).
struct Particle<W> {
    x: [W; 3],
    v: [W; 3],
    p: W,
    half_rot: [[W; 4]; 3],
}

impl<W: Wide> Particle<W> {
    #[inline(always)]
    fn gather(w: W, s: &State, own: &[u32; LANES], law: Law) -> Self {
        // SAFETY: the block's own particles, below the arrays' lengths (`chunk`).
        unsafe {
            let [x0, x1, x2, _] = w.gather(s.x, own, 0);
            let [v0, v1, v2, _] = w.gather(s.ve, own, 0);
            let mut half_rot = [[w.splat(0.0); 4]; 3];
            if law.corotated {
                for (c, h) in half_rot.iter_mut().enumerate() {
                    *h = w.gather(s.half_rot, own, c);
                }
            }
            Particle {
                x: [x0, x1, x2],
                v: [v0, v1, v2],
                p: w.splat(0.5 * law.kv) * w.gather1(s.jac, own),
                half_rot,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat3A, Quat};

    type Build = unsafe fn(&PairLanes, [usize; 3], State, Law, &mut [Vec3A]);

    /// The builds of [`PairLanes::chunk`] this processor can run.
    fn builds() -> Vec<Build> {
        let mut builds: Vec<Build> =
            vec![|l, at, s, law, out| l.chunk_by(F8([0.0; LANES]), at, s, law, out)];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                builds.push(PairLanes::chunk_avx2);
            }
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl")
            {
                builds.push(PairLanes::chunk_avx512);
            }
        }
        builds
    }

    /// One pair's term as the per-pair code computed it (glam's SSE2 vectors, one pair at a
    /// time): the reference.
    fn one_pair(s: &State, law: Law, i: usize, j: usize, r: Vec3A, rl: f32) -> Vec3A {
        let (ks, cs, kv) = (law.ks, law.cs, law.kv);
        let hkv = 0.5 * kv;
        let dx = s.x[j] - s.x[i];
        let p = (hkv * s.jac[i] + hkv * s.jac[j]) - kv;
        let dv = s.ve[j] - s.ve[i];
        if law.corotated {
            let d2 = dx.length_squared();
            if d2 <= 0.0 {
                return Vec3A::ZERO;
            }
            let nrm = dx * d2.sqrt().recip();
            let off = (s.half_rot[i] + s.half_rot[j]) * r;
            ks * (dx - off) + p * dx + (cs * dv.dot(nrm)) * nrm
        } else {
            let d = dx.length();
            if d <= 0.0 {
                return Vec3A::ZERO;
            }
            let nrm = dx / d;
            (ks * (d - rl) + cs * dv.dot(nrm)) * nrm + p * dx
        }
    }

    /// Irregular symmetric lists (0 to 9 own pairs, a last block of 3 particles, two
    /// particles on the same spot), both springs, in every build: each pair's term equals
    /// the per-pair code's to the bit.
    #[test]
    fn same_bits_as_one_pair_at_a_time() {
        let n = 43;
        let h = |i: usize, k: usize| ((i * 7919 + k * 104729) % 1000) as f32 / 1000.0 - 0.5;
        let v = |i: usize, k: usize| Vec3A::new(h(i, k), h(i, k + 1), h(i, k + 2));
        let mut x: Vec<Vec3A> = (0..n).map(|i| v(i, 0)).collect();
        x[17] = x[5];
        let rest: Vec<Vec3A> = x
            .iter()
            .enumerate()
            .map(|(i, &p)| p + 0.05 * v(i, 3))
            .collect();
        let mut lists = vec![Vec::new(); n];
        for i in 0..n {
            for k in 1..=(i * 5) % 10 {
                let j = (i + 2 * k + 1) % n;
                if j != i && !lists[i].contains(&(j as u32)) {
                    lists[i].push(j as u32);
                    lists[j].push(i as u32);
                }
            }
        }
        lists[5].push(17);
        lists[17].push(5);
        let (mut start, mut nbr, mut upper, mut pair_start) =
            (vec![0u32], vec![], vec![], vec![0u32]);
        for (i, l) in lists.iter_mut().enumerate() {
            l.sort_unstable();
            upper.push(nbr.len() as u32 + l.partition_point(|&j| (j as usize) < i) as u32);
            nbr.extend_from_slice(l);
            start.push(nbr.len() as u32);
            pair_start.push(pair_start[i] + start[i + 1] - upper[i]);
        }
        let entry = |i: usize| (start[i]..start[i + 1]).map(move |e| (i, e as usize));
        let rest_off: Vec<Vec3A> = (0..n)
            .flat_map(entry)
            .map(|(i, e)| rest[nbr[e] as usize] - rest[i])
            .collect();
        let rest_len: Vec<f32> = rest_off.iter().map(|r| r.length()).collect();
        let ve: Vec<Vec3A> = (0..n).map(|i| v(i, 6)).collect();
        let half_rot: Vec<Mat3A> = (0..n)
            .map(|i| {
                Mat3A::from_quat(Quat::from_xyzw(h(i, 9), h(i, 10), h(i, 11), 0.7).normalize())
                    * 0.5
            })
            .collect();
        let jac: Vec<f32> = (0..n).map(|i| 1.0 + h(i, 12)).collect();
        let s = State {
            x: &x,
            ve: &ve,
            half_rot: &half_rot,
            jac: &jac,
        };
        let lanes = PairLanes::build([&start, &upper, &pair_start, &nbr], &rest_off, &rest_len);
        for corotated in [true, false] {
            let law = Law {
                ks: 4e4,
                cs: 20.0,
                kv: 4e4,
                corotated,
            };
            for build in builds() {
                let mut out = vec![Vec3A::splat(f32::NAN); pair_start[n] as usize];
                for lo in (0..n).step_by(16) {
                    let hi = (lo + 16).min(n);
                    let (a, b) = (pair_start[lo] as usize, pair_start[hi] as usize);
                    // SAFETY: `builds` lists only what the processor has.
                    unsafe { build(&lanes, [lo, hi - lo, a], s, law, &mut out[a..b]) };
                }
                for i in 0..n {
                    for e in upper[i] as usize..start[i + 1] as usize {
                        let p = pair_start[i] as usize + e - upper[i] as usize;
                        let want = one_pair(&s, law, i, nbr[e] as usize, rest_off[e], rest_len[e]);
                        assert_eq!(
                            out[p].to_array().map(f32::to_bits),
                            want.to_array().map(f32::to_bits),
                            "pair {p} ({i}, {}), corotated {corotated}",
                            nbr[e]
                        );
                    }
                }
            }
        }
    }
}
