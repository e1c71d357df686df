//! Per-node timing and metrics, collected every frame and written as `report.json`.

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
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
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
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

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Report {
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
    /// The frame the run resumed at, when it continued from a checkpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub resumed_at: Option<u32>,
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
