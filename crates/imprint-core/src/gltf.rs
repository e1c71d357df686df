//! glTF 2.0 input: a skinned, animated body as one [`Mesh`] plus what it takes to pose it.
//!
//! A [`Document`] holds every triangle primitive of the default scene merged into one mesh at
//! bind pose, each vertex's joint weights, the one skin and the animation clips; it poses the
//! mesh by linear blend skinning at any clip time. Reading is our own on top of `gltf`'s JSON
//! types (the `import` feature stays off): buffers, GLB chunks and accessors are resolved here
//! so that every bad file gets a message naming the file, the object and what was expected,
//! and never a panic inside a third-party reader.
//!
//! Not read, on purpose: materials, textures, cameras, lights, normals and UVs (normals are
//! recomputed from the triangles), morph targets and `weights` animation channels (they deform
//! meshes in ways a skeleton-driven imprint does not need yet; their keyframe times still count
//! towards a clip's length).

use crate::{Error, Mesh, Result};
use base64::Engine as _;
use glam::{Mat4, Quat, Vec3, Vec4};
use gltf::json;
use gltf::json::accessor::{ComponentType, Type};
use gltf::json::animation::{Interpolation, Property};
use gltf::json::mesh::{Mode, Semantic};
use gltf::json::validation::Checked;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use serde_json::Value;
use std::collections::{BTreeSet, HashMap};
use std::path::{Path, PathBuf};

/// A glTF file read for posing: the bind-pose mesh, its weights, its skin and its clips.
#[derive(Clone, Debug)]
pub struct Document {
    pub path: PathBuf,
    /// Every mesh primitive (TRIANGLES mode; others are an error naming the mesh) of every node
    /// of the default scene (or scene 0, or with no scenes every root node), depth first, in
    /// world space at bind pose. Skinned primitives are placed as the skin places them at bind,
    /// Σ w·(jointWorld_bind·IBM)·v with jointWorld_bind = [`Joint::bind_world`], which is the
    /// file's mesh-space positions: so [`Document::skin_matrices`] carry this mesh exactly onto
    /// the posed one. That equals what a viewer shows without animation only when the file is
    /// consistent (its nodes' rest transforms agree with its inverse bind matrices, the usual
    /// export). Unskinned primitives: their node's world transform applied (in a skinned
    /// document, taken into the bind frame of the joint they follow, see `influences`). Y-up
    /// metres as in the file. Merged into one mesh (indices offset, vertices not welded,
    /// normals computed from the triangles).
    pub mesh: Mesh,
    /// Per vertex of `mesh`: (joint index into `skin.joints`, weight), zero weights dropped,
    /// repeated joints summed, renormalised to sum 1, from every JOINTS_n/WEIGHTS_n pair (u8/u16
    /// joints; f32 or normalised u8/u16 weights). Empty when there is no skin. Vertices of
    /// unskinned primitives in a skinned document are bound rigidly (weight 1) to the nearest
    /// joint among their node and its ancestors, so that props parented to a bone follow it.
    pub influences: Vec<Vec<(u32, f32)>>,
    /// The one skin used by the scene's meshes (several are an error naming them).
    pub skin: Option<Skin>,
    pub clips: Vec<Clip>,
    hierarchy: Hierarchy,
}

/// The joints of the document's skin, in the skin's order (the order weights refer to).
#[derive(Clone, Debug, PartialEq)]
pub struct Skin {
    pub name: String,
    pub joints: Vec<Joint>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct Joint {
    /// The node's name, or "joint `i`" when unnamed.
    pub name: String,
    /// The glTF node index.
    pub node: usize,
    /// Index into `joints` of the nearest ancestor node that is a joint.
    pub parent: Option<usize>,
    /// Identity when the skin has no inverse bind matrices (as the spec says).
    pub inverse_bind: Mat4,
    /// `inverse_bind.inverse()`: the joint's world frame at bind.
    pub bind_world: Mat4,
}

/// One glTF animation: translation, rotation and scale channels of nodes over [start, end].
#[derive(Clone, Debug)]
pub struct Clip {
    /// The animation's name, or "animation `i`" when unnamed.
    pub name: String,
    /// The earliest keyframe time of any channel (0 when the clip has none).
    pub start: f32,
    /// The latest keyframe time of any channel (0 when the clip has none).
    pub end: f32,
    channels: Vec<Channel>,
}

impl Clip {
    /// `end − start`, seconds.
    pub fn duration(&self) -> f32 {
        self.end - self.start
    }
}

/// How a pipeline maps its frame time to clip time.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default)]
pub struct ClipTime {
    /// Clip seconds per pipeline second (negative plays backwards).
    pub speed: f32,
    /// Wrap around the clip instead of holding its last (or first) pose.
    pub looping: bool,
    /// Clip seconds after `start` at pipeline time zero.
    pub offset: f32,
}

impl Default for ClipTime {
    fn default() -> Self {
        ClipTime {
            speed: 1.0,
            looping: false,
            offset: 0.0,
        }
    }
}

impl ClipTime {
    /// The clip time at pipeline time `t`: `start + offset + t·speed`, wrapped into
    /// [start, end) when looping (a zero-length clip stays at `start`), clamped to [start, end]
    /// otherwise.
    pub fn local(&self, clip: &Clip, t: f32) -> f32 {
        let x = self.offset + t * self.speed;
        let len = clip.end - clip.start;
        if !self.looping {
            return (clip.start + x).max(clip.start).min(clip.end);
        }
        if len <= 0.0 || !x.is_finite() {
            return clip.start;
        }
        let r = x.rem_euclid(len);
        // rem_euclid of a tiny negative number rounds up to `len` itself.
        clip.start + if r < len { r } else { 0.0 }
    }
}

impl Document {
    /// Reads a `.gltf` (external `.bin` files beside it, `data:` URIs in base64) or a `.glb`
    /// file; which one is told by the magic bytes "glTF", not by the extension.
    pub fn load(path: &Path) -> Result<Document> {
        let bytes = std::fs::read(path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Error::mesh(path, "file not found"),
            _ => Error::io(path, e),
        })?;
        let dir = path.parent().unwrap_or(Path::new("."));
        Self::parse(&bytes, dir, path.to_path_buf())
    }

    /// Reads glTF or GLB bytes held in memory; relative buffer URIs resolve against
    /// `base_dir`, and `base_dir/name` stands for the file in errors and in `path`.
    pub fn from_slice(bytes: &[u8], base_dir: &Path, name: &str) -> Result<Document> {
        Self::parse(bytes, base_dir, base_dir.join(name))
    }

    fn parse(bytes: &[u8], base_dir: &Path, path: PathBuf) -> Result<Document> {
        let source = Source::read(bytes, base_dir, &path)?;
        source.document()
    }

    /// The clip called `name`; the error lists the clips that exist.
    pub fn clip(&self, name: &str) -> Result<&Clip> {
        if let Some(c) = self.clips.iter().find(|c| c.name == name) {
            return Ok(c);
        }
        let problem = if self.clips.is_empty() {
            format!("no animation named '{name}': the file has no animations")
        } else {
            let names: Vec<String> = self.clips.iter().map(|c| format!("'{}'", c.name)).collect();
            format!(
                "no animation named '{name}'; the file has {}",
                names.join(", ")
            )
        };
        Err(Error::mesh(&self.path, problem))
    }

    pub fn joint_count(&self) -> usize {
        self.skin.as_ref().map_or(0, |s| s.joints.len())
    }

    /// Skinning matrices per joint at time `t` of `clip`: jointWorld(t) · inverse_bind, which
    /// carry [`Document::mesh`] onto the posed mesh. `None` is the bind pose: every matrix the
    /// identity. With a clip, nodes it does not animate keep their rest transforms from the
    /// file (as viewers do). Time is clamped to [start, end]; looping and speed are the
    /// caller's (see [`ClipTime`]). Channels of a clip from another document that name nodes
    /// this one lacks are ignored. Empty when there is no skin.
    pub fn skin_matrices(&self, clip: Option<&Clip>, t: f32) -> Vec<Mat4> {
        let Some(clip) = clip else {
            return vec![Mat4::IDENTITY; self.joint_count()];
        };
        let worlds = self.hierarchy.worlds(Some(clip), t);
        self.joints()
            .iter()
            .map(|j| worlds[j.node] * j.inverse_bind)
            .collect()
    }

    /// Joint world matrices at time `t` (for bone segments and measures): `bind_world` for
    /// `None`, otherwise as [`Document::skin_matrices`].
    pub fn joint_worlds(&self, clip: Option<&Clip>, t: f32) -> Vec<Mat4> {
        let Some(clip) = clip else {
            return self.joints().iter().map(|j| j.bind_world).collect();
        };
        let worlds = self.hierarchy.worlds(Some(clip), t);
        self.joints().iter().map(|j| worlds[j.node]).collect()
    }

    /// The mesh posed by linear blend skinning with the file's weights at `t` (the bind-pose
    /// mesh, exactly, when there is no skin or no clip): what a Mesh node with a clip shows.
    /// Normals are recomputed.
    pub fn posed_mesh(&self, clip: Option<&Clip>, t: f32) -> Mesh {
        if self.skin.is_none() || clip.is_none() {
            return self.mesh.clone();
        }
        let matrices = self.skin_matrices(clip, t);
        let mut mesh = Mesh {
            positions: blend(&self.mesh.positions, &self.influences, &matrices),
            triangles: self.mesh.triangles.clone(),
            normals: Vec::new(),
            uvs: None,
        };
        mesh.compute_normals();
        mesh
    }

    /// Rest segments (head, tail) per joint, for tying particles to bones and measuring
    /// joints. The head is the joint's bind-world translation; the tail is the mean of its
    /// child joints' heads; a leaf joint has no child to point at, so its tail continues its
    /// parent's bone by half: head + (head − parent head)·0.5; a joint with neither parent nor
    /// child gets a 0.1 m stub along the Y axis of its bind frame.
    pub fn joint_segments(&self) -> Vec<(Vec3, Vec3)> {
        let joints = self.joints();
        let heads: Vec<Vec3> = joints
            .iter()
            .map(|j| j.bind_world.w_axis.truncate())
            .collect();
        let mut sums = vec![(Vec3::ZERO, 0u32); joints.len()];
        for (j, head) in joints.iter().zip(&heads) {
            if let Some(p) = j.parent {
                sums[p].0 += *head;
                sums[p].1 += 1;
            }
        }
        joints
            .iter()
            .enumerate()
            .map(|(i, j)| {
                let head = heads[i];
                let tail = match (sums[i], j.parent) {
                    ((sum, n), _) if n > 0 => sum / n as f32,
                    (_, Some(p)) => head + (head - heads[p]) * 0.5,
                    (_, None) => {
                        let y = j.bind_world.y_axis.truncate().normalize_or(Vec3::Y);
                        head + 0.1 * y
                    }
                };
                (head, tail)
            })
            .collect()
    }

    fn joints(&self) -> &[Joint] {
        self.skin.as_ref().map_or(&[], |s| &s.joints)
    }
}

/// A matrix whose inverse exists and is finite (joints with a zero scale have none).
fn invertible(m: Mat4) -> bool {
    m.is_finite() && m.determinant() != 0.0 && m.inverse().is_finite()
}

/// Σ w·M_j·v per vertex: linear blend skinning of bind-pose points.
fn blend(bind: &[Vec3], influences: &[Vec<(u32, f32)>], matrices: &[Mat4]) -> Vec<Vec3> {
    bind.par_iter()
        .zip(influences)
        .map(|(v, inf)| {
            inf.iter()
                .map(|&(j, w)| matrices[j as usize].transform_point3(*v) * w)
                .sum()
        })
        .collect()
}

// ---------------------------------------------------------------------------------------------
// Node hierarchy and animation sampling.

/// The nodes, kept so that any clip time can be posed without the file.
#[derive(Clone, Debug)]
struct Hierarchy {
    nodes: Vec<Node>,
    /// Every node index, parents before their children.
    order: Vec<usize>,
}

#[derive(Clone, Debug)]
struct Node {
    name: String,
    parent: Option<usize>,
    rest: Local,
}

/// A node's local transform: the spec allows animating only the TRS form.
#[derive(Clone, Copy, Debug)]
enum Local {
    Matrix(Mat4),
    Trs { t: Vec3, r: Quat, s: Vec3 },
}

impl Local {
    fn matrix(&self) -> Mat4 {
        match *self {
            Local::Matrix(m) => m,
            Local::Trs { t, r, s } => Mat4::from_scale_rotation_translation(s, r, t),
        }
    }
}

impl Hierarchy {
    /// World matrix of every node at time `t` of `clip` (rest pose for `None`), parents first.
    fn worlds(&self, clip: Option<&Clip>, t: f32) -> Vec<Mat4> {
        let mut locals: Vec<Local> = self.nodes.iter().map(|n| n.rest).collect();
        if let Some(clip) = clip {
            let t = t.max(clip.start).min(clip.end);
            for ch in &clip.channels {
                if let Some(local) = locals.get_mut(ch.node) {
                    ch.apply(local, t);
                }
            }
        }
        let mut worlds = vec![Mat4::IDENTITY; self.nodes.len()];
        for &i in &self.order {
            let m = locals[i].matrix();
            worlds[i] = self.nodes[i].parent.map_or(m, |p| worlds[p] * m);
        }
        worlds
    }

    /// The nearest joint among `node` and its ancestors (`joint_of` maps node → joint).
    fn nearest_joint(&self, node: usize, joint_of: &HashMap<usize, usize>) -> Option<usize> {
        let mut n = Some(node);
        while let Some(i) = n {
            if let Some(&j) = joint_of.get(&i) {
                return Some(j);
            }
            n = self.nodes[i].parent;
        }
        None
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Target {
    Translation,
    Rotation,
    Scale,
}

/// One animated property of one node; `values` holds Vec3s in xyz or quaternions in xyzw,
/// three per key for cubic splines (in-tangent, value, out-tangent).
#[derive(Clone, Debug)]
struct Channel {
    node: usize,
    target: Target,
    interpolation: Interpolation,
    times: Vec<f32>,
    values: Vec<Vec4>,
}

impl Channel {
    fn apply(&self, local: &mut Local, t: f32) {
        let Local::Trs { t: tr, r, s } = local else {
            return; // refused at load: a matrix node cannot be animated
        };
        let v = self.sample(t);
        match self.target {
            Target::Translation => *tr = v.truncate(),
            Target::Rotation => *r = Quat::from_vec4(v),
            Target::Scale => *s = v.truncate(),
        }
    }

    /// The value at `t` (glTF 2.0 §3.11 and Appendix C): the first key's value before the
    /// first key, the last key's after the last, STEP holds, LINEAR lerps (rotations slerp
    /// along the shorter arc), CUBICSPLINE is Hermite with tangents scaled by the key interval.
    fn sample(&self, t: f32) -> Vec4 {
        let n = self.times.len();
        if t.is_nan() || t <= self.times[0] {
            return self.key(0);
        }
        if t >= self.times[n - 1] {
            return self.key(n - 1);
        }
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let td = self.times[k + 1] - self.times[k];
        let u = (t - self.times[k]) / td;
        match self.interpolation {
            Interpolation::Step => self.key(k),
            Interpolation::Linear => self.lerp(self.key(k), self.key(k + 1), u),
            Interpolation::CubicSpline => {
                let out = self.values[3 * k + 2];
                let inn = self.values[3 * (k + 1)];
                let p = hermite(self.key(k), out, self.key(k + 1), inn, td, u);
                self.finish(p)
            }
        }
    }

    fn key(&self, k: usize) -> Vec4 {
        match self.interpolation {
            Interpolation::CubicSpline => self.values[3 * k + 1],
            _ => self.values[k],
        }
    }

    fn lerp(&self, a: Vec4, b: Vec4, u: f32) -> Vec4 {
        match self.target {
            Target::Rotation => {
                let q = Quat::from_vec4(a).slerp(Quat::from_vec4(b), u);
                self.finish(Vec4::from(q))
            }
            _ => a.lerp(b, u),
        }
    }

    /// Rotations come out unit length (a degenerate spline point becomes the identity).
    fn finish(&self, v: Vec4) -> Vec4 {
        match self.target {
            Target::Rotation => v.normalize_or(Vec4::W),
            _ => v,
        }
    }
}

/// p(u) = (2u³−3u²+1)p0 + td(u³−2u²+u)b0 + (−2u³+3u²)p1 + td(u³−u²)a1 (glTF Appendix C).
fn hermite(p0: Vec4, b0: Vec4, p1: Vec4, a1: Vec4, td: f32, u: f32) -> Vec4 {
    let (u2, u3) = (u * u, u * u * u);
    p0 * (2.0 * u3 - 3.0 * u2 + 1.0)
        + b0 * (td * (u3 - 2.0 * u2 + u))
        + p1 * (-2.0 * u3 + 3.0 * u2)
        + a1 * (td * (u3 - u2))
}

// ---------------------------------------------------------------------------------------------
// Container, JSON header and buffers.

/// The parsed JSON with its buffers resolved: everything the document is built from.
struct Source<'p> {
    path: &'p Path,
    root: json::Root,
    buffers: Vec<Vec<u8>>,
}

/// Extensions that change only how a body looks (materials, textures, lights), never its
/// geometry or motion, so a file requiring them still loads correctly for us.
const LOOKS_ONLY: &[&str] = &[
    "KHR_materials_",
    "KHR_texture_transform",
    "KHR_texture_basisu",
    "EXT_texture_webp",
    "EXT_texture_avif",
    "MSFT_texture_dds",
    "KHR_lights_punctual",
];

const GLB_JSON: u32 = 0x4E4F_534A;
const GLB_BIN: u32 = 0x004E_4942;

fn fail(path: &Path, problem: impl Into<String>) -> Error {
    Error::mesh(path, problem)
}

/// "mesh 'Body'" or "mesh 3" when unnamed.
fn label(kind: &str, name: Option<&str>, index: usize) -> String {
    match name {
        Some(n) => format!("{kind} '{n}'"),
        None => format!("{kind} {index}"),
    }
}

/// The JSON chunk and the optional BIN chunk of a GLB container.
fn split_glb<'a>(bytes: &'a [u8], path: &Path) -> Result<(&'a [u8], Option<&'a [u8]>)> {
    let word = |at: usize| -> Option<u32> {
        let b = bytes.get(at..at + 4)?;
        Some(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    };
    let (Some(version), Some(length)) = (word(4), word(8)) else {
        return Err(fail(
            path,
            "truncated GLB: the 12-byte header is incomplete",
        ));
    };
    if version != 2 {
        return Err(fail(
            path,
            format!("GLB container version {version}; expected 2 (glTF 2.0)"),
        ));
    }
    let length = length as usize;
    if length > bytes.len() {
        return Err(fail(
            path,
            format!(
                "truncated GLB: the header says {length} bytes but the file has {}",
                bytes.len()
            ),
        ));
    }
    glb_chunks(&bytes[..length], path)
}

/// Walks the GLB chunks after the header: JSON first (required), then BIN (optional);
/// chunks of other types are skipped, as the spec asks.
fn glb_chunks<'a>(bytes: &'a [u8], path: &Path) -> Result<(&'a [u8], Option<&'a [u8]>)> {
    let mut at = 12;
    let mut json = None;
    let mut bin = None;
    while at + 8 <= bytes.len() {
        let len = u32::from_le_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
        let kind = u32::from_le_bytes(bytes[at + 4..at + 8].try_into().unwrap());
        let Some(data) = bytes.get(at + 8..(at + 8).saturating_add(len)) else {
            return Err(fail(
                path,
                format!("truncated GLB: a chunk at byte {at} claims {len} bytes past the end"),
            ));
        };
        match kind {
            GLB_JSON if json.is_none() => json = Some(data),
            GLB_BIN if bin.is_none() => bin = Some(data),
            _ => {}
        }
        at += 8 + len;
    }
    let json = json.ok_or_else(|| fail(path, "GLB without a JSON chunk"))?;
    Ok((json, bin))
}

/// The JSON text as a value, or "this is not glTF" when it is not JSON at all.
fn parse_json(bytes: &[u8], path: &Path) -> Result<Value> {
    serde_json::from_slice(bytes).map_err(|e| {
        fail(
            path,
            format!(
                "not a glTF file: expected glTF JSON with an \"asset\" object, or binary glTF \
                 starting with the magic bytes \"glTF\" ({e})"
            ),
        )
    })
}

/// Refuses JSON that is not glTF and glTF that is not 2.x.
fn check_asset(value: &Value, path: &Path) -> Result<()> {
    let Some(asset) = value.get("asset").and_then(Value::as_object) else {
        return Err(fail(
            path,
            "not a glTF file: the JSON has no \"asset\" object (every glTF file has one)",
        ));
    };
    let version = asset.get("version").and_then(Value::as_str).unwrap_or("");
    if version.split('.').next() != Some("2") {
        return Err(fail(
            path,
            format!(
                "glTF version \"{version}\"; only glTF 2.x is supported (re-export as glTF 2.0)"
            ),
        ));
    }
    match asset.get("minVersion").and_then(Value::as_str) {
        Some(min) if min != "2.0" => Err(fail(
            path,
            format!("the file needs a glTF {min} reader (minVersion); this one reads 2.0"),
        )),
        _ => Ok(()),
    }
}

/// Refuses files whose `extensionsRequired` changes geometry or motion (compression,
/// quantization, animation pointers...), listing them.
fn check_required_extensions(value: &Value, path: &Path) -> Result<()> {
    let required = value.get("extensionsRequired").and_then(Value::as_array);
    let unsupported: Vec<&str> = required
        .into_iter()
        .flatten()
        .filter_map(Value::as_str)
        .filter(|e| !LOOKS_ONLY.iter().any(|ok| e.starts_with(ok)))
        .collect();
    if unsupported.is_empty() {
        return Ok(());
    }
    Err(fail(
        path,
        format!(
            "the file requires glTF extensions this reader does not support: {} \
             (extensionsRequired); re-export without them (no mesh compression or quantization)",
            unsupported.join(", ")
        ),
    ))
}

/// `%20`-style escapes in a relative URI.
fn percent_decode(uri: &str) -> String {
    let b = uri.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        let hex = (b[i] == b'%')
            .then(|| std::str::from_utf8(b.get(i + 1..i + 3)?).ok())
            .flatten()
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match hex {
            Some(byte) => {
                out.push(byte);
                i += 3;
            }
            None => {
                out.push(b[i]);
                i += 1;
            }
        }
    }
    String::from_utf8_lossy(&out).into_owned()
}

impl<'p> Source<'p> {
    /// Container → JSON → checked header → typed root → buffers → views checked.
    fn read(bytes: &[u8], base_dir: &Path, path: &'p Path) -> Result<Self> {
        let (json_bytes, bin) = if bytes.starts_with(b"glTF") {
            split_glb(bytes, path)?
        } else {
            (bytes, None)
        };
        let value = parse_json(json_bytes, path)?;
        check_asset(&value, path)?;
        check_required_extensions(&value, path)?;
        let root: json::Root = serde_json::from_value(value)
            .map_err(|e| fail(path, format!("not valid glTF 2.0 JSON ({e})")))?;
        let mut source = Source {
            path,
            root,
            buffers: Vec::new(),
        };
        source.load_buffers(bin, base_dir)?;
        source.check_views()?;
        Ok(source)
    }

    fn fail(&self, problem: impl Into<String>) -> Error {
        fail(self.path, problem)
    }

    /// `list[index]`, or an error saying who referred to what that does not exist.
    fn item<'r, T>(&self, list: &'r [T], index: usize, kind: &str, who: &str) -> Result<&'r T> {
        list.get(index).ok_or_else(|| {
            self.fail(format!(
                "{who} refers to {kind} {index}, but the file has {} of them",
                list.len()
            ))
        })
    }

    /// Every buffer's bytes, cut to its byteLength; refuses buffers shorter than declared.
    fn load_buffers(&mut self, mut bin: Option<&[u8]>, base_dir: &Path) -> Result<()> {
        for (i, buffer) in self.root.buffers.iter().enumerate() {
            let mut data = match &buffer.uri {
                None if i == 0 => bin.take().map(<[u8]>::to_vec).ok_or_else(|| {
                    self.fail("buffer 0 has no uri and the file is not a GLB with a BIN chunk")
                })?,
                None => {
                    return Err(self.fail(format!(
                        "buffer {i} has no uri; only a GLB's first buffer may omit it"
                    )));
                }
                Some(uri) => self.buffer_uri(i, uri, base_dir)?,
            };
            let declared = buffer.byte_length.0;
            if (data.len() as u64) < declared {
                return Err(self.fail(format!(
                    "buffer {i} ({}) holds {} bytes but its byteLength says {declared}",
                    buffer.uri.as_deref().unwrap_or("GLB BIN chunk"),
                    data.len()
                )));
            }
            data.truncate(declared as usize);
            self.buffers.push(data);
        }
        Ok(())
    }

    /// The bytes behind a buffer URI: a base64 `data:` URI or a file relative to the glTF.
    fn buffer_uri(&self, i: usize, uri: &str, base_dir: &Path) -> Result<Vec<u8>> {
        if let Some(rest) = uri.strip_prefix("data:") {
            let (header, payload) = rest.split_once(',').unwrap_or((rest, ""));
            if !header.ends_with(";base64") {
                return Err(self.fail(format!(
                    "buffer {i} is a data: URI that is not base64 (expected \
                     \"data:application/octet-stream;base64,...\")"
                )));
            }
            return base64::engine::general_purpose::STANDARD
                .decode(payload.trim())
                .map_err(|e| {
                    self.fail(format!(
                        "buffer {i}: its data: URI is not valid base64 ({e})"
                    ))
                });
        }
        if uri.contains("://") {
            return Err(self.fail(format!(
                "buffer {i} refers to '{uri}'; only relative file paths and data: URIs are supported"
            )));
        }
        let file = base_dir.join(percent_decode(uri));
        std::fs::read(&file).map_err(|e| {
            self.fail(format!(
                "buffer {i} refers to '{uri}', but {} cannot be read ({e}); keep the .bin beside \
                 the .gltf",
                file.display()
            ))
        })
    }

    /// Every buffer view lies inside its buffer.
    fn check_views(&self) -> Result<()> {
        for (v, view) in self.root.buffer_views.iter().enumerate() {
            let who = format!("buffer view {v}");
            let b = view.buffer.value();
            let data = self.item(&self.buffers, b, "buffer", &who)?;
            let start = view.byte_offset.map_or(0, |o| o.0);
            let end = start.saturating_add(view.byte_length.0);
            if end > data.len() as u64 {
                return Err(self.fail(format!(
                    "buffer view {v} covers bytes {start}..{end} of buffer {b}, which holds only \
                     {} bytes",
                    data.len()
                )));
            }
        }
        Ok(())
    }

    /// The bytes of a buffer view (already checked to lie inside its buffer).
    fn view_bytes(&self, view: &json::buffer::View) -> &[u8] {
        let start = view.byte_offset.map_or(0, |o| o.0) as usize;
        &self.buffers[view.buffer.value()][start..start + view.byte_length.0 as usize]
    }
}

// ---------------------------------------------------------------------------------------------
// Accessors.

/// How one accessor element lies in memory: matrix columns start 4-byte aligned (spec §3.6.2.4).
struct Layout {
    ct: ComponentType,
    size: usize,
    rows: usize,
    columns: usize,
    column_stride: usize,
}

impl Layout {
    fn new(ty: Type, ct: ComponentType) -> Self {
        let size = component_size(ct);
        let (rows, columns) = match ty {
            Type::Scalar => (1, 1),
            Type::Vec2 => (2, 1),
            Type::Vec3 => (3, 1),
            Type::Vec4 => (4, 1),
            Type::Mat2 => (2, 2),
            Type::Mat3 => (3, 3),
            Type::Mat4 => (4, 4),
        };
        let column_stride = if columns > 1 {
            (rows * size).next_multiple_of(4)
        } else {
            rows * size
        };
        Layout {
            ct,
            size,
            rows,
            columns,
            column_stride,
        }
    }

    fn components(&self) -> usize {
        self.rows * self.columns
    }

    fn element_size(&self) -> usize {
        self.columns * self.column_stride
    }

    /// Appends the components of the element starting at `bytes[0]`, column by column.
    fn read(&self, bytes: &[u8], out: &mut Vec<f64>) {
        for c in 0..self.columns {
            for r in 0..self.rows {
                let at = c * self.column_stride + r * self.size;
                out.push(read_component(&bytes[at..], self.ct));
            }
        }
    }
}

fn component_size(ct: ComponentType) -> usize {
    match ct {
        ComponentType::I8 | ComponentType::U8 => 1,
        ComponentType::I16 | ComponentType::U16 => 2,
        ComponentType::U32 | ComponentType::F32 => 4,
    }
}

/// One little-endian component, exactly (every glTF component type fits an f64).
fn read_component(b: &[u8], ct: ComponentType) -> f64 {
    match ct {
        ComponentType::I8 => b[0] as i8 as f64,
        ComponentType::U8 => b[0] as f64,
        ComponentType::I16 => i16::from_le_bytes([b[0], b[1]]) as f64,
        ComponentType::U16 => u16::from_le_bytes([b[0], b[1]]) as f64,
        ComponentType::U32 => u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
        ComponentType::F32 => f32::from_le_bytes([b[0], b[1], b[2], b[3]]) as f64,
    }
}

/// A normalised integer as the spec maps it to [0, 1] or [−1, 1].
fn normalise(x: f64, ct: ComponentType) -> f64 {
    match ct {
        ComponentType::I8 => (x / 127.0).max(-1.0),
        ComponentType::U8 => x / 255.0,
        ComponentType::I16 => (x / 32767.0).max(-1.0),
        ComponentType::U16 => x / 65535.0,
        ComponentType::U32 => x / u32::MAX as f64,
        ComponentType::F32 => x,
    }
}

fn property_name(p: Property) -> &'static str {
    match p {
        Property::Translation => "translation",
        Property::Rotation => "rotation",
        Property::Scale => "scale",
        Property::MorphTargetWeights => "weights",
    }
}

fn type_name(ty: Type) -> &'static str {
    match ty {
        Type::Scalar => "SCALAR",
        Type::Vec2 => "VEC2",
        Type::Vec3 => "VEC3",
        Type::Vec4 => "VEC4",
        Type::Mat2 => "MAT2",
        Type::Mat3 => "MAT3",
        Type::Mat4 => "MAT4",
    }
}

impl Source<'_> {
    /// An accessor's components, flat, with its component type and `normalized` flag;
    /// `what` says what it is for in errors.
    fn components(
        &self,
        index: usize,
        what: &str,
        ty: Type,
    ) -> Result<(Vec<f64>, ComponentType, bool)> {
        let who = format!("{what} (accessor {index})");
        let acc = self.item(&self.root.accessors, index, "accessor", what)?;
        let (Checked::Valid(actual), Checked::Valid(ct)) = (acc.type_, acc.component_type) else {
            return Err(self.fail(format!("{who} has an invalid type or componentType")));
        };
        if actual != ty {
            return Err(self.fail(format!(
                "{who} is {}, expected {}",
                type_name(actual),
                type_name(ty)
            )));
        }
        let layout = Layout::new(ty, ct.0);
        let count = acc.count.0 as usize;
        let offset = acc.byte_offset.map_or(0, |o| o.0);
        let mut out = match acc.buffer_view {
            Some(v) => self.dense(v.value(), offset, count, &layout, &who)?,
            None => self.zeros(count, &layout, &who)?,
        };
        if let Some(sparse) = &acc.sparse {
            self.apply_sparse(sparse, count, &layout, &mut out, &who)?;
        }
        Ok((out, ct.0, acc.normalized))
    }

    /// `count` elements from a buffer view; refuses reads past the view's end.
    fn dense(
        &self,
        v: usize,
        offset: u64,
        count: usize,
        layout: &Layout,
        who: &str,
    ) -> Result<Vec<f64>> {
        let view = self.item(&self.root.buffer_views, v, "buffer view", who)?;
        let elem = layout.element_size();
        let stride = view.byte_stride.map_or(elem, |s| s.0);
        if stride < elem {
            return Err(self.fail(format!(
                "{who}: buffer view {v} has byteStride {stride} but each element takes {elem} bytes"
            )));
        }
        let data = self.view_bytes(view);
        if count == 0 {
            return Ok(Vec::new());
        }
        let end = (stride as u64)
            .saturating_mul(count as u64 - 1)
            .saturating_add(offset)
            .saturating_add(elem as u64);
        if end > data.len() as u64 {
            return Err(self.fail(format!(
                "{who} reads {count} elements, bytes {offset}..{end} of buffer view {v}, which \
                 has only {} bytes",
                data.len()
            )));
        }
        let mut out = Vec::with_capacity(count * layout.components());
        for i in 0..count {
            layout.read(&data[offset as usize + i * stride..], &mut out);
        }
        Ok(out)
    }

    /// The zero base of a sparse accessor without a buffer view (checked against memory first,
    /// since `count` is not bounded by any data).
    fn zeros(&self, count: usize, layout: &Layout, who: &str) -> Result<Vec<f64>> {
        let n = count.saturating_mul(layout.components());
        crate::error::check_alloc(who, n as u64 * 8)?;
        Ok(vec![0.0; n])
    }

    fn apply_sparse(
        &self,
        sparse: &json::accessor::sparse::Sparse,
        count: usize,
        layout: &Layout,
        out: &mut [f64],
        who: &str,
    ) -> Result<()> {
        let n = sparse.count.0 as usize;
        let Checked::Valid(ict) = sparse.indices.component_type else {
            return Err(self.fail(format!(
                "{who}: sparse indices have an invalid componentType"
            )));
        };
        let ilayout = Layout::new(Type::Scalar, ict.0);
        let (iv, vv) = (&sparse.indices, &sparse.values);
        let indices = self.dense(iv.buffer_view.value(), iv.byte_offset.0, n, &ilayout, who)?;
        let values = self.dense(vv.buffer_view.value(), vv.byte_offset.0, n, layout, who)?;
        let c = layout.components();
        for (k, &i) in indices.iter().enumerate() {
            let i = i as usize;
            if i >= count {
                return Err(self.fail(format!(
                    "{who}: sparse index {i} is out of range (the accessor has {count} elements)"
                )));
            }
            out[i * c..(i + 1) * c].copy_from_slice(&values[k * c..(k + 1) * c]);
        }
        Ok(())
    }

    /// Float data (normalised integers mapped as the spec says).
    fn floats(&self, index: usize, what: &str, ty: Type) -> Result<Vec<f32>> {
        let (values, ct, normalized) = self.components(index, what, ty)?;
        let value = |x: f64| if normalized { normalise(x, ct) } else { x };
        Ok(values.into_iter().map(|x| value(x) as f32).collect())
    }

    /// Unsigned integer data (indices, joints); refuses floats and signed types.
    fn uints(&self, index: usize, what: &str, ty: Type) -> Result<Vec<u32>> {
        let (values, ct, _) = self.components(index, what, ty)?;
        match ct {
            ComponentType::U8 | ComponentType::U16 | ComponentType::U32 => {
                Ok(values.into_iter().map(|x| x as u32).collect())
            }
            _ => Err(self.fail(format!(
                "{what} (accessor {index}) has component type {ct:?}; expected unsigned \
                 integers (UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT)"
            ))),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Nodes, skin and clips.

impl Source<'_> {
    fn node_label(&self, i: usize) -> String {
        label("node", self.root.nodes[i].name.as_deref(), i)
    }

    /// Parents from the children lists, rest transforms, and an order with parents first;
    /// refuses nodes with two parents and cycles.
    fn hierarchy(&self) -> Result<Hierarchy> {
        let parents = self.parents()?;
        let mut nodes = Vec::with_capacity(parents.len());
        for (i, parent) in parents.iter().enumerate() {
            nodes.push(Node {
                name: self.node_label(i),
                parent: *parent,
                rest: self.rest(i)?,
            });
        }
        let order = self.parents_first(&parents)?;
        Ok(Hierarchy { nodes, order })
    }

    fn parents(&self) -> Result<Vec<Option<usize>>> {
        let mut parents = vec![None; self.root.nodes.len()];
        for (p, node) in self.root.nodes.iter().enumerate() {
            for child in node.children.iter().flatten() {
                let c = child.value();
                let who = self.node_label(p);
                self.item(&self.root.nodes, c, "child node", &who)?;
                if let Some(q) = parents[c] {
                    return Err(self.fail(format!(
                        "{} has two parents ({} and {}); glTF nodes form trees",
                        self.node_label(c),
                        self.node_label(q),
                        who
                    )));
                }
                parents[c] = Some(p);
            }
        }
        Ok(parents)
    }

    /// Breadth-first from the parentless nodes; a node never reached lies on a cycle.
    fn parents_first(&self, parents: &[Option<usize>]) -> Result<Vec<usize>> {
        let mut order: Vec<usize> = (0..parents.len())
            .filter(|&i| parents[i].is_none())
            .collect();
        let mut next = 0;
        while next < order.len() {
            let p = order[next];
            let children = self.root.nodes[p].children.iter().flatten();
            order.extend(children.map(|c| c.value()));
            next += 1;
        }
        if order.len() < parents.len() {
            let mut reached = vec![false; parents.len()];
            order.iter().for_each(|&i| reached[i] = true);
            let lost = reached.iter().position(|r| !r).unwrap();
            return Err(self.fail(format!(
                "{} is its own ancestor (the children lists form a cycle)",
                self.node_label(lost)
            )));
        }
        Ok(order)
    }

    /// A node's rest transform. An identity `matrix` next to TRS is read as TRS, so that such
    /// nodes can still be animated.
    fn rest(&self, i: usize) -> Result<Local> {
        let node = &self.root.nodes[i];
        let bad = || self.fail(format!("{} has a non-finite transform", self.node_label(i)));
        if let Some(m) = node.matrix.map(|m| Mat4::from_cols_array(&m)) {
            if !m.is_finite() {
                return Err(bad());
            }
            if m != Mat4::IDENTITY {
                return Ok(Local::Matrix(m));
            }
        }
        let t = Vec3::from(node.translation.unwrap_or([0.0; 3]));
        let r = Vec4::from(node.rotation.map_or([0.0, 0.0, 0.0, 1.0], |q| q.0));
        let s = Vec3::from(node.scale.unwrap_or([1.0; 3]));
        if !(t.is_finite() && r.is_finite() && s.is_finite()) {
            return Err(bad());
        }
        let r = Quat::from_vec4(r.normalize_or(Vec4::W));
        Ok(Local::Trs { t, r, s })
    }

    /// The default scene's nodes (scene 0 without a default; every root node without
    /// scenes), depth first, each once.
    fn scene_nodes(&self, h: &Hierarchy) -> Result<Vec<usize>> {
        let scenes = &self.root.scenes;
        let roots: Vec<usize> = match (self.root.scene, scenes.is_empty()) {
            (Some(s), _) => {
                let scene = self.item(scenes, s.value(), "scene", "the default scene")?;
                scene.nodes.iter().map(|n| n.value()).collect()
            }
            (None, false) => scenes[0].nodes.iter().map(|n| n.value()).collect(),
            (None, true) => (0..h.nodes.len())
                .filter(|&i| h.nodes[i].parent.is_none())
                .collect(),
        };
        let mut seen = vec![false; h.nodes.len()];
        let mut out = Vec::new();
        let mut stack: Vec<usize> = roots.into_iter().rev().collect();
        while let Some(n) = stack.pop() {
            self.item(&self.root.nodes, n, "node", "the scene")?;
            if std::mem::replace(&mut seen[n], true) {
                continue;
            }
            out.push(n);
            let children = self.root.nodes[n].children.iter().flatten();
            stack.extend(children.rev().map(|c| c.value()));
        }
        Ok(out)
    }

    /// The one skin used by the scene's mesh nodes, if any; several are refused by name.
    fn used_skin(&self, scene: &[usize]) -> Result<Option<usize>> {
        let nodes = &self.root.nodes;
        let used: BTreeSet<usize> = scene
            .iter()
            .filter(|&&n| nodes[n].mesh.is_some())
            .filter_map(|&n| nodes[n].skin.map(|s| s.value()))
            .collect();
        for &s in &used {
            self.item(&self.root.skins, s, "skin", "a node")?;
        }
        if used.len() > 1 {
            let names: Vec<String> = used.iter().map(|&s| self.skin_label(s)).collect();
            return Err(self.fail(format!(
                "the scene uses {} skins ({}); only one skin per document is supported: export \
                 one character per file or merge the skeletons",
                used.len(),
                names.join(", ")
            )));
        }
        Ok(used.into_iter().next())
    }

    fn skin_label(&self, s: usize) -> String {
        label("skin", self.root.skins[s].name.as_deref(), s)
    }

    /// The skin's joints with their inverse bind matrices and joint parents.
    fn skin(&self, s: usize, h: &Hierarchy) -> Result<Skin> {
        let skin = &self.root.skins[s];
        let who = self.skin_label(s);
        let ibms = self.inverse_binds(s)?;
        let joint_of: HashMap<usize, usize> = skin
            .joints
            .iter()
            .enumerate()
            .map(|(j, n)| (n.value(), j))
            .collect();
        let mut joints = Vec::with_capacity(skin.joints.len());
        for (j, node) in skin.joints.iter().enumerate() {
            let n = node.value();
            self.item(&self.root.nodes, n, "node", &who)?;
            let inverse_bind = ibms.get(j).copied().unwrap_or(Mat4::IDENTITY);
            let name = self.root.nodes[n].name.clone();
            let name = name.unwrap_or_else(|| format!("joint {j}"));
            if !invertible(inverse_bind) {
                return Err(self.fail(format!(
                    "{who}, joint '{name}': its inverse bind matrix is not invertible or not finite"
                )));
            }
            let parent = h.nodes[n]
                .parent
                .and_then(|p| h.nearest_joint(p, &joint_of));
            joints.push(Joint {
                name,
                node: n,
                parent,
                inverse_bind,
                bind_world: inverse_bind.inverse(),
            });
        }
        let name = skin.name.clone().unwrap_or_else(|| format!("skin {s}"));
        Ok(Skin { name, joints })
    }

    /// The skin's inverse bind matrices (none when the skin has no accessor); refuses fewer
    /// matrices than joints.
    fn inverse_binds(&self, s: usize) -> Result<Vec<Mat4>> {
        let skin = &self.root.skins[s];
        let Some(acc) = skin.inverse_bind_matrices else {
            return Ok(Vec::new());
        };
        let what = format!("inverseBindMatrices of {}", self.skin_label(s));
        let m: Vec<Mat4> = self
            .floats(acc.value(), &what, Type::Mat4)?
            .chunks_exact(16)
            .map(Mat4::from_cols_slice)
            .collect();
        if m.len() < skin.joints.len() {
            return Err(self.fail(format!(
                "{what} holds {} matrices for {} joints",
                m.len(),
                skin.joints.len()
            )));
        }
        Ok(m)
    }

    /// One clip per animation.
    fn clips(&self, h: &Hierarchy) -> Result<Vec<Clip>> {
        (0..self.root.animations.len())
            .map(|a| self.clip(a, h))
            .collect()
    }

    fn clip(&self, a: usize, h: &Hierarchy) -> Result<Clip> {
        let anim = &self.root.animations[a];
        let name = anim
            .name
            .clone()
            .unwrap_or_else(|| format!("animation {a}"));
        let mut range: Option<(f32, f32)> = None;
        let mut channels = Vec::new();
        for c in 0..anim.channels.len() {
            let (channel, (first, last)) = self.channel(a, c, &name, h)?;
            range = Some(range.map_or((first, last), |(s, e)| (s.min(first), e.max(last))));
            channels.extend(channel);
        }
        let (start, end) = range.unwrap_or((0.0, 0.0));
        Ok(Clip {
            name,
            start,
            end,
            channels,
        })
    }

    /// One channel with its time range; `None` for a `weights` channel (morph targets are not
    /// read, but their times still count towards the clip's length).
    fn channel(
        &self,
        a: usize,
        c: usize,
        anim_name: &str,
        h: &Hierarchy,
    ) -> Result<(Option<Channel>, (f32, f32))> {
        let anim = &self.root.animations[a];
        let ch = &anim.channels[c];
        let who = format!("animation '{anim_name}' channel {c}");
        let sampler = self.item(&anim.samplers, ch.sampler.value(), "sampler", &who)?;
        let node = ch.target.node.value();
        self.item(&h.nodes, node, "node", &who)?;
        let (Checked::Valid(path), Checked::Valid(interpolation)) =
            (ch.target.path, sampler.interpolation)
        else {
            return Err(self.fail(format!("{who} has an unknown target path or interpolation")));
        };
        let who = format!("{who} ({} of {})", property_name(path), h.nodes[node].name);
        let times = self.floats(sampler.input.value(), &format!("{who} times"), Type::Scalar)?;
        self.check_times(&times, &who)?;
        let range = (times[0], times[times.len() - 1]);
        let target = match path {
            Property::Translation => Target::Translation,
            Property::Rotation => Target::Rotation,
            Property::Scale => Target::Scale,
            Property::MorphTargetWeights => return Ok((None, range)),
        };
        if let Local::Matrix(_) = h.nodes[node].rest {
            return Err(self.fail(format!(
                "{who}: the node has a matrix, and glTF allows animating only nodes with \
                 translation/rotation/scale"
            )));
        }
        let values = self.keyframe_values(sampler.output.value(), &who, target, interpolation)?;
        let per_key = if interpolation == Interpolation::CubicSpline {
            3
        } else {
            1
        };
        if values.len() != times.len() * per_key {
            return Err(self.fail(format!(
                "{who} has {} keyframe times but {} output values; {interpolation:?} needs {}",
                times.len(),
                values.len(),
                times.len() * per_key
            )));
        }
        let channel = Channel {
            node,
            target,
            interpolation,
            times,
            values,
        };
        Ok((Some(channel), range))
    }

    /// Keyframe times are finite and strictly increasing, and there is at least one.
    fn check_times(&self, times: &[f32], who: &str) -> Result<()> {
        if times.is_empty() {
            return Err(self.fail(format!("{who} has no keyframes")));
        }
        if let Some(k) = times.iter().position(|t| !t.is_finite()) {
            return Err(self.fail(format!(
                "{who}: keyframe time {k} is {}; times must be finite",
                times[k]
            )));
        }
        if let Some(k) = (1..times.len()).find(|&k| times[k] <= times[k - 1]) {
            return Err(self.fail(format!(
                "{who}: keyframe time {k} ({}) does not come after time {} ({}); keyframe \
                 times must increase",
                times[k],
                k - 1,
                times[k - 1]
            )));
        }
        Ok(())
    }

    /// Output values as Vec4 (xyz, or a quaternion), all finite; LINEAR and STEP rotation keys
    /// are normalised (spline tangents are not unit quaternions and stay as they are).
    fn keyframe_values(
        &self,
        acc: usize,
        who: &str,
        target: Target,
        interpolation: Interpolation,
    ) -> Result<Vec<Vec4>> {
        let what = format!("{who} values");
        let values: Vec<Vec4> = if target == Target::Rotation {
            let flat = self.floats(acc, &what, Type::Vec4)?;
            flat.chunks_exact(4).map(Vec4::from_slice).collect()
        } else {
            let flat = self.floats(acc, &what, Type::Vec3)?;
            flat.chunks_exact(3)
                .map(|v| Vec3::from_slice(v).extend(0.0))
                .collect()
        };
        if let Some(k) = values.iter().position(|v| !v.is_finite()) {
            return Err(self.fail(format!(
                "{who}: output value {k} is not finite ({}); keyframe values must be numbers",
                values[k]
            )));
        }
        if target == Target::Rotation && interpolation != Interpolation::CubicSpline {
            return values
                .into_iter()
                .enumerate()
                .map(|(k, v)| {
                    v.try_normalize().ok_or_else(|| {
                        self.fail(format!("{who}: rotation key {k} is a zero quaternion"))
                    })
                })
                .collect();
        }
        Ok(values)
    }
}

// ---------------------------------------------------------------------------------------------
// Geometry.

/// Vertices gathered from the primitives before posing.
#[derive(Default)]
struct Gathered {
    /// Bind-pose positions (see [`Document::mesh`]).
    bind: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    influences: Vec<Vec<(u32, f32)>>,
}

/// What the primitives of one node are placed by.
struct Placement<'s> {
    node: usize,
    world: Mat4,
    skin: Option<&'s SkinContext>,
    hierarchy: &'s Hierarchy,
}

/// The skin and what binding vertices to it needs.
struct SkinContext {
    index: usize,
    skin: Skin,
    /// Rest skin matrices (jointWorld_rest · IBM), for binding unskinned vertices rigidly.
    rest: Vec<Mat4>,
    joint_of: HashMap<usize, usize>,
}

impl Source<'_> {
    fn document(self) -> Result<Document> {
        let hierarchy = self.hierarchy()?;
        let scene = self.scene_nodes(&hierarchy)?;
        let worlds = hierarchy.worlds(None, 0.0);
        let skin = match self.used_skin(&scene)? {
            Some(s) => Some(self.skin_context(s, &hierarchy, &worlds)?),
            None => None,
        };
        let mut g = Gathered::default();
        for &n in &scene {
            let place = Placement {
                node: n,
                world: worlds[n],
                skin: skin.as_ref(),
                hierarchy: &hierarchy,
            };
            self.gather_node(&place, &mut g)?;
        }
        let clips = self.clips(&hierarchy)?;
        self.assemble(g, skin, hierarchy, clips)
    }

    fn skin_context(&self, s: usize, h: &Hierarchy, worlds: &[Mat4]) -> Result<SkinContext> {
        let skin = self.skin(s, h)?;
        let rest = skin
            .joints
            .iter()
            .map(|j| worlds[j.node] * j.inverse_bind)
            .collect();
        let joint_of = skin
            .joints
            .iter()
            .enumerate()
            .map(|(j, jt)| (jt.node, j))
            .collect();
        Ok(SkinContext {
            index: s,
            skin,
            rest,
            joint_of,
        })
    }

    /// The bind-pose mesh from the gathered vertices, and the document.
    fn assemble(
        &self,
        g: Gathered,
        skin: Option<SkinContext>,
        hierarchy: Hierarchy,
        clips: Vec<Clip>,
    ) -> Result<Document> {
        if g.triangles.is_empty() {
            return Err(self.fail("the scene has no mesh triangles; nothing to load"));
        }
        let source = self.path.display().to_string();
        let mesh = Mesh::new(g.bind, g.triangles, &source).map_err(|e| match e {
            Error::Invalid(problem) => {
                let prefix = format!("{source}: ");
                self.fail(problem.strip_prefix(&prefix).unwrap_or(&problem))
            }
            other => other,
        })?;
        Ok(Document {
            path: self.path.to_path_buf(),
            mesh,
            influences: if skin.is_some() {
                g.influences
            } else {
                Vec::new()
            },
            skin: skin.map(|sc| sc.skin),
            clips,
            hierarchy,
        })
    }

    fn gather_node(&self, place: &Placement, g: &mut Gathered) -> Result<()> {
        let node = &self.root.nodes[place.node];
        let h = place.hierarchy;
        let Some(m) = node.mesh else {
            return Ok(());
        };
        let mesh = self.item(
            &self.root.meshes,
            m.value(),
            "mesh",
            &h.nodes[place.node].name,
        )?;
        let name = label("mesh", mesh.name.as_deref(), m.value());
        for (p, prim) in mesh.primitives.iter().enumerate() {
            let who = format!("{name} primitive {p}");
            self.gather_primitive(prim, &who, &name, place, g)?;
        }
        Ok(())
    }

    fn gather_primitive(
        &self,
        prim: &json::mesh::Primitive,
        who: &str,
        mesh_name: &str,
        place: &Placement,
        g: &mut Gathered,
    ) -> Result<()> {
        self.check_mode(prim, who)?;
        let positions = self.positions(prim, who)?;
        let base = g.bind.len() as u32;
        for t in self.triangles(prim, positions.len(), who)? {
            g.triangles.push(t.map(|i| i + base));
        }
        let Some(sc) = place.skin else {
            g.bind
                .extend(positions.iter().map(|&v| place.world.transform_point3(v)));
            return Ok(());
        };
        let skinned = self.root.nodes[place.node].skin.map(|s| s.value()) == Some(sc.index);
        if skinned {
            let influences = self.influences(prim, who, positions.len(), &sc.skin)?;
            g.influences.extend(influences);
            g.bind.extend(positions);
            return Ok(());
        }
        self.bind_rigidly(&positions, mesh_name, place, sc, g)
    }

    /// Vertices of an unskinned primitive in a skinned document follow the nearest joint
    /// above them: their bind point is that joint's rest skin matrix (jointWorld_rest·IBM)
    /// undone on their rest world position, so that posing at the rest pose puts them where
    /// their node does, and a turn of the joint carries them along.
    fn bind_rigidly(
        &self,
        positions: &[Vec3],
        mesh_name: &str,
        place: &Placement,
        sc: &SkinContext,
        g: &mut Gathered,
    ) -> Result<()> {
        let h = place.hierarchy;
        let Some(j) = h.nearest_joint(place.node, &sc.joint_of) else {
            return Err(self.fail(format!(
                "{mesh_name} is not skinned and neither its {} nor any ancestor is a joint of \
                 skin '{}'; give it JOINTS_0/WEIGHTS_0 and the skin, or parent its node under a joint",
                h.nodes[place.node].name, sc.skin.name
            )));
        };
        let rest = sc.rest[j];
        if !invertible(rest) {
            return Err(self.fail(format!(
                "{mesh_name} follows joint '{}', whose rest skin matrix is singular (a zero scale?)",
                sc.skin.joints[j].name
            )));
        }
        let to_bind = rest.inverse() * place.world;
        g.bind
            .extend(positions.iter().map(|&v| to_bind.transform_point3(v)));
        g.influences
            .extend(positions.iter().map(|_| vec![(j as u32, 1.0)]));
        Ok(())
    }

    fn check_mode(&self, prim: &json::mesh::Primitive, who: &str) -> Result<()> {
        match prim.mode {
            Checked::Valid(Mode::Triangles) => Ok(()),
            Checked::Valid(mode) => Err(self.fail(format!(
                "{who} has mode {mode:?}; only TRIANGLES (mode 4) is supported"
            ))),
            Checked::Invalid => {
                Err(self.fail(format!("{who} has an invalid mode; expected TRIANGLES (4)")))
            }
        }
    }

    fn positions(&self, prim: &json::mesh::Primitive, who: &str) -> Result<Vec<Vec3>> {
        let Some(acc) = prim.attributes.get(&Checked::Valid(Semantic::Positions)) else {
            return Err(self.fail(format!("{who} has no POSITION attribute")));
        };
        let flat = self.floats(acc.value(), &format!("{who} POSITION"), Type::Vec3)?;
        Ok(flat.chunks_exact(3).map(Vec3::from_slice).collect())
    }

    /// Triangles from the index accessor (or consecutive vertices without one), every index
    /// checked against the primitive's vertex count.
    fn triangles(
        &self,
        prim: &json::mesh::Primitive,
        n: usize,
        who: &str,
    ) -> Result<Vec<[u32; 3]>> {
        let indices = match prim.indices {
            Some(acc) => self.uints(acc.value(), &format!("{who} indices"), Type::Scalar)?,
            None => (0..n as u32).collect(),
        };
        if indices.len() % 3 != 0 {
            return Err(self.fail(format!(
                "{who} has {} indices, not a multiple of 3 as TRIANGLES needs",
                indices.len()
            )));
        }
        if let Some(k) = indices.iter().position(|&i| i as usize >= n) {
            return Err(self.fail(format!(
                "{who}: index {k} is {} but the primitive has {n} vertices",
                indices[k]
            )));
        }
        Ok(indices
            .chunks_exact(3)
            .map(|t| [t[0], t[1], t[2]])
            .collect())
    }

    /// Per vertex (joint, weight) from every JOINTS_n/WEIGHTS_n pair, renormalised.
    fn influences(
        &self,
        prim: &json::mesh::Primitive,
        who: &str,
        n: usize,
        skin: &Skin,
    ) -> Result<Vec<Vec<(u32, f32)>>> {
        let mut out = vec![Vec::new(); n];
        for set in 0.. {
            let joints = prim.attributes.get(&Checked::Valid(Semantic::Joints(set)));
            let weights = prim.attributes.get(&Checked::Valid(Semantic::Weights(set)));
            match (joints, weights) {
                (None, None) if set == 0 => {
                    return Err(self.fail(format!(
                        "{who} is on a node with skin '{}' but has no JOINTS_0/WEIGHTS_0",
                        skin.name
                    )));
                }
                (None, None) => break,
                (Some(j), Some(w)) => {
                    self.add_influences(j.value(), w.value(), set, who, skin, &mut out)?
                }
                _ => {
                    return Err(self.fail(format!(
                        "{who} has only one of JOINTS_{set} and WEIGHTS_{set}; they come in pairs"
                    )));
                }
            }
        }
        for (v, inf) in out.iter_mut().enumerate() {
            let sum: f32 = inf.iter().map(|&(_, w)| w).sum();
            if sum.is_nan() || sum <= 0.0 {
                return Err(self.fail(format!(
                    "{who}, vertex {v}: its weights sum to zero; every skinned vertex needs a \
                     positive weight"
                )));
            }
            inf.iter_mut().for_each(|(_, w)| *w /= sum);
        }
        Ok(out)
    }

    /// Adds one JOINTS_n/WEIGHTS_n set: zero weights dropped, repeated joints summed.
    fn add_influences(
        &self,
        joints: usize,
        weights: usize,
        set: u32,
        who: &str,
        skin: &Skin,
        out: &mut [Vec<(u32, f32)>],
    ) -> Result<()> {
        let j = self.uints(joints, &format!("{who} JOINTS_{set}"), Type::Vec4)?;
        let w = self.floats(weights, &format!("{who} WEIGHTS_{set}"), Type::Vec4)?;
        if j.len() != out.len() * 4 || w.len() != out.len() * 4 {
            return Err(self.fail(format!(
                "{who}: JOINTS_{set} has {} and WEIGHTS_{set} {} elements, but POSITION has {}",
                j.len() / 4,
                w.len() / 4,
                out.len()
            )));
        }
        for (v, inf) in out.iter_mut().enumerate() {
            for k in 4 * v..4 * v + 4 {
                if w[k] == 0.0 {
                    continue;
                }
                self.check_influence(j[k], w[k], v, who, skin)?;
                match inf.iter_mut().find(|(joint, _)| *joint == j[k]) {
                    Some((_, weight)) => *weight += w[k],
                    None => inf.push((j[k], w[k])),
                }
            }
        }
        Ok(())
    }

    /// A non-zero weight must be a positive number on a joint the skin has.
    fn check_influence(
        &self,
        joint: u32,
        weight: f32,
        v: usize,
        who: &str,
        skin: &Skin,
    ) -> Result<()> {
        if !weight.is_finite() || weight <= 0.0 {
            return Err(self.fail(format!(
                "{who}, vertex {v}: weight {weight} is negative or not finite"
            )));
        }
        if joint as usize >= skin.joints.len() {
            return Err(self.fail(format!(
                "{who}, vertex {v}: joint {joint} is out of range; skin '{}' has {} joints \
                 (0..={})",
                skin.name,
                skin.joints.len(),
                skin.joints.len().saturating_sub(1)
            )));
        }
        Ok(())
    }
}
