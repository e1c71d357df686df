//! glTF input against answers worked out by hand: skinning a two-joint rig, the three
//! interpolations, GLB and external buffers, weights, clip time, and every kind of bad file.

use base64::Engine as _;
use imprint_core::glam::{Mat4, Vec3};
use imprint_core::gltf::{ClipTime, Document};
use serde_json::{Value, json};
use std::f32::consts::FRAC_1_SQRT_2;
use std::path::Path;

/// Packs arrays into one buffer, each with its own buffer view and accessor; `gltf`/`glb`
/// wrap a document around them.
#[derive(Default)]
struct Packer {
    bin: Vec<u8>,
    views: Vec<Value>,
    accessors: Vec<Value>,
}

fn components(ty: &str) -> usize {
    match ty {
        "SCALAR" => 1,
        "VEC3" => 3,
        "VEC4" => 4,
        "MAT4" => 16,
        _ => panic!("test packer: type {ty}"),
    }
}

impl Packer {
    /// Adds a buffer view over `bytes` and an accessor of `count` elements; returns its index.
    fn push(&mut self, bytes: &[u8], count: usize, ty: &str, component: u32) -> usize {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        self.views.push(json!({
            "buffer": 0, "byteOffset": self.bin.len(), "byteLength": bytes.len()
        }));
        self.bin.extend_from_slice(bytes);
        self.accessors.push(json!({
            "bufferView": self.views.len() - 1,
            "componentType": component, "count": count, "type": ty
        }));
        self.accessors.len() - 1
    }

    fn f32s(&mut self, data: &[f32], ty: &str) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.push(&bytes, data.len() / components(ty), ty, 5126)
    }

    fn u16s(&mut self, data: &[u16], ty: &str) -> usize {
        let bytes: Vec<u8> = data.iter().flat_map(|x| x.to_le_bytes()).collect();
        self.push(&bytes, data.len() / components(ty), ty, 5123)
    }

    fn u8s(&mut self, data: &[u8], ty: &str, normalized: bool) -> usize {
        let a = self.push(data, data.len() / components(ty), ty, 5121);
        self.accessors[a]["normalized"] = json!(normalized);
        a
    }

    fn attach(&self, doc: &mut Value, uri: Option<String>) {
        doc["asset"] = json!({"version": "2.0"});
        let mut buffer = json!({"byteLength": self.bin.len()});
        if let Some(uri) = uri {
            buffer["uri"] = json!(uri);
        }
        doc["buffers"] = json!([buffer]);
        doc["bufferViews"] = json!(self.views);
        doc["accessors"] = json!(self.accessors);
    }

    /// The document as .gltf JSON with the buffer as a base64 data URI.
    fn gltf(&self, mut doc: Value) -> Vec<u8> {
        let b64 = base64::engine::general_purpose::STANDARD.encode(&self.bin);
        self.attach(
            &mut doc,
            Some(format!("data:application/octet-stream;base64,{b64}")),
        );
        serde_json::to_vec_pretty(&doc).unwrap()
    }

    /// The document as .gltf JSON whose buffer is the external file `uri`.
    fn gltf_external(&self, mut doc: Value, uri: &str) -> Vec<u8> {
        self.attach(&mut doc, Some(uri.to_string()));
        serde_json::to_vec_pretty(&doc).unwrap()
    }

    /// The document as GLB: header, JSON chunk (space padded), BIN chunk (zero padded).
    fn glb(&self, mut doc: Value) -> Vec<u8> {
        self.attach(&mut doc, None);
        let mut json = serde_json::to_vec(&doc).unwrap();
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = self.bin.clone();
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = b"glTF".to_vec();
        for word in [2, total as u32, json.len() as u32, 0x4E4F_534A] {
            out.extend(word.to_le_bytes());
        }
        out.extend(&json);
        out.extend((bin.len() as u32).to_le_bytes());
        out.extend(0x004E_4942u32.to_le_bytes());
        out.extend(&bin);
        out
    }
}

/// The two-joint rig: "root" at the origin, "child" at (0, 1, 0) under it, and three vertices
/// on "body": (1,0,0) all root, (1,2,0) all child, (1,1,0) half and half. Animation "bend"
/// turns the child about Z from 0 to 90° over `times` (LINEAR). Accessors: 0 POSITION,
/// 1 indices, 2 JOINTS_0, 3 WEIGHTS_0, 4 inverse binds, 5 times, 6 rotations.
struct Rig {
    joints: Vec<u16>,
    weights: Vec<f32>,
    times: Vec<f32>,
    rotations: Vec<f32>,
    mode: u32,
}

const S45: f32 = FRAC_1_SQRT_2;

impl Default for Rig {
    fn default() -> Self {
        Rig {
            joints: vec![0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0],
            weights: vec![1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.5, 0.5, 0.0, 0.0],
            times: vec![0.0, 1.0],
            // identity, then 90° about Z: (0, 0, sin 45°, cos 45°)
            rotations: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, S45, S45],
            mode: 4,
        }
    }
}

impl Rig {
    fn parts(&self) -> (Packer, Value) {
        let mut p = Packer::default();
        let pos = p.f32s(&[1.0, 0.0, 0.0, 1.0, 2.0, 0.0, 1.0, 1.0, 0.0], "VEC3");
        let idx = p.u16s(&[0, 1, 2], "SCALAR");
        let joints = p.u16s(&self.joints, "VEC4");
        let weights = p.f32s(&self.weights, "VEC4");
        #[rustfmt::skip]
        let ibm = p.f32s(&[
            1.0, 0.0, 0.0, 0.0,  0.0, 1.0, 0.0, 0.0,  0.0, 0.0, 1.0, 0.0,  0.0, 0.0, 0.0, 1.0,
            1.0, 0.0, 0.0, 0.0,  0.0, 1.0, 0.0, 0.0,  0.0, 0.0, 1.0, 0.0,  0.0, -1.0, 0.0, 1.0,
        ], "MAT4");
        let times = p.f32s(&self.times, "SCALAR");
        let rots = p.f32s(&self.rotations, "VEC4");
        let doc = json!({
            "scene": 0,
            "scenes": [{"nodes": [0, 2]}],
            "nodes": [
                {"name": "root", "children": [1]},
                {"name": "child", "translation": [0.0, 1.0, 0.0]},
                {"name": "body", "mesh": 0, "skin": 0}
            ],
            "meshes": [{"name": "body", "primitives": [{
                "attributes": {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights},
                "indices": idx, "mode": self.mode
            }]}],
            "skins": [{"name": "rig", "joints": [0, 1], "inverseBindMatrices": ibm}],
            "animations": [{
                "name": "bend",
                "samplers": [{"input": times, "output": rots, "interpolation": "LINEAR"}],
                "channels": [{"sampler": 0, "target": {"node": 1, "path": "rotation"}}]
            }]
        });
        (p, doc)
    }

    fn bytes(&self) -> Vec<u8> {
        let (p, doc) = self.parts();
        p.gltf(doc)
    }
}

fn read(bytes: &[u8], name: &str) -> Document {
    Document::from_slice(bytes, Path::new("/no/such/dir"), name).unwrap()
}

fn error(bytes: &[u8], name: &str) -> String {
    match Document::from_slice(bytes, Path::new("/no/such/dir"), name) {
        Ok(_) => panic!("{name} loaded but should not have"),
        Err(e) => e.to_string(),
    }
}

fn assert_has(message: &str, words: &[&str]) {
    for w in words {
        assert!(message.contains(w), "'{w}' missing from: {message}");
    }
}

fn assert_close(got: Vec3, want: Vec3) {
    assert!(got.distance(want) < 1e-5, "got {got}, want {want}");
}

fn assert_points(got: &[Vec3], want: &[Vec3]) {
    assert_eq!(got.len(), want.len());
    got.iter().zip(want).for_each(|(g, w)| assert_close(*g, *w));
}

#[test]
fn two_joint_rig_skins_by_hand_computed_positions() {
    let doc = read(&Rig::default().bytes(), "rig.gltf");
    let bind = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 2.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
    ];
    assert_points(&doc.mesh.positions, &bind);
    assert_eq!(doc.mesh.triangles, vec![[0, 1, 2]]);
    let clip = doc.clip("bend").unwrap();
    assert_eq!((clip.start, clip.end), (0.0, 1.0));
    // t = 0.5: the child has turned 45° about its head (0,1,0). The child vertex (1,2,0) sits
    // at (1,1,0) from the head, which turns to (0, √2): (0, 1+√2, 0). The shared vertex is the
    // mean of (1,1,0) (root) and the head + (1,0,0) turned 45°: (0,1,0) + (c, s, 0).
    let c = S45;
    let half = doc.posed_mesh(Some(clip), 0.5).positions;
    let want_half = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(0.0, 1.0 + 2f32.sqrt(), 0.0),
        Vec3::new((1.0 + c) / 2.0, (1.0 + 1.0 + c) / 2.0, 0.0),
    ];
    assert_points(&half, &want_half);
    // t = 1: 90°, (x, y) from the head goes to (−y, x).
    let full = doc.posed_mesh(Some(clip), 1.0).positions;
    let want_full = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, 2.0, 0.0),
        Vec3::new(0.5, 1.5, 0.0),
    ];
    assert_points(&full, &want_full);
    // Clamped past the end: the last pose.
    assert_points(&doc.posed_mesh(Some(clip), 7.0).positions, &want_full);
}

#[test]
fn rig_skin_joints_matrices_and_segments() {
    let doc = read(&Rig::default().bytes(), "rig.gltf");
    let skin = doc.skin.as_ref().unwrap();
    assert_eq!(skin.name, "rig");
    assert_eq!(doc.joint_count(), 2);
    let names: Vec<&str> = skin.joints.iter().map(|j| j.name.as_str()).collect();
    assert_eq!(names, ["root", "child"]);
    assert_eq!(skin.joints[0].parent, None);
    assert_eq!(skin.joints[1].parent, Some(0));
    assert_close(skin.joints[1].bind_world.w_axis.truncate(), Vec3::Y);
    for m in doc.skin_matrices(None, 0.0) {
        assert!(m.abs_diff_eq(Mat4::IDENTITY, 1e-6), "bind skin matrix {m}");
    }
    let clip = doc.clip("bend").unwrap();
    let worlds = doc.joint_worlds(Some(clip), 1.0);
    assert_close(worlds[1].w_axis.truncate(), Vec3::Y);
    assert_close(worlds[1].x_axis.truncate(), Vec3::Y); // x turned onto y
    // The root's tail is its child's head; the leaf child continues the bone by half.
    let segments = doc.joint_segments();
    assert_close(segments[0].0, Vec3::ZERO);
    assert_close(segments[0].1, Vec3::Y);
    assert_close(segments[1].0, Vec3::Y);
    assert_close(segments[1].1, Vec3::new(0.0, 1.5, 0.0));
    assert_eq!(doc.influences[2], vec![(0, 0.5), (1, 0.5)]);
}

#[test]
fn rest_pose_differing_from_bind_keeps_the_mesh_at_bind_and_clips_use_the_rest() {
    // The child rests turned 90° about Z although its inverse bind matrix says it was bound
    // unturned; the clip animates only the root (held still).
    let rig = Rig {
        rotations: vec![0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        ..Rig::default()
    };
    let (p, mut doc) = rig.parts();
    doc["nodes"][1]["rotation"] = json!([0.0, 0.0, S45, S45]);
    doc["animations"][0]["channels"][0]["target"]["node"] = json!(0);
    let doc = read(&p.gltf(doc), "rest.gltf");
    let bind = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(1.0, 2.0, 0.0),
        Vec3::new(1.0, 1.0, 0.0),
    ];
    assert_points(&doc.mesh.positions, &bind);
    assert!(
        doc.skin_matrices(None, 0.0)
            .iter()
            .all(|m| *m == Mat4::IDENTITY)
    );
    assert_close(doc.joint_worlds(None, 0.0)[1].x_axis.truncate(), Vec3::X);
    // With the clip the child takes its rest turn: the same answers as the bend at t = 1.
    let posed = doc.posed_mesh(Some(doc.clip("bend").unwrap()), 0.5);
    let want = [
        Vec3::new(1.0, 0.0, 0.0),
        Vec3::new(-1.0, 2.0, 0.0),
        Vec3::new(0.5, 1.5, 0.0),
    ];
    assert_points(&posed.positions, &want);
}

#[test]
fn unknown_clip_lists_the_clips_that_exist() {
    let doc = read(&Rig::default().bytes(), "rig.gltf");
    assert_has(
        &doc.clip("walk").unwrap_err().to_string(),
        &["rig.gltf", "'walk'", "'bend'"],
    );
}

/// Three root joints, each moved by one translation channel of clip "moves": "cubic"
/// (CUBICSPLINE, keys 0 and 2), "step" (STEP, keys 0, 1, 2) and "linear" (LINEAR, keys 1 and 3).
fn sampling_document() -> Document {
    let mut p = Packer::default();
    let pos = p.f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
    let joints = p.u16s(&[0; 12], "VEC4");
    let weights = p.f32s(&[1.0, 0.0, 0.0, 0.0].repeat(3), "VEC4");
    let cubic_t = p.f32s(&[0.0, 2.0], "SCALAR");
    #[rustfmt::skip]
    let cubic_v = p.f32s(&[
        9.0, 9.0, 9.0,  0.0, 0.0, 0.0,  1.0, 0.0, 0.0, // a0 (unused), v0, b0
        0.0, 1.0, 0.0,  1.0, 2.0, 0.0,  9.0, 9.0, 9.0, // a1, v1, b1 (unused)
    ], "VEC3");
    let step_t = p.f32s(&[0.0, 1.0, 2.0], "SCALAR");
    let step_v = p.f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 2.0, 0.0, 0.0], "VEC3");
    let linear_t = p.f32s(&[1.0, 3.0], "SCALAR");
    let linear_v = p.f32s(&[0.0, 0.0, 0.0, 2.0, 4.0, 0.0], "VEC3");
    let sampler = |i, o, how| json!({"input": i, "output": o, "interpolation": how});
    let channel = |s, n| json!({"sampler": s, "target": {"node": n, "path": "translation"}});
    let doc = json!({
        "scenes": [{"nodes": [0, 1, 2, 3]}],
        "nodes": [{"name": "cubic"}, {"name": "step"}, {"name": "linear"},
                  {"name": "body", "mesh": 0, "skin": 0}],
        "meshes": [{"primitives": [{"attributes":
            {"POSITION": pos, "JOINTS_0": joints, "WEIGHTS_0": weights}}]}],
        "skins": [{"joints": [0, 1, 2]}],
        "animations": [{"name": "moves",
            "samplers": [sampler(cubic_t, cubic_v, "CUBICSPLINE"),
                         sampler(step_t, step_v, "STEP"),
                         sampler(linear_t, linear_v, "LINEAR")],
            "channels": [channel(0, 0), channel(1, 1), channel(2, 2)]}]
    });
    read(&p.gltf(doc), "moves.gltf")
}

/// The translations of the three joints at `t`.
fn translations(doc: &Document, t: f32) -> Vec<Vec3> {
    let clip = doc.clip("moves").unwrap();
    let worlds = doc.joint_worlds(Some(clip), t);
    worlds.iter().map(|m| m.w_axis.truncate()).collect()
}

#[test]
fn cubic_spline_matches_hermite_worked_by_hand() {
    let doc = sampling_document();
    let clip = doc.clip("moves").unwrap();
    assert_eq!((clip.start, clip.end), (0.0, 3.0));
    // td = 2, v0 = 0, b0 = (1,0,0), a1 = (0,1,0), v1 = (1,2,0):
    // p = h01·v1 + 2·h10·b0 + 2·h11·a1 with h01 = −2u³+3u², h10 = u³−2u²+u, h11 = u³−u².
    // t=0.5, u=0.25: h01 = 0.15625, h10 = 0.140625, h11 = −0.046875 → (0.4375, 0.21875, 0)
    // t=1.0, u=0.5:  h01 = 0.5,     h10 = 0.125,    h11 = −0.125    → (0.75, 0.75, 0)
    // t=1.5, u=0.75: h01 = 0.84375, h10 = 0.046875, h11 = −0.140625 → (0.9375, 1.40625, 0)
    assert_close(translations(&doc, 0.5)[0], Vec3::new(0.4375, 0.21875, 0.0));
    assert_close(translations(&doc, 1.0)[0], Vec3::new(0.75, 0.75, 0.0));
    assert_close(translations(&doc, 1.5)[0], Vec3::new(0.9375, 1.40625, 0.0));
    assert_close(translations(&doc, 0.0)[0], Vec3::ZERO);
    // After its last key (t = 2) the spline holds v1, not a tangent.
    assert_close(translations(&doc, 2.5)[0], Vec3::new(1.0, 2.0, 0.0));
}

#[test]
fn step_holds_and_linear_interpolates_and_both_clamp() {
    let doc = sampling_document();
    let x = |v: f32| Vec3::new(v, 0.0, 0.0);
    assert_close(translations(&doc, 0.5)[1], x(0.0));
    assert_close(translations(&doc, 0.999)[1], x(0.0));
    assert_close(translations(&doc, 1.0)[1], x(1.0));
    assert_close(translations(&doc, 1.7)[1], x(1.0));
    assert_close(translations(&doc, 2.5)[1], x(2.0));
    // LINEAR keys at 1 and 3: before the first key its first value, then halfway at t = 2.
    assert_close(translations(&doc, 0.5)[2], Vec3::ZERO);
    assert_close(translations(&doc, 2.0)[2], Vec3::new(1.0, 2.0, 0.0));
    assert_close(translations(&doc, 2.5)[2], Vec3::new(1.5, 3.0, 0.0));
    // Time clamped to the clip [0, 3]: before the start every channel's first value, after the
    // end every channel's last value.
    let before = translations(&doc, -5.0);
    assert_points(&before, &[Vec3::ZERO, Vec3::ZERO, Vec3::ZERO]);
    let after = translations(&doc, 10.0);
    assert_points(
        &after,
        &[Vec3::new(1.0, 2.0, 0.0), x(2.0), Vec3::new(2.0, 4.0, 0.0)],
    );
}

#[test]
fn glb_and_external_bin_load_the_same_as_embedded_gltf() {
    let (p, doc) = Rig::default().parts();
    let embedded = read(&p.gltf(doc.clone()), "rig.gltf");
    let glb = read(&p.glb(doc.clone()), "rig.glb");
    let dir = tempfile::tempdir().unwrap();
    // GLB bytes under a .gltf name: the magic decides, not the extension.
    let misnamed = dir.path().join("rig-binary.gltf");
    std::fs::write(&misnamed, p.glb(doc.clone())).unwrap();
    let from_file = Document::load(&misnamed).unwrap();
    // An external buffer whose URI is percent-encoded.
    std::fs::write(dir.path().join("rig data.bin"), &p.bin).unwrap();
    let gltf_path = dir.path().join("rig.gltf");
    std::fs::write(&gltf_path, p.gltf_external(doc, "rig%20data.bin")).unwrap();
    let external = Document::load(&gltf_path).unwrap();
    let clip = embedded.clip("bend").unwrap();
    let want = embedded.posed_mesh(Some(clip), 0.5).positions;
    for other in [&glb, &from_file, &external] {
        assert_eq!(other.mesh.positions, embedded.mesh.positions);
        assert_eq!(other.influences, embedded.influences);
        let posed = other.posed_mesh(Some(other.clip("bend").unwrap()), 0.5);
        assert_eq!(posed.positions, want);
    }
    assert_eq!(from_file.path, misnamed);
}

#[test]
fn weights_are_renormalised_and_second_sets_used() {
    let rig = Rig {
        weights: vec![1.0, 0.0, 0.0, 0.0, 0.2, 0.2, 0.0, 0.0, 0.25, 0.0, 0.0, 0.0],
        joints: vec![0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0],
        ..Rig::default()
    };
    let (mut p, mut doc) = rig.parts();
    // Vertex 2 gets joint 1 at full weight from a second set, as normalised u8.
    let joints1 = p.u8s(&[0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0], "VEC4", false);
    let weights1 = p.u8s(&[0, 0, 0, 0, 0, 0, 0, 0, 255, 0, 0, 0], "VEC4", true);
    let attributes = &mut doc["meshes"][0]["primitives"][0]["attributes"];
    attributes["JOINTS_1"] = json!(joints1);
    attributes["WEIGHTS_1"] = json!(weights1);
    let doc = read(&p.gltf(doc), "weights.gltf");
    assert_eq!(doc.influences[0], vec![(0, 1.0)]); // zero weights dropped
    assert_eq!(doc.influences[1], vec![(0, 0.5), (1, 0.5)]); // (0.2, 0.2) → (0.5, 0.5)
    assert_eq!(doc.influences[2], vec![(0, 0.2), (1, 0.8)]); // (0.25, 1.0) / 1.25
    // At t = 1 vertex 2 = 0.2·(1,1,0) + 0.8·(0,2,0) (the child's 90° turn of (1,1,0)).
    let posed = doc.posed_mesh(Some(doc.clip("bend").unwrap()), 1.0);
    assert_close(posed.positions[2], Vec3::new(0.2, 1.8, 0.0));
}

#[test]
fn unskinned_prop_under_a_joint_follows_it_rigidly() {
    let (mut p, mut doc) = Rig::default().parts();
    let prop = p.f32s(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.5, 0.0], "VEC3");
    doc["meshes"].as_array_mut().unwrap().push(json!(
        {"name": "prop", "primitives": [{"attributes": {"POSITION": prop}}]}));
    doc["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "holder", "mesh": 1}));
    doc["nodes"][1]["children"] = json!([3]);
    let doc = read(&p.gltf(doc), "prop.gltf");
    // Depth first through the scene: root → child → holder (the prop) comes before body.
    assert_eq!(
        doc.influences[..3],
        [vec![(1, 1.0)], vec![(1, 1.0)], vec![(1, 1.0)]]
    );
    assert_eq!(doc.influences[3], vec![(0, 1.0)]);
    // At rest the prop's node (under the child at (0,1,0)) puts (1,0,0) at (1,1,0).
    assert_close(doc.mesh.positions[0], Vec3::new(1.0, 1.0, 0.0));
    // At t = 1 the child has turned 90°: (1,0,0) → (0,1,0), plus the head (0,1,0);
    // (0,0.5,0) → (−0.5,0,0) → (−0.5,1,0).
    let posed = doc.posed_mesh(Some(doc.clip("bend").unwrap()), 1.0);
    assert_close(posed.positions[0], Vec3::new(0.0, 2.0, 0.0));
    assert_close(posed.positions[2], Vec3::new(-0.5, 1.0, 0.0));
    assert_close(posed.positions[4], Vec3::new(-1.0, 2.0, 0.0)); // the body's child vertex
}

#[test]
fn unskinned_document_applies_node_transforms_and_sparse_positions() {
    let mut p = Packer::default();
    let pos = p.f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
    // Sparse: element 2 replaced by (0, 3, 0).
    let idx_view = p.u16s(&[2], "SCALAR");
    let val_view = p.f32s(&[0.0, 3.0, 0.0], "VEC3");
    let (iv, vv) = (
        p.accessors[idx_view]["bufferView"].clone(),
        p.accessors[val_view]["bufferView"].clone(),
    );
    p.accessors[pos]["sparse"] = json!({"count": 1,
        "indices": {"bufferView": iv, "componentType": 5123},
        "values": {"bufferView": vv}});
    let doc = json!({
        "scenes": [{"nodes": [0]}],
        "nodes": [{"children": [1], "scale": [2.0, 2.0, 2.0]},
                  {"mesh": 0, "translation": [0.0, 0.0, 1.0]}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": pos}}]}]
    });
    let doc = read(&p.gltf(doc), "static.gltf");
    assert!(doc.skin.is_none() && doc.influences.is_empty() && doc.clips.is_empty());
    // world = S(2)·T(0,0,1): (x, y, z) → 2·(x, y, z + 1)
    let want = [
        Vec3::new(0.0, 0.0, 2.0),
        Vec3::new(2.0, 0.0, 2.0),
        Vec3::new(0.0, 6.0, 2.0),
    ];
    assert_points(&doc.mesh.positions, &want);
    assert_eq!(doc.posed_mesh(None, 3.0), doc.mesh);
    assert!(doc.skin_matrices(None, 0.0).is_empty());
}

#[test]
fn clip_time_loops_scales_offsets_and_clamps() {
    let doc = read(
        &Rig {
            times: vec![1.0, 3.0],
            ..Rig::default()
        }
        .bytes(),
        "rig.gltf",
    );
    let clip = doc.clip("bend").unwrap();
    assert_eq!((clip.start, clip.end), (1.0, 3.0));
    let looping = ClipTime {
        speed: 2.0,
        looping: true,
        offset: 0.0,
    };
    let near = |a: f32, b: f32| assert!((a - b).abs() < 1e-5, "{a} vs {b}");
    near(looping.local(clip, 0.0), 1.0);
    near(looping.local(clip, 0.5), 2.0);
    near(looping.local(clip, 1.0), 1.0); // a full period wraps to the start
    near(looping.local(clip, 1.25), 1.5);
    near(looping.local(clip, -0.25), 2.5); // backwards wraps from the end
    let offset = ClipTime {
        speed: 1.0,
        looping: true,
        offset: 0.5,
    };
    near(offset.local(clip, 0.0), 1.5);
    near(offset.local(clip, 1.6), 1.1);
    let clamped = ClipTime {
        speed: 2.0,
        looping: false,
        offset: 0.0,
    };
    near(clamped.local(clip, 0.5), 2.0);
    near(clamped.local(clip, 5.0), 3.0);
    near(clamped.local(clip, -1.0), 1.0);
    assert_eq!(
        ClipTime::default(),
        ClipTime {
            speed: 1.0,
            looping: false,
            offset: 0.0
        }
    );
    let still = Rig {
        times: vec![2.0],
        rotations: vec![0.0, 0.0, 0.0, 1.0],
        ..Rig::default()
    };
    let still = read(&still.bytes(), "still.gltf");
    let clip = still.clip("bend").unwrap();
    assert_eq!((clip.start, clip.end), (2.0, 2.0));
    near(looping.local(clip, 5.3), 2.0);
}

// ---------------------------------------------------------------------------------------------
// Bad input: each message names the file and what was wrong.

#[test]
fn not_gltf_wrong_version_and_required_extensions_are_refused() {
    assert_has(
        &error(b"solid cube\nfacet normal 0 0 1", "cube.gltf"),
        &["cube.gltf", "not a glTF file", "glTF"],
    );
    assert_has(
        &error(br#"{"meshes": []}"#, "plain.json"),
        &["plain.json", "\"asset\""],
    );
    assert_has(
        &error(b"glTF\x01\0\0\0\x0c\0\0\0", "old.glb"),
        &["old.glb", "version 1", "expected 2"],
    );
    let (p, mut doc) = Rig::default().parts();
    doc["extensionsRequired"] = json!(["KHR_draco_mesh_compression", "KHR_materials_unlit"]);
    let mut bytes = p.gltf(doc);
    let e = error(&bytes, "draco.gltf");
    assert_has(
        &e,
        &[
            "draco.gltf",
            "KHR_draco_mesh_compression",
            "extensionsRequired",
        ],
    );
    assert!(
        !e.contains("KHR_materials_unlit"),
        "a looks-only extension was refused: {e}"
    );
    let mut v: Value = serde_json::from_slice(&bytes).unwrap();
    v["asset"]["version"] = json!("1.0");
    v.as_object_mut().unwrap().remove("extensionsRequired");
    bytes = serde_json::to_vec(&v).unwrap();
    assert_has(
        &error(&bytes, "v1.gltf"),
        &["v1.gltf", "\"1.0\"", "glTF 2.x"],
    );
}

#[test]
fn missing_external_bin_names_the_uri_and_the_path_tried() {
    let (p, doc) = Rig::default().parts();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("lonely.gltf");
    std::fs::write(&path, p.gltf_external(doc, "lonely.bin")).unwrap();
    let e = Document::load(&path).unwrap_err().to_string();
    let tried = dir.path().join("lonely.bin");
    assert_has(
        &e,
        &["lonely.gltf", "'lonely.bin'", &tried.display().to_string()],
    );
    let e = Document::load(&dir.path().join("absent.gltf"))
        .unwrap_err()
        .to_string();
    assert_has(&e, &["absent.gltf", "not found"]);
}

#[test]
fn buffers_shorter_than_their_views_or_accessors_are_refused() {
    let (mut p, doc) = Rig::default().parts();
    let last = p.views.len() - 1;
    p.views[last]["byteLength"] = json!(p.views[last]["byteLength"].as_u64().unwrap() + 64);
    let e = error(&p.gltf(doc), "short.gltf");
    assert_has(
        &e,
        &["short.gltf", &format!("buffer view {last}"), "holds only"],
    );

    let (p, doc) = Rig::default().parts();
    let mut v: Value = serde_json::from_slice(&p.gltf(doc)).unwrap();
    v["buffers"][0]["byteLength"] = json!(p.bin.len() + 8);
    let e = error(&serde_json::to_vec(&v).unwrap(), "declared.gltf");
    assert_has(&e, &["declared.gltf", "buffer 0", "byteLength"]);

    let (mut p, doc) = Rig::default().parts();
    p.accessors[0]["count"] = json!(100); // POSITION
    let e = error(&p.gltf(doc), "range.gltf");
    assert_has(
        &e,
        &[
            "range.gltf",
            "mesh 'body' primitive 0 POSITION (accessor 0)",
            "reads 100 elements",
        ],
    );
}

#[test]
fn bad_joints_and_weights_name_mesh_vertex_and_joint() {
    let mut rig = Rig::default();
    rig.joints[4] = 5; // vertex 1's first joint
    let e = error(&rig.bytes(), "joints.gltf");
    assert_has(
        &e,
        &[
            "joints.gltf",
            "mesh 'body'",
            "vertex 1",
            "joint 5",
            "skin 'rig' has 2 joints",
        ],
    );
    let mut rig = Rig::default();
    rig.weights[8..12].fill(0.0);
    let e = error(&rig.bytes(), "weights.gltf");
    assert_has(
        &e,
        &["weights.gltf", "mesh 'body'", "vertex 2", "sum to zero"],
    );
}

#[test]
fn bad_keyframes_name_the_animation_and_channel() {
    let e = error(
        &Rig {
            times: vec![0.0, f32::NAN],
            ..Rig::default()
        }
        .bytes(),
        "nan.gltf",
    );
    assert_has(
        &e,
        &[
            "nan.gltf",
            "animation 'bend' channel 0",
            "rotation of node 'child'",
            "NaN",
        ],
    );
    let e = error(
        &Rig {
            times: vec![0.5, 0.5],
            ..Rig::default()
        }
        .bytes(),
        "order.gltf",
    );
    assert_has(
        &e,
        &["order.gltf", "animation 'bend' channel 0", "must increase"],
    );
    let mut rig = Rig::default();
    rig.rotations[6] = f32::INFINITY;
    let e = error(&rig.bytes(), "inf.gltf");
    assert_has(
        &e,
        &["inf.gltf", "animation 'bend' channel 0", "not finite"],
    );
}

#[test]
fn non_triangle_modes_several_skins_and_loose_meshes_are_refused() {
    let e = error(
        &Rig {
            mode: 1,
            ..Rig::default()
        }
        .bytes(),
        "lines.gltf",
    );
    assert_has(
        &e,
        &[
            "lines.gltf",
            "mesh 'body' primitive 0",
            "Lines",
            "TRIANGLES",
        ],
    );

    let (p, mut doc) = Rig::default().parts();
    doc["skins"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "other", "joints": [1]}));
    doc["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "twin", "mesh": 0, "skin": 1}));
    doc["scenes"][0]["nodes"] = json!([0, 2, 3]);
    let e = error(&p.gltf(doc), "skins.gltf");
    assert_has(
        &e,
        &["skins.gltf", "skin 'rig'", "skin 'other'", "one skin"],
    );

    let (mut p, mut doc) = Rig::default().parts();
    let loose = p.f32s(&[0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0], "VEC3");
    doc["meshes"].as_array_mut().unwrap().push(json!(
        {"name": "rock", "primitives": [{"attributes": {"POSITION": loose}}]}));
    doc["nodes"]
        .as_array_mut()
        .unwrap()
        .push(json!({"name": "ground", "mesh": 1}));
    doc["scenes"][0]["nodes"] = json!([0, 2, 3]);
    let e = error(&p.gltf(doc), "loose.gltf");
    assert_has(
        &e,
        &["loose.gltf", "mesh 'rock' is not skinned", "node 'ground'"],
    );
}

#[test]
fn truncated_or_corrupted_files_give_errors_not_panics() {
    let (p, doc) = Rig::default().parts();
    for bytes in [p.glb(doc.clone()), p.gltf(doc)] {
        for cut in 0..bytes.len() {
            let _ = Document::from_slice(&bytes[..cut], Path::new("."), "cut.glb");
        }
        for i in 0..bytes.len() {
            let mut flipped = bytes.clone();
            flipped[i] ^= 0xA5;
            let _ = Document::from_slice(&flipped, Path::new("."), "flipped.glb");
        }
    }
    let e = error(&p.glb(json!({}))[..40], "cut.glb");
    assert_has(&e, &["cut.glb", "truncated GLB"]);
}
