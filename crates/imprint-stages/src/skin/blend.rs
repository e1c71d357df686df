//! Linear blend skinning (LBS) and dual quaternion skinning (DQS): each vertex moves by a
//! weighted blend of its bones' skin transforms (`Pose::skin`, rest space → posed space).
//!
//! - **LBS**: p' = Σ w_b M_b p. The blend of rotations is not a rotation: a vertex weighted
//!   w / 1 − w between two bones turned θ apart about an axis through it lands at a fraction
//!   √(w² + (1−w)² + 2w(1−w) cos θ) of its distance to that axis, so a joint ring twisted by
//!   θ shrinks by that factor (0 at 180° with w = ½: the candy wrapper), and a bent joint
//!   loses volume on its inner side.
//! - **DQS** (Kavan et al.): each rigid M_b as a unit dual quaternion q̂_b = q_b + ε ½ t_b q_b,
//!   blended b̂ = Σ w_b s_b q̂_b, divided by |real part| and applied as a rigid motion, so a
//!   twisted ring keeps its radius. A rotation is both q and −q; the blend must take every
//!   q_b in the same hemisphere, so s_b = sign(q_b · q_pivot) with the pivot the vertex's
//!   most-weighted bone (the first of [`Weights::of`]; ties go to the lower bone index).
//!   This is the standard antipodality fix, and it is what makes DQS *flip* at 180°: for
//!   a joint twisted past 180° relative to the pivot, q_b · q_pivot changes sign, the blend
//!   jumps from turning by about +θ/2 to about θ/2 − 180°, and a vertex weighted ½/½ jumps
//!   across the limb (about a diameter). LBS is continuous there (it collapses instead).
//!   A blend whose real part vanishes (weights cancelling exactly) keeps the pivot's
//!   transform.
//!
//! Both in f64 per vertex; the skin transforms must be rigid for DQS (a rig's are).

use crate::skin::weights::Weights;
use glam::{Affine3A, DAffine3, DQuat, DVec3, Vec3};
use rayon::prelude::*;

/// Linear blend skinning of the rest positions.
pub fn lbs(rest: &[Vec3], weights: &Weights, skin: &[Affine3A]) -> Vec<Vec3> {
    assert_eq!(rest.len(), weights.len(), "one weight list per vertex");
    let m: Vec<DAffine3> = skin.iter().map(|s| s.as_daffine3()).collect();
    rest.par_iter()
        .enumerate()
        .map(|(v, p)| {
            let p = p.as_dvec3();
            weights
                .of(v)
                .iter()
                .fold(DVec3::ZERO, |acc, &(b, w)| {
                    acc + w as f64 * m[b as usize].transform_point3(p)
                })
                .as_vec3()
        })
        .collect()
}

/// A rigid transform as a unit dual quaternion (real, dual), in f64 (the GPU path rounds
/// these to f32, so both paths start from the same quaternions).
pub(crate) fn dual_quat(m: &DAffine3) -> (DQuat, DQuat) {
    let q = DQuat::from_mat3(&m.matrix3).normalize();
    let t = m.translation;
    let d = DQuat::from_xyzw(t.x, t.y, t.z, 0.0) * q * 0.5;
    (q, d)
}

/// Dual quaternion skinning of the rest positions (see the module doc for the 180° flip).
pub fn dqs(rest: &[Vec3], weights: &Weights, skin: &[Affine3A]) -> Vec<Vec3> {
    assert_eq!(rest.len(), weights.len(), "one weight list per vertex");
    let dq: Vec<(DQuat, DQuat)> = skin.iter().map(|s| dual_quat(&s.as_daffine3())).collect();
    rest.par_iter()
        .enumerate()
        .map(|(v, p)| {
            let list = weights.of(v);
            let pivot = dq[list[0].0 as usize].0;
            let (mut r, mut d) = (
                DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
                DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
            );
            for &(b, w) in list {
                let (qr, qd) = dq[b as usize];
                let w = if qr.dot(pivot) < 0.0 {
                    -(w as f64)
                } else {
                    w as f64
                };
                r += qr * w;
                d += qd * w;
            }
            let len = r.length();
            let (r, d) = if len > 1e-12 {
                (r * (1.0 / len), d * (1.0 / len))
            } else {
                dq[list[0].0 as usize]
            };
            // t = 2 d r*, rotation by r.
            let t = d * r.conjugate() * 2.0;
            (r * p.as_dvec3() + DVec3::new(t.x, t.y, t.z)).as_vec3()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::skin::weights::from_lists;
    use glam::Quat;

    #[test]
    fn a_single_bone_reproduces_its_transform() {
        let m = Affine3A::from_rotation_translation(
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 2.5),
            Vec3::new(0.3, -1.0, 2.0),
        );
        let rest = [Vec3::new(0.1, 0.2, 0.3), Vec3::new(-1.0, 0.5, 2.0)];
        let w = from_lists(&[vec![(0, 1.0)], vec![(0, 1.0)]], 1).unwrap();
        for out in [lbs(&rest, &w, &[m]), dqs(&rest, &w, &[m])] {
            for (p, q) in rest.iter().zip(&out) {
                assert!((m.transform_point3(*p) - *q).length() < 1e-5, "{q}");
            }
        }
    }
}
