//! Rig files: a valid rig parses and poses; malformed ones give errors with the file, line,
//! column and what was expected, and exit code 2 (input to fix).

use glam::Vec3;
use imprint_graph::diagnostics::{PipelineError, Source};
use imprint_graph::rig::{LoadedRig, load, parse};
use imprint_graph::{Error, Result};
use std::path::Path;

const LIMB: &str = r#"Rig(
    bones: [
        (name: "upper", head: (0, 0, 0), tail: (0.5, 0, 0)),
        (name: "lower", head: (0.5, 0, 0), tail: (1.0, 0, 0), parent: "upper"),
    ],
    animation: [
        Keys(bone: "lower", interpolation: Linear, keys: [
            (time: 0.0, rotation: (axis: (0, 0, 1), degrees: 0)),
            (time: 1.0, rotation: (axis: (0, 0, 1), degrees: 90)),
        ]),
        Keys(bone: "upper", keys: [(time: 0.0, translation: (0, 0, 0)), (time: 2.0, translation: (0, 0, 1))]),
        Twist(bone: "lower", degrees: 180, start: 1.0, duration: 1.0),
    ],
)
"#;

fn parse_text(text: &str) -> Result<LoadedRig> {
    parse(
        &Source {
            name: "limb.ron".into(),
            text: text.into(),
        },
        Path::new("."),
    )
}

/// The located error of a text that must fail, after checking its exit code and display.
fn error_of(text: &str) -> Box<PipelineError> {
    let e = parse_text(text).expect_err("the rig must be rejected");
    assert_eq!(e.exit_code(), 2, "{e}");
    match e {
        Error::Pipeline(p) => {
            let shown = p.to_string();
            assert!(
                shown.starts_with(&format!("limb.ron:{}:{}: ", p.line, p.column)),
                "{shown}"
            );
            p
        }
        other => panic!("expected a located error, got {other}"),
    }
}

/// (line, column) of the n-th occurrence (0-based) of `needle` in `text`, 1-based.
fn at(text: &str, needle: &str, n: usize) -> (usize, usize) {
    let i = text
        .match_indices(needle)
        .nth(n)
        .unwrap_or_else(|| panic!("{needle} #{n}"))
        .0;
    let before = &text[..i];
    let line = before.matches('\n').count() + 1;
    let col = before.rfind('\n').map_or(i, |nl| i - nl - 1) + 1;
    (line, col)
}

#[test]
fn a_valid_rig_parses_and_poses() {
    let loaded = parse_text(LIMB).unwrap();
    let rig = &loaded.rig;
    assert!(loaded.mesh.is_none());
    assert_eq!(rig.bones.len(), 2);
    // t = 1: bent 90° about z at the joint; the root moved up half-way.
    let pose = rig.pose(1.0);
    let seg = rig.posed_segments(&pose);
    assert!(
        (seg[1].1 - Vec3::new(0.5, 0.5, 0.5)).length() < 1e-5,
        "{seg:?}"
    );
    // t = 2: then twisted 180° about the bent axis: its +z side faces -z.
    let pose = rig.pose(2.0);
    let p = pose.skin[1].transform_point3(Vec3::new(0.75, 0.0, 0.1));
    assert!((p - Vec3::new(0.5, 0.25, 0.9)).length() < 1e-5, "{p}");
    // The shipped example rig.
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/rigs/limb.ron");
    let limb = load(&path).unwrap().rig;
    let seg = limb.posed_segments(&limb.pose(2.0));
    assert!(
        (seg[1].1 - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-5,
        "{seg:?}"
    );
}

#[test]
fn the_mesh_binding_is_relative_to_the_rig_file() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir_all(dir.path().join("rigs")).unwrap();
    std::fs::create_dir_all(dir.path().join("meshes")).unwrap();
    std::fs::write(
        dir.path().join("meshes/tri.obj"),
        "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    )
    .unwrap();
    let with_mesh = |m: &str| {
        LIMB.replacen(
            "    animation",
            &format!("    mesh: \"{m}\",\n    animation"),
            1,
        )
    };
    let rig = dir.path().join("rigs/limb.ron");
    std::fs::write(&rig, with_mesh("../meshes/tri.obj")).unwrap();
    let loaded = load(&rig).unwrap();
    assert_eq!(
        loaded.mesh.unwrap().canonicalize().unwrap(),
        dir.path().join("meshes/tri.obj").canonicalize().unwrap()
    );
    std::fs::write(&rig, with_mesh("../meshes/none.obj")).unwrap();
    let e = load(&rig).unwrap_err();
    assert_eq!(e.exit_code(), 2);
    let shown = e.to_string();
    assert!(
        shown.contains("limb.ron:6:11: mesh file not found"),
        "{shown}"
    );
}

#[test]
fn a_syntax_error_is_located() {
    // A missing comma between two bones.
    let text = LIMB.replacen("(0.5, 0, 0)),\n", "(0.5, 0, 0))\n", 1);
    let e = error_of(&text);
    println!("{e}");
    assert_eq!((e.line, e.column), at(&text, "(name: \"lower\"", 0), "{e}");
    assert!(e.message.to_lowercase().contains("expected"), "{e}");
}

#[test]
fn an_unknown_field_is_located_and_named() {
    let text = LIMB.replacen("tail: (1.0", "tial: (1.0", 1);
    let e = error_of(&text);
    println!("{e}");
    assert_eq!((e.line, e.column), at(&text, "tial", 0), "{e}");
    assert!(e.message.contains("tial"), "{e}");
    assert!(
        e.help.as_deref().unwrap_or("").contains("tail"),
        "{:?}",
        e.help
    );
    // An unknown motion kind.
    let text = LIMB.replacen("Twist(", "Twirl(", 1);
    let e = error_of(&text);
    assert_eq!(e.line, at(&text, "Twirl", 0).0, "{e}");
    assert!(
        e.help
            .as_deref()
            .unwrap_or("")
            .contains("Keys, Bend or Twist")
    );
}

#[test]
fn an_unknown_parent_points_at_the_bone() {
    let text = LIMB.replacen("parent: \"upper\"", "parent: \"uper\"", 1);
    let e = error_of(&text);
    println!("{e}");
    assert_eq!((e.line, e.column), at(&text, "\"uper\"", 0), "{e}");
    assert!(
        e.message.contains("'lower'") && e.message.contains("'uper'"),
        "{e}"
    );
    assert!(
        e.message.contains("'upper'"),
        "the message lists the bones: {e}"
    );
    assert_eq!(e.label, "this parent");
}

#[test]
fn keys_out_of_order_point_at_the_key() {
    let text = LIMB.replacen("(time: 1.0, rotation", "(time: -1.0, rotation", 1);
    let e = error_of(&text);
    println!("{e}");
    assert_eq!((e.line, e.column), at(&text, "-1.0", 0), "{e}");
    assert!(
        e.message.contains("out of order") && e.message.contains("key 2"),
        "{e}"
    );
}

#[test]
fn translation_on_a_child_points_at_it() {
    let text = LIMB.replacen(
        "(time: 1.0, rotation: (axis: (0, 0, 1), degrees: 90))",
        "(time: 1.0, rotation: (axis: (0, 0, 1), degrees: 90), translation: (0, 1, 0))",
        1,
    );
    let e = error_of(&text);
    println!("{e}");
    assert_eq!((e.line, e.column), at(&text, "(0, 1, 0))", 0), "{e}");
    assert!(
        e.message.contains("root") && e.message.contains("'lower'"),
        "{e}"
    );
    // A cycle and a zero-length bone, located at the offending bone.
    let text = LIMB.replacen(
        "(name: \"upper\", head: (0, 0, 0), tail: (0.5, 0, 0))",
        "(name: \"upper\", head: (0, 0, 0), tail: (0.5, 0, 0), parent: \"lower\")",
        1,
    );
    let e = error_of(&text);
    assert!(e.message.contains("cycle"), "{e}");
    assert_eq!(e.line, 3, "{e}");
    let text = LIMB.replacen("tail: (1.0, 0, 0)", "tail: (0.5, 0, 0)", 1);
    let e = error_of(&text);
    assert!(e.message.contains("zero length"), "{e}");
    assert_eq!(
        (e.line, e.column),
        at(&text, "(0.5, 0, 0), parent", 0),
        "{e}"
    );
}
