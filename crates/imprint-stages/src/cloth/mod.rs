//! Cloth (H §4-5, T §(2)): a mass-spring cloth pushed by the bodies' distance fields.
//!
//! Read in this order:
//! - [`params`]: what a pipeline file says (shape, material, pins, contact, substeps) and
//!   its validation;
//! - [`shape`]: the rest particles and faces of a grid or a garment mesh;
//! - [`springs`]: springs (H eq. 9 or T eq. 1), hinges (T eq. 2), faces, stored per
//!   particle (CSR) so that each particle gathers its own forces; [`lanes`]: the same
//!   springs eight particles at a time (SIMD); [`texture`]: T eq. 5's anisotropy map;
//! - [`cpu`]: the simulator, [`ClothSim`]: damped Verlet (H eq. 10) in substeps (H §5.2),
//!   deterministic on any number of threads; [`contact`]: projection out of the bodies with
//!   friction (H eq. 11-12), which side of an unsigned field a particle is on, and the fields
//!   blended in time (H §5.3); [`sampler`]: reading a field fast, with the field's numbers;
//!   [`contact_lanes`]: the contact with a body read from unsigned fields eight particles
//!   at a time, same bits; [`side`]: each particle's memory of which side of a body it is
//!   on, kept by blocks of eight;
//! - [`gpu`]: the same simulator on the GPU, [`gpu::GpuCloth`], one dispatch per substep;
//! - [`stability`]: the largest stable substep, predicted before running, and the stress
//!   map that checks it; [`metrics`]: what each frame reports.
//!
//! One-way coupling: the bodies push the cloth, never the reverse. A run never returns
//! garbage: a non-finite position, a spring stretched beyond `limits.max_stretch` or runaway
//! kinetic energy stops it with `Error::Numerical`, naming the frame, the substep and the
//! substeps (or stiffness) that would fix it.
//!
//! ```
//! use imprint_stages::cloth::{ClothParams, ClothSim, Material, Shape};
//! let params = ClothParams::new(
//!     Shape::Grid { size: [1.0, 1.0], resolution: [8, 8], center: Default::default(),
//!                   normal: glam::Vec3::Y },
//!     Material::Harada { k_structural: 50.0, k_shear: 10.0, k_bend: None },
//! );
//! let mut cloth = ClothSim::new(&params, std::path::Path::new(".")).unwrap();
//! assert!(cloth.stability().warning(params.substeps, 1.0 / 60.0).is_none());
//! let m = cloth.step_frame(&[], &[], 0, 1.0 / 60.0).unwrap();
//! assert!(m.kinetic > 0.0); // it falls
//! let mesh = cloth.to_mesh();
//! assert_eq!(mesh.positions.len(), 64);
//! ```

pub mod attach;
pub mod contact;
pub mod contact_lanes;
pub mod cpu;
pub mod gpu;
pub mod lanes;
pub mod metrics;
pub mod params;
pub mod sampler;
pub mod shape;
pub mod side;
pub mod springs;
pub mod stability;
pub mod stress;
pub mod texture;

pub use cpu::{Body, ClothAssets, ClothSim, ClothState};
pub use metrics::{ClothFrameMetrics, Energy};
pub use params::{
    Anisotropy, ClothParams, Collision, Limits, Material, Pin, Shape, StiffnessMode, Wind,
};
pub use stability::StabilityEstimate;
pub use stress::{StressCase, StressOutcome, stress_map};
pub use texture::AnisotropyMap;
