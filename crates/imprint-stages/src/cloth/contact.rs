//! Contact with the bodies' distance fields (H §5.1, §5.3) and the ground plane.
//!
//! **Which side.** A field built from a closed mesh is *signed* (its cells know whether they
//! lie inside, [`imprint_core::DistanceField::inside`]): the blend of the cells' signed
//! distances at the particle says which side it is on, to within the surface's curvature over a
//! cell. Inside, the closest-point vector points to the nearest surface, which is the way out:
//! a particle that got into a thin part (an ear, a horn) leaves through the wall it is
//! nearest to, never through the far one. Deeper than the band (no vector), it goes back to
//! where it was at the substep's start.
//!
//! An open mesh has no inside, and its field is *unsigned*: a sample says how far the closest
//! surface point is and where (the vector points to it), not which side the particle is on.
//! Near a surface the interpolated vector is -(signed distance) x normal, so it turns round
//! when the particle crosses. Each particle therefore remembers, per field, the outward
//! direction at its last sample in the band, and reads an unsigned sample as:
//! - vector against that outward direction → outside, signed distance +d;
//! - vector along it, and the surface within reach (the particle's own step this substep,
//!   plus 2ε for the body's, plus how far the body moved there between the two fields when
//!   blending, `moved`) → it crossed the surface: inside, signed distance -d.
//!
//! When blending, a crossing in one field where the other finds the particle outside must
//! also be one the surface could make: outside by d there and inside by d' here is a sweep of
//! d + d' within the reach, with the two fields' outward directions agreeing. Without these
//! two checks a particle in a gap (between two ears, under an armpit) whose closest point
//! jumps to the other side between two frames read as crossed, was pushed into the far side
//! and blew the cloth up, on bodies that moved at a fraction of the band per frame.
//!
//! A particle deeper than that reach is taken to be outside (so a body that jumps through the
//! cloth is not caught, and a gap narrower than the reach can be misread): H's rule that
//! nothing moves more than ε per substep relative to the body is what the substeps are for.
//!
//! **Blending in time (H eq. 13-14).** Substep j of n sees each body `s = j/n` of the way
//! through the frame: each of the two fields is read as a signed distance and an outward
//! normal, and those are blended linearly. (Blending the raw samples instead goes wrong where
//! the body moves fast past a particle: two closest-point vectors from different surface
//! points blend to one that points sideways, and the side is lost.) The band must be wider
//! than ε plus the bodies' motion in a frame; where one field is far and the other near, the
//! near one is used alone and the contact is counted in the metrics as a `band_miss`.
//!
//! **Response.** Closer than ε (or inside), the particle moves along the outward normal to
//! distance ε (eq. 11), then a fraction b of the substep's tangential displacement is
//! cancelled (eq. 12, as docs/methods.md reads it).

use super::sampler::{FieldView, Read};
use glam::{Vec3, Vec4};
use imprint_core::FieldSample;

/// One body: two fields it blends between (when blending) and where the frame lies between
/// them: `span` is the weight of `end` at the frame's start and end, (0, 1) when the fields
/// are the frame's own ends, narrower when they are keyframes built around it.
#[derive(Clone, Copy)]
pub struct Collider<'a> {
    pub start: Option<FieldView<'a>>,
    pub end: FieldView<'a>,
    pub span: (f32, f32),
}

impl Collider<'_> {
    /// The weight of `end` at fraction `s` of the frame (1 at its end, exactly).
    #[inline]
    pub fn weight(&self, s: f32) -> f32 {
        let (a, b) = self.span;
        if s >= 1.0 { b } else { a + (b - a) * s }
    }
}

/// A field read at a particle: signed distance (negative inside) and the outward direction.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Signed {
    pub distance: f32,
    /// Away from the surface; not normalised (only [`respond`] needs its length to be 1, and
    /// only where there is contact).
    pub outward: Vec3,
    /// The blend mixed a far field with a near one (see the module docs).
    pub band_miss: bool,
}

/// Reads one sample as signed: by the field's sign when it has one (`signed`, negative
/// inside), else by the particle's memory `side` (xyz the outward direction at its last
/// sample, w = 1 when known) and how deep a crossing can reach (computed only when the vector
/// has turned round: `reach()` is the rare path). Inside a signed field but deeper than the
/// band, the outward direction is zero (unknown).
#[inline(always)]
fn classify(
    d: f32,
    v: Vec3,
    signed: Option<f32>,
    side: Vec4,
    reach: impl Fn() -> f32,
) -> Option<(f32, Vec3)> {
    if let Some(sd) = signed {
        return match (sd < 0.0, d.is_finite() && v != Vec3::ZERO) {
            (true, true) => Some((-d, v)),
            (true, false) => sd.is_finite().then_some((sd, Vec3::ZERO)),
            (false, true) => Some((d, -v)),
            (false, false) => None,
        };
    }
    if !(d.is_finite() && v != Vec3::ZERO) {
        return None;
    }
    if side.w > 0.0 && v.dot(side.truncate()) > 0.0 && d < reach() {
        Some((-d, v))
    } else {
        Some((d, -v))
    }
}

/// The body `c` at `x` (the particle's new position, `x_from` where it was), `s` of the way
/// through the frame (the blend's weight is `c.span` mapped over the frame). None where the field knows no direction (far from the body, or exactly
/// on its medial axis).
#[inline(always)]
pub fn signed_sample(
    c: &Collider,
    x: Vec3,
    x_from: Vec3,
    s: f32,
    side: Vec4,
    eps: f32,
) -> Option<Signed> {
    // The particle's own step plus 2ε for the body's.
    let reach = || 2.0 * eps + (x - x_from).length();
    let rb = c.end.read(x);
    let one = |r: &Read, reach: &dyn Fn() -> f32, band_miss: bool| {
        let f = &r.sample;
        classify(f.distance, f.vector, r.side, side, reach).map(|(distance, outward)| Signed {
            distance,
            outward,
            band_miss,
        })
    };
    let s = c.weight(s);
    let (ra, f0) = match c.start {
        Some(f0) if s < 1.0 => (f0.read(x), f0),
        _ => return one(&rb, &reach, false),
    };
    let (a, b) = (ra.sample, rb.sample);
    let far = c.end.field.far_value();
    match (a.in_band, b.in_band) {
        (true, true) => {
            // A reading whose vector turned round is a crossing only as deep as the body
            // moved here ([`moved`]); and where the other field finds the particle outside,
            // only if the surface could have swept past it: outside by d in one field and
            // inside by d' in the other is a sweep of d + d', and the two fields' outward
            // directions then agree (one's vector runs against the other's).
            let jump = (b.vector - a.vector).length();
            let reach_a = || reach() + moved(x + a.vector, &c.end, jump);
            let reach_b = || reach() + moved(x + b.vector, &f0, jump);
            let (p0, q0) = (one(&ra, &reach_a, false), one(&rb, &reach_b, false));
            let agree = a.vector.dot(b.vector) < 0.0;
            let outside = |r: Option<Signed>| match r {
                Some(r) if r.distance >= 0.0 => sweep(r.distance, agree),
                _ => 0.0,
            };
            let p = one(&ra, &|| reach_a() - outside(q0), false);
            let q = one(&rb, &|| reach_b() - outside(p0), false);
            match (p, q) {
                (Some(p), Some(q)) => {
                    let distance = p.distance + (q.distance - p.distance) * s;
                    // In contact, blend the outward directions as unit vectors, so that the
                    // nearer field does not count for less; otherwise only the side matters.
                    let (np, nq) = if distance < eps {
                        (p.outward.normalize(), q.outward.normalize())
                    } else {
                        (p.outward, q.outward)
                    };
                    Some(Signed {
                        distance,
                        outward: np + (nq - np) * s,
                        band_miss: false,
                    })
                }
                (p, q) => q.or(p),
            }
        }
        // One field far: the body moved here by up to the band, or more.
        (false, true) => one(&rb, &|| reach() + moved(x + b.vector, &f0, far), true),
        (true, false) => one(&ra, &|| reach() + moved(x + a.vector, &c.end, far), true),
        (false, false) => {
            // Both at the band's edge: the trilinear blends of the cells, far ones included.
            let f = Read {
                sample: FieldSample {
                    distance: a.distance + (b.distance - a.distance) * s,
                    vector: a.vector + (b.vector - a.vector) * s,
                    in_band: false,
                },
                side: match (ra.side, rb.side) {
                    (Some(p), Some(q)) => Some(p + (q - p) * s),
                    _ => None,
                },
            };
            one(&f, &reach, false)
        }
    }
}

/// How far a body moved near the closest point `q` one field gives, as far as a crossing
/// of it can tell: the other field's distance at `q`, and no more than `jump`, how far the
/// closest point moved between the two fields. The closest point alone overstates it where
/// it jumps to another part of the body: a particle in the gap between two ears, nearer one
/// ear at the frame's start and the other at its end, has its closest point cross the gap,
/// though neither ear moved; counted as motion, the other ear would read as crossed and the
/// particle would be pushed through it. Where the surface did sweep past the particle, the
/// other field's surface lies as far from `q` as the sweep (for a crossing it must be).
#[inline(always)]
pub(super) fn moved(q: Vec3, other: &FieldView, jump: f32) -> f32 {
    other.read(q).sample.distance.min(jump)
}

/// How much less than its reach a crossing in one field may go where the other field
/// finds the particle outside by `d`: all of `d`, or all of the reach where the fields'
/// outward directions disagree (`agree` false).
#[inline(always)]
pub(super) fn sweep(d: f32, agree: bool) -> f32 {
    if agree { d } else { f32::INFINITY }
}

/// What a contact did to one particle.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Hit {
    /// ε minus the signed distance before the projection (> ε: it was inside).
    pub depth: f32,
    /// The particle was found inside the body (it crossed the surface).
    pub inside: bool,
}

/// Keeps `x` (the particle's new position; `x_from` where it was at the substep's start) at
/// distance ε from a body read as `sample`, and updates the particle's memory `side`.
#[inline(always)]
pub fn respond(
    x: &mut Vec3,
    x_from: Vec3,
    sample: &Signed,
    side: &mut Vec4,
    eps: f32,
    friction: f32,
) -> Option<Hit> {
    if sample.distance < 0.0 && sample.outward == Vec3::ZERO {
        // Inside a signed field, deeper than its band: no way out is known; undo the step.
        *x = x_from;
        return Some(Hit {
            depth: eps - sample.distance,
            inside: true,
        });
    }
    *side = sample.outward.extend(1.0);
    if sample.distance >= eps {
        return None;
    }
    let out = sample.outward.try_normalize()?;
    *x += (eps - sample.distance) * out;
    if friction > 0.0 {
        let step = *x - x_from;
        *x -= friction * (step - step.dot(out) * out);
    }
    Some(Hit {
        depth: eps - sample.distance,
        inside: sample.distance < 0.0,
    })
}

/// Keeps `x` at height `ground + ε`, with the same friction.
#[inline(always)]
pub fn ground(x: &mut Vec3, x_from: Vec3, h: f32, eps: f32, friction: f32) -> Option<Hit> {
    let target = h + eps;
    if x.y >= target {
        return None;
    }
    let depth = target - x.y;
    x.y = target;
    if friction > 0.0 {
        x.x -= friction * (x.x - x_from.x);
        x.z -= friction * (x.z - x_from.z);
    }
    Some(Hit {
        depth,
        inside: depth > eps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outside_particles_go_to_epsilon_and_crossers_come_back() {
        let eps = 0.1;
        // Surface: the plane y = 0, outside above. A particle at y = 0.05 sees v = (0, -0.05, 0).
        let mut side = Vec4::ZERO;
        let mut x = Vec3::new(0.0, 0.05, 0.0);
        let from = x;
        let s = classify(0.05, Vec3::new(0.0, -0.05, 0.0), None, side, || 0.2).unwrap();
        let hit = respond(&mut x, from, &sig(s), &mut side, eps, 0.0);
        assert!((x.y - 0.1).abs() < 1e-7 && !hit.unwrap().inside);
        assert_eq!(side, Vec4::new(0.0, 0.05, 0.0, 1.0));
        // It then falls through to y = -0.03: the vector now points up, along the outward side.
        let from = x;
        let mut x = Vec3::new(0.0, -0.03, 0.0);
        let s = classify(0.03, Vec3::new(0.0, 0.03, 0.0), None, side, || 0.33).unwrap();
        assert_eq!(s.0, -0.03);
        let hit = respond(&mut x, from, &sig(s), &mut side, eps, 0.0).unwrap();
        assert!(hit.inside);
        assert!((x.y - 0.1).abs() < 1e-7, "{x}");
        assert!((hit.depth - 0.13).abs() < 1e-6);
        // Far deeper than it could have gone in one step: taken to be outside.
        let s = classify(0.9, Vec3::new(0.0, -0.9, 0.0), None, side, || 0.3).unwrap();
        assert_eq!(s.0, 0.9);
        // A signed field says inside at any depth, whatever the memory: out along the vector.
        let s = classify(0.9, Vec3::new(0.0, 0.9, 0.0), Some(-0.9), side, || 0.3).unwrap();
        assert_eq!(s, (-0.9, Vec3::new(0.0, 0.9, 0.0)));
        let s = classify(
            0.03,
            Vec3::new(0.0, -0.03, 0.0),
            Some(0.03),
            Vec4::ZERO,
            || 0.0,
        );
        assert_eq!(s, Some((0.03, Vec3::new(0.0, 0.03, 0.0))));
        // Deeper than the band: inside, no direction; the particle goes back.
        let s = classify(0.3, Vec3::ZERO, Some(-0.3), side, || 0.3).unwrap();
        let (from, mut x) = (Vec3::new(0.0, 0.2, 0.0), Vec3::new(0.0, -0.5, 0.0));
        let hit = respond(&mut x, from, &sig(s), &mut side, eps, 0.0).unwrap();
        assert!(hit.inside && x == from);
    }

    /// A column of 2 mm cells along y from -1 cm to 6 cm, band 4 cm, from a closest-point
    /// function: the particles below sit at cell centres, so a read is the cell's own.
    fn slab(closest: impl Fn(Vec3) -> Vec3) -> imprint_core::DistanceField {
        let origin = Vec3::new(-0.004, -0.01, -0.004);
        let spec = imprint_core::GridSpec::new(origin, 0.002, glam::UVec3::new(5, 36, 5));
        imprint_core::DistanceField::from_closest_points(spec.unwrap(), 20.0, closest)
    }

    /// The nearer of the planes y = `lo` and y = `hi`: the walls of a gap.
    fn walls(lo: f32, hi: f32) -> impl Fn(Vec3) -> Vec3 {
        move |p| Vec3::new(p.x, if p.y - lo <= hi - p.y { lo } else { hi }, p.z)
    }

    /// A particle in a 5 cm gap, 2.4 cm above its floor, remembers the floor below it. The
    /// walls move down 2 mm in the frame: the end field finds the ceiling nearer, and its
    /// vector (up) runs along the memory. The closest point jumped 4.8 cm, the walls moved
    /// 2 mm: still outside, 2.4 cm from either, and no contact.
    #[test]
    fn a_closest_point_jumping_across_a_gap_is_not_a_crossing() {
        let (start, end) = (slab(walls(0.0, 0.05)), slab(walls(-0.002, 0.048)));
        let (start, end) = (FieldView::new(&start), FieldView::new(&end));
        let c = Collider {
            start: Some(start),
            end,
            span: (0.0, 1.0),
        };
        let x = Vec3::new(0.0, 0.024, 0.0);
        let side = Vec4::new(0.0, 0.024, 0.0, 1.0);
        let eps = 0.008;
        for s in [0.1, 0.5, 0.9] {
            let got = signed_sample(&c, x, x, s, side, eps).unwrap();
            assert!((got.distance - 0.024).abs() < 1e-4, "s {s}: {got:?}");
            assert!(got.outward.y > 0.0 || s > 0.5, "s {s}: {got:?}");
        }
    }

    /// A floor rising 3 cm in a frame sweeps past a particle 1.2 cm above it: the end field
    /// finds it 1.8 cm inside (its vector up, along the memory), and the blend says inside
    /// from halfway through the frame; pushed up, out of the floor.
    #[test]
    fn a_surface_that_swept_past_a_particle_is_a_crossing() {
        let floor = |h: f32| move |p: Vec3| Vec3::new(p.x, h, p.z);
        let (start, end) = (slab(floor(0.0)), slab(floor(0.03)));
        let (start, end) = (FieldView::new(&start), FieldView::new(&end));
        let c = Collider {
            start: Some(start),
            end,
            span: (0.0, 1.0),
        };
        let x = Vec3::new(0.0, 0.012, 0.0);
        let mut side = Vec4::new(0.0, 0.012, 0.0, 1.0);
        let eps = 0.008;
        let got = signed_sample(&c, x, x, 0.6, side, eps).unwrap();
        assert!(
            (got.distance - (0.012 - 0.03 * 0.6)).abs() < 1e-4,
            "{got:?}"
        );
        let mut y = x;
        let hit = respond(&mut y, x, &got, &mut side, eps, 0.0).unwrap();
        assert!(
            hit.inside && (y.y - (0.018 + eps)).abs() < 1e-4,
            "{y} {hit:?}"
        );
    }

    fn sig((distance, outward): (f32, Vec3)) -> Signed {
        Signed {
            distance,
            outward,
            band_miss: false,
        }
    }

    #[test]
    fn friction_cancels_a_fraction_of_the_sliding() {
        let mut side = Vec4::ZERO;
        let from = Vec3::new(0.0, 0.1, 0.0);
        let mut x = Vec3::new(1.0, 0.05, 0.0);
        respond(&mut x, from, &sig((0.05, Vec3::Y)), &mut side, 0.1, 0.25);
        assert!((x - Vec3::new(0.75, 0.1, 0.0)).length() < 1e-6, "{x}");
    }
}
