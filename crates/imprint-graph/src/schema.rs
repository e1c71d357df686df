//! The pipeline file as users write it (RON). Every struct rejects unknown fields, so a typo
//! is an error with its position rather than a silently ignored setting.

use imprint_core::BoundaryVariant;
use imprint_render::slice::SliceOptions;
use imprint_stages::cloth::ClothParams;
use imprint_stages::depth::HeightView;
use imprint_stages::drape::DrapeParams;
use imprint_stages::ground::GroundParams;
use imprint_stages::mesh::MeshParams;
use imprint_stages::snow::SnowParams;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(rename = "Pipeline", deny_unknown_fields)]
pub struct PipelineFile {
    /// Number of frames to run.
    pub frames: u32,
    /// Frames per second: frame f is at time f / fps seconds.
    #[serde(default = "default_fps")]
    pub fps: f32,
    #[serde(default)]
    pub backend: Backend,
    /// Seed for every stochastic stage (none yet in this version; kept for reproducibility).
    #[serde(default)]
    pub seed: u64,
    /// Nodes by name; each names its inputs by node name.
    pub nodes: BTreeMap<String, NodeSpec>,
}

fn default_fps() -> f32 {
    30.0
}

/// Where a node runs. `Auto` takes a hardware GPU when there is one, the CPU otherwise (a
/// software Vulkan adapter is never picked by `Auto`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
pub enum Backend {
    #[default]
    Auto,
    Cpu,
    Gpu,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum NodeSpec {
    /// A mesh from an OBJ file or a primitive, fitted and moved (output: Mesh).
    Mesh(MeshParams),
    /// Surface voxelisation into a discrete boundary (input: Mesh; output: Boundary).
    Voxelize(VoxelizeNode),
    /// Narrow-band distance field (input: Boundary; output: DistanceField).
    DistanceField(FieldNode),
    /// Writes a field per frame as .npy + JSON and PNG slices (input: DistanceField; a writer).
    WriteField(WriteFieldNode),
    /// Writes a mesh per frame as OBJ or PLY, for other tools (input: Mesh; a writer).
    WriteMesh(WriteMeshNode),
    /// A mass-spring cloth (Harada, or Tokoi's material) pushed by distance fields (inputs:
    /// DistanceField colliders; output: Mesh, so every mesh consumer takes it).
    Cloth(ClothNode),
    /// The heights of a mesh seen straight down or up through a depth buffer, one pixel per
    /// cell (input: Mesh; output: HeightField).
    Heightmap(HeightmapNode),
    /// Writes a height field per frame: 16-bit PNG + JSON sidecar, EXR, .npy, coloured
    /// preview (input: HeightField; a writer).
    WriteHeightmap(WriteHeightmapNode),
    /// Renders meshes, height fields and field slices to a PNG per frame, with an optional
    /// contact sheet and GIF of the run (inputs: Mesh, HeightField, DistanceField; a writer).
    Render(RenderNode),
    /// A deformable ground (Onoue & Nishita): objects pressed into it leave prints that last
    /// (inputs: Mesh objects; output: HeightField).
    Ground(GroundNode),
    /// Snow falling on meshes and, optionally, a flat ground (Tokoi): arrival by depth maps
    /// from jittered directions, accumulation, slides steeper than the repose angle (inputs:
    /// Mesh; output: with `ground`, the ground's surface with its snow as a HeightField;
    /// without, the first mesh with its snow as a Mesh).
    Snow(SnowNode),
    /// Tokoi's depth-buffer draping: a garment's vertices inside a body pushed out along the
    /// views' depth maps (a distance field for what no view resolves) (inputs: body and
    /// garment Mesh; output: the fitted garment as a Mesh).
    Drape(DrapeNode),
    /// A mesh deformed by a rig (Tokoi's particle skinning with adaptive radii, or linear
    /// blend or dual quaternion skinning) (input: the rest Mesh, or the rig's own binding;
    /// output: the posed Mesh, for any mesh consumer).
    Skin(SkinNode),
}

/// The Skin node: which mesh, which rig, which method.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SkinNode {
    /// The Mesh node in the rig's rest pose (its first frame is taken as the rest). Leave it
    /// out to load the OBJ the rig file binds (`mesh:` in the rig).
    #[serde(default)]
    pub mesh: Option<String>,
    /// The rig file (RON: bones, binding, animation), relative to the pipeline file.
    pub rig: String,
    /// `Particles(...)` (T, default parameters suit a limb of radius ~0.1 m),
    /// `Linear(...)` or `DualQuaternion(...)`.
    pub method: SkinMethod,
    /// Added to the output's positions (to stand several methods side by side), m.
    #[serde(default)]
    pub offset: (f32, f32, f32),
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// How a Skin node deforms its mesh.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum SkinMethod {
    /// Tokoi's particle skinning: `imprint_stages::skin::particles::ParticleParams`.
    Particles(#[serde(default)] imprint_stages::skin::particles::ParticleParams),
    /// Linear blend skinning with automatic weights.
    Linear {
        #[serde(default)]
        weights: imprint_stages::skin::weights::WeightMethod,
    },
    /// Dual quaternion skinning with automatic weights.
    DualQuaternion {
        #[serde(default)]
        weights: imprint_stages::skin::weights::WeightMethod,
    },
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DrapeNode {
    /// The Mesh node the garment must not enter (closed; it may deform).
    pub body: String,
    /// The Mesh node to fit (a garment mesh, or a Cloth node's output).
    pub garment: String,
    /// Views, resolution, offset, fallback: `imprint_stages::drape::DrapeParams`.
    #[serde(default)]
    pub params: DrapeParams,
    /// Where the views' depth maps are rendered; the pushes run on the CPU.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SnowNode {
    /// Mesh nodes the snow falls on; each also shades the others (and the ground).
    pub meshes: Vec<String>,
    /// A flat ground under the meshes that collects snow too; the node then outputs the
    /// ground's snow surface instead of the first mesh.
    #[serde(default)]
    pub ground: Option<SnowGround>,
    /// Direction, jitter, rate, repose angle, …: `imprint_stages::snow::SnowParams`.
    #[serde(default)]
    pub params: SnowParams,
    /// Where the K depth maps are rendered; deposit and slides run on the CPU.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// The flat ground a `Snow` node collects snow on (cells as a `Ground` node's, so a Ground
/// with the same grid can take the snow in with `accumulate`).
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SnowGround {
    /// Extent along x and z, m.
    pub size: (f32, f32),
    /// Cells along x and z (square cells).
    pub resolution: (u32, u32),
    /// World (x, z) of the centre of cell (0, 0); default: centred on the origin.
    #[serde(default)]
    pub origin: Option<(f32, f32)>,
    /// Height of the bare ground, m.
    #[serde(default)]
    pub height: f32,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GroundNode {
    /// Mesh nodes pressed into the ground every frame (seen from below; the ground does not
    /// push back).
    #[serde(default)]
    pub objects: Vec<String>,
    /// Grid, initial height, material (`Preset(Sand | Snow)` or custom), relaxation:
    /// `imprint_stages::ground::GroundParams`.
    pub params: GroundParams,
    /// A HeightField node (a `Snow` node's ground, on the same cells) whose rise from one
    /// frame to the next is added to this ground before the objects press into it: fresh
    /// snow that then takes prints.
    #[serde(default)]
    pub accumulate: Option<String>,
    /// Where the contact view (the depth map from below) is rendered; the passes run on the
    /// CPU.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ClothNode {
    /// DistanceField nodes the cloth collides with, applied in this order each substep.
    #[serde(default)]
    pub colliders: Vec<String>,
    /// Bodies the cloth collides with through depth maps (T's draping test every substep,
    /// `imprint_stages::drape::collider`), applied after `colliders` each substep. A cloth
    /// with depth colliders runs on the CPU.
    #[serde(default)]
    pub depth_colliders: Vec<DepthColliderNode>,
    /// Shape, material, pins, contact, substeps: `imprint_stages::cloth::ClothParams`.
    pub params: ClothParams,
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// A body read through depth maps by a cloth.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DepthColliderNode {
    /// The Mesh node of the body (any closed mesh, possibly deforming).
    pub body: String,
    /// Views and map resolution: `imprint_stages::drape::DepthColliderParams`.
    #[serde(default)]
    pub params: imprint_stages::drape::DepthColliderParams,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct HeightmapNode {
    /// The Mesh node to look at.
    pub mesh: String,
    /// `Above` (the top surface, default) or `Below` (the underside).
    #[serde(default)]
    pub view: HeightView,
    pub grid: HeightGrid,
    /// Height of cells the mesh does not cover.
    #[serde(default)]
    pub empty: f32,
    #[serde(default)]
    pub backend: Option<Backend>,
    /// Compute on frames where (frame - offset) mod every = 0 (and on the run's first
    /// frame); consumers reuse the last result in between.
    #[serde(default = "one")]
    pub every: u32,
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// The x-z cells of a Heightmap node.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum HeightGrid {
    /// Square cells, `resolution` along the longer x/z side of the box the mesh sweeps over
    /// the run, grown by `padding` (a fraction of that side) on every side.
    Fit {
        resolution: u32,
        #[serde(default = "default_padding")]
        padding: f32,
    },
    /// `origin` is the (x, z) centre of cell (0, 0).
    Explicit {
        origin: (f32, f32),
        cell: f32,
        dims: (u32, u32),
    },
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WriteHeightmapNode {
    /// The HeightField node to write.
    pub heights: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
    /// Files per frame, each `<heights>_<frame:04>.<ext>` (the preview `_preview.png`).
    #[serde(default = "default_heightmap_formats")]
    pub formats: Vec<HeightmapFormat>,
    /// Write every k-th frame (1 = every frame).
    #[serde(default = "one")]
    pub every: u32,
    /// Frames written are those where (frame - offset) mod every = 0.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// File formats of `WriteHeightmap`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize)]
pub enum HeightmapFormat {
    /// 16-bit grayscale PNG, heights mapped to the full range; the range is in a JSON
    /// sidecar so the file reads back to within one quantisation step.
    Png16,
    /// Single-channel 32-bit float OpenEXR (channel "Y"): exact heights.
    Exr,
    /// NumPy `.npy`, f32, shape (nz, nx): exact heights.
    Npy,
    /// 8-bit colour-mapped picture with a legend, for people.
    Preview,
}

fn default_heightmap_formats() -> Vec<HeightmapFormat> {
    vec![HeightmapFormat::Png16, HeightmapFormat::Preview]
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct VoxelizeNode {
    /// The Mesh node to voxelise.
    pub mesh: String,
    pub grid: GridChoice,
    /// `Closest` (sub-voxel, default) or `Centre` (H's voxel centres).
    #[serde(default)]
    pub variant: BoundaryVariant,
    #[serde(default)]
    pub backend: Option<Backend>,
    /// Compute on frames where (frame - offset) mod every = 0 (and on the run's first
    /// frame); consumers reuse the last result in between.
    #[serde(default = "one")]
    pub every: u32,
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// The grid a Voxelize node works on.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum GridChoice {
    /// Cubic cells, `resolution` along the longest side of the box the mesh sweeps over the run,
    /// grown by `padding` (a fraction of that side) on every side. The grid stays fixed.
    Fit {
        resolution: u32,
        #[serde(default = "default_padding")]
        padding: f32,
    },
    /// An explicit grid: `origin` is the centre of cell (0, 0, 0).
    Explicit {
        origin: (f32, f32, f32),
        cell: f32,
        dims: (u32, u32, u32),
    },
}

fn default_padding() -> f32 {
    0.1
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct FieldNode {
    /// The Voxelize node whose boundary the field is built from.
    pub boundary: String,
    /// Half-width of the band, in cells (H's `a`).
    #[serde(default = "default_band")]
    pub band: f32,
    #[serde(default)]
    pub backend: Option<Backend>,
    /// On which frames the error against the exact distance is measured (costly: one exact
    /// closest-point query per band cell).
    #[serde(default)]
    pub measure: Measure,
    /// Compute on frames where (frame - offset) mod every = 0 (and on the run's first
    /// frame); consumers reuse the last result in between.
    #[serde(default = "one")]
    pub every: u32,
    #[serde(default)]
    pub offset: u32,
    /// Spread each build over this many frames (z-slabs, the same field as one build);
    /// the result appears on the last of them. At most `every`.
    #[serde(default = "one")]
    pub split: u32,
    /// Consumers see the linear blend in time of the two builds around each frame (H eq.
    /// 13-14); builds are made `every` frames ahead, from the mesh at their own time, so the
    /// blend adds no lag. Needs the boundary's mesh to be a `Mesh` node (a function of time).
    #[serde(default)]
    pub interpolate: bool,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

fn default_band() -> f32 {
    3.0
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
pub enum Measure {
    Never,
    /// The first frame run.
    #[default]
    First,
    /// Every k-th frame run, starting with the first.
    Every(u32),
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WriteFieldNode {
    /// The DistanceField node to write.
    pub field: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
    /// Write `<name>_<frame>_dist.npy`, `_vec.npy` and `_field.json`.
    #[serde(default = "yes")]
    pub npy: bool,
    /// PNG slices per frame.
    #[serde(default)]
    pub slices: Vec<SliceOptions>,
    /// Write every k-th frame (1 = every frame).
    #[serde(default = "one")]
    pub every: u32,
    /// Frames written are those where (frame - offset) mod every = 0.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WriteMeshNode {
    /// The Mesh node to write.
    pub mesh: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
    #[serde(default)]
    pub format: MeshFormat,
    /// Write every k-th frame (1 = every frame).
    #[serde(default = "one")]
    pub every: u32,
    /// Frames written are those where (frame - offset) mod every = 0.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
}

/// File format of `WriteMesh`: OBJ (positions, normals, UVs where they exist) or binary PLY.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
pub enum MeshFormat {
    #[default]
    Obj,
    Ply,
}

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct RenderNode {
    /// What to draw, nearest surface wins.
    pub objects: Vec<RenderObject>,
    pub camera: CameraSpec,
    #[serde(default = "default_width")]
    pub width: u32,
    #[serde(default = "default_height")]
    pub height: u32,
    /// Supersampling per axis (1..=4): the CPU renderer's anti-aliasing.
    #[serde(default = "two")]
    pub samples: u32,
    /// A grid on the ground plane y = 0, for orientation.
    #[serde(default = "yes")]
    pub ground_grid: bool,
    /// File pattern under the run's output folder; `{frame:04}` (or `{frame}`) is replaced.
    #[serde(default = "default_pattern")]
    pub out: String,
    /// Render every k-th frame (1 = every frame).
    #[serde(default = "one")]
    pub every: u32,
    /// Frames written are those where (frame - offset) mod every = 0.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "yes")]
    pub enabled: bool,
    /// A grid of every k-th rendered frame in one PNG.
    #[serde(default)]
    pub contact_sheet: Option<ContactSheetSpec>,
    /// An animated GIF of the rendered frames, playing at the run's speed.
    #[serde(default)]
    pub gif: Option<GifSpec>,
    #[serde(default)]
    pub backend: Option<Backend>,
}

/// Where and how a Render node writes its contact sheet.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct ContactSheetSpec {
    /// Path under the run's output folder.
    #[serde(default = "default_sheet_path")]
    pub path: String,
    /// Take every k-th rendered frame.
    #[serde(default = "four")]
    pub every: u32,
    #[serde(default = "four")]
    pub columns: u32,
    /// Thumbnail width in pixels.
    #[serde(default = "default_thumb_width")]
    pub width: u32,
}

/// Where and how a Render node writes its GIF preview.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GifSpec {
    /// Path under the run's output folder.
    #[serde(default = "default_gif_path")]
    pub path: String,
    /// Take every k-th rendered frame.
    #[serde(default = "one")]
    pub every: u32,
    /// Frame width in pixels (frames are scaled down, never up).
    #[serde(default = "default_gif_width")]
    pub width: u32,
}

fn four() -> u32 {
    4
}
fn default_sheet_path() -> String {
    "contact_sheet.png".into()
}
fn default_thumb_width() -> u32 {
    320
}
fn default_gif_path() -> String {
    "preview.gif".into()
}
fn default_gif_width() -> u32 {
    480
}

fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}
fn two() -> u32 {
    2
}
fn default_pattern() -> String {
    "frames/{frame:04}.png".into()
}

/// One thing a Render node draws.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum RenderObject {
    /// A Mesh node's mesh, lit, in a linear RGB colour (0..1).
    Mesh {
        mesh: String,
        #[serde(default = "default_color")]
        color: (f32, f32, f32),
        #[serde(default)]
        wireframe: bool,
    },
    /// A plane of a DistanceField node's grid, colour-mapped (0 at the surface, band at the edge).
    FieldSlice {
        field: String,
        #[serde(default = "default_axis")]
        axis: imprint_render::slice::Axis,
        #[serde(default)]
        index: imprint_render::slice::SliceIndex,
    },
    /// A HeightField node's surface through its cell centres, lit like a mesh.
    HeightField {
        heights: String,
        #[serde(default = "default_ground_color")]
        color: (f32, f32, f32),
        #[serde(default)]
        wireframe: bool,
    },
}

fn default_ground_color() -> (f32, f32, f32) {
    (0.55, 0.6, 0.5)
}

fn default_color() -> (f32, f32, f32) {
    (0.8, 0.45, 0.35)
}
fn default_axis() -> imprint_render::slice::Axis {
    imprint_render::slice::Axis::Z
}

/// Where the camera is. Angles in degrees; `spin` turns an orbit at degrees per second.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum CameraSpec {
    Orbit {
        #[serde(default)]
        target: (f32, f32, f32),
        distance: f32,
        #[serde(default = "default_elevation")]
        elevation: f32,
        #[serde(default)]
        azimuth: f32,
        #[serde(default = "default_fov")]
        fov: f32,
        #[serde(default)]
        spin: f32,
    },
    LookAt {
        eye: (f32, f32, f32),
        #[serde(default)]
        target: (f32, f32, f32),
        #[serde(default = "default_fov")]
        fov: f32,
    },
}

fn default_elevation() -> f32 {
    20.0
}
fn default_fov() -> f32 {
    40.0
}

fn yes() -> bool {
    true
}
fn one() -> u32 {
    1
}

/// The resource types that flow along edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortType {
    Mesh,
    Boundary,
    DistanceField,
    HeightField,
}

impl std::fmt::Display for PortType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PortType::Mesh => "Mesh",
            PortType::Boundary => "Boundary",
            PortType::DistanceField => "DistanceField",
            PortType::HeightField => "HeightField",
        })
    }
}

impl NodeSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            NodeSpec::Mesh(_) => "Mesh",
            NodeSpec::Voxelize(_) => "Voxelize",
            NodeSpec::DistanceField(_) => "DistanceField",
            NodeSpec::WriteField(_) => "WriteField",
            NodeSpec::WriteMesh(_) => "WriteMesh",
            NodeSpec::Cloth(_) => "Cloth",
            NodeSpec::Heightmap(_) => "Heightmap",
            NodeSpec::WriteHeightmap(_) => "WriteHeightmap",
            NodeSpec::Render(_) => "Render",
            NodeSpec::Ground(_) => "Ground",
            NodeSpec::Snow(_) => "Snow",
            NodeSpec::Drape(_) => "Drape",
            NodeSpec::Skin(_) => "Skin",
        }
    }

    /// Typed input ports: (port name, node named, type expected).
    pub fn inputs(&self) -> Vec<(&'static str, &str, PortType)> {
        match self {
            NodeSpec::Mesh(_) => vec![],
            NodeSpec::Voxelize(v) => vec![("mesh", &v.mesh, PortType::Mesh)],
            NodeSpec::DistanceField(f) => vec![("boundary", &f.boundary, PortType::Boundary)],
            NodeSpec::WriteField(w) => vec![("field", &w.field, PortType::DistanceField)],
            NodeSpec::WriteMesh(w) => vec![("mesh", &w.mesh, PortType::Mesh)],
            NodeSpec::Cloth(c) => c
                .colliders
                .iter()
                .map(|f| ("colliders", f.as_str(), PortType::DistanceField))
                .chain(
                    c.depth_colliders
                        .iter()
                        .map(|d| ("depth_colliders", d.body.as_str(), PortType::Mesh)),
                )
                .collect(),
            NodeSpec::Heightmap(h) => vec![("mesh", &h.mesh, PortType::Mesh)],
            NodeSpec::Ground(g) => g
                .objects
                .iter()
                .map(|o| ("objects", o.as_str(), PortType::Mesh))
                .chain(
                    g.accumulate
                        .iter()
                        .map(|a| ("accumulate", a.as_str(), PortType::HeightField)),
                )
                .collect(),
            NodeSpec::Skin(k) => k
                .mesh
                .iter()
                .map(|m| ("mesh", m.as_str(), PortType::Mesh))
                .collect(),
            NodeSpec::Drape(d) => vec![
                ("body", &d.body, PortType::Mesh),
                ("garment", &d.garment, PortType::Mesh),
            ],
            NodeSpec::Snow(n) => n
                .meshes
                .iter()
                .map(|m| ("meshes", m.as_str(), PortType::Mesh))
                .collect(),
            NodeSpec::WriteHeightmap(w) => vec![("heights", &w.heights, PortType::HeightField)],
            NodeSpec::Render(r) => r
                .objects
                .iter()
                .map(|o| match o {
                    RenderObject::Mesh { mesh, .. } => ("objects", mesh.as_str(), PortType::Mesh),
                    RenderObject::FieldSlice { field, .. } => {
                        ("objects", field.as_str(), PortType::DistanceField)
                    }
                    RenderObject::HeightField { heights, .. } => {
                        ("objects", heights.as_str(), PortType::HeightField)
                    }
                })
                .collect(),
        }
    }

    /// The type of the node's output, or None for writers.
    pub fn output(&self) -> Option<PortType> {
        match self {
            NodeSpec::Mesh(_) => Some(PortType::Mesh),
            NodeSpec::Voxelize(_) => Some(PortType::Boundary),
            NodeSpec::DistanceField(_) => Some(PortType::DistanceField),
            NodeSpec::Cloth(_) => Some(PortType::Mesh),
            NodeSpec::Heightmap(_) | NodeSpec::Ground(_) => Some(PortType::HeightField),
            NodeSpec::Snow(n) if n.ground.is_some() => Some(PortType::HeightField),
            NodeSpec::Snow(_) | NodeSpec::Drape(_) | NodeSpec::Skin(_) => Some(PortType::Mesh),
            NodeSpec::WriteField(_)
            | NodeSpec::WriteMesh(_)
            | NodeSpec::WriteHeightmap(_)
            | NodeSpec::Render(_) => None,
        }
    }

    pub fn is_writer(&self) -> bool {
        self.output().is_none()
    }

    /// Whether the node has a GPU path (the others always run on the CPU).
    pub fn has_gpu_path(&self) -> bool {
        match self {
            NodeSpec::Voxelize(_)
            | NodeSpec::DistanceField(_)
            | NodeSpec::Heightmap(_)
            | NodeSpec::Render(_)
            | NodeSpec::Ground(_)
            | NodeSpec::Snow(_)
            | NodeSpec::Drape(_) => true,
            // The GPU cloth reads distance fields only.
            NodeSpec::Cloth(c) => c.depth_colliders.is_empty(),
            NodeSpec::Skin(_) => true,
            NodeSpec::Mesh(_)
            | NodeSpec::WriteField(_)
            | NodeSpec::WriteMesh(_)
            | NodeSpec::WriteHeightmap(_) => false,
        }
    }

    /// The per-node backend override, for nodes that have two paths.
    pub fn backend(&self) -> Option<Backend> {
        match self {
            NodeSpec::Voxelize(v) => v.backend,
            NodeSpec::DistanceField(f) => f.backend,
            NodeSpec::Heightmap(h) => h.backend,
            NodeSpec::Render(r) => r.backend,
            NodeSpec::Cloth(c) => c.backend,
            NodeSpec::Ground(g) => g.backend,
            NodeSpec::Snow(n) => n.backend,
            NodeSpec::Drape(d) => d.backend,
            NodeSpec::Skin(k) => k.backend,
            _ => None,
        }
    }
}
