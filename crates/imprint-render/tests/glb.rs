//! A run's meshes as one animated GLB ([`MeshSequence`], [`glb_bytes`]): each layout is a
//! valid file (checked byte by byte and by the `gltf` crate) that shows, at each animation
//! key, exactly the frame that was pushed, at `(frame - first) / fps`.

mod glb_check;

use glb_check::Frame;
use imprint_core::Mesh;
use imprint_core::glam::Vec3;
use imprint_core::mesh::primitives;
use imprint_render::mesh_io::{MeshSequence, glb_bytes, write_glb};

/// A sphere stretched, sheared and squashed more at each frame: the same triangles throughout.
fn deformed(k: u32) -> Mesh {
    let mut m = primitives::uv_sphere(1.0, 12, 6);
    let s = 1.0 + 0.1 * k as f32;
    for p in &mut m.positions {
        *p = Vec3::new(
            p.x * s + 0.05 * k as f32 * p.y,
            p.y + 0.3 * k as f32,
            p.z / s,
        );
    }
    m.compute_normals();
    m
}

/// `frame` shows `mesh`'s triangles, corner by corner, within `tol`.
fn assert_shows(frame: &Frame, mesh: &Mesh, tol: f32, what: &str) {
    assert_eq!(
        frame.triangles.len(),
        mesh.triangles.len(),
        "{what}: triangles"
    );
    for (t, tri) in frame.triangles.iter().enumerate() {
        for (c, corner) in mesh.triangle(t).iter().enumerate() {
            let d = (Vec3::from(tri[c]) - *corner).abs().max_element();
            assert!(d <= tol, "{what}: triangle {t} corner {c} off by {d}");
        }
    }
}

#[test]
fn same_triangles_make_one_morphed_mesh_with_a_step_key_per_frame() {
    let fps = 24.0;
    let meshes: Vec<Mesh> = (0..5).map(deformed).collect();
    let mut seq = MeshSequence::default();
    for (k, m) in meshes.iter().enumerate() {
        // The run started at frame 10: the file still plays from time 0.
        seq.push(10 + k as u32, m).unwrap();
    }
    assert!(seq.shares_topology());
    let glb = glb_check::check(&glb_bytes(&seq, fps, "ball").unwrap());
    let j = &glb.json;
    assert_eq!(j["nodes"].as_array().unwrap().len(), 1);
    let prim = &j["meshes"][0]["primitives"][0];
    assert_eq!(
        prim["targets"].as_array().unwrap().len(),
        5,
        "a target per frame"
    );
    assert!(prim["targets"][4]["NORMAL"].is_u64(), "normal deltas too");
    assert_eq!(j["meshes"][0]["extras"]["targetNames"][4], "frame_0014");
    assert_eq!(
        j["animations"][0]["channels"][0]["target"]["path"],
        "weights"
    );
    let frames = glb_check::frames(&glb);
    assert_eq!(frames.len(), 5);
    for (k, (f, m)) in frames.iter().zip(&meshes).enumerate() {
        assert_eq!(f.time, k as f32 / fps, "key {k}'s time");
        // Base + delta in f32: within an ulp or two of the pushed positions (about 3).
        assert_shows(f, m, 1e-6, &format!("frame {k}"));
    }
}

#[test]
fn changing_triangles_make_one_node_per_frame_shown_in_turn() {
    let fps = 30.0;
    let mut moved = primitives::cuboid(Vec3::ONE, 1);
    moved.transform(imprint_core::glam::Mat4::from_translation(Vec3::X * 3.0));
    let meshes = [
        primitives::cuboid(Vec3::ONE, 1),
        primitives::cuboid(Vec3::ONE, 2),
        primitives::uv_sphere(1.0, 8, 4),
        moved,
    ];
    let mut seq = MeshSequence::default();
    for (k, m) in meshes.iter().enumerate() {
        seq.push(k as u32, m).unwrap();
    }
    assert!(!seq.shares_topology());
    let glb = glb_check::check(&glb_bytes(&seq, fps, "shapes").unwrap());
    assert_eq!(
        glb.json["nodes"].as_array().unwrap().len(),
        1 + 4,
        "a root and a node per frame"
    );
    assert_eq!(glb.json["meshes"].as_array().unwrap().len(), 4);
    let frames = glb_check::frames(&glb);
    assert_eq!(frames.len(), 4);
    for (k, (f, m)) in frames.iter().zip(&meshes).enumerate() {
        assert_eq!(f.time, k as f32 / fps);
        // Each frame's own positions: exact.
        assert_shows(f, m, 0.0, &format!("frame {k}"));
    }
}

#[test]
fn one_frame_is_a_still_mesh() {
    let m = deformed(2);
    let mut seq = MeshSequence::default();
    seq.push(0, &m).unwrap();
    let glb = glb_check::check(&glb_bytes(&seq, 24.0, "still").unwrap());
    assert!(glb.json.get("animations").is_none());
    let frames = glb_check::frames(&glb);
    assert_eq!(frames.len(), 1);
    assert_shows(&frames[0], &m, 0.0, "the frame");
}

#[test]
fn stepping_back_replaces_the_later_frames() {
    let mut seq = MeshSequence::default();
    for k in 0..4 {
        seq.push(k, &deformed(k)).unwrap();
    }
    // A seek back to frame 2, which now has another shape.
    let other = primitives::cuboid(Vec3::ONE, 1);
    seq.push(2, &other).unwrap();
    assert_eq!(seq.frame_numbers(), [0, 1, 2]);
    let frames = glb_check::frames(&glb_check::check(&glb_bytes(&seq, 10.0, "s").unwrap()));
    assert_eq!(frames.len(), 3);
    assert_shows(&frames[2], &other, 0.0, "the replaced frame");
    // Back again to frame 2 with the sphere: one topology again, so morph targets.
    seq.push(2, &deformed(2)).unwrap();
    assert!(seq.shares_topology());
}

#[test]
fn a_mesh_no_glb_can_hold_is_refused_at_its_frame() {
    let mut seq = MeshSequence::default();
    seq.push(0, &deformed(0)).unwrap();
    let mut bad = deformed(1);
    bad.positions[5].y = f32::NAN;
    let e = seq.push(7, &bad).unwrap_err().to_string();
    assert!(e.contains("frame 7") && e.contains("position 5"), "{e}");
    assert_eq!(seq.len(), 1, "nothing kept of the refused frame");
    let empty = MeshSequence::default();
    assert!(
        glb_bytes(&empty, 24.0, "e")
            .unwrap_err()
            .to_string()
            .contains("no frames")
    );
    assert!(glb_bytes(&seq, 0.0, "e").is_err());
}

#[test]
fn a_checkpointed_sequence_writes_the_same_file() {
    let mut seq = MeshSequence::default();
    for k in 0..3 {
        seq.push(k, &deformed(k)).unwrap();
    }
    let saved = postcard::to_allocvec(&seq).unwrap();
    let back: MeshSequence = postcard::from_bytes(&saved).unwrap();
    assert_eq!(back, seq);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out/ball.glb");
    write_glb(&path, &back, 24.0, "ball").unwrap();
    assert_eq!(
        std::fs::read(&path).unwrap(),
        glb_bytes(&seq, 24.0, "ball").unwrap()
    );
    // Only the file: no temporary left beside it.
    assert_eq!(
        std::fs::read_dir(dir.path().join("out")).unwrap().count(),
        1
    );
}

#[test]
fn imprint_reads_back_frame_0_of_the_glb_it_writes() {
    let dir = tempfile::tempdir().unwrap();
    let mut seq = MeshSequence::default();
    for k in 0..3 {
        seq.push(k, &deformed(k + 1)).unwrap();
    }
    let path = dir.path().join("ball.glb");
    write_glb(&path, &seq, 24.0, "ball").unwrap();
    // imprint's glTF reader takes the base mesh (morph targets are not read): frame 0.
    let back = imprint_core::load_mesh(&path).unwrap();
    let want = deformed(1);
    assert_eq!(back.triangles, want.triangles);
    assert_eq!(back.positions, want.positions);
}
