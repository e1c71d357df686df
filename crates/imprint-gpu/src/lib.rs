//! imprint-gpu: the one place that talks to wgpu setup, so stages only write passes.
//!
//! - [`GpuContext`]: adapter choice (hardware first, a software Vulkan such as Mesa lavapipe
//!   accepted), one device per process, capability checks that turn "too big for this GPU"
//!   into a typed error instead of a wgpu panic, buffer upload and readback, and cached
//!   compute pipelines built from WGSL;
//! - [`shader!`]: embeds a WGSL file from the workspace `shaders/` folder, the same way for
//!   every stage;
//! - [`GpuTimer`]: per-pass GPU timestamps where the adapter has them, wall clock otherwise;
//! - [`test_context`]: what every GPU test calls, so a machine without a GPU skips politely.
//!
//! This crate knows no stage: stages (in `imprint-stages`) own their shaders and passes.

mod context;
mod timer;

pub use context::{GpuContext, WORKGROUP_SIZE};
pub use timer::{GpuTimer, Timings, compute_pass};
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
        include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../../shaders/", $path))
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
