//! `imprint view`: a pipeline run live in a window. The executor is stepped from the window's
//! frame loop ([`session`]); the 3D view is drawn by the same GPU renderer as the `Render`
//! node, from its camera, so a frame on screen is the frame `imprint run` writes
//! (`display`); a panel (egui) shows each node's time, backend and metrics, and plays,
//! scrubs, hides objects, moves field slices and edits numbers (`panel`). The pipeline file
//! and its assets are watched ([`watch`]): a save reloads the plan keeping the state of every
//! node that did not change; a broken save is shown while the last good plan runs on. With a
//! target frame rate, the schedule of the expensive nodes is chosen to hold it
//! (`imprint_graph::budget`).
//!
//! Headless (tests, CI): `exit_after` frames, then the window's last frame to `screenshot`,
//! under Xvfb where there is no display.

mod app;
mod budget;
pub mod camera;
mod display;
mod edits;
mod panel;
pub mod scene;
pub mod session;
pub mod watch;

use imprint_graph::schema::Backend;
use std::ops::Range;
use std::path::PathBuf;

/// Width of the panel left of the 3D view, in points.
pub const PANEL_WIDTH: u32 = 340;

/// What `imprint view` was asked.
#[derive(Clone, Debug, Default)]
pub struct ViewOptions {
    pub file: PathBuf,
    pub backend: Option<Backend>,
    /// Frames per second to hold by choosing schedules; the file's fps paces playback
    /// otherwise.
    pub target_fps: Option<f64>,
    pub frames: Option<Range<u32>>,
    /// `--set NODE.FIELD=VALUE` overrides, as for `imprint run`.
    pub sets: Vec<String>,
    /// Size of the 3D view in pixels (default: the Render node's image, else 960 x 540).
    pub size: Option<[u32; 2]>,
    /// Run this many frames, save the screenshot (if asked) and exit.
    pub exit_after: Option<u32>,
    pub screenshot: Option<PathBuf>,
}

/// Why the viewer stopped, with the exit code it means: 2 for what the user must fix (no
/// display, a broken file with `--exit-after`), 1 for a failure while running.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct ViewError {
    pub code: u8,
    pub message: String,
}

impl ViewError {
    pub fn display(message: impl Into<String>) -> ViewError {
        ViewError {
            code: 2,
            message: message.into(),
        }
    }
    pub fn failed(message: impl Into<String>) -> ViewError {
        ViewError {
            code: 1,
            message: message.into(),
        }
    }
}

/// Opens the window and runs until it is closed (or `exit_after` frames have run).
pub fn run(opts: ViewOptions) -> Result<(), ViewError> {
    check_display()?;
    app::run(opts)
}

/// A window needs a display server; say which variables are missing and what to do.
fn check_display() -> Result<(), ViewError> {
    let set = |v: &str| std::env::var_os(v).is_some_and(|s| !s.is_empty());
    if cfg!(target_os = "linux") && !set("DISPLAY") && !set("WAYLAND_DISPLAY") {
        return Err(ViewError::display(
            "imprint view needs a display, and neither DISPLAY nor WAYLAND_DISPLAY is set; \
             on a machine without one, run it under Xvfb: xvfb-run -a imprint view FILE \
             (Debian: apt-get install xvfb)",
        ));
    }
    Ok(())
}
