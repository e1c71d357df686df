//! The depth-map collider for the cloth: T's draping test applied every substep, beside the
//! distance-field collider of [`crate::cloth::contact`].
//!
//! **What the cloth sees.** Per view direction d, two orthographic depth maps of the body
//! (looking along d and against it), rendered once per body pose with fixed cameras
//! ([`DepthCamera`]), and *dilated by the cloth's ε*: each map holds the first surface of the
//! body's ε-offset as seen from its side (the Minkowski sum of the map's surface points with a
//! ball of radius ε, over the texels within ε). Along one view a point is inside the offset
//! body when it lies behind both maps' surfaces; its signed distance along that view is
//! `max(−e_front, −e_back)`, where `e` is how far the point lies behind each surface.
//! Uncovered texels (past the dilated silhouette) are outside.
//!
//! **Which views decide.** Over the views the body is the intersection of the views' slabs
//! (a point a view sees in front of the body is outside), and a point inside moves out
//! through the view that gives the shortest push (T's rule). Beyond T, the push is along the
//! surface normal that view's depth gradient gives (the axis distance times cos θ), not
//! along the axis: two views see the same surface and its normal, so a particle handed
//! from one view to the other is not thrown sideways, and friction acts in the surface's
//! plane. Where the map has no gradient (an uncovered texel among the 2×2) the push is
//! along the axis. But near a view's silhouette its maps are unreliable: the surface turns
//! away, its depth changes by many texels across one, and coverage is decided at texel
//! centres, so a point inside the body can read as outside there (a cloth resting on a
//! sphere fell in at the views' silhouettes and was thrown out a substep later, which kept
//! it jittering). So only *steady* views vote: where the 2×2 texels around the point are all
//! covered with depths within `STEEP` texels of each other, or all uncovered. A steady
//! view that sees the point outside decides. Otherwise the push is the shortest among the
//! steady views that see it inside, provided it is within the particle's *reach* (its own
//! step this substep plus 2ε for the body's, as for the field collider): a longer push is
//! not the way it came in. Failing that, the shortest push within reach of any view; failing
//! that, the point is outside if any view (even an unsteady one) sees it so, and else takes
//! the shortest push there is. (A cloth falling on the cow's head was found 4 cm deep along
//! the front view between the horns, which the top view, unsteady there, saw as outside:
//! pushed 4 cm sideways in one substep, it tore.) STEEP = 1.5 was chosen by the sphere drop
//! of `tests/drape_collider.rs`: at 1.0, 2.0, 2.5 and 3.0 the resting cloth kept jittering
//! (the maps' dilation errs by up to a millimetre on steep surfaces, and a particle handed
//! between two views' slightly different surfaces is kicked each time).
//!
//! **Exactness.** For a convex body each view alone is exact along its axis, so the
//! intersection is the body itself (up to the texel sampling); for a body with layers along
//! every view (a gap no view sees into) it is larger than the body, and the cloth is held off
//! the gap: T's failure, seen from the cloth's side. The friction of
//! [`crate::cloth::contact::respond`] is applied as for the field collider.
//!
//! **Measured against the field collider** (`tests/drape_collider.rs`, the CLI test and
//! `pipelines/cloth_colliders.ron`): on a sphere the resting cloth sits at ε within a texel
//! and within 0.1 mm of the field collider's, no particle inside. But it does not come to
//! rest as well: on a 17×17 cloth over a sphere the kinetic energy stays near 1.5e-3 J where
//! the field's falls to 3e-7 J, and the middle wanders by ±3 mm (the views' dilated
//! surfaces differ by up to a millimetre on steep parts, and a particle crossing from one
//! view's steady region to another's feels the step).
//!
//! **Sampling.** A point reads the bilinear blend of the 2×2 texels around its projection
//! when all four are covered, else the nearest covered of them (the smallest depth: the
//! outermost surface) provided the texel it falls in is covered.
//!
//! **Time.** A substep s of the way through the frame blends the two poses' maps per texel,
//! as the field collider blends its two fields: covered in both, linearly in s (exact for
//! motion along the view); covered in one, that one throughout the frame. Where the body
//! moves across a view, the linear blend is not the body in between: a silhouette swept
//! across a texel in the frame would appear only at one end, so the union keeps it (a point
//! the moving body covers is not called outside by that view, which would end the
//! intersection's test early).
//!
//! **Cost.** Per pose: two renders per distinct view line (d and −d give the same pair of
//! maps, so T's top/front/back renders four maps), then the dilation, O(texels · (ε/texel)²).
//! Per particle and substep: two projections and up to 16 texel reads per view line.

use super::params::{validate_resolution, validate_views};
use crate::cloth::contact::Signed;
use crate::snow::arrival::{Lookup, snow_camera};
use glam::Vec3;
use imprint_core::raster::{DepthMap, RasterOptions};
use imprint_core::{Aabb, Camera, Mesh, Result};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// A body the cloth collides with through depth maps, as a pipeline file states it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct DepthColliderParams {
    /// The directions the views look along (as [`super::DrapeParams::views`]); a direction
    /// and its opposite give the same view. Default T's top, front and back.
    #[schemars(with = "Vec<[f32; 3]>")]
    pub views: Vec<Vec3>,
    /// Side of the square depth maps, pixels. Default 256.
    pub resolution: u32,
}

impl Default for DepthColliderParams {
    fn default() -> Self {
        DepthColliderParams {
            views: super::DrapeParams::default().views,
            resolution: 256,
        }
    }
}

impl DepthColliderParams {
    /// Checks every number; errors name the field.
    pub fn validate(&self) -> Result<()> {
        validate_views(&self.views, "depth collider")?;
        validate_resolution(self.resolution, "depth collider")
    }
}

/// The fixed cameras of a depth collider: one pair of maps per distinct view line, over a box
/// the body stays inside.
pub struct DepthCamera {
    views: Vec<CameraPair>,
    resolution: u32,
    eps: f32,
    /// The box the cameras see whole (the body's box grown by ε and a margin).
    bounds: Aabb,
    texel: f32,
}

struct CameraPair {
    dir: Vec3,
    front: (Camera, Lookup),
    back: (Camera, Lookup),
}

/// One body pose as the collider reads it: per view line, the front and back maps of the
/// body's ε-offset (`f32::INFINITY` where uncovered).
#[derive(Clone, Debug)]
pub struct DepthPose {
    maps: Vec<[Vec<f32>; 2]>,
}

/// The distinct lines of a list of directions, in order: a direction whose opposite (or
/// itself) came earlier is dropped.
pub fn distinct_lines(dirs: &[Vec3]) -> Vec<Vec3> {
    let mut out: Vec<Vec3> = Vec::new();
    for &d in dirs {
        let d = d.normalize();
        if !out.iter().any(|o| o.dot(d).abs() > 1.0 - 1e-6) {
            out.push(d);
        }
    }
    out
}

impl DepthCamera {
    /// Cameras that see `bounds` (the body's box over the frames it is used for) grown by
    /// `eps` (the cloth's contact distance, which the maps are dilated by) and a few texels.
    pub fn new(bounds: &Aabb, params: &DepthColliderParams, eps: f32) -> Result<Self> {
        params.validate()?;
        if !(eps.is_finite() && eps >= 0.0) {
            return Err(imprint_core::Error::Invalid(format!(
                "depth collider: epsilon = {eps} must be a finite number >= 0"
            )));
        }
        if bounds.is_empty() {
            return Err(imprint_core::Error::Invalid(
                "depth collider: the body has no triangles to render".into(),
            ));
        }
        let res = params.resolution;
        let grow = eps + 4.0 * bounds.size().max_element() / res as f32;
        let bounds = Aabb {
            min: bounds.min - Vec3::splat(grow),
            max: bounds.max + Vec3::splat(grow),
        };
        let mut views = Vec::new();
        let mut texel = 0f32;
        for dir in distinct_lines(&params.views) {
            let side = |d: Vec3| -> Result<(Camera, Lookup)> {
                let cam = snow_camera(&bounds, d, res)?;
                let look = Lookup::for_camera(&cam, res);
                Ok((cam, look))
            };
            let (front, back) = (side(dir)?, side(-dir)?);
            texel = texel.max(front.1.texel).max(back.1.texel);
            views.push(CameraPair { dir, front, back });
        }
        Ok(DepthCamera {
            views,
            resolution: res,
            eps,
            bounds,
            texel,
        })
    }

    /// Whether `b` lies inside the box the cameras see (else the maps would clip the body).
    pub fn sees(&self, b: &Aabb) -> bool {
        b.is_empty() || (b.min.cmpge(self.bounds.min).all() && b.max.cmple(self.bounds.max).all())
    }

    /// The largest texel of the maps, m.
    pub fn texel(&self) -> f32 {
        self.texel
    }

    /// The distinct view lines (unit).
    pub fn lines(&self) -> Vec<Vec3> {
        self.views.iter().map(|v| v.dir).collect()
    }

    /// Renders the body with `rasterize` (the CPU's `imprint_core::raster::rasterize_depth_with`
    /// or a closure over the GPU's) and dilates the maps by ε.
    pub fn pose(
        &self,
        body: &Mesh,
        mut rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
    ) -> Result<DepthPose> {
        let res = self.resolution;
        let mut maps = Vec::with_capacity(self.views.len());
        for v in &self.views {
            let mut one = |(cam, look): &(Camera, Lookup)| -> Result<Vec<f32>> {
                let m = rasterize(body, cam, res, res, &RasterOptions::default())?;
                let depth: Vec<f32> = m
                    .depth
                    .iter()
                    .zip(&m.coverage)
                    .map(|(&d, &c)| if c { d } else { f32::INFINITY })
                    .collect();
                Ok(dilate(&depth, res as usize, look.texel, self.eps))
            };
            maps.push([one(&v.front)?, one(&v.back)?]);
        }
        Ok(DepthPose { maps })
    }

    /// The collider between two poses over a frame (`start: None` reads `end` throughout).
    pub fn collider<'a>(
        &'a self,
        start: Option<&'a DepthPose>,
        end: &'a DepthPose,
    ) -> DepthCollider<'a> {
        DepthCollider {
            camera: self,
            start,
            end,
        }
    }
}

/// The body's ε-offset seen from the same side: each texel takes the nearest of the ε-balls
/// around the covered texels' surface points within ε (their depth minus the ball's height
/// over the texel). ε = 0 leaves the map as it is.
fn dilate(depth: &[f32], res: usize, texel: f32, eps: f32) -> Vec<f32> {
    let reach = (eps / texel).floor() as i64;
    if reach < 1 {
        return depth.to_vec();
    }
    // (di, dj, ball height) for every texel offset within ε.
    let mut ball = Vec::new();
    for dj in -reach..=reach {
        for di in -reach..=reach {
            let r2 = (di * di + dj * dj) as f32 * texel * texel;
            if r2 <= eps * eps {
                ball.push((di, dj, (eps * eps - r2).sqrt()));
            }
        }
    }
    let n = res as i64;
    let mut out = vec![f32::INFINITY; depth.len()];
    out.par_chunks_mut(res).enumerate().for_each(|(j, row)| {
        let j = j as i64;
        for (i, o) in row.iter_mut().enumerate() {
            let i = i as i64;
            let mut best = f32::INFINITY;
            for &(di, dj, h) in &ball {
                let (a, b) = (i + di, j + dj);
                if a >= 0 && b >= 0 && a < n && b < n {
                    best = best.min(depth[(b * n + a) as usize] - h);
                }
            }
            *o = best;
        }
    });
    out
}

/// A body as the cloth reads it in one frame: fixed cameras and the poses at the frame's two
/// ends.
#[derive(Clone, Copy)]
pub struct DepthCollider<'a> {
    camera: &'a DepthCamera,
    start: Option<&'a DepthPose>,
    end: &'a DepthPose,
}

impl DepthCollider<'_> {
    /// The ε the maps are dilated by.
    pub fn eps(&self) -> f32 {
        self.camera.eps
    }

    /// The body at `x`, `s` of the way through the frame: the signed distance to the body
    /// (ε added back to the offset's) and the outward push direction, or `None` where `x` is
    /// outside (see the module doc for which views decide). `reach` is how deep `x` can have
    /// got since it was last outside (its own step plus 2ε for the body's, as for the field
    /// collider): a push longer than that is not the way it came in.
    #[inline]
    pub fn sample(&self, x: Vec3, reach: f32, s: f32) -> Option<Signed> {
        let res = self.camera.resolution as usize;
        // The shortest push (largest distance, all negative) among: steady views within
        // reach, any view within reach, steady views, any view.
        let mut best = [None::<(f32, Vec3)>; 4];
        let mut any_out = false;
        for (k, v) in self.camera.views.iter().enumerate() {
            let read = |side: usize, look: &Lookup| -> (Surface, f32) {
                let (px, py, z) = look.project(x);
                let r = surface_at(
                    self.start.map(|p| p.maps[k][side].as_slice()),
                    &self.end.maps[k][side],
                    res,
                    px,
                    py,
                    s,
                    STEEP * look.texel,
                );
                (r, z)
            };
            let ((f, zf), (b, zb)) = (read(0, &v.front.1), read(1, &v.back.1));
            let steady = f.steady && b.steady;
            // How far x lies outside this view's slab (negative inside), along the nearer
            // surface's normal, and that normal.
            let (d, out) = match (f.depth, b.depth) {
                (Some(df), Some(db)) if df - zf >= db - zb => normal(df - zf, &f, &v.front.1),
                (Some(_), Some(db)) => normal(db - zb, &b, &v.back.1),
                // Uncovered: this view sees x outside.
                _ => (f32::INFINITY, Vec3::ZERO),
            };
            if d >= 0.0 {
                if steady {
                    return None;
                }
                any_out = true;
                continue;
            }
            let near = -d <= reach;
            for (slot, counts) in best.iter_mut().zip([steady && near, near, steady, true]) {
                if counts && slot.is_none_or(|(b, _)| d > b) {
                    *slot = Some((d, out));
                }
            }
        }
        let [steady_near, any_near, steady, any] = best;
        // A view that sees x outside, even at its silhouette, outweighs a long push.
        let (d, outward) = match (steady_near.or(any_near), any_out) {
            (Some(b), _) => b,
            (None, true) => return None,
            (None, false) => steady.or(any)?,
        };
        Some(Signed {
            distance: d + self.camera.eps,
            outward,
            band_miss: false,
        })
    }
}

/// A view's depth is trusted where the 2×2 texels around the point are all covered and
/// differ by at most this many texels (the surface turned less than about 65° from the
/// view), or all uncovered: away from its silhouettes.
const STEEP: f32 = 1.5;

/// A map's surface at a point: its depth (`None` where the texel the point falls in is
/// uncovered) and whether the map is steady there (see `STEEP`).
struct Surface {
    depth: Option<f32>,
    steady: bool,
    /// The depth's change per pixel along the image's x and y (down), where the 2×2 is
    /// covered.
    gradient: Option<(f32, f32)>,
}

/// A distance along a map's axis (`d`: the surface's depth minus the point's) as a distance
/// along the surface's outward normal, with that normal: from the map's depth gradient where
/// it has one (cos θ shortens the axis distance), else the axis itself (toward the map's
/// camera).
#[inline]
fn normal(d: f32, surface: &Surface, look: &Lookup) -> (f32, Vec3) {
    let f = &look.frame;
    match surface.gradient {
        Some((gx, gy)) => {
            // Depth per world unit along the view's right and up (pixel y runs down).
            let (sx, sy) = (gx * look.k, -gy * look.k);
            let n = f.right * sx + f.up * sy - f.forward;
            let len = n.length();
            (d / len, n / len)
        }
        None => (d, -f.forward),
    }
}

/// The map's surface depth at pixel coordinates (px, py), blended between the poses at `s`
/// (see the module doc): bilinear over the 2×2 texel centres around the point when all are
/// covered, else the nearest covered depth among them when the point's own texel is covered.
/// `steep` is the largest depth spread over the 2×2 at which the map is steady, m.
#[inline]
fn surface_at(
    start: Option<&[f32]>,
    end: &[f32],
    res: usize,
    px: f32,
    py: f32,
    s: f32,
    steep: f32,
) -> Surface {
    let at = |k: usize| -> f32 {
        let b = end[k];
        match start {
            Some(a) if s < 1.0 => {
                let a = a[k];
                match (a.is_finite(), b.is_finite()) {
                    (true, true) => a + (b - a) * s,
                    (true, false) => a,
                    (false, true) => b,
                    _ => f32::INFINITY,
                }
            }
            _ => b,
        }
    };
    let last = res as f32;
    if !(px >= 0.0 && py >= 0.0 && px < last && py < last) {
        return Surface {
            depth: None,
            steady: true,
            gradient: None,
        };
    }
    let own = at(py as usize * res + px as usize);
    // The 2×2 texel centres around the point.
    let (fx, fy) = (px - 0.5, py - 0.5);
    let (i0, j0) = (fx.floor(), fy.floor());
    let (tx, ty) = (fx - i0, fy - j0);
    let clamp = |v: f32| (v.max(0.0) as usize).min(res - 1);
    let (i0, i1) = (clamp(i0), clamp(i0 + 1.0));
    let (j0, j1) = (clamp(j0), clamp(j0 + 1.0));
    let q = [
        at(j0 * res + i0),
        at(j0 * res + i1),
        at(j1 * res + i0),
        at(j1 * res + i1),
    ];
    let covered = q.iter().filter(|d| d.is_finite()).count();
    if covered == 4 {
        let (lo, hi) = q
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &d| {
                (a.min(d), b.max(d))
            });
        let top = q[0] + (q[1] - q[0]) * tx;
        let bottom = q[2] + (q[3] - q[2]) * tx;
        let along_x = (q[1] - q[0]) + ((q[3] - q[2]) - (q[1] - q[0])) * ty;
        return Surface {
            depth: Some(top + (bottom - top) * ty),
            steady: hi - lo <= steep,
            gradient: Some((along_x, bottom - top)),
        };
    }
    Surface {
        depth: own
            .is_finite()
            .then(|| q.iter().copied().fold(own, f32::min)),
        steady: covered == 0,
        gradient: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::uv_sphere;
    use imprint_core::raster::rasterize_depth_with;

    fn sphere_collider(r: f32, eps: f32, res: u32) -> (DepthCamera, DepthPose) {
        let body = uv_sphere(r, 192, 96);
        let params = DepthColliderParams {
            views: vec![Vec3::NEG_Y, Vec3::NEG_Z, Vec3::X],
            resolution: res,
        };
        let cam = DepthCamera::new(&body.bounds(), &params, eps).unwrap();
        let pose = cam.pose(&body, rasterize_depth_with).unwrap();
        (cam, pose)
    }

    #[test]
    fn opposite_directions_are_one_line() {
        let l = distinct_lines(&[Vec3::NEG_Y, Vec3::NEG_Z, Vec3::Z, Vec3::Y * 2.0, Vec3::X]);
        assert_eq!(l, vec![Vec3::NEG_Y, Vec3::NEG_Z, Vec3::X]);
    }

    /// On a sphere (convex: each view exact along its axis) the collider's signed distance
    /// near the surface is the exact (radial) one within a texel, along the normal.
    #[test]
    fn sphere_distances_match_the_exact_ones_near_the_surface() {
        let (r, eps) = (0.5, 0.02);
        let (cam, pose) = sphere_collider(r, eps, 256);
        let c = cam.collider(None, &pose);
        let texel = cam.texel();
        // Straight above the pole, at heights from inside to within ε.
        for h in [-0.05f32, -0.01, 0.0, 0.01] {
            let s = c
                .sample(Vec3::new(0.0, r + h, 0.0), f32::INFINITY, 1.0)
                .unwrap();
            // The tessellated pole is a vertex at r exactly.
            assert!(
                (s.distance - h).abs() < 0.5 * texel,
                "h {h}: {} (texel {texel})",
                s.distance
            );
            // The normal from the top map's gradient: straight up at the pole.
            assert!((s.outward - Vec3::Y).length() < 1e-3, "{}", s.outward);
        }
        // Beyond ε above the pole: outside the offset in the side views (uncovered).
        assert!(
            c.sample(
                Vec3::new(0.0, r + eps + 2.0 * texel, 0.0),
                f32::INFINITY,
                1.0
            )
            .is_none()
        );
        // Near the surface off the axes (a sphere's radius between the views): the distance
        // along the normal of the view that pushes is the radial one, and so is the normal.
        for dir in [
            Vec3::new(1.0, 1.0, 0.3),
            Vec3::new(-0.2, 0.5, 1.0),
            Vec3::new(0.6, -1.0, -0.4),
        ] {
            let dir = dir.normalize();
            for depth in [-0.005f32, 0.0, 0.005] {
                let p = dir * (r + depth);
                let s = c.sample(p, f32::INFINITY, 1.0).unwrap();
                assert!(
                    (s.distance - depth).abs() < texel,
                    "{dir} at {depth}: {} (texel {texel})",
                    s.distance
                );
                assert!(
                    (s.outward - dir).length() < 0.05,
                    "{dir}: normal {}",
                    s.outward
                );
            }
        }
    }

    /// Blending two poses: a sphere moved up by 0.1 between them is met half-way at s = 0.5.
    #[test]
    fn blends_poses_in_time() {
        let (r, eps) = (0.4, 0.0);
        let a = uv_sphere(r, 96, 48);
        let mut b = a.clone();
        b.transform(glam::Mat4::from_translation(Vec3::Y * 0.1));
        let mut bounds = a.bounds();
        bounds = bounds.union(&b.bounds());
        let params = DepthColliderParams {
            views: vec![Vec3::NEG_Y],
            resolution: 128,
        };
        let cam = DepthCamera::new(&bounds, &params, eps).unwrap();
        let (pa, pb) = (
            cam.pose(&a, rasterize_depth_with).unwrap(),
            cam.pose(&b, rasterize_depth_with).unwrap(),
        );
        let c = cam.collider(Some(&pa), &pb);
        // 5 cm under the first pose's top: 15 cm under the second's, 10 cm half-way.
        let p = Vec3::new(0.0, r - 0.05, 0.0);
        for (s, expect) in [(0.0, -0.05), (0.5, -0.1), (1.0, -0.15)] {
            let d = c.sample(p, f32::INFINITY, s).unwrap().distance;
            assert!((d - expect).abs() < 1e-3, "s {s}: {d} vs {expect}");
        }
        // Above both tops: outside throughout.
        assert!(
            c.sample(Vec3::new(0.0, r + 0.2, 0.0), f32::INFINITY, 0.5)
                .is_none()
        );
    }

    #[test]
    fn dilation_is_the_offset_of_a_plane_and_grows_coverage() {
        // A flat map at depth 1 over the left half: dilated by ε = 3 texels.
        let res = 16;
        let depth: Vec<f32> = (0..res * res)
            .map(|k| if k % res < 8 { 1.0 } else { f32::INFINITY })
            .collect();
        let d = dilate(&depth, res, 1.0, 3.0);
        assert_eq!(d[5 * res + 3], 1.0 - 3.0);
        // Two texels past the edge: the ball around the edge texel, sqrt(9 - 4) lower.
        assert!((d[5 * res + 9] - (1.0 - 5f32.sqrt())).abs() < 1e-6);
        assert!(d[5 * res + 10].is_finite() && d[5 * res + 11].is_infinite());
    }
}
