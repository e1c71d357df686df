//! `imprint sweep` as users meet it, on a tiny pipeline (a breathing sphere, a 24³ field, an
//! 8×8 cloth on it, 6 frames): one CSV row per combination plus the reference row (`ref`,
//! first), zero error where a run is the reference, error growing as the field is rebuilt
//! less often, the plot a PNG of the stated size, the reference cached between sweeps, and
//! bad `--vary` refused with exit code 2 before anything runs.

use std::path::Path;

/// What a run of `imprint` said: exit code, stdout, stderr.
struct Said {
    code: Option<i32>,
    out: String,
    err: String,
}

/// Runs the built binary in `cwd`, as `tests/cli.rs` does.
fn imprint(args: &[&str], cwd: &Path) -> Said {
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(args)
        .current_dir(cwd)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("imprint runs");
    Said {
        code: o.status.code(),
        out: String::from_utf8_lossy(&o.stdout).into_owned(),
        err: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

/// Runs `imprint`, expecting success; its stdout.
mod common;
use common::scenes::untimed_csv;

fn run_ok(args: &[&str], cwd: &Path) -> String {
    let said = imprint(args, cwd);
    assert_eq!(said.code, Some(0), "{}", said.err);
    said.out
}

const PIPELINE: &str = r#"Pipeline(
    frames: 6,
    fps: 24,
    backend: Cpu,
    nodes: {
        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 24, rings: 12),
                     motion: [Breathe(amplitude: 0.15, period: 0.5)]),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 24, padding: 0.2)),
        "field": DistanceField(boundary: "vox", band: 2.5, measure: Never),
        "cloth": Cloth(colliders: ["field"], params: (
            shape: Grid(size: (0.8, 0.8), resolution: (8, 8), center: (0, 0.45, 0)),
            material: Harada(k_structural: 20.0, k_shear: 5.0),
            collision: (epsilon: 0.01, friction: 0.3),
            substeps: 16)),
        "obj": WriteMesh(mesh: "cloth"),
    },
)
"#;

/// `imprint sweep p.ron --out s` and `extra`.
fn sweep_args<'a>(extra: &[&'a str]) -> Vec<&'a str> {
    let mut args = vec!["sweep", "p.ron", "--out", "s"];
    args.extend_from_slice(extra);
    args
}

fn scene() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.ron"), PIPELINE).unwrap();
    dir
}

/// `sweep.csv` as a header and rows of cells (no quoted commas in these tests' values).
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap();
    let mut lines = text
        .lines()
        .map(|l| l.split(',').map(String::from).collect());
    let header: Vec<String> = lines.next().unwrap();
    let rows: Vec<Vec<String>> = lines.collect();
    for r in &rows {
        assert_eq!(r.len(), header.len(), "{r:?}");
    }
    (header, rows)
}

fn col(header: &[String], name: &str) -> usize {
    header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {header:?}"))
}

fn error_columns(header: &[String]) -> Vec<usize> {
    (0..header.len())
        .filter(|&i| header[i].starts_with("field_err_") || header[i].starts_with("cloth_dist_"))
        .collect()
}

fn num(s: &str) -> f64 {
    s.parse()
        .unwrap_or_else(|_| panic!("'{s}' is not a number"))
}

#[test]
fn one_row_per_combination_and_zero_error_where_the_run_is_the_reference() {
    let dir = scene();
    let out = run_ok(
        &sweep_args(&[
            "--vary",
            "cloth.params.substeps=8,16",
            "--vary",
            "vox.grid.resolution=16,24",
            "--reference",
            "cloth.params.substeps=16",
        ]),
        dir.path(),
    );
    let stdout = out;
    let s = dir.path().join("s");
    let (header, rows) = read_csv(&s.join("sweep.csv"));
    // The reference first, then the 2 × 2 combinations, the first --vary changing slowest.
    assert_eq!(rows.len(), 1 + 4, "{stdout}");
    let ids: Vec<&str> = rows.iter().map(|r| r[0].as_str()).collect();
    assert_eq!(ids, ["ref", "1", "2", "3", "4"]);
    let (sub, res) = (
        col(&header, "cloth.params.substeps"),
        col(&header, "vox.grid.resolution"),
    );
    let settings: Vec<(&str, &str)> = rows[1..]
        .iter()
        .map(|r| (r[sub].as_str(), r[res].as_str()))
        .collect();
    assert_eq!(
        settings,
        [("8", "16"), ("8", "24"), ("16", "16"), ("16", "24")]
    );
    for name in [
        "status",
        "frame_ms_mean",
        "frame_ms_p95",
        "frame_ms_max",
        "field_ms_per_frame",
        "cloth_runs",
        "field_err_rms_cells",
        "field_err_max_cells",
        "cloth_dist_rms",
        "cloth_dist_max",
        "pareto",
    ] {
        col(&header, name);
    }
    let status = col(&header, "status");
    assert!(rows.iter().all(|r| r[status] == "ok"), "{rows:?}");
    assert!(
        rows.iter()
            .all(|r| num(&r[col(&header, "frame_ms_mean")]) > 0.0)
    );
    assert_eq!(rows[1][col(&header, "cloth_runs")], "6");

    // The reference row, and setting 4 (the same pipeline), have zero error everywhere.
    let errs = error_columns(&header);
    assert_eq!(errs.len(), 6, "{header:?}");
    for row in [&rows[0], &rows[4]] {
        for &i in &errs {
            assert_eq!(num(&row[i]), 0.0, "{} of {:?}", header[i], row[0]);
        }
    }
    // A coarser grid or fewer substeps is not the reference.
    assert!(num(&rows[1][col(&header, "cloth_dist_max")]) > 0.0);
    assert!(num(&rows[1][col(&header, "field_err_rms_cells")]) > 0.0);
    assert_eq!(num(&rows[2][col(&header, "field_err_rms_cells")]), 0.0);

    // The same rows as a Markdown table, per-frame errors, the plot.
    let md = std::fs::read_to_string(s.join("sweep.md")).unwrap();
    let table_rows = md.lines().filter(|l| l.starts_with("| ")).count();
    assert_eq!(table_rows, 1 + 5, "{md}");
    assert!(md.contains("cloth 'cloth': max particle distance"), "{md}");
    let frames = std::fs::read_to_string(s.join("sweep_frames.csv")).unwrap();
    assert_eq!(frames.lines().count(), 1 + 5 * 2 * 6, "{frames}");
    let png = image::open(s.join("sweep.png")).unwrap();
    assert_eq!((png.width(), png.height()), (1200, 800));
    // Each setting's own outputs, and nothing half-written.
    assert!(s.join("runs/3/obj/cloth_0005.obj").exists());
    let leftovers: Vec<_> = std::fs::read_dir(&s)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "{leftovers:?}");
}

#[test]
fn second_sweep_reuses_the_cached_reference_and_writes_the_same_errors() {
    let dir = scene();
    let args = sweep_args(&[
        "--vary",
        "cloth.params.substeps=8,12",
        "--reference",
        "cloth.params.substeps=32",
    ]);
    let first_out = run_ok(&args, dir.path());
    assert!(!first_out.contains("reusing"), "{first_out}");
    let csv1 = std::fs::read_to_string(dir.path().join("s/sweep.csv")).unwrap();
    let second_out = run_ok(&args, dir.path());
    assert!(
        second_out.contains("reference: reusing the cached run"),
        "{second_out}"
    );
    let csv2 = std::fs::read_to_string(dir.path().join("s/sweep.csv")).unwrap();
    // Same inputs, same bytes, but for the timing columns (and the Pareto front they decide).
    assert_eq!(untimed_csv(&csv1), untimed_csv(&csv2));
    // A different reference is not taken for the cached one.
    let other = run_ok(
        &sweep_args(&[
            "--vary",
            "cloth.params.substeps=8",
            "--reference",
            "cloth.params.substeps=24",
        ]),
        dir.path(),
    );
    assert!(!other.contains("reusing"), "{other}");
}

#[test]
fn error_grows_as_the_field_is_refreshed_less_often() {
    let dir = scene();
    run_ok(
        &sweep_args(&[
            "--vary",
            "field.every=1,2,4",
            "--reference",
            "field.every=1",
            "--error",
            "field",
        ]),
        dir.path(),
    );
    let (header, rows) = read_csv(&dir.path().join("s/sweep.csv"));
    let every = col(&header, "field.every");
    let (rms, max) = (
        col(&header, "field_err_rms_cells"),
        col(&header, "field_err_max_cells"),
    );
    let runs = col(&header, "field_runs");
    let by_every: Vec<(&str, f64, f64, &str)> = rows[1..]
        .iter()
        .map(|r| {
            (
                r[every].as_str(),
                num(&r[rms]),
                num(&r[max]),
                r[runs].as_str(),
            )
        })
        .collect();
    assert_eq!(by_every.len(), 3);
    assert_eq!(by_every[0].0, "1");
    assert_eq!(by_every[0].1, 0.0, "every=1 is the reference");
    assert_eq!(
        by_every.iter().map(|b| b.3).collect::<Vec<_>>(),
        ["6", "3", "2"],
        "the field is rebuilt on every k-th frame"
    );
    assert!(
        by_every[0].1 < by_every[1].1 && by_every[1].1 < by_every[2].1,
        "rms error should grow with every: {by_every:?}"
    );
    assert!(by_every[1].2 <= by_every[2].2, "{by_every:?}");
}

#[test]
fn bad_vary_exits_2_and_says_what_is_wrong_before_anything_runs() {
    let dir = scene();
    let cases: [(&[&str], &str); 5] = [
        (&["--vary", "nosuch.band=1,2"], "no node named 'nosuch'"),
        (
            &["--vary", "field.band=2,(1"],
            "setting 2 (`field.band=(1`)",
        ),
        (&["--vary", "field.band"], "expected NODE.FIELD=VALUE"),
        (&["--vary", "field.band=1,,2"], "an empty value"),
        (
            &["--vary", "field.band=1", "--reference", "field.band=1,2"],
            "one value only",
        ),
    ];
    for (extra, want) in cases {
        let Said { code, err, .. } = imprint(&sweep_args(extra), dir.path());
        assert_eq!(code, Some(2), "{extra:?}: {err}");
        assert!(err.contains(want), "{extra:?}: expected '{want}' in: {err}");
        assert!(!dir.path().join("s").exists(), "{extra:?}: nothing may run");
    }
}

#[test]
fn a_setting_that_fails_is_a_row_saying_why_and_exit_code_1() {
    let dir = scene();
    // One substep per frame is far beyond the stiffest spring's stable step: the cloth
    // explodes, and the sweep goes on to write every file.
    let out = imprint(
        &sweep_args(&["--vary", "cloth.params.substeps=1,16"]),
        dir.path(),
    );
    let Said { code, err, .. } = out;
    assert_eq!(code, Some(1), "{err}");
    assert!(err.contains("1 of 2 settings failed (setting 1)"), "{err}");
    let text = std::fs::read_to_string(dir.path().join("s/sweep.csv")).unwrap();
    let rows: Vec<&str> = text.lines().collect();
    assert_eq!(rows.len(), 1 + 3, "{text}");
    assert!(rows[2].starts_with("1,1,\"failed: node 'cloth'"), "{text}");
    assert!(rows[3].starts_with("2,16,ok,"), "{text}");
    assert!(dir.path().join("s/sweep.png").exists());
}
