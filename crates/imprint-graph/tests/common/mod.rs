//! What the graph's tests share: a plan from a few nodes.

use imprint_graph::diagnostics::Source;
use imprint_graph::{Plan, parse};
use std::path::Path;

/// A plan of `frames` frames at 24 fps on the CPU with `nodes` (RON map entries).
pub fn plan(frames: u32, nodes: &str) -> Plan {
    let text = format!("Pipeline(frames: {frames}, fps: 24, backend: Cpu, nodes: {{\n{nodes}\n}})");
    parse(
        Source {
            name: "test.ron".into(),
            text,
        },
        Path::new("."),
    )
    .unwrap()
}
