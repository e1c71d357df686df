//! Voxelize (H §1, §6.1): conservative surface voxelisation into a discrete boundary.
//!
//! A cell is a surface cell when its closed box touches a triangle (separating-axis test in
//! grid coordinates, so triangles lying exactly on a cell face mark both cells and nothing thin
//! or axis-aligned slips between cells). Each surface cell gets one point: its centre (H) or,
//! by default, the closest point of the touching triangles to its centre (sub-voxel accurate).
//! Only surface positions are used, so open, flipped, duplicated or unwelded meshes all work.

pub mod cpu;
pub mod gpu;
pub mod solid;

pub use cpu::voxelize_cpu;
