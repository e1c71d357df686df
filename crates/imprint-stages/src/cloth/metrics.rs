//! What a cloth frame reports: how stretched, how close to the bodies, how energetic.

use serde::Serialize;

/// Energy of the cloth, J. Springs, bending and gravity are averaged over the current and
/// previous positions and kinetic energy comes from their difference (see
/// [`super::ClothSim::energy`]). Gravity's zero is at the origin; pinned particles carry none.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct Energy {
    pub kinetic: f64,
    pub springs: f64,
    pub bending: f64,
    pub gravity: f64,
}

impl Energy {
    pub fn total(&self) -> f64 {
        self.kinetic + self.springs + self.bending + self.gravity
    }

    pub fn add(&mut self, o: &Energy) {
        self.kinetic += o.kinetic;
        self.springs += o.springs;
        self.bending += o.bending;
        self.gravity += o.gravity;
    }
}

/// One frame of the cloth stage.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct ClothFrameMetrics {
    pub frame: u32,
    pub substeps: u32,
    /// Seconds per substep.
    pub dt_substep: f32,
    /// Largest |length / rest - 1| over the springs at the frame's end.
    pub max_strain: f32,
    /// Particles the last substep moved out of a body's ε shell (or off the ground): the
    /// cloth resting on or pushed by something.
    pub contacts: u32,
    /// Most particles found *inside* a body (crossed its surface) in one substep of the
    /// frame; 0 when the substeps keep up with the bodies.
    pub inside: u32,
    /// Largest ε - signed distance a projection fixed during the frame (> ε: from inside).
    pub max_depth: f32,
    /// After the frame, against the end-of-frame fields: free particles closer than ε...
    pub close: u32,
    /// ...and how much closer, at most (the projection's residual: interpolation, or a later
    /// collider pushing into an earlier one).
    pub close_max_depth: f32,
    /// Largest |x_next - 2 x + x_prev| / dt² of a free particle over the frame's substeps,
    /// m/s²: contact jerks show here.
    pub max_accel: f32,
    /// Particle-substeps in contact where the time blend mixed a far sample with a near one:
    /// a body moved farther than its field's band in one frame, and the contact there is
    /// unreliable. Widen the field's band beyond the bodies' motion per frame plus ε.
    pub band_misses: u32,
    pub kinetic: f64,
    pub energy: Energy,
    /// Total energy minus the total at the end of the first frame stepped.
    pub energy_drift: f64,
    /// `energy_drift` / |that first total| (0 when it is 0).
    pub energy_drift_rel: f64,
}

/// What a GPU frame reports: the subset of [`super::ClothFrameMetrics`] that per-particle
/// flags give without a reduction on the GPU, and the residual contacts, measured on the GPU
/// after the frame's last substep. [`super::ClothSim::adopt_gpu_frame_resident`] completes it
/// (strain, energies) from the state read back once per frame without any field on the CPU;
/// [`super::ClothSim::adopt_gpu_frame`] does the same but measures the residual contacts again on
/// the CPU against CPU copies of the end-of-frame fields.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct GpuClothFrameMetrics {
    pub frame: u32,
    pub substeps: u32,
    pub dt_substep: f32,
    /// Contacts (collider and ground hits) in the last substep, as on the CPU.
    pub contacts: u32,
    /// Sum over particles of each one's most hits from inside in one substep: at least the
    /// CPU's `inside` (the most in one substep), and 0 exactly when it is 0.
    pub inside: u32,
    pub max_depth: f32,
    pub max_accel: f32,
    pub band_misses: u32,
    /// Kinetic energy of the last substep (free particles), J.
    pub kinetic: f64,
    /// Colliders of the frame (the side memory holds this many entries per particle, at
    /// least one).
    pub colliders: u32,
    /// After the frame, against the end-of-frame colliders (their end fields, as the CPU's
    /// frame pass takes them) and the ground: free particles closer than ε...
    pub close: u32,
    /// ...and how much closer, at most (0 when none is). The CPU's formulas, in the shader's
    /// f32 arithmetic (which may fuse), so a particle left within rounding of ε may count
    /// here and not on the CPU, or the other way.
    pub close_max_depth: f32,
}
