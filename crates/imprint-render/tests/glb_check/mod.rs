//! What a GLB imprint writes must be, checked from its bytes: the container (magic, version,
//! total length, 4-byte chunks), the JSON's structure (asset 2.0, the buffer's byteLength,
//! every bufferView inside the buffer, every accessor inside its view, min/max present where
//! the spec requires them and equal to the data), then read with the `gltf` crate (which
//! checks every reference) into the frames a player shows at each animation key.
//!
//! Shared by imprint-render's GLB tests and the CLI's pipeline test (`#[path]`).

#![allow(dead_code)]

use serde_json::Value as Json;

/// A GLB that passed [`check`].
pub struct Glb {
    pub json: Json,
    pub bin: Vec<u8>,
    pub gltf: gltf::Gltf,
}

fn u32_at(b: &[u8], at: usize) -> u32 {
    u32::from_le_bytes(b[at..at + 4].try_into().unwrap())
}

/// Splits `bytes` into its chunks and checks everything listed above; panics naming the fault.
pub fn check(bytes: &[u8]) -> Glb {
    assert_eq!(&bytes[0..4], b"glTF", "magic");
    assert_eq!(u32_at(bytes, 4), 2, "container version");
    assert_eq!(
        u32_at(bytes, 8) as usize,
        bytes.len(),
        "header's total length"
    );
    let json_len = u32_at(bytes, 12) as usize;
    assert_eq!(&bytes[16..20], b"JSON", "first chunk");
    let bin_at = 20 + json_len;
    assert_eq!(&bytes[bin_at + 4..bin_at + 8], b"BIN\0", "second chunk");
    let bin_len = u32_at(bytes, bin_at) as usize;
    assert_eq!(bin_at + 8 + bin_len, bytes.len(), "chunks fill the file");
    assert!(
        json_len.is_multiple_of(4) && bin_len.is_multiple_of(4),
        "chunks padded to 4 bytes"
    );
    let json: Json = serde_json::from_slice(&bytes[20..bin_at]).expect("JSON chunk parses");
    let bin = bytes[bin_at + 8..].to_vec();
    assert_eq!(json["asset"]["version"], "2.0");
    let byte_length = json["buffers"][0]["byteLength"].as_u64().unwrap() as usize;
    assert!(
        byte_length <= bin_len && bin_len - byte_length < 4,
        "buffer byteLength"
    );
    check_views(&json, byte_length);
    check_accessors(&json, &bin);
    check_required_bounds(&json);
    let gltf = gltf::Gltf::from_slice(bytes).expect("the gltf crate reads and validates it");
    Glb { json, bin, gltf }
}

fn check_views(json: &Json, buffer_len: usize) {
    for (i, v) in json["bufferViews"].as_array().unwrap().iter().enumerate() {
        let offset = v["byteOffset"].as_u64().unwrap_or(0) as usize;
        let len = v["byteLength"].as_u64().unwrap() as usize;
        assert!(
            len > 0 && offset + len <= buffer_len,
            "bufferView {i} outside the buffer"
        );
        assert_eq!(offset % 4, 0, "bufferView {i} aligned");
    }
}

/// Every accessor inside its view; its min and max, when given, those of its data.
fn check_accessors(json: &Json, bin: &[u8]) {
    let views = json["bufferViews"].as_array().unwrap();
    for (i, a) in json["accessors"].as_array().unwrap().iter().enumerate() {
        let comp = match a["componentType"].as_u64().unwrap() {
            5126 | 5125 => 4,
            5123 | 5122 => 2,
            _ => 1,
        };
        let width = match a["type"].as_str().unwrap() {
            "SCALAR" => 1,
            "VEC2" => 2,
            "VEC3" => 3,
            "VEC4" => 4,
            t => panic!("accessor {i}: unexpected type {t}"),
        };
        let count = a["count"].as_u64().unwrap() as usize;
        let view = &views[a["bufferView"].as_u64().unwrap() as usize];
        let at = a["byteOffset"].as_u64().unwrap_or(0) as usize;
        let view_len = view["byteLength"].as_u64().unwrap() as usize;
        assert!(count > 0, "accessor {i}: count");
        assert!(
            at + count * width * comp <= view_len,
            "accessor {i} outside its view"
        );
        if let (Some(min), Some(max)) = (a.get("min"), a.get("max")) {
            assert_eq!(
                a["componentType"], 5126,
                "accessor {i}: bounds checked on floats"
            );
            let start = view["byteOffset"].as_u64().unwrap_or(0) as usize + at;
            let data: Vec<f32> = bin[start..start + 4 * count * width]
                .chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().unwrap()))
                .collect();
            for c in 0..width {
                let col = data.iter().skip(c).step_by(width).copied();
                let lo = col.clone().fold(f32::INFINITY, f32::min);
                let hi = col.fold(f32::NEG_INFINITY, f32::max);
                assert_eq!(min[c].as_f64().unwrap() as f32, lo, "accessor {i} min[{c}]");
                assert_eq!(max[c].as_f64().unwrap() as f32, hi, "accessor {i} max[{c}]");
            }
        }
    }
}

/// The spec requires min and max on POSITION accessors (of primitives and morph targets) and
/// on animation sampler inputs.
fn check_required_bounds(json: &Json) {
    let accessors = json["accessors"].as_array().unwrap();
    let bounded = |i: &Json, what: &str| {
        let a = &accessors[i.as_u64().unwrap() as usize];
        assert!(
            a.get("min").is_some() && a.get("max").is_some(),
            "{what}: min/max"
        );
    };
    for m in json["meshes"].as_array().unwrap() {
        for p in m["primitives"].as_array().unwrap() {
            bounded(&p["attributes"]["POSITION"], "POSITION");
            for t in p["targets"].as_array().into_iter().flatten() {
                bounded(&t["POSITION"], "morph target POSITION");
            }
        }
    }
    for anim in json["animations"].as_array().into_iter().flatten() {
        for s in anim["samplers"].as_array().unwrap() {
            bounded(&s["input"], "animation input");
            assert_eq!(s["interpolation"], "STEP");
        }
    }
}

/// What one mesh of the file holds: base positions, indices, morph target deltas.
struct MeshData {
    positions: Vec<[f32; 3]>,
    indices: Vec<u32>,
    deltas: Vec<Vec<[f32; 3]>>,
}

fn mesh_data(glb: &Glb, mesh: gltf::Mesh<'_>) -> MeshData {
    let blob = glb.bin.as_slice();
    let prim = mesh.primitives().next().expect("a primitive");
    assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
    let r = prim.reader(|_| Some(blob));
    MeshData {
        positions: r.read_positions().expect("positions").collect(),
        indices: r.read_indices().expect("indices").into_u32().collect(),
        deltas: r
            .read_morph_targets()
            .map(|(p, _, _)| p.expect("target positions").collect())
            .collect(),
    }
}

/// One frame as a player shows it: its time, its triangles as corner positions.
pub struct Frame {
    pub time: f32,
    pub triangles: Vec<[[f32; 3]; 3]>,
}

fn corners(positions: &[[f32; 3]], indices: &[u32]) -> Vec<[[f32; 3]; 3]> {
    indices
        .chunks_exact(3)
        .map(|t| [0, 1, 2].map(|c| positions[t[c] as usize]))
        .collect()
}

/// The frames shown at each animation key (one frame at time 0 when there is no animation):
/// a morphed mesh's base plus the key's weighted deltas, or the one mesh whose node's STEP
/// scale is 1 at that key.
pub fn frames(glb: &Glb) -> Vec<Frame> {
    let doc = &glb.gltf.document;
    let Some(anim) = doc.animations().next() else {
        let m = mesh_data(glb, doc.meshes().next().unwrap());
        return vec![Frame {
            time: 0.0,
            triangles: corners(&m.positions, &m.indices),
        }];
    };
    let blob = glb.bin.as_slice();
    let channels: Vec<_> = anim.channels().collect();
    if channels[0].target().property() == gltf::animation::Property::MorphTargetWeights {
        assert_eq!(channels.len(), 1);
        morph_frames(glb, &channels[0], blob)
    } else {
        visible_frames(glb, &channels, blob)
    }
}

fn morph_frames(glb: &Glb, ch: &gltf::animation::Channel<'_>, blob: &[u8]) -> Vec<Frame> {
    let r = ch.reader(|_| Some(blob));
    let times: Vec<f32> = r.read_inputs().unwrap().collect();
    let Some(gltf::animation::util::ReadOutputs::MorphTargetWeights(
        gltf::animation::util::MorphTargetWeights::F32(w),
    )) = r.read_outputs()
    else {
        panic!("weights as floats");
    };
    let weights: Vec<f32> = w.collect();
    let m = mesh_data(
        glb,
        ch.target()
            .node()
            .mesh()
            .expect("the animated node has the mesh"),
    );
    let n = m.deltas.len();
    assert_eq!(
        weights.len(),
        n * times.len(),
        "one weight per target per key"
    );
    times
        .iter()
        .enumerate()
        .map(|(k, &time)| {
            let mut pos = m.positions.clone();
            for (j, d) in m.deltas.iter().enumerate() {
                let w = weights[k * n + j];
                for (p, d) in pos.iter_mut().zip(d) {
                    for c in 0..3 {
                        p[c] += w * d[c];
                    }
                }
            }
            Frame {
                time,
                triangles: corners(&pos, &m.indices),
            }
        })
        .collect()
}

/// STEP-sampled scale of one channel at `t`: the value of the last key at or before `t`
/// (the node's own scale before the first key).
fn scale_at(ch: &gltf::animation::Channel<'_>, blob: &[u8], t: f32) -> f32 {
    let r = ch.reader(|_| Some(blob));
    let times: Vec<f32> = r.read_inputs().unwrap().collect();
    let Some(gltf::animation::util::ReadOutputs::Scales(s)) = r.read_outputs() else {
        panic!("scales");
    };
    let scales: Vec<[f32; 3]> = s.collect();
    match times.iter().rposition(|&k| k <= t) {
        Some(i) => scales[i][0],
        None => ch.target().node().transform().decomposed().2[0],
    }
}

fn visible_frames(glb: &Glb, channels: &[gltf::animation::Channel<'_>], blob: &[u8]) -> Vec<Frame> {
    let mut times: Vec<f32> = Vec::new();
    for ch in channels {
        assert_eq!(ch.target().property(), gltf::animation::Property::Scale);
        times.extend(ch.reader(|_| Some(blob)).read_inputs().unwrap());
    }
    times.sort_by(f32::total_cmp);
    times.dedup();
    times
        .into_iter()
        .map(|time| {
            let shown: Vec<_> = channels
                .iter()
                .filter(|c| scale_at(c, blob, time) != 0.0)
                .collect();
            assert_eq!(shown.len(), 1, "one frame visible at t = {time}");
            assert_eq!(scale_at(shown[0], blob, time), 1.0);
            let m = mesh_data(glb, shown[0].target().node().mesh().unwrap());
            Frame {
                time,
                triangles: corners(&m.positions, &m.indices),
            }
        })
        .collect()
}
