//! The pipeline file as users write it (RON). Every struct rejects unknown fields, so a typo
//! is an error with its position rather than a silently ignored setting. Each node kind's
//! fields live in its module under [`crate::nodes`]; this enum is the one place that lists
//! the kinds.

pub use crate::node::{Backend, PortType};
use crate::node::{Node, Port};
pub use crate::nodes::*;
use imprint_stages::mesh::MeshParams;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(rename = "Pipeline", deny_unknown_fields)]
pub struct PipelineFile {
    /// Number of frames to run.
    pub frames: u32,
    /// Frames per second: frame f is at time f / fps seconds.
    #[serde(default = "default_fps")]
    pub fps: f32,
    /// Where nodes run unless their own `backend` says: `Auto`, `Cpu` or `Gpu` (the
    /// command line's `--backend` overrides both).
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

/// Declares [`NodeSpec`], one variant per node kind with the type of its fields, its one
/// dispatch to the kind's module ([`NodeSpec::node`]) and the list of kinds
/// ([`NodeSpec::KINDS`]).
macro_rules! node_kinds {
    ($($(#[$doc:meta])* $kind:ident($spec:ty),)*) => {
        /// A node of the file: its kind and fields.
        #[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
        pub enum NodeSpec {
            $($(#[$doc])* $kind($spec),)*
        }

        impl NodeSpec {
            /// Every node kind, as the file spells it, in this list's order (for messages:
            /// generated here, so it cannot fall behind the kinds).
            pub const KINDS: &'static [&'static str] = &[$(stringify!($kind),)*];

            /// The node's module: the one dispatch on the kind.
            pub fn node(&self) -> &dyn Node {
                match self {
                    $(NodeSpec::$kind(n) => n,)*
                }
            }
        }
    };
}

// Adding a node kind: its module in `nodes/` (registered there with `pub mod`) and a line here.
node_kinds! {
    /// A mesh from a file (OBJ, PLY, STL, glTF) or a primitive, fitted and moved (output: Mesh).
    Mesh(MeshParams),
    /// Surface voxelisation into a discrete boundary (input: Mesh; output: Boundary).
    Voxelize(VoxelizeNode),
    /// Narrow-band distance field (input: Boundary; output: DistanceField).
    DistanceField(FieldNode),
    /// Writes a field per frame as .npy + JSON and PNG slices (input: DistanceField; a writer).
    WriteField(WriteFieldNode),
    /// Writes a mesh per frame as OBJ or PLY, or the whole run as one animated GLB, for
    /// other tools (input: Mesh; a writer).
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

impl NodeSpec {
    pub fn kind(&self) -> &'static str {
        self.node().kind()
    }

    pub fn inputs(&self) -> Vec<Port<'_>> {
        self.node().inputs()
    }

    pub fn output(&self) -> Option<PortType> {
        self.node().output()
    }

    pub fn is_writer(&self) -> bool {
        self.output().is_none()
    }

    pub fn enabled(&self) -> bool {
        self.node().enabled()
    }

    pub fn schedule(&self) -> crate::schedule::Schedule {
        self.node().schedule()
    }

    pub fn has_gpu_path(&self) -> bool {
        self.node().has_gpu_path()
    }

    pub fn backend(&self) -> Option<Backend> {
        self.node().backend()
    }
}

/// Serde defaults shared by the node modules.
pub(crate) mod defaults {
    pub fn yes() -> bool {
        true
    }
    pub fn one() -> u32 {
        1
    }
    pub fn one_f32() -> f32 {
        1.0
    }
    pub fn padding() -> f32 {
        0.1
    }
}
