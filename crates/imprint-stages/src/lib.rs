//! imprint-stages: one module per stage, each with its parameters (serde), a CPU path (the
//! reference), a GPU path (wgpu compute, tested against the CPU), and its error metrics.
//! Stages know nothing of RON files or scheduling: the graph crate calls them.

mod bare_option;
pub mod checkpoint;
pub mod cloth;
pub mod depth;
pub mod drape;
pub mod ground;
pub mod mesh;
pub mod metrics;
pub mod sdf;
pub mod skin;
pub mod snow;
pub mod voxel;
