//! Scratch buffers shared by the tasks of a parallel pass: a task takes one (or makes one when
//! none is free) and gives it back, so a pass run frame after frame allocates a few tasks'
//! worth once, not a buffer per task per frame (a fresh buffer of a few hundred KiB is
//! fresh pages, a fault each). The voxeliser's slab keys and the field's slab distances. And
//! the process-wide half of the same: [`retain_freed_memory`], which the binaries call.

use rayon::prelude::*;
use std::sync::Mutex;

/// Tells the allocator to keep the memory this process frees for its next allocations (glibc;
/// elsewhere nothing). By default glibc returns a freed block above a threshold it moves as it
/// goes to the system, and serves the next such request with fresh pages, whose first touches
/// are faults (about 2 µs each on the benchmarks' machine): a stage that builds its buffers
/// afresh at every call (the drape's inside test, some 20 MB a call) then paid for them again
/// at every call, or not, as that threshold had moved, which changed with unrelated code (two
/// builds of the drape that differed only in its ray walks: 23 thousand page faults in 40
/// calls against 190 thousand, and 19 against 28 ms a call). Blocks up to 32 MiB (glibc's
/// most) now come from its heaps, which it no longer trims: what the process frees stays with
/// it, up to its peak. The binaries call this first thing, before any thread starts.
pub fn retain_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    // SAFETY: `mallopt` sets allocator parameters; called before other threads allocate.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, libc::c_int::MAX);
    }
}

/// Free buffers of one kind; what a buffer holds when taken is whatever it was given back
/// with (each user says what that is).
#[derive(Debug)]
pub struct Pool<T> {
    free: Mutex<Vec<T>>,
}

impl<T> Default for Pool<T> {
    fn default() -> Self {
        Pool {
            free: Mutex::new(Vec::new()),
        }
    }
}

impl<T> Pool<T> {
    /// A free buffer, or `make()`'s when none is.
    pub fn take(&self, make: impl FnOnce() -> T) -> T {
        let taken = self.free.lock().ok().and_then(|mut f| f.pop());
        taken.unwrap_or_else(make)
    }

    /// Gives `item` back for the next [`Pool::take`].
    pub fn give(&self, item: T) {
        if let Ok(mut f) = self.free.lock() {
            f.push(item);
        }
    }
}

/// `n` copies of `value` in a grid-sized buffer, written by the pool's threads: a fresh
/// buffer's first touches are page faults (on the 2-core VM of BENCHMARKS a 128³ field's
/// 32 MiB of cells took 16 ms of them on one thread), and split over the threads they cost
/// a fraction. The values are those of `vec![value; n]`.
pub fn grid_vec<T: Copy + Send + Sync>(n: usize, value: T) -> Vec<T> {
    /// Elements per task: 256 KiB of them, so that a 128³ grid's faults spread over the
    /// threads.
    const CHUNK_BYTES: usize = 256 << 10;
    let mut v = Vec::with_capacity(n);
    let chunk = (CHUNK_BYTES / size_of::<T>().max(1)).max(1);
    v.spare_capacity_mut()[..n]
        .par_chunks_mut(chunk)
        .for_each(|c| c.iter_mut().for_each(|x| _ = x.write(value)));
    // SAFETY: the first `n` slots (within the capacity) were all written just above.
    unsafe { v.set_len(n) };
    v
}

/// Runs `f` on one of rayon's worker threads, so that the parallel passes inside it start
/// there. Started from a thread outside the pool (a program's main thread, or the executor
/// running a wave of one node, which rayon runs on the calling thread), each pass wakes the
/// workers and puts the caller to sleep until they are done, and a stage with a pass per
/// substep makes dozens a frame. Started from a worker, a pass pushes its work onto that
/// worker's own queue and the other workers, still spinning from the last pass, take from it.
/// Measured: a 64² cloth's 60 frames switched context 4,395 times before, 871 after, and H's
/// scene through `imprint run` 10,766 against 5,102; a 32² cloth ran 32% faster, a 64² one
/// 16%, larger work no faster beyond the noise. Inside the pool already, `f` runs where it
/// is. Which thread runs `f` changes nothing it computes.
pub fn on_workers<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    rayon::scope(|_| f())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn on_workers_runs_on_a_worker_of_the_pool_it_is_called_for() {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap();
        assert_eq!(rayon::current_thread_index(), None);
        assert!(on_workers(rayon::current_thread_index).is_some());
        // Inside a pool, it stays on the calling worker.
        pool.install(|| {
            let here = rayon::current_thread_index();
            assert_eq!(on_workers(rayon::current_thread_index), here);
        });
    }

    /// Every slot written, with the value given, at sizes below, at and past a task's chunk
    /// and over many chunks, and of a type whose size does not divide a chunk's bytes.
    #[test]
    fn grid_vec_is_vec_of_copies() {
        for n in [0, 1, 65_535, 65_536, 65_537, 3 << 20] {
            assert_eq!(grid_vec(n, 7u32), vec![7u32; n], "n = {n}");
        }
        let odd = [1.5f32, -2.0, 3.25];
        assert_eq!(grid_vec(100_003, odd), vec![odd; 100_003]);
    }

    #[test]
    fn a_given_buffer_is_taken_again_and_make_runs_only_when_none_is_free() {
        let pool = Pool::default();
        assert_eq!(pool.take(|| vec![1u8]), vec![1]);
        pool.give(vec![7u8, 7]);
        assert_eq!(pool.take(|| unreachable!("one was free")), vec![7, 7]);
        assert_eq!(pool.take(|| vec![2u8]), vec![2]);
    }
}
