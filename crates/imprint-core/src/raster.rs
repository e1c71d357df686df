//! The CPU triangle rasteriser and depth maps: the reference for every depth-buffer method
//! (draping, snow "shadow" depth, ground contact from below) and the renderer's fallback.
//!
//! - Depth is the **view depth**: the distance along the camera's viewing direction,
//!   `dot(p - eye, forward)`, in world units, positive in front of the camera (linear, not NDC).
//!   Uncovered pixels hold `f32::INFINITY`. Nearest depth wins; on an exact tie the triangle
//!   that comes first in the mesh keeps the pixel.
//! - Pixels: row 0 is the top row; pixel (i, j) has its centre at (i + 0.5, j + 0.5).
//! - Coverage follows the top-left rule on vertices snapped to 1/256 pixel, with exact integer
//!   edge functions: a pixel centre exactly on an edge shared by two triangles is covered by
//!   exactly one of them, so a closed surface has neither cracks nor double writes.
//! - Triangles are clipped (in view space) against the near and far planes and against a guard
//!   band 2^20 pixels around the image; both windings are drawn unless
//!   [`RasterOptions::cull_back`] is set (front = counter-clockwise as seen by the camera).
//! - Orthographic depth is interpolated linearly in screen space; perspective depth through
//!   1/depth (perspective-correct).
//! - Rows are rasterised in parallel bands, each band drawing its triangles in mesh order, so
//!   the result is bit-identical for any number of threads.

use crate::camera::{Camera, Frame};
use crate::geom::barycentric;
use crate::{Error, Mesh, Result};
use glam::Vec3;
use rayon::prelude::*;

/// Largest accepted width or height, in pixels.
pub const MAX_SIZE: u32 = 16384;
/// Subpixel precision of the snapped vertex coordinates (1/256 pixel).
const SUB_BITS: u32 = 8;
const SUB: f32 = (1 << SUB_BITS) as f32;
const HALF: i64 = 1 << (SUB_BITS - 1);
/// Guard band (pixels) beyond which triangles are clipped: keeps fixed-point products in i64.
const GUARD: f32 = (1 << 20) as f32;
/// Rows per parallel band.
const BAND_ROWS: u32 = 16;

/// Options of the rasteriser.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RasterOptions {
    /// Skip triangles whose front side (counter-clockwise as seen by the camera) faces away.
    pub cull_back: bool,
}

/// A depth image: the camera it was taken with, the view depth per pixel (row 0 on top) and
/// the coverage mask. Uncovered pixels hold `f32::INFINITY`.
#[derive(Clone, Debug, PartialEq)]
pub struct DepthMap {
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    /// View depth per pixel, row-major from the top row; `f32::INFINITY` where uncovered.
    pub depth: Vec<f32>,
    /// Whether a triangle covers the pixel centre.
    pub coverage: Vec<bool>,
}

/// Maps between view space and pixel coordinates for one camera and image size.
#[derive(Clone, Copy, Debug)]
struct Projector {
    frame: Frame,
    persp: bool,
    /// Pixels per world unit (orthographic) or per unit of x/depth (perspective).
    k: f32,
    cx: f32,
    cy: f32,
    near: f32,
    far: f32,
}

impl Projector {
    fn new(camera: &Camera, width: u32, height: u32) -> Self {
        Projector {
            frame: camera.frame(),
            persp: camera.is_perspective(),
            k: height as f32 / (2.0 * camera.half_height_scale()),
            cx: 0.5 * width as f32,
            cy: 0.5 * height as f32,
            near: camera.near,
            far: camera.far,
        }
    }

    /// View coordinates (x, y, view depth) → pixel coordinates (x right, y down).
    #[inline]
    fn view_to_px(&self, v: Vec3) -> (f32, f32) {
        let s = if self.persp { self.k / v.z } else { self.k };
        (self.cx + v.x * s, self.cy - v.y * s)
    }

    /// Pixel coordinates and view depth → view coordinates.
    #[inline]
    fn px_to_view(&self, px: f32, py: f32, depth: f32) -> Vec3 {
        let s = if self.persp {
            depth / self.k
        } else {
            1.0 / self.k
        };
        Vec3::new((px - self.cx) * s, (self.cy - py) * s, depth)
    }

    /// Signed distances to the six clip planes (inside ≥ 0): near, far, and the guard band.
    #[inline]
    fn plane_values(&self, v: Vec3) -> [f32; 6] {
        let g = if self.persp { GUARD * v.z } else { GUARD };
        let (x, y) = (self.k * v.x, self.k * v.y);
        [v.z - self.near, self.far - v.z, g + x, g - x, g + y, g - y]
    }

    #[inline]
    fn outcode(&self, v: Vec3) -> u8 {
        let p = self.plane_values(v);
        let mut code = 0;
        for (i, d) in p.iter().enumerate() {
            if d.is_nan() || *d < 0.0 {
                code |= 1 << i;
            }
        }
        code
    }

    /// Snapped screen vertex for a view-space point inside every clip plane.
    #[inline]
    fn screen_vertex(&self, v: Vec3) -> SVert {
        let (px, py) = self.view_to_px(v);
        SVert {
            x: crate::geom::floor_i(px * SUB + 0.5),
            y: crate::geom::floor_i(py * SUB + 0.5),
            z: if self.persp { 1.0 / v.z } else { v.z },
            fx: px,
            fy: py,
        }
    }
}

impl DepthMap {
    /// An empty map (nothing covered).
    pub fn empty(camera: Camera, width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        DepthMap {
            camera,
            width,
            height,
            depth: vec![f32::INFINITY; n],
            coverage: vec![false; n],
        }
    }

    #[inline]
    pub fn index(&self, i: u32, j: u32) -> usize {
        j as usize * self.width as usize + i as usize
    }

    /// The view depth at pixel (i, j) (column i, row j from the top), `None` where uncovered
    /// or outside the image.
    #[inline]
    pub fn get(&self, i: u32, j: u32) -> Option<f32> {
        (i < self.width && j < self.height && self.coverage[self.index(i, j)])
            .then(|| self.depth[self.index(i, j)])
    }

    pub fn is_covered(&self, i: u32, j: u32) -> bool {
        i < self.width && j < self.height && self.coverage[self.index(i, j)]
    }

    pub fn covered_count(&self) -> usize {
        self.coverage.iter().filter(|c| **c).count()
    }

    /// `width / height`, the aspect ratio the camera's matrices need.
    pub fn aspect(&self) -> f32 {
        self.width as f32 / self.height as f32
    }

    /// The world point seen at the centre of covered pixel (i, j), at its depth.
    pub fn world_point(&self, i: u32, j: u32) -> Option<Vec3> {
        let d = self.get(i, j)?;
        Some(self.unproject(i as f32 + 0.5, j as f32 + 0.5, d))
    }

    /// The world point at pixel coordinates (px, py) (y down) and view depth `depth`.
    pub fn unproject(&self, px: f32, py: f32, depth: f32) -> Vec3 {
        let p = Projector::new(&self.camera, self.width, self.height);
        p.frame.to_world(p.px_to_view(px, py, depth))
    }

    /// Pixel coordinates (x right, y down; the centre of pixel (i, j) is (i + 0.5, j + 0.5))
    /// and view depth of a world point. `None` for a perspective camera when the point is not
    /// in front of the eye. The coordinates may lie outside the image; callers check bounds.
    pub fn pixel_of(&self, world: Vec3) -> Option<(f32, f32, f32)> {
        let p = Projector::new(&self.camera, self.width, self.height);
        let v = p.frame.to_view(world);
        if p.persp && (v.z.is_nan() || v.z <= 0.0) {
            return None;
        }
        let (x, y) = p.view_to_px(v);
        Some((x, y, v.z))
    }
}

/// A screen vertex: position in 1/256 pixel, and the interpolated depth quantity (view depth
/// for orthographic cameras, 1 / view depth for perspective ones).
#[derive(Clone, Copy, Debug)]
struct SVert {
    x: i32,
    y: i32,
    z: f32,
    /// Unsnapped pixel coordinates: the depth plane is fitted through these, so that
    /// snapping moves coverage by at most 1/512 pixel but does not tilt the depth.
    fx: f32,
    fy: f32,
}

/// A set-up screen triangle: counter-clockwise in the edge-function sense (positive area), with its
/// pixel bounding box clipped to the image, and the mesh triangle it came from.
#[derive(Clone, Copy, Debug)]
struct Tri {
    v: [SVert; 3],
    i0: i32,
    i1: i32,
    j0: i32,
    j1: i32,
    id: u32,
}

/// `E_pq(P) = A Px + B Py + C`, positive inside a triangle set up by [`setup`].
#[inline(always)]
fn edge(p: SVert, q: SVert) -> (i64, i64, i64) {
    let (px, py, qx, qy) = (p.x as i64, p.y as i64, q.x as i64, q.y as i64);
    let a = qy - py;
    let b = px - qx;
    (a, b, -(px * a + py * b))
}

/// Sets up one screen triangle; `None` when it is degenerate, culled or covers no pixel centre
/// of the image.
#[inline]
fn setup(v: [SVert; 3], id: u32, cull_back: bool, w: i32, h: i32) -> Option<Tri> {
    let [a, mut b, mut c] = v;
    let (ea, eb, ec) = edge(a, b);
    let area = ea * c.x as i64 + eb * c.y as i64 + ec;
    if area == 0 || (cull_back && area < 0) {
        return None;
    }
    if area < 0 {
        std::mem::swap(&mut b, &mut c);
    }
    let minx = a.x.min(b.x).min(c.x) as i64;
    let maxx = a.x.max(b.x).max(c.x) as i64;
    let miny = a.y.min(b.y).min(c.y) as i64;
    let maxy = a.y.max(b.y).max(c.y) as i64;
    // Pixel centres 256 i + 128 inside [min, max].
    let i0 = ((minx - HALF + (1 << SUB_BITS) - 1) >> SUB_BITS).max(0);
    let i1 = ((maxx - HALF) >> SUB_BITS).min(w as i64 - 1);
    let j0 = ((miny - HALF + (1 << SUB_BITS) - 1) >> SUB_BITS).max(0);
    let j1 = ((maxy - HALF) >> SUB_BITS).min(h as i64 - 1);
    if i0 > i1 || j0 > j1 {
        return None;
    }
    Some(Tri {
        v: [a, b, c],
        i0: i0 as i32,
        i1: i1 as i32,
        j0: j0 as i32,
        j1: j1 as i32,
        id,
    })
}

/// A view-space polygon vertex during clipping.
type ClipVert = Vec3;

/// Clips a view-space triangle against the planes in `mask` (Sutherland–Hodgman). Each
/// intersection is computed from the inside vertex towards the outside one, so the two
/// triangles sharing an edge clip it to the same point.
fn clip(proj: &Projector, tri: [Vec3; 3], mask: u8, out: &mut Vec<ClipVert>) {
    let mut poly: Vec<ClipVert> = tri.to_vec();
    let mut next = Vec::with_capacity(9);
    for plane in 0..6 {
        if mask & (1 << plane) == 0 || poly.is_empty() {
            continue;
        }
        next.clear();
        let vals: Vec<f32> = poly.iter().map(|v| proj.plane_values(*v)[plane]).collect();
        for k in 0..poly.len() {
            let (p, q) = (poly[k], poly[(k + 1) % poly.len()]);
            let (dp, dq) = (vals[k], vals[(k + 1) % poly.len()]);
            let (pin, qin) = (dp >= 0.0, dq >= 0.0);
            if pin {
                next.push(p);
            }
            if pin != qin {
                let (i, o, di, d_o) = if pin { (p, q, dp, dq) } else { (q, p, dq, dp) };
                let t = di / (di - d_o);
                next.push(i + (o - i) * t);
            }
        }
        std::mem::swap(&mut poly, &mut next);
    }
    out.clear();
    out.extend_from_slice(&poly);
}

/// Screen triangles of the mesh, in mesh order (clipped triangles become fans, in order).
fn setup_all(mesh: &Mesh, proj: &Projector, opts: &RasterOptions, w: u32, h: u32) -> Vec<Tri> {
    struct PVert {
        v: Vec3,
        s: SVert,
        out: u8,
    }
    let verts: Vec<PVert> = mesh
        .positions
        .par_iter()
        .map(|p| {
            let v = proj.frame.to_view(*p);
            let out = proj.outcode(v);
            let s = if out == 0 {
                proj.screen_vertex(v)
            } else {
                SVert {
                    x: 0,
                    y: 0,
                    z: 0.0,
                    fx: 0.0,
                    fy: 0.0,
                }
            };
            PVert { v, s, out }
        })
        .collect();
    let (wi, hi) = (w as i32, h as i32);
    let chunks: Vec<Vec<Tri>> = mesh
        .triangles
        .par_chunks(4096)
        .enumerate()
        .map(|(c, chunk)| {
            let mut tris = Vec::with_capacity(chunk.len());
            let mut poly = Vec::with_capacity(9);
            for (k, t) in chunk.iter().enumerate() {
                let id = (c * 4096 + k) as u32;
                let [a, b, cc] = [
                    &verts[t[0] as usize],
                    &verts[t[1] as usize],
                    &verts[t[2] as usize],
                ];
                let any = a.out | b.out | cc.out;
                if any == 0 {
                    if let Some(tri) = setup([a.s, b.s, cc.s], id, opts.cull_back, wi, hi) {
                        tris.push(tri);
                    }
                    continue;
                }
                if a.out & b.out & cc.out != 0 {
                    continue;
                }
                clip(proj, [a.v, b.v, cc.v], any, &mut poly);
                if poly.len() < 3 {
                    continue;
                }
                let s: Vec<SVert> = poly.iter().map(|v| proj.screen_vertex(*v)).collect();
                for m in 1..s.len() - 1 {
                    if let Some(tri) = setup([s[0], s[m], s[m + 1]], id, opts.cull_back, wi, hi) {
                        tris.push(tri);
                    }
                }
            }
            tris
        })
        .collect();
    chunks.concat()
}

/// Draws `ids` (indices into `tris`, in order) into the band of rows starting at `row0`.
#[allow(clippy::too_many_arguments)]
fn raster_band(
    tris: &[Tri],
    ids: &[u32],
    persp: bool,
    width: usize,
    row0: i32,
    depth: &mut [f32],
    cover: &mut [bool],
    mut tri_id: Option<&mut [u32]>,
) {
    let rows = (depth.len() / width) as i32;
    let sub = 1i64 << SUB_BITS;
    for &t in ids {
        let tri = &tris[t as usize];
        let j0 = tri.j0.max(row0);
        let j1 = tri.j1.min(row0 + rows - 1);
        if j0 > j1 {
            continue;
        }
        let [a, b, c] = tri.v;
        // e0 weighs a (edge b→c), e1 weighs b (edge c→a), e2 weighs c (edge a→b).
        let edges = [edge(b, c), edge(c, a), edge(a, b)];
        let px0 = tri.i0 as i64 * sub + HALF;
        let py0 = j0 as i64 * sub + HALF;
        let mut row_e = [0i64; 3];
        let mut bias = [0i64; 3];
        let mut step_x = [0i64; 3];
        let mut step_y = [0i64; 3];
        for k in 0..3 {
            let (ea, eb, ec) = edges[k];
            row_e[k] = ea * px0 + eb * py0 + ec;
            // Top-left rule (y down): a left edge has the interior towards +x (A > 0), a top
            // edge is horizontal with the interior below (A = 0, B > 0).
            bias[k] = if ea > 0 || (ea == 0 && eb > 0) { 0 } else { -1 };
            step_x[k] = ea * sub;
            step_y[k] = eb * sub;
        }
        // Depth plane through the unsnapped vertices, evaluated at pixel centres.
        let (x0, y0, z0) = (a.fx as f64, a.fy as f64, a.z as f64);
        let (x1, y1, z1) = (b.fx as f64 - x0, b.fy as f64 - y0, b.z as f64 - z0);
        let (x2, y2, z2) = (c.fx as f64 - x0, c.fy as f64 - y0, c.z as f64 - z0);
        let det = x1 * y2 - x2 * y1;
        let (gx, gy) = if det != 0.0 {
            ((z1 * y2 - z2 * y1) / det, (z2 * x1 - z1 * x2) / det)
        } else {
            (0.0, 0.0)
        };
        let z00 = z0 + gx * (tri.i0 as f64 + 0.5 - x0) + gy * (j0 as f64 + 0.5 - y0);
        let (z00, dzdx, dzdy) = (z00 as f32, gx as f32, gy as f32);
        for k in 0..3 {
            row_e[k] += bias[k];
        }
        for j in j0..=j1 {
            let dj = (j - j0) as f32;
            let base = (j - row0) as usize * width;
            let [mut e0, mut e1, mut e2] = row_e;
            for i in tri.i0..=tri.i1 {
                if (e0 | e1 | e2) >= 0 {
                    let z = z00 + dzdx * (i - tri.i0) as f32 + dzdy * dj;
                    let d = if persp { 1.0 / z } else { z };
                    let idx = base + i as usize;
                    if d < depth[idx] && (!persp || z > 0.0) {
                        depth[idx] = d;
                        cover[idx] = true;
                        if let Some(ids) = tri_id.as_deref_mut() {
                            ids[idx] = tri.id;
                        }
                    }
                }
                e0 += step_x[0];
                e1 += step_x[1];
                e2 += step_x[2];
            }
            for k in 0..3 {
                row_e[k] += step_y[k];
            }
        }
    }
}

fn check_size(width: u32, height: u32) -> Result<()> {
    for (name, v) in [("width", width), ("height", height)] {
        if v == 0 || v > MAX_SIZE {
            return Err(Error::Invalid(format!(
                "rasteriser: {name} must be in 1..={MAX_SIZE} pixels, got {v}"
            )));
        }
    }
    Ok(())
}

fn rasterize_impl(
    mesh: &Mesh,
    camera: &Camera,
    width: u32,
    height: u32,
    opts: &RasterOptions,
    want_ids: bool,
) -> Result<(DepthMap, Vec<u32>)> {
    camera.validate()?;
    check_size(width, height)?;
    mesh.validate("rasterised mesh")?;
    let proj = Projector::new(camera, width, height);
    let tris = setup_all(mesh, &proj, opts, width, height);
    // Bin the triangles by band, keeping mesh order within each band.
    let bands = height.div_ceil(BAND_ROWS) as usize;
    let mut bins: Vec<Vec<u32>> = vec![Vec::new(); bands];
    for (t, tri) in tris.iter().enumerate() {
        for bin in
            &mut bins[tri.j0 as usize / BAND_ROWS as usize..=tri.j1 as usize / BAND_ROWS as usize]
        {
            bin.push(t as u32);
        }
    }
    let mut map = DepthMap::empty(*camera, width, height);
    let mut ids = if want_ids {
        vec![u32::MAX; map.depth.len()]
    } else {
        Vec::new()
    };
    let w = width as usize;
    let chunk = w * BAND_ROWS as usize;
    let persp = proj.persp;
    if want_ids {
        map.depth
            .par_chunks_mut(chunk)
            .zip(map.coverage.par_chunks_mut(chunk))
            .zip(ids.par_chunks_mut(chunk))
            .zip(bins.par_iter())
            .enumerate()
            .for_each(|(b, (((d, c), id), bin))| {
                let row0 = (b as u32 * BAND_ROWS) as i32;
                raster_band(&tris, bin, persp, w, row0, d, c, Some(id));
            });
    } else {
        map.depth
            .par_chunks_mut(chunk)
            .zip(map.coverage.par_chunks_mut(chunk))
            .zip(bins.par_iter())
            .enumerate()
            .for_each(|(b, ((d, c), bin))| {
                let row0 = (b as u32 * BAND_ROWS) as i32;
                raster_band(&tris, bin, persp, w, row0, d, c, None);
            });
    }
    Ok((map, ids))
}

/// Rasterises `mesh` into a `width` × `height` depth map (both windings, see the module doc).
pub fn rasterize_depth(mesh: &Mesh, camera: &Camera, width: u32, height: u32) -> Result<DepthMap> {
    rasterize_depth_with(mesh, camera, width, height, &RasterOptions::default())
}

/// [`rasterize_depth`] with options.
pub fn rasterize_depth_with(
    mesh: &Mesh,
    camera: &Camera,
    width: u32,
    height: u32,
    opts: &RasterOptions,
) -> Result<DepthMap> {
    Ok(rasterize_impl(mesh, camera, width, height, opts, false)?.0)
}

/// The depth map and, per pixel, the index of the mesh triangle that won it (`u32::MAX` where
/// uncovered): what a later pass needs to look up anything about the visible surface.
pub fn rasterize_triangle_ids(
    mesh: &Mesh,
    camera: &Camera,
    width: u32,
    height: u32,
    opts: &RasterOptions,
) -> Result<(DepthMap, Vec<u32>)> {
    rasterize_impl(mesh, camera, width, height, opts, true)
}

/// Interpolates a per-vertex attribute over the visible surface: for each covered pixel, the
/// attribute at the surface point seen through its centre (barycentric in the 3D triangle,
/// hence perspective-correct); `None` where uncovered. `attrs` has one value per vertex.
pub fn rasterize_attributes<const N: usize>(
    mesh: &Mesh,
    camera: &Camera,
    width: u32,
    height: u32,
    opts: &RasterOptions,
    attrs: &[[f32; N]],
) -> Result<(DepthMap, Vec<Option<[f32; N]>>)> {
    if attrs.len() != mesh.positions.len() {
        return Err(Error::Invalid(format!(
            "rasteriser: {} attribute values for {} vertices",
            attrs.len(),
            mesh.positions.len()
        )));
    }
    let (map, ids) = rasterize_triangle_ids(mesh, camera, width, height, opts)?;
    let w = width as usize;
    let out: Vec<Option<[f32; N]>> = ids
        .par_iter()
        .enumerate()
        .map(|(idx, &t)| {
            if t == u32::MAX {
                return None;
            }
            let p = map.world_point((idx % w) as u32, (idx / w) as u32)?;
            let tri = mesh.triangles[t as usize];
            let l = barycentric(p, mesh.triangle(t as usize));
            let mut v = [0.0f32; N];
            for (k, &vi) in tri.iter().enumerate() {
                for (o, a) in v.iter_mut().zip(attrs[vi as usize]) {
                    *o += l[k] * a;
                }
            }
            Some(v)
        })
        .collect();
    Ok((map, out))
}

/// Per-pixel interpolated (renormalised) vertex normals; `Vec3::ZERO` where uncovered.
pub fn rasterize_normals(
    mesh: &Mesh,
    camera: &Camera,
    width: u32,
    height: u32,
    opts: &RasterOptions,
) -> Result<(DepthMap, Vec<Vec3>)> {
    let attrs: Vec<[f32; 3]> = mesh.normals.iter().map(|n| n.to_array()).collect();
    let (map, vals) = rasterize_attributes(mesh, camera, width, height, opts, &attrs)?;
    let normals = vals
        .into_iter()
        .map(|v| v.map_or(Vec3::ZERO, |a| Vec3::from_array(a).normalize_or_zero()))
        .collect();
    Ok((map, normals))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives::uv_sphere;
    use std::path::Path;

    fn mesh(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Mesh {
        Mesh::new(positions, triangles, "test").unwrap()
    }

    /// An `n` × `n` grid of quads over the parallelogram `origin + s u + t v`, s, t in [0, 1].
    fn patch(origin: Vec3, u: Vec3, v: Vec3, n: u32) -> Mesh {
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                pos.push(origin + u * (i as f32 / n as f32) + v * (j as f32 / n as f32));
            }
        }
        let id = |i: u32, j: u32| j * (n + 1) + i;
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        mesh(pos, tris)
    }

    fn ortho_down_z(center: Vec3, half_height: f32) -> Camera {
        Camera::orthographic(center + Vec3::Z * 5.0, center, Vec3::Y, half_height).unwrap()
    }

    #[test]
    fn orthographic_plane_has_the_analytic_depth_everywhere() {
        let cam = ortho_down_z(Vec3::ZERO, 1.0);
        let m = patch(
            Vec3::new(-5.0, -5.0, -1.5),
            Vec3::X * 10.0,
            Vec3::Y * 10.0,
            3,
        );
        let map = rasterize_depth(&m, &cam, 64, 48).unwrap();
        assert_eq!(map.covered_count(), 64 * 48);
        for d in &map.depth {
            assert!((d - 6.5).abs() <= 6.5 * 1e-5, "{d}");
        }
    }

    #[test]
    fn orthographic_tilted_plane_matches_ray_plane_distance() {
        let cam = Camera::orthographic(
            Vec3::new(0.3, -0.2, 4.0),
            Vec3::new(0.1, 0.0, 0.0),
            Vec3::Y,
            1.3,
        )
        .unwrap();
        // Plane z = -1 + 0.3 x + 0.2 y, as a 9 × 9 grid (shared edges everywhere).
        let f = |x: f32, y: f32| Vec3::new(x, y, -1.0 + 0.3 * x + 0.2 * y);
        let o = f(-6.0, -6.0);
        let m = patch(o, f(6.0, -6.0) - o, f(-6.0, 6.0) - o, 9);
        let n = Vec3::new(-0.3, -0.2, 1.0);
        let map = rasterize_depth(&m, &cam, 80, 60).unwrap();
        assert_eq!(map.covered_count(), 80 * 60);
        let fr = cam.frame();
        for j in 0..60 {
            for i in 0..80 {
                // The ray through the pixel centre starts on the plane through the eye.
                let origin = map.unproject(i as f32 + 0.5, j as f32 + 0.5, 0.0);
                let t = (Vec3::new(0.0, 0.0, -1.0) - origin).dot(n) / fr.forward.dot(n);
                let d = map.get(i, j).unwrap();
                assert!((d - t).abs() <= 1e-4, "pixel ({i}, {j}): {d} vs {t}");
            }
        }
    }

    #[test]
    fn sphere_coverage_and_depth_match_the_analytic_sphere() {
        let (r, seg, rings) = (1.0f32, 256, 128);
        let m = uv_sphere(r, seg, rings);
        let cam = ortho_down_z(Vec3::ZERO, 1.25);
        let (w, h) = (256u32, 256u32);
        let map = rasterize_depth(&m, &cam, w, h).unwrap();
        let pix = 2.5 / h as f32;
        let (a, b) = (
            std::f32::consts::TAU / seg as f32,
            std::f32::consts::PI / rings as f32,
        );
        let sag = 1.05 * r * (a * a + b * b) / 8.0;
        let mut checked = 0;
        for j in 0..h {
            for i in 0..w {
                let c = map.unproject(i as f32 + 0.5, j as f32 + 0.5, 0.0);
                let rr = c.truncate().length();
                if rr < r - pix {
                    assert!(map.is_covered(i, j), "({i}, {j}) inside the disc");
                    let p = map.world_point(i, j).unwrap();
                    let radial = p.length();
                    assert!(
                        radial >= r - sag - 1e-4 && radial <= r + 1e-4,
                        "({i}, {j}): |p| = {radial}, sag {sag}"
                    );
                    let analytic = 5.0 - (r * r - rr * rr).sqrt();
                    let d = map.get(i, j).unwrap();
                    assert!(d >= analytic - 1e-4, "({i}, {j}): {d} < {analytic}");
                    checked += 1;
                } else if rr > r + pix {
                    assert!(!map.is_covered(i, j), "({i}, {j}) outside the disc");
                }
            }
        }
        assert!(checked > 30_000);
    }

    #[test]
    fn perspective_plane_has_view_depth_and_points_round_trip() {
        let eye = Vec3::new(1.0, 2.0, 3.0);
        let cam = Camera::perspective(eye, Vec3::new(-0.5, 0.5, -1.0), Vec3::Y, 60.0)
            .unwrap()
            .with_depth_range(0.1, 100.0)
            .unwrap();
        let fr = cam.frame();
        let dist = 4.0;
        let c = eye + fr.forward * dist;
        let m = patch(
            c - 20.0 * fr.right - 20.0 * fr.up,
            40.0 * fr.right,
            40.0 * fr.up,
            4,
        );
        let map = rasterize_depth(&m, &cam, 96, 64).unwrap();
        assert_eq!(map.covered_count(), 96 * 64);
        for d in &map.depth {
            assert!((d - dist).abs() <= dist * 1e-5, "{d}");
        }
        let q = c + 0.3 * fr.right - 0.2 * fr.up;
        let (px, py, d) = map.pixel_of(q).unwrap();
        assert!((d - dist).abs() < 1e-5);
        assert!((map.unproject(px, py, d) - q).length() < 1e-5);
        let (i, j) = (px as u32, py as u32);
        let p = map.world_point(i, j).unwrap();
        let (qx, qy, qd) = map.pixel_of(p).unwrap();
        assert!((qx - (i as f32 + 0.5)).abs() < 1e-3 && (qy - (j as f32 + 0.5)).abs() < 1e-3);
        assert!((qd - dist).abs() < 1e-5);
        assert!(map.pixel_of(eye - fr.forward).is_none());
    }

    #[test]
    fn perspective_floor_crossing_the_near_plane_is_clipped() {
        // Camera at the origin looking down -z; floor y = -1 from z = +10 (behind) to -50.
        let cam = Camera::perspective(Vec3::ZERO, -Vec3::Z, Vec3::Y, 70.0)
            .unwrap()
            .with_depth_range(0.05, 1000.0)
            .unwrap();
        let m = patch(
            Vec3::new(-40.0, -1.0, 10.0),
            Vec3::X * 80.0,
            Vec3::Z * -60.0,
            2,
        );
        let (w, h) = (64u32, 48u32);
        let map = rasterize_depth(&m, &cam, w, h).unwrap();
        let k = h as f32 / (2.0 * cam.half_height_scale());
        for j in 0..h {
            let yc = 0.5 * h as f32 - (j as f32 + 0.5);
            for i in 0..w {
                let analytic = if yc < 0.0 { k / -yc } else { f32::INFINITY };
                let x = (i as f32 + 0.5 - 0.5 * w as f32) * analytic / k;
                if analytic < 49.0 && x.abs() < 39.0 {
                    let d = map.get(i, j).expect("floor pixel covered");
                    assert!((d - analytic).abs() <= 1e-4 * analytic, "{d} vs {analytic}");
                } else if yc >= 0.0 {
                    assert!(!map.is_covered(i, j));
                }
            }
        }
    }

    /// 8 × 8 pixels, world (x, y) ↦ pixel (x, 8 - y): pixel centres at half-integers.
    fn pixel_camera() -> Camera {
        ortho_down_z(Vec3::new(4.0, 4.0, 0.0), 4.0)
    }

    fn coverage_counts(m: &Mesh, cam: &Camera) -> Vec<u32> {
        let mut counts = vec![0u32; 64];
        for (t, tri) in m.triangles.iter().enumerate() {
            let one = mesh(m.positions.clone(), vec![*tri]);
            let map = rasterize_depth(&one, cam, 8, 8).unwrap();
            for (c, &cov) in counts.iter_mut().zip(&map.coverage) {
                *c += cov as u32;
            }
            let _ = t;
        }
        counts
    }

    #[test]
    fn top_left_rule_covers_shared_edges_exactly_once() {
        let cam = pixel_camera();
        let p = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        // A square split along a diagonal through pixel centres (px + py = 8), both windings.
        for tris in [vec![[0, 1, 2], [0, 2, 3]], vec![[0, 2, 1], [3, 2, 0]]] {
            let m = mesh(
                vec![p(1.0, 1.0), p(7.0, 1.0), p(7.0, 7.0), p(1.0, 7.0)],
                tris,
            );
            let counts = coverage_counts(&m, &cam);
            for j in 0..8 {
                for i in 0..8 {
                    let inside = (1..7).contains(&i) && (1..7).contains(&j);
                    assert_eq!(counts[j * 8 + i], inside as u32, "pixel ({i}, {j})");
                }
            }
        }
        // A fan of 8 triangles around a pixel centre, its rim through pixel centres too:
        // horizontal, vertical and diagonal shared edges all pass through centres.
        let rim = [
            (0.5, 0.5),
            (4.5, 0.5),
            (7.5, 0.5),
            (7.5, 4.5),
            (7.5, 7.5),
            (4.5, 7.5),
            (0.5, 7.5),
            (0.5, 4.5),
        ];
        let mut pos = vec![p(4.5, 4.5)];
        pos.extend(rim.iter().map(|&(x, y)| p(x, y)));
        let tris = (0..8u32).map(|k| [0, 1 + k, 1 + (k + 1) % 8]).collect();
        let m = mesh(pos, tris);
        let counts = coverage_counts(&m, &cam);
        assert!(counts.iter().all(|&c| c <= 1), "{counts:?}");
        // Strictly inside the rim (pixels 1..=6 both ways) every centre is covered once.
        for j in 1..7 {
            for i in 1..7 {
                assert_eq!(counts[j * 8 + i], 1, "pixel ({i}, {j})");
            }
        }
        // Drawn together, coverage is the union.
        let map = rasterize_depth(&m, &cam, 8, 8).unwrap();
        for (c, &cov) in counts.iter().zip(&map.coverage) {
            assert_eq!(*c == 1, cov);
        }
    }

    #[test]
    fn triangles_outside_the_viewport_and_degenerate_ones() {
        let cam = pixel_camera();
        let p = |x: f32, y: f32| Vec3::new(x, y, 0.0);
        // Partially outside, and one vertex far beyond the guard band.
        for far in [50.0f32, 3.0e9] {
            let verts = [(-20.0f32, 2.0f32), (far, 3.0), (3.0, 30.0)];
            let m = mesh(
                verts.iter().map(|&(x, y)| p(x, y)).collect(),
                vec![[0, 1, 2]],
            );
            let map = rasterize_depth(&m, &cam, 8, 8).unwrap();
            // Analytic point-in-triangle at every centre (none lies on an edge here).
            let inside = |x: f64, y: f64| {
                let v: Vec<(f64, f64)> = verts.iter().map(|&(a, b)| (a as f64, b as f64)).collect();
                let s = |a: (f64, f64), b: (f64, f64)| {
                    (b.0 - a.0) * (y - a.1) - (b.1 - a.1) * (x - a.0)
                };
                let (e0, e1, e2) = (s(v[0], v[1]), s(v[1], v[2]), s(v[2], v[0]));
                (e0 > 0.0 && e1 > 0.0 && e2 > 0.0) || (e0 < 0.0 && e1 < 0.0 && e2 < 0.0)
            };
            for j in 0..8u32 {
                for i in 0..8u32 {
                    let (x, y) = (i as f64 + 0.5, 8.0 - (j as f64 + 0.5));
                    assert_eq!(map.is_covered(i, j), inside(x, y), "far {far}: ({i}, {j})");
                }
            }
            assert!(map.covered_count() > 0);
        }
        // Zero-area triangles (collinear, repeated vertex) write nothing.
        let m = mesh(
            vec![p(1.0, 1.0), p(4.0, 4.0), p(7.0, 7.0), p(2.0, 6.0)],
            vec![[0, 1, 2], [3, 3, 1]],
        );
        let map = rasterize_depth(&m, &cam, 8, 8).unwrap();
        assert_eq!(map.covered_count(), 0);
        assert!(map.depth.iter().all(|d| *d == f32::INFINITY));
        // Bad sizes are errors.
        assert!(rasterize_depth(&m, &cam, 0, 8).is_err());
        assert!(rasterize_depth(&m, &cam, 8, MAX_SIZE + 1).is_err());
    }

    #[test]
    fn nearest_wins_and_back_faces_can_be_culled() {
        let cam = pixel_camera();
        let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        // Counter-clockwise seen from +z (front), at z = 1; a back-facing one nearer, z = 2.
        let m = mesh(
            vec![
                p(0.0, 0.0, 1.0),
                p(8.0, 0.0, 1.0),
                p(0.0, 8.0, 1.0),
                p(0.0, 0.0, 2.0),
                p(0.0, 8.0, 2.0),
                p(8.0, 0.0, 2.0),
            ],
            vec![[0, 1, 2], [3, 4, 5]],
        );
        let both = rasterize_depth(&m, &cam, 8, 8).unwrap();
        assert_eq!(both.get(1, 6), Some(3.0));
        let culled =
            rasterize_depth_with(&m, &cam, 8, 8, &RasterOptions { cull_back: true }).unwrap();
        assert_eq!(culled.get(1, 6), Some(4.0));
        let (_, ids) = rasterize_triangle_ids(&m, &cam, 8, 8, &RasterOptions::default()).unwrap();
        assert_eq!(ids[6 * 8 + 1], 1);
        assert_eq!(ids[0], u32::MAX);
    }

    #[test]
    fn interpolated_normals_of_a_sphere_are_radial() {
        let mut m = uv_sphere(1.0, 128, 64);
        // Exact radial vertex normals: the interpolated normal at a facet point p is then
        // exactly p / |p| (the barycentric combination of the vertices is p).
        m.normals = m.positions.iter().map(|p| p.normalize()).collect();
        let cam = Camera::perspective(Vec3::new(0.0, 0.5, 4.0), Vec3::ZERO, Vec3::Y, 40.0).unwrap();
        let (map, normals) =
            rasterize_normals(&m, &cam, 64, 64, &RasterOptions::default()).unwrap();
        let mut n = 0;
        for j in 0..64 {
            for i in 0..64 {
                if let Some(p) = map.world_point(i, j) {
                    let nr = normals[map.index(i, j)];
                    assert!((nr - p.normalize()).length() < 1e-4, "{nr} vs {p}");
                    n += 1;
                }
            }
        }
        assert!(n > 500);
    }

    #[test]
    fn deterministic_for_any_thread_count() {
        let m = uv_sphere(1.0, 64, 32);
        let cam = Camera::perspective(Vec3::new(0.3, 0.4, 3.0), Vec3::ZERO, Vec3::Y, 50.0).unwrap();
        let bits = |map: &DepthMap| map.depth.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        let a = rasterize_depth(&m, &cam, 200, 150).unwrap();
        let b = rasterize_depth(&m, &cam, 200, 150).unwrap();
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let c = pool.install(|| rasterize_depth(&m, &cam, 200, 150).unwrap());
        assert_eq!(bits(&a), bits(&b));
        assert_eq!(bits(&a), bits(&c));
        assert_eq!(a.coverage, c.coverage);
    }

    /// Not a test: `cargo test --release -p imprint-core raster -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn bunny_depth_map_timing() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/meshes/stanford-bunny.obj");
        let m = Mesh::load_obj(&path).unwrap();
        let b = m.bounds();
        let size = b.size().max_element();
        let c = b.center();
        let cams = [
            (
                "orthographic",
                Camera::orthographic(c + Vec3::Z * 2.0 * size, c, Vec3::Y, 0.6 * size).unwrap(),
            ),
            (
                "perspective",
                Camera::perspective(c + Vec3::new(0.5, 0.3, 2.0) * size, c, Vec3::Y, 40.0).unwrap(),
            ),
        ];
        for (name, cam) in cams {
            let mut times = Vec::new();
            let mut covered = 0;
            for _ in 0..15 {
                let t = std::time::Instant::now();
                let map = rasterize_depth(&m, &cam, 512, 512).unwrap();
                times.push(t.elapsed().as_secs_f64() * 1e3);
                covered = map.covered_count();
            }
            times.sort_by(|a, b| a.partial_cmp(b).unwrap());
            println!(
                "bunny {} triangles, 512x512 {name}: median {:.2} ms (min {:.2}), {covered} pixels covered, {} threads",
                m.triangles.len(),
                times[times.len() / 2],
                times[0],
                rayon::current_num_threads()
            );
        }
    }
}
