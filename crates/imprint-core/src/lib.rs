//! imprint-core: the math and data every stage shares, with no knowledge of wgpu or the graph.
//!
//! - [`mesh`]: triangle meshes (OBJ loading through tobj, validation, procedural primitives);
//! - [`grid`]: the uniform cell grid ([`GridSpec`]) and dense 3D arrays ([`Grid3`]);
//! - [`geom`]: bounding boxes, closest point on a triangle, triangle/box overlap;
//! - [`bvh`]: an exact closest-point query on a mesh, the reference every error is measured against;
//! - [`camera`], [`raster`]: cameras and the CPU depth rasteriser (`DepthMap`), the reference for
//!   the depth-buffer methods (draping, snow, ground contact);
//! - [`field`]: the discrete boundary and distance-field resources;
//! - [`io`]: atomic file writing (nothing half-written under a final name);
//! - [`error`]: the error type and what each kind means as an exit code.

pub mod bvh;
pub mod camera;
pub mod error;
pub mod field;
pub mod geom;
pub mod grid;
pub mod heightfield;
pub mod io;
pub mod mesh;
pub mod raster;

pub use camera::Camera;
pub use error::{Error, Result};
pub use field::{Boundary, BoundaryVariant, DistanceField, FieldSample, Sampling};
pub use geom::Aabb;
pub use grid::{Grid3, GridSpec};
pub use heightfield::HeightField;
pub use mesh::Mesh;
pub use raster::DepthMap;

pub use glam;
