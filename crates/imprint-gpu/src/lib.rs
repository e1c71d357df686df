//! imprint-gpu: the one place that talks to wgpu setup, so stages only write passes.
//!
//! - [`GpuContext`]: adapter choice (hardware first, a software Vulkan such as Mesa lavapipe
//!   accepted), one device per process, capability checks that turn "too big for this GPU"
//!   into a typed error instead of a wgpu panic, buffer upload and readback (the only ways,
//!   each counted per thread by [`transfer`]), and cached compute pipelines built from WGSL;
//! - [`shader!`]: embeds a WGSL file from the workspace `shaders/` folder, the same way for
//!   every stage;
//! - [`GpuTimer`]: per-pass GPU timestamps where the adapter has them, wall clock otherwise;
//! - [`test_context`]: what every GPU test calls, so a machine without a GPU skips politely;
//! - [`raster`]: GPU depth maps ([`raster::GpuRasterizer`], read back or left on the device)
//!   and the pieces every raster pass shares (camera uniform, render shader modules, growing
//!   buffers, texture readback);
//! - [`transfer`]: per-thread counts of the bytes every upload and read-back moves.
//!
//! This crate knows no stage: stages (in `imprint-stages`) own their shaders and passes.

mod context;
pub mod raster;
mod timer;
pub mod transfer;

pub use context::{GpuContext, GpuQueue, WORKGROUP_SIZE};
pub use timer::{Dispatch, GpuTimer, Timings, compute_pass, record_pass, submit};
pub use wgpu;

/// The WGSL source of a file under the workspace `shaders/` folder, embedded at compile time
/// (so a binary never depends on where it was built, and editing a shader rebuilds the crate).
///
/// `shader!("sdf/field.wgsl")` reads `<workspace>/shaders/sdf/field.wgsl`. The path is resolved
/// from the *calling* crate's manifest directory, which must be `crates/<name>/` (every
/// library crate of the workspace is).
#[macro_export]
macro_rules! shader {
    ($path:literal) => {
        include_str!(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../shaders/",
            $path
        ))
    };
}

/// The shared context for a GPU test, or `None` (with a note on stderr) where this machine has
/// no adapter. With `IMPRINT_REQUIRE_GPU=1` a missing adapter fails the test instead, so CI
/// that installed a driver cannot silently skip every GPU test.
pub fn test_context() -> Option<&'static GpuContext> {
    match GpuContext::shared() {
        Ok(ctx) => Some(ctx),
        Err(e) => {
            if std::env::var("IMPRINT_REQUIRE_GPU").is_ok_and(|v| v == "1") {
                panic!("IMPRINT_REQUIRE_GPU=1 but no GPU context: {e}");
            }
            eprintln!("skipped: no GPU adapter (set IMPRINT_REQUIRE_GPU=1 to fail instead)");
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::Error;

    #[test]
    fn buffers_round_trip_and_fill() {
        let Some(ctx) = test_context() else { return };
        let data: Vec<u32> = (0..1000).collect();
        let b = ctx.storage_buffer("data", &data).unwrap();
        assert_eq!(ctx.read_buffer::<u32>(&b).unwrap(), data);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        ctx.fill_u32(&mut encoder, &b, 7).unwrap();
        ctx.queue.submit([encoder.finish()]);
        assert!(ctx.read_buffer::<u32>(&b).unwrap().iter().all(|&v| v == 7));
        let z = ctx.zeroed_buffer("zeros", 10).unwrap();
        assert_eq!(ctx.read_buffer::<u32>(&z).unwrap(), vec![0; 4]);
    }

    #[test]
    fn shader_errors_are_errors_not_panics() {
        let Some(ctx) = test_context() else { return };
        let e = ctx
            .pipeline(
                "broken",
                &["@compute @workgroup_size(1) fn main() { let x: u32 = 1.5; }"],
                "main",
            )
            .unwrap_err();
        assert!(matches!(e, Error::Gpu(_)), "{e}");
        assert!(e.to_string().contains("broken"), "{e}");
    }

    #[test]
    fn oversized_buffers_are_refused() {
        let Some(ctx) = test_context() else { return };
        let e = ctx
            .zeroed_buffer("huge", ctx.max_storage_bytes() + 4)
            .unwrap_err();
        assert!(matches!(e, Error::TooLarge { .. }), "{e}");
        let e = ctx.check_grid("field", [4096, 4096, 4096], 16).unwrap_err();
        assert!(e.to_string().contains("4096x4096x4096"), "{e}");
    }

    #[test]
    fn timer_reports_every_pass() {
        let Some(ctx) = test_context() else { return };
        let b = ctx.zeroed_buffer("t", 4096).unwrap();
        let pipeline = ctx
            .pipeline(
                "fill",
                &[shader!("common/dispatch.wgsl"), shader!("common/fill.wgsl")],
                "fill_u32",
            )
            .unwrap();
        let params = ctx.uniform_buffer("p", &[5u32, 1024, 0, 0]);
        let bind = ctx.bind_group("t", &pipeline, &[(0, &params), (1, &b)]);
        let mut timer = GpuTimer::new(ctx);
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        for label in ["one", "two"] {
            let mut pass = compute_pass(&mut encoder, label, Some(&mut timer));
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &bind, &[]);
            ctx.dispatch_1d(&mut pass, 1024);
        }
        timer.submit(ctx, encoder);
        let t = timer.wait(ctx).unwrap();
        if ctx.has_timestamps() {
            let labels: Vec<_> = t.passes.iter().map(|(l, _)| l.as_str()).collect();
            assert_eq!(labels, ["one", "two"]);
        } else {
            assert!(t.passes.is_empty());
        }
        assert!(t.wall > std::time::Duration::ZERO);
        assert!(ctx.read_buffer::<u32>(&b).unwrap().iter().all(|&v| v == 5));
    }

    #[test]
    fn adapter_is_described() {
        let Some(ctx) = test_context() else { return };
        eprintln!(
            "adapter: {} (software: {}), max storage binding {}, timestamps {}",
            ctx.adapter_name(),
            ctx.is_software(),
            imprint_core::error::human_bytes(ctx.max_storage_bytes()),
            ctx.has_timestamps()
        );
        assert!(!ctx.adapter_name().is_empty());
    }
}
