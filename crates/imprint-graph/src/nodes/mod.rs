//! One module per node kind: its fields as the file gives them, its [`crate::node::Node`]
//! description and its [`crate::node::Stage`].

pub mod cloth;
pub mod distance_field;
pub mod drape;
pub mod ground;
pub mod heightmap;
pub mod mesh;
pub mod render;
pub mod skin;
pub mod snow;
pub mod voxelize;
pub mod write_field;
pub mod write_heightmap;
pub mod write_mesh;

pub use cloth::{ClothNode, DepthColliderNode};
pub use distance_field::{FieldNode, Measure};
pub use drape::DrapeNode;
pub use ground::GroundNode;
pub use heightmap::{HeightGrid, HeightmapNode};
pub use render::{CameraSpec, ContactSheetSpec, GifSpec, RenderNode, RenderObject};
pub use skin::{SkinMethod, SkinNode};
pub use snow::{SnowGround, SnowNode};
pub use voxelize::{GridChoice, VoxelizeNode};
pub use write_field::WriteFieldNode;
pub use write_heightmap::{HeightmapFormat, WriteHeightmapNode};
pub use write_mesh::{MeshFormat, WriteMeshNode};
