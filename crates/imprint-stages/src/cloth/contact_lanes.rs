//! The contact with a body read from unsigned fields (one field, or two blended in time as
//! H eq. 13-14 does for a moving body), [`LANES`] particles at a time: the bits of
//! [`contact::signed_sample`] followed by [`contact::respond`]. Signed fields keep the
//! per-particle path in `cpu`.
//!
//! One particle at a time, a field read is a chain of dependent steps (a division, the
//! cell's index, its loads, eight additions in order, a square root) and the response another
//! (a square root and a division), with branches on which side the particle is and whether it
//! touches that follow no order a predictor can learn (a cloth resting on a body jitters about
//! ε). Here the lanes go side by side ([`FieldView::sample_lanes`]), every case is computed
//! with the scalar code's operations in its order and selected, and the loops over the lanes
//! are compiled for AVX2 where the processor has it (decided once per process, as in
//! `imprint_core::closest`): the same bits, which the unit tests check.
//!
//! [`contact::signed_sample`]: super::contact::signed_sample
//! [`contact::respond`]: super::contact::respond

use super::contact;
use super::lanes::{LANES, bool_bits, lane_vec, lanes_of, mask, select};
use super::sampler::{Corners, FieldView};
use glam::Vec3;

type Lanes = [f32; LANES];

/// What the contact of [`LANES`] particles with one body reads: borrowed where the
/// substep keeps them (copied into a struct of their own, they were 2% of its instructions).
#[derive(Clone, Copy, Debug)]
pub struct Touch<'a> {
    /// The particles' new positions, and where they were at the substep's start.
    pub x: &'a [Lanes; 3],
    pub from: &'a [Lanes; 3],
    /// The particles' memory of this body: the outward direction at their last sample
    /// (xyz), and w = 1 when known.
    pub side: &'a [Lanes; 4],
    /// The lanes that take part (a particle, not pinned).
    pub live: &'a [bool; LANES],
}

/// What the contact did, lane by lane.
#[derive(Clone, Copy, Debug, Default)]
pub struct Touched {
    /// The new positions (unchanged where there was no hit).
    pub x: [Lanes; 3],
    /// The new memory: the outward direction read and w = 1 where a live lane had a sample,
    /// else the old.
    pub side: [Lanes; 4],
    /// Pushed out to ε; of those, found inside; and how deep (ε − signed distance).
    pub hit: [bool; LANES],
    pub inside: [bool; LANES],
    pub depth: Lanes,
    /// Hits whose blend of two fields mixed a far one with a near one.
    pub band_miss: [bool; LANES],
}

/// The fields a body is read from: `end`, or blended in time from `start` to `end` with
/// weight `s` < 1 on `end` (H eq. 13-14) when `start` is `Some((start, s))`; unsigned.
#[derive(Clone, Copy)]
pub struct Fields<'a> {
    pub end: &'a FieldView<'a>,
    pub start: Option<(&'a FieldView<'a>, f32)>,
}

/// [`touch_lanes`] in the AVX2 build where the processor has it: what the tests hold to the
/// plain build and to one particle at a time (the cloth's update, compiled for AVX2 already,
/// takes `touch_lanes` into its own build).
#[cfg(test)]
#[inline]
pub fn touch(
    f: Fields,
    t: &Touch,
    eps: f32,
    friction: f32,
    corners: [&mut Corners; 2],
) -> Option<Touched> {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { touch_avx2(f, t, eps, friction, corners) };
    }
    touch_lanes(f, t, eps, friction, corners)
}

/// [`touch_lanes`] compiled for AVX2: the same operations, eight lanes per instruction.
#[cfg(all(test, target_arch = "x86_64"))]
#[target_feature(enable = "avx2")]
unsafe fn touch_avx2(
    f: Fields,
    t: &Touch,
    eps: f32,
    friction: f32,
    corners: [&mut Corners; 2],
) -> Option<Touched> {
    touch_lanes(f, t, eps, friction, corners)
}

/// A sample read as signed, for one lane: whether there is one, the signed distance and
/// the outward direction.
type Signed = (bool, f32, [f32; 3]);

/// Reads the body at the lanes' new positions and responds, as
/// [`super::contact::signed_sample`] and then [`super::contact::respond`] do one particle at
/// a time, in the caller's build: inlined into the cloth's AVX2 update, which spares a call
/// per block, the copies of its arguments and result through memory, and a feature check
/// (with `lane_bits`' `movmskps`, 4% of the 128² cloth's instructions). `corners` holds the
/// lanes' cells of the `end` and `start` fields from the last read of these fields
/// ([`Corners`]). `None` where no lane has a sample (every lane far from the body): the
/// positions and memories stay as they are, and nothing is copied.
#[inline(always)]
pub(super) fn touch_lanes(
    f: Fields,
    t: &Touch,
    eps: f32,
    friction: f32,
    corners: [&mut Corners; 2],
) -> Option<Touched> {
    let SignedLanes {
        some,
        distance,
        outward,
        miss,
    } = signed_lanes(f, t, eps, corners)?;
    // Every lane pushed, then each lane's new position and memory selected in a loop of
    // their own ([`select`]): selected in this loop, they compiled to masked stores, which
    // on AMD processors take many cycles.
    let (mut pushed, mut read) = ([0u32; LANES], [0u32; LANES]);
    let mut x_pushed = [[0.0f32; LANES]; 3];
    let (mut hit, mut depth) = ([false; LANES], [0.0f32; LANES]);
    let (mut inside, mut band_miss) = ([false; LANES], [false; LANES]);
    for m in 0..LANES {
        // `respond`: the memory, then a push to ε along the outward direction normalised
        // (`try_normalize`: none unless 1 / length is a positive finite number), friction.
        let (o, d) = (each(|k| outward[k][m]), distance[m]);
        let valid = t.live[m] & some[m];
        let rcp: f32 = 1.0 / length(o);
        hit[m] = valid & (d < eps) & rcp.is_finite() & (rcp > 0.0);
        let n = each(|k| o[k] * rcp);
        depth[m] = eps - d;
        let mut x = each(|k| t.x[k][m] + depth[m] * n[k]);
        if friction > 0.0 {
            let q = each(|k| x[k] - t.from[k][m]);
            let along = q[0] * n[0] + q[1] * n[1] + q[2] * n[2];
            x = each(|k| x[k] - friction * (q[k] - along * n[k]));
        }
        (pushed[m], read[m]) = (mask(hit[m]), mask(valid));
        (0..3).for_each(|k| x_pushed[k][m] = x[k]);
        inside[m] = hit[m] & (d < 0.0);
        band_miss[m] = hit[m] & miss[m];
    }
    let (mut x_out, mut side) = ([[0.0f32; LANES]; 3], [[0.0f32; LANES]; 4]);
    for m in 0..LANES {
        for k in 0..3 {
            x_out[k][m] = select(pushed[m], x_pushed[k][m], t.x[k][m]);
            side[k][m] = select(read[m], outward[k][m], t.side[k][m]);
        }
        side[3][m] = select(read[m], 1.0, t.side[3][m]);
    }
    Some(Touched {
        x: x_out,
        side,
        hit,
        inside,
        depth,
        band_miss,
    })
}

/// The lanes' samples read as signed ([`super::contact::signed_sample`]'s bits): whether
/// there is one, the signed distance, the outward direction, and whether a blend of two fields
/// mixed a far one with a near one.
struct SignedLanes {
    some: [bool; LANES],
    distance: Lanes,
    outward: [Lanes; 3],
    miss: [bool; LANES],
}

/// The body read at the lanes' new positions, as signed; `None` when every lane is far from
/// it in every field (no lane has a sample, as a read with no vector classifies as none).
// A lane indexes the samples and the outputs alike.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn signed_lanes(
    Fields { end, start }: Fields,
    t: &Touch,
    eps: f32,
    [end_corners, start_corners]: [&mut Corners; 2],
) -> Option<SignedLanes> {
    let end_cells = end.cell_lanes(t.x);
    let start_cells = start.map(|(f, _)| f.cell_lanes(t.x));
    if end.lanes_far(&end_cells)
        && start
            .zip(start_cells.as_ref())
            .is_none_or(|((f, _), c)| f.lanes_far(c))
    {
        return None;
    }
    let (db, vb, ib) = end.sample_lanes(t.x, &end_cells, end_corners);
    let lane = |v: &[Lanes; 3], m: usize| [v[0][m], v[1][m], v[2][m]];
    let side = |m: usize| [t.side[0][m], t.side[1][m], t.side[2][m], t.side[3][m]];
    let reach = |m: usize| 2.0 * eps + length(each(|k| t.x[k][m] - t.from[k][m]));
    // Each lane's sample read as signed, in straight loops over the lanes (which vectorise).
    let mut out = SignedLanes {
        some: [false; LANES],
        distance: [0.0; LANES],
        outward: [[0.0; LANES]; 3],
        miss: [false; LANES],
    };
    match start {
        None => {
            for m in 0..LANES {
                let o;
                (out.some[m], out.distance[m], o) =
                    classify(db[m], lane(&vb, m), side(m), reach(m));
                (0..3).for_each(|k| out.outward[k][m] = o[k]);
            }
        }
        Some((start, s)) => {
            let cells = start_cells.as_ref().expect("computed with start");
            let (da, va, ia) = start.sample_lanes(t.x, cells, start_corners);
            let motion = turned_motion(t, (start, &va, ia), (end, &vb, ib));
            for m in 0..LANES {
                let (a, b) = ((da[m], lane(&va, m)), (db[m], lane(&vb, m)));
                let own = reach(m);
                let moved = [own + motion[0][m], own + motion[1][m]];
                let ((p, d, o), band_miss) =
                    blend(a, ia[m], b, ib[m], s, side(m), (own, moved), eps);
                (out.some[m], out.distance[m], out.miss[m]) = (p, d, band_miss);
                (0..3).for_each(|k| out.outward[k][m] = o[k]);
            }
        }
    }
    Some(out)
}

/// For the lanes whose vector in a field's band turned round against their memory
/// (`[start, end]`, by lane): [`contact::moved`] at that field's closest point, a read of
/// the other field, no more than the closest point's jump (or than the band, where the
/// other field is far). Rare (a few lanes of a few blocks), so read one at a time; zero
/// elsewhere, where the reading does not depend on it.
#[allow(clippy::needless_range_loop)]
#[inline(always)]
fn turned_motion(
    t: &Touch,
    (start, va, ia): (&FieldView, &[Lanes; 3], [bool; LANES]),
    (end, vb, ib): (&FieldView, &[Lanes; 3], [bool; LANES]),
) -> [Lanes; 2] {
    let along = |v: &[Lanes; 3], m: usize| {
        v[0][m] * t.side[0][m] + v[1][m] * t.side[1][m] + v[2][m] * t.side[2][m]
    };
    let mut turned = [[false; LANES]; 2];
    for m in 0..LANES {
        let known = t.side[3][m] > 0.0;
        turned[0][m] = known & ia[m] & (along(va, m) > 0.0);
        turned[1][m] = known & ib[m] & (along(vb, m) > 0.0);
    }
    let mut motion = [[0.0; LANES]; 2];
    for m in lanes_of(bool_bits(&turned[0]) | bool_bits(&turned[1])) {
        let x = Vec3::new(t.x[0][m], t.x[1][m], t.x[2][m]);
        let (a, b) = (lane_vec(va, m), lane_vec(vb, m));
        let jump = if ia[m] & ib[m] {
            (b - a).length()
        } else {
            end.field.far_value()
        };
        if turned[0][m] {
            motion[0][m] = contact::moved(x + a, end, jump);
        }
        if turned[1][m] {
            motion[1][m] = contact::moved(x + b, start, jump);
        }
    }
    motion
}

/// The signed distance [`super::contact::signed_sample`] gives at each lane's position `x`
/// with no motion (`from` = `x`), remembering `side` (xyz, w = 1 when known): what the check
/// at a frame's end reads; `None` where there is no sample. `corners` holds the lanes' cells
/// ([`Corners`]).
#[inline]
pub fn resting(
    f: Fields,
    x: &[Lanes; 3],
    side: &[Lanes; 4],
    eps: f32,
    corners: [&mut Corners; 2],
) -> [Option<f32>; LANES] {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { resting_avx2(f, x, side, eps, corners) };
    }
    resting_lanes(f, x, side, eps, corners)
}

/// [`resting_lanes`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn resting_avx2(
    f: Fields,
    x: &[Lanes; 3],
    side: &[Lanes; 4],
    eps: f32,
    corners: [&mut Corners; 2],
) -> [Option<f32>; LANES] {
    resting_lanes(f, x, side, eps, corners)
}

#[inline(always)]
fn resting_lanes(
    f: Fields,
    x: &[Lanes; 3],
    side: &[Lanes; 4],
    eps: f32,
    corners: [&mut Corners; 2],
) -> [Option<f32>; LANES] {
    let t = Touch {
        x,
        from: x,
        side,
        live: &[true; LANES],
    };
    let mut out = [None; LANES];
    if let Some(s) = signed_lanes(f, &t, eps, corners) {
        for (m, out) in out.iter_mut().enumerate() {
            *out = s.some[m].then_some(s.distance[m]);
        }
    }
    out
}

/// `[f(0), f(1), f(2)]` (`array::map` is not inlined into the AVX2 build).
#[inline(always)]
fn each(f: impl Fn(usize) -> f32) -> [f32; 3] {
    [f(0), f(1), f(2)]
}

#[inline(always)]
fn length(v: [f32; 3]) -> f32 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// `contact::classify` without a sign: a vector and a finite distance, else no sample; the
/// particle crossed when the vector runs along its remembered outward direction and the
/// surface is within `reach`.
#[inline(always)]
fn classify(d: f32, v: [f32; 3], side: [f32; 4], reach: f32) -> Signed {
    let valid = d.is_finite() & ((v[0] != 0.0) | (v[1] != 0.0) | (v[2] != 0.0));
    let along_memory = v[0] * side[0] + v[1] * side[1] + v[2] * side[2];
    let crossed = (side[3] > 0.0) & (along_memory > 0.0) & (d < reach);
    let outward = each(|k| if crossed { v[k] } else { -v[k] });
    (valid, if crossed { -d } else { d }, outward)
}

/// `contact::signed_sample`'s blend of the two fields' samples `a` (start) and `b` (end),
/// each (distance, vector) and whether in the band, at weight `s`: also whether the blend
/// mixed a far field with a near one (a band miss). `reach` is the particle's own, then per
/// field with the body's motion added ([`turned_motion`]).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn blend(
    a: (f32, [f32; 3]),
    a_in: bool,
    b: (f32, [f32; 3]),
    b_in: bool,
    s: f32,
    side: [f32; 4],
    (reach, moved): (f32, [f32; 2]),
    eps: f32,
) -> (Signed, bool) {
    let mix = |p: f32, q: f32| p + (q - p) * s;
    match (a_in, b_in) {
        (true, true) => {
            let (p0, q0) = (
                classify(a.0, a.1, side, moved[0]),
                classify(b.0, b.1, side, moved[1]),
            );
            let agree = a.1[0] * b.1[0] + a.1[1] * b.1[1] + a.1[2] * b.1[2] < 0.0;
            let outside = |r: Signed| {
                if r.0 & (r.1 >= 0.0) {
                    contact::sweep(r.1, agree)
                } else {
                    0.0
                }
            };
            let p = classify(a.0, a.1, side, moved[0] - outside(q0));
            let q = classify(b.0, b.1, side, moved[1] - outside(p0));
            let distance = mix(p.1, q.1);
            // In contact the outward directions are blended as unit vectors.
            let unit = |o: [f32; 3]| {
                let r = 1.0 / length(o);
                if distance < eps {
                    each(|k| o[k] * r)
                } else {
                    o
                }
            };
            let (np, nq) = (unit(p.2), unit(q.2));
            let both = (true, distance, each(|k| mix(np[k], nq[k])));
            let one = if q.0 { q } else { p };
            (if p.0 & q.0 { both } else { one }, false)
        }
        (false, true) => (classify(b.0, b.1, side, moved[1]), true),
        (true, false) => (classify(a.0, a.1, side, moved[0]), true),
        (false, false) => {
            // Both at the band's edge: the blends of the cells' trilinear samples.
            let v = each(|k| mix(a.1[k], b.1[k]));
            (classify(mix(a.0, b.0), v, side, reach), false)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloth::contact::{self, Collider};
    use glam::{UVec3, Vec3, Vec4};
    use imprint_core::{DistanceField, GridSpec};

    /// A uniform number in [0, 1) from a linear congruential sequence (deterministic).
    fn uniform(state: &mut u64) -> f32 {
        *state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (*state >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A point uniform in [-0.5, 0.5)³.
    fn centred(state: &mut u64) -> Vec3 {
        Vec3::new(uniform(state), uniform(state), uniform(state)) - 0.5
    }

    /// The exact field of a sphere of radius `r` about `c` on a 40³ grid of 2 cm cells.
    fn sphere(r: f32, c: Vec3) -> DistanceField {
        let spec = GridSpec::new(Vec3::splat(-0.39), 0.02, UVec3::splat(40)).unwrap();
        DistanceField::from_closest_points(spec, 3.0, |p| {
            c + r * (p - c).try_normalize().unwrap_or(Vec3::X)
        })
    }

    /// A [`Touch`]'s arrays, owned.
    #[derive(Clone, Copy, Default)]
    struct Lanes8 {
        x: [Lanes; 3],
        from: [Lanes; 3],
        side: [Lanes; 4],
        live: [bool; LANES],
    }

    impl Lanes8 {
        fn touch(&self) -> Touch<'_> {
            Touch {
                x: &self.x,
                from: &self.from,
                side: &self.side,
                live: &self.live,
            }
        }
    }

    /// Eight random particles about a sphere of radius `r`: in the band on both sides, at
    /// its edge, far, in the grid's outermost cells and off it (every fourth `round`), with
    /// and without a memory, some pinned.
    fn particles(rng: &mut u64, r: f32, round: usize) -> Lanes8 {
        let mut t = Lanes8::default();
        for m in 0..LANES {
            let x = match round % 4 {
                0 => centred(rng) * 1.2,
                _ => centred(rng).normalize_or(Vec3::Y) * (r + 0.12 * (uniform(rng) - 0.5)),
            };
            let from = x + centred(rng) * 0.03;
            let side = centred(rng).extend((uniform(rng) > 0.3) as u32 as f32);
            for a in 0..3 {
                (t.x[a][m], t.from[a][m]) = (x[a], from[a]);
            }
            for a in 0..4 {
                t.side[a][m] = side[a];
            }
            t.live[m] = uniform(rng) > 0.1;
        }
        t
    }

    /// What [`touch`] did, with `None` (no lane near the body) as its meaning: every lane
    /// unchanged, no hit.
    fn or_unchanged(r: Option<Touched>, t: &Touch) -> Touched {
        r.unwrap_or(Touched {
            x: *t.x,
            side: *t.side,
            ..Default::default()
        })
    }

    /// [`touch_lanes`] (in the caller's build) with no cells held, as [`or_unchanged`] gives it.
    fn touch_afresh(fields: Fields, t: &Touch, eps: f32, friction: f32) -> Touched {
        let mut held: [Corners; 2] = Default::default();
        or_unchanged(touch_lanes(fields, t, eps, friction, held.each_mut()), t)
    }

    /// Checks `lanes` against the per-particle sample and response of `collider` at frame
    /// fraction `s`; returns (hits, particles found inside, band misses).
    /// [`resting`] gives `signed_sample`'s distance at each lane's position with no motion,
    /// to the bit; returns how many lanes had a sample.
    fn resting_as_scalar(
        collider: &Collider,
        fields: Fields,
        s: f32,
        t: &Touch,
        eps: f32,
        corners: [&mut Corners; 2],
    ) -> u32 {
        let got = resting(fields, t.x, t.side, eps, corners);
        for (m, got) in got.iter().enumerate() {
            let x = Vec3::new(t.x[0][m], t.x[1][m], t.x[2][m]);
            let side = Vec4::new(t.side[0][m], t.side[1][m], t.side[2][m], t.side[3][m]);
            let want = contact::signed_sample(collider, x, x, s, side, eps).map(|s| s.distance);
            assert_eq!(got.map(f32::to_bits), want.map(f32::to_bits), "{x}");
        }
        got.iter().flatten().count() as u32
    }

    fn same_as_scalar(
        collider: &Collider,
        s: f32,
        t: &Touch,
        lanes: &Touched,
        (eps, friction): (f32, f32),
    ) -> (u32, u32, u32) {
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        let mut counts = (0, 0, 0);
        for m in 0..LANES {
            let x = Vec3::new(t.x[0][m], t.x[1][m], t.x[2][m]);
            let from = Vec3::new(t.from[0][m], t.from[1][m], t.from[2][m]);
            let mut side = Vec4::new(t.side[0][m], t.side[1][m], t.side[2][m], t.side[3][m]);
            let mut y = x;
            let sample = t.live[m]
                .then(|| contact::signed_sample(collider, x, from, s, side, eps))
                .flatten();
            let hit =
                sample.and_then(|s| contact::respond(&mut y, from, &s, &mut side, eps, friction));
            let got = Vec4::from_array(lanes.side.map(|a| a[m]));
            assert_eq!(
                got.to_array().map(f32::to_bits),
                side.to_array().map(f32::to_bits)
            );
            assert_eq!(lanes.hit[m], hit.is_some(), "{x}");
            let got = Vec3::new(lanes.x[0][m], lanes.x[1][m], lanes.x[2][m]);
            assert_eq!(bits(got), bits(y), "{x}");
            if let Some(h) = hit {
                let miss = sample.is_some_and(|s| s.band_miss);
                assert_eq!(lanes.depth[m].to_bits(), h.depth.to_bits());
                assert_eq!((lanes.inside[m], lanes.band_miss[m]), (h.inside, miss));
                counts.0 += 1;
                counts.1 += h.inside as u32;
                counts.2 += miss as u32;
            }
        }
        counts
    }

    /// Eight particles at a time give the per-particle contact's positions, memories and
    /// counts to the bit, and the field reads its samples, with and without friction; the
    /// build without AVX2 gives the same.
    #[test]
    fn same_bits_as_one_particle_at_a_time() {
        let (r, eps) = (0.3, 0.02);
        let field = sphere(r, Vec3::ZERO);
        let view = FieldView::new(&field);
        let collider = Collider {
            start: None,
            end: view,
            span: (0.0, 1.0),
        };
        let mut rng = 0x9e3779b97f4a7c15u64;
        let (mut hits, mut inside, mut resting_samples) = (0, 0, 0);
        // Kept across the rounds, as the cloth keeps it across substeps: most lanes of a
        // round's second read find their cells held, the next round's lanes seldom do.
        let mut kept: [Corners; 2] = Default::default();
        for round in 0..4000 {
            let first = particles(&mut rng, r, round);
            let friction = if round % 2 == 0 { 0.3 } else { 0.0 };
            let fields = Fields {
                end: &view,
                start: None,
            };
            for nudge in [0.0, 1e-4] {
                let mut owned = first;
                owned.x.iter_mut().flatten().for_each(|x| *x += nudge);
                let t = owned.touch();
                let lanes = or_unchanged(touch(fields, &t, eps, friction, kept.each_mut()), &t);
                let (d, v, in_band) =
                    view.sample_lanes(t.x, &view.cell_lanes(t.x), &mut Corners::default());
                for m in 0..LANES {
                    let f = view.sample(Vec3::new(t.x[0][m], t.x[1][m], t.x[2][m]));
                    let vector = Vec3::new(v[0][m], v[1][m], v[2][m]).to_array();
                    assert_eq!(d[m].to_bits(), f.distance.to_bits());
                    assert_eq!(
                        vector.map(f32::to_bits),
                        f.vector.to_array().map(f32::to_bits)
                    );
                    assert_eq!(in_band[m], f.in_band);
                }
                let plain = touch_afresh(fields, &t, eps, friction);
                assert_eq!(format!("{lanes:?}"), format!("{plain:?}"));
                let (h, i, _) = same_as_scalar(&collider, 1.0, &t, &lanes, (eps, friction));
                (hits, inside) = (hits + h, inside + i);
                resting_samples +=
                    resting_as_scalar(&collider, fields, 1.0, &t, eps, kept.each_mut());
            }
        }
        // The cases were met: contacts, and particles found across the surface.
        assert!(hits > 1000 && inside > 100, "{hits} hits, {inside} inside");
        assert!(resting_samples > 10_000, "{resting_samples}");
    }

    /// The same for a body read from two fields blended in time (a sphere that grew and
    /// moved between them), at weights across the frame.
    #[test]
    fn blended_same_bits_as_one_particle_at_a_time() {
        let (r, eps) = (0.3, 0.02);
        let (a, b) = (
            sphere(r, Vec3::ZERO),
            sphere(r + 0.015, Vec3::new(0.02, 0.0, 0.01)),
        );
        let (va, vb) = (FieldView::new(&a), FieldView::new(&b));
        let collider = Collider {
            start: Some(va),
            end: vb,
            span: (0.0, 1.0),
        };
        let mut rng = 0x2545f4914f6cdd1du64;
        let (mut hits, mut inside, mut misses, mut resting_samples) = (0, 0, 0, 0);
        let mut kept: [Corners; 2] = Default::default();
        for round in 0..4000 {
            let first = particles(&mut rng, r, round);
            let friction = if round % 2 == 0 { 0.3 } else { 0.0 };
            let s = uniform(&mut rng);
            for nudge in [0.0, 1e-4] {
                let mut owned = first;
                owned.x.iter_mut().flatten().for_each(|x| *x += nudge);
                let t = owned.touch();
                let fields = Fields {
                    end: &vb,
                    start: Some((&va, s)),
                };
                let lanes = or_unchanged(touch(fields, &t, eps, friction, kept.each_mut()), &t);
                let plain = touch_afresh(fields, &t, eps, friction);
                assert_eq!(format!("{lanes:?}"), format!("{plain:?}"));
                let (h, i, b) = same_as_scalar(&collider, s, &t, &lanes, (eps, friction));
                (hits, inside, misses) = (hits + h, inside + i, misses + b);
                resting_samples +=
                    resting_as_scalar(&collider, fields, s, &t, eps, kept.each_mut());
            }
        }
        assert!(
            hits > 1000 && inside > 100 && misses > 10 && resting_samples > 10_000,
            "{hits}, {inside}, {misses}, {resting_samples}"
        );
    }
}
