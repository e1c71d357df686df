//! Eight values at a time in plain arrays: the lane type and the few helpers every
//! eight-wide kernel uses (the cloth's springs and contact, the particle
//! skinning's rotations). Loops over a [`Lane`] vectorise in a function compiled for AVX2,
//! and do the same operations per lane as one value at a time, so the same bits.

use glam::Vec3;

/// Values per lane array (a block of particles).
pub const LANES: usize = 8;

/// One value per particle of a block.
pub type Lane = [f32; LANES];

/// Lane `m` of a block's vectors, stored by axis.
#[inline(always)]
pub fn lane_vec(v: &[Lane; 3], m: usize) -> Vec3 {
    Vec3::new(v[0][m], v[1][m], v[2][m])
}

/// `[f(0), .., f(LANES - 1)]`, as a loop the compiler vectorises (`std::array::from_fn` and
/// `map` can stay calls in a function compiled for AVX2).
#[inline(always)]
pub fn lanewise<T: Copy + Default>(f: impl Fn(usize) -> T) -> [T; LANES] {
    let mut v = [T::default(); LANES];
    for (m, v) in v.iter_mut().enumerate() {
        *v = f(m);
    }
    v
}

/// A lane mask's value for `b`: all ones or zero. Lane loops over masks vectorise where
/// loops over `bool`s (bytes) do not.
#[inline(always)]
pub fn mask(b: bool) -> u32 {
    if b { u32::MAX } else { 0 }
}

/// `a` where lane mask `m` is all ones, else `b`, by the bits: a select the compiler keeps
/// as one (an `if` into an array in memory can become a masked store, which on AMD
/// processors takes many cycles).
#[inline(always)]
pub fn select(m: u32, a: f32, b: f32) -> f32 {
    f32::from_bits((a.to_bits() & m) | (b.to_bits() & !m))
}

/// One bit per lane of a lane mask (bit `m` set where lane `m`'s mask is all ones), from
/// the masks' top bits. On x86-64, two SSE2 `movmskps` (baseline, so inlined in every build):
/// the compiler turned the loop into a shift and an OR per lane, 8% of the cloth's contact.
#[inline(always)]
pub fn lane_bits(mask: &[u32; LANES]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_loadu_ps, _mm_movemask_ps};
        let at = mask.as_ptr().cast::<f32>();
        // SAFETY: SSE2 is part of x86-64; `mask` holds eight 32-bit values, read as two
        // unaligned groups of four (the sign bit of a float is the top bit of its word).
        unsafe {
            let (lo, hi) = (_mm_loadu_ps(at), _mm_loadu_ps(at.add(4)));
            (_mm_movemask_ps(lo) | _mm_movemask_ps(hi) << 4) as u32
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut bits = 0;
        for (m, &k) in mask.iter().enumerate() {
            bits |= (k >> 31) << m;
        }
        bits
    }
}

/// One bit per lane (bit `m` set where lane `m` is true). On x86-64 one SSE2 `pmovmskb` of
/// the bytes shifted to their top bits, as [`lane_bits`].
#[inline(always)]
pub fn bool_bits(b: &[bool; LANES]) -> u32 {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_cvtsi64_si128, _mm_movemask_epi8, _mm_slli_epi16};
        // A `bool` is the byte 0 or 1: shifted left by 7 in 16-bit lanes, each byte's 1
        // becomes its top bit and no bit crosses into the next byte.
        // SAFETY: SSE2 is part of x86-64; eight `bool`s are eight initialised bytes.
        unsafe {
            let bytes = b.as_ptr().cast::<i64>().read_unaligned();
            let top = _mm_slli_epi16::<7>(_mm_cvtsi64_si128(bytes));
            _mm_movemask_epi8(top) as u32
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        let mut bits = 0;
        for (m, &b) in b.iter().enumerate() {
            bits |= (b as u32) << m;
        }
        bits
    }
}

/// The lanes whose bits are set, in increasing order: for loops over the few lanes that
/// need scalar work (a hit to record, a pinned particle). As a filter over every lane, each
/// lane was tested and branched on: about 8% of the substep's instructions.
#[inline(always)]
pub fn lanes_of(mut bits: u32) -> impl Iterator<Item = usize> {
    std::iter::from_fn(move || {
        (bits != 0).then(|| {
            let m = bits.trailing_zeros() as usize;
            bits &= bits - 1;
            m
        })
    })
}

/// Eight `f32`s with arithmetic by lane: `a + b` is `a[m] + b[m]` for every `m`, one IEEE
/// operation per lane, so that code written with it reads as the one-value code it must
/// match bit for bit. Two kinds: [`F8`], plain arrays (any CPU), and [`avx::Avx`], one AVX
/// register, each operator one instruction (LLVM's vectoriser does not reliably turn the
/// arrays' loops into those in long straight-line code: it scalarised square roots and
/// rebuilt the transposes as inserts). Constants come from a value (`x.splat(1.0)`): an
/// `Avx` exists only where the CPU has AVX, and so do the values made from it.
pub trait Wide:
    Copy
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
{
    /// A lane mask (all ones or zero per lane).
    type Mask: Copy;
    /// Every lane `v`.
    fn splat(self, v: f32) -> Self;
    /// The lanes `l`.
    fn load(self, l: &Lane) -> Self;
    /// The lanes as an array.
    fn lanes(self) -> Lane;
    /// The lane masks `m` ([`mask`]'s values).
    fn mask(self, m: &[u32; LANES]) -> Self::Mask;
    fn sqrt(self) -> Self;
    fn abs(self) -> Self;
    /// `self < rhs` (false where either is NaN).
    fn lt(self, rhs: Self) -> Self::Mask;
    /// `self <= rhs` (false where either is NaN).
    fn le(self, rhs: Self) -> Self::Mask;
    /// `a` where `m` is set, else `b`.
    fn select(m: Self::Mask, a: Self, b: Self) -> Self;
    /// Quad `k` of values `at` of `v` by component (a `Vec3A`'s fourth: whatever it holds).
    ///
    /// # Safety
    /// Every index is below `v.len()` and `k` below `T::N`.
    unsafe fn gather<T: quads::Quads>(self, v: &[T], at: &[u32; LANES], k: usize) -> [Self; 4];
    /// Lane m of `v`'s four components to the four floats at `at[m]`.
    ///
    /// # Safety
    /// Each pointer can be written for four floats.
    unsafe fn scatter(at: [*mut f32; LANES], v: [Self; 4]);

    /// Values `at` of `v`.
    ///
    /// # Safety
    /// Every index is below `v.len()`.
    #[inline(always)]
    unsafe fn gather1(self, v: &[f32], at: &[u32; LANES]) -> Self {
        debug_assert!(at.iter().all(|&i| (i as usize) < v.len()));
        // SAFETY: the caller's promise.
        self.load(&lanewise(|m| unsafe { *v.get_unchecked(at[m] as usize) }))
    }

    /// `f32::clamp` in every lane: `lo` below it, `hi` above, NaN left NaN.
    #[inline(always)]
    fn clamp(self, lo: f32, hi: f32) -> Self {
        let (lo, hi) = (self.splat(lo), self.splat(hi));
        let v = Self::select(self.lt(lo), lo, self);
        Self::select(hi.lt(v), hi, v)
    }
}

/// A [`Lane`] as a [`Wide`]: loops over the lanes.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct F8(pub Lane);

macro_rules! f8_op {
    ($trait:ident, $method:ident, $op:tt) => {
        impl std::ops::$trait for F8 {
            type Output = F8;
            #[inline(always)]
            fn $method(self, rhs: F8) -> F8 {
                let mut r = self.0;
                for (r, b) in r.iter_mut().zip(rhs.0) {
                    *r $op b;
                }
                F8(r)
            }
        }
    };
}
f8_op!(Add, add, +=);
f8_op!(Sub, sub, -=);
f8_op!(Mul, mul, *=);
f8_op!(Div, div, /=);

impl std::ops::Neg for F8 {
    type Output = F8;
    #[inline(always)]
    fn neg(self) -> F8 {
        self.map(|v| -v)
    }
}

impl F8 {
    /// `f` of every lane.
    #[inline(always)]
    fn map(self, f: impl Fn(f32) -> f32) -> F8 {
        let mut r = self.0;
        for r in &mut r {
            *r = f(*r);
        }
        F8(r)
    }

    #[inline(always)]
    fn cmp(self, rhs: F8, f: impl Fn(f32, f32) -> bool) -> [u32; LANES] {
        lanewise(|m| mask(f(self.0[m], rhs.0[m])))
    }
}

impl Wide for F8 {
    type Mask = [u32; LANES];

    #[inline(always)]
    fn splat(self, v: f32) -> F8 {
        F8([v; LANES])
    }

    #[inline(always)]
    fn load(self, l: &Lane) -> F8 {
        F8(*l)
    }

    #[inline(always)]
    fn lanes(self) -> Lane {
        self.0
    }

    #[inline(always)]
    fn mask(self, m: &[u32; LANES]) -> [u32; LANES] {
        *m
    }

    #[inline(always)]
    fn sqrt(self) -> F8 {
        self.map(f32::sqrt)
    }

    #[inline(always)]
    fn abs(self) -> F8 {
        self.map(f32::abs)
    }

    #[inline(always)]
    fn lt(self, rhs: F8) -> [u32; LANES] {
        self.cmp(rhs, |a, b| a < b)
    }

    #[inline(always)]
    fn le(self, rhs: F8) -> [u32; LANES] {
        self.cmp(rhs, |a, b| a <= b)
    }

    #[inline(always)]
    fn select(m: [u32; LANES], a: F8, b: F8) -> F8 {
        F8(lanewise(|k| select(m[k], a.0[k], b.0[k])))
    }

    #[inline(always)]
    unsafe fn gather<T: quads::Quads>(self, v: &[T], at: &[u32; LANES], k: usize) -> [F8; 4] {
        debug_assert!(k < T::N && at.iter().all(|&i| (i as usize) < v.len()));
        let mut q = [F8([0.0; LANES]); 4];
        for (m, &i) in at.iter().enumerate() {
            // SAFETY: `i` is in range (the caller's promise).
            let c = unsafe { v.get_unchecked(i as usize) }.quad(k);
            for (q, c) in q.iter_mut().zip(c) {
                q.0[m] = c;
            }
        }
        q
    }

    #[inline(always)]
    unsafe fn scatter(at: [*mut f32; LANES], v: [F8; 4]) {
        for (m, at) in at.into_iter().enumerate() {
            for (c, v) in v.iter().enumerate() {
                // SAFETY: the caller's promise.
                unsafe { at.add(c).write(v.0[m]) };
            }
        }
    }
}

/// [`Wide`] in AVX registers.
#[cfg(target_arch = "x86_64")]
pub mod avx {
    use super::{LANES, Lane, Wide, quads};
    use std::arch::x86_64::*;

    /// Eight lanes in an AVX register. Made only by [`Avx::gather`] and [`Avx::first`],
    /// which are unsafe: a value vouches that the CPU has AVX, so its operators are safe.
    #[derive(Clone, Copy, Debug)]
    pub struct Avx(__m256);

    impl Avx {
        /// A first value (zero), to make the others from.
        ///
        /// # Safety
        /// The CPU has AVX.
        #[inline(always)]
        pub unsafe fn first() -> Avx {
            // SAFETY: the caller's promise.
            Avx(unsafe { _mm256_setzero_ps() })
        }
    }

    macro_rules! avx_op {
        ($trait:ident, $method:ident, $intrinsic:ident) => {
            impl std::ops::$trait for Avx {
                type Output = Avx;
                #[inline(always)]
                fn $method(self, rhs: Avx) -> Avx {
                    // SAFETY: an `Avx` exists only where the CPU has AVX.
                    Avx(unsafe { $intrinsic(self.0, rhs.0) })
                }
            }
        };
    }
    avx_op!(Add, add, _mm256_add_ps);
    avx_op!(Sub, sub, _mm256_sub_ps);
    avx_op!(Mul, mul, _mm256_mul_ps);
    avx_op!(Div, div, _mm256_div_ps);

    impl std::ops::Neg for Avx {
        type Output = Avx;
        #[inline(always)]
        fn neg(self) -> Avx {
            // SAFETY: as for the operators. The sign bit flipped, as `-x` does.
            Avx(unsafe { _mm256_xor_ps(self.0, _mm256_set1_ps(-0.0)) })
        }
    }

    // SAFETY (every `unsafe` block below): an `Avx` exists only where the CPU has AVX; the
    // pointers are the callers' promises.
    impl Wide for Avx {
        type Mask = __m256;

        #[inline(always)]
        fn splat(self, v: f32) -> Avx {
            Avx(unsafe { _mm256_set1_ps(v) })
        }

        #[inline(always)]
        fn load(self, l: &Lane) -> Avx {
            Avx(unsafe { _mm256_loadu_ps(l.as_ptr()) })
        }

        #[inline(always)]
        fn lanes(self) -> Lane {
            let mut l = [0.0; LANES];
            unsafe { _mm256_storeu_ps(l.as_mut_ptr(), self.0) };
            l
        }

        #[inline(always)]
        fn mask(self, m: &[u32; LANES]) -> __m256 {
            unsafe { _mm256_loadu_ps(m.as_ptr().cast()) }
        }

        #[inline(always)]
        fn sqrt(self) -> Avx {
            Avx(unsafe { _mm256_sqrt_ps(self.0) })
        }

        #[inline(always)]
        fn abs(self) -> Avx {
            // The sign bit cleared, as `f32::abs` does.
            Avx(unsafe { _mm256_andnot_ps(_mm256_set1_ps(-0.0), self.0) })
        }

        #[inline(always)]
        fn lt(self, rhs: Avx) -> __m256 {
            // Ordered and quiet: false with a NaN, as `<`.
            unsafe { _mm256_cmp_ps::<_CMP_LT_OQ>(self.0, rhs.0) }
        }

        #[inline(always)]
        fn le(self, rhs: Avx) -> __m256 {
            unsafe { _mm256_cmp_ps::<_CMP_LE_OQ>(self.0, rhs.0) }
        }

        #[inline(always)]
        fn select(m: __m256, a: Avx, b: Avx) -> Avx {
            Avx(unsafe { _mm256_blendv_ps(b.0, a.0, m) })
        }

        #[inline(always)]
        unsafe fn gather<T: quads::Quads>(self, v: &[T], at: &[u32; LANES], k: usize) -> [Avx; 4] {
            debug_assert!(k < T::N && at.iter().all(|&i| (i as usize) < v.len()));
            let base = v.as_ptr();
            let at =
                super::lanewise(|m| unsafe { base.add(at[m] as usize).cast::<f32>().add(4 * k) });
            let [a, b, c, d] = unsafe { quads::load(at) };
            [Avx(a), Avx(b), Avx(c), Avx(d)]
        }

        #[inline(always)]
        unsafe fn scatter(at: [*mut f32; LANES], v: [Avx; 4]) {
            unsafe { quads::store(at, [v[0].0, v[1].0, v[2].0, v[3].0]) }
        }
    }
}

/// Eight values of four floats each (`Vec3A`, `Quat`, a `Mat3A`'s columns: 16 bytes) to
/// four registers by component (lane `m` of component `c` is value `m`'s float `c`), and
/// back: AVX's 4 × 4 transposes in its two halves, about 20 instructions for what a load or
/// store per float and lane takes 50 to 60 for. Only data moves, so the bits are those of
/// [`F8`]'s loops.
pub mod quads {
    use glam::{Mat3A, Quat, Vec3A};
    #[cfg(target_arch = "x86_64")]
    use {super::LANES, std::arch::x86_64::*};

    /// A value made of `N` runs of four floats in memory (quad `k` at `16 k` bytes).
    ///
    /// # Safety
    /// The type is `4 N` `f32`s, quad `k`'s floats in the order `quad(k)` gives them.
    pub unsafe trait Quads {
        const N: usize;
        fn quad(&self, k: usize) -> [f32; 4];
    }

    // SAFETY: glam's SSE2 `Vec3A` and `Quat` are one `__m128` each, x first, and `Mat3A`
    // three `Vec3A` columns (`repr(C)`).
    unsafe impl Quads for Vec3A {
        const N: usize = 1;
        #[inline(always)]
        fn quad(&self, _: usize) -> [f32; 4] {
            [self.x, self.y, self.z, 0.0]
        }
    }

    // SAFETY: as for `Vec3A`.
    unsafe impl Quads for Quat {
        const N: usize = 1;
        #[inline(always)]
        fn quad(&self, _: usize) -> [f32; 4] {
            self.to_array()
        }
    }

    // SAFETY: as for `Vec3A`.
    unsafe impl Quads for Mat3A {
        const N: usize = 3;
        #[inline(always)]
        fn quad(&self, k: usize) -> [f32; 4] {
            self.col(k).quad(0)
        }
    }

    /// The 4 × 4 transposes of `[q0|q4]`, `[q1|q5]`, `[q2|q6]`, `[q3|q7]` (either way).
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    fn transpose([a, b, c, d]: [__m256; 4]) -> [__m256; 4] {
        let (t0, t1) = (_mm256_unpacklo_ps(a, b), _mm256_unpackhi_ps(a, b));
        let (t2, t3) = (_mm256_unpacklo_ps(c, d), _mm256_unpackhi_ps(c, d));
        [
            _mm256_shuffle_ps::<0b01_00_01_00>(t0, t2),
            _mm256_shuffle_ps::<0b11_10_11_10>(t0, t2),
            _mm256_shuffle_ps::<0b01_00_01_00>(t1, t3),
            _mm256_shuffle_ps::<0b11_10_11_10>(t1, t3),
        ]
    }

    /// The four floats at each of `at` (value m in lane m), by component.
    ///
    /// # Safety
    /// The CPU has AVX, and each pointer can be read for four floats.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub unsafe fn load(at: [*const f32; LANES]) -> [__m256; 4] {
        // SAFETY: the caller's promise.
        let pair = |m: usize| unsafe {
            _mm256_insertf128_ps::<1>(
                _mm256_castps128_ps256(_mm_loadu_ps(at[m])),
                _mm_loadu_ps(at[m + 4]),
            )
        };
        transpose([pair(0), pair(1), pair(2), pair(3)])
    }

    /// Lane m of `v`'s four components to the four floats at `at[m]`.
    ///
    /// # Safety
    /// The CPU has AVX, and each pointer can be written for four floats.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx")]
    #[inline]
    pub unsafe fn store(at: [*mut f32; LANES], v: [__m256; 4]) {
        for (k, t) in transpose(v).into_iter().enumerate() {
            // SAFETY: the caller's promise.
            unsafe {
                _mm_storeu_ps(at[k], _mm256_castps256_ps128(t));
                _mm_storeu_ps(at[k + 4], _mm256_extractf128_ps::<1>(t));
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The SSE2 reads give the lanes' bits as the loops over the lanes define them, for every
    /// pattern of eight lanes, and `lane_bits` reads only each word's top bit.
    #[test]
    fn the_bits_are_the_lanes_in_order() {
        for pattern in 0u32..256 {
            let on = |m: usize| pattern >> m & 1 == 1;
            let b: [bool; LANES] = std::array::from_fn(on);
            assert_eq!(bool_bits(&b), pattern);
            assert_eq!(lane_bits(&b.map(mask)), pattern);
            // Other low bits do not count: only the top one.
            let words = std::array::from_fn(|m| if on(m) { 0x8000_0001 } else { 0x7fff_ffff });
            assert_eq!(lane_bits(&words), pattern);
            let set: Vec<usize> = lanes_of(pattern).collect();
            assert_eq!(set, (0..LANES).filter(|&m| on(m)).collect::<Vec<_>>());
        }
    }
}
