//! The snow checks itself after each step: no receiver holds more snow than fell.
//!
//! **What fell** ([`Fallen`], kept by [`SnowSim`] from step to step):
//! - *per mesh vertex*: Σ rate · dt over the steps, summed in f32 as the deposit adds to a
//!   depth. A vertex gains rate · dt · P · cos φ a step with P ≤ 1 and cos φ ≤ 1, and mesh snow
//!   is never stabilised, so no vertex can be deeper than that (the open-sky depth);
//! - *on the ground*: the quanta the deposit added to the field, summed over the steps. The
//!   ground's snow is stabilised (it slides to lower cells, so one cell may well hold more than
//!   fell on it): the bound is on the total, which the stabilisation moves in whole quanta and
//!   never makes.
//!
//! **Hard error or count.** Beyond the rounding below, more snow than fell is a broken
//! invariant (a stabilisation that made snow, a corrupted checkpoint): [`Error::Numerical`].
//! Within it, it is f32 rounding and is counted ([`SnowCheck`]):
//! - a vertex facing the fall under open sky gains rate · dt · cos φ with a unit normal of
//!   length 1 ± a few ulps, summed in f32 step by step like the bound itself: it may end a few
//!   ulps per step above it ([`MESH_ULPS_PER_STEP`]);
//! - the ground's total is summed in f64 from u32 quanta and f32 remainders
//!   ([`GROUND_REL_TOL`]).
//!
//! Cost: one pass over the mesh depths and one over the ground's cells per step (the deposit
//! already makes two).

use super::cpu::SnowSim;
use imprint_core::{Error, Result};
use serde::{Deserialize, Serialize};

/// The rounding a vertex's depth may carry above the bound, in f32 ulps (relative) per step:
/// its normal's length (1 ± 2 ulps), the product rate · dt · P · cos φ (2 ulps), and the sums
/// of depth and bound rounding apart (2 ulps).
pub const MESH_ULPS_PER_STEP: f32 = 6.0;

/// The ground's total may exceed what fell by this fraction (f64 sums of the remainders).
pub const GROUND_REL_TOL: f64 = 1e-9;

/// What has fallen so far (see the module doc).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Fallen {
    /// Steps taken.
    pub steps: u64,
    /// Σ rate · dt, m, summed in f32: the deepest a mesh vertex's snow can be.
    pub depth: f32,
    /// Quanta the deposit added to the ground (whole quanta and remainders).
    pub ground_quanta: f64,
}

/// What [`SnowSim::check`] found within the rounding (beyond it, it is an error).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct SnowCheck {
    /// Mesh vertices deeper than what fell by no more than the rounding.
    pub vertices_over: usize,
    /// The ground's snow above what fell (within the rounding), quanta; 0 when not above.
    pub ground_over_quanta: f64,
}

impl SnowCheck {
    /// Whether anything was above its bound (within the rounding).
    pub fn any(&self) -> bool {
        self.vertices_over > 0 || self.ground_over_quanta > 0.0
    }
}

impl SnowSim {
    /// No receiver holds more snow than fell (see the module doc): `Ok` with what is above
    /// its bound within the rounding, or [`Error::Numerical`] (node "snow", the step count as
    /// frame; a graph node names itself and its frame) naming the first vertex or the ground.
    pub fn check(&self) -> Result<SnowCheck> {
        let f = self.fallen();
        let mut out = SnowCheck::default();
        let slack = f.depth * (MESH_ULPS_PER_STEP * f32::EPSILON * f.steps.max(1) as f32);
        for m in 0..self.mesh_count() {
            for (v, &d) in self.mesh_depth(m).iter().enumerate() {
                // A NaN depth falls through to the error (the depths are not an output the
                // executor's finiteness check sees).
                if d <= f.depth {
                    continue;
                }
                if d <= f.depth + slack {
                    out.vertices_over += 1;
                    continue;
                }
                return Err(broken(
                    f.steps,
                    format!(
                        "mesh {m}'s vertex {v} holds {d} m of snow, more than fell in {} steps \
                         ({} m: rate × time, the depth under open sky facing the fall)",
                        f.steps, f.depth
                    ),
                ));
            }
        }
        if let Some(g) = self.ground() {
            let total = g.total_quanta();
            let fell = f.ground_quanta;
            let over = total - fell;
            let tol = GROUND_REL_TOL * (fell + g.units.len() as f64);
            if over > tol || over.is_nan() {
                return Err(broken(
                    f.steps,
                    format!(
                        "the ground holds {:.6e} m³ of snow, more than fell on it in {} steps \
                         ({:.6e} m³); the stabilisation moves snow, it never makes it",
                        g.quanta_volume(total),
                        f.steps,
                        g.quanta_volume(fell)
                    ),
                ));
            }
            if over > 0.0 {
                out.ground_over_quanta = over;
            }
        }
        Ok(out)
    }
}

/// More snow than fell, beyond rounding: the state is broken, not the parameters.
fn broken(steps: u64, message: String) -> Error {
    Error::Numerical {
        node: "snow".into(),
        frame: steps.min(u32::MAX as u64) as u32,
        message,
        hint: "start the run again from its first frame (without --resume: a checkpoint \
               from another version, or damaged, gives such a state); if it happens from the \
               start, it is a bug in the snow stage: please report it with the pipeline"
            .into(),
    }
}
