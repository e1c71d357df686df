//! `imprint check` refuses what `imprint run` would: a `Fit` grid over a mesh that is
//! computed while running (a Cloth's output) exits 2 at the `grid` field, naming the Explicit
//! grid to write instead; a `Fit` grid over a Mesh node still checks and runs.

use std::path::Path;

mod common;
use common::{imprint, run_ok};

/// A falling 8 x 8 cloth, a ball, and `nodes` after them, written to `dir/p.ron`; the text.
fn write(dir: &Path, nodes: &str) -> String {
    let text = format!(
        r#"Pipeline(
    frames: 2,
    backend: Cpu,
    nodes: {{
        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8)),
        "cloth": Cloth(
            params: (
                shape: Grid(size: (1.0, 1.0), resolution: (8, 8), center: (0.0, 1.0, 0.0), normal: (0, 1, 0)),
                material: Harada(k_structural: 60.0, k_shear: 15.0),
                substeps: 10,
            ),
        ),
{nodes}
    }},
)
"#
    );
    std::fs::write(dir.join("p.ron"), &text).unwrap();
    text
}

/// `p.ron:LINE:COL` of the first `needle` in `text`.
fn at(text: &str, needle: &str) -> String {
    let i = text.find(needle).expect("needle in text");
    let before = &text[..i];
    let line = before.matches('\n').count() + 1;
    let col = before.len() - before.rfind('\n').map_or(0, |n| n + 1) + 1;
    format!("p.ron:{line}:{col}")
}

/// stderr with runs of whitespace made one space (the help may wrap).
fn stderr(out: &std::process::Output) -> String {
    String::from_utf8_lossy(&out.stderr)
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
}

/// `check` and `run` both exit 2 with the message at `grid: Fit` and the fix.
fn refused(nodes: &str, want: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let text = write(dir.path(), nodes);
    let place = at(&text, "grid: Fit");
    for args in [
        &["check", "p.ron"][..],
        &["run", "p.ron", "--out", "out"][..],
    ] {
        let out = imprint(args, dir.path());
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(&format!("{place}: node '")), "{args:?}: {err}");
        for w in want {
            assert!(err.contains(w), "{args:?}: no {w:?} in {err}");
        }
    }
    // Refused before anything ran: no frame was written.
    assert!(!dir.path().join("out").join("report.json").exists());
}

#[test]
fn check_refuses_a_heightmap_fit_over_a_cloth_at_its_grid_field() {
    refused(
        r#"        "top": Heightmap(
            grid: Fit(resolution: 32),
            mesh: "cloth",
        ),
        "hw": WriteHeightmap(heights: "top"),"#,
        &[
            "node 'top': Fit needs the box 'cloth' sweeps over the run before running",
            "'cloth' is a Cloth node, computed frame by frame",
            "grid: Explicit(origin: (x, z), cell: size, dims: (nx, nz))",
            "Fit works on the output of a Mesh node",
        ],
    );
}

#[test]
fn check_refuses_a_voxelize_fit_over_a_cloth_at_its_grid_field() {
    refused(
        r#"        "vox": Voxelize(
            grid: Fit(resolution: 16, padding: 0.2),
            mesh: "cloth",
        ),
        "field": DistanceField(boundary: "vox"),
        "fw": WriteField(field: "field"),"#,
        &[
            "node 'vox': Fit needs the box 'cloth' sweeps over the run before running",
            "'cloth' is a Cloth node",
            "grid: Explicit(origin: (x, y, z), cell: size, dims: (nx, ny, nz))",
        ],
    );
}

#[test]
fn a_fit_over_a_mesh_node_checks_and_runs() {
    let dir = tempfile::tempdir().unwrap();
    write(
        dir.path(),
        r#"        "top": Heightmap(mesh: "ball", grid: Fit(resolution: 24)),
        "hw": WriteHeightmap(heights: "top", formats: [Npy]),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 12)),
        "field": DistanceField(boundary: "vox"),
        "fw": WriteField(field: "field"),
        "cloth_top": Heightmap(mesh: "cloth", grid: Explicit(origin: (-0.6, -0.6), cell: 0.05, dims: (25, 25))),
        "chw": WriteHeightmap(heights: "cloth_top", formats: [Npy]),"#,
    );
    let out = run_ok(&["check", "p.ron"], dir.path());
    assert!(String::from_utf8_lossy(&out.stdout).contains("p.ron: valid"));
    run_ok(&["run", "p.ron", "--out", "out"], dir.path());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("out/report.json")).unwrap())
            .unwrap();
    for node in ["top", "vox", "field", "cloth_top"] {
        assert!(
            report["nodes"][node]["frames_run"]
                .as_array()
                .is_some_and(|f| !f.is_empty()),
            "{node}: {report}"
        );
    }
}
