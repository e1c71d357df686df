//! Snow (T §(1), docs/methods.md §5): snow falling on a scene, found like a shadow, piled up over
//! time, slid down slopes steeper than its angle of repose, and shown by displacing the
//! surfaces it lies on.
//!
//! **T's method.** Snow reaches a point when nothing stands between it and the sky in the
//! direction the snow comes from, which is the question a shadow map answers: render the
//! scene's depth looking along the fall, and a point is reached when it is the first surface
//! the map sees. Rendering from several jittered directions (irregular fall, wind) gives each
//! point an arrival probability. Snow accumulates over time in proportion to it, is
//! stabilised by a particle-deposition model (snow on slopes steeper than its repose angle
//! slides to lower neighbours), and displaces the surface for display.
//!
//! **Where T is thin, and what we chose** (each in the module that does it):
//! - *the jitter* ([`arrival::fall_directions`]): K directions on a cone of half-angle
//!   `jitter_degrees` around the fall, evenly spaced in azimuth and turned by a hash of
//!   `seed`. Beside a straight roof edge at height H the expected coverage of a ground point
//!   at signed distance x outside the edge is F(x / (H tan α)), F(a) = 1/2 + asin(a)/π for
//!   |a| ≤ 1 (0 below, 1 above), and K evenly spaced azimuths are within 1/K of it;
//! - *the depth bias* ([`arrival`]): `texel × (bias_texels + min(tan β, 8))`, β the angle
//!   between the normal and the fall, and only points facing the fall can be reached;
//! - *how much snow* ([`cpu`]): depth += rate · dt · P · cos φ along the normal, φ between the
//!   normal and the fall: a flux through a tilted patch is spread over a larger area, so a
//!   slope's layer is thinner by cos φ while its vertical thickness stays that of flat ground;
//! - *T's accumulation buffer* (found deprecated by T): plain per-receiver buffers (f32 depth
//!   per mesh vertex; whole quanta of 2^-16 m per ground cell plus an f32 remainder);
//! - *the particle-deposition model* ([`relax`]): on the ground height field only, Jacobi
//!   passes over a 16-neighbour stencil that move whole quanta from a cell to its neighbours
//!   lower than the repose slope allows, computed from a snapshot and gathered, so the total
//!   is conserved exactly and the order of cells does not matter (the shape of a WGSL port);
//!   a point pour settles to the cone of height (3V tan²θ / π)^(1/3);
//! - *the receivers*: per mesh vertex (output: depths and the mesh displaced along its
//!   normals) and per ground cell (output: the ground height field with the snow added, on
//!   which a `Ground` node then prints objects into fresh snow).
//!
//! Read in this order: [`params`] (what a pipeline file says), [`arrival`] (depth maps and
//! probabilities), [`cpu`] (deposit and outputs, [`SnowSim`]), [`relax`] (stabilisation),
//! [`gpu`] (the stabilisation on the GPU, bit-identical to [`relax`], and the arrival
//! look-ups), [`check`] (after each step: no more snow than fell).
//!
//! ```
//! use imprint_stages::snow::{SnowParams, SnowSim};
//! use imprint_core::{HeightField, mesh::primitives::uv_sphere};
//! use glam::{UVec2, Vec2, Vec3};
//! let params = SnowParams { resolution: 64, directions: 4, ..Default::default() };
//! let ground = HeightField::constant(Vec2::splat(-1.0), 0.1, UVec2::new(21, 21), 0.0).unwrap();
//! let mut ball = uv_sphere(0.4, 16, 8);
//! ball.transform(glam::Mat4::from_translation(Vec3::new(0.0, 0.8, 0.0)));
//! let mut snow = SnowSim::new(&params).unwrap();
//! for _ in 0..10 {
//!     snow.step(&[&ball], Some(&ground), 0.1).unwrap();
//! }
//! let cover = snow.cover(&[&ball]).unwrap();
//! let g = cover.ground.unwrap();
//! // 1 cm/s for 1 s in the open; less under the ball, which shields the ground beneath it.
//! assert!((g.thickness.get(0, 0) - 0.01).abs() < 1e-4);
//! assert!(g.thickness.get(10, 10) < 0.005);
//! assert!(cover.meshes[0].depth[0] > 0.009); // the ball's top vertex
//! ```

pub mod arrival;
pub mod check;
pub mod cpu;
pub mod gpu;
pub mod params;
pub mod relax;

pub use arrival::{Arrival, Receivers, fall_directions};
pub use check::{Fallen, SnowCheck};
pub use cpu::{GroundCover, GroundSnow, MeshSnow, SnowCover, SnowSim, SnowStep};
pub use params::SnowParams;
pub use relax::{QUANTUM, RelaxReport};

/// What a Snow node reports per frame.
#[derive(Clone, Debug, serde::Serialize)]
pub struct SnowFrameMetrics {
    pub frame: u32,
    /// Receivers reached from at least one direction.
    pub reached: usize,
    /// Snow on the ground, m³ (with a ground).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ground_snow_volume: Option<f64>,
    /// The deepest snow on the first mesh, m.
    pub mesh_max_depth: f32,
}

impl SnowSim {
    /// The frame's figures after [`SnowSim::step`] gave `step`.
    pub fn frame_metrics(&self, frame: u32, step: &SnowStep) -> SnowFrameMetrics {
        SnowFrameMetrics {
            frame,
            reached: step.reached,
            ground_snow_volume: self.ground().map(|g| g.volume()),
            mesh_max_depth: self.mesh_depth(0).iter().copied().fold(0.0f32, f32::max),
        }
    }
}

/// A flat ground of `resolution` square cells over `size` (x, z) at `height`, centred on the
/// origin unless `origin` (the centre of cell (0, 0)) is given.
pub fn flat_ground(
    size: (f32, f32),
    resolution: (u32, u32),
    origin: Option<(f32, f32)>,
    height: f32,
) -> imprint_core::Result<imprint_core::HeightField> {
    use imprint_core::Error;
    let (nx, nz) = resolution;
    if nx == 0 || nz == 0 {
        return Err(Error::Invalid(format!(
            "ground resolution must be at least 1 x 1, got {nx} x {nz}"
        )));
    }
    let cell = size.0 / nx as f32;
    if !(cell.is_finite() && cell > 0.0) || (size.1 / nz as f32 - cell).abs() > 1e-6 * cell {
        return Err(Error::Invalid(format!(
            "ground cells must be square: size ({}, {}) over resolution ({nx}, {nz}) gives \
             {} x {}",
            size.0,
            size.1,
            cell,
            size.1 / nz as f32
        )));
    }
    let origin = match origin {
        Some((x, z)) => glam::Vec2::new(x, z),
        None => glam::Vec2::new(-size.0, -size.1) * 0.5 + glam::Vec2::splat(cell * 0.5),
    };
    imprint_core::HeightField::new(
        origin,
        cell,
        glam::UVec2::new(nx, nz),
        vec![height; nx as usize * nz as usize],
    )
}
