//! Skin: deforming a mesh by a rig (docs/methods.md §6, T §(3)): particle-based skinning with
//! adaptive radii, beside linear blend (LBS) and dual quaternion (DQS) skinning.
//!
//! - [`rig`]: bones (head, tail, parent), the rest pose, keyframed and procedural animation,
//!   and the pose at a time (per-bone skinning transforms).
//! - [`skeleton`]: a rig RON or a glTF skin and clip behind one interface: names, parents,
//!   rest segments, the pose at a time, the file's weights.
//! - [`weights`]: automatic weights for the blends, or a file's.
//! - [`blend`]: LBS and DQS.
//! - [`gpu`]: LBS and DQS as a compute dispatch, tested against [`blend`].
//! - [`fill`]: the adaptive close-packed particle fill.
//! - [`particles`]: the particle skinning simulation and its vertices.
//! - `rotation_lanes`, `pair_lanes`: the particles' rotations and volume changes, and the
//!   pairs' forces, eight particles at a time, the same bits as [`particles`] one at a time.
//! - [`gpu_particles`]: the same substeps and vertices on the GPU, tested against
//!   [`particles`].
//! - [`measure`]: volume, joint cross-section and self-intersection of a skinned mesh.
//! - [`check`]: no particle beyond its reach (the self-check; the substeps test it too).

pub mod blend;
pub mod check;
pub mod fill;
pub mod gpu;
pub mod gpu_particles;
pub mod measure;
mod pair_lanes;
pub mod particles;
pub mod rig;
mod rotation_lanes;
pub mod skeleton;
pub mod weights;
