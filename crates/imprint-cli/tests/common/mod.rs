//! What every CLI test does: run the built `imprint` in a folder.

pub mod scenes;

use std::path::Path;
use std::process::{Command, Output};

/// Runs the built binary in `cwd` (with a runtime folder, so the graphics stack's probe has
/// one, and the default log level whatever `IMPRINT_LOG` the test runner has).
#[allow(dead_code)] // The sweep tests run it their own way.
pub fn imprint(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(args)
        .current_dir(cwd)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env_remove("IMPRINT_LOG")
        .output()
        .expect("imprint runs")
}

/// Runs `imprint` and expects success, showing its arguments and stderr otherwise.
#[allow(dead_code)] // The sweep tests run it their own way.
pub fn run_ok(args: &[&str], cwd: &Path) -> Output {
    let out = imprint(args, cwd);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Every file under `dir`, recursively, as paths relative to it (in no set order).
#[allow(dead_code)] // Only the tests that look at output folders use it.
pub fn files_under(dir: &Path) -> Vec<std::path::PathBuf> {
    let mut files = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                files.push(p.strip_prefix(dir).unwrap().to_path_buf());
            }
        }
    }
    files
}
