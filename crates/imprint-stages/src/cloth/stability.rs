//! How large a substep the explicit integrator survives, predicted before running (the stress
//! map of [`super::stress`] checks the prediction).
//!
//! Verlet with damping d on one mode of angular frequency ω is stable for
//! ω dt ≤ sqrt(2 (1 + d)) (2 when undamped: H's dt ≲ 2 sqrt(m / k) for one spring on one
//! mass). A cloth's fastest mode is found two ways:
//! - a bound: Gershgorin on M⁻¹K, 2 Σ k / m over each particle's springs (never above the
//!   true limit; up to ~√2 too cautious in dt on a grid);
//! - an estimate: power iteration on M⁻¹K, the springs' stiffness matrix at rest (pinned
//!   particles fixed), which finds the true fastest mode to a few percent.
//!
//! Linear springs have stiffness k whatever their length. Tokoi's quadratic springs have
//! stiffness 2 k |e|, zero at rest: they are taken at a working strain of
//! [`REFERENCE_STRAIN`]. Hinge bending has stiffness c sin|φ| (zero when flat), taken at its
//! largest, c, through a Gershgorin bound added to both (λ_max(A + B) ≤ λ_max(A) + λ_max(B)).

use super::springs::{Hinges, Links, hinge_angle_gradient};
use glam::Vec3;
use imprint_core::Error;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The strain at which Tokoi's quadratic springs are linearised for the estimate.
pub const REFERENCE_STRAIN: f32 = 0.1;

/// A substep is taken as safe up to this fraction of the estimated critical step.
pub const SAFETY: f32 = 0.9;

const POWER_ITERATIONS: usize = 100;

/// The largest stable substep, predicted from the rest state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StabilityEstimate {
    /// Power-iteration estimate of the critical substep, s (a few percent above the truth
    /// at worst: use [`StabilityEstimate::substeps_for`], which keeps a margin).
    pub dt_crit: f32,
    /// Gershgorin bound: every substep up to this is stable, s.
    pub dt_crit_bound: f32,
    /// The fastest mode's angular frequency (power iteration), rad/s.
    pub omega_max: f32,
    /// The particle with the largest Σ k / m, and that value (1/s²).
    pub stiffest_particle: u32,
    pub stiffest_k_over_m: f32,
}

/// The band misses of a frame that blew up: contacts that read one of the two fields they
/// blend alone, because the body moved farther between the fields than their band. Particles
/// the body then reaches from inside are pushed the wrong way, and that can blow a cloth up
/// whatever its substeps: the cow under H's cloth, its field built every 4 frames and
/// interpolated, blew up at 80 and at 160 substeps, and ran through with a band wider than its
/// motion (14 cells). Where the misses are few they may be beside the point (H's bunny at 16
/// substeps blew up with one miss and a 10-cell band), so the hint offers both.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BandMisses {
    pub count: u32,
    /// The narrowest band among the colliders: half-width in cells and in world units.
    pub cells: f32,
    pub width: f32,
}

impl BandMisses {
    /// `count` misses against `colliders` (each its band in cells and its cell size), if any.
    pub fn of(count: u32, colliders: impl Iterator<Item = (f32, f32)>) -> Option<Self> {
        let (cells, cell) = colliders.min_by(|a, b| (a.0 * a.1).total_cmp(&(b.0 * b.1)))?;
        (count > 0).then_some(BandMisses {
            count,
            cells,
            width: cells * cell,
        })
    }

    /// The hint's second remedy.
    fn hint(&self) -> String {
        format!(
            "; or, as {} contacts this frame read one of the two fields they blend alone (band \
             misses: the body moved farther between them than their band, now {} cells, {:.3} \
             m), widen the field's `band` beyond that motion or build the field more often \
             (`every`)",
            self.count, self.cells, self.width
        )
    }
}

impl StabilityEstimate {
    /// The error of a blown-up frame, for both paths: `what` failed at substep `j` (from 0)
    /// of `n_sub` substeps of `dt` in a frame of `dt_frame`; the hint names the substep count
    /// (or the stiffness division) that the estimate says would hold, or, when the springs
    /// alone are within their stable step, blames contact, wind or pins and doubles the
    /// substeps, and names the fields' band too when the frame had band misses (`misses`).
    #[allow(clippy::too_many_arguments)]
    pub fn blow_up(
        &self,
        node: &str,
        path: &str,
        frame: u32,
        j: u32,
        n_sub: u32,
        dt: f32,
        dt_frame: f32,
        what: &str,
        misses: Option<BandMisses>,
    ) -> Error {
        let needed = self.substeps_for(dt_frame);
        let hint = if needed > n_sub {
            format!(
                "substeps: {needed} (now {n_sub}; the stiffest spring is stable for dt up to \
                 {:.3e} s, this substep is {dt:.3e} s), or divide the material's stiffness by {:.0}",
                self.dt_crit,
                ((dt / (SAFETY * self.dt_crit)).powi(2)).ceil().max(2.0)
            )
        } else {
            format!(
                "substeps: {} (now {n_sub}; the springs alone are within their stable step \
                 {:.3e} s, so contact, wind or pin motion moved particles too far per substep), \
                 or lower the colliders' or pins' speed{}",
                (2 * n_sub).max(needed),
                self.dt_crit,
                misses.map_or(String::new(), |m| m.hint())
            )
        };
        Error::Numerical {
            node: node.to_string(),
            frame,
            message: format!("{path} exploded at substep {} of {n_sub}: {what}", j + 1),
            hint,
        }
    }

    /// Substeps a frame of `dt_frame` needs to stay at or below `SAFETY * dt_crit`.
    pub fn substeps_for(&self, dt_frame: f32) -> u32 {
        if !(self.dt_crit.is_finite() && self.dt_crit > 0.0) {
            return 1;
        }
        (dt_frame as f64 / (SAFETY * self.dt_crit) as f64)
            .ceil()
            .clamp(1.0, u32::MAX as f64) as u32
    }

    /// A warning when `substeps` per frame of `dt_frame` is predicted to blow up.
    pub fn warning(&self, substeps: u32, dt_frame: f32) -> Option<String> {
        let needed = self.substeps_for(dt_frame);
        (substeps < needed).then(|| {
            format!(
                "cloth: {substeps} substeps of {:.3e} s exceed the stable step {:.3e} s of the \
                 stiffest springs (particle {}); use substeps: {needed} or more",
                dt_frame / substeps as f32,
                self.dt_crit,
                self.stiffest_particle
            )
        })
    }
}

/// Estimates the critical substep of a cloth at rest.
pub fn estimate(
    links: &Links,
    hinges: &Hinges,
    rest: &[Vec3],
    pinned: &[bool],
    mass: f32,
    damping: f32,
) -> StabilityEstimate {
    let n = rest.len();
    let law = links.law;
    // Per-particle stiffness of each link at the working point.
    let k_of = |ks: f32, l: f32| law.stiffness(ks, REFERENCE_STRAIN * l);
    let mut sum_k = vec![0.0f64; n];
    for (i, s) in sum_k.iter_mut().enumerate() {
        for q in links.of(i) {
            for l in 0..4 {
                *s += k_of(q.k_stretch[l], q.rest[l]) as f64;
            }
        }
    }
    // Hinges: Gauss-Newton Hessian c ∇θ ∇θᵀ, Gershgorin row sums.
    let mut hinge_row = vec![0.0f64; n];
    for h in &hinges.hinges {
        if let Some((_, g)) = hinge_angle_gradient(h.v.map(|v| rest[v as usize])) {
            let total: f64 = g.iter().map(|g| g.length() as f64).sum();
            for (r, &v) in h.v.iter().enumerate() {
                hinge_row[v as usize] += h.c as f64 * g[r].length() as f64 * total;
            }
        }
    }
    let m = mass as f64;
    let free = |i: usize| !pinned[i];
    let (mut stiffest, mut k_max, mut lambda_bound, mut lambda_hinge) =
        (0u32, 0.0f64, 0.0f64, 0.0f64);
    for i in (0..n).filter(|&i| free(i)) {
        if sum_k[i] > k_max {
            k_max = sum_k[i];
            stiffest = i as u32;
        }
        lambda_bound = lambda_bound.max(2.0 * sum_k[i] / m);
        lambda_hinge = lambda_hinge.max(hinge_row[i] / m);
    }

    // Power iteration on K v = Σ k (n nᵀ)(v_i - v_j), in f64, from a fixed pseudo-random start.
    let mut v: Vec<[f64; 3]> = (0..n)
        .map(|i| {
            if free(i) {
                let h = |k: u64| {
                    let x = (i as u64 * 3 + k + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                    ((x >> 11) as f64 / (1u64 << 53) as f64) - 0.5
                };
                [h(0), h(1), h(2)]
            } else {
                [0.0; 3]
            }
        })
        .collect();
    let mut w = vec![[0.0f64; 3]; n];
    let mut lambda = 0.0f64;
    for _ in 0..POWER_ITERATIONS {
        let norm = v.iter().flatten().map(|x| x * x).sum::<f64>().sqrt();
        if norm == 0.0 {
            break;
        }
        v.iter_mut().flatten().for_each(|x| *x /= norm);
        // Each particle's row on its own (in parallel; no sum crosses particles).
        let vr = &v;
        w.par_iter_mut().enumerate().for_each(|(i, out)| {
            let mut acc = glam::DVec3::ZERO;
            if free(i) {
                for q in links.of(i) {
                    for l in 0..4 {
                        let j = q.other[l] as usize;
                        let k = k_of(q.k_stretch[l], q.rest[l]) as f64;
                        let d = (rest[j] - rest[i]).as_dvec3();
                        let len = d.length();
                        if k == 0.0 || j == i || len == 0.0 {
                            continue;
                        }
                        let nn = d / len;
                        let dv = glam::DVec3::from(vr[i]) - glam::DVec3::from(vr[j]);
                        acc += nn * (k * nn.dot(dv) / m);
                    }
                }
            }
            *out = acc.to_array();
        });
        lambda = v
            .iter()
            .zip(&w)
            .map(|(a, b)| a[0] * b[0] + a[1] * b[1] + a[2] * b[2])
            .sum::<f64>();
        std::mem::swap(&mut v, &mut w);
    }
    let limit = (2.0 * (1.0 + damping as f64)).sqrt();
    let dt = |lambda: f64| {
        if lambda > 0.0 {
            (limit / lambda.sqrt()) as f32
        } else {
            f32::INFINITY
        }
    };
    let lambda = lambda.min(lambda_bound) + lambda_hinge;
    StabilityEstimate {
        dt_crit: dt(lambda),
        dt_crit_bound: dt(lambda_bound + lambda_hinge),
        omega_max: lambda.sqrt() as f32,
        stiffest_particle: stiffest,
        stiffest_k_over_m: (k_max / m) as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A blow-up with stable springs names the substeps, and the band as well when the
    /// frame had band misses: the narrowest band in world units, with its cells.
    #[test]
    fn a_blow_up_with_band_misses_names_the_band_too() {
        let est = StabilityEstimate {
            dt_crit: 1e-2,
            dt_crit_bound: 8e-3,
            omega_max: 200.0,
            stiffest_particle: 0,
            stiffest_k_over_m: 1e4,
        };
        // 3 cells of 1 cm (3 cm) against 4 cells of 5 mm (2 cm): the second is narrower.
        let bands = [(3.0, 0.01), (4.0, 0.005)];
        let misses = BandMisses::of(12, bands.into_iter());
        assert_eq!(
            misses,
            Some(BandMisses {
                count: 12,
                cells: 4.0,
                width: 0.02
            })
        );
        assert_eq!(BandMisses::of(0, bands.into_iter()), None);
        assert_eq!(BandMisses::of(5, std::iter::empty()), None);
        let hint = |misses| match est.blow_up("c", "cloth", 3, 1, 8, 2e-3, 1.0 / 60.0, "x", misses)
        {
            Error::Numerical { hint, .. } => hint,
            other => panic!("{other}"),
        };
        let with = hint(misses);
        assert!(with.contains("substeps: 16"), "{with}");
        assert!(with.contains("12 contacts"), "{with}");
        assert!(with.contains("now 4 cells, 0.020 m"), "{with}");
        assert!(
            with.contains("`band`") && with.contains("`every`"),
            "{with}"
        );
        let without = hint(None);
        assert!(without.contains("substeps: 16"), "{without}");
        assert!(!without.contains("band"), "{without}");
    }
}
