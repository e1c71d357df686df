//! Resumable runs: a run cut into pieces with `--checkpoint-every` and `--resume` ends with
//! the same bytes as one uninterrupted run, for every node kind that carries state from frame
//! to frame; an interrupted run keeps its report and checkpoint; bad `--resume` input is
//! refused with exit code 2 and changes nothing.

use std::path::Path;
use std::process::Command;

mod common;
use common::scenes::{assert_same_outputs, outputs, stateful_scene, stateful_scene_on};
use common::{imprint, run_ok};

fn report(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("report.json")).unwrap()).unwrap()
}

/// A run cut in three (4 frames, then on to 8 from the checkpoint, then on to 12, each piece
/// with other checkpoint spacings) ends with the same bytes as one run of 12 frames: cloths
/// against interpolated and depth-map colliders, ground, snow, particle skinning, split
/// field builds, and the contact sheet and GIF. Its report lists all 12 frames.
#[test]
fn a_run_cut_in_three_with_resume_equals_the_whole_run() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("scene.ron");
    std::fs::write(&file, stateful_scene(12)).unwrap();
    let f = file.to_str().unwrap();
    run_ok(&["run", f, "--out", "whole"], dir.path());
    let cut = ["run", f, "--out", "cut"];
    run_ok(
        &[&cut[..], &["--frames", "0..4", "--checkpoint-every", "3"]].concat(),
        dir.path(),
    );
    let out = run_ok(
        &[
            &cut[..],
            &["--frames", "0..8", "--resume", "--checkpoint-every", "1"],
        ]
        .concat(),
        dir.path(),
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("resuming at frame 4"));
    run_ok(
        &[&cut[..], &["--frames", "0..12", "--resume"]].concat(),
        dir.path(),
    );
    assert_same_outputs(&dir.path().join("whole"), &dir.path().join("cut"));
    let r = report(&dir.path().join("cut"));
    assert_eq!(r["frames"].as_array().unwrap().len(), 12, "{}", r["frames"]);
    assert_eq!(r["resumed_at"], 8);
    // The cloth's per-frame metrics run on across the cuts, one entry per frame.
    let per_frame = &r["nodes"]["cloth"]["metrics"]["per_frame"];
    assert_eq!(per_frame.as_array().unwrap().len(), 12);
    // No temporary file is left behind.
    let tmp: Vec<_> = outputs(&dir.path().join("cut"))
        .into_keys()
        .filter(|p| p.to_string_lossy().contains(".tmp"))
        .collect();
    assert!(tmp.is_empty(), "{tmp:?}");
}

/// The same on the GPU (the software adapter in CI): GPU cloths, field builds, ground
/// passes, snow maps and particle skinning are checkpointed through their CPU mirrors and
/// rebuilt on the GPU, and the cut run equals the whole one byte for byte.
#[test]
fn a_gpu_run_cut_in_three_equals_the_whole_gpu_run() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("scene.ron");
    std::fs::write(&file, stateful_scene_on(6, "Gpu")).unwrap();
    let f = file.to_str().unwrap();
    let whole = imprint(&["run", f, "--out", "whole"], dir.path());
    let err = String::from_utf8_lossy(&whole.stderr);
    if whole.status.code() == Some(1) && err.contains("no GPU adapter") {
        assert!(
            std::env::var("IMPRINT_REQUIRE_GPU").as_deref() != Ok("1"),
            "IMPRINT_REQUIRE_GPU=1 but: {err}"
        );
        eprintln!("skipped: no GPU adapter (set IMPRINT_REQUIRE_GPU=1 to fail instead)");
        return;
    }
    assert_eq!(whole.status.code(), Some(0), "{err}");
    let report = report(&dir.path().join("whole"));
    for node in ["cloth", "field", "prints", "snow", "skin"] {
        assert_eq!(report["nodes"][node]["backend"], "gpu", "{node}");
    }
    let cut = ["run", f, "--out", "cut"];
    run_ok(
        &[&cut[..], &["--frames", "0..2", "--checkpoint-every", "2"]].concat(),
        dir.path(),
    );
    run_ok(
        &[
            &cut[..],
            &["--frames", "0..4", "--resume", "--checkpoint-every", "1"],
        ]
        .concat(),
        dir.path(),
    );
    run_ok(
        &[&cut[..], &["--frames", "0..6", "--resume"]].concat(),
        dir.path(),
    );
    assert_same_outputs(&dir.path().join("whole"), &dir.path().join("cut"));
}

/// Ctrl-C stops a run between frames with exit code 130, leaving report.json with the frames
/// done and why, and a checkpoint that a resumed run finishes from to the same bytes.
#[test]
fn an_interrupted_run_keeps_its_report_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("scene.ron");
    std::fs::write(&file, stateful_scene(12)).unwrap();
    let f = file.to_str().unwrap();
    run_ok(&["run", f, "--out", "whole"], dir.path());
    let cut = dir.path().join("cut");
    let mut child = Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(["run", f, "--out", "cut", "--checkpoint-every", "2"])
        .current_dir(dir.path())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    // Interrupt once the first checkpoint is there (the run is then under way).
    let start = std::time::Instant::now();
    while !cut.join("checkpoint.bin").exists() && start.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let pid = child.id().to_string();
    Command::new("kill").args(["-INT", &pid]).status().unwrap();
    let status = child.wait().unwrap();
    let r = report(&cut);
    let done = r["frames"].as_array().unwrap().len();
    if status.code() == Some(0) {
        // The run finished before the signal arrived: nothing to resume.
        assert_eq!(done, 12);
    } else {
        assert_eq!(status.code(), Some(130));
        assert!(done < 12);
        let why = r["error"].as_str().unwrap();
        assert!(
            why.contains(&format!("interrupted before frame {done}")),
            "{why}"
        );
        let out = run_ok(&["run", f, "--out", "cut", "--resume"], dir.path());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(err.contains(&format!("resuming at frame {done}")), "{err}");
    }
    assert_same_outputs(&dir.path().join("whole"), &cut);
}

/// `--resume` into a folder with no checkpoint, with a checkpoint of another pipeline, or of
/// a run that began at another frame: exit code 2, a message that says what to do, and the
/// folder's files unchanged.
#[test]
fn bad_resume_input_is_refused_and_changes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = d.join("scene.ron");
    std::fs::write(&file, stateful_scene(6)).unwrap();
    let f = file.to_str().unwrap();

    let out = imprint(&["run", f, "--out", "empty", "--resume"], d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("no checkpoint in") && err.contains("--checkpoint-every"),
        "{err}"
    );
    assert!(!d.join("empty/report.json").exists());

    run_ok(
        &[
            "run",
            f,
            "--out",
            "o",
            "--frames",
            "0..3",
            "--checkpoint-every",
            "3",
        ],
        d,
    );
    let before = outputs(&d.join("o"));
    let report_before = std::fs::read(d.join("o/report.json")).unwrap();
    let checkpoint_before = std::fs::read(d.join("o/checkpoint.bin")).unwrap();
    let unchanged = || {
        assert_eq!(outputs(&d.join("o")), before);
        assert_eq!(
            std::fs::read(d.join("o/report.json")).unwrap(),
            report_before
        );
        assert_eq!(
            std::fs::read(d.join("o/checkpoint.bin")).unwrap(),
            checkpoint_before
        );
    };

    let other = d.join("other.ron");
    let text = stateful_scene(6).replacen("k_structural: 30.0", "k_structural: 60.0", 1);
    assert_ne!(text, stateful_scene(6));
    std::fs::write(&other, text).unwrap();
    let out = imprint(
        &["run", other.to_str().unwrap(), "--out", "o", "--resume"],
        d,
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("different pipeline") && err.contains("node 'cloth'"),
        "{err}"
    );
    unchanged();

    let out = imprint(&["run", f, "--out", "o", "--frames", "1..6", "--resume"], d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("began at frame 0") && err.contains("--frames 0..6"),
        "{err}"
    );
    unchanged();

    let out = imprint(&["run", f, "--out", "o", "--frames", "0..2", "--resume"], d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("at frame 3, outside --frames 0..2"), "{err}");
    unchanged();

    std::fs::create_dir_all(d.join("garbage")).unwrap();
    std::fs::write(d.join("garbage/checkpoint.bin"), b"not a checkpoint").unwrap();
    let out = imprint(&["run", f, "--out", "garbage", "--resume"], d);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("not an imprint checkpoint"), "{err}");
}
