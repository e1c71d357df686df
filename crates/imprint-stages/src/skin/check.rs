//! The particle skin's self-check: no particle beyond its reach.
//!
//! **Reach** (docs/methods.md §6, force (c)): each particle is pulled toward its target, the
//! point its bone's skinning transform gives its rest position; springs to its neighbours
//! and the bone's motion pull it off by a lag (about `bone_damping / bone_stiffness` seconds of the
//! bone's motion) and a joint's shear, never by a sizeable part of the body. The model allows
//! [`ParticleParams::max_deviation`](super::particles::ParticleParams::max_deviation) × the
//! rest mesh's box diagonal; farther, the explicit integration has left its stable range
//! (such an error grows geometrically) or the state is not one the simulation made.
//!
//! **Hard error, always.** No approximation of the model puts a particle there.
//! - While stepping, [`ParticleSkin::step_frame`] (and the GPU's substeps) test every particle
//!   after every substep: a blow-up, with the substeps to raise.
//! - [`ParticleSkin::check_reach`] tests a state against a pose without stepping: what a
//!   checkpoint gave, before the first frame after it (a damaged checkpoint, or one taken with
//!   another rig, would otherwise be reported as a blow-up, with the wrong remedy).
//!
//! Cost: one transform per particle (a substep costs three passes with ~10 pairs each).

use super::particles::ParticleSkin;
use glam::Affine3A;
use imprint_core::{Error, Result};

impl ParticleSkin {
    /// The reach: how far a particle may be from its bone's target, m
    /// (`max_deviation` × the rest mesh's box diagonal).
    pub fn reach(&self) -> f32 {
        self.gpu_deviation_limit()
    }

    /// Checks that every particle is within [`ParticleSkin::reach`] of the target the bones'
    /// skinning transforms `pose` give it: `Err(Error::Numerical)` (node "skin", frame 0: a
    /// graph node names itself and its frame) naming the first particle beyond it.
    pub fn check_reach(&self, pose: &[Affine3A]) -> Result<()> {
        let bones = self.particle_bones();
        if let Some(&b) = bones.iter().find(|&&b| b as usize >= pose.len()) {
            return Err(Error::Invalid(format!(
                "particle skinning: a particle is tied to bone {b}, but the pose has {} bones",
                pose.len()
            )));
        }
        let limit = self.reach();
        let (x, rest) = (self.positions(), self.rest_positions());
        let beyond = (0..x.len()).find_map(|i| {
            let target = pose[bones[i] as usize].transform_point3(rest[i]);
            let d = x[i].distance(target);
            // NaN positions are beyond too.
            (d > limit || d.is_nan()).then_some((i, d))
        });
        match beyond {
            None => Ok(()),
            Some((i, d)) => Err(Error::Numerical {
                node: "skin".into(),
                frame: 0,
                message: format!(
                    "particle {i} (bone {}) is {d} m from its bone's target, beyond the reach \
                     the skin allows ({limit} m: max_deviation {} × the rest mesh's box \
                     diagonal), before this frame's substeps",
                    bones[i],
                    self.params().max_deviation
                ),
                hint: "start the run again from its first frame (without --resume: a damaged \
                       checkpoint, or one taken with another rig or mesh, gives such a state)"
                    .into(),
            }),
        }
    }
}
