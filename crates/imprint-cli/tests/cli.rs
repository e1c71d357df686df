//! The `imprint` binary as users meet it: every bad input gets its message and exit code 2,
//! good runs write what they promise, and two runs write the same bytes.

use std::path::{Path, PathBuf};

mod common;
use common::{imprint, run_ok};

/// `imprint run FILE --out OUT --backend gpu`, expecting success; false (the test skips)
/// when there is no adapter, unless `IMPRINT_REQUIRE_GPU=1`, which makes that a failure.
fn run_gpu_or_skip(file: &str, out: &str, cwd: &Path) -> bool {
    let gpu = imprint(&["run", file, "--out", out, "--backend", "gpu"], cwd);
    let err = String::from_utf8_lossy(&gpu.stderr);
    if gpu.status.code() == Some(1) && err.contains("no GPU adapter") {
        assert!(
            std::env::var("IMPRINT_REQUIRE_GPU").as_deref() != Ok("1"),
            "IMPRINT_REQUIRE_GPU=1 but: {err}"
        );
        eprintln!("skipped: no GPU adapter (set IMPRINT_REQUIRE_GPU=1 to fail instead)");
        return false;
    }
    assert_eq!(gpu.status.code(), Some(0), "{err}");
    true
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

/// Runs the case into `cpu/` on the CPU and into `gpu/` on the GPU; false (skip) without an
/// adapter, as [`run_gpu_or_skip`].
fn run_cpu_and_gpu(c: &Case) -> bool {
    let f = c.file.to_str().unwrap();
    run_ok(
        &["run", f, "--out", "cpu", "--backend", "cpu"],
        c.dir.path(),
    );
    run_gpu_or_skip(f, "gpu", c.dir.path())
}

/// A JSON file the run wrote (`report.json`, a field's sidecar).
fn read_json(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// [`case`] with `timing` (e.g. `frames: 12, fps: 24`) instead of the default 2 frames.
fn case_timed(nodes: &str, timing: &str) -> Case {
    let c = case(nodes);
    let text = std::fs::read_to_string(&c.file)
        .unwrap()
        .replace("frames: 2", timing);
    std::fs::write(&c.file, text).unwrap();
    c
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
    let json: serde_json::Value = read_json(&d.join("o1/report.json"));
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
    let meta: serde_json::Value = read_json(&d.join("o1/out/field_0000_field.json"));
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
    let meta: serde_json::Value = read_json(&dir.path().join("f/field_0000_field.json"));
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
    let nodes = format!(
        "{}\n        \"top\": Heightmap(mesh: \"m\", view: Below, grid: Fit(resolution: 48)),\n        \"hm\": WriteHeightmap(heights: \"top\", formats: [Exr]),\n        \"pics\": Render(objects: [Mesh(mesh: \"m\")], camera: Orbit(distance: 12, elevation: 30), width: 96, height: 64, samples: 1, ground_grid: false),",
        good_nodes(&teapot())
    );
    let c = case(&nodes);
    if !run_cpu_and_gpu(&c) {
        return;
    }
    let report: serde_json::Value = read_json(&c.dir.path().join("gpu/report.json"));
    assert_eq!(report["nodes"]["field"]["backend"], "gpu");
    assert_eq!(report["nodes"]["vox"]["backend"], "gpu");
    assert_eq!(report["nodes"]["top"]["backend"], "gpu");
    assert_eq!(report["nodes"]["pics"]["backend"], "gpu");
    for frame in ["0000", "0001"] {
        // Heights from the GPU depth buffer: same coverage, same heights to 1e-4.
        let name = format!("hm/top_{frame}.exr");
        let a =
            imprint_render::heightmap::read_heightmap_exr(&c.dir.path().join("cpu").join(&name))
                .unwrap();
        let b =
            imprint_render::heightmap::read_heightmap_exr(&c.dir.path().join("gpu").join(&name))
                .unwrap();
        assert_eq!(a.dims, b.dims);
        let worst = a
            .heights
            .iter()
            .zip(&b.heights)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max);
        assert!(worst < 1e-4, "frame {frame}: heights differ by {worst}");
        // Frames: lit surfaces without lines or anti-aliasing agree to a level or two.
        let name = format!("frames/{frame}.png");
        let a = image::open(c.dir.path().join("cpu").join(&name))
            .unwrap()
            .to_rgb8();
        let b = image::open(c.dir.path().join("gpu").join(&name))
            .unwrap()
            .to_rgb8();
        let near = a
            .pixels()
            .zip(b.pixels())
            .filter(|(p, q)| (0..3).all(|k| p.0[k].abs_diff(q.0[k]) <= 2))
            .count();
        assert!(
            near as f64 >= 0.995 * (96 * 64) as f64,
            "frame {frame}: only {near} of {} pixels agree",
            96 * 64
        );
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

/// Heightmap → WriteHeightmap in every format, a rendered height field, and the run's
/// contact sheet and GIF: the box's top face reads back as its height, the EXR and .npy
/// exactly, the 16-bit PNG within one quantisation step.
#[test]
fn heightmaps_contact_sheet_and_gif() {
    let nodes = r#"        "box": Mesh(primitive: Box(size: (1.0, 0.5, 1.0), subdivisions: 2), fit: (size: 1.0, center: (0, 0.25, 0))),
        "top": Heightmap(mesh: "box", view: Above, grid: Explicit(origin: (-0.95, -0.95), cell: 0.1, dims: (20, 20)), empty: -1.0),
        "hm": WriteHeightmap(heights: "top", formats: [Png16, Exr, Npy, Preview]),
        "pics": Render(objects: [HeightField(heights: "top"), Mesh(mesh: "box")], camera: Orbit(distance: 4), width: 64, height: 48, samples: 1,
            contact_sheet: (every: 1, columns: 2, width: 32), gif: (width: 32)),"#;
    let c = case(nodes);
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let d = c.dir.path().join("o");
    // Box fitted to size 1 (longest side): top face at y = 0.5 over |x|, |z| < 0.5.
    let want = |i: u32, k: u32| {
        let (x, z) = (-0.95 + 0.1 * i as f32, -0.95 + 0.1 * k as f32);
        if x.abs() < 0.5 && z.abs() < 0.5 {
            0.5
        } else {
            -1.0
        }
    };
    for frame in ["0000", "0001"] {
        let exr =
            imprint_render::heightmap::read_heightmap_exr(&d.join(format!("hm/top_{frame}.exr")))
                .unwrap();
        let png =
            imprint_render::heightmap::read_heightmap_png16(&d.join(format!("hm/top_{frame}.png")))
                .unwrap();
        let npy = imprint_render::read_npy_f32(&d.join(format!("hm/top_{frame}.npy"))).unwrap();
        assert_eq!(exr.dims, glam::UVec2::new(20, 20));
        let step = 1.5 / 65535.0;
        for k in 0..20 {
            for i in 0..20 {
                let w = want(i, k);
                assert!(
                    (exr.get(i, k) - w).abs() < 1e-5,
                    "exr ({i},{k}) {} vs {w}",
                    exr.get(i, k)
                );
                assert!((png.get(i, k) - w).abs() <= step, "png ({i},{k})");
                // North up, as the pictures: row r holds k = nz - 1 - r.
                let north_up = ((19 - k) * 20 + i) as usize;
                assert_eq!(npy.1[north_up], exr.get(i, k), "npy ({i},{k})");
            }
        }
        assert!(d.join(format!("hm/top_{frame}_preview.png")).is_file());
    }
    // Contact sheet: two 32x24 tiles side by side with 4-pixel gaps.
    let sheet = image::open(d.join("contact_sheet.png")).unwrap().to_rgb8();
    assert_eq!(sheet.dimensions(), (4 + 2 * 36, 4 + 28));
    // GIF: two frames, 32 pixels wide, at the run's 30 fps (3 cs, GIF's whole hundredths).
    let mut opts = gif::DecodeOptions::new();
    opts.set_color_output(gif::ColorOutput::RGBA);
    let mut dec = opts
        .read_info(std::fs::File::open(d.join("preview.gif")).unwrap())
        .unwrap();
    assert_eq!((dec.width(), dec.height()), (32, 24));
    let mut n = 0;
    while let Some(f) = dec.read_next_frame().unwrap() {
        assert_eq!(f.delay, 3);
        n += 1;
    }
    assert_eq!(n, 2);
}

/// A cloth dropped on a static sphere's field: frames and OBJs come out, the report carries
/// per-frame contact metrics, and no particle ends inside the body.
#[test]
fn cloth_node_runs_and_reports_per_frame_metrics() {
    let nodes = r#"        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 48, rings: 24)),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 48)),
        "field": DistanceField(boundary: "vox", band: 3, measure: Never),
        "cloth": Cloth(colliders: ["field"], params: (
            shape: Grid(size: (0.8, 0.8), resolution: (12, 12), center: (0, 0.4, 0)),
            material: Harada(k_structural: 20.0, k_shear: 5.0),
            collision: (epsilon: 0.01, friction: 0.3, ground: -0.5),
            substeps: 16)),
        "obj": WriteMesh(mesh: "cloth"),"#;
    let c = case(nodes);
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let d = c.dir.path().join("o");
    let m = imprint_core::Mesh::load_obj(&d.join("obj/cloth_0001.obj")).unwrap();
    assert_eq!(m.positions.len(), 144);
    let report: serde_json::Value = read_json(&d.join("report.json"));
    let frames = report["nodes"]["cloth"]["metrics"]["per_frame"]
        .as_array()
        .unwrap();
    assert_eq!(frames.len(), 2);
    for f in frames {
        assert_eq!(f["inside"], 0);
        assert!(f["max_strain"].as_f64().unwrap().is_finite());
    }
    // Frame 0 starts at rest and falls: kinetic energy grows.
    assert!(frames[1]["kinetic"].as_f64() > frames[0]["kinetic"].as_f64());
}

/// An unstable cloth is warned about before running and stopped with exit code 1 and a
/// message naming node, frame, substep and the substeps that would fix it; `stress cloth`
/// prints the map with the estimate's predictions.
#[test]
fn unstable_cloth_is_warned_stopped_and_mapped() {
    let nodes = r#"        "cloth": Cloth(params: (
            shape: Grid(size: (0.5, 0.5), resolution: (8, 8), center: (0, 1, 0), normal: (0, 0, 1)),
            material: Harada(k_structural: 10000000.0, k_shear: 10000000.0),
            pins: [TopEdge], substeps: 1)),
        "obj": WriteMesh(mesh: "cloth"),"#;
    let c = case(nodes);
    let out = imprint(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("warning: node 'cloth'"), "{err}");
    assert!(
        err.contains("node 'cloth', frame 1") && err.contains("substep 1 of 1"),
        "{err}"
    );
    assert!(err.contains("substeps:"), "{err}");
    // Frame 0 (at rest) was written; nothing for the frame that failed.
    assert!(c.dir.path().join("o/obj/cloth_0000.obj").exists());
    assert!(!c.dir.path().join("o/obj/cloth_0001.obj").exists());

    let stable = nodes
        .replace("10000000.0", "50.0")
        .replace("substeps: 1", "substeps: 16");
    let c = case(&stable);
    let out = run_ok(
        &[
            "stress",
            "cloth",
            c.file.to_str().unwrap(),
            "--scales",
            "1,100",
            "--ratios",
            "0.5,2",
            "--frames",
            "4",
        ],
        c.dir.path(),
    );
    let text = String::from_utf8_lossy(&out.stdout);
    let rows: Vec<&str> = text.lines().filter(|l| l.contains("x |")).collect();
    assert_eq!(rows.len(), 2, "{text}");
    for r in rows {
        assert!(r.contains("ok ") && r.contains("BOOM@"), "{r}");
    }
    assert!(text.contains("predicted"), "{text}");
}

/// The Cloth node on the GPU (lavapipe in CI) lands where the CPU cloth does.
#[test]
fn gpu_cloth_agrees_with_cpu_through_the_pipeline() {
    let nodes = r#"        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 48, rings: 24)),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 48)),
        "field": DistanceField(boundary: "vox", band: 3, measure: Never),
        "cloth": Cloth(colliders: ["field"], params: (
            shape: Grid(size: (0.8, 0.8), resolution: (12, 12), center: (0, 0.33, 0)),
            material: Harada(k_structural: 20.0, k_shear: 5.0),
            collision: (epsilon: 0.01, friction: 0.3),
            substeps: 16)),
        "obj": WriteMesh(mesh: "cloth"),"#;
    let c = case(nodes);
    if !run_cpu_and_gpu(&c) {
        return;
    }
    let report: serde_json::Value = read_json(&c.dir.path().join("gpu/report.json"));
    assert_eq!(report["nodes"]["cloth"]["backend"], "gpu");
    // The GPU path reports the CPU's per-frame metrics, with the same keys and close values.
    let cpu_report: serde_json::Value = read_json(&c.dir.path().join("cpu/report.json"));
    let per_frame = |r: &serde_json::Value| r["nodes"]["cloth"]["metrics"]["per_frame"].clone();
    let (g, cpu) = (per_frame(&report), per_frame(&cpu_report));
    for (g, cpu) in g.as_array().unwrap().iter().zip(cpu.as_array().unwrap()) {
        let keys =
            |v: &serde_json::Value| v.as_object().unwrap().keys().cloned().collect::<Vec<_>>();
        assert_eq!(keys(g), keys(cpu));
        for k in ["max_strain", "kinetic", "energy_drift"] {
            let (a, b) = (g[k].as_f64().unwrap(), cpu[k].as_f64().unwrap());
            assert!(
                (a - b).abs() <= 1e-3 * a.abs().max(b.abs()) + 1e-9,
                "{k}: {a} vs {b}"
            );
        }
    }
    // Frame 1: the cloth (3 cm above the ball's top) has reached it; both paths agree.
    let a = imprint_core::Mesh::load_obj(&c.dir.path().join("cpu/obj/cloth_0001.obj")).unwrap();
    let b = imprint_core::Mesh::load_obj(&c.dir.path().join("gpu/obj/cloth_0001.obj")).unwrap();
    let worst = a
        .positions
        .iter()
        .zip(&b.positions)
        .map(|(p, q)| (*p - *q).length())
        .fold(0.0, f32::max);
    assert!(worst < 1e-4, "CPU and GPU cloth differ by {worst} m");
}

/// `imprint check` prints the schedule (what each node does on the first frames) and warns
/// about a writer that a switched-off node leaves without input; bad schedules are refused
/// with the field named.
#[test]
fn check_prints_the_schedule_and_refuses_bad_ones() {
    let nodes = r#"        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8),
                     motion: [Breathe(amplitude: 0.1, period: 1.0)]),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 16)),
        "field": DistanceField(boundary: "vox", measure: Never, every: 4, split: 2),
        "off": DistanceField(boundary: "vox", measure: Never, enabled: false),
        "w": WriteField(field: "field", npy: false, every: 2, offset: 1),
        "w_off": WriteField(field: "off", npy: false),"#;
    let c = case_timed(nodes, "frames: 12");
    let out = run_ok(&["check", c.file.to_str().unwrap()], c.dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    let row = |n: &str| {
        text.lines()
            .find(|l| l.starts_with(&format!("{n} ")))
            .unwrap_or_else(|| panic!("no row {n} in {text}"))
            .to_string()
    };
    assert!(row("field").contains(" #...12..12.. "), "{text}");
    assert!(row("w").contains(" .w.w.w.w.w.w "), "{text}");
    assert!(
        text.contains("warning: writer 'w_off' loses its input 'off'"),
        "{text}"
    );
    assert!(text.contains("disabled (enabled: false)"), "{text}");
    expect_invalid(
        &nodes.replace("every: 4, split: 2", "every: 2, split: 3"),
        &[
            "node 'field'",
            "split must be between 1 and every (2), got 3",
        ],
    );
    expect_invalid(
        &nodes.replace("every: 2, offset: 1", "every: 2, offset: 2"),
        &["node 'w'", "offset must be less than every (2), got 2"],
    );
}

/// A ball rolled over sand: the Ground node's height map comes out in every format, the
/// print is as deep as the ball was pressed, and the sand's mass (α = 1) never changes.
#[test]
fn ground_node_keeps_its_prints_and_its_mass() {
    let nodes = r#"        "ball": Mesh(primitive: Sphere(radius: 0.1, segments: 32, rings: 16),
                     fit: (size: 0.2, center: (-0.2, 0.17, 0)),
                     motion: [Rigid(keys: [(time: 0), (time: 1, translate: (0.4, 0, 0))])]),
        "sand": Ground(objects: ["ball"],
                       params: (size: (0.64, 0.32), resolution: (64, 32), initial: Flat(0.1))),
        "h": WriteHeightmap(heights: "sand", formats: [Png16, Exr, Npy], every: 100),"#;
    let c = case_timed(nodes, "frames: 24, fps: 24");
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let d = c.dir.path().join("o");
    assert!(d.join("h/sand_0000.exr").is_file() && d.join("h/sand_0000.npy").is_file());
    let report: serde_json::Value = read_json(&d.join("report.json"));
    let frames = report["nodes"]["sand"]["metrics"]["per_frame"]
        .as_array()
        .unwrap();
    assert_eq!(frames.len(), 24);
    let mass0 = frames[0]["mass_units"].as_i64().unwrap();
    assert_eq!(mass0, 64 * 32 * 10_000, "0.1 m in 10 µm units per cell");
    for f in frames {
        assert_eq!(f["mass_units"].as_i64().unwrap(), mass0, "{f}");
        assert!(f["contact_cells"].as_u64().unwrap() > 0, "{f}");
        assert_eq!(f["removed_units"], f["displaced_units"], "{f}");
    }
}

/// Snow falls on a box and a flat ground; a Ground node takes the ground's snow in
/// (`accumulate`): its mass grows frame after frame with no object pressing, and a Snow node
/// without a ground outputs the box with snow on its top.
#[test]
fn snow_piles_up_on_meshes_and_on_a_ground_that_takes_it_in() {
    let nodes = r#"        "box": Mesh(primitive: Box(size: (0.2, 0.2, 0.2)), fit: (size: 0.2, center: (0, 0.2, 0))),
        "snowy_box": Snow(meshes: ["box"], params: (directions: 4, resolution: 64, rate: 0.1)),
        "fall": Snow(meshes: ["box"], ground: (size: (0.64, 0.64), resolution: (32, 32), height: 0.05),
                     params: (directions: 4, resolution: 64, rate: 0.1)),
        "ground": Ground(accumulate: "fall",
                         params: (size: (0.64, 0.64), resolution: (32, 32), initial: Flat(0.05),
                                  material: Preset(Snow))),
        "m": WriteMesh(mesh: "snowy_box", every: 100),
        "h": WriteHeightmap(heights: "ground", formats: [Npy], every: 100),"#;
    let c = case_timed(nodes, "frames: 6, fps: 10");
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let d = c.dir.path().join("o");
    let report: serde_json::Value = read_json(&d.join("report.json"));
    let mass: Vec<i64> = report["nodes"]["ground"]["metrics"]["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["mass_units"].as_i64().unwrap())
        .collect();
    // 0.1 m/s at 10 fps: 1 cm per frame on open ground, taken in from the second frame on.
    assert_eq!(mass[0], 32 * 32 * 5_000, "frame 0 takes nothing in");
    for w in mass.windows(2) {
        assert!(w[1] > w[0], "{mass:?}");
    }
    let open_cells = 32 * 32;
    let per_frame = (mass[5] - mass[4]) as f64 / open_cells as f64 * 1e-5;
    assert!(
        per_frame > 0.005 && per_frame < 0.0105,
        "{per_frame} m per frame"
    );
    let depth = report["nodes"]["snowy_box"]["metrics"]["per_frame"][5]["mesh_max_depth"]
        .as_f64()
        .unwrap();
    assert!(
        (depth - 0.06).abs() < 0.002,
        "6 frames of 1 cm on the top: {depth}"
    );
}

/// Ground and Snow parameters are checked before anything runs, errors naming the node.
#[test]
fn ground_and_snow_bad_parameters_are_named() {
    expect_invalid(
        r#"        "g": Ground(params: (size: (1.0, 1.0), resolution: (10, 20))),
        "h": WriteHeightmap(heights: "g"),"#,
        &["node 'g'"],
    );
    expect_invalid(
        r#"        "box": Mesh(primitive: Box(size: (0.2, 0.2, 0.2))),
        "s": Snow(meshes: ["box"], params: (directions: 0)),
        "m": WriteMesh(mesh: "s"),"#,
        &["node 's'", "directions"],
    );
    expect_invalid(
        r#"        "box": Mesh(primitive: Box(size: (0.2, 0.2, 0.2))),
        "s": Snow(meshes: ["box"], ground: (size: (1.0, 2.0), resolution: (10, 10))),
        "h": WriteHeightmap(heights: "s"),"#,
        &["node 's'", "square"],
    );
}

/// Ground and Snow with their depth maps on the GPU (lavapipe in CI) give the CPU's heights:
/// the rasterisers agree on coverage and to ~1e-6 relative in depth, so the ground's integer
/// heights (10 µm units) and the snow surface may differ by a unit or two where a depth rounds
/// the other way, and no more. Measured on lavapipe: identical after 12 frames.
#[test]
fn gpu_ground_and_snow_agree_with_the_cpu() {
    let nodes = r#"        "ball": Mesh(primitive: Sphere(radius: 0.1, segments: 32, rings: 16),
                     fit: (size: 0.2, center: (-0.2, 0.17, 0)),
                     motion: [Rigid(keys: [(time: 0), (time: 1, translate: (0.4, 0, 0))])]),
        "fall": Snow(meshes: ["ball"], ground: (size: (0.64, 0.32), resolution: (64, 32), height: 0.1),
                     params: (directions: 4, resolution: 64, rate: 0.1)),
        "sand": Ground(objects: ["ball"], accumulate: "fall",
                       params: (size: (0.64, 0.32), resolution: (64, 32), initial: Flat(0.1))),
        "bare": Ground(objects: ["ball"],
                       params: (size: (0.64, 0.32), resolution: (64, 32), initial: Flat(0.1))),
        "h": WriteHeightmap(heights: "sand", formats: [Npy], every: 11),
        "s": WriteHeightmap(heights: "fall", formats: [Npy], every: 11),
        "b": WriteHeightmap(heights: "bare", formats: [Npy], every: 11),"#;
    let c = case_timed(nodes, "frames: 12, fps: 24");
    if !run_cpu_and_gpu(&c) {
        return;
    }
    // `bare` runs its passes on the GPU too (`GpuGround`); `sand` takes snow in, which has
    // no GPU port, so only its contact view is on the GPU.
    for (dir, stem, tol) in [
        ("h", "sand", 2e-5f32),
        ("s", "fall", 2e-5),
        ("b", "bare", 2e-5),
    ] {
        let read = |run: &str| {
            imprint_render::npy::read_npy_f32(
                &c.dir.path().join(format!("{run}/{dir}/{stem}_0011.npy")),
            )
            .unwrap()
            .1
        };
        let (a, b) = (read("cpu"), read("gpu"));
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        eprintln!("{stem}: CPU vs GPU worst {worst:.2e} m");
        assert!(worst <= tol, "{stem}: CPU and GPU differ by {worst} m");
    }
    let report: serde_json::Value = read_json(&c.dir.path().join("gpu/report.json"));
    assert_eq!(report["nodes"]["sand"]["backend"], "gpu");
    assert_eq!(report["nodes"]["fall"]["backend"], "gpu");
    assert_eq!(report["nodes"]["bare"]["backend"], "gpu");
}

/// The Drape node fits a sphere of radius 0.27 out of a sphere of radius 0.3: every vertex
/// ends at the surface or beyond (within a texel), and the report counts them.
#[test]
fn drape_node_pushes_a_garment_out_of_the_body() {
    let nodes = r#"        "body": Mesh(primitive: Sphere(radius: 0.3, segments: 64, rings: 32)),
        "shell": Mesh(primitive: Sphere(radius: 0.27, segments: 24, rings: 12)),
        "fit": Drape(body: "body", garment: "shell", params: (resolution: 128, offset: 0.0)),
        "obj": WriteMesh(mesh: "fit"),"#;
    let c = case(nodes);
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let d = c.dir.path().join("o");
    let m = imprint_core::Mesh::load_obj(&d.join("obj/fit_0000.obj")).unwrap();
    let report: serde_json::Value = read_json(&d.join("report.json"));
    let f = &report["nodes"]["fit"]["metrics"]["per_frame"][0];
    let texel = f["texel"].as_f64().unwrap() as f32;
    assert_eq!(f["inside"], f["vertices"], "{f}");
    assert_eq!(f["unresolved"], 0, "{f}");
    // The body is a polygon sphere: its faces lie up to r(1 - cos(π/64)) inside r.
    let flat = 0.3 * (1.0 - (std::f32::consts::PI / 64.0).cos());
    for p in &m.positions {
        assert!(
            p.length() >= 0.3 - flat - texel,
            "{} from the centre",
            p.length()
        );
    }
    // Only frame 0 computes: both meshes are static.
    assert_eq!(report["nodes"]["fit"]["runs"], 1);
    // The views rendered on the GPU (lavapipe in CI) fit the garment as well. The maps agree
    // on coverage and to ~1e-6 relative in depth, so pushes agree, except where a vertex lies
    // on the sphere's plane of symmetry: its front and back pushes tie and the last bit of
    // depth picks a side (measured: 1 of 266 vertices).
    if !run_gpu_or_skip(c.file.to_str().unwrap(), "gpu", c.dir.path()) {
        return;
    }
    let g = imprint_core::Mesh::load_obj(&c.dir.path().join("gpu/obj/fit_0000.obj")).unwrap();
    let differ = m
        .positions
        .iter()
        .zip(&g.positions)
        .filter(|(a, b)| (**a - **b).length() > 1e-5)
        .count();
    eprintln!(
        "drape: {differ} of {} vertices differ CPU vs GPU",
        m.positions.len()
    );
    assert!(differ * 20 <= m.positions.len(), "{differ} vertices differ");
    for p in &g.positions {
        assert!(
            p.length() >= 0.3 - flat - texel,
            "GPU: {} from the centre",
            p.length()
        );
    }
}

/// A stage that fails while running (snow piling past what a ground cell holds) stops the run
/// with exit code 1, naming the node and frame and what to change; no frame is written, and
/// report.json says which frames were done (none) and why the run stopped.
#[test]
fn a_failing_stage_names_node_and_frame_and_exits_1() {
    let nodes = r#"        "box": Mesh(primitive: Box(size: (0.2, 0.2, 0.2))),
        "s": Snow(meshes: ["box"], ground: (size: (0.64, 0.64), resolution: (16, 16)),
                  params: (directions: 1, resolution: 32, rate: 100000.0)),
        "h": WriteHeightmap(heights: "s", formats: [Npy]),"#;
    let c = case(nodes);
    let out = imprint(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("node 's', frame 0") && err.contains("lower rate"),
        "{err}"
    );
    assert!(!c.dir.path().join("o/h/s_0000.npy").exists());
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(c.dir.path().join("o/report.json")).unwrap())
            .unwrap();
    assert_eq!(report["frames"], serde_json::json!([]), "{report}");
    let why = report["error"].as_str().unwrap_or_default();
    assert!(why.contains("node 's', frame 0"), "{why}");
}

/// One pipeline drops two cloths on the same sphere, one colliding through its distance field
/// and one through its depth maps: both rest on it, none inside, at the same height within a
/// few texels; a cloth with depth colliders asked to run on the GPU is refused.
#[test]
fn a_pipeline_compares_the_field_and_depth_map_colliders() {
    let cloth = |name: &str, colliders: &str| {
        format!(
            r#"        "{name}": Cloth({colliders}
            params: (
                shape: Grid(size: (0.9, 0.9), resolution: (17, 17), center: (0, 0.42, 0), normal: (0, 1, 0)),
                material: Harada(k_structural: 60.0, k_shear: 15.0),
                mass: 0.001, damping: 0.995, collision: (epsilon: 0.01, friction: 0.5), substeps: 16,
            )),
"#
        )
    };
    let nodes = format!(
        r#"        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 96, rings: 48)),
        "boundary": Voxelize(mesh: "ball", grid: Fit(resolution: 48, padding: 0.2)),
        "field": DistanceField(boundary: "boundary", band: 3),
{}{}        "obj": WriteMesh(mesh: "by_maps", every: 119),
        "obj_field": WriteMesh(mesh: "by_field", every: 119),"#,
        cloth("by_field", r#"colliders: ["field"],"#),
        cloth(
            "by_maps",
            r#"depth_colliders: [(body: "ball", params: (views: [(0, -1, 0), (0, 0, -1), (1, 0, 0)], resolution: 192))],"#
        ),
    );
    let c = case_timed(&nodes, "frames: 120, fps: 60");
    run_ok(
        &["run", c.file.to_str().unwrap(), "--out", "o"],
        c.dir.path(),
    );
    let report = read_json(&c.dir.path().join("o/report.json"));
    for n in ["by_field", "by_maps"] {
        let frames = report["nodes"][n]["metrics"]["per_frame"]
            .as_array()
            .unwrap_or_else(|| panic!("{n}: {}", report["nodes"][n]));
        assert!(frames.iter().all(|f| f["inside"] == 0), "{n}: {frames:?}");
        assert!(
            frames.last().unwrap()["contacts"].as_u64().unwrap() > 20,
            "{n}"
        );
        assert_eq!(report["nodes"][n]["backend"], "cpu");
    }
    // The resting cloth's middle (the grid's centre particle) over the pole: ε above the
    // sphere on both.
    let middle = |file: &str| {
        let m = imprint_core::Mesh::load_obj(&c.dir.path().join(file)).unwrap();
        m.positions[8 * 17 + 8]
    };
    let (maps, field) = (
        middle("o/obj/by_maps_0119.obj"),
        middle("o/obj_field/by_field_0119.obj"),
    );
    eprintln!("middle particle: depth maps {maps}, field {field}");
    assert!(
        (maps.y - 0.31).abs() < 0.003,
        "depth-map cloth rests at {maps}"
    );
    assert!(
        (field.y - 0.31).abs() < 0.003,
        "field cloth rests at {field}"
    );
    // A cloth with depth colliders is a CPU cloth: asking for the GPU is an input error.
    let bad = nodes.replace("depth_colliders: [", "backend: Gpu, depth_colliders: [");
    expect_invalid(&bad, &["by_maps", "backend", "depth_colliders"]);
}

/// The Skin node, three ways on one limb (radius 0.1, length 1, joint at the middle) twisted
/// 180°: LBS's joint collapses (the automatic weights are ½ and ½ on the joint's ring, so its
/// section goes to 0), DQS keeps it exactly, particles keep ≥ 90% of it and the volume within
/// 5%; the particle fill is smaller than a uniform one. A bent limb flows into a Heightmap like
/// any mesh. A broken rig file is named with its line and column (exit 2).
#[test]
fn skin_node_twists_a_limb_three_ways_and_feeds_other_nodes() {
    let limb = r#"        "limb": Mesh(primitive: Cylinder(radius: 0.1, length: 1.0, segments: 32, rings: 32)),"#;
    let nodes = format!(
        r#"{limb}
        "lbs": Skin(mesh: "limb", rig: "twist.ron", method: Linear()),
        "dqs": Skin(mesh: "limb", rig: "twist.ron", method: DualQuaternion(), offset: (0, 0, 0.5)),
        "particles": Skin(mesh: "limb", rig: "twist.ron", method: Particles()),
        "bent": Skin(mesh: "limb", rig: "bend.ron", method: Linear()),
        "top": Heightmap(mesh: "bent", grid: Explicit(origin: (-0.2, -0.2), cell: 0.01, dims: (90, 40)), empty: -1.0),
        "obj": WriteMesh(mesh: "dqs", every: 35),
        "obj_p": WriteMesh(mesh: "particles", every: 35),
        "obj_l": WriteMesh(mesh: "lbs", every: 35),
        "hm": WriteHeightmap(heights: "top", formats: [Npy], every: 100),"#
    );
    let c = case_timed(&nodes, "frames: 36, fps: 24");
    let rig = |motion: &str| {
        format!(
            r#"Rig(
    bones: [
        (name: "upper", head: (0, 0, 0), tail: (0.5, 0, 0)),
        (name: "lower", head: (0.5, 0, 0), tail: (1.0, 0, 0), parent: "upper"),
    ],
    animation: [{motion}],
)"#
        )
    };
    let dir = c.dir.path();
    std::fs::write(
        dir.join("twist.ron"),
        rig(r#"Twist(bone: "lower", degrees: 180, start: 0.0, duration: 0.5)"#),
    )
    .unwrap();
    std::fs::write(
        dir.join("bend.ron"),
        rig(r#"Bend(bone: "lower", axis: (0, 0, 1), degrees: 90, start: 0.0, duration: 0.5)"#),
    )
    .unwrap();
    run_ok(&["run", c.file.to_str().unwrap(), "--out", "o"], dir);
    let report = read_json(&dir.join("o/report.json"));
    let last = |n: &str| {
        report["nodes"][n]["metrics"]["per_frame"]
            .as_array()
            .unwrap()
            .last()
            .unwrap()
            .clone()
    };
    let section = |n: &str| {
        last(n)["joints"]["lower"]["section_ratio"]
            .as_f64()
            .unwrap()
    };
    let volume = |n: &str| last(n)["volume_ratio"].as_f64().unwrap();
    eprintln!(
        "twist 180°: section LBS {:.4} DQS {:.4} particles {:.4}; volume LBS {:.4} DQS {:.4} particles {:.4}",
        section("lbs"),
        section("dqs"),
        section("particles"),
        volume("lbs"),
        volume("dqs"),
        volume("particles")
    );
    assert!(section("lbs") < 1e-3, "LBS section {}", section("lbs"));
    assert!(
        (section("dqs") - 1.0).abs() < 1e-3,
        "DQS section {}",
        section("dqs")
    );
    assert!(
        section("particles") >= 0.9,
        "particles {}",
        section("particles")
    );
    assert!((volume("particles") - 1.0).abs() <= 0.05);
    let p = &report["nodes"]["particles"]["metrics"];
    assert!(
        p["particles"].as_u64() < p["particles_uniform"].as_u64(),
        "{p}"
    );
    // A run of the last frames only replays the particles' history first: its frame 35 is
    // the whole run's, byte for byte.
    run_ok(
        &[
            "run",
            c.file.to_str().unwrap(),
            "--out",
            "part",
            "--frames",
            "30..36",
        ],
        dir,
    );
    let read = |d: &str| std::fs::read(dir.join(d).join("obj_p/particles_0035.obj")).unwrap();
    assert!(
        read("o") == read("part"),
        "a partial run's particles differ"
    );
    // The DQS mesh is the twisted limb, moved by its offset.
    let m = imprint_core::Mesh::load_obj(&dir.join("o/obj/dqs_0000.obj")).unwrap();
    let z = m.positions.iter().map(|p| p.z).sum::<f32>() / m.positions.len() as f32;
    assert!((z - 0.5).abs() < 1e-3, "mean z {z}");
    // The bent limb's lower half stands up: its cap reaches y = 0.5 (+ the cylinder's radius
    // beside it, not above), seen by the Heightmap.
    let top = report["nodes"]["top"]["metrics"]["height_max"]
        .as_f64()
        .unwrap();
    assert!((top - 0.5).abs() < 0.02, "bent limb's top at {top}");
    // A rig with an unknown parent: named with file, line and column, exit 2.
    std::fs::write(
        dir.join("twist.ron"),
        rig("").replace(r#"parent: "upper""#, r#"parent: "uper""#),
    )
    .unwrap();
    let out = imprint(&["check", c.file.to_str().unwrap()], dir);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("twist.ron:4:") && err.contains("uper"),
        "{err}"
    );
    // On the GPU (lavapipe in CI): the same twisted limbs to f32 rounding, the particles'
    // included.
    std::fs::write(
        dir.join("twist.ron"),
        rig(r#"Twist(bone: "lower", degrees: 180, start: 0.0, duration: 0.5)"#),
    )
    .unwrap();
    if !run_gpu_or_skip(c.file.to_str().unwrap(), "gpu", dir) {
        return;
    }
    let gpu_report = read_json(&dir.join("gpu/report.json"));
    for (n, file) in [
        ("dqs", "obj/dqs_0035.obj"),
        ("lbs", "obj_l/lbs_0035.obj"),
        ("particles", "obj_p/particles_0035.obj"),
    ] {
        assert_eq!(gpu_report["nodes"][n]["backend"], "gpu");
        let a = imprint_core::Mesh::load_obj(&dir.join("o").join(file)).unwrap();
        let b = imprint_core::Mesh::load_obj(&dir.join("gpu").join(file)).unwrap();
        let worst = a
            .positions
            .iter()
            .zip(&b.positions)
            .map(|(p, q)| (*p - *q).length())
            .fold(0f32, f32::max);
        eprintln!("{n}: GPU − CPU at most {worst:.2e} m");
        assert!(worst < 1e-5, "{n}: GPU and CPU differ by {worst}");
    }
}

/// A Skin node whose rig file is missing, or whose particle parameters are out of range, is
/// refused before anything runs, naming the node and the field.
#[test]
fn skin_node_input_errors_name_the_field() {
    let limb = r#"        "limb": Mesh(primitive: Cylinder(radius: 0.1, length: 1.0)),"#;
    expect_invalid(
        &format!(
            "{limb}\n        \"s\": Skin(mesh: \"limb\", rig: \"missing.ron\", method: Linear()),\n        \"o\": WriteMesh(mesh: \"s\"),"
        ),
        &["'s'", "rig file not found", "missing.ron"],
    );
    let c = case(&format!(
        "{limb}\n        \"s\": Skin(mesh: \"limb\", rig: \"r.ron\", method: Particles(substeps: 0)),\n        \"o\": WriteMesh(mesh: \"s\"),"
    ));
    std::fs::write(
        c.dir.path().join("r.ron"),
        r#"Rig(bones: [(name: "a", head: (0, 0, 0), tail: (1, 0, 0))])"#,
    )
    .unwrap();
    let out = imprint(&["check", c.file.to_str().unwrap()], c.dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("method") && err.contains("substeps"), "{err}");
}

/// H's scene with the cow in place of the bunny and its field built every 4 frames,
/// interpolated: the horns move farther between two builds than the 3-cell band, and the
/// cloth caught on them blows up at frame 21 whatever its substeps (160 too). The error names
/// the band misses and the band, and with the band widened beyond that motion, as it says,
/// the same scene runs on past that frame.
#[test]
fn a_cloth_blown_up_by_band_misses_names_the_band_and_a_wider_band_holds() {
    let dir = tempfile::tempdir().unwrap();
    let file = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../pipelines/harada_cloth.ron"
    ));
    let run = |band: &str, frames: &str| {
        let args = [
            "run",
            file.to_str().unwrap(),
            "--out",
            "o",
            "--backend",
            "cpu",
            "--frames",
            frames,
            "--set",
            "bunny.path=\"../assets/meshes/cow.obj\"",
            "--set",
            "field.every=4",
            "--set",
            "field.interpolate=true",
            "--set",
            band,
            "--set",
            "render.enabled=false",
        ];
        imprint(&args, dir.path())
    };
    let out = run("field.band=3.0", "0..24");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("node 'cloth', frame 21"), "{err}");
    assert!(
        err.contains("band misses") && err.contains("now 3 cells"),
        "{err}"
    );
    assert!(err.contains("`every`"), "{err}");
    let out = run("field.band=14.0", "0..30");
    assert_eq!(
        out.status.code(),
        Some(0),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// H's scene on the GPU (`harada_cloth.ron --backend gpu`, its first 3 frames): the field
/// built on the GPU feeds the GPU cloth without coming back to the CPU. report.json counts
/// the bytes each node moved: no field is read back, voxeliser and field read nothing back,
/// and the cloth reads back only its own state (under 100 bytes per particle).
#[test]
fn gpu_field_feeds_gpu_cloth_without_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let file = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../pipelines/harada_cloth.ron"
    ));
    let gpu = imprint(
        &[
            "run",
            file.to_str().unwrap(),
            "--out",
            "o",
            "--backend",
            "gpu",
            "--frames",
            "0..3",
        ],
        dir.path(),
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
        serde_json::from_slice(&std::fs::read(dir.path().join("o/report.json")).unwrap()).unwrap();
    let nodes = report["nodes"].as_object().unwrap();
    let moved = |node: &str, key: &str| -> Vec<u64> {
        let t = nodes[node]["transfers"]
            .as_array()
            .cloned()
            .unwrap_or_default();
        t.iter().map(|f| f[key].as_u64().unwrap_or(0)).collect()
    };
    for node in ["boundary", "field", "cloth"] {
        assert_eq!(nodes[node]["backend"], "gpu", "{node}");
    }
    for (name, _) in nodes {
        assert!(
            moved(name, "field_read_backs").iter().all(|&n| n == 0),
            "{name} read a field back: {}",
            nodes[name]["transfers"]
        );
    }
    assert!(moved("boundary", "read_back_bytes").iter().all(|&b| b == 0));
    assert!(moved("field", "read_back_bytes").iter().all(|&b| b == 0));
    let cloth = moved("cloth", "read_back_bytes");
    assert_eq!(cloth.len(), 3, "the cloth's state comes back once a frame");
    let particles = 70 * 70;
    assert!(
        cloth.iter().all(|&b| b > 0 && b < 100 * particles),
        "{cloth:?}"
    );
}
