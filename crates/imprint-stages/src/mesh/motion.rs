//! Motions as position maps. Each motion is compiled once against the rest bounding box,
//! then evaluated per frame into a `Deform`: a few scalars that a pure per-vertex function
//! applies, so results are the same whatever the thread count.

use super::params::{Axis, Motion, RigidKey};
use glam::{Affine3A, Quat, Vec3, Vec3A};
use imprint_core::Aabb;

/// sin(2π t / period), with the phase reduced in f64 so long runs keep their precision.
pub fn periodic(time: f32, period: f32) -> f32 {
    let phase = (time as f64 / period as f64).rem_euclid(1.0);
    (std::f64::consts::TAU * phase).sin() as f32
}

/// A motion bound to the rest box: everything that does not depend on time, precomputed.
#[derive(Clone, Debug)]
pub(crate) enum Compiled {
    Rigid {
        center: Vec3,
        keys: Vec<(f32, Vec3, Quat, f32)>,
    },
    Breathe {
        center: Vec3,
        amplitude: f32,
        period: f32,
    },
    Twist {
        axis: usize,
        center: Vec3,
        low: f32,
        /// Radians per unit length at full amplitude (0 for a flat box).
        rate: f32,
        period: Option<f32>,
    },
    Bend {
        axis: usize,
        toward: usize,
        low: f32,
        center_toward: f32,
        /// Curvature (radians per unit length) at full amplitude.
        curvature: f32,
        period: Option<f32>,
    },
    Wave {
        amplitude: f32,
        wavelength: f32,
        speed: f32,
        direction: usize,
        displace: usize,
    },
}

impl Compiled {
    pub(crate) fn new(m: &Motion, rest: &Aabb) -> Self {
        let center = rest.center();
        let size = rest.size();
        let per_length = |radians: f32, axis: Axis| {
            let len = size[axis.index()];
            if len > 0.0 { radians / len } else { 0.0 }
        };
        match m {
            Motion::Rigid { keys } => Compiled::Rigid {
                center,
                keys: keys.iter().map(compile_key).collect(),
            },
            &Motion::Breathe { amplitude, period } => Compiled::Breathe {
                center,
                amplitude,
                period,
            },
            &Motion::Twist {
                axis,
                degrees,
                period,
            } => Compiled::Twist {
                axis: axis.index(),
                center,
                low: rest.min[axis.index()],
                rate: per_length(degrees.to_radians(), axis),
                period,
            },
            &Motion::Bend {
                axis,
                degrees,
                toward,
                period,
            } => {
                let toward = toward.unwrap_or(axis.default_toward()).index();
                Compiled::Bend {
                    axis: axis.index(),
                    toward,
                    low: rest.min[axis.index()],
                    center_toward: center[toward],
                    curvature: per_length(degrees.to_radians(), axis),
                    period,
                }
            }
            &Motion::Wave {
                amplitude,
                wavelength,
                speed,
                direction,
                displace,
            } => Compiled::Wave {
                amplitude,
                wavelength,
                speed,
                direction: direction.index(),
                displace: displace.index(),
            },
        }
    }

    /// The per-vertex map at `time`.
    pub(crate) fn at(&self, time: f32) -> Deform {
        let factor = |period: Option<f32>| period.map_or(1.0, |p| periodic(time, p));
        match self {
            Compiled::Rigid { center, keys } => {
                let (t, q, s) = rigid_at(keys, time);
                // p' = c + t + q (s (p - c))
                let m = Affine3A::from_translation(*center + t)
                    * Affine3A::from_scale_rotation_translation(Vec3::splat(s), q, Vec3::ZERO)
                    * Affine3A::from_translation(-*center);
                Deform::Affine(m)
            }
            &Compiled::Breathe {
                center,
                amplitude,
                period,
            } => {
                let s = 1.0 + amplitude * periodic(time, period);
                Deform::Scale {
                    center: center.into(),
                    scale: s,
                }
            }
            &Compiled::Twist {
                axis,
                center,
                low,
                rate,
                period,
            } => Deform::Twist {
                axis,
                center,
                low,
                rate: rate * factor(period),
            },
            &Compiled::Bend {
                axis,
                toward,
                low,
                center_toward,
                curvature,
                period,
            } => Deform::Bend {
                axis,
                toward,
                low,
                center_toward,
                curvature: curvature * factor(period),
            },
            &Compiled::Wave {
                amplitude,
                wavelength,
                speed,
                direction,
                displace,
            } => {
                // Phase offset reduced in f64 so that a large speed * time stays precise.
                let shift =
                    ((speed as f64 * time as f64) / wavelength as f64).rem_euclid(1.0) as f32;
                Deform::Wave {
                    amplitude,
                    inv_wavelength: 1.0 / wavelength,
                    shift,
                    direction,
                    displace,
                }
            }
        }
    }
}

fn compile_key(k: &RigidKey) -> (f32, Vec3, Quat, f32) {
    let axis = k.rotate.axis.vector().normalize();
    let q = Quat::from_axis_angle(axis, k.rotate.degrees.to_radians());
    (k.time, k.translate, q, k.scale)
}

/// Translation, rotation and scale of the keyframes at `time` (clamped at the ends).
fn rigid_at(keys: &[(f32, Vec3, Quat, f32)], time: f32) -> (Vec3, Quat, f32) {
    let first = keys[0];
    let last = keys[keys.len() - 1];
    if time <= first.0 {
        return (first.1, first.2, first.3);
    }
    if time >= last.0 {
        return (last.1, last.2, last.3);
    }
    let i = keys.partition_point(|k| k.0 <= time) - 1;
    let (a, b) = (keys[i], keys[i + 1]);
    let u = (time - a.0) / (b.0 - a.0);
    (a.1.lerp(b.1, u), a.2.slerp(b.2, u), a.3 + (b.3 - a.3) * u)
}

/// One motion at one time: a pure function of a vertex position.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Deform {
    Affine(Affine3A),
    Scale {
        center: Vec3A,
        scale: f32,
    },
    Twist {
        axis: usize,
        center: Vec3,
        low: f32,
        rate: f32,
    },
    Bend {
        axis: usize,
        toward: usize,
        low: f32,
        center_toward: f32,
        curvature: f32,
    },
    Wave {
        amplitude: f32,
        inv_wavelength: f32,
        shift: f32,
        direction: usize,
        displace: usize,
    },
}

impl Deform {
    /// This map applied to one point.
    #[cfg(test)]
    pub(crate) fn apply(&self, p: Vec3) -> Vec3 {
        let mut one = [p];
        self.apply_all(&mut one);
        one[0]
    }

    /// This map applied to every point: one match per slice, so each arm is a plain loop.
    pub(crate) fn apply_all(&self, points: &mut [Vec3]) {
        match *self {
            Deform::Affine(m) => map(points, |p| m.transform_point3(p)),
            Deform::Scale { center, scale } => map(points, |p| {
                (center + (Vec3A::from(p) - center) * scale).into()
            }),
            Deform::Twist {
                axis,
                center,
                low,
                rate,
            } => {
                // Right-handed rotation in the plane of the two axes that follow `axis`
                // cyclically (about Y: Z toward X), so +X turns toward -Z for a positive angle.
                let [a, b, c] = frame(axis, (axis + 1) % 3);
                let (cb, cc) = (center.dot(b), center.dot(c));
                map(points, |p| {
                    let (sin, cos) = sin_cos(rate * (p.dot(a) - low));
                    let (u, v) = (p.dot(b) - cb, p.dot(c) - cc);
                    a * p.dot(a) + b * (cb + u * cos - v * sin) + c * (cc + u * sin + v * cos)
                })
            }
            Deform::Bend {
                axis,
                toward,
                low,
                center_toward,
                curvature,
            } => {
                let [a, t, w] = frame(axis, toward);
                map(points, |p| {
                    // Arc of radius 1/k through the centre line, written without dividing by
                    // k so that a vanishing bend is exact: with θ = k s,
                    // s' = s sinc θ - u sin θ,  u' = s (1 - cos θ)/θ + u cos θ.
                    let s = p.dot(a) - low;
                    let u = p.dot(t) - center_toward;
                    let half = 0.5 * curvature * s;
                    let (sh, ch) = sin_cos(half);
                    let sinc_half = if half.abs() < 1e-4 {
                        1.0 - half * half / 6.0
                    } else {
                        sh / half
                    };
                    let sin = 2.0 * sh * ch;
                    let cos = 1.0 - 2.0 * sh * sh;
                    a * (low + s * sinc_half * ch - u * sin)
                        + t * (center_toward + s * sh * sinc_half + u * cos)
                        + w * p.dot(w)
                })
            }
            Deform::Wave {
                amplitude,
                inv_wavelength,
                shift,
                direction,
                displace,
            } => {
                let (d, n) = (Vec3::AXES[direction], Vec3::AXES[displace]);
                map(points, |p| {
                    let phase = p.dot(d) * inv_wavelength - shift;
                    p + n * (amplitude * sin_cos(std::f32::consts::TAU * phase).0)
                })
            }
        }
    }
}

/// Unit vectors of `first`, `second` and the remaining axis. Coordinates are read with dot
/// products and written as sums of multiples of these (multiplying by 0 and 1 and adding
/// zeros is exact for finite values): branch-free code with no indexing by a runtime axis.
fn frame(first: usize, second: usize) -> [Vec3; 3] {
    [
        Vec3::AXES[first],
        Vec3::AXES[second],
        Vec3::AXES[3 - first - second],
    ]
}

#[inline(always)]
fn map(points: &mut [Vec3], f: impl Fn(Vec3) -> Vec3) {
    for p in points {
        *p = f(*p);
    }
}

/// sin and cos in plain f32 arithmetic (Cody-Waite reduction by π/2, Cephes minimax
/// polynomials): a few times faster than libm per vertex, vectorisable, and the same bits on
/// every platform, which libm does not promise. Error below 1e-7 for |x| < 1e3.
#[inline(always)]
pub fn sin_cos(x: f32) -> (f32, f32) {
    // Round to nearest with the 1.5 * 2^23 trick (no libm call, exact for |k| < 2^22).
    const ROUND: f32 = 12_582_912.0;
    let k = (x * std::f32::consts::FRAC_2_PI + ROUND) - ROUND;
    // π/2 split in three; k * P1 is exact for |k| < 2^16 (|x| < 1e5).
    const P1: f32 = 1.570_312_5;
    const P2: f32 = 4.837_513e-4;
    const P3: f32 = 7.549_79e-8;
    let r = ((x - k * P1) - k * P2) - k * P3;
    let r2 = r * r;
    let s = r + r * r2 * (-1.666_665_5e-1 + r2 * (8.332_161e-3 + r2 * -1.951_529_6e-4));
    let c =
        1.0 - 0.5 * r2 + r2 * r2 * (4.166_664_6e-2 + r2 * (-1.388_731_6e-3 + r2 * 2.443_315_7e-5));
    // Quadrant k mod 4 picks (s, c), (c, -s), (-s, -c), (-c, s): selects and sign flips,
    // no branches, so loops over vertices vectorise.
    let q = k as i32;
    let odd = q & 1 != 0;
    let (sin, cos) = if odd { (c, s) } else { (s, c) };
    let sin_sign = ((q & 2) as u32) << 30;
    let cos_sign = (((q + 1) & 2) as u32) << 30;
    (
        f32::from_bits(sin.to_bits() ^ sin_sign),
        f32::from_bits(cos.to_bits() ^ cos_sign),
    )
}

#[cfg(test)]
mod tests {
    use super::super::params::{Rotation, RotationAxis};
    use super::*;
    use std::f32::consts::FRAC_1_SQRT_2;

    /// A 1 x 2 x 1 box standing on y = 0: centre (0, 1, 0).
    fn tall_box() -> Aabb {
        Aabb {
            min: Vec3::new(-0.5, 0.0, -0.5),
            max: Vec3::new(0.5, 2.0, 0.5),
        }
    }

    fn at(m: Motion, time: f32) -> Deform {
        Compiled::new(&m, &tall_box()).at(time)
    }

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).length() <= tol
    }

    #[test]
    fn sin_cos_matches_f64() {
        let mut worst = (0.0f64, 0.0f32);
        for i in -200_000..=200_000 {
            let x = i as f32 * 0.005_123; // about ±1000, off the multiples of π/2
            let (s, c) = sin_cos(x);
            let e = (s as f64 - (x as f64).sin())
                .abs()
                .max((c as f64 - (x as f64).cos()).abs());
            if e > worst.0 {
                worst = (e, x);
            }
        }
        assert!(worst.0 < 1e-7, "max error {} at {}", worst.0, worst.1);
        for k in -8..=8 {
            let x = k as f32 * std::f32::consts::FRAC_PI_2;
            let (s, c) = sin_cos(x);
            assert!(
                (s as f64 - (x as f64).sin()).abs() < 1e-7
                    && (c as f64 - (x as f64).cos()).abs() < 1e-7
            );
        }
        assert!(sin_cos(f32::NAN).0.is_nan());
    }

    #[test]
    fn periodic_factor_is_exact_at_quarter_period() {
        assert_eq!(periodic(0.5, 2.0), 1.0);
        assert_eq!(periodic(0.0, 2.0), 0.0);
        assert_eq!(periodic(1.5, 2.0), -1.0);
        // Long runs keep the phase: one hour in, still exact at the quarter.
        assert_eq!(periodic(3600.5, 2.0), 1.0);
    }

    #[test]
    fn breathe_scales_distances_from_the_centre() {
        let d = at(
            Motion::Breathe {
                amplitude: 0.05,
                period: 2.0,
            },
            0.5,
        );
        let c = tall_box().center();
        for p in [
            Vec3::new(0.5, 2.0, 0.5),
            Vec3::new(-0.3, 0.1, 0.2),
            Vec3::new(0.0, 1.7, 0.0),
        ] {
            let q = d.apply(p);
            let ratio = (q - c).length() / (p - c).length();
            assert!((ratio - 1.05).abs() < 1e-6, "{ratio}");
            // Radial: the direction from the centre is kept.
            assert!((q - c).normalize().dot((p - c).normalize()) > 1.0 - 1e-6);
        }
        assert_eq!(
            at(
                Motion::Breathe {
                    amplitude: 0.05,
                    period: 2.0
                },
                0.0
            )
            .apply(Vec3::ONE),
            Vec3::ONE
        );
        let q = at(
            Motion::Breathe {
                amplitude: 0.05,
                period: 2.0,
            },
            1.5,
        )
        .apply(Vec3::new(0.0, 2.0, 0.0));
        assert!(close(q, Vec3::new(0.0, 1.95, 0.0), 1e-6), "{q}");
    }

    #[test]
    fn twist_turns_the_top_and_keeps_the_bottom() {
        // Right-handed about +Y: the top's +X side goes to -Z.
        let d = at(
            Motion::Twist {
                axis: Axis::Y,
                degrees: 90.0,
                period: None,
            },
            7.0,
        );
        let q = d.apply(Vec3::new(0.5, 2.0, 0.0));
        assert!(close(q, Vec3::new(0.0, 2.0, -0.5), 1e-6), "{q}");
        let bottom = Vec3::new(0.5, 0.0, 0.3);
        assert_eq!(d.apply(bottom), bottom);
        // Linear in height: half way up, half the angle.
        let q = d.apply(Vec3::new(0.5, 1.0, 0.0));
        assert!(
            close(
                q,
                Vec3::new(0.5 * FRAC_1_SQRT_2, 1.0, -0.5 * FRAC_1_SQRT_2),
                1e-6
            ),
            "{q}"
        );
        // Periodic: full angle at a quarter period, none at zero.
        let m = Motion::Twist {
            axis: Axis::Y,
            degrees: 90.0,
            period: Some(4.0),
        };
        assert!(close(
            at(m.clone(), 1.0).apply(Vec3::new(0.5, 2.0, 0.0)),
            Vec3::new(0.0, 2.0, -0.5),
            1e-6
        ));
        assert_eq!(
            at(m, 0.0).apply(Vec3::new(0.5, 2.0, 0.0)),
            Vec3::new(0.5, 2.0, 0.0)
        );
        // About X (the box's x extent is 1, low end -0.5): +Y turns toward +Z.
        let d = at(
            Motion::Twist {
                axis: Axis::X,
                degrees: 90.0,
                period: None,
            },
            0.0,
        );
        let q = d.apply(Vec3::new(0.5, 2.0, 0.0)); // y - 1 = +1 from the centre
        assert!(close(q, Vec3::new(0.5, 1.0, 1.0), 1e-6), "{q}");
    }

    #[test]
    fn bend_keeps_the_centre_line_length_and_turns_the_end() {
        let d = at(
            Motion::Bend {
                axis: Axis::Y,
                degrees: 90.0,
                toward: None,
                period: None,
            },
            0.0,
        );
        let n = 2000;
        let line: Vec<Vec3> = (0..=n)
            .map(|i| d.apply(Vec3::new(0.0, 2.0 * i as f32 / n as f32, 0.0)))
            .collect();
        let length: f32 = line.windows(2).map(|w| (w[1] - w[0]).length()).sum();
        assert!((length - 2.0).abs() < 1e-4, "{length}");
        // The low end is fixed; the high end lies on the quarter circle of radius 2/(π/2),
        // toward +X (the default for Y), and its tangent has turned by 90°.
        assert_eq!(line[0], Vec3::ZERO);
        let r = 2.0 / std::f32::consts::FRAC_PI_2;
        assert!(close(line[n], Vec3::new(r, r, 0.0), 1e-5), "{}", line[n]);
        let tangent = (line[n] - line[n - 1]).normalize();
        assert!(close(tangent, Vec3::X, 1e-3), "{tangent}");
        // Off the centre line, the cross-section stays perpendicular to the arc: the outer
        // side stretches, the inner side shrinks (toward X: -x is outer).
        let outer = d.apply(Vec3::new(-0.5, 2.0, 0.0));
        assert!(close(outer, Vec3::new(r, r + 0.5, 0.0), 1e-5), "{outer}");
        // Third axis untouched; negative angles bend the other way.
        assert_eq!(d.apply(Vec3::new(0.0, 1.0, 0.4)).z, 0.4);
        let neg = at(
            Motion::Bend {
                axis: Axis::Y,
                degrees: -90.0,
                toward: None,
                period: None,
            },
            0.0,
        );
        assert!(close(
            neg.apply(Vec3::new(0.0, 2.0, 0.0)),
            Vec3::new(-r, r, 0.0),
            1e-5
        ));
        // No bend, no change.
        let zero = at(
            Motion::Bend {
                axis: Axis::Y,
                degrees: 0.0,
                toward: Some(Axis::Z),
                period: None,
            },
            0.0,
        );
        let p = Vec3::new(0.3, 1.3, -0.2);
        assert!(close(zero.apply(p), p, 1e-7));
    }

    #[test]
    fn rigid_interpolates_between_keys() {
        let key = |time: f32, translate: Vec3, degrees: f32, scale: f32| RigidKey {
            time,
            translate,
            rotate: Rotation {
                axis: RotationAxis::Named(Axis::Y),
                degrees,
            },
            scale,
        };
        let m = Motion::Rigid {
            keys: vec![
                key(0.0, Vec3::ZERO, 0.0, 1.0),
                key(2.0, Vec3::new(2.0, 0.0, 0.0), 90.0, 3.0),
            ],
        };
        let c = tall_box().center();
        let p = c + Vec3::X;
        // Half way: translate (1, 0, 0), 45° about Y through the centre, scale 2.
        let q = at(m.clone(), 1.0).apply(p);
        let want = c + Vec3::new(1.0 + 2.0 * FRAC_1_SQRT_2, 0.0, -2.0 * FRAC_1_SQRT_2);
        assert!(close(q, want, 1e-5), "{q} vs {want}");
        // Clamped outside the keys.
        assert!(close(at(m.clone(), -1.0).apply(p), p, 1e-6));
        let end = c + Vec3::new(2.0, 0.0, -3.0);
        assert!(close(at(m, 10.0).apply(p), end, 1e-5));
    }

    #[test]
    fn wave_travels() {
        let m = Motion::Wave {
            amplitude: 0.1,
            wavelength: 2.0,
            speed: 0.5,
            direction: Axis::X,
            displace: Axis::Y,
        };
        // sin(2π (x - speed t) / wavelength): x = 1, t = 1 → sin(π/2); x = 2 → sin(3π/2).
        let d = at(m.clone(), 1.0);
        assert!(close(
            d.apply(Vec3::new(1.0, 0.0, 0.3)),
            Vec3::new(1.0, 0.1, 0.3),
            1e-6
        ));
        assert!(close(
            d.apply(Vec3::new(2.0, 5.0, 0.0)),
            Vec3::new(2.0, 4.9, 0.0),
            1e-6
        ));
        // The crest moves by speed * dt.
        let later = at(m, 3.0);
        assert!(close(
            later.apply(Vec3::new(2.0, 0.0, 0.0)),
            Vec3::new(2.0, 0.1, 0.0),
            1e-6
        ));
    }
}
