//! Closest points on triangles, [`LANES`] (point, triangle) pairs at a time, bit for bit the
//! results of [`closest_point_on_triangle`] followed by `(q - p).length_squared()`.
//!
//! The voxeliser (a triangle against its candidate cells), the field's refinement (a cell
//! against its candidate triangles) and the field's per-cell vectors spend most of their time
//! there, and the scalar function's region branches mispredict on nearly every call. Here
//! every lane computes all of Ericson's regions with the same operations in the same order
//! (Rust never fuses or reorders float operations) and selects the first that applies, as the
//! scalar `return`s do, so the loop over lanes vectorises and the results keep their bits.
//! The rare collinear triangle that reaches the scalar fallback is redone by the scalar
//! function.
//!
//! Thirty-two lanes at a time: the kernel's chains of operations are short and dependent, so
//! four independent AVX registers per quantity keep the units busy (on the bunny's field,
//! 8 → 32 lanes took the voxeliser 7.2 → 6.5 ms and the field 11.1 → 9.2 ms), and where the
//! CPU has AVX-512 the kernel is compiled for it: its 32 vector registers spare the spills of
//! AVX's 16 (LLVM still picks 256-bit operations; same operations, same bits).

use crate::geom::closest_point_on_triangle;
use glam::Vec3;

/// Pairs per batch: four AVX registers.
pub const LANES: usize = 32;

type Lanes = [f32; LANES];

/// [`LANES`] (point, triangle) pairs in structure-of-arrays form, set lane by lane and
/// evaluated together. A caller may keep lanes across evaluations: the field's refinement
/// keeps a group of cells and changes only their triangles.
#[derive(Clone, Default)]
pub struct Pairs {
    p: [Lanes; 3],
    tri: [[Lanes; 3]; 3],
}

/// What [`Pairs::closest`] gives per lane: the closest point `q` and `|q - p|²`, written into
/// a value the caller keeps. Returned by value, it was built in a struct of its own and
/// copied out: 512 bytes through `memcpy` for every 32 pairs, 1.3% of a one-thread field
/// build's samples.
#[derive(Default)]
pub struct Closest {
    pub q: [Lanes; 3],
    pub d2: Lanes,
    /// The scalar function's collinear fallback applies: redo the lane with it.
    degenerate: [bool; LANES],
}

impl Pairs {
    /// The point of lane `l`.
    #[inline(always)]
    pub fn set_point(&mut self, l: usize, p: Vec3) {
        for (axis, v) in p.to_array().into_iter().enumerate() {
            self.p[axis][l] = v;
        }
    }

    /// The triangle of lane `l`.
    #[inline(always)]
    pub fn set_triangle(&mut self, l: usize, tri: &[Vec3; 3]) {
        for (corner, v) in tri.iter().enumerate() {
            for (axis, x) in v.to_array().into_iter().enumerate() {
                self.tri[corner][axis][l] = x;
            }
        }
    }

    /// Lane `l`'s triangle is `faces[idx[l]]`, for every lane. Where the CPU has AVX, eight
    /// triangles are loaded whole and transposed into the lanes with shuffles (the lane by
    /// lane copy is nine scalar stores per lane, and took half the field refinement's time
    /// outside the kernel); the same values either way.
    #[inline]
    pub fn set_triangles(&mut self, faces: &[[Vec3; 3]], idx: &[u32; LANES]) {
        // Every lane tested, no early exit, so the test vectorises (a compare per vector).
        let len = faces.len().min(u32::MAX as usize) as u32;
        assert!(idx.iter().fold(true, |ok, &n| ok & (n < len)));
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx") {
            // SAFETY: the CPU has AVX (checked just above); every index is in `faces`.
            return unsafe { self.set_triangles_avx(faces, idx) };
        }
        for (l, &n) in idx.iter().enumerate() {
            self.set_triangle(l, &faces[n as usize]);
        }
    }

    /// [`Pairs::set_triangles`] eight lanes at a time: the first eight floats of each
    /// triangle (a, b, c.x, c.y) as one load per lane, an 8×8 transpose, and c.z lane by lane.
    ///
    /// # Safety
    /// The CPU has AVX, and every index is in `faces`.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    unsafe fn set_triangles_avx(&mut self, faces: &[[Vec3; 3]], idx: &[u32; LANES]) {
        use std::arch::x86_64::*;
        const { assert!(std::mem::size_of::<[Vec3; 3]>() == 36) };
        let base = faces.as_ptr().cast::<f32>();
        for g in 0..LANES / 8 {
            let lanes = g * 8..g * 8 + 8;
            // SAFETY: each index is in `faces` (the caller's promise), so the 8 floats read
            // from a face's start lie within its 9; stores go to 8 lanes of a live array.
            unsafe {
                let row = |k: usize| _mm256_loadu_ps(base.add(idx[g * 8 + k] as usize * 9));
                let (r0, r1, r2, r3) = (row(0), row(1), row(2), row(3));
                let (r4, r5, r6, r7) = (row(4), row(5), row(6), row(7));
                let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
                let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
                let (t4, t5) = (_mm256_unpacklo_ps(r4, r5), _mm256_unpackhi_ps(r4, r5));
                let (t6, t7) = (_mm256_unpacklo_ps(r6, r7), _mm256_unpackhi_ps(r6, r7));
                let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
                let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
                let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
                let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
                let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
                let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
                let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
                let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
                // Float k of every lane's triangle: corner k / 3, axis k % 3.
                let floats = [
                    _mm256_permute2f128_ps::<0x20>(u0, u4),
                    _mm256_permute2f128_ps::<0x20>(u1, u5),
                    _mm256_permute2f128_ps::<0x20>(u2, u6),
                    _mm256_permute2f128_ps::<0x20>(u3, u7),
                    _mm256_permute2f128_ps::<0x31>(u0, u4),
                    _mm256_permute2f128_ps::<0x31>(u1, u5),
                    _mm256_permute2f128_ps::<0x31>(u2, u6),
                    _mm256_permute2f128_ps::<0x31>(u3, u7),
                ];
                for (k, v) in floats.into_iter().enumerate() {
                    let dst = &mut self.tri[k / 3][k % 3][lanes.clone()];
                    _mm256_storeu_ps(dst.as_mut_ptr(), v);
                }
                for l in lanes {
                    self.tri[2][2][l] = *base.add(idx[l] as usize * 9 + 8);
                }
            }
        }
    }

    /// Every lane's closest point and squared distance into `out`, the scalar function's
    /// bits (a lane the kernel cannot take is redone by the scalar function).
    #[inline]
    pub fn closest(&self, out: &mut Closest) {
        kernel(&self.p, &self.tri, out);
        // Nearly never: one test of all lanes (no early exit, so it vectorises) first.
        let any = out.degenerate.iter().fold(false, |any, &d| any | d);
        for l in (0..LANES).filter(|&l| any && out.degenerate[l]) {
            let p = Vec3::new(self.p[0][l], self.p[1][l], self.p[2][l]);
            let [a, b, c] = self.tri.map(|v| Vec3::new(v[0][l], v[1][l], v[2][l]));
            let q = closest_point_on_triangle(p, a, b, c);
            for (axis, x) in q.to_array().into_iter().enumerate() {
                out.q[axis][l] = x;
            }
            out.d2[l] = (q - p).length_squared();
        }
    }
}

/// Up to [`LANES`] pending (point, triangle, tag) triples.
pub struct Batch<T> {
    pairs: Pairs,
    tags: [T; LANES],
    len: usize,
    out: Closest,
}

impl<T: Copy + Default> Default for Batch<T> {
    fn default() -> Self {
        Batch {
            pairs: Pairs::default(),
            tags: [T::default(); LANES],
            len: 0,
            out: Closest::default(),
        }
    }
}

impl<T: Copy + Default> Batch<T> {
    /// Queues a pair; true when the batch is full (call [`Batch::run`]).
    #[inline(always)]
    pub fn push(&mut self, p: Vec3, tri: [Vec3; 3], tag: T) -> bool {
        let l = self.len;
        self.pairs.set_point(l, p);
        self.pairs.set_triangle(l, &tri);
        self.tags[l] = tag;
        self.len += 1;
        self.len == LANES
    }

    /// Evaluates the queued pairs, calling `f(tag, q, |q - p|²)` for each in the order queued,
    /// and empties the batch.
    #[inline]
    pub fn run(&mut self, mut f: impl FnMut(T, Vec3, f32)) {
        if self.len == 0 {
            return;
        }
        let out = &mut self.out;
        self.pairs.closest(out);
        for l in 0..self.len {
            let q = Vec3::new(out.q[0][l], out.q[1][l], out.q[2][l]);
            f(self.tags[l], q, out.d2[l]);
        }
        self.len = 0;
    }
}

/// The lanes through AVX-512 or AVX where the CPU has them (decided once per process), else
/// SSE2.
#[inline]
fn kernel(p: &[Lanes; 3], tri: &[[Lanes; 3]; 3], out: &mut Closest) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx512f") {
        // SAFETY: the CPU has AVX-512F (checked just above).
        return unsafe { kernel_avx512(p, tri, out) };
    }
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above).
        return unsafe { kernel_avx(p, tri, out) };
    }
    kernel_lanes(p, tri, out)
}

/// [`kernel_lanes`] compiled for AVX: the same operations, eight lanes per instruction (Rust
/// does not contract a multiply and an add into a fused one).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
unsafe fn kernel_avx(p: &[Lanes; 3], tri: &[[Lanes; 3]; 3], out: &mut Closest) {
    kernel_lanes(p, tri, out)
}

/// [`kernel_lanes`] compiled for AVX-512F: the same operations, with 32 vector registers.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f")]
unsafe fn kernel_avx512(p: &[Lanes; 3], tri: &[[Lanes; 3]; 3], out: &mut Closest) {
    kernel_lanes(p, tri, out)
}

/// [`closest_point_on_triangle`] per lane, every region computed and the first that applies
/// selected (the scalar function's `return`s in reverse order, so earlier ones win).
#[inline(always)]
fn kernel_lanes(p: &[Lanes; 3], [a, b, c]: &[[Lanes; 3]; 3], out: &mut Closest) {
    for l in 0..LANES {
        let v3 = |v: &[Lanes; 3]| [v[0][l], v[1][l], v[2][l]];
        let (p, a, b, c) = (v3(p), v3(a), v3(b), v3(c));
        let sub = |u: [f32; 3], v: [f32; 3]| [u[0] - v[0], u[1] - v[1], u[2] - v[2]];
        let dot = |u: [f32; 3], v: [f32; 3]| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
        // u + t v, as glam's `u + t * v`.
        let along =
            |u: [f32; 3], t: f32, v: [f32; 3]| [u[0] + t * v[0], u[1] + t * v[1], u[2] + t * v[2]];
        let (ab, ac, ap) = (sub(b, a), sub(c, a), sub(p, a));
        let (d1, d2) = (dot(ab, ap), dot(ac, ap));
        let bp = sub(p, b);
        let (d3, d4) = (dot(ab, bp), dot(ac, bp));
        let vc = d1 * d4 - d3 * d2;
        let cp = sub(p, c);
        let (d5, d6) = (dot(ab, cp), dot(ac, cp));
        let vb = d5 * d2 - d1 * d6;
        let va = d3 * d6 - d5 * d4;
        let in_a = d1 <= 0.0 && d2 <= 0.0;
        let in_b = d3 >= 0.0 && d4 <= d3;
        let on_ab = vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0;
        let in_c = d6 >= 0.0 && d5 <= d6;
        let on_ac = vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0;
        let on_bc = va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0;
        let denom = va + vb + vc;
        let inv = 1.0 / denom;
        // Interior: a + ab v + ac w.
        let (v, w) = (vb * inv, vc * inv);
        let interior = [
            a[0] + ab[0] * v + ac[0] * w,
            a[1] + ab[1] * v + ac[1] * w,
            a[2] + ab[2] * v + ac[2] * w,
        ];
        let mut q = interior;
        let pick = |q: &mut [f32; 3], cond: bool, r: [f32; 3]| {
            for k in 0..3 {
                q[k] = if cond { r[k] } else { q[k] };
            }
        };
        let w_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        pick(&mut q, on_bc, along(b, w_bc, sub(c, b)));
        pick(&mut q, on_ac, along(a, d2 / (d2 - d6), ac));
        pick(&mut q, in_c, c);
        pick(&mut q, on_ab, along(a, d1 / (d1 - d3), ab));
        pick(&mut q, in_b, b);
        pick(&mut q, in_a, a);
        let region = in_a | in_b | on_ab | in_c | on_ac | on_bc;
        out.degenerate[l] = !region & !(denom.abs() > f32::MIN_POSITIVE && denom.is_finite());
        let d = sub(q, p);
        out.q[0][l] = q[0];
        out.q[1][l] = q[1];
        out.q[2][l] = q[2];
        out.d2[l] = dot(d, d);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random pairs, degenerate triangles (a repeated corner, collinear corners) and
    /// vertices on cell centres and faces.
    fn test_pairs() -> Vec<(Vec3, [Vec3; 3])> {
        let mut seed = 0x2545_f491_4f6c_dd1du64;
        let mut rnd = move || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            // Small integers and halves too: vertices on cell centres and faces.
            match seed % 4 {
                0 => ((seed >> 8) % 9) as f32 * 0.5 - 2.0,
                _ => ((seed >> 11) as f64 / (1u64 << 53) as f64 * 6.0 - 3.0) as f32,
            }
        };
        let mut pairs = Vec::new();
        for i in 0..200_000 {
            let p = Vec3::new(rnd(), rnd(), rnd());
            let a = Vec3::new(rnd(), rnd(), rnd());
            let (b, c) = match i % 5 {
                0 => (a, Vec3::new(rnd(), rnd(), rnd())),
                1 => {
                    let b = Vec3::new(rnd(), rnd(), rnd());
                    (b, a + 2.0 * (b - a))
                }
                _ => (
                    Vec3::new(rnd(), rnd(), rnd()),
                    Vec3::new(rnd(), rnd(), rnd()),
                ),
            };
            pairs.push((p, [a, b, c]));
        }
        pairs
    }

    fn assert_scalar_bits((p, [a, b, c]): (Vec3, [Vec3; 3]), q: Vec3, d2: f32) {
        let want = closest_point_on_triangle(p, a, b, c);
        assert_eq!(
            q.to_array().map(f32::to_bits),
            want.to_array().map(f32::to_bits)
        );
        assert_eq!(d2.to_bits(), (want - p).length_squared().to_bits());
    }

    /// The transposed load gives every lane the triangle the lane by lane copy gives it,
    /// the last face of the array included (its load stops at its own end).
    #[test]
    fn set_triangles_is_set_triangle_per_lane() {
        let faces: Vec<[Vec3; 3]> = test_pairs().into_iter().take(1000).map(|p| p.1).collect();
        let mut seed = 7u32;
        for round in 0..200 {
            let idx: [u32; LANES] = std::array::from_fn(|l| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                if (round + l) % 5 == 0 {
                    999
                } else {
                    (seed >> 8) % 1000
                }
            });
            let (mut fast, mut slow) = (Pairs::default(), Pairs::default());
            fast.set_triangles(&faces, &idx);
            for (l, &n) in idx.iter().enumerate() {
                slow.set_triangle(l, &faces[n as usize]);
            }
            let bits = |p: &Pairs| p.tri.map(|c| c.map(|a| a.map(f32::to_bits)));
            assert_eq!(bits(&fast), bits(&slow), "round {round}");
        }
    }

    /// Through a batch (the kernel this CPU picks, and the scalar redo of degenerate lanes),
    /// every pair gives the scalar function's bits.
    #[test]
    fn same_bits_as_the_scalar_function() {
        let pairs = test_pairs();
        let mut batch = Batch::<usize>::default();
        let mut seen = 0;
        let mut check = |i: usize, q: Vec3, d2: f32| {
            assert_scalar_bits(pairs[i], q, d2);
            seen += 1;
        };
        for (i, &(p, t)) in pairs.iter().enumerate() {
            if batch.push(p, t, i) {
                batch.run(&mut check);
            }
        }
        batch.run(&mut check);
        assert_eq!(seen, pairs.len());
    }

    /// Each build of the kernel this CPU can run (SSE2, AVX, AVX-512) gives the scalar
    /// function's bits on every lane it does not hand back as degenerate, and hands back
    /// only degenerate triangles (a third of these pairs have repeated or collinear corners;
    /// the kernel's regions answer those itself).
    #[test]
    fn every_kernel_build_gives_the_same_bits() {
        type Kernel = unsafe fn(&[Lanes; 3], &[[Lanes; 3]; 3], &mut Closest);
        let mut kernels: Vec<(&str, Kernel)> = vec![("sse2", |p, t, o| kernel_lanes(p, t, o))];
        #[cfg(target_arch = "x86_64")]
        {
            if std::is_x86_feature_detected!("avx") {
                kernels.push(("avx", kernel_avx));
            }
            if std::is_x86_feature_detected!("avx512f") {
                kernels.push(("avx512f", kernel_avx512));
            }
        }
        let pairs = test_pairs();
        for (name, k) in kernels {
            let mut handed_back = 0;
            for chunk in pairs.chunks_exact(LANES) {
                let mut lanes = Pairs::default();
                for (l, &(p, t)) in chunk.iter().enumerate() {
                    lanes.set_point(l, p);
                    lanes.set_triangle(l, &t);
                }
                let mut out = Closest::default();
                // SAFETY: each build is listed only when the CPU has its features.
                unsafe { k(&lanes.p, &lanes.tri, &mut out) };
                for (l, &pair) in chunk.iter().enumerate() {
                    if out.degenerate[l] {
                        let [a, b, c] = pair.1;
                        assert!((b - a).cross(c - a).length_squared() == 0.0, "{name}");
                        handed_back += 1;
                        continue;
                    }
                    let q = Vec3::new(out.q[0][l], out.q[1][l], out.q[2][l]);
                    assert_scalar_bits(pair, q, out.d2[l]);
                }
            }
            assert!(handed_back < pairs.len() / 10, "{name}: {handed_back}");
        }
    }
}
