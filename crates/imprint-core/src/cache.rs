//! Hints to the memory system.

/// Asks for the cache line holding `value` ahead of its use, where the CPU takes the hint
/// (x86-64's `prefetcht0`; elsewhere nothing). For loops that gather from addresses the
/// hardware prefetcher cannot guess, a few iterations before the load: the voxeliser's
/// triangles, listed by slab, are scattered over the mesh's arrays, and their loads stalled
/// the slab loop on nearly every triangle. Only a hint: it reads nothing and cannot fault.
#[inline(always)]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        // SAFETY: SSE is part of x86-64; a prefetch of a valid reference has no effect
        // beyond the caches.
        unsafe { _mm_prefetch::<_MM_HINT_T0>(std::ptr::from_ref(value).cast()) };
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}
