//! The viewer's pipeline side without a window: a save reloads the plan keeping the state
//! of every node that did not change (the falling cloth goes on exactly as if nothing had
//! happened), a changed node starts again, a broken save is shown with its line and column
//! while the last good plan runs on, and a live edit written back keeps the file's comments.

use imprint_graph::value::Value;
use imprint_view::session::{Reloaded, Session};
use std::path::{Path, PathBuf};

const PIPELINE: &str = r#"// A small cloth falling onto Suzanne.
Pipeline(
    frames: 30,
    fps: 24,
    backend: Cpu,
    nodes: {
        "head": Mesh(path: "MESH", fit: (size: 0.6, center: (0, 0.3, 0))),
        "boundary": Voxelize(mesh: "head", grid: Fit(resolution: 24, padding: 0.1)),
        "field": DistanceField(boundary: "boundary", band: 3, measure: Never),
        "cloth": Cloth(
            colliders: ["field"],
            params: (
                shape: Grid(size: (0.8, 0.8), resolution: (10, 10), center: (0.0, 0.8, 0.0), normal: (0, 1, 0)),
                material: Harada(k_structural: 30.0, k_shear: 7.5),
                mass: 0.002,
                substeps: 8, // stable for this size
                collision: (epsilon: 0.01, friction: 0.3, ground: 0.0),
            ),
        ),
        "render": Render(
            objects: [Mesh(mesh: "head"), Mesh(mesh: "cloth", color: (0.2, 0.4, 0.8))],
            camera: Orbit(target: (0, 0.3, 0), distance: 2.0),
        ),
    },
)
"#;

fn write_pipeline(dir: &Path) -> PathBuf {
    let mesh = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/meshes/suzanne.obj");
    let path = dir.join("fall.ron");
    let text = PIPELINE.replace("MESH", &mesh.canonicalize().unwrap().display().to_string());
    std::fs::write(&path, text).unwrap();
    path
}

fn cloth(s: &Session) -> Vec<glam::Vec3> {
    match s.executor().unwrap().value("cloth") {
        Some(Value::Mesh(m)) => m.positions.clone(),
        _ => panic!("the cloth has a mesh"),
    }
}

fn steps(s: &mut Session, n: u32) {
    for _ in 0..n {
        assert!(s.step(false), "{:?}", s.problem());
    }
}

fn edit_file(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{from}");
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

#[test]
fn a_save_that_touches_only_the_picture_keeps_the_cloth_falling() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    let mut whole = Session::open(&path, &[], None, None);
    let mut edited = Session::open(&path, &[], None, None);
    assert!(whole.problem().is_none(), "{:?}", whole.problem());
    steps(&mut whole, 12);
    steps(&mut edited, 6);
    let before = cloth(&edited);
    edit_file(&path, "color: (0.2, 0.4, 0.8)", "color: (0.0, 1.0, 0.0)");
    // The Render node is not run live: nothing is built anew.
    assert_eq!(edited.reload(), Reloaded::Applied { rebuilt: vec![] });
    assert_eq!(edited.shown_frame(), Some(5));
    assert_eq!(cloth(&edited), before, "the reload itself moves nothing");
    steps(&mut edited, 6);
    assert_eq!(
        cloth(&edited),
        cloth(&whole),
        "frame 11 as if no reload happened"
    );
}

#[test]
fn a_changed_node_and_what_reads_it_start_again() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    let mut s = Session::open(&path, &[], None, None);
    steps(&mut s, 6);
    edit_file(&path, "substeps: 8", "substeps: 10");
    let Reloaded::Applied { rebuilt } = s.reload() else {
        panic!("{:?}", s.problem());
    };
    assert_eq!(rebuilt, ["cloth"]);
    // Built anew at rest: its next frame is the first frame's fall from the start pose, not
    // frame 6's.
    let mut fresh = Session::open(&path, &[], None, None);
    steps(&mut fresh, 1);
    steps(&mut s, 1);
    assert_eq!(s.shown_frame(), Some(6));
    let (a, b) = (cloth(&s), cloth(&fresh));
    let moved = a
        .iter()
        .zip(&b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0f32, f32::max);
    assert!(
        moved < 0.05,
        "the rebuilt cloth starts from its rest pose ({moved} m)"
    );
}

#[test]
fn a_broken_save_is_shown_and_the_last_good_plan_runs_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    let mut s = Session::open(&path, &[], None, None);
    steps(&mut s, 3);
    edit_file(&path, "substeps: 8,", "substeps: 8 8,");
    assert_eq!(s.reload(), Reloaded::Refused);
    let p = s.problem().expect("a problem to show").clone();
    assert!(p.still_running);
    let line = PIPELINE
        .lines()
        .position(|l| l.contains("substeps"))
        .unwrap()
        + 1;
    let at = format!("fall.ron:{line}:");
    assert!(p.message.contains(&at), "{} should name {at}", p.message);
    assert!(p.detail.contains("substeps: 8 8"), "{}", p.detail);
    steps(&mut s, 3);
    assert_eq!(s.shown_frame(), Some(5));
    // Fixed again: the problem goes, nothing is rebuilt (the text is the running one).
    edit_file(&path, "substeps: 8 8,", "substeps: 8,");
    assert_eq!(s.reload(), Reloaded::Unchanged);
    assert!(s.problem().is_none());
}

#[test]
fn a_file_broken_at_start_waits_for_a_good_save() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    edit_file(&path, "frames: 30", "frames: -30");
    let mut s = Session::open(&path, &[], None, None);
    assert!(s.executor().is_none());
    assert!(!s.problem().unwrap().still_running);
    assert!(!s.step(true));
    edit_file(&path, "frames: -30", "frames: 30");
    assert!(matches!(s.reload(), Reloaded::Applied { .. }));
    steps(&mut s, 1);
}

#[test]
fn live_edits_apply_at_once_and_write_back_keeping_comments() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    let original = std::fs::read_to_string(&path).unwrap();
    let mut s = Session::open(&path, &[], None, None);
    steps(&mut s, 2);
    let Reloaded::Applied { rebuilt } = s.edit("cloth.params.substeps=12".into()) else {
        panic!("{:?}", s.problem());
    };
    assert_eq!(rebuilt, ["cloth"]);
    // A value the file's checks refuse is dropped, and said.
    assert_eq!(s.edit("cloth.params.substeps=-3".into()), Reloaded::Refused);
    assert_eq!(s.edits(), ["cloth.params.substeps=12"]);
    assert_eq!(
        std::fs::read_to_string(&path).unwrap(),
        original,
        "nothing written yet"
    );
    s.write_edits().unwrap();
    let written = std::fs::read_to_string(&path).unwrap();
    assert_eq!(written, original.replace("substeps: 8,", "substeps: 12,"));
    assert!(written.contains("// stable for this size"));
    assert_eq!(
        s.reload(),
        Reloaded::Unchanged,
        "the file now says what runs"
    );
}

#[test]
fn scrubbing_back_shows_the_same_values_as_the_first_time() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    let mut s = Session::open(&path, &[], None, None);
    steps(&mut s, 10);
    let at_9 = cloth(&s);
    s.show(3);
    assert_eq!(s.shown_frame(), Some(3));
    s.show(9);
    assert_eq!(cloth(&s), at_9);
}

#[test]
fn a_saved_asset_rebuilds_the_nodes_that_read_it_and_what_follows() {
    let dir = tempfile::tempdir().unwrap();
    let suzanne = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/meshes/suzanne.obj");
    let mesh = dir.path().join("head.obj");
    std::fs::copy(&suzanne, &mesh).unwrap();
    let path = write_pipeline(dir.path());
    edit_file(
        &path,
        &suzanne.canonicalize().unwrap().display().to_string(),
        "head.obj",
    );
    let mut s = Session::open(&path, &[], None, None);
    steps(&mut s, 2);
    // The file's text did not change, but the mesh it reads did.
    let stale = std::collections::BTreeSet::from(["head".to_string()]);
    let Reloaded::Applied { rebuilt } = s.reload_with(&stale) else {
        panic!("{:?}", s.problem());
    };
    assert_eq!(rebuilt, ["head", "boundary", "field", "cloth"]);
    assert_eq!(
        s.reload(),
        Reloaded::Unchanged,
        "without a changed asset nothing happens"
    );
}

/// A file whose only writer is switched off runs nothing offline (its nodes feed only that
/// writer, so `run` prunes them), yet the viewer still runs and shows them.
#[test]
fn the_viewer_runs_what_a_switched_off_writer_would_show() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_pipeline(dir.path());
    edit_file(
        &path,
        "camera: Orbit(target: (0, 0.3, 0), distance: 2.0),",
        "camera: Orbit(target: (0, 0.3, 0), distance: 2.0), enabled: false,",
    );
    let plan = imprint_graph::plan::load(&path, &[]).unwrap();
    assert!(
        plan.order.is_empty(),
        "offline, nothing runs: {:?}",
        plan.order
    );
    let mut s = Session::open(&path, &[], None, None);
    steps(&mut s, 3);
    assert_eq!(cloth(&s).len(), 100, "the cloth runs live");
}
