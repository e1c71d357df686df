//! The stress map behind `imprint stress cloth`: the cloth run at multiples of its stiffness
//! and fractions of the estimated critical substep ([`super::stability`]), to check where the
//! estimate is right.

use super::cpu::ClothSim;
use super::params::ClothParams;
use glam::Vec3;
use imprint_core::{Error, Result};
use serde::Serialize;

/// One cell of the stress map.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct StressCase {
    /// Multiplier of every stiffness constant.
    pub stiffness_scale: f32,
    /// Substep over the estimated critical step.
    pub dt_ratio: f32,
    pub dt_substep: f32,
    /// The estimate says it is stable (`dt_ratio` ≤ 1).
    pub predicted_stable: bool,
    /// Below the Gershgorin bound (stable for certain, in the linear regime).
    pub below_bound: bool,
    pub outcome: StressOutcome,
}

#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum StressOutcome {
    /// Ran every frame; the largest strain seen.
    Stable { max_strain: f32 },
    /// Stopped with `Error::Numerical`.
    Exploded { frame: u32, message: String },
}

impl StressOutcome {
    pub fn is_stable(&self) -> bool {
        matches!(self, StressOutcome::Stable { .. })
    }
}

/// The table behind `imprint stress cloth`: for each stiffness multiplier (e.g. decades
/// 1, 10, 100) and each substep as a fraction of the estimated critical step (e.g. 0.5..2),
/// runs `params`' cloth (no colliders, every particle nudged by 1% of the shortest rest
/// length, pseudo-randomly but reproducibly) for `frames` frames of `params.substeps`
/// substeps and records whether it blew up. Rows by stiffness, then ratio.
pub fn stress_map(
    params: &ClothParams,
    assets: &super::ClothAssets,
    stiffness_scales: &[f32],
    dt_ratios: &[f32],
    frames: u32,
) -> Result<Vec<StressCase>> {
    if let Some(bad) = stiffness_scales
        .iter()
        .chain(dt_ratios)
        .find(|x| !(x.is_finite() && **x > 0.0))
    {
        return Err(Error::Invalid(format!(
            "stress map: scales and ratios must be positive finite numbers, got {bad}"
        )));
    }
    let mut out = Vec::new();
    for &scale in stiffness_scales {
        let mut p = params.clone();
        p.scale_stiffness(scale);
        let base = ClothSim::from_assets(&p, assets)?;
        let est = *base.stability();
        if !est.dt_crit.is_finite() {
            return Err(Error::Invalid(
                "stress map: the cloth has no stiffness to be unstable with".into(),
            ));
        }
        let shortest = base
            .links()
            .quads
            .iter()
            .flat_map(|q| q.rest)
            .filter(|&l| l > 0.0)
            .fold(f32::INFINITY, f32::min);
        let nudged: Vec<Vec3> = base
            .positions()
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let h = |k: u64| {
                    let v = (i as u64 * 3 + k + 7).wrapping_mul(0xD1B5_4A32_D192_ED03);
                    ((v >> 40) as f32 / (1u64 << 24) as f32) - 0.5
                };
                *x + 0.02 * shortest * Vec3::new(h(0), h(1), h(2))
            })
            .collect();
        for &ratio in dt_ratios {
            let mut sim = ClothSim::from_assets(&p, assets)?;
            sim.set_positions(&nudged)?;
            let dt = ratio * est.dt_crit;
            let dt_frame = dt * p.substeps as f32;
            let mut max_strain = 0.0f32;
            let mut outcome = None;
            for f in 0..frames {
                match sim.step_frame(&[], &[], f, dt_frame) {
                    Ok(m) => max_strain = max_strain.max(m.max_strain),
                    Err(Error::Numerical { frame, message, .. }) => {
                        outcome = Some(StressOutcome::Exploded { frame, message });
                        break;
                    }
                    Err(e) => return Err(e),
                }
            }
            out.push(StressCase {
                stiffness_scale: scale,
                dt_ratio: ratio,
                dt_substep: dt,
                predicted_stable: ratio <= 1.0,
                below_bound: dt <= est.dt_crit_bound,
                outcome: outcome.unwrap_or(StressOutcome::Stable { max_strain }),
            });
        }
    }
    Ok(out)
}
