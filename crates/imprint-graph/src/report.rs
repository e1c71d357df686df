//! Per-node timing and metrics, collected every frame and written as `report.json`.

use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The layout version [`Report::schema_version`] states (see there for when it goes up).
pub const REPORT_SCHEMA_VERSION: u32 = 1;

/// The program's version as reports state it; the binary sets it (with its git revision)
/// before running, as only the binary's build knows the revision.
static PROGRAM_VERSION: std::sync::OnceLock<String> = std::sync::OnceLock::new();

/// Names the program's version in every report written from now on (the first call wins).
pub fn set_program_version(version: &str) {
    let _ = PROGRAM_VERSION.set(version.to_string());
}

/// The version reports state: the binary's, else this crate's (no git revision known).
pub fn program_version() -> String {
    PROGRAM_VERSION
        .get()
        .cloned()
        .unwrap_or_else(|| env!("CARGO_PKG_VERSION").to_string())
}

/// Units of every number in the pipeline file and the files a run writes (the report's own
/// timings excepted: milliseconds, named `*_ms`).
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema, PartialEq)]
pub struct Units {
    /// Lengths and positions: metres.
    pub length: String,
    /// Times (motion keys, clip times, `fps`): seconds.
    pub time: String,
    /// Angles (rotations, twists, bends, repose angles): degrees.
    pub angle: String,
    /// Masses (cloth particles): kilograms.
    pub mass: String,
    /// The report's timings (`wall_ms`, `frame_ms`, `*_ms` of each node): milliseconds.
    pub durations: String,
}

impl Default for Units {
    fn default() -> Self {
        Units {
            length: "metre".into(),
            time: "second".into(),
            angle: "degree".into(),
            mass: "kilogram".into(),
            durations: "millisecond".into(),
        }
    }
}

/// The world's frame, and how height maps lay out their cells.
#[derive(Clone, Debug, Serialize, Deserialize, JsonSchema, PartialEq)]
pub struct Axes {
    /// Which way is up: `+y` (gravity is -y; height fields are heights in y over x-z).
    pub up: String,
    /// `right-handed` (x right, y up, z toward the viewer).
    pub handedness: String,
    /// What a row of a height map (PNG, EXR, `.npy`, preview) is: a line of constant z,
    /// row 0 the largest z.
    pub heightmap_rows: String,
    /// What a column of a height map is: a line of constant x, column 0 the smallest x.
    pub heightmap_columns: String,
}

impl Default for Axes {
    fn default() -> Self {
        Axes {
            up: "+y".into(),
            handedness: "right-handed".into(),
            heightmap_rows: imprint_render::heightmap::ROWS.into(),
            heightmap_columns: imprint_render::heightmap::COLUMNS.into(),
        }
    }
}

/// One node's runs, times and figures over the run.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
pub struct NodeReport {
    pub kind: String,
    /// "cpu" or "gpu".
    pub backend: String,
    /// Times the node computed or wrote (a node whose inputs did not change is not re-run;
    /// a build split over frames counts each part).
    pub runs: u32,
    /// The frames of those runs.
    pub frames_run: Vec<u32>,
    pub total_ms: f64,
    pub mean_ms: f64,
    pub max_ms: f64,
    /// Time spent measuring error against the exact reference (not part of the stage's time).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub measure_ms: f64,
    /// Bytes moved between host and GPU, per frame that moved any.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub transfers: Vec<FrameTransfers>,
    /// The stage's own figures (boundary points, band cells, error in cells, files written…).
    pub metrics: BTreeMap<String, serde_json::Value>,
    /// What the node warned about while running, each kind once per run
    /// ([`crate::node::FrameCtx::warn_once`]; also in the run's [`Report::warnings`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
}

/// Bytes a node moved between host and GPU on one frame.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
pub struct FrameTransfers {
    pub frame: u32,
    pub uploaded_bytes: u64,
    pub read_back_bytes: u64,
    /// Distance fields read back from the GPU.
    #[serde(default, skip_serializing_if = "is_zero_u64")]
    pub field_read_backs: u64,
}

fn is_zero_u64(v: &u64) -> bool {
    *v == 0
}

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl NodeReport {
    pub fn record(&mut self, frame: u32, ms: f64) {
        self.runs += 1;
        self.frames_run.push(frame);
        self.total_ms += ms;
        self.max_ms = self.max_ms.max(ms);
        self.mean_ms = self.total_ms / self.runs as f64;
    }
}

/// `report.json`: what ran, how long it took, what it measured, and what the numbers mean.
#[derive(Clone, Debug, Default, Serialize, Deserialize, JsonSchema)]
pub struct Report {
    /// The layout of this file ([`REPORT_SCHEMA_VERSION`]): raised when a field is removed,
    /// renamed or changes meaning, not when one is added, so a reader that knows version N
    /// reads every file of version N.
    #[serde(default)]
    pub schema_version: u32,
    /// The imprint that wrote the file: its version and git revision, as `imprint --version`
    /// prints them.
    #[serde(default)]
    pub imprint_version: String,
    /// The `--set NODE.FIELD=VALUE` arguments of the run, as given and in their order.
    #[serde(default)]
    pub overrides: Vec<String>,
    /// The units of the pipeline file and of every file the run writes.
    #[serde(default)]
    pub units: Units,
    /// The world's axes, and how height maps lay them out.
    #[serde(default)]
    pub axes: Axes,
    /// The pipeline file, as named on the command line.
    pub pipeline: String,
    pub frames: Vec<u32>,
    pub fps: f32,
    /// The GPU adapter used, if any node ran on the GPU.
    pub adapter: Option<String>,
    pub threads: usize,
    pub wall_ms: f64,
    /// Wall time of each frame (all its nodes, writers included; an observer's time not), ms.
    pub frame_ms: Vec<f64>,
    pub nodes: BTreeMap<String, NodeReport>,
    pub pruned: Vec<(String, String)>,
    pub files_written: usize,
    /// What the user should know: the plan's and the stages' construction warnings (printed
    /// by the binary before the run), then what nodes warned about while running (each kind
    /// once per node and run, `node 'NAME': …`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// Why the run stopped early, when it did (the frames above are those done).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// Whether the run did all its frames and its whole-run writers: false in a report
    /// written at a checkpoint or by a run that stopped early.
    #[serde(default)]
    pub complete: bool,
    /// The frame the run resumed at, when it continued from a checkpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resumed_at: Option<u32>,
    /// Files the folder's previous run wrote and this one did not, removed at its end
    /// (`manifest.json` lists what each run wrote).
    #[serde(default, skip_serializing_if = "is_zero_usize")]
    pub stale_removed: usize,
}

fn is_zero_usize(v: &usize) -> bool {
    *v == 0
}

impl Report {
    /// The per-node timing table printed at the end of a run.
    pub fn table(&self, order: &[String]) -> String {
        let mut s = format!(
            "{:<16} {:<14} {:>4} {:>6} {:>10} {:>10} {:>10}\n",
            "node", "kind", "on", "runs", "total ms", "mean ms", "max ms"
        );
        for name in order {
            if let Some(n) = self.nodes.get(name) {
                s += &format!(
                    "{:<16} {:<14} {:>4} {:>6} {:>10.1} {:>10.2} {:>10.2}\n",
                    name, n.kind, n.backend, n.runs, n.total_ms, n.mean_ms, n.max_ms
                );
            }
        }
        for (name, why) in &self.pruned {
            s += &format!("{name:<16} pruned: {why}\n");
        }
        s += &format!(
            "{} frame(s) in {:.1} ms ({} threads){}",
            self.frames.len(),
            self.wall_ms,
            self.threads,
            self.adapter
                .as_ref()
                .map_or(String::new(), |a| format!(", GPU: {a}"))
        );
        s
    }
}
