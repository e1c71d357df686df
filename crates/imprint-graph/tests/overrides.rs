//! `--set NODE.FIELD=VALUE` edits the parsed file, not its text: an override's error names the
//! argument and says what is wrong (an unknown node or field with the names it could be, a
//! value out of its type's range, a node's own check) without a line and column of the file,
//! which does not hold the value; a valid override gives the plan the edited file gives.

use imprint_graph::{Error, load};
use std::path::{Path, PathBuf};

fn amortised() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines/amortised_cloth.ron")
}

fn err(path: &Path, sets: &[&str]) -> (String, Error) {
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let e = load(path, &sets).expect_err("the override must be refused");
    (e.to_string(), e)
}

/// The message has no `file:line:col` of the pipeline file.
fn not_located_in_file(msg: &str) {
    assert!(
        !msg.contains("amortised_cloth.ron:") && !msg.contains("p.ron:"),
        "points into the file: {msg}"
    );
}

#[test]
fn a_misspelt_field_names_the_argument_and_the_field_it_could_be() {
    let (msg, e) = err(&amortised(), &["cloth.params.substep=3"]);
    assert_eq!(e.exit_code(), 2);
    assert!(msg.starts_with("--set cloth.params.substep=3: "), "{msg}");
    assert!(msg.contains("no field 'substep'"), "{msg}");
    assert!(msg.contains("did you mean 'substeps'?"), "{msg}");
    // The node's fields are listed.
    assert!(
        msg.contains("material") && msg.contains("collision"),
        "{msg}"
    );
    not_located_in_file(&msg);

    // A misspelt field on the way to it, too.
    let (msg, _) = err(&amortised(), &["cloth.parms.substeps=3"]);
    assert!(
        msg.starts_with("--set cloth.parms.substeps=3: ") && msg.contains("did you mean 'params'?"),
        "{msg}"
    );
}

#[test]
fn a_negative_count_says_the_range() {
    let (msg, _) = err(&amortised(), &["cloth.params.substeps=-3"]);
    assert!(msg.starts_with("--set cloth.params.substeps=-3: "), "{msg}");
    assert!(
        msg.contains("expected an unsigned integer 0..=4294967295: substeps cannot be negative"),
        "{msg}"
    );
    not_located_in_file(&msg);
}

#[test]
fn an_unknown_node_lists_the_nodes() {
    let (msg, _) = err(&amortised(), &["nosuch.x=1"]);
    assert!(msg.starts_with("--set nosuch.x=1: "), "{msg}");
    assert!(msg.contains("no node named 'nosuch'"), "{msg}");
    assert!(
        msg.contains("bunny, boundary") || msg.contains("boundary, bunny"),
        "{msg}"
    );
    assert!(msg.contains("cloth") && msg.contains("render"), "{msg}");
    let (msg, _) = err(&amortised(), &["clot.params.substeps=3"]);
    assert!(msg.contains("did you mean 'cloth'?"), "{msg}");
}

#[test]
fn a_value_of_the_wrong_type_is_named() {
    let (msg, _) = err(&amortised(), &["cloth.params.substeps=\"many\""]);
    assert!(
        msg.starts_with("--set cloth.params.substeps=\"many\": ") && msg.contains("u32"),
        "{msg}"
    );
    let (msg, _) = err(&amortised(), &["cloth.params.substeps=(3"]);
    assert!(msg.contains("not a RON value"), "{msg}");
}

#[test]
fn a_node_check_failing_on_an_override_says_it_came_from_it() {
    // substeps 0 parses (a u32) and is refused by the cloth's own check.
    let (msg, e) = err(&amortised(), &["cloth.params.substeps=0"]);
    assert_eq!(e.exit_code(), 2);
    assert!(
        msg.starts_with("--set cloth.params.substeps=0: node 'cloth'"),
        "{msg}"
    );
    not_located_in_file(&msg);
    // split > every: the schedule's check.
    let (msg, _) = err(&amortised(), &["render.enabled=false", "field.split=9"]);
    assert!(
        msg.starts_with("--set field.split=9: node 'field': split must be between 1 and every"),
        "{msg}"
    );
}

/// A temp folder with `p.ron` holding `text`.
fn file(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("p.ron");
    std::fs::write(&path, text).unwrap();
    (dir, path)
}

const SMALL: &str = r#"// a comment: "cloth": Cloth(
Pipeline(frames: 2, fps: 24, backend: Cpu, nodes: {
    "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8)),
    "boundary": Voxelize(mesh: "ball", grid: Fit(resolution: 24, padding: 0.1)),
    "field": DistanceField(boundary: "boundary", band: 3),
    "cloth": Cloth(colliders: ["field"], params: (
        shape: Grid(size: (1.0, 1.0), resolution: (8, 8), center: (0.0, 1.0, 0.0), normal: (0, 1, 0)),
        material: Harada(k_structural: 60.0, k_shear: 15.0),
        substeps: 10,
    )),
    "obj": WriteMesh(mesh: "cloth"),
})"#;

/// The file's value after `load` with `sets`, and after editing the text by hand.
fn same_plan(sets: &[&str], by_hand: &[(&str, &str)]) {
    let (_d, path) = file(SMALL);
    let sets: Vec<String> = sets.iter().map(|s| s.to_string()).collect();
    let over = load(&path, &sets).unwrap();
    let mut text = SMALL.to_string();
    for (from, to) in by_hand {
        assert!(text.contains(from), "{from}");
        text = text.replacen(from, to, 1);
    }
    let (_d2, edited) = file(&text);
    let hand = load(&edited, &[]).unwrap();
    assert_eq!(format!("{:?}", over.file), format!("{:?}", hand.file));
    assert_eq!(over.order, hand.order);
    assert_eq!(over.pruned, hand.pruned);
    // The plan's text (which tells plans apart) is not the file's.
    assert_ne!(over.source.text, load(&path, &[]).unwrap().source.text);
}

#[test]
fn nested_overrides_give_the_plan_of_the_edited_file() {
    same_plan(
        &["boundary.grid.resolution=48"],
        &[("Fit(resolution: 24", "Fit(resolution: 48")],
    );
    same_plan(
        &["cloth.params.material.k_structural=10"],
        &[("k_structural: 60.0", "k_structural: 10")],
    );
    // A whole value, a variant switched, and two overrides in order.
    same_plan(
        &[
            "boundary.grid=Fit(resolution: 32)",
            "boundary.grid.padding=0.25",
            "cloth.params.material=Harada(k_structural: 5, k_shear: 1)",
        ],
        &[
            (
                "Fit(resolution: 24, padding: 0.1)",
                "Fit(resolution: 32, padding: 0.25)",
            ),
            (
                "Harada(k_structural: 60.0, k_shear: 15.0)",
                "Harada(k_structural: 5, k_shear: 1)",
            ),
        ],
    );
}

#[test]
fn a_field_the_file_leaves_at_its_default_is_set() {
    same_plan(
        &["field.backend=Some(Cpu)", "obj.every=2"],
        &[
            ("band: 3)", "band: 3, backend: Some(Cpu))"),
            (
                "WriteMesh(mesh: \"cloth\")",
                "WriteMesh(mesh: \"cloth\", every: 2)",
            ),
        ],
    );
    same_plan(
        &["field.backend=Cpu"],
        &[("band: 3)", "band: 3, backend: Cpu)")],
    );
}

#[test]
fn the_files_own_errors_stay_located_in_it() {
    // The file is parsed before the overrides: its error is at its line.
    let (_d, path) = file(&SMALL.replace("substeps: 10", "substeps: -3"));
    let (msg, e) = err(&path, &["obj.every=2"]);
    assert!(matches!(e, Error::Pipeline(_)), "{msg}");
    assert!(msg.contains("p.ron:9:"), "{msg}");
    assert!(
        msg.contains("expected an unsigned integer 0..=4294967295: substeps cannot be negative"),
        "{msg}"
    );
    // Without overrides, too; and a number too large for a u32.
    let (msg, _) = err(&path, &[]);
    assert!(msg.contains("substeps cannot be negative"), "{msg}");
    let (_d, path) = file(&SMALL.replace("substeps: 10", "substeps: 99999999999"));
    let (msg, _) = err(&path, &[]);
    assert!(
        msg.contains(
            "expected an unsigned integer 0..=4294967295: substeps 99999999999 is too large"
        ),
        "{msg}"
    );
    // A check the file fails by itself is the file's, even with an override elsewhere.
    let (_d, path) = file(&SMALL.replace("substeps: 10", "substeps: 0"));
    let (msg, e) = err(&path, &["obj.every=2"]);
    assert!(matches!(e, Error::Pipeline(_)), "{msg}");
    assert!(msg.starts_with(&format!("{}:", path.display())), "{msg}");
}

#[test]
fn every_shipped_pipeline_survives_an_override_round_trip() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../pipelines");
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "ron") {
            continue;
        }
        let plain = load(&path, &[]).unwrap();
        let (name, node) = plain.file.nodes.iter().next().unwrap();
        let enabled = if node.enabled() { "true" } else { "false" };
        let set = format!("{name}.enabled={enabled}");
        let over = load(&path, &[set]).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!(
            format!("{:?}", plain.file),
            format!("{:?}", over.file),
            "{}",
            path.display()
        );
    }
}
