//! The one-shot fit on the CPU: depth maps of the body per view, the exact inside test, the
//! pushes and their check, and the distance-field fallback (see the module doc of
//! [`super`] for the method and the definitions).

use super::collider::distinct_lines;
use super::inside::{InsideTest, Lines};
use super::params::{DrapeParams, Fallback};
use crate::snow::arrival::{Lookup, snow_camera};
use glam::Vec3;
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{BoundaryVariant, DistanceField, GridSpec, Mesh, Result, Sampling};
use rayon::prelude::*;

/// What one call did.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DrapeReport {
    /// Garment vertices given.
    pub vertices: usize,
    /// Vertices inside the body before the call (the exact inside test).
    pub inside: usize,
    /// Vertices whose position changed.
    pub moved: usize,
    /// Inside vertices no view resolved (before any fallback).
    pub unresolved_by_views: usize,
    /// Of those, the ones the fallback resolved.
    pub resolved_by_fallback: usize,
    /// Inside vertices left unresolved after the fallback (left where they were).
    pub unresolved: usize,
    /// Vertices inside the body after the call (the exact inside test): the unresolved ones,
    /// and pushed ones that ended short of the surface (a push is checked to leave the body
    /// by half a texel past the pushed point, so it may end inside by less than that). What
    /// the node counts and warns about; never an error (see the node).
    pub inside_after: usize,
    /// Longest push applied, m.
    pub max_push: f32,
    /// The largest depth-map texel of the views, m (the resolution of the fit).
    pub texel: f32,
}

/// Two depth maps of the body along one view: `front` looks along `dir`, `back` against it.
struct View {
    dir: Vec3,
    front: DepthMap,
    front_look: Lookup,
    back: DepthMap,
    back_look: Lookup,
}

/// The push of one view for one vertex: unit direction and length (offset included).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Push {
    pub dir: Vec3,
    pub length: f32,
}

/// The surface depth a push goes to: the smallest covered depth of the 2×2 texels around the
/// projection (conservative near silhouettes, where the depth changes fast across a texel),
/// provided the texel the point falls in is covered and the point lies behind it. `None`
/// when the point is not behind the surface this map sees.
fn behind(map: &DepthMap, look: &Lookup, p: Vec3) -> Option<f32> {
    let (px, py, depth) = look.project(p);
    let last = look.res as f32 - 1.0;
    if !(px >= 0.0 && py >= 0.0 && px <= last + 1.0 && py <= last + 1.0) {
        return None;
    }
    // Read from the depths alone: an uncovered texel holds +∞ (`DepthMap`'s contract), so it
    // has nothing in front of the point and is never the nearest. (Reading the coverage too
    // doubled the cache lines a lookup touches.)
    let at = |i: u32, j: u32| map.depth[map.index(i, j)];
    // Truncation is the floor of these non-negative coordinates (and 0 for those in
    // (−1, 0), as `max(0.0)` would make it); `floor` is a library call on x86-64 without
    // SSE4.1. Through a signed conversion, one instruction (to an unsigned one, with the
    // saturating cast's fix-ups, about ten).
    // SAFETY: −0.5 ≤ c ≤ res + 1 (tested above, so not NaN), which an i32 holds.
    let trunc = |c: f32| unsafe { c.to_int_unchecked::<i32>() } as u32;
    let last = look.res - 1;
    let (i, j) = (trunc(px).min(last), trunc(py).min(last));
    let seen = at(i, j);
    if seen == f32::INFINITY || depth <= seen {
        return None;
    }
    let (i0, j0) = (trunc(px - 0.5), trunc(py - 0.5));
    let mut nearest = seen;
    for (a, b) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
        if i0 + a < map.width && j0 + b < map.height {
            nearest = nearest.min(at(i0 + a, j0 + b));
        }
    }
    Some(depth - nearest)
}

impl View {
    /// The push of this view for `p`, when it sees `p` inside: to the nearer of the two
    /// surfaces, plus `offset`.
    fn push(&self, p: Vec3, offset: f32) -> Option<Push> {
        let f = behind(&self.front, &self.front_look, p)?;
        let b = behind(&self.back, &self.back_look, p)?;
        Some(if f <= b {
            Push {
                dir: -self.dir,
                length: f + offset,
            }
        } else {
            Push {
                dir: self.dir,
                length: b + offset,
            }
        })
    }
}

/// What a drape reads of the body: the maps per distinct view line and the inside test.
struct Prepared {
    views: Vec<View>,
    test: InsideTest,
    /// The largest texel of the maps, m.
    texel: f32,
}

/// A prepared body with what identifies it: its positions (as bits) and triangles, the map
/// resolution and the distinct view lines. The maps and the inside test depend on nothing else.
struct Cached {
    positions: Vec<[u32; 3]>,
    triangles: Vec<[u32; 3]>,
    resolution: u32,
    lines: Vec<[u32; 3]>,
    prepared: Prepared,
}

impl Cached {
    fn is_for(&self, body: &Mesh, resolution: u32, lines: &[[u32; 3]]) -> bool {
        self.resolution == resolution
            && self.lines == lines
            && self.triangles == body.triangles
            && self.positions.len() == body.positions.len()
            && self
                .positions
                .iter()
                .zip(&body.positions)
                .all(|(a, b)| *a == b.to_array().map(f32::to_bits))
    }
}

/// The last body a caller draped on, kept for its next call: a pipeline with a static body
/// re-drapes every frame, and the maps and inside test (most of a call) need not be made
/// again. Each caller (a Drape node) holds its own, so two bodies never evict each other.
#[derive(Default)]
pub struct BodyCache(Option<Cached>);

/// The one-shot fit on the CPU: pushes the garment's vertices out of the body in place and
/// reports what it did. The body should be closed (see the module doc); the garment is any
/// set of points (a mesh's positions, a cloth's particles).
pub fn drape_cpu(body: &Mesh, garment: &mut [Vec3], params: &DrapeParams) -> Result<DrapeReport> {
    drape_cached(&mut BodyCache::default(), body, garment, params)
}

/// [`drape_cpu`] reusing the maps and the inside test `cache` holds when `body` is the one it
/// was made for (positions and triangles bit for bit, same resolution and view lines), with
/// the same result as a fresh call; otherwise it prepares `body` and keeps it in `cache`.
pub fn drape_cached(
    cache: &mut BodyCache,
    body: &Mesh,
    garment: &mut [Vec3],
    params: &DrapeParams,
) -> Result<DrapeReport> {
    params.validate()?;
    if garment.is_empty() || body.triangles.is_empty() || body.bounds().is_empty() {
        return fit(None, body, garment, params);
    }
    let lines: Vec<[u32; 3]> = distinct_lines(&params.views)
        .iter()
        .map(|v| v.to_array().map(f32::to_bits))
        .collect();
    let res = params.resolution;
    let kept = cache.0.take().filter(|c| c.is_for(body, res, &lines));
    let cached = match kept {
        Some(c) => c,
        None => Cached {
            prepared: prepare(body, params, rasterize_depth_with)?,
            positions: body
                .positions
                .iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect(),
            triangles: body.triangles.clone(),
            resolution: res,
            lines,
        },
    };
    let report = fit(Some(&cached.prepared), body, garment, params);
    cache.0 = Some(cached);
    report
}

/// A depth rasteriser with the signature of `imprint_core::raster::rasterize_depth_with`
/// (the GPU one is a closure over its context).
pub trait Rasterize:
    FnMut(&Mesh, &imprint_core::camera::Camera, u32, u32, &RasterOptions) -> Result<DepthMap>
{
}

impl<F> Rasterize for F where
    F: FnMut(&Mesh, &imprint_core::camera::Camera, u32, u32, &RasterOptions) -> Result<DepthMap>
{
}

/// [`drape_cpu`] with the depth maps from any [`Rasterize`]r; the pushes and the inside test
/// run on the CPU. Nothing is kept between calls.
pub fn drape_with(
    body: &Mesh,
    garment: &mut [Vec3],
    params: &DrapeParams,
    rasterize: impl Rasterize,
) -> Result<DrapeReport> {
    params.validate()?;
    if garment.is_empty() || body.triangles.is_empty() || body.bounds().is_empty() {
        return fit(None, body, garment, params);
    }
    let prepared = prepare(body, params, rasterize)?;
    fit(Some(&prepared), body, garment, params)
}

/// The maps of a body with triangles and a non-empty box, and its inside test.
fn prepare(body: &Mesh, params: &DrapeParams, mut rasterize: impl Rasterize) -> Result<Prepared> {
    let bounds = body.bounds();
    let res = params.resolution;
    // The inside test is built while the maps are rendered: its three axes do not share two
    // threads evenly, the renders fill the gap. (The rasteriser may not be `Send`, so the
    // build is the spawned job.)
    let mut test = None;
    let views = rayon::in_place_scope(|s| {
        // The garment lies near the surface, where the far-cell grid seldom answers.
        s.spawn(|_| test = Some(InsideTest::rays_only(body)));
        // Opposite directions give the same pair of maps (front of d = back of −d), hence the
        // same pushes: one view per line (T's three views are two lines).
        let mut views = Vec::with_capacity(params.views.len());
        for dir in distinct_lines(&params.views) {
            let mut map = |d: Vec3| -> Result<(DepthMap, Lookup)> {
                let cam = snow_camera(&bounds, d, res)?;
                let m = rasterize(body, &cam, res, res, &RasterOptions::default())?;
                let look = Lookup::new(&m);
                Ok((m, look))
            };
            let (front, front_look) = map(dir)?;
            let (back, back_look) = map(-dir)?;
            views.push(View {
                dir,
                front,
                front_look,
                back,
                back_look,
            });
        }
        Ok::<_, imprint_core::Error>(views)
    })?;
    let test = test.expect("the scope ran the build");
    let texel = views.iter().fold(0f32, |t, v| {
        t.max(v.front_look.texel).max(v.back_look.texel)
    });
    Ok(Prepared { views, test, texel })
}

/// What the fit does with one vertex: `None` = outside (untouched); `Some(Ok((new, inside
/// there)))` = resolved; `Some(Err(()))` = inside and unresolved by the views.
type Outcome = Option<std::result::Result<(Vec3, bool), ()>>;

/// Vertices the fit takes together (the inside test's rays go axis by axis over them).
const BATCH: usize = 128;

/// A fit worker's buffers for one batch.
struct Batch {
    crossings: Vec<f64>,
    points: Vec<Vec3>,
    lines: Vec<Lines>,
    inside: Vec<bool>,
}

impl Batch {
    fn new(n: usize) -> Self {
        Batch {
            crossings: Vec::new(),
            points: Vec::with_capacity(n),
            lines: vec![Lines::default(); n],
            inside: vec![false; n],
        }
    }
}

/// The pushes of the garment's vertices out of the prepared body (`None`: nothing to fit:
/// no garment, or a body without triangles or box).
fn fit(
    prepared: Option<&Prepared>,
    body: &Mesh,
    garment: &mut [Vec3],
    params: &DrapeParams,
) -> Result<DrapeReport> {
    let mut report = DrapeReport {
        vertices: garment.len(),
        ..Default::default()
    };
    let Some(Prepared { views, test, texel }) = prepared else {
        return Ok(report);
    };
    report.texel = *texel;
    let texel = *texel;
    let offset = params.offset;

    // Visited in the test's locality order (the answers do not depend on the order), a batch
    // at a time: the inside test asks the batch's rays axis by axis.
    let order = test.locality_order(garment);
    let found: Vec<Vec<Outcome>> = order
        .par_chunks(BATCH)
        .map_init(
            || Batch::new(BATCH),
            |Batch {
                 crossings,
                 points,
                 lines,
                 inside,
             },
             chunk| {
                points.clear();
                points.extend(chunk.iter().map(|&i| garment[i as usize]));
                let n = points.len();
                // The drape's test has no far-cell grid: `inside` is `exact`, here keeping the
                // axis lines through p for the push's check and the self-check of its end.
                test.exact_keeping(points, &mut lines[..n], &mut inside[..n]);
                let each = points.iter().zip(&lines[..n]).zip(&inside[..n]);
                each.map(|((&p, lines), &inside)| {
                    inside.then(|| push_out(test, views, p, lines, (offset, texel), crossings))
                })
                .collect()
            },
        )
        .collect();
    let mut outcome = vec![None; garment.len()];
    for (&i, o) in order.iter().zip(found.into_iter().flatten()) {
        outcome[i as usize] = o;
    }

    let mut unresolved: Vec<usize> = Vec::new();
    // Vertices pushed out by the fallback: the only ones whose inside test may have changed
    // and is not known yet.
    let mut pushed: Vec<usize> = Vec::new();
    // Vertices the views pushed that are still inside (checked above).
    let mut short = 0;
    for (i, o) in outcome.iter().enumerate() {
        match o {
            None => {}
            Some(Ok((q, inside))) => {
                report.inside += 1;
                short += *inside as usize;
                apply(&mut report, &mut garment[i], *q);
            }
            Some(Err(())) => {
                report.inside += 1;
                unresolved.push(i);
            }
        }
    }
    report.unresolved_by_views = unresolved.len();

    if let (Fallback::DistanceField { resolution, band }, false) =
        (params.fallback, unresolved.is_empty())
    {
        let field = body_field(body, resolution, band)?;
        let step = field.spec.cell.min(texel);
        let fixed: Vec<Option<Vec3>> = unresolved
            .par_iter()
            .map_init(Vec::new, |crossings, &i| {
                let (p, candidates) = field_push(&field, garment[i], offset);
                candidates
                    .into_iter()
                    .flatten()
                    .find(|push| leaves_cleanly(test, p, *push, step, crossings, None))
                    .map(|push| p + push.dir * push.length)
            })
            .collect();
        for (&i, q) in unresolved.iter().zip(fixed) {
            if let Some(q) = q {
                report.resolved_by_fallback += 1;
                pushed.push(i);
                apply(&mut report, &mut garment[i], q);
            }
        }
    }
    report.unresolved = report.unresolved_by_views - report.resolved_by_fallback;
    // The self-check: inside after the call. Outside vertices did not move and unresolved
    // ones stayed inside, so only the pushed ones are tested again (each was tested along
    // its push already: no more than the fit's own queries); those the views pushed were
    // tested above.
    short += pushed
        .par_iter()
        .with_min_len(256)
        .filter(|&&i| test.inside(garment[i]))
        .count();
    report.inside_after = report.unresolved + short;
    Ok(report)
}

/// The views' push of an inside vertex `p` (the shortest), when its path leaves the body
/// cleanly: the pushed point and whether it is still inside; `lines` were kept at `p`.
fn push_out(
    test: &InsideTest,
    views: &[View],
    p: Vec3,
    lines: &Lines,
    (offset, texel): (f32, f32),
    crossings: &mut Vec<f64>,
) -> std::result::Result<(Vec3, bool), ()> {
    let best = views
        .iter()
        .filter_map(|v| v.push(p, offset))
        .min_by(|a, b| a.length.total_cmp(&b.length));
    match best {
        Some(push) if leaves_cleanly(test, p, push, texel, crossings, Some(lines)) => {
            let q = p + push.dir * push.length;
            Ok((q, test.exact_on_lines(q, lines)))
        }
        _ => Err(()),
    }
}

fn apply(report: &mut DrapeReport, p: &mut Vec3, q: Vec3) {
    if q != *p {
        report.moved += 1;
        report.max_push = report.max_push.max((q - *p).length());
        *p = q;
    }
}

/// Whether the straight path of a push leaves the body once and for all, to half a `texel`
/// past the pushed point: it crosses the surface once (crossings that coincide, as on a face
/// two touching pieces share, cancel in pairs) and ends outside. `p` is inside; `lines`, when
/// given, were kept at `p` ([`InsideTest::exact_keeping`]).
///
/// Along an axis the crossings are exact: one walk of the inside test's triangle list for that
/// axis ([`InsideTest::ray_crossings`]), where the ray agrees with the test's vote at `p`.
/// Otherwise the path is sampled every half texel with the full test ([`sampled_path`]).
fn leaves_cleanly(
    test: &InsideTest,
    p: Vec3,
    push: Push,
    texel: f32,
    crossings: &mut Vec<f64>,
    lines: Option<&Lines>,
) -> bool {
    let Some(axis) = (0..3).find(|&a| push.dir[a].abs() == 1.0) else {
        return sampled_path(test, p, push, texel);
    };
    let end = p + push.dir * (push.length + 0.5 * texel);
    let reach = (end[axis] as f64 - p[axis] as f64).abs();
    let positive = push.dir[axis] > 0.0;
    let odd = match lines {
        Some(l) => test.ray_crossings_kept(l, axis, positive, reach, crossings),
        None => test.ray_crossings(p, axis, positive, reach, crossings),
    };
    if odd != Some(true) {
        return sampled_path(test, p, push, texel);
    }
    // Crossings closer than this are one place on the surface (f32 rounding of the corners
    // of two tessellations of one face), far below the half texel the samples resolved.
    let scale = p[axis].abs() as f64 + reach;
    let tol = (1e-3 * texel as f64).max(8.0 * f32::EPSILON as f64 * scale);
    crossings.sort_unstable_by(f64::total_cmp);
    let mut surfaces = 0;
    let mut k = 0;
    while k < crossings.len() {
        let mut run = k + 1;
        while run < crossings.len() && crossings[run] - crossings[run - 1] <= tol {
            run += 1;
        }
        surfaces += (run - k) % 2;
        k = run;
    }
    // One surface: the ray along the axis crosses it an even number of times past `end`
    // (outside by this ray), so the test's vote there needs only the other two rays (or none,
    // when `end` lies on the surface, which counts as outside).
    surfaces == 1 && (crossings.last() == Some(&reach) || !test.exact_even_along(end, axis))
}

/// [`leaves_cleanly`] by samples every half `texel` from `p` to half a texel past the pushed
/// point: no sample is inside once one has been outside, and the last one is outside. Gaps
/// thinner than half a texel are not seen.
fn sampled_path(test: &InsideTest, p: Vec3, push: Push, texel: f32) -> bool {
    let h = 0.5 * texel;
    let end = push.length + h;
    let steps = ((end / h).ceil() as usize).clamp(1, 1 << 16);
    let mut left = false;
    for k in 1..=steps {
        let t = end * k as f32 / steps as f32;
        let inside = test.inside(p + push.dir * t);
        if inside && left {
            return false;
        }
        left |= !inside;
    }
    left
}

/// The fallback's two candidate pushes for `p`, best first: to the closest point of the
/// triangles that the (up to 8) in-band cells around `p` own, evaluated at `p` itself (exact
/// where one of them is `p`'s nearest triangle: near edges and corners, where the blended
/// vector is not), then along the field's blended closest-point vector ("A" sampling).
fn field_push(field: &DistanceField, p: Vec3, offset: f32) -> (Vec3, [Option<Push>; 2]) {
    let to_push = |v: Vec3| {
        let len = v.length();
        (len > 1e-9 && len.is_finite()).then(|| Push {
            dir: v / len,
            length: len + offset,
        })
    };
    let spec = &field.spec;
    let base = spec.to_cell(p).floor().as_ivec3();
    let mut best: Option<Vec3> = None;
    for k in 0..8 {
        let c = base + glam::IVec3::new(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        if !spec.contains(c) {
            continue;
        }
        let n = field.nearest[spec.index(c.as_uvec3())];
        if n == DistanceField::FAR {
            continue;
        }
        let q = field.closest_point(n as usize, p) - p;
        if best.is_none_or(|b| q.length_squared() < b.length_squared()) {
            best = Some(q);
        }
    }
    let s = field.sample(p, Sampling::Vector);
    let blended = if s.in_band { to_push(s.vector) } else { None };
    (p, [best.and_then(to_push), blended])
}

/// The body's distance field for the fallback (the voxel and sdf stages' CPU paths).
pub fn body_field(body: &Mesh, resolution: u32, band: f32) -> Result<DistanceField> {
    let spec = GridSpec::fit(&body.bounds(), resolution, 0.05)?;
    let boundary = crate::voxel::voxelize_cpu(body, &spec, BoundaryVariant::Closest)?;
    crate::sdf::build_field_cpu(&boundary, band)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::torus;

    /// [`drape_cpu`] against a fresh preparation ([`drape_with`] keeps nothing).
    fn same_as_fresh(cache: &mut BodyCache, body: &Mesh, garment: &[Vec3], params: &DrapeParams) {
        let (mut kept, mut fresh) = (garment.to_vec(), garment.to_vec());
        let a = drape_cached(cache, body, &mut kept, params).unwrap();
        let b = drape_with(body, &mut fresh, params, rasterize_depth_with).unwrap();
        assert_eq!(a, b);
        assert_eq!(kept, fresh);
        assert!(a.moved > 0, "{a:?}");
    }

    /// The kept maps serve only the body they were made for: a second call on the same body
    /// reuses them; a moved body, a changed triangle list or another resolution is prepared
    /// again. Each result equals a fresh drape's.
    #[test]
    fn a_changed_body_is_prepared_again() {
        let body = torus(0.5, 0.2, 60, 24);
        let garment = torus(0.5, 0.17, 50, 20).positions;
        let params = DrapeParams {
            resolution: 96,
            ..Default::default()
        };
        let mut cache = BodyCache::default();
        same_as_fresh(&mut cache, &body, &garment, &params);
        same_as_fresh(&mut cache, &body, &garment, &params);
        let mut moved = body.clone();
        moved.positions[7].y += 0.05;
        same_as_fresh(&mut cache, &moved, &garment, &params);
        let mut shifted = body.clone();
        for p in &mut shifted.positions {
            p.x += 0.01;
        }
        same_as_fresh(&mut cache, &shifted, &garment, &params);
        let mut flipped = shifted.clone();
        flipped.triangles.rotate_left(5);
        flipped.triangles[0].swap(1, 2);
        same_as_fresh(&mut cache, &flipped, &garment, &params);
        let finer = DrapeParams {
            resolution: 128,
            ..params.clone()
        };
        same_as_fresh(&mut cache, &flipped, &garment, &finer);
        let sideways = DrapeParams {
            views: vec![Vec3::X],
            ..params
        };
        same_as_fresh(&mut cache, &flipped, &garment, &sideways);
    }
}
