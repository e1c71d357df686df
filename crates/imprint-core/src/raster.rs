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
//!
//! Implementation: the vertices are projected once (in parallel; this pass also does the
//! validation of the mesh). Triangles are then set up in parallel chunks of mesh order. A
//! small triangle (at most 8 × 8 pixel centres, the common case at depth-map resolutions)
//! gets its coverage right away, as a bit mask from its edge functions evaluated four pixel
//! centres at a time (eight, in integers, where the CPU has AVX2: the projection, the setup
//! and the drawing are compiled for it too, with the same bits), and its depth plane, and is
//! kept per band it touches as a compact record; a larger one is kept set up and drawn row
//! by row in each band it touches. Each
//! band then draws its records chunk after chunk, so in mesh order. Within a band a
//! triangle's depth is interpolated from its first row in the band (see `BAND_ROWS`).

use crate::camera::{Camera, Frame};
use crate::geom::barycentric;
use crate::{Error, Mesh, Result};
use glam::{BVec4A, Vec3, Vec4};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicBool, Ordering};

/// Largest accepted width or height, in pixels.
pub const MAX_SIZE: u32 = 16384;
/// Subpixel precision of the snapped vertex coordinates (1/256 pixel).
const SUB_BITS: u32 = 8;
const SUB: f32 = (1 << SUB_BITS) as f32;
const HALF: i64 = 1 << (SUB_BITS - 1);
/// Guard band (pixels) beyond which triangles are clipped: keeps fixed-point products in i64.
const GUARD: f32 = (1 << 20) as f32;
/// Rows per band: the unit of parallel rasterisation, and of depth interpolation (a
/// triangle's depth is interpolated from its first row in each band, see [`Plane`]), so it
/// is part of the output's bit pattern.
const BAND_ROWS: u32 = 16;

/// Options of the rasteriser.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RasterOptions {
    /// Skip triangles whose front side (counter-clockwise as seen by the camera) faces away.
    pub cull_back: bool,
}

/// A depth image: the camera it was taken with, the view depth per pixel (row 0 on top) and
/// the coverage mask. Uncovered pixels hold `f32::INFINITY`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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

    /// A bit per plane the point is outside of (a NaN value counts as outside).
    #[inline]
    fn outcode(&self, v: Vec3) -> u8 {
        let p = self.plane_values(v);
        let mut code = 0;
        for (i, d) in p.iter().enumerate() {
            // Not `d >= 0`: negative or NaN, one comparison and no branch.
            code |= ((*d >= 0.0) as u8 ^ 1) << i;
        }
        code
    }

    /// Snapped screen vertex for a view-space point inside every clip plane.
    #[inline]
    fn screen_vertex(&self, v: Vec3) -> SVert {
        let (px, py) = self.view_to_px(v);
        SVert {
            x: floor_in_guard(px * SUB + 0.5),
            y: floor_in_guard(py * SUB + 0.5),
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

/// [`crate::geom::floor_i`] of a snapped coordinate, clamped to ±2^30 first (`max` takes a
/// NaN to the bound), so that the conversion needs none of the saturating cast's fix-ups
/// (about a dozen instructions each). Inside the guard band (or clipped onto it) the
/// coordinates are below 2^29 in magnitude, so the clamp changes nothing there; it keeps the
/// setup's premise (coordinates below 2^30) even for a vertex clipped to a perspective
/// camera's near plane with rounding to spare.
#[inline(always)]
fn floor_in_guard(x: f32) -> i32 {
    const LIMIT: f32 = (1u32 << 30) as f32;
    // Not `clamp`, which keeps a NaN.
    #[allow(clippy::manual_clamp)]
    let x = x.max(-LIMIT).min(LIMIT);
    // SAFETY: finite and within ±2^30 (clamped just above).
    let i = unsafe { x.to_int_unchecked::<i32>() };
    if (i as f32) > x { i - 1 } else { i }
}

/// A screen vertex: position in 1/256 pixel, and the interpolated depth quantity (view depth
/// for orthographic cameras, 1 / view depth for perspective ones).
#[derive(Clone, Copy, Debug, Default)]
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
struct Tri<'a> {
    v: [&'a SVert; 3],
    i0: i32,
    i1: i32,
    j0: i32,
    j1: i32,
    id: u32,
    /// At most [`SMALL`] × [`SMALL`] pixel centres and vertex extents below [`SMALL_EXTENT`].
    small: bool,
}

/// `E_pq(P) = A Px + B Py + C`, positive inside a triangle set up by [`setup`].
#[inline(always)]
fn edge(p: &SVert, q: &SVert) -> (i64, i64, i64) {
    let (px, py, qx, qy) = (p.x as i64, p.y as i64, q.x as i64, q.y as i64);
    let a = qy - py;
    let b = px - qx;
    (a, b, -(px * a + py * b))
}

/// Sets up one screen triangle; `None` when it is degenerate, culled or covers no pixel centre
/// of the image.
#[inline(always)]
fn setup<'a>(v: [&'a SVert; 3], id: u32, cull_back: bool, w: i32, h: i32) -> Option<Tri<'a>> {
    let [a, mut b, mut c] = v;
    // E_ab(c): twice the signed area, exact (the coordinates are below 2^30 in magnitude).
    let d = |p: &SVert, q: &SVert| (q.x as i64 - p.x as i64, q.y as i64 - p.y as i64);
    let ((abx, aby), (acx, acy)) = (d(a, b), d(a, c));
    let area = aby * acx - abx * acy;
    if area == 0 || (cull_back && area < 0) {
        return None;
    }
    if area < 0 {
        std::mem::swap(&mut b, &mut c);
    }
    let minx = a.x.min(b.x).min(c.x);
    let maxx = a.x.max(b.x).max(c.x);
    let miny = a.y.min(b.y).min(c.y);
    let maxy = a.y.max(b.y).max(c.y);
    // Pixel centres 256 i + 128 inside [min, max].
    let (half, sub) = (HALF as i32, 1 << SUB_BITS);
    let i0 = ((minx - half + sub - 1) >> SUB_BITS).max(0);
    let i1 = ((maxx - half) >> SUB_BITS).min(w - 1);
    let j0 = ((miny - half + sub - 1) >> SUB_BITS).max(0);
    let j1 = ((maxy - half) >> SUB_BITS).min(h - 1);
    if i0 > i1 || j0 > j1 {
        return None;
    }
    let small = i1 - i0 < SMALL
        && j1 - j0 < SMALL
        && maxx - minx < SMALL_EXTENT
        && maxy - miny < SMALL_EXTENT;
    Some(Tri {
        v: [a, b, c],
        i0,
        i1,
        j0,
        j1,
        id,
        small,
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

/// Triangles per setup chunk: the unit of parallel setup and binning.
const CHUNK: usize = 2048;
/// Small triangles (pixel-centre bounding box of at most `SMALL` × `SMALL` pixels) get their
/// coverage during setup ([`Rec`]); larger ones are drawn band by band ([`BigTri`]).
const SMALL: i32 = 8;
/// Vertex extents (1/256 pixel, both axes) of a small triangle are below this. At every pixel
/// centre of its bounding box an edge function `A (Px - px) + B (Py - py)` is then an integer
/// below 2 · extent_x · extent_y < 2^23 in magnitude (|A| ≤ extent_y, |Px - px| ≤ extent_x,
/// and the same for B), and so are its steps from the box's first pixel: exact in `i32` and
/// in `f32`.
const SMALL_EXTENT: i32 = 1 << 11;

/// A projected vertex: its snapped screen position (when inside every clip plane) and outcode.
#[derive(Clone, Copy, Debug)]
struct PVert {
    s: SVert,
    out: u8,
}

/// The depth plane of a set-up triangle, through its unsnapped vertices. The depth at pixel
/// (i, j) is `row_z(jb) + dzdx (i - i0) + dzdy (j - jb)` in `f32`, where `jb` is the
/// triangle's first row in the band of row j: bands of [`BAND_ROWS`] rows restart the
/// interpolation, so this rule (not the work split) fixes the depth bits.
#[derive(Clone, Copy, Debug)]
struct Plane {
    /// `z0 + gx (i0 + 0.5 - x0)`: the plane at the centres of column i0, less the row term
    /// `gy (j + 0.5 - y0)` (in this order, as the sums are rounded).
    zx: f64,
    gy: f64,
    y0: f64,
    dzdx: f32,
    dzdy: f32,
}

impl Plane {
    #[inline]
    fn new(tri: &Tri) -> Self {
        let [a, b, c] = tri.v;
        let (x0, y0, z0) = (a.fx as f64, a.fy as f64, a.z as f64);
        let (x1, y1, z1) = (b.fx as f64 - x0, b.fy as f64 - y0, b.z as f64 - z0);
        let (x2, y2, z2) = (c.fx as f64 - x0, c.fy as f64 - y0, c.z as f64 - z0);
        let det = x1 * y2 - x2 * y1;
        let (gx, gy) = if det != 0.0 {
            ((z1 * y2 - z2 * y1) / det, (z2 * x1 - z1 * x2) / det)
        } else {
            (0.0, 0.0)
        };
        Plane {
            zx: z0 + gx * (tri.i0 as f64 + 0.5 - x0),
            gy,
            y0,
            dzdx: gx as f32,
            dzdy: gy as f32,
        }
    }

    /// The depth quantity at the centre of pixel (i0, jb).
    #[inline]
    fn row_z(&self, jb: i32) -> f32 {
        (self.zx + self.gy * (jb as f64 + 0.5 - self.y0)) as f32
    }
}

/// A small triangle's part in one band, or a reference to a big triangle (`mask == 0`).
/// Bit `8 dr + c` of `mask` is set when the pixel centre (i0 + c, jb + dr) is covered, where
/// jb is the triangle's first row in the band; there the depth quantity is
/// `z00 + dzdx c + dzdy dr` (see [`Plane`]), at pixel index `base + dr · width + c`.
#[derive(Clone, Copy, Debug, Default)]
struct Rec {
    mask: u64,
    /// Pixel index of (i0, jb), or for a big triangle its index in [`Binned::bigs`].
    base: u32,
    z00: f32,
    dzdx: f32,
    dzdy: f32,
    id: u32,
    band: u16,
    /// Whether the rows of the mask can be drawn four (or eight) columns at a time: those
    /// columns lie inside the image.
    rows: bool,
}

/// A triangle drawn row by row in each band it touches, with exact `i64` edge functions.
#[derive(Clone, Copy, Debug)]
struct BigTri {
    /// Edge functions (top-left bias included) at the centre of pixel (i0, j0).
    e: [i64; 3],
    step_x: [i64; 3],
    step_y: [i64; 3],
    plane: Plane,
    i0: i32,
    i1: i32,
    j0: i32,
    j1: i32,
    id: u32,
}

/// The output of one setup chunk, binned by band.
struct Binned {
    /// The chunk's small and big triangles by band (`recs[off[b]..off[b + 1]]`), in mesh order
    /// within each band.
    recs: Vec<Rec>,
    off: Vec<u32>,
    bigs: Vec<BigTri>,
}

/// Sets up and bins the triangles of one chunk.
struct Binner {
    w: i32,
    h: i32,
    cull_back: bool,
    /// Records in mesh order, and how many each band has.
    recs: Vec<Rec>,
    count: Vec<u32>,
    bigs: Vec<BigTri>,
}

/// Coverage of the (at most 8 × 8) pixel centres of a small triangle's bounding box: bit
/// `8 r + c` for pixel (i0 + c, j0 + r). The three edge functions (top-left bias included,
/// `row` at the box's first pixel centre) are evaluated four columns at a time in `f32` lanes
/// ([`Vec4`], SIMD). Inside the box every value, product and sum is an integer below 2^24 in
/// magnitude (see [`SMALL_EXTENT`]), so exact, and the signs are those of the exact integer
/// edge functions; lanes outside the box are masked off.
#[inline(always)]
fn small_coverage(row: [i32; 3], step_x: [i32; 3], step_y: [i32; 3], ni: i32, nj: i32) -> u64 {
    let lanes = Vec4::new(0.0, 1.0, 2.0, 3.0);
    let mut e = [Vec4::ZERO; 3];
    let mut x4 = [Vec4::ZERO; 3];
    let mut y = [Vec4::ZERO; 3];
    for k in 0..3 {
        let sx = step_x[k] as f32;
        e[k] = Vec4::splat(row[k] as f32) + Vec4::splat(sx) * lanes;
        x4[k] = Vec4::splat(4.0 * sx);
        y[k] = Vec4::splat(step_y[k] as f32);
    }
    let covered = |e: [Vec4; 3]| e[0].min(e[1]).min(e[2]).cmpge(Vec4::ZERO).bitmask() as u64;
    let mut mask = 0u64;
    // Fixed trip counts (4 or 8 rows, 4 or 8 columns): no data-dependent branches inside.
    let rows = if nj <= 4 { 4 } else { 8 };
    if ni <= 4 {
        for r in 0..rows {
            mask |= covered(e) << (8 * r);
            for k in 0..3 {
                e[k] += y[k];
            }
        }
    } else {
        for r in 0..rows {
            let hi = [e[0] + x4[0], e[1] + x4[1], e[2] + x4[2]];
            mask |= (covered(e) | covered(hi) << 4) << (8 * r);
            for k in 0..3 {
                e[k] += y[k];
            }
        }
    }
    let cols = (1u64 << ni) - 1;
    mask & (cols * 0x0101_0101_0101_0101) & (u64::MAX >> (64 - 8 * nj))
}

/// [`small_coverage`] with a row's eight columns in one AVX2 register, in `i32`: inside the
/// box the values are the same exact integers as there (below 2^24 in magnitude, see
/// [`SMALL_EXTENT`]), and lanes outside it (at most 8 pixels from its first centre, so
/// below 2^25) are masked off the same way, so the mask is the same bits.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
fn small_coverage_avx2(row: [i32; 3], step_x: [i32; 3], step_y: [i32; 3], ni: i32, nj: i32) -> u64 {
    use std::arch::x86_64::*;
    let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    let mut e = [_mm256_setzero_si256(); 3];
    let mut y = [_mm256_setzero_si256(); 3];
    for k in 0..3 {
        let x = _mm256_mullo_epi32(_mm256_set1_epi32(step_x[k]), lanes);
        e[k] = _mm256_add_epi32(_mm256_set1_epi32(row[k]), x);
        y[k] = _mm256_set1_epi32(step_y[k]);
    }
    // A lane's sign bit is set where some edge function is negative (outside).
    let outside = |e: &[__m256i; 3]| {
        let m = _mm256_min_epi32(_mm256_min_epi32(e[0], e[1]), e[2]);
        _mm256_movemask_ps(_mm256_castsi256_ps(m)) as u64
    };
    let mut out = 0u64;
    // Fixed trip counts (4 or 8 rows), as in `small_coverage`; rows not evaluated are
    // masked off below.
    let rows = if nj <= 4 { 4 } else { 8 };
    for r in 0..rows {
        out |= outside(&e) << (8 * r);
        for k in 0..3 {
            e[k] = _mm256_add_epi32(e[k], y[k]);
        }
    }
    let cols = (1u64 << ni) - 1;
    !out & (cols * 0x0101_0101_0101_0101) & (u64::MAX >> (64 - 8 * nj))
}

impl Binner {
    fn new(w: u32, h: u32, cull_back: bool, triangles: usize) -> Self {
        Binner {
            w: w as i32,
            h: h as i32,
            cull_back,
            recs: Vec::with_capacity(triangles + triangles / 4),
            count: vec![0; h.div_ceil(BAND_ROWS) as usize],
            bigs: Vec::new(),
        }
    }

    #[inline(always)]
    fn push(&mut self, rec: Rec) {
        self.count[rec.band as usize] += 1;
        self.recs.push(rec);
    }

    /// Groups the records by band, keeping mesh order within each (counting sort).
    fn finish(self) -> Binned {
        let mut off = Vec::with_capacity(self.count.len() + 1);
        let mut at = 0;
        off.push(0);
        for &n in &self.count {
            at += n;
            off.push(at);
        }
        let mut next = off.clone();
        let mut recs = vec![Rec::default(); self.recs.len()];
        for r in &self.recs {
            let slot = &mut next[r.band as usize];
            recs[*slot as usize] = *r;
            *slot += 1;
        }
        Binned {
            recs,
            off,
            bigs: self.bigs,
        }
    }

    /// Sets up one screen triangle and bins it; `AVX2` only where the CPU has it (see
    /// [`bin_chunk`]). Inlined into it, so that the AVX2 build reaches the coverage.
    #[inline(always)]
    fn add<const AVX2: bool>(&mut self, v: [&SVert; 3], id: u32) {
        let Some(tri) = setup(v, id, self.cull_back, self.w, self.h) else {
            return;
        };
        if tri.small {
            self.small::<AVX2>(&tri);
        } else {
            self.big(&tri);
        }
    }

    /// A small triangle (at most 8 × 8 pixel centres): its coverage as a bit mask, four pixel
    /// centres at a time (eight with AVX2), and its depth plane where it covers any.
    #[inline(always)]
    fn small<const AVX2: bool>(&mut self, tri: &Tri) {
        let [a, b, c] = tri.v;
        let sub = 1i32 << SUB_BITS;
        let px0 = tri.i0 * sub + HALF as i32;
        let py0 = tri.j0 * sub + HALF as i32;
        let mut row = [0i32; 3];
        let mut step_x = [0i32; 3];
        let mut step_y = [0i32; 3];
        for (k, (p, q)) in [(b, c), (c, a), (a, b)].into_iter().enumerate() {
            // E(P) = A (Px - px) + B (Py - py): `edge` without its large constant term.
            let (ea, eb) = (q.y - p.y, p.x - q.x);
            let bias = if ea > 0 || (ea == 0 && eb > 0) { 0 } else { -1 };
            row[k] = ea * (px0 - p.x) + eb * (py0 - p.y) + bias;
            step_x[k] = ea * sub;
            step_y[k] = eb * sub;
        }
        let (ni, nj) = (tri.i1 - tri.i0 + 1, tri.j1 - tri.j0 + 1);
        #[cfg(target_arch = "x86_64")]
        // SAFETY: `AVX2` is set only where the CPU has AVX2 (`bin_chunk`).
        let mask = if AVX2 {
            unsafe { small_coverage_avx2(row, step_x, step_y, ni, nj) }
        } else {
            small_coverage(row, step_x, step_y, ni, nj)
        };
        #[cfg(not(target_arch = "x86_64"))]
        let mask = small_coverage(row, step_x, step_y, ni, nj);
        if mask == 0 {
            return;
        }
        let plane = Plane::new(tri);
        // Rows of the first band, then (at most) the rest in the next one.
        let split = BAND_ROWS as i32 - tri.j0 % BAND_ROWS as i32;
        let mut part = |jb: i32, mask: u64| {
            if mask != 0 {
                self.push(Rec {
                    mask,
                    base: (jb * self.w + tri.i0) as u32,
                    z00: plane.row_z(jb),
                    dzdx: plane.dzdx,
                    dzdy: plane.dzdy,
                    id: tri.id,
                    band: (jb / BAND_ROWS as i32) as u16,
                    rows: tri.i0 + if mask & WIDE != 0 { 8 } else { 4 } <= self.w,
                });
            }
        };
        if split >= nj {
            part(tri.j0, mask);
        } else {
            part(tri.j0, mask & ((1u64 << (8 * split)) - 1));
            part(tri.j0 + split, mask >> (8 * split));
        }
    }

    /// Keeps a larger triangle, set up, for every band it touches.
    fn big(&mut self, tri: &Tri) {
        let [a, b, c] = tri.v;
        let edges = [edge(b, c), edge(c, a), edge(a, b)];
        let sub = 1i64 << SUB_BITS;
        let px0 = tri.i0 as i64 * sub + HALF;
        let py0 = tri.j0 as i64 * sub + HALF;
        let mut e = [0i64; 3];
        let mut step_x = [0i64; 3];
        let mut step_y = [0i64; 3];
        for k in 0..3 {
            let (ea, eb, ec) = edges[k];
            // Top-left rule (y down): a left edge has the interior towards +x (A > 0), a top
            // edge is horizontal with the interior below (A = 0, B > 0).
            let bias = if ea > 0 || (ea == 0 && eb > 0) { 0 } else { -1 };
            e[k] = ea * px0 + eb * py0 + ec + bias;
            step_x[k] = ea * sub;
            step_y[k] = eb * sub;
        }
        let big = self.bigs.len() as u32;
        self.bigs.push(BigTri {
            e,
            step_x,
            step_y,
            plane: Plane::new(tri),
            i0: tri.i0,
            i1: tri.i1,
            j0: tri.j0,
            j1: tri.j1,
            id: tri.id,
        });
        for band in tri.j0 / BAND_ROWS as i32..=tri.j1 / BAND_ROWS as i32 {
            self.push(Rec {
                mask: 0,
                base: big,
                id: tri.id,
                band: band as u16,
                ..Rec::default()
            });
        }
    }
}

/// Name of the mesh in validation errors.
const MESH_NAME: &str = "rasterised mesh";

/// Which compiled build of the setup and the drawing runs: the widest the CPU has, or the
/// plain one (which the tests compare with it; both give the same bits).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Build {
    Widest,
    #[cfg(test)]
    Plain,
}

impl Build {
    /// Whether the AVX2 build runs.
    #[inline]
    fn avx2(self) -> bool {
        #[cfg(target_arch = "x86_64")]
        if self == Build::Widest {
            return std::is_x86_feature_detected!("avx2");
        }
        false
    }
}

/// Projects the vertices, sets up the triangles (clipped ones become fans, in order) and bins
/// them by band, in parallel chunks. `Err` for the errors of [`Mesh::validate`], which is folded
/// into these passes.
fn setup_binned(
    mesh: &Mesh,
    proj: &Projector,
    opts: &RasterOptions,
    w: u32,
    h: u32,
    build: Build,
) -> Result<Vec<Binned>> {
    let invalid = || {
        Err(mesh
            .validate(MESH_NAME)
            .err()
            .unwrap_or_else(|| Error::Invalid(format!("{MESH_NAME}: invalid mesh"))))
    };
    if mesh.triangles.is_empty() {
        return invalid();
    }
    let bad = AtomicBool::new(false);
    let mut verts = vec![
        PVert {
            s: SVert::default(),
            out: 0,
        };
        mesh.positions.len()
    ];
    verts
        .par_chunks_mut(4096)
        .zip(mesh.positions.par_chunks(4096))
        .for_each(|(out, pos)| {
            if !project_chunk(proj, pos, out, build) {
                bad.store(true, Ordering::Relaxed);
            }
        });
    if bad.load(Ordering::Relaxed) {
        return invalid();
    }
    let ctx = ChunkCtx {
        mesh,
        proj,
        verts: &verts,
        w,
        h,
        cull_back: opts.cull_back,
    };
    let chunks: Vec<Binned> = mesh
        .triangles
        .par_chunks(CHUNK)
        .enumerate()
        .map(|(c, chunk)| bin_chunk(&ctx, c * CHUNK, chunk, &bad, build))
        .collect();
    if bad.load(Ordering::Relaxed) {
        return invalid();
    }
    Ok(chunks)
}

/// Projects `pos` into `out` (outcodes, and the screen vertex where inside every plane);
/// false when a position is not finite. Compiled for AVX2 too, with the same bits.
fn project_chunk(proj: &Projector, pos: &[Vec3], out: &mut [PVert], build: Build) -> bool {
    #[cfg(target_arch = "x86_64")]
    if build.avx2() {
        // SAFETY: the CPU has AVX2 (`Build::avx2` checked it).
        return unsafe { project_chunk_avx2(proj, pos, out) };
    }
    project_chunk_any(proj, pos, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn project_chunk_avx2(proj: &Projector, pos: &[Vec3], out: &mut [PVert]) -> bool {
    project_chunk_any(proj, pos, out)
}

#[inline(always)]
fn project_chunk_any(proj: &Projector, pos: &[Vec3], out: &mut [PVert]) -> bool {
    let mut finite = true;
    for (o, p) in out.iter_mut().zip(pos) {
        finite &= p.is_finite();
        let v = proj.frame.to_view(*p);
        o.out = proj.outcode(v);
        if o.out == 0 {
            o.s = proj.screen_vertex(v);
        }
    }
    finite
}

/// What every setup chunk reads.
struct ChunkCtx<'a> {
    mesh: &'a Mesh,
    proj: &'a Projector,
    verts: &'a [PVert],
    w: u32,
    h: u32,
    cull_back: bool,
}

/// Sets up and bins the triangles `first..` of one chunk; sets `bad` on an index out of
/// range. Compiled for AVX2 too, where a small triangle's rows take one instruction per edge
/// (and VEX's three-operand forms spare the register copies); the bits are the same.
fn bin_chunk(
    ctx: &ChunkCtx,
    first: usize,
    chunk: &[[u32; 3]],
    bad: &AtomicBool,
    build: Build,
) -> Binned {
    #[cfg(target_arch = "x86_64")]
    if build.avx2() {
        // SAFETY: the CPU has AVX2 (`Build::avx2` checked it).
        return unsafe { bin_chunk_avx2(ctx, first, chunk, bad) };
    }
    bin_chunk_any::<false>(ctx, first, chunk, bad)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn bin_chunk_avx2(
    ctx: &ChunkCtx,
    first: usize,
    chunk: &[[u32; 3]],
    bad: &AtomicBool,
) -> Binned {
    bin_chunk_any::<true>(ctx, first, chunk, bad)
}

#[inline(always)]
fn bin_chunk_any<const AVX2: bool>(
    ctx: &ChunkCtx,
    first: usize,
    chunk: &[[u32; 3]],
    bad: &AtomicBool,
) -> Binned {
    let (proj, verts) = (ctx.proj, ctx.verts);
    let mut bin = Binner::new(ctx.w, ctx.h, ctx.cull_back, chunk.len());
    let mut poly = Vec::with_capacity(9);
    for (k, t) in chunk.iter().enumerate() {
        let id = (first + k) as u32;
        let (Some(a), Some(b), Some(cc)) = (
            verts.get(t[0] as usize),
            verts.get(t[1] as usize),
            verts.get(t[2] as usize),
        ) else {
            bad.store(true, Ordering::Relaxed);
            continue;
        };
        let any = a.out | b.out | cc.out;
        if any == 0 {
            bin.add::<AVX2>([&a.s, &b.s, &cc.s], id);
            continue;
        }
        if a.out & b.out & cc.out != 0 {
            continue;
        }
        let view = t.map(|i| proj.frame.to_view(ctx.mesh.positions[i as usize]));
        clip(proj, view, any, &mut poly);
        if poly.len() < 3 {
            continue;
        }
        let s: Vec<SVert> = poly.iter().map(|v| proj.screen_vertex(*v)).collect();
        for m in 1..s.len() - 1 {
            bin.add::<AVX2>([&s[0], &s[m], &s[m + 1]], id);
        }
    }
    bin.finish()
}

/// Columns 4..8 of every row of a small-triangle mask.
const WIDE: u64 = 0xf0f0_f0f0_f0f0_f0f0;

/// Lane masks for the 16 patterns of 4 bits.
const LANE_MASKS: [BVec4A; 16] = {
    let mut t = [BVec4A::new(false, false, false, false); 16];
    let mut b = 0;
    while b < 16 {
        t[b] = BVec4A::new(b & 1 != 0, b & 2 != 0, b & 4 != 0, b & 8 != 0);
        b += 1;
    }
    t
};

/// Draws a small triangle's pixels one row of four (`W` = 1) or eight (`W` = 2) at a time
/// ([`Vec4`] lanes, the same operations per lane as [`draw_bits`]); its columns must lie
/// inside the image rows. Rows without a covered pixel before the last one are drawn too
/// (nothing changes there), which saves a branch per row.
#[inline(always)]
fn draw_rows<const IDS: bool, const PERSP: bool, const W: usize>(
    rec: &Rec,
    width: usize,
    base: usize,
    depth: &mut [f32],
    ids: &mut [u32],
) {
    let lanes = Vec4::new(0.0, 1.0, 2.0, 3.0);
    let z0 = Vec4::splat(rec.z00);
    let dzdx = Vec4::splat(rec.dzdx);
    let zc: [Vec4; W] = std::array::from_fn(|h| z0 + dzdx * (lanes + 4.0 * h as f32));
    let mut m = rec.mask;
    let mut k = base;
    let mut dr = 0.0f32;
    while m != 0 {
        let dy = Vec4::splat(rec.dzdy * dr);
        for (h, zc) in zc.iter().enumerate() {
            let z = *zc + dy;
            let d = if PERSP { Vec4::ONE / z } else { z };
            let at = k + 4 * h;
            let cur = Vec4::from_slice(&depth[at..at + 4]);
            let mut win = d.cmplt(cur) & LANE_MASKS[(m as usize >> (4 * h)) & 0xf];
            if PERSP {
                win &= z.cmpgt(Vec4::ZERO);
            }
            Vec4::select(win, d, cur).write_to_slice(&mut depth[at..at + 4]);
            if IDS {
                let mut w = win.bitmask();
                while w != 0 {
                    ids[at + w.trailing_zeros() as usize] = rec.id;
                    w &= w - 1;
                }
            }
        }
        m >>= 8;
        k += width;
        dr += 1.0;
    }
}

/// Draws a small triangle's pixels one at a time.
#[inline(always)]
fn draw_bits<const IDS: bool, const PERSP: bool>(
    rec: &Rec,
    width: usize,
    base: usize,
    depth: &mut [f32],
    ids: &mut [u32],
) {
    let mut m = rec.mask;
    while m != 0 {
        let bit = m.trailing_zeros() as usize;
        m &= m - 1;
        let (dr, c) = (bit >> 3, bit & 7);
        let z = rec.z00 + rec.dzdx * c as f32 + rec.dzdy * dr as f32;
        let d = if PERSP { 1.0 / z } else { z };
        let k = base + dr * width + c;
        if d < depth[k] && (!PERSP || z > 0.0) {
            depth[k] = d;
            if IDS {
                ids[k] = rec.id;
            }
        }
    }
}

/// One band's rows of the output: band `band` (rows from `BAND_ROWS * band`, as many as
/// `depth` holds) of an image `width` pixels wide.
struct Band<'a> {
    band: usize,
    width: usize,
    depth: &'a mut [f32],
    cover: &'a mut [bool],
    ids: &'a mut [u32],
}

/// Draws a band: every chunk's triangles touching it, in mesh order. Nearest depth wins, the
/// earlier triangle on a tie. Compiled for AVX2 too (VEX's three-operand forms); the same
/// operations, so the same bits.
fn draw_band<const IDS: bool, const PERSP: bool>(chunks: &[Binned], out: Band, build: Build) {
    #[cfg(target_arch = "x86_64")]
    if build.avx2() {
        // SAFETY: the CPU has AVX2 (`Build::avx2` checked it).
        return unsafe { draw_band_avx2::<IDS, PERSP>(chunks, out) };
    }
    draw_band_any::<IDS, PERSP>(chunks, out)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn draw_band_avx2<const IDS: bool, const PERSP: bool>(chunks: &[Binned], out: Band) {
    draw_band_any::<IDS, PERSP>(chunks, out)
}

#[inline(always)]
fn draw_band_any<const IDS: bool, const PERSP: bool>(chunks: &[Binned], out: Band) {
    let Band {
        band,
        width,
        depth,
        cover,
        ids,
    } = out;
    let row0 = band * BAND_ROWS as usize;
    let first = row0 * width;
    depth.fill(f32::INFINITY);
    if IDS {
        ids.fill(u32::MAX);
    }
    for ch in chunks {
        for rec in &ch.recs[ch.off[band] as usize..ch.off[band + 1] as usize] {
            if rec.mask == 0 {
                let big = &ch.bigs[rec.base as usize];
                draw_big::<IDS, PERSP>(big, width, row0 as i32, depth, ids);
                continue;
            }
            let base = rec.base as usize - first;
            if rec.rows && rec.mask & WIDE == 0 {
                draw_rows::<IDS, PERSP, 1>(rec, width, base, depth, ids);
            } else if rec.rows {
                draw_rows::<IDS, PERSP, 2>(rec, width, base, depth, ids);
            } else {
                draw_bits::<IDS, PERSP>(rec, width, base, depth, ids);
            }
        }
    }
    // Every written depth is below the initial infinity, and depths only decrease.
    for (c, d) in cover.iter_mut().zip(depth.iter()) {
        *c = *d != f32::INFINITY;
    }
}

/// Draws the rows of a big triangle that lie in the band starting at row `row0`.
fn draw_big<const IDS: bool, const PERSP: bool>(
    tri: &BigTri,
    width: usize,
    row0: i32,
    depth: &mut [f32],
    ids: &mut [u32],
) {
    let rows = (depth.len() / width) as i32;
    let j0 = tri.j0.max(row0);
    let j1 = tri.j1.min(row0 + rows - 1);
    let dj0 = (j0 - tri.j0) as i64;
    let mut row_e: [i64; 3] = std::array::from_fn(|k| tri.e[k] + tri.step_y[k] * dj0);
    let p = &tri.plane;
    let z00 = p.row_z(j0);
    let sx = tri.step_x;
    for j in j0..=j1 {
        let dj = (j - j0) as f32;
        let base = (j - row0) as usize * width;
        let [mut e0, mut e1, mut e2] = row_e;
        for i in tri.i0..=tri.i1 {
            if (e0 | e1 | e2) >= 0 {
                let z = z00 + p.dzdx * (i - tri.i0) as f32 + p.dzdy * dj;
                let d = if PERSP { 1.0 / z } else { z };
                let idx = base + i as usize;
                if d < depth[idx] && (!PERSP || z > 0.0) {
                    depth[idx] = d;
                    if IDS {
                        ids[idx] = tri.id;
                    }
                }
            }
            e0 += sx[0];
            e1 += sx[1];
            e2 += sx[2];
        }
        for (e, s) in row_e.iter_mut().zip(tri.step_y) {
            *e += s;
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
    build: Build,
) -> Result<(DepthMap, Vec<u32>)> {
    camera.validate()?;
    check_size(width, height)?;
    let proj = Projector::new(camera, width, height);
    let chunks = setup_binned(mesh, &proj, opts, width, height, build)?;
    // Zeroed (cheap) allocations; every band clears its rows in parallel.
    let n = width as usize * height as usize;
    let mut map = DepthMap {
        camera: *camera,
        width,
        height,
        depth: vec![0.0; n],
        coverage: vec![false; n],
    };
    let mut ids = if want_ids { vec![0; n] } else { Vec::new() };
    let w = width as usize;
    let chunk = w * BAND_ROWS as usize;
    let persp = proj.persp;
    let band = |band, depth, cover, ids| Band {
        band,
        width: w,
        depth,
        cover,
        ids,
    };
    if want_ids {
        map.depth
            .par_chunks_mut(chunk)
            .zip(map.coverage.par_chunks_mut(chunk))
            .zip(ids.par_chunks_mut(chunk))
            .enumerate()
            .for_each(|(b, ((d, c), id))| {
                if persp {
                    draw_band::<true, true>(&chunks, band(b, d, c, id), build)
                } else {
                    draw_band::<true, false>(&chunks, band(b, d, c, id), build)
                }
            });
    } else {
        map.depth
            .par_chunks_mut(chunk)
            .zip(map.coverage.par_chunks_mut(chunk))
            .enumerate()
            .for_each(|(b, (d, c))| {
                if persp {
                    draw_band::<false, true>(&chunks, band(b, d, c, &mut []), build)
                } else {
                    draw_band::<false, false>(&chunks, band(b, d, c, &mut []), build)
                }
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
    Ok(rasterize_impl(mesh, camera, width, height, opts, false, Build::Widest)?.0)
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
    rasterize_impl(mesh, camera, width, height, opts, true, Build::Widest)
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

    /// The snapped coordinates' floor is `geom::floor_i`'s inside ±2^30 (where every vertex
    /// in the guard band lies), and defined past it: NaN and ±∞ go to the bounds.
    #[test]
    fn floor_in_guard_is_floor_i_in_range() {
        let mut x = 0x2545_f491u32;
        let mut values = vec![
            0.0, -0.0, 0.5, -0.5, 1.0, -1.0, 1e-30, -1e-30, 5.3e8, -5.3e8,
        ];
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let scale = [1.0, 300.0, 7e4, 1e7, 1.07e9][(x % 5) as usize];
            values.push(((x >> 8) as f32 / (1u32 << 24) as f32 - 0.5) * 2.0 * scale);
        }
        for v in values {
            assert_eq!(floor_in_guard(v), crate::geom::floor_i(v), "{v}");
        }
        let limit = 1 << 30;
        assert_eq!(floor_in_guard(f32::NAN), -limit);
        assert_eq!(floor_in_guard(f32::INFINITY), limit);
        assert_eq!(floor_in_guard(f32::NEG_INFINITY), -limit);
        assert_eq!(floor_in_guard(3e9), limit);
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
    fn invalid_meshes_give_the_errors_of_mesh_validate() {
        let cam = pixel_camera();
        let good = patch(Vec3::ZERO, Vec3::X * 8.0, Vec3::Y * 8.0, 40);
        assert!(good.triangles.len() > CHUNK);
        let mut cases = Vec::new();
        let mut m = good.clone();
        m.triangles.clear();
        cases.push(m);
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            // A vertex of a triangle, and one that no triangle uses.
            let mut m = good.clone();
            m.positions[5].y = bad;
            cases.push(m);
            let mut m = good.clone();
            m.positions.push(Vec3::new(0.0, 0.0, bad));
            cases.push(m);
        }
        // An index out of range in the last chunk, and after a non-finite vertex.
        let mut m = good.clone();
        m.triangles.last_mut().unwrap()[2] = m.positions.len() as u32;
        cases.push(m.clone());
        m.positions[0].x = f32::NAN;
        cases.push(m);
        for m in &cases {
            let want = m.validate("rasterised mesh").unwrap_err().to_string();
            let got = rasterize_depth(m, &cam, 8, 8).unwrap_err().to_string();
            assert_eq!(got, want);
        }
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

    /// The straightforward rasteriser the binned one must match bit for bit: every pixel
    /// centre against every set-up triangle in mesh order, with the exact `i64` edge functions,
    /// the top-left rule and the band-relative depth interpolation (see [`Plane`]).
    fn reference(
        m: &Mesh,
        cam: &Camera,
        w: u32,
        h: u32,
        opts: &RasterOptions,
    ) -> (Vec<f32>, Vec<bool>, Vec<u32>) {
        let proj = Projector::new(cam, w, h);
        let mut tris: Vec<([SVert; 3], [i32; 4], u32)> = Vec::new();
        let mut poly = Vec::new();
        for (id, t) in m.triangles.iter().enumerate() {
            let view = t.map(|i| proj.frame.to_view(m.positions[i as usize]));
            let out = view.map(|v| proj.outcode(v));
            if out[0] & out[1] & out[2] != 0 {
                continue;
            }
            clip(&proj, view, out[0] | out[1] | out[2], &mut poly);
            let s: Vec<SVert> = poly.iter().map(|v| proj.screen_vertex(*v)).collect();
            for k in 2..s.len() {
                let v = [&s[0], &s[k - 1], &s[k]];
                if let Some(t) = setup(v, id as u32, opts.cull_back, w as i32, h as i32) {
                    tris.push((t.v.map(|v| *v), [t.i0, t.i1, t.j0, t.j1], t.id));
                }
            }
        }
        let n = (w * h) as usize;
        let (mut depth, mut ids) = (vec![f32::INFINITY; n], vec![u32::MAX; n]);
        for j in 0..h as i32 {
            for i in 0..w as i32 {
                let (px, py) = (i as i64 * 256 + 128, j as i64 * 256 + 128);
                let k = (j * w as i32 + i) as usize;
                for &([a, b, c], [i0, i1, j0, j1], id) in &tris {
                    if i < i0 || i > i1 || j < j0 || j > j1 {
                        continue;
                    }
                    let inside = [(b, c), (c, a), (a, b)].iter().all(|(p, q)| {
                        let (ea, eb, ec) = edge(p, q);
                        let e = ea * px + eb * py + ec;
                        e > 0 || (e == 0 && (ea > 0 || (ea == 0 && eb > 0)))
                    });
                    if !inside {
                        continue;
                    }
                    // Depth plane through the unsnapped vertices, restarted at the triangle's
                    // first row in each band of 16 rows.
                    let (x0, y0, z0) = (a.fx as f64, a.fy as f64, a.z as f64);
                    let (x1, y1, z1) = (b.fx as f64 - x0, b.fy as f64 - y0, b.z as f64 - z0);
                    let (x2, y2, z2) = (c.fx as f64 - x0, c.fy as f64 - y0, c.z as f64 - z0);
                    let det = x1 * y2 - x2 * y1;
                    let (gx, gy) = if det != 0.0 {
                        ((z1 * y2 - z2 * y1) / det, (z2 * x1 - z1 * x2) / det)
                    } else {
                        (0.0, 0.0)
                    };
                    let jb = j0.max(j - j % 16);
                    let z00 = z0 + gx * (i0 as f64 + 0.5 - x0) + gy * (jb as f64 + 0.5 - y0);
                    let z = z00 as f32 + gx as f32 * (i - i0) as f32 + gy as f32 * (j - jb) as f32;
                    let d = if proj.persp { 1.0 / z } else { z };
                    if d < depth[k] && (!proj.persp || z > 0.0) {
                        depth[k] = d;
                        ids[k] = id;
                    }
                }
            }
        }
        let cover = depth.iter().map(|d| *d != f32::INFINITY).collect();
        (depth, cover, ids)
    }

    /// A small pseudo-random generator (xorshift64*), for reproducible test meshes.
    struct Rng(u64);

    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 40) as f32 / (1u64 << 24) as f32
        }

        fn range(&mut self, lo: f32, hi: f32) -> f32 {
            lo + (hi - lo) * self.next()
        }

        fn point(&mut self, c: Vec3, r: f32) -> Vec3 {
            c + Vec3::new(self.range(-r, r), self.range(-r, r), self.range(-r, r))
        }
    }

    /// Triangles of every kind the rasteriser distinguishes: tiny, up to 8 × 8 pixels (narrow,
    /// wide, tall, across band boundaries and the image border), larger ones, a jittered grid
    /// with shared edges, exact duplicates in both windings (depth ties), triangles through
    /// the near plane and far beyond the guard band.
    fn random_mesh(rng: &mut Rng) -> Mesh {
        let mut pos = Vec::new();
        let mut tris = Vec::new();
        let mut tri = |pos: &mut Vec<Vec3>, a: Vec3, b: Vec3, c: Vec3| {
            let n = pos.len() as u32;
            pos.extend([a, b, c]);
            tris.push([n, n + 1, n + 2]);
        };
        for k in 0..400 {
            // Sizes in world units; the image spans about 2 units.
            let size = [0.01, 0.03, 0.08, 0.15, 0.4, 1.0][k % 6];
            let c = rng.point(Vec3::ZERO, 1.1);
            let (a, b, d) = (rng.point(c, size), rng.point(c, size), rng.point(c, size));
            tri(&mut pos, a, b, d);
            if k % 9 == 0 {
                tri(&mut pos, a, d, b);
                tri(&mut pos, a, b, d);
            }
        }
        // Behind the rest (seen from +z), reaching far beyond the guard band.
        for _ in 0..4 {
            let c = rng.point(Vec3::new(0.0, 0.0, -2.0), 0.5);
            let far =
                |rng: &mut Rng| c + Vec3::new(rng.range(-1e7, 1e7), rng.range(-1e7, 1e7), 0.0);
            let (a, b) = (far(rng), far(rng));
            tri(&mut pos, c, a, b);
        }
        let base = pos.len() as u32;
        let n = 12;
        for j in 0..=n {
            for i in 0..=n {
                let p = Vec3::new(i as f32 / n as f32 - 0.5, j as f32 / n as f32 - 0.5, 0.3);
                pos.push(p * 1.6 + rng.point(Vec3::ZERO, 0.02));
            }
        }
        let id = |i: u32, j: u32| base + j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        mesh(pos, tris)
    }

    #[test]
    fn binned_rasteriser_matches_the_reference_bit_for_bit() {
        let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
        // Big triangles, small ones drawn 4 and 8 columns at a time, one pixel at a time (at
        // the right border), and taller than 4 rows.
        let mut paths = [0usize; 5];
        for round in 0..6 {
            let m = random_mesh(&mut rng);
            let eye = rng.point(Vec3::new(0.0, 0.0, 3.0), 0.5);
            let cams = [
                Camera::orthographic(eye, Vec3::ZERO, Vec3::Y, 1.2).unwrap(),
                Camera::perspective(eye, Vec3::ZERO, Vec3::Y, 45.0)
                    .unwrap()
                    .with_depth_range(2.0, 100.0)
                    .unwrap(),
            ];
            let (w, h) = [(61, 47), (96, 64), (37, 83)][round % 3];
            for cam in cams {
                for cull_back in [false, true] {
                    let opts = RasterOptions { cull_back };
                    let (depth, cover, ids) = reference(&m, &cam, w, h, &opts);
                    let (map, got_ids) = rasterize_triangle_ids(&m, &cam, w, h, &opts).unwrap();
                    let only = rasterize_depth_with(&m, &cam, w, h, &opts).unwrap();
                    // The plain build too, where the widest is AVX2.
                    let (plain, plain_ids) =
                        rasterize_impl(&m, &cam, w, h, &opts, true, Build::Plain).unwrap();
                    for (k, d) in depth.iter().enumerate() {
                        let at = format!("round {round}, {cam:?}, {opts:?}, pixel {k}");
                        assert_eq!(map.depth[k].to_bits(), d.to_bits(), "{at}");
                        assert_eq!(only.depth[k].to_bits(), d.to_bits(), "{at}");
                        assert_eq!(plain.depth[k].to_bits(), d.to_bits(), "{at}, plain");
                        assert_eq!(map.coverage[k], cover[k], "{at}");
                        assert_eq!(plain.coverage[k], cover[k], "{at}, plain");
                        assert_eq!(got_ids[k], ids[k], "{at}");
                        assert_eq!(plain_ids[k], ids[k], "{at}, plain");
                    }
                    let mut visible = ids.clone();
                    visible.sort_unstable();
                    visible.dedup();
                    assert!(visible.len() > 100, "{} triangles visible", visible.len());
                    // Every path of the binned rasteriser is taken.
                    let proj = Projector::new(&cam, w, h);
                    for ch in setup_binned(&m, &proj, &opts, w, h, Build::Widest).unwrap() {
                        for r in &ch.recs {
                            paths[0] += (r.mask == 0) as usize;
                            paths[1] += (r.mask != 0 && r.rows && r.mask & WIDE == 0) as usize;
                            paths[2] += (r.mask != 0 && r.rows && r.mask & WIDE != 0) as usize;
                            paths[3] += (r.mask != 0 && !r.rows) as usize;
                            paths[4] += (r.mask >= 1 << 32) as usize;
                        }
                    }
                }
            }
        }
        assert!(paths.iter().all(|&n| n > 20), "{paths:?}");
    }

    /// Not a test: `cargo test --release -p imprint-core raster -- --ignored --nocapture`.
    /// Times 512 × 512 depth maps of the bunny (orthographic and perspective) and of a
    /// 50k-triangle sphere seen orthographically from above, as the depth stages do.
    #[test]
    #[ignore]
    fn bunny_depth_map_timing() {
        let path =
            Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets/meshes/stanford-bunny.obj");
        let bunny = Mesh::load_obj(&path).unwrap();
        let b = bunny.bounds();
        let size = b.size().max_element();
        let c = b.center();
        let sphere = uv_sphere(0.5, 160, 157);
        let above = Camera::orthographic(Vec3::new(0.0, 2.0, 0.0), Vec3::ZERO, -Vec3::Z, 0.6)
            .unwrap()
            .with_depth_range(0.0, 3.0)
            .unwrap();
        let cases = [
            (
                "bunny",
                &bunny,
                "orthographic",
                Camera::orthographic(c + Vec3::Z * 2.0 * size, c, Vec3::Y, 0.6 * size).unwrap(),
            ),
            (
                "bunny",
                &bunny,
                "perspective",
                Camera::perspective(c + Vec3::new(0.5, 0.3, 2.0) * size, c, Vec3::Y, 40.0).unwrap(),
            ),
            ("sphere", &sphere, "orthographic from above", above),
        ];
        for (mesh_name, m, name, cam) in cases {
            let mut times = Vec::new();
            let mut covered = 0;
            for _ in 0..31 {
                let t = std::time::Instant::now();
                let map = rasterize_depth(m, &cam, 512, 512).unwrap();
                times.push(t.elapsed().as_secs_f64() * 1e3);
                covered = map.covered_count();
            }
            times.sort_by(|a, b| a.partial_cmp(b).unwrap());
            println!(
                "{mesh_name} {} triangles, 512x512 {name}: median {:.2} ms (min {:.2}), {covered} pixels covered, {} threads, loadavg {}",
                m.triangles.len(),
                times[times.len() / 2],
                times[0],
                rayon::current_num_threads(),
                std::fs::read_to_string("/proc/loadavg")
                    .unwrap_or_default()
                    .trim()
            );
        }
    }
}
