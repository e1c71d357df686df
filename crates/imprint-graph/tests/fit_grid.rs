//! A `Fit` grid needs the box its mesh sweeps over the run before the run starts. Only a Mesh
//! node knows it; over any other mesh producer (a Cloth, a Drape) the plan refuses the grid
//! at the `grid` field, naming the Explicit grid to write instead, so that what `check`
//! accepts also runs.

use imprint_graph::diagnostics::Source;
use imprint_graph::exec::{RunOptions, run};
use imprint_graph::{Error, PipelineError, Plan, parse};
use std::path::Path;

/// A cloth of 8 x 8 particles falling from y = 1, a ball under it, and `consumer` (one node
/// entry, the last one) reading one of them; the file's text and its parse.
fn pipeline(consumer: &str) -> (String, imprint_graph::Result<Plan>) {
    let text = format!(
        r#"Pipeline(frames: 3, fps: 24, backend: Cpu, nodes: {{
    "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8)),
    "cloth": Cloth(params: (
        shape: Grid(size: (1.0, 1.0), resolution: (8, 8), center: (0.0, 1.0, 0.0), normal: (0, 1, 0)),
        material: Harada(k_structural: 60.0, k_shear: 15.0),
        substeps: 10,
    )),
    "draped": Drape(body: "ball", garment: "cloth"),
{consumer}
}})"#
    );
    let plan = parse(
        Source {
            name: "fit.ron".into(),
            text: text.clone(),
        },
        Path::new("."),
    );
    (text, plan)
}

fn refused(consumer: &str) -> (String, PipelineError) {
    let (text, plan) = pipeline(consumer);
    match plan {
        Err(Error::Pipeline(e)) => (text, *e),
        Err(e) => panic!("expected a pipeline error, got {e}"),
        Ok(_) => panic!("plan accepted a Fit grid over a computed mesh:\n{consumer}"),
    }
}

/// 1-based line and column of the first `needle` in `text`.
fn line_col(text: &str, needle: &str) -> (usize, usize) {
    let at = text.find(needle).expect("needle in text");
    let before = &text[..at];
    let line = before.matches('\n').count() + 1;
    let column = before.len() - before.rfind('\n').map_or(0, |i| i + 1) + 1;
    (line, column)
}

fn run_plan(p: &Plan) -> imprint_graph::report::Report {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        out: dir.path().to_path_buf(),
        ..Default::default()
    };
    run(p, &opts, &mut |_, _| {}).unwrap()
}

#[test]
fn a_fit_grid_over_a_cloth_or_drape_is_refused_at_its_grid_field_with_the_fix() {
    let cases = [
        // (consumer, mesh, kind, the Explicit grid the fix names)
        (
            "    \"top\": Heightmap(\n        grid: Fit(resolution: 32),\n        mesh: \"cloth\",\n    ),",
            "cloth",
            "Cloth",
            "grid: Explicit(origin: (x, z), cell: size, dims: (nx, nz))",
        ),
        (
            "    \"top\": Heightmap(\n        grid: Fit(resolution: 32),\n        mesh: \"draped\",\n    ),",
            "draped",
            "Drape",
            "grid: Explicit(origin: (x, z), cell: size, dims: (nx, nz))",
        ),
        (
            "    \"vox\": Voxelize(\n        grid: Fit(resolution: 16, padding: 0.2),\n        mesh: \"cloth\",\n    ),",
            "cloth",
            "Cloth",
            "grid: Explicit(origin: (x, y, z), cell: size, dims: (nx, ny, nz))",
        ),
        (
            "    \"vox\": Voxelize(\n        grid: Fit(resolution: 16),\n        mesh: \"draped\",\n    ),",
            "draped",
            "Drape",
            "grid: Explicit(origin: (x, y, z), cell: size, dims: (nx, ny, nz))",
        ),
    ];
    for (consumer, mesh, kind, explicit) in cases {
        let (text, e) = refused(consumer);
        assert!(
            e.message.contains("Fit needs the box")
                && e.message.contains(&format!("'{mesh}' is a {kind} node")),
            "{}",
            e.message
        );
        assert_eq!(
            (e.line, e.column),
            line_col(&text, "grid: Fit"),
            "{consumer}"
        );
        let help = e.help.expect("a fix");
        assert!(
            help.contains(explicit) && help.contains("Mesh node"),
            "{help}"
        );
    }
}

#[test]
fn a_fit_grid_over_a_mesh_node_passes_and_runs() {
    let (_, plan) = pipeline(
        r#"    "top": Heightmap(mesh: "ball", grid: Fit(resolution: 20, padding: 0.0)),
    "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 12)),
    "hw": WriteHeightmap(heights: "top"),
    "field": DistanceField(boundary: "vox"),
    "fw": WriteField(field: "field"),"#,
    );
    let plan = plan.unwrap_or_else(|e| panic!("{e}"));
    let report = run_plan(&plan);
    for node in ["top", "vox", "field"] {
        assert_eq!(report.nodes[node].frames_run, [0], "{node}");
    }
}

#[test]
fn an_explicit_grid_over_a_cloth_passes_and_runs() {
    let (_, plan) = pipeline(
        r#"    "top": Heightmap(mesh: "cloth", grid: Explicit(origin: (-0.6, -0.6), cell: 0.05, dims: (25, 25))),
    "hw": WriteHeightmap(heights: "top"),"#,
    );
    let plan = plan.unwrap_or_else(|e| panic!("{e}"));
    let report = run_plan(&plan);
    assert_eq!(report.nodes["top"].frames_run, [0, 1, 2]);
}

#[test]
fn the_fit_check_comes_after_the_value_checks() {
    // A Fit grid's own values are checked first: the resolution is the first thing wrong.
    let (_, e) = refused(
        "    \"top\": Heightmap(mesh: \"cloth\", grid: Fit(resolution: 0)),\n    \"hw\": WriteHeightmap(heights: \"top\"),",
    );
    assert!(
        e.message.contains("resolution must be in 1..="),
        "{}",
        e.message
    );
}
