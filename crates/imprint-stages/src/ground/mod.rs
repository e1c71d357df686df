//! Ground deformation by contact (docs/methods.md §7, Onoue & Nishita, "O"): objects pressing into
//! a soft heightfield leave prints, with rims that slump (sand) or clean walls (snow).
//! The field persists across frames, so a body moving over it leaves a track.
//!
//! One frame, as O does it, and the choices we made where O is thin:
//! 1. **Contact** ([`contact`], O §2.1): each object's underside seen from below,
//!    orthographic, one pixel per cell (the depth views of [`crate::depth`]); a cell is in
//!    contact where the lowest object bottom over it is below the ground. O uses one depth
//!    buffer and a stencil; we rasterise each object over the cells under its bounds only,
//!    and keep the lowest bottom. The ground never goes below its base plane (height 0).
//! 2. **Inner contour map** ([`contour`], O §2.2): 0 outside the contact, and inside the
//!    distance from its edge growing inward. O's "next to" is read as sharing an edge, which
//!    makes the map the exact city-block (L1, 4-neighbour) distance; we compute it in two
//!    raster passes and test it against brute force.
//! 3. **Compression and displacement** (O §2.3): contact cells drop to the object's bottom;
//!    α of the removed height is passed from the deepest contour value outward, each cell
//!    sharing equally among its neighbours one level lower, to the rim (the first ring
//!    outside); the rest is compressed away. Shares are exact integers (the remainder goes
//!    one unit at a time in a fixed order), so with α = 1 mass is conserved exactly.
//! 4. **Outer contour map** (O §2.4): around the contact, the distance from it, rim = 0,
//!    for `slump_band` rings (O gives no width).
//! 5. **Settle** (the default, `Relaxation::Settle`, `settle.rs`): a work list that starts
//!    from every cell the frame changed (what the press changed, last frame's released
//!    contact, cells a layer was added to) slides whole units from a cell down a path from
//!    its steepest free lower neighbour, levelled in one move to a ramp of slope T, while a
//!    difference exceeds T + one unit, and queues what it touched, until nothing is steeper
//!    anywhere the ground changed. Material leaning on a body higher than the body's top
//!    (the top of its bounds) spills over the body to its far side: a heightfield cannot
//!    hold it on the body, so no cell rises above the start height plus the body's height.
//!    Cost grows with the cells that move (a heap carried n cells is one path, not a
//!    diffusion); each move lowers Σh², so it ends. O's slump below visits only this frame's labelled
//!    cells En times, which cannot spread what a dragged body pushes ahead of it (a dragged
//!    box left 35 cm steps between neighbours, `tests/ground_settle.rs`); it stays as
//!    `Relaxation::Labelled`.
//!
//!    **Slump** (O §2.5, `Labelled`): En passes from the rim outward; step k moves material over the
//!    edges of ring k (to ring k + 1, and along ring k) wherever a neighbour difference
//!    exceeds T = tan θ · cell, sharing each cell's excess so that nothing overshoots. Only
//!    labelled cells are visited. O moves material outward only; we also let it run along a
//!    ring and back inward where that is downhill, because the L1 displacement funnels the
//!    pressed-out material along the grid axes into a few rim cells, and outward-only
//!    slumping leaves those spikes standing (see [`GroundSim`]'s `slump_labelled`).
//!    `Relaxation::Full` applies the same rule (on matchings of neighbour pairs) over the
//!    whole field, in every direction, until nothing moves, for comparison: afterwards
//!    every slope is at most tan θ plus one height unit over a cell. Cells under an object
//!    are held in both modes: the object bears the walls; they slump once it has left.
//!
//! **Heights are fixed point**: `i32` multiples of `height_unit` (default 10 µm), so
//! material moves in whole units, mass is an exact integer sum, and every pass gives the same
//! integers whatever order cells are visited in. Passes read a snapshot and write after (or
//! touch disjoint pairs), with no data-dependent races: the planned GPU path runs each as a
//! dispatch over flat arrays and must match the CPU bit for bit.
//!
//! Presets (O §3): `Snow` θ = 90°, En = 0, α = 0; `Sand` θ = 30°, En = 5, α = 1.
//!
//! Read in this order: [`params`] (what a pipeline file says, and its validation);
//! [`contact`] (step 1, and the grid and window types); [`contour`] (steps 2 and 4);
//! [`cpu`] ([`GroundSim`]: steps 3 and 5, the `Full` relaxation, the heightmap loader);
//! `settle` (step 5's default);
//! [`metrics`] (what each frame reports).
//!
//! ```
//! use imprint_core::mesh::primitives::uv_sphere;
//! use imprint_stages::ground::{GroundParams, GroundSim, Material, Preset};
//! let mut p = GroundParams::new([1.0, 1.0], [64, 64], Material::Preset(Preset::Sand));
//! p.initial = imprint_stages::ground::Initial::Flat(0.1);
//! let mut ground = GroundSim::new(&p, std::path::Path::new(".")).unwrap();
//! let before = ground.mass();
//! let mut ball = uv_sphere(0.1, 32, 16);
//! ball.transform(glam::Mat4::from_translation(glam::Vec3::new(0.0, 0.15, 0.0)));
//! let m = ground.step(&[&ball]).unwrap();
//! assert!(m.contact_cells > 0 && m.removed_units > 0);
//! assert_eq!(ground.mass(), before); // α = 1: moved, never lost
//! ```

pub mod contact;
pub mod contour;
pub mod cpu;
pub mod gpu;
pub mod metrics;
pub mod params;
pub(crate) mod settle;

pub use contact::{Bottoms, GroundGrid, NO_OBJECT, Window};
pub use contour::{ContourMaps, UNLABELLED};
pub use cpu::GroundSim;
pub use metrics::GroundFrameMetrics;
/// The rise of a layer since the last frame, per cell (what a ground takes in when fresh snow
/// or anything else piles up on it; see [`GroundSim::add_heights`]).
pub fn rise(now: &imprint_core::HeightField, before: &imprint_core::HeightField) -> Vec<f32> {
    now.heights
        .iter()
        .zip(&before.heights)
        .map(|(n, b)| n - b)
        .collect()
}

pub use params::{GroundParams, Initial, Material, MaterialValues, Preset, Relaxation};
