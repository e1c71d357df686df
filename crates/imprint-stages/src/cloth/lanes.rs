//! The springs' forces eight particles at a time, with the same bits as [`Links`] read one
//! particle at a time.
//!
//! [`Links`] lists each particle's springs in quads, four springs per step. Here the
//! particles go in blocks of eight, one particle per lane, and a block's springs in *slots*:
//! slot `4q + l` holds spring `l` of quad `q` of each of the eight particles. Each lane thus
//! sees its particle's springs in the order [`Links`] has them, and sums them into four
//! accumulators (one per `l`) added up as `(a0 + a1) + (a2 + a3)`, the order the quad's
//! horizontal sum takes: same forces, to the bit, as the per-particle code.
//!
//! The lanes are plain arrays in loops that vectorise, so that the cloth's substep, compiled
//! for AVX2 where the processor has it (`cpu`), takes them eight per instruction.
//!
//! Positions are read from plain `x`, `y`, `z` arrays (structure of arrays). On a grid the
//! eight particles of a block away from the edges have their `k`-th neighbours side by side
//! too, so a slot's other ends are one load per axis (a *run*), not eight.

use super::springs::{LinkQuad, Links, SpringLaw};
use glam::{Vec3, Vec4};
use std::collections::HashMap;

pub use imprint_core::lanes::{
    LANES, Lane, bool_bits, lane_bits, lane_vec, lanes_of, lanewise, mask, select,
};

/// Lengths below this count as zero when normalising a spring (as in `cpu`).
const TINY: f32 = 1e-20;

/// Spring `l` of quad `q` of the eight particles of a block: where its other ends and its
/// constants are. Twelve bytes: a substep reads every block's slots, and with the lanes'
/// ends and constants in each slot they were 136 bytes, most of what it streamed from
/// memory per particle; a cloth has few distinct constants (a grid: one set per kind of
/// spring and edge), kept once in [`Blocks`].
#[derive(Clone, Copy, Debug)]
struct Slot {
    /// The first other end when they are consecutive (one load per axis), else `u32::MAX`.
    run: u32,
    /// The other ends, one per lane: `Blocks::others[other]`.
    other: u32,
    /// The lanes' rest lengths and constants: `Blocks::constants[constants]`.
    constants: u32,
}

/// The rest lengths and constants of a slot's springs, one per lane.
#[derive(Clone, Copy, Debug, Default)]
struct Constants {
    rest: Lane,
    k_stretch: Lane,
    k_compress: Lane,
}

impl Constants {
    /// Every value's bits: equal sets are equal bits (a slot shares a set only if so).
    fn bits(&self) -> [u32; 3 * LANES] {
        let mut bits = [0u32; 3 * LANES];
        let values = [self.rest, self.k_stretch, self.k_compress];
        for (b, v) in bits.iter_mut().zip(values.iter().flatten()) {
            *b = v.to_bits();
        }
        bits
    }
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
    /// The slots' other ends, one array per slot that is not a run.
    others: Vec<[u32; LANES]>,
    /// The slots' distinct constants.
    constants: Vec<Constants>,
}

/// A build of the spring forces on a block ([`Blocks::forces_fn`]).
pub type ForcesFn = unsafe fn(&Blocks, usize, &Lanes, f32) -> ([Lane; 3], u32);

/// Particle positions as structure of arrays, padded to a whole number of blocks.
#[derive(Clone, Debug, Default)]
pub struct Lanes {
    pub x: Vec<f32>,
    pub y: Vec<f32>,
    pub z: Vec<f32>,
}

impl Lanes {
    /// Particle `i`'s position.
    #[inline(always)]
    pub fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.x[i], self.y[i], self.z[i])
    }

    /// The xyz of `points` (padded as [`Lanes::resize`] pads).
    pub fn set_from(&mut self, points: &[Vec4]) {
        self.resize(points.len());
        for (i, p) in points.iter().enumerate() {
            (self.x[i], self.y[i], self.z[i]) = (p.x, p.y, p.z);
        }
    }

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
fn load(a: &[f32], at: usize) -> Lane {
    a[at..at + LANES].try_into().expect("a block of 8")
}

/// `a[at..at + 8]` in an AVX register.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn load8(a: &[f32], at: usize) -> std::arch::x86_64::__m256 {
    let v = &a[at..at + LANES];
    // SAFETY: `v` holds eight floats.
    unsafe { std::arch::x86_64::_mm256_loadu_ps(v.as_ptr()) }
}

/// Defines `$name`, [`Blocks::forces_by`] in AVX2 instructions compiled with `$features`
/// enabled: the AVX2 build, and the same instructions with AVX-512's 32 registers (one body,
/// two builds; `forces_fn` picks).
#[cfg(target_arch = "x86_64")]
macro_rules! forces_simd {
    ($(#[$doc:meta])* $name:ident, $features:literal) => {
        $(#[$doc])*
        #[target_feature(enable = $features)]
        fn $name(&self, b: usize, at: &Lanes, max_stretch: f32) -> ([Lane; 3], u32) {
            use std::arch::x86_64::*;
            let quadratic = self.law == SpringLaw::Quadratic;
            let first = b * LANES;
            let p = [
                load8(&at.x, first),
                load8(&at.y, first),
                load8(&at.z, first),
            ];
            let (zero, tiny) = (_mm256_setzero_ps(), _mm256_set1_ps(TINY));
            let (limit, sign) = (_mm256_set1_ps(max_stretch), _mm256_set1_ps(-0.0));
            let mut acc = [[zero; 3]; 4];
            let mut over = zero;
            let slots = &self.slots[self.offsets[b] as usize..self.offsets[b + 1] as usize];
            // Every slot's other ends are particles, and a run's eight lie within the blocks
            // (`Blocks::build`), which the positions cover: checked once here, so the loads
            // below need no check of their own.
            let len = at.x.len().min(at.y.len()).min(at.z.len());
            assert!(
                len >= self
                    .particles
                    .max(self.offsets.len().saturating_sub(1) * LANES)
            );
            let axes = [at.x.as_ptr(), at.y.as_ptr(), at.z.as_ptr()];
            for quad in slots.chunks_exact(4) {
                for (l, slot) in quad.iter().enumerate() {
                    // SAFETY: in bounds (the assertion above), the run's eight as the gathered;
                    // `Blocks::build`, which alone makes slots, gives each a gather index
                    // within `others` and a constants one within `constants`.
                    let o = unsafe {
                        if slot.run != u32::MAX {
                            let o = slot.run as usize;
                            axes.map(|a| _mm256_loadu_ps(a.add(o)))
                        } else {
                            // One gather per axis: eight loads and stores into lanes and a load
                            // back were the springs' costliest line (at 64², the edges).
                            let ends = self.others.get_unchecked(slot.other as usize);
                            let i = _mm256_loadu_si256(ends.as_ptr().cast());
                            axes.map(|a| _mm256_i32gather_ps::<4>(a, i))
                        }
                    };
                    // SAFETY: as above.
                    let consts = unsafe { self.constants.get_unchecked(slot.constants as usize) };
                    // (No `array::map` here: its closures are not inlined into AVX2 code.)
                    let d = [
                        _mm256_sub_ps(o[0], p[0]),
                        _mm256_sub_ps(o[1], p[1]),
                        _mm256_sub_ps(o[2], p[2]),
                    ];
                    let sq = |v| _mm256_mul_ps(v, v);
                    let len =
                        _mm256_sqrt_ps(_mm256_add_ps(_mm256_add_ps(sq(d[0]), sq(d[1])), sq(d[2])));
                    let rest = load8(&consts.rest, 0);
                    let e = _mm256_sub_ps(len, rest);
                    let k = _mm256_blendv_ps(
                        load8(&consts.k_compress, 0),
                        load8(&consts.k_stretch, 0),
                        _mm256_cmp_ps::<_CMP_GE_OQ>(e, zero),
                    );
                    // `maxps` gives the second operand when either is NaN, as `forces_by`.
                    let mut c = _mm256_div_ps(_mm256_mul_ps(k, e), _mm256_max_ps(len, tiny));
                    if quadratic {
                        c = _mm256_mul_ps(c, _mm256_andnot_ps(sign, e));
                    }
                    for (acc, d) in acc[l].iter_mut().zip(d) {
                        *acc = _mm256_add_ps(*acc, _mm256_mul_ps(c, d));
                    }
                    let long = _mm256_cmp_ps::<_CMP_GT_OQ>(len, _mm256_mul_ps(rest, limit));
                    over = _mm256_or_ps(over, long);
                }
            }
            let mut f = [[0.0f32; LANES]; 3];
            for (a, f) in f.iter_mut().enumerate() {
                let sum = _mm256_add_ps(
                    _mm256_add_ps(acc[0][a], acc[1][a]),
                    _mm256_add_ps(acc[2][a], acc[3][a]),
                );
                // SAFETY: `f` holds eight floats.
                unsafe { _mm256_storeu_ps(f.as_mut_ptr(), sum) };
            }
            (f, _mm256_movemask_ps(over) as u32)
        }
    };
}

impl Blocks {
    /// Regroups `links` (padding lanes point at their own particle with rest length and
    /// constants 0, as [`Links`] pads its quads: they add exactly zero).
    pub fn build(links: &Links, n: usize) -> Self {
        let blocks = n.div_ceil(LANES);
        let mut offsets = Vec::with_capacity(blocks + 1);
        let (mut slots, mut others, mut constants) = (Vec::new(), Vec::new(), Vec::new());
        // Each distinct set of constants once, found by its bits.
        let mut known: HashMap<[u32; 3 * LANES], u32> = HashMap::new();
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
                    let (other, c) = spring_of_lanes(first, |i| quads(i).get(q), l);
                    let run = (1..LANES).all(|m| other[m] == other[0] + m as u32)
                        && (other[0] as usize + LANES) <= blocks * LANES;
                    let constants_at = *known.entry(c.bits()).or_insert_with(|| {
                        constants.push(c);
                        constants.len() as u32 - 1
                    });
                    slots.push(Slot {
                        run: if run { other[0] } else { u32::MAX },
                        other: if run { u32::MAX } else { others.len() as u32 },
                        constants: constants_at,
                    });
                    if !run {
                        others.push(other);
                    }
                }
            }
            offsets.push(slots.len() as u32);
        }
        Blocks {
            law: links.law,
            particles: n,
            offsets,
            slots,
            others,
            constants,
        }
    }

    /// Slot `slot`'s other ends' positions: one load per axis for a run, else one lane at
    /// a time.
    #[inline(always)]
    fn other_ends(&self, slot: &Slot, at: &Lanes) -> [Lane; 3] {
        if slot.run != u32::MAX {
            let o = slot.run as usize;
            return [load(&at.x, o), load(&at.y, o), load(&at.z, o)];
        }
        let mut v = [[0.0f32; LANES]; 3];
        for (m, &i) in self.others[slot.other as usize].iter().enumerate() {
            let i = i as usize;
            (v[0][m], v[1][m], v[2][m]) = (at.x[i], at.y[i], at.z[i]);
        }
        v
    }

    /// Whether this was built for `n` particles (a checkpoint leaves it empty).
    pub fn fits(&self, n: usize) -> bool {
        self.particles == n && self.offsets.len() == n.div_ceil(LANES) + 1
    }

    /// The build of the spring forces this processor runs, picked once (a substep takes it
    /// for all its blocks; checked per block, the features were 1% of the cloth's
    /// instructions). The function gives the spring forces on block `b`'s particles (x, y,
    /// z, lane by lane), and a bit per lane whose particle has a spring longer than
    /// `max_stretch` times its rest length: AVX2 instructions where the processor has them,
    /// the same bits either way.
    ///
    /// Where it also has AVX-512 (F and VL), the same AVX2 instructions are compiled for it:
    /// its 32 vector registers hold the twelve accumulators that spill from AVX2's 16 (the
    /// instructions that address the stack fell from 83 to 41, and the springs' time against
    /// the rest of the substep by about a fifth).
    ///
    /// Calling the function is safe on this processor (it is why it was picked): `unsafe`
    /// only because the AVX builds are.
    pub fn forces_fn() -> ForcesFn {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl") {
            return Blocks::forces_avx512;
        }
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            return Blocks::forces_avx2;
        }
        |blocks, b, at, max_stretch| blocks.forces_portable(b, at, max_stretch)
    }

    /// The spring forces ([`Blocks::forces_fn`]) in plain Rust.
    #[inline(always)]
    fn forces_portable(&self, b: usize, at: &Lanes, max_stretch: f32) -> ([Lane; 3], u32) {
        if self.law == SpringLaw::Quadratic {
            self.forces_by::<true>(b, at, max_stretch)
        } else {
            self.forces_by::<false>(b, at, max_stretch)
        }
    }

    #[cfg(target_arch = "x86_64")]
    forces_simd!(
        /// [`Blocks::forces_by`] in AVX2 instructions: the same operations in the same order,
        /// and IEEE single precision gives their bits whatever the width (the compiler, left
        /// to vectorise the loops itself, mixed lanes and axes and gained nothing).
        forces_avx2,
        "avx2"
    );

    #[cfg(target_arch = "x86_64")]
    forces_simd!(
        /// [`Blocks::forces_avx2`] compiled for AVX-512F and VL: the same instructions, with
        /// 32 registers.
        forces_avx512,
        "avx2,avx512f,avx512vl"
    );

    /// The spring forces ([`Blocks::forces_fn`]); `QUAD` picks T eq. 1's law. A block's
    /// slots come four to a quad, spring `l` of each quad into accumulator `l`; the loops
    /// over the lanes vectorise.
    #[inline(always)]
    fn forces_by<const QUAD: bool>(
        &self,
        b: usize,
        at: &Lanes,
        max_stretch: f32,
    ) -> ([Lane; 3], u32) {
        let first = b * LANES;
        let p = [load(&at.x, first), load(&at.y, first), load(&at.z, first)];
        let mut acc = [[[0.0f32; LANES]; 3]; 4];
        let mut over = [false; LANES];
        let slots = &self.slots[self.offsets[b] as usize..self.offsets[b + 1] as usize];
        for quad in slots.chunks_exact(4) {
            for (l, slot) in quad.iter().enumerate() {
                let o = self.other_ends(slot, at);
                let k = &self.constants[slot.constants as usize];
                let (c, d) = spring_lanes::<QUAD>(&p, &o, k, max_stretch, &mut over);
                for (acc, d) in acc[l].iter_mut().zip(&d) {
                    for m in 0..LANES {
                        acc[m] += c[m] * d[m];
                    }
                }
            }
        }
        let mut f = [[0.0f32; LANES]; 3];
        for (a, f) in f.iter_mut().enumerate() {
            for m in 0..LANES {
                f[m] = (acc[0][a][m] + acc[1][a][m]) + (acc[2][a][m] + acc[3][a][m]);
            }
        }
        let mask = (0..LANES).fold(0, |mask, m| mask | (over[m] as u32) << m);
        (f, mask)
    }
}

impl Blocks {
    /// Half the potential energy of block `b`'s particles' springs at `at` (each spring is
    /// listed at both ends) and the largest |length / rest − 1| among them, lane by lane: what
    /// the frame pass measures, with the bits of the per-particle reference (`cpu`'s
    /// `spring_energy`, four springs per step and a horizontal sum). Compiled for AVX2
    /// where the processor has it (the same operations, so the same bits): one particle at a
    /// time, its gathers of `Vec4` positions made the energy a seventh of the springs' cost
    /// over a frame's 32 substeps, though it is measured once per frame.
    ///
    /// Without `strain` the strains are left at zero and their division per spring is not
    /// made (the frame pass reads the strain at the frame's end only).
    pub fn energy(&self, b: usize, at: &Lanes, strain: bool) -> (Lane, Lane) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { self.energy_avx2(b, at, strain) };
        }
        self.energy_portable(b, at, strain)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn energy_avx2(&self, b: usize, at: &Lanes, strain: bool) -> (Lane, Lane) {
        self.energy_portable(b, at, strain)
    }

    #[inline(always)]
    fn energy_portable(&self, b: usize, at: &Lanes, strain: bool) -> (Lane, Lane) {
        match (self.law == SpringLaw::Quadratic, strain) {
            (true, true) => self.energy_by::<true, true>(b, at),
            (true, false) => self.energy_by::<true, false>(b, at),
            (false, true) => self.energy_by::<false, true>(b, at),
            (false, false) => self.energy_by::<false, false>(b, at),
        }
    }

    /// [`Blocks::energy`]; `QUAD` picks T eq. 1's law. Spring `l` of each quad goes into
    /// accumulator `l`, summed as `(u0 + u1) + (u2 + u3)` and maxed as `max(max(s0, s2),
    /// max(s1, s3))` (SSE's horizontal sum and maximum, which the reference takes);
    /// `max` is SSE's (the second operand when either is NaN) throughout. Padding slots
    /// (rest and constants 0) add +0 to a sum that is never −0, and a strain of 0.
    #[inline(always)]
    // A lane indexes the positions, constants and sums alike.
    #[allow(clippy::needless_range_loop)]
    fn energy_by<const QUAD: bool, const STRAIN: bool>(
        &self,
        b: usize,
        at: &Lanes,
    ) -> (Lane, Lane) {
        let sse_max = |a: f32, b: f32| if a > b { a } else { b };
        let first = b * LANES;
        let p = [load(&at.x, first), load(&at.y, first), load(&at.z, first)];
        let (mut u, mut strain) = ([[0.0f32; LANES]; 4], [[0.0f32; LANES]; 4]);
        let slots = &self.slots[self.offsets[b] as usize..self.offsets[b + 1] as usize];
        for quad in slots.chunks_exact(4) {
            for (l, slot) in quad.iter().enumerate() {
                let o = self.other_ends(slot, at);
                let c = &self.constants[slot.constants as usize];
                for m in 0..LANES {
                    let d = [o[0][m] - p[0][m], o[1][m] - p[1][m], o[2][m] - p[2][m]];
                    let e = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() - c.rest[m];
                    let k = if e >= 0.0 {
                        c.k_stretch[m]
                    } else {
                        c.k_compress[m]
                    };
                    u[l][m] += if QUAD {
                        k * e.abs() * e * e * (0.5 / 3.0)
                    } else {
                        k * e * e * 0.25
                    };
                    if STRAIN {
                        let s = e.abs() / sse_max(c.rest[m], TINY);
                        strain[l][m] = sse_max(strain[l][m], s);
                    }
                }
            }
        }
        let (mut u_sum, mut worst) = ([0.0f32; LANES], [0.0f32; LANES]);
        for m in 0..LANES {
            u_sum[m] = (u[0][m] + u[1][m]) + (u[2][m] + u[3][m]);
            let (a, b) = (
                sse_max(strain[0][m], strain[2][m]),
                sse_max(strain[1][m], strain[3][m]),
            );
            worst[m] = sse_max(a, b);
        }
        (u_sum, worst)
    }
}

/// One slot's springs, lane by lane: the force's factor along the spring and the spring's
/// vector (so the force is factor times vector); sets `over` where a spring is longer than
/// `max_stretch` times its rest length. One operation at a time over the lanes, each a loop
/// that becomes one vector instruction (written as one loop per lane, the compiler
/// vectorised across the axes instead and shuffled).
#[inline(always)]
fn spring_lanes<const QUAD: bool>(
    p: &[Lane; 3],
    o: &[Lane; 3],
    slot: &Constants,
    max_stretch: f32,
    over: &mut [bool; LANES],
) -> (Lane, [Lane; 3]) {
    let d = [
        lanewise(|m| o[0][m] - p[0][m]),
        lanewise(|m| o[1][m] - p[1][m]),
        lanewise(|m| o[2][m] - p[2][m]),
    ];
    let [dx, dy, dz] = &d;
    let len = lanewise(|m| (dx[m] * dx[m] + dy[m] * dy[m] + dz[m] * dz[m]).sqrt());
    let e = lanewise(|m| len[m] - slot.rest[m]);
    let k = lanewise(|m| {
        if e[m] >= 0.0 {
            slot.k_stretch[m]
        } else {
            slot.k_compress[m]
        }
    });
    // `max` as SSE's: the second operand when either is NaN.
    let len_or_tiny = lanewise(|m| if len[m] > TINY { len[m] } else { TINY });
    let mut c = lanewise(|m| k[m] * e[m] / len_or_tiny[m]);
    if QUAD {
        c = lanewise(|m| c[m] * e[m].abs());
    }
    for m in 0..LANES {
        over[m] |= len[m] > slot.rest[m] * max_stretch;
    }
    (c, d)
}

/// Spring `l` of the quads `quad(i)` of particles `first..first + LANES`: the other ends and
/// constants, lane by lane; a particle with no such quad pads its lane (its own index,
/// constants 0: it adds exactly zero).
// A lane indexes the ends and every constant alike.
#[allow(clippy::needless_range_loop)]
fn spring_of_lanes<'a>(
    first: usize,
    quad: impl Fn(usize) -> Option<&'a LinkQuad>,
    l: usize,
) -> ([u32; LANES], Constants) {
    let mut other: [u32; LANES] = std::array::from_fn(|m| (first + m) as u32);
    let mut c = Constants::default();
    for m in 0..LANES {
        if let Some(quad) = quad(first + m) {
            other[m] = quad.other[l];
            c.rest[m] = quad.rest[l];
            c.k_stretch[m] = quad.k_stretch[l];
            c.k_compress[m] = quad.k_compress[l];
        }
    }
    (other, c)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloth::{ClothParams, ClothSim, Material, Shape, StiffnessMode};
    use glam::Vec3;

    /// The builds of the spring forces this processor can run.
    fn builds() -> Vec<ForcesFn> {
        let mut builds: Vec<ForcesFn> = vec![|s, b, at, max| s.forces_portable(b, at, max)];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx2") {
                builds.push(Blocks::forces_avx2);
            }
            if std::is_x86_feature_detected!("avx512f") && std::is_x86_feature_detected!("avx512vl")
            {
                builds.push(Blocks::forces_avx512);
            }
        }
        builds
    }

    /// A grid whose rows do not fill whole blocks, with its particles jostled, for each
    /// law: the cloth, its positions in lanes and as points.
    fn jostled_grids() -> Vec<(ClothSim, Lanes, Vec<Vec3>)> {
        let mut grids = Vec::new();
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
            let mut at = Lanes::default();
            at.resize(n);
            for (i, p) in jostled.iter().enumerate() {
                (at.x[i], at.y[i], at.z[i]) = (p.x, p.y, p.z);
            }
            grids.push((sim, at, jostled));
        }
        grids
    }

    /// The blocks give the per-particle forces ([`ClothSim::forces`]) to the bit, on
    /// [`jostled_grids`], in every build.
    #[test]
    fn same_bits_as_one_particle_at_a_time() {
        for (sim, at, _) in jostled_grids() {
            let n = sim.len();
            let blocks = Blocks::build(sim.links(), n);
            let want = sim.forces();
            // Every build the processor can run: plain Rust, AVX2 and AVX-512 (the
            // dispatcher picks only the widest).
            let builds = builds();
            for (b, &build) in
                (0..n.div_ceil(LANES)).flat_map(|b| builds.iter().map(move |f| (b, f)))
            {
                // SAFETY: `builds` lists only what the processor has.
                let ([fx, fy, fz], over) = unsafe { build(&blocks, b, &at, 10.0) };
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

    /// The blocks give the per-particle springs' energy and strain (`spring_energy`, the
    /// frame pass's reference) to the bit, on [`jostled_grids`] (stretched and compressed
    /// springs), in both builds.
    #[test]
    fn energy_same_bits_as_one_particle_at_a_time() {
        for (sim, at, points) in jostled_grids() {
            let n = sim.len();
            let blocks = Blocks::build(sim.links(), n);
            let pos: Vec<Vec4> = points.iter().map(|p| p.extend(1.0)).collect();
            // Particles whose springs have energy and strain (counted once, whatever the
            // builds): the jostle leaves none at rest.
            let mut strained = 0;
            for b in 0..n.div_ceil(LANES) {
                let mut builds = vec![blocks.energy_portable(b, &at, true)];
                #[cfg(target_arch = "x86_64")]
                if std::is_x86_feature_detected!("avx2") {
                    // SAFETY: the CPU has AVX2 (checked just above).
                    builds.push(unsafe { blocks.energy_avx2(b, &at, true) });
                }
                // Without the strains, the same energy.
                let (u_alone, no_strain) = blocks.energy(b, &at, false);
                assert_eq!(no_strain, [0.0; LANES]);
                assert_eq!(u_alone.map(f32::to_bits), builds[0].0.map(f32::to_bits));
                for (build, (u, strain)) in builds.into_iter().enumerate() {
                    for m in 0..LANES.min(n - b * LANES) {
                        let i = b * LANES + m;
                        let want = crate::cloth::cpu::spring_energy(i, sim.links(), &pos);
                        assert_eq!(
                            (u[m].to_bits(), strain[m].to_bits()),
                            (want.0.to_bits(), want.1.to_bits()),
                            "particle {i}"
                        );
                        strained += (build == 0 && want.0 > 0.0 && want.1 > 0.0) as usize;
                    }
                }
            }
            assert_eq!(strained, n, "particles with strained springs");
        }
    }
}
