//! Scratch buffers shared by the tasks of a parallel pass: a task takes one (or makes one when
//! none is free) and gives it back, so a pass run frame after frame allocates a few tasks'
//! worth once, not a buffer per task per frame (a fresh buffer of a few hundred KiB is
//! fresh pages, a fault each). The voxeliser's slab keys and the field's slab distances.

use std::sync::Mutex;

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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_given_buffer_is_taken_again_and_make_runs_only_when_none_is_free() {
        let pool = Pool::default();
        assert_eq!(pool.take(|| vec![1u8]), vec![1]);
        pool.give(vec![7u8, 7]);
        assert_eq!(pool.take(|| unreachable!("one was free")), vec![7, 7]);
        assert_eq!(pool.take(|| vec![2u8]), vec![2]);
    }
}
