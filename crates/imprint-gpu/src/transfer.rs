//! Host ↔ device traffic, counted per thread: every upload (a buffer created with contents, a
//! queue write into a buffer or a texture) and every read-back (a mapped copy of a buffer, a
//! texture or timestamps) that goes through [`GpuContext`](crate::GpuContext) adds its bytes
//! here, and `GpuField::to_cpu` in `imprint-stages` adds one to
//! [`Transfers::field_read_backs`].
//!
//! The counters are the thread's own: the executor runs each node on one thread, so the
//! difference of two [`snapshot`]s taken around a node's run is that node's traffic, whatever
//! other threads do meanwhile.
//!
//! There is one way to move data: [`GpuContext::storage_buffer`](crate::GpuContext::storage_buffer)
//! and [`GpuContext::uniform_buffer`](crate::GpuContext::uniform_buffer) (created with
//! contents), [`GpuQueue::write_buffer`](crate::GpuQueue::write_buffer) and
//! [`GpuQueue::write_texture`](crate::GpuQueue::write_texture) (the context's `queue` is a
//! [`GpuQueue`](crate::GpuQueue), not a bare `wgpu::Queue`), and
//! [`GpuContext::read_buffer`](crate::GpuContext::read_buffer) (which
//! `raster::TextureReadback::read` and the timer use). A test in this module fails when a
//! source file of the workspace maps a buffer, creates one with contents or writes a texture
//! by any other route.

use std::cell::Cell;

/// Cumulative host ↔ device traffic of one thread (or, from [`Transfers::since`], of a span
/// of its work).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub struct Transfers {
    /// Bytes handed to the device: contents of buffers created with data, queue writes into
    /// buffers and textures (the whole slice given).
    pub uploaded_bytes: u64,
    /// Bytes copied back from the device: the whole buffer for each read-back (texture
    /// read-backs with their rows padded to 256 bytes, as they are copied), and timestamps.
    pub read_back_bytes: u64,
    /// Calls of `GpuField::to_cpu` (a GPU distance field read back as a CPU one).
    pub field_read_backs: u64,
}

impl Transfers {
    /// The traffic between `earlier` (a [`snapshot`] of the same thread) and `self`.
    pub fn since(&self, earlier: &Transfers) -> Transfers {
        Transfers {
            uploaded_bytes: self.uploaded_bytes.wrapping_sub(earlier.uploaded_bytes),
            read_back_bytes: self.read_back_bytes.wrapping_sub(earlier.read_back_bytes),
            field_read_backs: self.field_read_backs.wrapping_sub(earlier.field_read_backs),
        }
    }
}

thread_local! {
    static COUNTS: Cell<Transfers> = const {
        Cell::new(Transfers {
            uploaded_bytes: 0,
            read_back_bytes: 0,
            field_read_backs: 0,
        })
    };
}

fn add(f: impl FnOnce(&mut Transfers)) {
    COUNTS.with(|c| {
        let mut t = c.get();
        f(&mut t);
        c.set(t);
    });
}

/// This thread's cumulative traffic since it started.
pub fn snapshot() -> Transfers {
    COUNTS.with(Cell::get)
}

/// Counts `bytes` sent to the device (the context's upload helpers call it).
pub(crate) fn count_upload(bytes: u64) {
    add(|t| t.uploaded_bytes = t.uploaded_bytes.wrapping_add(bytes));
}

/// Counts `bytes` copied back from the device (the context's read-back helper calls it).
pub(crate) fn count_read_back(bytes: u64) {
    add(|t| t.read_back_bytes = t.read_back_bytes.wrapping_add(bytes));
}

/// Counts one GPU distance field read back as a CPU one: `GpuField::to_cpu` calls it (its
/// bytes are counted by the read-backs it makes).
pub fn count_field_read_back() {
    add(|t| t.field_read_backs = t.field_read_backs.wrapping_add(1));
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::test_context;

    #[test]
    fn counts_are_per_thread_and_diff() {
        let a = snapshot();
        count_upload(10);
        count_read_back(7);
        count_field_read_back();
        let d = snapshot().since(&a);
        assert_eq!(
            d,
            Transfers {
                uploaded_bytes: 10,
                read_back_bytes: 7,
                field_read_backs: 1
            }
        );
        let other = std::thread::spawn(|| {
            count_upload(1000);
            snapshot()
        })
        .join()
        .unwrap();
        assert_eq!(other.uploaded_bytes, 1000);
        assert_eq!(snapshot().since(&a).uploaded_bytes, 10);
    }

    #[test]
    fn every_helper_counts_its_bytes() {
        let Some(ctx) = test_context() else { return };
        let t0 = snapshot();
        let data: Vec<u32> = (0..100).collect();
        let b = ctx.storage_buffer("counted", &data).unwrap();
        assert_eq!(snapshot().since(&t0).uploaded_bytes, 400);
        let _u = ctx.uniform_buffer("counted uniform", &[1u32, 2, 3, 4]);
        assert_eq!(snapshot().since(&t0).uploaded_bytes, 416);
        ctx.queue
            .write_buffer(&b, 0, bytemuck::cast_slice(&data[..10]));
        assert_eq!(snapshot().since(&t0).uploaded_bytes, 456);
        let z = ctx.zeroed_buffer("not counted", 1 << 16).unwrap();
        assert_eq!(snapshot().since(&t0).uploaded_bytes, 456);
        let back: Vec<u32> = ctx.read_buffer(&b).unwrap();
        assert_eq!(back[..10], data[..10]);
        assert_eq!(snapshot().since(&t0).read_back_bytes, 400);
        let _: Vec<u8> = ctx.read_buffer(&z).unwrap();
        let d = snapshot().since(&t0);
        assert_eq!(
            (d.read_back_bytes, d.field_read_backs),
            (400 + (1 << 16), 0)
        );
    }

    /// The counters see every transfer only if nothing goes around the helpers: no source
    /// file of the workspace but `context.rs` maps a buffer, creates a buffer with contents
    /// (`create_buffer_init`, `mapped_at_creation: true`), writes through a staging view or
    /// takes a texture with data. (Queue writes go through [`crate::GpuQueue`], which
    /// counts; code cannot reach a bare `wgpu::Queue` of the context.)
    #[test]
    fn no_source_moves_data_around_the_counters() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let forbidden = [
            ".map_async(",
            "create_buffer_init",
            "mapped_at_creation: true",
            "write_buffer_with",
            "create_texture_with_data",
            "get_mapped_range_mut",
        ];
        let mut bad = Vec::new();
        let mut stack = vec![
            root.join("crates"),
            root.join("tests"),
            root.join("benches"),
        ];
        while let Some(dir) = stack.pop() {
            let Ok(entries) = std::fs::read_dir(&dir) else {
                continue;
            };
            for e in entries.flatten() {
                let p = e.path();
                if p.is_dir() {
                    if p.file_name().is_some_and(|n| n != "target") {
                        stack.push(p);
                    }
                    continue;
                }
                if p.extension().is_none_or(|x| x != "rs")
                    || p.ends_with("imprint-gpu/src/context.rs")
                    || p.ends_with("imprint-gpu/src/transfer.rs")
                {
                    continue;
                }
                let text = std::fs::read_to_string(&p).unwrap_or_default();
                for f in forbidden {
                    if text.contains(f) {
                        bad.push(format!("{}: {f}", p.display()));
                    }
                }
            }
        }
        assert!(
            bad.is_empty(),
            "data moved around the transfer counters (use the GpuContext helpers): {bad:#?}"
        );
    }
}
