//! Mesh files: Wavefront OBJ (text) and binary little-endian PLY, one per frame, and a whole
//! run's frames as one animated glTF binary ([`MeshSequence`], [`write_glb`]), all written
//! through [`atomic_write`] (a reader never finds a half-written file under its final name).
//!
//! Floats are written with Rust's `{}` Display for f32, which prints the shortest decimal that
//! parses back to the same f32, so positions, normals and uvs round-trip bit-exactly.
//! Non-finite values are refused (the write fails and no file appears).

use imprint_core::glam::{Vec2, Vec3};
use imprint_core::io::{atomic_write, atomic_write_bytes};
use imprint_core::{Error, Mesh, Result};
use serde::{Deserialize, Serialize};
use serde_json::{Value as Json, json};
use std::collections::HashMap;
use std::io::Error as IoError;
use std::path::Path;

/// What an OBJ file carries besides positions and faces.
#[derive(Clone, Debug)]
pub struct ObjOptions {
    /// Write `vn` lines (when the mesh has one normal per vertex).
    pub normals: bool,
    /// Write `vt` lines (when the mesh has one uv per vertex).
    pub uvs: bool,
    /// A `#` comment line at the top (e.g. the node and frame); none when empty.
    pub comment: String,
}

impl Default for ObjOptions {
    fn default() -> Self {
        ObjOptions {
            normals: true,
            uvs: true,
            comment: String::new(),
        }
    }
}

fn non_finite(what: &str, index: usize) -> IoError {
    IoError::new(
        std::io::ErrorKind::InvalidData,
        format!("{what} {index} is not finite; nothing written"),
    )
}

/// Writes `mesh` as OBJ: `v x y z`, then `vt u v` and `vn x y z` where the mesh has them (and
/// `opts` asks for them), then one `f` per triangle with 1-based indices in the form that
/// matches: `f a b c`, `f a/a b/b c/c` (uvs), `f a//a ...` (normals) or `f a/a/a ...` (both).
pub fn write_obj(path: &Path, mesh: &Mesh, opts: &ObjOptions) -> Result<()> {
    let n = mesh.positions.len();
    let normals = opts.normals && mesh.normals.len() == n && n > 0;
    let uvs = match &mesh.uvs {
        Some(uv) if opts.uvs && uv.len() == n && n > 0 => Some(uv.as_slice()),
        _ => None,
    };
    atomic_write(path, |w| {
        for line in opts.comment.lines() {
            writeln!(w, "# {line}")?;
        }
        writeln!(
            w,
            "# imprint: {} vertices, {} triangles",
            n,
            mesh.triangles.len()
        )?;
        for (j, p) in mesh.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(non_finite("position", j));
            }
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
        if let Some(uvs) = uvs {
            for (j, t) in uvs.iter().enumerate() {
                if !t.is_finite() {
                    return Err(non_finite("uv", j));
                }
                writeln!(w, "vt {} {}", t.x, t.y)?;
            }
        }
        if normals {
            for (j, v) in mesh.normals.iter().enumerate() {
                if !v.is_finite() {
                    return Err(non_finite("normal", j));
                }
                writeln!(w, "vn {} {} {}", v.x, v.y, v.z)?;
            }
        }
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if tri.iter().any(|&i| i as usize >= n) {
                return Err(IoError::new(
                    std::io::ErrorKind::InvalidData,
                    format!("triangle {t} indexes past the {n} vertices; nothing written"),
                ));
            }
            let [a, b, c] = tri.map(|i| i as u64 + 1);
            match (uvs.is_some(), normals) {
                (false, false) => writeln!(w, "f {a} {b} {c}")?,
                (true, false) => writeln!(w, "f {a}/{a} {b}/{b} {c}/{c}")?,
                (false, true) => writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?,
                (true, true) => writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?,
            }
        }
        Ok(())
    })
}

/// The PLY header [`write_ply`] writes for `vertices` vertices (with normals or not) and
/// `faces` triangles.
pub fn ply_header(vertices: usize, faces: usize, normals: bool) -> String {
    let mut h = String::from("ply\nformat binary_little_endian 1.0\ncomment written by imprint\n");
    h += &format!("element vertex {vertices}\n");
    h += "property float x\nproperty float y\nproperty float z\n";
    if normals {
        h += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    h += &format!("element face {faces}\n");
    h += "property list uchar uint vertex_indices\nend_header\n";
    h
}

/// Writes `mesh` as binary little-endian PLY: per vertex x y z (and nx ny nz when the mesh has
/// one normal per vertex) as f32, per face a `uchar` count (3) and three `uint` indices.
pub fn write_ply(path: &Path, mesh: &Mesh) -> Result<()> {
    let n = mesh.positions.len();
    let normals = mesh.normals.len() == n && n > 0;
    atomic_write(path, |w| {
        w.write_all(ply_header(n, mesh.triangles.len(), normals).as_bytes())?;
        for (j, p) in mesh.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(non_finite("position", j));
            }
            let mut rec = [0u8; 24];
            for (c, v) in p.to_array().into_iter().enumerate() {
                rec[4 * c..4 * c + 4].copy_from_slice(&v.to_le_bytes());
            }
            if normals {
                let v = mesh.normals[j];
                if !v.is_finite() {
                    return Err(non_finite("normal", j));
                }
                for (c, v) in v.to_array().into_iter().enumerate() {
                    rec[12 + 4 * c..16 + 4 * c].copy_from_slice(&v.to_le_bytes());
                }
                w.write_all(&rec)?;
            } else {
                w.write_all(&rec[..12])?;
            }
        }
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if tri.iter().any(|&i| i as usize >= n) {
                return Err(IoError::new(
                    std::io::ErrorKind::InvalidData,
                    format!("triangle {t} indexes past the {n} vertices; nothing written"),
                ));
            }
            let mut rec = [3u8; 13];
            for (c, i) in tri.iter().enumerate() {
                rec[1 + 4 * c..5 + 4 * c].copy_from_slice(&i.to_le_bytes());
            }
            w.write_all(&rec)?;
        }
        Ok(())
    })
}

/// A mesh's frames, kept for one whole-run file ([`write_glb`]): every frame's positions (and
/// normals), and the distinct topologies (triangles and uvs) once each, so a deforming mesh
/// holds its triangles once however many frames it has. Serialisable, so a checkpoint keeps
/// the frames written so far and a resumed run's file holds them all.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MeshSequence {
    frames: Vec<SequenceFrame>,
    topologies: Vec<Topology>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct SequenceFrame {
    frame: u32,
    /// Index into [`MeshSequence::topologies`].
    topology: usize,
    positions: Vec<Vec3>,
    /// One per vertex, or empty when the mesh had none.
    normals: Vec<Vec3>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Topology {
    vertices: usize,
    triangles: Vec<[u32; 3]>,
    uvs: Option<Vec<Vec2>>,
}

impl MeshSequence {
    /// Adds `mesh` as frame `frame`. Frames at or after `frame` are dropped first, so a run
    /// that steps back (a seek, a restored checkpoint) and forward again keeps one copy of
    /// each frame, in order. A mesh the file could not hold (no triangles, a non-finite
    /// coordinate, an index past the vertices) is refused here, at the frame that has it.
    pub fn push(&mut self, frame: u32, mesh: &Mesh) -> Result<()> {
        check_for_glb(frame, mesh)?;
        self.frames.retain(|f| f.frame < frame);
        let kept = self.frames.last().map_or(0, |f| f.topology + 1);
        self.topologies.truncate(kept);
        let uvs = mesh.uvs.clone().filter(|u| u.len() == mesh.positions.len());
        let topology = Topology {
            vertices: mesh.positions.len(),
            triangles: mesh.triangles.clone(),
            uvs,
        };
        if self.topologies.last() != Some(&topology) {
            self.topologies.push(topology);
        }
        let normals = if mesh.normals.len() == mesh.positions.len() {
            mesh.normals.clone()
        } else {
            Vec::new()
        };
        self.frames.push(SequenceFrame {
            frame,
            topology: self.topologies.len() - 1,
            positions: mesh.positions.clone(),
            normals,
        });
        Ok(())
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The frame numbers held, in order.
    pub fn frame_numbers(&self) -> Vec<u32> {
        self.frames.iter().map(|f| f.frame).collect()
    }

    /// Whether every frame has the same triangles (and vertex count and uvs): the file then
    /// animates one mesh by morph targets.
    pub fn shares_topology(&self) -> bool {
        self.topologies.len() <= 1
    }

    /// Each frame's animation time, s: `(frame - first frame) / fps`, so the file plays from 0
    /// whatever frame the run started at.
    fn times(&self, fps: f32) -> Vec<f32> {
        let first = self.frames.first().map_or(0, |f| f.frame);
        self.frames
            .iter()
            .map(|f| (f.frame - first) as f32 / fps)
            .collect()
    }
}

/// What a glTF file needs of a frame's mesh.
fn check_for_glb(frame: u32, mesh: &Mesh) -> Result<()> {
    let bad = |what: String| {
        Err(Error::Invalid(format!(
            "frame {frame}: {what}; no GLB frame kept"
        )))
    };
    if mesh.triangles.is_empty() {
        return bad("the mesh has no triangles".into());
    }
    let finite = |v: &[Vec3]| v.iter().position(|p| !p.is_finite());
    if let Some(j) = finite(&mesh.positions) {
        return bad(format!("position {j} is not finite"));
    }
    if let Some(j) = finite(&mesh.normals) {
        return bad(format!("normal {j} is not finite"));
    }
    if let Some(uvs) = &mesh.uvs
        && let Some(j) = uvs.iter().position(|t| !t.is_finite())
    {
        return bad(format!("uv {j} is not finite"));
    }
    let n = mesh.positions.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&i| i as usize >= n))
    {
        return bad(format!("triangle {t} indexes past the {n} vertices"));
    }
    Ok(())
}

/// Writes `seq` as one glTF 2.0 binary (`.glb`) that Blender and three.js play at `fps`;
/// `name` names the scene's node, mesh and animation.
///
/// - Every frame with the same triangles (a moving or deforming mesh): one mesh whose base is
///   frame 0 and one morph target per frame (position deltas from frame 0, and normal deltas
///   when every frame has normals), animated by a `weights` channel with STEP interpolation,
///   one key per frame at `(frame - first) / fps`, the key's weights one-hot on its frame.
/// - Triangles that change: one node per frame under a root node, each with its own mesh
///   (index buffers shared between frames with the same triangles), shown by a STEP `scale`
///   animation: scale 1 from its frame's time to the next frame's, 0 otherwise.
/// - One frame: the mesh alone, no animation.
///
/// The file is rebuilt whole, in memory, on every call: its size is about the frames'
/// vertices × 12 bytes (× 2 with normals). Atomic: a failed write leaves the previous file.
pub fn write_glb(path: &Path, seq: &MeshSequence, fps: f32, name: &str) -> Result<()> {
    atomic_write_bytes(path, &glb_bytes(seq, fps, name)?)
}

/// The bytes [`write_glb`] writes.
pub fn glb_bytes(seq: &MeshSequence, fps: f32, name: &str) -> Result<Vec<u8>> {
    if seq.is_empty() {
        return Err(Error::Invalid(format!("GLB '{name}': no frames to write")));
    }
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::Invalid(format!(
            "GLB '{name}': fps {fps} is not positive"
        )));
    }
    let mut b = GlbBuilder::default();
    let mut doc = if seq.len() == 1 {
        static_document(seq, name, &mut b)
    } else if seq.shares_topology() {
        morph_document(seq, fps, name, &mut b)
    } else {
        node_per_frame_document(seq, fps, name, &mut b)
    };
    doc["asset"] = json!({"version": "2.0", "generator": "imprint"});
    doc["buffers"] = json!([{"byteLength": b.bin.len()}]);
    doc["bufferViews"] = Json::Array(std::mem::take(&mut b.views));
    doc["accessors"] = Json::Array(std::mem::take(&mut b.accessors));
    glb_container(&doc, &b.bin, name)
}

const ARRAY_BUFFER: u32 = 34962;
const ELEMENT_ARRAY_BUFFER: u32 = 34963;
const FLOAT: u32 = 5126;
const UNSIGNED_INT: u32 = 5125;
const TRIANGLES: u32 = 4;

/// The binary chunk and the JSON arrays that describe it, built side by side: each accessor
/// gets its own tightly packed bufferView, 4-byte aligned (every component here is 4 bytes).
#[derive(Default)]
struct GlbBuilder {
    bin: Vec<u8>,
    views: Vec<Json>,
    accessors: Vec<Json>,
}

impl GlbBuilder {
    /// Appends `values` (little-endian 4-byte words, `width` per element of glTF type `ty`) as a
    /// bufferView and an accessor over it; returns the accessor's index. `bounds` adds the
    /// per-component min and max (the spec requires them for POSITION and animation inputs).
    fn accessor(
        &mut self,
        words: &[[u8; 4]],
        component: u32,
        ty: &str,
        width: usize,
        target: Option<u32>,
        bounds: Option<(Vec<f32>, Vec<f32>)>,
    ) -> usize {
        let offset = self.bin.len();
        self.bin.extend(words.iter().flatten());
        let mut view = json!({"buffer": 0, "byteOffset": offset, "byteLength": 4 * words.len()});
        if let Some(t) = target {
            view["target"] = json!(t);
        }
        self.views.push(view);
        let mut acc = json!({
            "bufferView": self.views.len() - 1,
            "componentType": component,
            "count": words.len() / width,
            "type": ty,
        });
        if let Some((min, max)) = bounds {
            acc["min"] = json!(min);
            acc["max"] = json!(max);
        }
        self.accessors.push(acc);
        self.accessors.len() - 1
    }

    /// VEC3 floats, with their bounds.
    fn vec3(&mut self, v: &[Vec3], target: Option<u32>) -> usize {
        let words: Vec<[u8; 4]> = v
            .iter()
            .flat_map(|p| p.to_array())
            .map(f32::to_le_bytes)
            .collect();
        let (min, max) = v.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let bounds = (min.to_array().to_vec(), max.to_array().to_vec());
        self.accessor(&words, FLOAT, "VEC3", 3, target, Some(bounds))
    }

    fn vec2(&mut self, v: &[Vec2]) -> usize {
        let words: Vec<[u8; 4]> = v
            .iter()
            .flat_map(|p| p.to_array())
            .map(f32::to_le_bytes)
            .collect();
        self.accessor(&words, FLOAT, "VEC2", 2, Some(ARRAY_BUFFER), None)
    }

    /// SCALAR floats (animation times and weights), with their bounds.
    fn scalars(&mut self, v: &[f32]) -> usize {
        let words: Vec<[u8; 4]> = v.iter().map(|x| x.to_le_bytes()).collect();
        let min = v.iter().copied().fold(f32::INFINITY, f32::min);
        let max = v.iter().copied().fold(f32::NEG_INFINITY, f32::max);
        self.accessor(
            &words,
            FLOAT,
            "SCALAR",
            1,
            None,
            Some((vec![min], vec![max])),
        )
    }

    fn indices(&mut self, triangles: &[[u32; 3]]) -> usize {
        let words: Vec<[u8; 4]> = triangles
            .iter()
            .flatten()
            .map(|i| i.to_le_bytes())
            .collect();
        self.accessor(
            &words,
            UNSIGNED_INT,
            "SCALAR",
            1,
            Some(ELEMENT_ARRAY_BUFFER),
            None,
        )
    }

    /// A triangle primitive of one frame: positions, normals with `normals` (the frame must
    /// have them), uvs when its topology has them, and `indices` (an accessor already written).
    fn primitive(
        &mut self,
        f: &SequenceFrame,
        topology: &Topology,
        indices: usize,
        normals: bool,
    ) -> Json {
        let mut attributes = json!({"POSITION": self.vec3(&f.positions, Some(ARRAY_BUFFER))});
        if normals {
            attributes["NORMAL"] = json!(self.vec3(&f.normals, Some(ARRAY_BUFFER)));
        }
        if let Some(uvs) = &topology.uvs {
            attributes["TEXCOORD_0"] = json!(self.vec2(uvs));
        }
        json!({"attributes": attributes, "indices": indices, "mode": TRIANGLES})
    }
}

/// `frame_0012` for frame 12: the names of morph targets and per-frame nodes.
fn frame_name(frame: u32) -> String {
    format!("frame_{frame:04}")
}

/// One frame: a node and its mesh.
fn static_document(seq: &MeshSequence, name: &str, b: &mut GlbBuilder) -> Json {
    let f = &seq.frames[0];
    let topology = &seq.topologies[f.topology];
    let indices = b.indices(&topology.triangles);
    let primitive = b.primitive(f, topology, indices, !f.normals.is_empty());
    json!({
        "scene": 0,
        "scenes": [{"name": name, "nodes": [0]}],
        "nodes": [{"name": name, "mesh": 0}],
        "meshes": [{"name": name, "primitives": [primitive]}],
    })
}

/// One mesh, frame 0 its base, a morph target per frame, a STEP `weights` animation.
fn morph_document(seq: &MeshSequence, fps: f32, name: &str, b: &mut GlbBuilder) -> Json {
    let base = &seq.frames[0];
    let topology = &seq.topologies[0];
    let indices = b.indices(&topology.triangles);
    // Normals only when every frame has them: base normals without target deltas would
    // shade every frame like frame 0.
    let normals = seq.frames.iter().all(|f| !f.normals.is_empty());
    let mut primitive = b.primitive(base, topology, indices, normals);
    primitive["targets"] = Json::Array(morph_targets(seq, normals, b));
    let n = seq.len();
    let one_hot = |k: usize| (0..n).map(move |j| if j == k { 1.0 } else { 0.0 });
    let input = b.scalars(&seq.times(fps));
    let output = b.scalars(&(0..n).flat_map(one_hot).collect::<Vec<f32>>());
    let names: Vec<String> = seq.frames.iter().map(|f| frame_name(f.frame)).collect();
    json!({
        "scene": 0,
        "scenes": [{"name": name, "nodes": [0]}],
        "nodes": [{"name": name, "mesh": 0}],
        "meshes": [{
            "name": name,
            "primitives": [primitive],
            "weights": one_hot(0).collect::<Vec<f32>>(),
            "extras": {"targetNames": names},
        }],
        "animations": [{
            "name": name,
            "samplers": [{"input": input, "output": output, "interpolation": "STEP"}],
            "channels": [{"sampler": 0, "target": {"node": 0, "path": "weights"}}],
        }],
    })
}

/// One morph target per frame: its position deltas from frame 0, and its normal deltas with
/// `normals`.
fn morph_targets(seq: &MeshSequence, normals: bool, b: &mut GlbBuilder) -> Vec<Json> {
    let base = &seq.frames[0];
    let delta = |a: &[Vec3], b: &[Vec3]| a.iter().zip(b).map(|(p, q)| *p - *q).collect::<Vec<_>>();
    seq.frames
        .iter()
        .map(|f| {
            let moved = delta(&f.positions, &base.positions);
            let mut target = json!({"POSITION": b.vec3(&moved, Some(ARRAY_BUFFER))});
            if normals {
                let turned = delta(&f.normals, &base.normals);
                target["NORMAL"] = json!(b.vec3(&turned, Some(ARRAY_BUFFER)));
            }
            target
        })
        .collect()
}

/// A root node with one child per frame, each shown only during its frame by a STEP `scale`
/// animation ([`visibility_sampler`]).
fn node_per_frame_document(seq: &MeshSequence, fps: f32, name: &str, b: &mut GlbBuilder) -> Json {
    let times = seq.times(fps);
    let n = seq.len();
    let mut indices_of: HashMap<usize, usize> = HashMap::new();
    let (mut meshes, mut nodes, mut samplers, mut channels) = (vec![], vec![], vec![], vec![]);
    nodes.push(json!({"name": name, "children": (1..=n).collect::<Vec<_>>()}));
    for (k, f) in seq.frames.iter().enumerate() {
        let topology = &seq.topologies[f.topology];
        let indices = *indices_of
            .entry(f.topology)
            .or_insert_with(|| b.indices(&topology.triangles));
        let primitive = b.primitive(f, topology, indices, !f.normals.is_empty());
        meshes.push(json!({"name": frame_name(f.frame), "primitives": [primitive]}));
        let shown = if k == 0 { 1.0 } else { 0.0 };
        nodes.push(json!({"name": frame_name(f.frame), "mesh": k, "scale": [shown, shown, shown]}));
        samplers.push(visibility_sampler(&times, k, b));
        channels.push(json!({"sampler": k, "target": {"node": k + 1, "path": "scale"}}));
    }
    json!({
        "scene": 0,
        "scenes": [{"name": name, "nodes": [0]}],
        "nodes": nodes,
        "meshes": meshes,
        "animations": [{"name": name, "samplers": samplers, "channels": channels}],
    })
}

/// The STEP `scale` sampler that shows frame `k` of those at `times` during its frame only:
/// keys 0 at the start (unless it is the first), 1 at its time, 0 at the next frame's time
/// (unless it is the last).
fn visibility_sampler(times: &[f32], k: usize, b: &mut GlbBuilder) -> Json {
    let mut keys = Vec::new();
    if k > 0 {
        keys.push((times[0], 0.0));
    }
    keys.push((times[k], 1.0));
    if let Some(&next) = times.get(k + 1) {
        keys.push((next, 0.0));
    }
    let input = b.scalars(&keys.iter().map(|k| k.0).collect::<Vec<_>>());
    let scales: Vec<Vec3> = keys.iter().map(|k| Vec3::splat(k.1)).collect();
    let output = b.vec3(&scales, None);
    json!({"input": input, "output": output, "interpolation": "STEP"})
}

/// The GLB container: a 12-byte header, the JSON chunk padded with spaces and the BIN chunk
/// padded with zeros, each to 4 bytes.
fn glb_container(doc: &Json, bin: &[u8], name: &str) -> Result<Vec<u8>> {
    let mut json = serde_json::to_vec(doc).expect("plain data");
    json.resize(json.len().next_multiple_of(4), b' ');
    let mut bin = bin.to_vec();
    bin.resize(bin.len().next_multiple_of(4), 0);
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let total32 = u32::try_from(total).map_err(|_| {
        Error::Invalid(format!(
            "GLB '{name}' would be {} but a GLB holds at most 4 GiB: write fewer frames \
             (every: k) or format Obj/Ply",
            imprint_core::error::human_bytes(total as u64)
        ))
    })?;
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&total32.to_le_bytes());
    for (kind, data) in [(b"JSON", &json), (b"BIN\0", &bin)] {
        out.extend_from_slice(&(data.len() as u32).to_le_bytes());
        out.extend_from_slice(kind);
        out.extend_from_slice(data);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::glam::{Vec2, Vec3};
    use imprint_core::mesh::primitives;

    fn bits(v: Vec3) -> [u32; 3] {
        v.to_array().map(f32::to_bits)
    }

    #[test]
    fn display_of_f32_round_trips_bit_exactly() {
        // A deterministic spread of bit patterns: every exponent, scrambled mantissas.
        let mut x: u32 = 0x1234_5678;
        let mut checked = 0;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let f = f32::from_bits(x);
            if !f.is_finite() {
                continue;
            }
            let back: f32 = format!("{f}").parse().unwrap();
            assert_eq!(back.to_bits(), f.to_bits(), "{f:e} printed as {f}");
            checked += 1;
        }
        for f in [
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::EPSILON,
            1e-45,
            -0.0,
            0.1,
            1.0 / 3.0,
        ] {
            let back: f32 = format!("{f}").parse().unwrap();
            assert_eq!(back.to_bits(), f.to_bits());
        }
        assert!(checked > 100_000);
    }

    /// A mesh whose faces reference vertices in order of first use, so a reader that
    /// renumbers vertices by first use (tobj with `single_index`) keeps the numbering.
    fn ordered_mesh() -> Mesh {
        let mut m = primitives::plane(1.0, 3);
        // Awkward values that need many digits.
        for (j, p) in m.positions.iter_mut().enumerate() {
            p.y = (j as f32 * 0.1 + 1.0 / 3.0).sin() * 1e-3 + f32::EPSILON;
            p.x *= std::f32::consts::PI;
        }
        m.compute_normals();
        let n = m.positions.len();
        m.uvs = Some(
            (0..n)
                .map(|j| Vec2::new(j as f32 / 7.0, 1.0 - j as f32 / 11.0))
                .collect(),
        );
        // Renumber vertices by first use in the faces.
        let mut map = vec![u32::MAX; n];
        let mut order = Vec::new();
        for t in &mut m.triangles {
            for i in t.iter_mut() {
                if map[*i as usize] == u32::MAX {
                    map[*i as usize] = order.len() as u32;
                    order.push(*i as usize);
                }
                *i = map[*i as usize];
            }
        }
        let uvs = m.uvs.as_ref().unwrap();
        Mesh {
            positions: order.iter().map(|&j| m.positions[j]).collect(),
            triangles: m.triangles.clone(),
            normals: order.iter().map(|&j| m.normals[j]).collect(),
            uvs: Some(order.iter().map(|&j| uvs[j]).collect()),
        }
    }

    #[test]
    fn obj_round_trips_bit_exactly_through_load_obj() {
        let dir = tempfile::tempdir().unwrap();
        let m = ordered_mesh();
        for (normals, uvs) in [(true, true), (true, false), (false, true), (false, false)] {
            let path = dir.path().join(format!("m_{normals}_{uvs}.obj"));
            let opts = ObjOptions {
                normals,
                uvs,
                comment: "frame 3".into(),
            };
            write_obj(&path, &m, &opts).unwrap();
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text.starts_with("# frame 3\n"));
            assert_eq!(text.contains("\nvn "), normals);
            assert_eq!(text.contains("\nvt "), uvs);
            let back = Mesh::load_obj(&path).unwrap();
            assert_eq!(back.triangles, m.triangles);
            assert_eq!(back.positions.len(), m.positions.len());
            for (a, b) in back.positions.iter().zip(&m.positions) {
                assert_eq!(bits(*a), bits(*b));
            }
            if normals {
                // load_obj normalises normals: unit normals come back within an ulp or so.
                for (a, b) in back.normals.iter().zip(&m.normals) {
                    assert!((*a - *b).length() < 1e-6);
                }
            }
            if uvs {
                let (a, b) = (back.uvs.unwrap(), m.uvs.clone().unwrap());
                assert_eq!(a.len(), b.len());
                for (a, b) in a.iter().zip(&b) {
                    assert_eq!(
                        a.to_array().map(f32::to_bits),
                        b.to_array().map(f32::to_bits)
                    );
                }
            } else {
                assert!(back.uvs.is_none());
            }
        }
    }

    #[test]
    fn obj_of_a_general_mesh_keeps_every_triangle_corner() {
        // uv_sphere's faces do not use vertices in order; compare corners, not numbering.
        let m = primitives::uv_sphere(1.3, 12, 7);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.obj");
        write_obj(&path, &m, &ObjOptions::default()).unwrap();
        let back = Mesh::load_obj(&path).unwrap();
        assert_eq!(back.triangles.len(), m.triangles.len());
        for t in 0..m.triangles.len() {
            let (a, b) = (m.triangle(t), back.triangle(t));
            for c in 0..3 {
                assert_eq!(bits(a[c]), bits(b[c]));
            }
        }
    }

    #[test]
    fn ply_header_and_length_are_exact() {
        let m = primitives::cuboid(Vec3::new(1.0, 2.0, 0.5), 2);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ply");
        write_ply(&path, &m).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (nv, nf) = (m.positions.len(), m.triangles.len());
        let header = format!(
            "ply\nformat binary_little_endian 1.0\ncomment written by imprint\n\
             element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n\
             element face {nf}\nproperty list uchar uint vertex_indices\nend_header\n"
        );
        assert!(bytes.starts_with(header.as_bytes()));
        let body = &bytes[header.len()..];
        assert_eq!(body.len(), nv * 24 + nf * 13);
        // First vertex and first face decode back.
        let f = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().unwrap());
        assert_eq!(Vec3::new(f(0), f(4), f(8)), m.positions[0]);
        assert_eq!(Vec3::new(f(12), f(16), f(20)), m.normals[0]);
        let face = &body[nv * 24..nv * 24 + 13];
        assert_eq!(face[0], 3);
        let idx = |o: usize| u32::from_le_bytes(face[o..o + 4].try_into().unwrap());
        assert_eq!([idx(1), idx(5), idx(9)], m.triangles[0]);

        // Without normals: 12 bytes per vertex, no normal properties.
        let mut bare = m.clone();
        bare.normals.clear();
        write_ply(&path, &bare).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let header = ply_header(nv, nf, false);
        assert!(!header.contains("nx"));
        assert!(bytes.starts_with(header.as_bytes()));
        assert_eq!(bytes.len() - header.len(), nv * 12 + nf * 13);
    }

    #[test]
    fn ply_round_trips_exactly_through_load_mesh() {
        let dir = tempfile::tempdir().unwrap();
        let mut deformed = primitives::uv_sphere(1.3, 12, 7);
        for p in &mut deformed.positions {
            p.x += (p.y * 7.0).sin() / 3.0;
        }
        deformed.compute_normals();
        let mut bare = primitives::cuboid(Vec3::new(1.0, 2.0, 0.5), 2);
        bare.normals.clear();
        for (name, m) in [
            ("cuboid", primitives::cuboid(Vec3::new(1.0, 2.0, 0.5), 2)),
            ("deformed", deformed),
            ("bare", bare),
        ] {
            let path = dir.path().join(format!("{name}.ply"));
            write_ply(&path, &m).unwrap();
            let back = imprint_core::load_mesh(&path).unwrap();
            assert_eq!(back.triangles, m.triangles, "{name}");
            let all_bits = |v: &[Vec3]| v.iter().map(|p| bits(*p)).collect::<Vec<_>>();
            assert_eq!(all_bits(&back.positions), all_bits(&m.positions), "{name}");
            // Normals as written, bit for bit; a mesh written without gets computed ones.
            let mut want = m.clone();
            if want.normals.is_empty() {
                want.compute_normals();
            }
            assert_eq!(all_bits(&back.normals), all_bits(&want.normals), "{name}");
        }
    }

    #[test]
    fn a_failing_write_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = primitives::uv_sphere(1.0, 8, 5);
        // The last normal is NaN: the writers fail after writing most of the file.
        let last = m.normals.len() - 1;
        m.normals[last] = Vec3::NAN;
        let obj = dir.path().join("bad.obj");
        let ply = dir.path().join("bad.ply");
        assert!(write_obj(&obj, &m, &ObjOptions::default()).is_err());
        assert!(write_ply(&ply, &m).is_err());
        assert!(!obj.exists() && !ply.exists());
        // Nor any temporary file.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);

        // A failed rewrite keeps the previous complete file.
        let good = primitives::uv_sphere(1.0, 8, 5);
        write_obj(&obj, &good, &ObjOptions::default()).unwrap();
        let before = std::fs::read(&obj).unwrap();
        assert!(write_obj(&obj, &m, &ObjOptions::default()).is_err());
        assert_eq!(std::fs::read(&obj).unwrap(), before);
    }
}
