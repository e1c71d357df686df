//! imprint-core: the math and data every stage shares, with no knowledge of wgpu or the graph.
//!
//! - [`mesh`]: triangle meshes (OBJ loading through tobj, validation, procedural primitives);
//! - [`mesh_formats`]: [`load_mesh`], any supported mesh file (OBJ, PLY, STL, glTF) by content;
//! - [`grid`]: the uniform cell grid ([`GridSpec`]) and dense 3D arrays ([`Grid3`]);
//! - [`geom`]: bounding boxes, closest point on a triangle, triangle/box overlap;
//! - [`closest`]: closest points on triangles 32 pairs at a time, the scalar function's bits;
//! - [`buckets`]: items grouped by a small integer key in the order they came (a counting sort);
//! - [`bvh`]: an exact closest-point query on a mesh, the reference every error is measured against;
//! - [`camera`], [`raster`]: cameras and the CPU depth rasteriser (`DepthMap`), the reference for
//!   the depth-buffer methods (draping, snow, ground contact);
//! - [`gltf`]: glTF 2.0 input: the skinned mesh, its skin and clips, and posing them by
//!   linear blend skinning;
//! - [`field`]: the discrete boundary and distance-field resources;
//! - [`lanes`]: eight values at a time (the lane type, masks, selects, lane bits);
//! - [`cache`]: prefetch hints for loops that gather from scattered addresses;
//! - [`pool`]: scratch buffers the tasks of a parallel pass take and give back;
//! - [`io`]: atomic file writing (nothing half-written under a final name);
//! - [`error`]: the error type and what each kind means as an exit code.

pub mod buckets;
pub mod bvh;
pub mod cache;
pub mod camera;
pub mod closest;
pub mod error;
pub mod field;
pub mod geom;
pub mod gltf;
pub mod grid;
pub mod heightfield;
pub mod io;
pub mod lanes;
pub mod mesh;
pub mod mesh_formats;
pub mod pool;
pub mod raster;

pub use camera::Camera;
pub use error::{Error, Result};
pub use field::{Boundary, BoundaryVariant, DistanceField, FieldSample, Sampling};
pub use geom::Aabb;
pub use grid::{Grid3, GridSpec};
pub use heightfield::HeightField;
pub use mesh::Mesh;
pub use mesh_formats::load_mesh;
pub use raster::DepthMap;

pub use glam;
