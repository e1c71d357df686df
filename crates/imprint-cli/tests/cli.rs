//! The `imprint` binary as users meet it: every bad input gets its message and exit code 2,
//! good runs write what they promise, and two runs write the same bytes.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn imprint(args: &[&str], cwd: &Path) -> Output {
    Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(args)
        .current_dir(cwd)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .expect("imprint runs")
}

/// Runs `imprint` and expects success, showing its stderr otherwise.
fn run_ok(args: &[&str], cwd: &Path) -> Output {
    let out = imprint(args, cwd);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

fn assets() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../assets/meshes"))
}

/// A pipeline around one mesh file, written into `dir`.
fn pipeline(dir: &Path, nodes: &str) -> PathBuf {
    let text = format!(
        "Pipeline(\n    frames: 2,\n    backend: Cpu,\n    nodes: {{\n{nodes}\n    }},\n)\n"
    );
    let p = dir.join("p.ron");
    std::fs::write(&p, text).unwrap();
    p
}

fn good_nodes(mesh: &str) -> String {
    format!(
        r#"        "m": Mesh(path: "{mesh}", motion: [Breathe(amplitude: 0.05, period: 1.0)]),
        "vox": Voxelize(mesh: "m", grid: Fit(resolution: 24, padding: 0.15)),
        "field": DistanceField(boundary: "vox", band: 2.5),
        "out": WriteField(field: "field", slices: [(axis: Z)]),"#
    )
}

struct Case {
    dir: tempfile::TempDir,
    file: PathBuf,
}

fn case(nodes: &str) -> Case {
    let dir = tempfile::tempdir().unwrap();
    let file = pipeline(dir.path(), nodes);
    Case { dir, file }
}

fn teapot() -> String {
    assets().join("teapot.obj").display().to_string()
}

/// Runs `imprint check` and expects exit 2 with every needle in stderr.
fn expect_invalid(nodes: &str, needles: &[&str]) {
    let c = case(nodes);
    let out = imprint(&["check", c.file.to_str().unwrap()], c.dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "stderr: {err}");
    for n in needles {
        assert!(err.contains(n), "missing {n:?} in: {err}");
    }
}

#[test]
fn ron_syntax_error_names_file_line_and_column() {
    let nodes = good_nodes(&teapot()).replace("band: 2.5)", "band: 2.5");
    // The missing ')' is noticed at the next line's start.
    expect_invalid(&nodes, &["p.ron:8:"]);
}

#[test]
fn unknown_node_kind() {
    let nodes = good_nodes(&teapot()).replace("Voxelize(", "Voxelise(");
    expect_invalid(&nodes, &["p.ron:6:", "Voxelise", "node kinds are"]);
}

#[test]
fn unknown_field() {
    let nodes = good_nodes(&teapot()).replace("band: 2.5", "bandwidth: 2.5");
    expect_invalid(&nodes, &["p.ron:7:", "bandwidth"]);
}

#[test]
fn input_that_names_no_node() {
    let nodes = good_nodes(&teapot()).replace("boundary: \"vox\"", "boundary: \"voxx\"");
    expect_invalid(
        &nodes,
        &[
            "'voxx', which is not a node",
            "did you mean 'vox'",
            "p.ron:7:",
        ],
    );
}

#[test]
fn type_mismatch_names_the_port_and_types() {
    let nodes = good_nodes(&teapot()).replace("boundary: \"vox\"", "boundary: \"m\"");
    expect_invalid(
        &nodes,
        &[
            "input 'boundary' expects a Boundary",
            "'m' (Mesh) produces a Mesh",
        ],
    );
}

#[test]
fn cycle_names_its_nodes() {
    // Cycles are found before types are compared, so this reports the cycle itself.
    let nodes = r#"        "f": DistanceField(boundary: "v"),
        "v": Voxelize(mesh: "f", grid: Fit(resolution: 8)),
        "w": WriteField(field: "f"),"#;
    expect_invalid(nodes, &["cycle through nodes: f -> v"]);
}

#[test]
fn missing_asset_file() {
    let nodes = good_nodes("no/such/bunny.obj");
    expect_invalid(
        &nodes,
        &["mesh file not found", "no/such/bunny.obj", "p.ron:5:"],
    );
}

#[test]
fn values_out_of_range() {
    let t = teapot();
    expect_invalid(
        &good_nodes(&t).replace("resolution: 24", "resolution: 0"),
        &["resolution must be at least 1"],
    );
    expect_invalid(
        &good_nodes(&t).replace("band: 2.5", "band: -1"),
        &["band must be a finite number of cells > 0"],
    );
    expect_invalid(
        &good_nodes(&t).replace("band: 2.5", "band: NaN"),
        &["band must be a finite number"],
    );
    expect_invalid(
        &good_nodes(&t).replace("period: 1.0", "period: -2.0"),
        &["period"],
    );
}

#[test]
fn a_huge_grid_is_refused_before_allocating() {
    let c = case(&good_nodes(&teapot()).replace("resolution: 24", "resolution: 100000"));
    let out = imprint(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("would need") && err.contains("PiB"), "{err}");
    assert!(!c.dir.path().join("o").exists(), "nothing written");
}

fn run_with_mesh_text(obj: &str) -> (Option<i32>, String) {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("bad.obj"), obj).unwrap();
    let file = pipeline(dir.path(), &good_nodes("bad.obj"));
    let out = imprint(&["run", file.to_str().unwrap(), "--out", "o"], dir.path());
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_meshes_name_the_file_and_the_problem() {
    let (code, err) = run_with_mesh_text("# nothing here\nv 0 0 0\n");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("bad.obj") && err.contains("no triangles"),
        "{err}"
    );

    let (code, err) = run_with_mesh_text("v 0 0 0\nv 1 0 0\nv 0 nan 0\nf 1 2 3\n");
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("bad.obj") && err.contains("vertex 3") && err.contains("non-finite"),
        "{err}"
    );

    let (code, err) = run_with_mesh_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 9\n");
    assert_eq!(code, Some(2), "{err}");
    assert!(err.contains("bad.obj"), "{err}");
}

#[test]
fn bad_override_and_bad_frames_are_invalid_input() {
    let c = case(&good_nodes(&teapot()));
    let f = c.file.to_str().unwrap();
    let out = imprint(&["run", f, "--set", "field.band=-3"], c.dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("band must be"));
    let out = imprint(&["run", f, "--frames", "5..9"], c.dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("outside the pipeline's 0..2"));
    let out = imprint(&["run", f, "--frames", "x"], c.dir.path());
    assert_eq!(out.status.code(), Some(2));
}

#[test]
fn check_lists_what_runs_and_what_is_pruned() {
    let nodes = format!(
        "{}\n        \"unused\": Voxelize(mesh: \"m\", grid: Fit(resolution: 8)),",
        good_nodes(&teapot())
    );
    let c = case(&nodes);
    let out = imprint(&["check", c.file.to_str().unwrap()], c.dir.path());
    assert_eq!(out.status.code(), Some(0));
    let s = String::from_utf8_lossy(&out.stdout);
    assert!(
        s.contains("unused") && s.contains("its output reaches no writer"),
        "{s}"
    );
    let order: Vec<usize> = ["  m ", "  vox ", "  field ", "  out "]
        .iter()
        .map(|n| s.find(n).unwrap())
        .collect();
    assert!(
        order.windows(2).all(|w| w[0] < w[1]),
        "dependency order: {s}"
    );

    let out = imprint(&["graph", c.file.to_str().unwrap(), "--dot"], c.dir.path());
    let dot = String::from_utf8_lossy(&out.stdout);
    assert!(
        dot.starts_with("digraph")
            && dot.contains("\"vox\" -> \"field\" [label=\"boundary: Boundary\"]"),
        "{dot}"
    );
    assert!(
        dot.contains("\"unused\"") && dot.contains("dashed"),
        "{dot}"
    );
}

#[test]
fn run_writes_frames_and_a_report_and_is_deterministic() {
    let c = case(&good_nodes(&teapot()));
    let f = c.file.to_str().unwrap();
    for out_dir in ["o1", "o2"] {
        run_ok(
            &[
                "run",
                f,
                "--out",
                out_dir,
                "--set",
                "vox.grid.resolution=20",
            ],
            c.dir.path(),
        );
    }
    let d = c.dir.path();
    for frame in ["0000", "0001"] {
        for suffix in ["_dist.npy", "_vec.npy", "_field.json"] {
            let name = format!("out/field_{frame}{suffix}");
            let a = std::fs::read(d.join("o1").join(&name)).unwrap();
            let b = std::fs::read(d.join("o2").join(&name)).unwrap();
            assert!(a == b, "{name} differs between runs");
        }
    }
    let json: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("o1/report.json")).unwrap()).unwrap();
    assert_eq!(json["frames"], serde_json::json!([0, 1]));
    let field = &json["nodes"]["field"];
    assert_eq!(field["runs"], 2);
    assert_eq!(field["backend"], "cpu");
    let err = &field["metrics"]["error_cells"];
    // A 20-cell grid is coarse; the accuracy goal itself is tested in tests/field_cpu.rs.
    assert!(
        err["p99"].as_f64().unwrap() < 0.35 && err["max"].as_f64().unwrap() < 1.0,
        "{err}"
    );
    assert!(err["far_fraction"].as_f64().unwrap() < 0.05, "{err}");
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("o1/out/field_0000_field.json")).unwrap())
            .unwrap();
    assert_eq!(meta["dims"][0], 20);
}

#[test]
fn field_command_computes_one_mesh() {
    let dir = tempfile::tempdir().unwrap();
    let mesh = assets().join("suzanne.obj");
    run_ok(
        &[
            "field",
            mesh.to_str().unwrap(),
            "--resolution",
            "24",
            "--band",
            "2",
            "--backend",
            "cpu",
            "--out",
            "f",
        ],
        dir.path(),
    );
    let meta: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("f/field_0000_field.json")).unwrap())
            .unwrap();
    assert_eq!(
        meta["dims"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_u64().unwrap())
            .max(),
        Some(24)
    );
    assert_eq!(meta["band"], 2.0);
    assert!(dir.path().join("f/report.json").is_file());
    let out = imprint(&["field", "nope.obj"], dir.path());
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("nope.obj"));
}

#[test]
fn gpu_backend_agrees_with_cpu_through_the_whole_pipeline() {
    let c = case(&good_nodes(&teapot()));
    let f = c.file.to_str().unwrap();
    run_ok(
        &["run", f, "--out", "cpu", "--backend", "cpu"],
        c.dir.path(),
    );
    let gpu = imprint(
        &["run", f, "--out", "gpu", "--backend", "gpu"],
        c.dir.path(),
    );
    let err = String::from_utf8_lossy(&gpu.stderr);
    if gpu.status.code() == Some(1) && err.contains("no GPU adapter") {
        assert!(
            std::env::var("IMPRINT_REQUIRE_GPU").as_deref() != Ok("1"),
            "IMPRINT_REQUIRE_GPU=1 but: {err}"
        );
        eprintln!("skipped: no GPU adapter (set IMPRINT_REQUIRE_GPU=1 to fail instead)");
        return;
    }
    assert_eq!(gpu.status.code(), Some(0), "{err}");
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(c.dir.path().join("gpu/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["nodes"]["field"]["backend"], "gpu");
    assert_eq!(report["nodes"]["vox"]["backend"], "gpu");
    for frame in ["0000", "0001"] {
        let name = format!("out/field_{frame}_dist.npy");
        let (sa, a) = imprint_render::read_npy_f32(&c.dir.path().join("cpu").join(&name)).unwrap();
        let (sb, b) = imprint_render::read_npy_f32(&c.dir.path().join("gpu").join(&name)).unwrap();
        assert_eq!(sa, sb);
        let meta: serde_json::Value = serde_json::from_slice(
            &std::fs::read(
                c.dir
                    .path()
                    .join("cpu/out")
                    .join(format!("field_{frame}_field.json")),
            )
            .unwrap(),
        )
        .unwrap();
        let cell = meta["cell_size"].as_f64().unwrap() as f32;
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs() / cell)
            .fold(0.0, f32::max);
        assert!(
            worst < 1e-3,
            "frame {frame}: CPU and GPU differ by {worst} cells"
        );
    }
}

#[test]
fn write_mesh_writes_frames_other_tools_can_read() {
    let nodes = format!(
        "{}\n        \"objs\": WriteMesh(mesh: \"m\"),\n        \"plys\": WriteMesh(mesh: \"m\", format: Ply, every: 2),",
        good_nodes(&teapot())
    );
    let c = case(&nodes);
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let d = c.dir.path().join("o");
    let teapot = imprint_core::Mesh::load_obj(&assets().join("teapot.obj")).unwrap();
    for frame in ["0000", "0001"] {
        let m = imprint_core::Mesh::load_obj(&d.join(format!("objs/m_{frame}.obj"))).unwrap();
        assert_eq!(m.triangles.len(), teapot.triangles.len());
    }
    assert!(d.join("plys/m_0000.ply").is_file());
    assert!(
        !d.join("plys/m_0001.ply").exists(),
        "every: 2 skips frame 1"
    );
    // Frame 0 is the rest mesh breathing at sin(0) = 0: positions equal the file's.
    let m0 = imprint_core::Mesh::load_obj(&d.join("objs/m_0000.obj")).unwrap();
    let (a, b) = (m0.bounds(), teapot.bounds());
    assert!((a.min - b.min).length() < 1e-5 && (a.max - b.max).length() < 1e-5);
}

#[test]
fn render_writes_frames_that_show_the_scene() {
    let nodes = format!(
        "{}\n        \"pics\": Render(objects: [Mesh(mesh: \"m\"), FieldSlice(field: \"field\")], camera: Orbit(distance: 12, elevation: 30), width: 64, height: 48, samples: 1, out: \"pics/f{{frame:04}}.png\"),",
        good_nodes(&teapot())
    );
    let c = case(&nodes);
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    for frame in ["0000", "0001"] {
        let img = image::open(c.dir.path().join(format!("o/pics/f{frame}.png")))
            .unwrap()
            .to_rgb8();
        assert_eq!(img.dimensions(), (64, 48));
        // The background is one flat colour; the teapot and its slice cover part of the view.
        let bg = *img.get_pixel(0, 0);
        let covered = img.pixels().filter(|p| **p != bg).count();
        assert!(
            covered > 64 * 48 / 20 && covered < 64 * 48,
            "{covered} pixels differ from the background"
        );
    }
    // A pattern without {frame} would overwrite itself: refused before running.
    let bad = nodes.replace("pics/f{frame:04}.png", "pics/f.png");
    expect_invalid(&bad, &["has no {frame}"]);
}
