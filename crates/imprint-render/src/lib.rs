//! imprint-render: turning resources into files people and tools read. No physics here.
//!
//! - [`npy`]: NumPy `.npy` arrays (f32, u16, u8) through npyz, so fields load with `numpy.load`;
//! - [`field_io`]: a distance field as `_dist.npy`, `_vec.npy` and a `_field.json`;
//! - [`colormap`]: viridis (sequential) and RdBu (diverging) colour tables;
//! - [`text`]: labels on pictures, drawn by ab_glyph in the DejaVu Sans shipped in `assets/fonts/`;
//! - [`slice`](mod@slice): a PNG of one grid plane of a distance field, with a legend (H Fig. 1/4);
//! - [`frame`]: the CPU frame renderer (meshes, field slices, sun + ambient, ground grid,
//!   wireframe, supersampling);
//! - [`gpu_frame`]: the same frames on the GPU ([`gpu_frame::GpuRenderer`]), checked against
//!   the CPU renderer;
//! - [`png`]: PNG output;
//! - [`sequence`]: a contact sheet and an animated GIF of a run.
//!
//! Every file is written through `imprint_core::io::atomic_write`: a reader never finds a
//! half-written file under its final name.

pub mod colormap;
pub mod field_io;
pub mod frame;
pub mod gpu_frame;
pub mod heightmap;
pub mod mesh_io;
pub mod npy;
pub mod png;
pub mod sequence;
pub mod slice;
pub mod text;

pub use colormap::Colormap;
pub use field_io::{FieldMeta, write_field};
pub use frame::{GroundGrid, Lights, Object, RenderOptions, Scene, orbit, render_cpu};
pub use npy::{read_npy_f32, write_npy_f32};
pub use png::write_png;
pub use slice::{Axis, SliceIndex, SliceOptions, render_field_slice, write_field_slice};
