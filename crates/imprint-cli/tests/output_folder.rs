//! The output folder: `manifest.json` lists what a run wrote; a rerun into the same folder
//! removes what the previous run wrote and it did not, and nothing else; a writer switched
//! off prunes the nodes that only feed it.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

mod common;
use common::{imprint, run_ok};

/// A sphere, rendered small on the CPU into `frames/`, and its mesh as OBJ every other
/// frame; `extra` adds nodes.
fn scene(frames: u32, extra: &str) -> String {
    format!(
        r#"Pipeline(
    frames: {frames},
    backend: Cpu,
    nodes: {{
        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 8, rings: 6),
                     motion: [Rigid(keys: [(time: 0), (time: 1, translate: (0.5, 0, 0))])]),
        "render": Render(objects: [Mesh(mesh: "ball", color: (0.8, 0.3, 0.2))],
                         camera: Orbit(distance: 2.0), width: 32, height: 24, samples: 1,
                         out: "frames/{{frame:04}}.png"),
        "obj": WriteMesh(mesh: "ball", every: 2),
        {extra}
    }},
)
"#
    )
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    std::fs::write(dir.join(name), text).unwrap();
    name.to_string()
}

/// Every file under `dir`, relative, with `/` separators.
fn files(dir: &Path) -> BTreeSet<String> {
    common::files_under(dir)
        .iter()
        .map(|p| p.to_string_lossy().replace('\\', "/"))
        .collect()
}

fn json(path: PathBuf) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap()
}

fn set(names: &[&str]) -> BTreeSet<String> {
    names.iter().map(|s| s.to_string()).collect()
}

/// The files the manifest lists for `node`.
fn listed(out: &Path, node: &str) -> BTreeSet<String> {
    let m = json(out.join("manifest.json"));
    m["files"][node]
        .as_array()
        .map(|a| a.iter().map(|v| v.as_str().unwrap().to_string()).collect())
        .unwrap_or_default()
}

#[test]
fn a_shorter_rerun_removes_the_frames_it_did_not_write_and_keeps_the_users_files() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = write(d, "p.ron", &scene(4, ""));
    run_ok(&["run", &p, "--out", "o"], d);
    let first = set(&[
        "frames/0000.png",
        "frames/0001.png",
        "frames/0002.png",
        "frames/0003.png",
        "obj/ball_0000.obj",
        "obj/ball_0002.obj",
        "manifest.json",
        "report.json",
    ]);
    assert_eq!(files(&d.join("o")), first);
    assert_eq!(
        listed(&d.join("o"), "render"),
        set(&[
            "frames/0000.png",
            "frames/0001.png",
            "frames/0002.png",
            "frames/0003.png"
        ])
    );
    // The user's own files in the folder, and in a writer's folder.
    std::fs::write(d.join("o/notes.txt"), b"mine").unwrap();
    std::fs::write(d.join("o/frames/keep.png"), b"mine").unwrap();

    run_ok(&["run", &p, "--out", "o", "--frames", "0..2"], d);
    let second = set(&[
        "frames/0000.png",
        "frames/0001.png",
        "frames/keep.png",
        "obj/ball_0000.obj",
        "manifest.json",
        "report.json",
        "notes.txt",
    ]);
    assert_eq!(files(&d.join("o")), second);
    let report = json(d.join("o/report.json"));
    assert_eq!(report["stale_removed"], 3, "{report}");
    let m = json(d.join("o/manifest.json"));
    assert!(m.get("stale").is_none(), "nothing is left to remove: {m}");
}

#[test]
fn a_renamed_output_leaves_no_old_folder_behind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = write(d, "p.ron", &scene(2, ""));
    run_ok(&["run", &p, "--out", "o"], d);
    assert!(d.join("o/frames/0001.png").is_file());
    let renamed = scene(2, "").replace("frames/{frame:04}.png", "shots/f{frame}.png");
    write(d, "p.ron", &renamed);
    run_ok(&["run", &p, "--out", "o"], d);
    assert!(!d.join("o/frames").exists(), "{:?}", files(&d.join("o")));
    assert!(d.join("o/shots/f1.png").is_file());
}

#[test]
fn a_resumed_run_keeps_the_files_of_the_frames_before_its_checkpoint() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = write(d, "p.ron", &scene(4, ""));
    let args = ["run", &p, "--out", "o", "--frames", "0..2"];
    run_ok(&[&args[..], &["--checkpoint-every", "1"]].concat(), d);
    run_ok(&["run", &p, "--out", "o", "--resume"], d);
    let out = d.join("o");
    for f in 0..4 {
        assert!(
            out.join(format!("frames/{f:04}.png")).is_file(),
            "frame {f}"
        );
    }
    assert_eq!(listed(&out, "render").len(), 4);
    assert_eq!(
        listed(&out, "obj"),
        set(&["obj/ball_0000.obj", "obj/ball_0002.obj"])
    );
    assert_eq!(listed(&out, "(run)"), set(&["checkpoint.bin"]));
    // A later run without checkpoints removes the stale checkpoint: nothing can resume from
    // a state this folder's outputs no longer match.
    run_ok(&["run", &p, "--out", "o"], d);
    assert!(!out.join("checkpoint.bin").exists());
}

#[test]
fn an_unreadable_manifest_stops_the_run_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let p = write(d, "p.ron", &scene(2, ""));
    std::fs::create_dir(d.join("o")).unwrap();
    std::fs::write(d.join("o/manifest.json"), "{\"files\": [").unwrap();
    let out = imprint(&["run", &p, "--out", "o"], d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("manifest.json:1:") && err.contains("delete it"),
        "{err}"
    );
    assert_eq!(files(&d.join("o")), set(&["manifest.json"]));
}

#[test]
fn a_writer_switched_off_prunes_the_nodes_that_only_feed_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let extra = r#""vox": Voxelize(mesh: "ball", grid: Fit(resolution: 16)),
        "field": DistanceField(boundary: "vox"),
        "slices": WriteField(field: "field", enabled: false),"#;
    let p = write(d, "p.ron", &scene(2, extra));
    let check = run_ok(&["check", &p], d);
    let said = String::from_utf8_lossy(&check.stdout);
    let pruned = said.split("pruned (will not run):").nth(1).unwrap_or("");
    for node in ["vox", "field"] {
        let line = pruned
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("{node} ")))
            .unwrap_or_else(|| panic!("no pruned line for {node}:\n{said}"));
        assert!(line.contains("switched off"), "{line}");
    }
    run_ok(&["run", &p, "--out", "o"], d);
    let report = json(d.join("o/report.json"));
    let nodes = report["nodes"].as_object().unwrap();
    assert!(
        !nodes.contains_key("vox") && !nodes.contains_key("field"),
        "{report}"
    );
    assert!(nodes.contains_key("ball") && nodes.contains_key("render"));
}
