//! Mesh files in and out of a real run: a Mesh node reads STL and PLY as it reads OBJ, and
//! refuses an image with what it is; `WriteMesh(format: Glb)` writes one `.glb` of the whole
//! run that plays, key by key at `k / fps`, exactly the meshes `WriteMesh(format: Obj)` writes
//! frame by frame, and that a run cut in two with `--resume` writes byte for byte as the whole
//! run does.

use imprint_core::Mesh;
use imprint_core::glam::Vec3;
use std::path::Path;

mod common;
use common::{imprint, run_ok};

#[path = "../../imprint-render/tests/glb_check/mod.rs"]
mod glb_check;

const FRAMES: usize = 5;
const FPS: f32 = 12.0;

/// A sphere that breathes and ripples (it deforms, not just moves), written as OBJ every
/// frame and as one GLB.
fn scene(dir: &Path) -> String {
    let text = format!(
        r#"Pipeline(
    frames: {FRAMES},
    fps: {FPS},
    backend: Cpu,
    nodes: {{
        "m": Mesh(primitive: Sphere(radius: 0.5, segments: 16, rings: 8),
                  motion: [Breathe(amplitude: 0.1, period: 0.5),
                           Wave(amplitude: 0.05, wavelength: 0.4, speed: 1.0)]),
        "objs": WriteMesh(mesh: "m"),
        "glb": WriteMesh(mesh: "m", format: Glb),
    }},
)
"#
    );
    let p = dir.join("p.ron");
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn glb_plays_the_frames_the_objs_hold_at_k_over_fps() {
    let dir = tempfile::tempdir().unwrap();
    let file = scene(dir.path());
    run_ok(&["run", &file, "--out", "o"], dir.path());
    let out = dir.path().join("o");
    let objs: Vec<Mesh> = (0..FRAMES)
        .map(|k| Mesh::load_obj(&out.join(format!("objs/m_{k:04}.obj"))).unwrap())
        .collect();
    let glb = glb_check::check(&std::fs::read(out.join("glb/m.glb")).unwrap());
    // The same triangles every frame: morph targets, one per frame.
    let prim = &glb.json["meshes"][0]["primitives"][0];
    assert_eq!(prim["targets"].as_array().unwrap().len(), FRAMES);
    let frames = glb_check::frames(&glb);
    assert_eq!(frames.len(), FRAMES, "one key per frame");
    for (k, (f, obj)) in frames.iter().zip(&objs).enumerate() {
        assert_eq!(f.time, k as f32 / FPS, "key {k} at k / fps");
        assert_eq!(f.triangles.len(), obj.triangles.len());
        // OBJ prints the shortest decimal that reads back to the same f32; the GLB's frame is
        // base + delta in f32: equal within an ulp or two of these coordinates (< 1).
        let worst = (0..obj.triangles.len())
            .flat_map(|t| (0..3).map(move |c| (t, c)))
            .map(|(t, c)| {
                (Vec3::from(f.triangles[t][c]) - obj.triangle(t)[c])
                    .abs()
                    .max_element()
            })
            .fold(0.0, f32::max);
        assert!(worst <= 2.0 * f32::EPSILON, "frame {k}: off by {worst}");
    }
    // Every frame differs from frame 0: a still mesh would pass the above trivially.
    for (k, obj) in objs.iter().enumerate().skip(1) {
        let moved = (obj.positions.iter().zip(&objs[0].positions))
            .map(|(a, b)| (*a - *b).length())
            .fold(0.0, f32::max);
        assert!(moved > 0.01, "frame {k} moved {moved}");
    }
    let report: serde_json::Value =
        serde_json::from_slice(&std::fs::read(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(
        report["nodes"]["glb"]["metrics"]["glb_layout"],
        "morph targets"
    );
}

#[test]
fn a_resumed_run_writes_the_whole_runs_glb() {
    let dir = tempfile::tempdir().unwrap();
    let file = scene(dir.path());
    run_ok(&["run", &file, "--out", "whole"], dir.path());
    let cut = ["run", &file, "--out", "cut"];
    run_ok(
        &[&cut[..], &["--frames", "0..2", "--checkpoint-every", "1"]].concat(),
        dir.path(),
    );
    let first = glb_check::frames(&glb_check::check(
        &std::fs::read(dir.path().join("cut/glb/m.glb")).unwrap(),
    ));
    assert_eq!(
        first.len(),
        2,
        "the first piece's file holds its own frames"
    );
    run_ok(
        &[&cut[..], &["--frames", &format!("0..{FRAMES}"), "--resume"]].concat(),
        dir.path(),
    );
    let read = |d: &str| std::fs::read(dir.path().join(d).join("glb/m.glb")).unwrap();
    assert_eq!(read("cut"), read("whole"));
}

/// A binary STL of a unit cube (12 triangles, corners repeated as STL stores them), its
/// header starting with "solid" as some exporters write it.
fn cube_stl() -> Vec<u8> {
    const QUADS: [[usize; 4]; 6] = [
        [0, 4, 6, 2],
        [1, 3, 7, 5],
        [0, 1, 5, 4],
        [2, 6, 7, 3],
        [0, 2, 3, 1],
        [4, 5, 7, 6],
    ];
    let corner = |i: usize| [0, 1, 2].map(|a| (i >> a & 1) as f32);
    let mut b = b"solid cube, binary".to_vec();
    b.resize(80, b' ');
    b.extend_from_slice(&12u32.to_le_bytes());
    for q in QUADS {
        for t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
            b.extend_from_slice(&[0u8; 12]);
            for c in t.map(corner).iter().flatten() {
                b.extend_from_slice(&c.to_le_bytes());
            }
            b.extend_from_slice(&[0, 0]);
        }
    }
    b
}

/// A one-frame pipeline reading `mesh` and writing it as OBJ.
fn reading(dir: &Path, mesh: &str) -> String {
    let text = format!(
        "Pipeline(frames: 1, backend: Cpu, nodes: {{\n\
         \"m\": Mesh(path: \"{mesh}\"),\n\
         \"objs\": WriteMesh(mesh: \"m\"),\n}})\n"
    );
    let p = dir.join("read.ron");
    std::fs::write(&p, text).unwrap();
    p.display().to_string()
}

#[test]
fn a_mesh_node_reads_stl_and_ply_and_refuses_an_image() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.stl"), cube_stl()).unwrap();
    let file = reading(dir.path(), "cube.stl");
    run_ok(&["run", &file, "--out", "stl"], dir.path());
    let m = Mesh::load_obj(&dir.path().join("stl/objs/m_0000.obj")).unwrap();
    assert_eq!(
        (m.positions.len(), m.triangles.len()),
        (8, 12),
        "welded cube"
    );
    assert!(m.is_closed());

    // The same cube as imprint's own PLY, read back by a pipeline.
    imprint_render::mesh_io::write_ply(&dir.path().join("cube.ply"), &m).unwrap();
    let file = reading(dir.path(), "cube.ply");
    run_ok(&["run", &file, "--out", "ply"], dir.path());
    let p = Mesh::load_obj(&dir.path().join("ply/objs/m_0000.obj")).unwrap();
    assert_eq!(p.positions, m.positions);
    assert_eq!(p.triangles, m.triangles);

    std::fs::write(
        dir.path().join("photo.png"),
        b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR",
    )
    .unwrap();
    let file = reading(dir.path(), "photo.png");
    let out = imprint(&["run", &file, "--out", "png"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("photo.png") && err.contains("a PNG image"),
        "{err}"
    );
    assert!(err.contains(imprint_core::mesh_formats::SUPPORTED), "{err}");
}

/// A Skin node over the hand-made two-joint glTF (tests/data/two_joint.gltf), edited by
/// `edit` into a bad file: the run stops before any frame with exit code 2, a message that
/// names the file and says `what`, and no output folder.
fn bad_rig(name: &str, edit: impl FnOnce(&mut serde_json::Value), clip: &str, what: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/two_joint.gltf");
    let mut json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(src).unwrap()).unwrap();
    edit(&mut json);
    std::fs::write(dir.path().join(name), json.to_string()).unwrap();
    let text = format!(
        "Pipeline(frames: 2, backend: Cpu, nodes: {{\n\
         \"s\": Skin(rig: \"{name}\", clip: \"{clip}\", method: Linear()),\n\
         \"objs\": WriteMesh(mesh: \"s\"),\n}})\n"
    );
    std::fs::write(dir.path().join("p.ron"), text).unwrap();
    let out = imprint(&["run", "p.ron", "--out", "o"], dir.path());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{name}: {err}");
    assert!(
        err.contains(name),
        "{name}: the message names the file: {err}"
    );
    for w in what {
        assert!(err.contains(w), "{name}: the message says {w:?}: {err}");
    }
    assert!(!dir.path().join("o").exists(), "{name}: nothing written");
}

#[test]
fn bad_gltf_rigs_stop_with_the_file_and_the_fault() {
    bad_rig("unknown_clip.gltf", |_| {}, "Run", &["Run", "Bend"]);
    bad_rig(
        "no_skin.gltf",
        |j| {
            j.as_object_mut().unwrap().remove("skins");
            j["nodes"][0].as_object_mut().unwrap().remove("skin");
            let attrs = j["meshes"][0]["primitives"][0]["attributes"]
                .as_object_mut()
                .unwrap();
            attrs.remove("JOINTS_0");
            attrs.remove("WEIGHTS_0");
        },
        "Bend",
        &["no skin"],
    );
    bad_rig(
        "missing_bin.gltf",
        |j| j["buffers"][0]["uri"] = "limb.bin".into(),
        "Bend",
        &["limb.bin"],
    );
    bad_rig(
        "draco.gltf",
        |j| j["extensionsRequired"] = serde_json::json!(["KHR_draco_mesh_compression"]),
        "Bend",
        &["KHR_draco_mesh_compression"],
    );
    bad_rig(
        "joint_out_of_range.gltf",
        |j| j["skins"][0]["joints"] = serde_json::json!([1]),
        "Bend",
        &["joint"],
    );
}
