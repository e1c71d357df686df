//! The CPU frame renderer: a [`Scene`] of coloured meshes and distance-field slices
//! ([`Object::FieldSlice`], a colour-mapped quad at the slice plane), one sun plus ambient
//! light, a ground grid and optional wireframe overlays, rendered to an `RgbImage` through the CPU rasteriser
//! of `imprint_core::raster`.
//!
//! Pipeline of [`render_cpu`]:
//! 1. every object is merged into one mesh, remembering which object each triangle came from;
//! 2. the merged mesh is rasterised once at `width * samples` × `height * samples`
//!    ([`rasterize_triangle_ids`]): the nearest surface wins per sample, whatever the object
//!    order (on an exact depth tie the earlier object wins, as the rasteriser documents);
//! 3. each covered sample is shaded in linear space with Lambert's law on the interpolated
//!    vertex normal, flipped towards the camera (two-sided), `color * (ambient + sun * max(0,
//!    n·l))`, clamped to 1; uncovered samples take the background;
//! 4. the ground grid (lines on y = 0) and the wireframe edges are drawn into the sample
//!    buffer as lines about one output pixel wide, **depth-tested** against the depth map with a
//!    small relative bias (so hidden edges and grid lines behind objects are not drawn);
//! 5. the sample buffer is box-filtered `samples × samples` in linear space (the CPU
//!    anti-aliasing) and sRGB-encoded to `u8`.
//!
//! Every step is deterministic: the same scene gives the same bytes on any machine with the
//! same float behaviour and any number of threads.
//!
//! A new resource kind (cloth, heightfield) only needs an adapter that produces a [`Mesh`]
//! (with normals) and a colour: `Object::mesh(Arc::new(adapter_output), color)`.

use crate::colormap::Colormap;
use crate::field_io::check_field;
use crate::slice::{Axis, FAR_GREY, SliceIndex};
use glam::{UVec3, Vec3};
use image::{Rgb, RgbImage};
use imprint_core::camera::Camera;
use imprint_core::geom::barycentric;
use imprint_core::raster::{DepthMap, MAX_SIZE, RasterOptions, rasterize_triangle_ids};
use imprint_core::{DistanceField, Error, Mesh, Result};
use std::sync::Arc;

/// One directional light (the sun) plus ambient light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lights {
    /// Direction **towards** the light (need not be normalised; must not be zero).
    pub sun_direction: Vec3,
    /// Intensity of the sun term.
    pub sun: f32,
    /// Intensity of the ambient term.
    pub ambient: f32,
}

impl Default for Lights {
    fn default() -> Self {
        Lights {
            sun_direction: Vec3::new(0.4, 1.0, 0.6),
            sun: 0.8,
            ambient: 0.2,
        }
    }
}

/// Lines on the plane y = 0, every `spacing` units, over `[-half_extent, half_extent]²`
/// around the origin, for orientation. Depth-tested against the objects.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GroundGrid {
    pub spacing: f32,
    pub half_extent: f32,
    /// sRGB colour of the lines.
    pub color: [u8; 3],
}

impl Default for GroundGrid {
    fn default() -> Self {
        GroundGrid {
            spacing: 0.5,
            half_extent: 5.0,
            color: [110, 110, 110],
        }
    }
}

/// Something the renderer draws.
#[derive(Clone, Debug)]
pub enum Object {
    /// A triangle mesh (its per-vertex normals are used for shading) with a linear RGB colour
    /// in 0..1; `wireframe` overlays its triangle edges as thin dark lines.
    Mesh {
        mesh: Arc<Mesh>,
        color: [f32; 3],
        wireframe: bool,
    },
    /// One grid plane of a distance field, drawn as a quad in the world at the plane's cell
    /// centres (spanning the cells' full extent), each cell one flat colour: the distance in
    /// cells through `colormap` (0 at the surface, `band` at the band's edge, as in
    /// [`crate::slice`]), far cells opaque grey ([`FAR_GREY`]). Unlit: the colours are data.
    FieldSlice {
        field: Arc<DistanceField>,
        axis: Axis,
        index: SliceIndex,
        colormap: Colormap,
    },
}

/// How one object's samples are coloured.
enum Shader {
    Lambert(Vec3),
    Slice {
        field: Arc<DistanceField>,
        axis: Axis,
        index: u32,
        colormap: Colormap,
    },
}

/// The world quad of a field slice (two triangles, normal along the axis).
pub(crate) fn slice_quad(field: &DistanceField, axis: Axis, index: u32) -> Mesh {
    let spec = &field.spec;
    let (u, v) = axis.plane_axes();
    let (du, dv) = (u.dim(), v.dim());
    let mut lo = spec.origin - Vec3::splat(0.5 * spec.cell);
    lo[axis.dim()] = spec.origin[axis.dim()] + index as f32 * spec.cell;
    let mut eu = Vec3::ZERO;
    eu[du] = spec.dims[du] as f32 * spec.cell;
    let mut ev = Vec3::ZERO;
    ev[dv] = spec.dims[dv] as f32 * spec.cell;
    Mesh::new(
        vec![lo, lo + eu, lo + eu + ev, lo + ev],
        vec![[0, 1, 2], [0, 2, 3]],
        "field slice",
    )
    .expect("a slice quad of a valid grid is a valid mesh")
}

impl Object {
    /// A solid mesh object with a linear RGB colour (0..1).
    pub fn mesh(mesh: impl Into<Arc<Mesh>>, color: [f32; 3]) -> Self {
        Object::Mesh {
            mesh: mesh.into(),
            color,
            wireframe: false,
        }
    }

    /// The same object with the wireframe overlay switched on or off.
    pub fn with_wireframe(self, on: bool) -> Self {
        match self {
            Object::Mesh { mesh, color, .. } => Object::Mesh {
                mesh,
                color,
                wireframe: on,
            },
            other => other,
        }
    }
}

/// Everything in a frame.
#[derive(Clone, Debug)]
pub struct Scene {
    pub objects: Vec<Object>,
    pub lights: Lights,
    /// sRGB background colour.
    pub background: [u8; 3],
    pub ground_grid: Option<GroundGrid>,
}

impl Default for Scene {
    fn default() -> Self {
        Scene {
            objects: Vec::new(),
            lights: Lights::default(),
            background: [235, 238, 242],
            ground_grid: None,
        }
    }
}

/// Image size, anti-aliasing and camera of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RenderOptions {
    pub width: u32,
    pub height: u32,
    /// Supersampling factor per axis, 1..=4 (`samples²` shaded samples per pixel).
    pub samples: u32,
    pub camera: Camera,
}

impl RenderOptions {
    /// Checks the sizes and the sampling factor; errors name the field.
    pub fn validate(&self) -> Result<()> {
        for (name, v) in [("width", self.width), ("height", self.height)] {
            if v == 0 || v > MAX_SIZE {
                return Err(Error::Invalid(format!(
                    "render: {name} must be in 1..={MAX_SIZE}, got {v}"
                )));
            }
        }
        if !(1..=4).contains(&self.samples) {
            return Err(Error::Invalid(format!(
                "render: samples must be in 1..=4, got {}",
                self.samples
            )));
        }
        for (name, v) in [("width", self.width), ("height", self.height)] {
            if v as u64 * self.samples as u64 > MAX_SIZE as u64 {
                return Err(Error::Invalid(format!(
                    "render: {name} * samples = {} exceeds {MAX_SIZE}; lower {name} or samples",
                    v as u64 * self.samples as u64
                )));
            }
        }
        self.camera.validate()
    }
}

/// A perspective camera orbiting `target`: `distance` away, `elevation_deg` above the x-z
/// plane, `azimuth_deg` around +y measured from +z towards +x; up is +y, vertical field of
/// view `fov_y_degrees`. Errors on a non-positive distance or an elevation of ±90°.
pub fn orbit(
    target: Vec3,
    distance: f32,
    elevation_deg: f32,
    azimuth_deg: f32,
    fov_y_degrees: f32,
) -> Result<Camera> {
    if !(distance.is_finite() && distance > 0.0) {
        return Err(Error::Invalid(format!(
            "orbit: distance must be finite and > 0, got {distance}"
        )));
    }
    let (el, az) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    let dir = Vec3::new(el.cos() * az.sin(), el.sin(), el.cos() * az.cos());
    Camera::perspective(target + dir * distance, target, Vec3::Y, fov_y_degrees)
}

/// sRGB `u8` → linear.
pub fn srgb_to_linear(c: u8) -> f32 {
    let c = c as f32 / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear (clamped to 0..1) → sRGB `u8`, rounded to nearest.
pub fn linear_to_srgb(l: f32) -> u8 {
    let l = if l.is_nan() { 0.0 } else { l.clamp(0.0, 1.0) };
    let c = if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    (c * 255.0 + 0.5).floor().clamp(0.0, 255.0) as u8
}

/// Colour of wireframe lines (linear).
pub(crate) const WIRE_COLOR: Vec3 = Vec3::new(0.015, 0.015, 0.02);
/// Relative depth bias of the line depth test.
pub(crate) const LINE_BIAS_REL: f32 = 2.0e-3;

/// An sRGB colour → linear.
pub(crate) fn srgb3_to_linear(c: [u8; 3]) -> Vec3 {
    Vec3::new(
        srgb_to_linear(c[0]),
        srgb_to_linear(c[1]),
        srgb_to_linear(c[2]),
    )
}

/// The unit direction towards the sun; errors on a zero or non-finite direction.
pub(crate) fn sun_direction(lights: &Lights) -> Result<Vec3> {
    let d = lights.sun_direction;
    if !(d.is_finite() && d.length_squared() > 0.0) {
        return Err(Error::Invalid(format!(
            "render: lights.sun_direction must be finite and non-zero, got {d}"
        )));
    }
    Ok(d.normalize())
}

/// The mesh's per-vertex normals, computed when it has none.
pub(crate) fn vertex_normals(mesh: &Mesh) -> std::borrow::Cow<'_, [Vec3]> {
    if mesh.normals.len() == mesh.positions.len() {
        std::borrow::Cow::Borrowed(&mesh.normals)
    } else {
        let mut m = mesh.clone();
        m.compute_normals();
        std::borrow::Cow::Owned(m.normals)
    }
}

/// The ground grid's linear colour and its segments, in drawing order; errors on a spacing
/// that is not finite and positive, or too many lines.
pub(crate) fn grid_segments(g: &GroundGrid) -> Result<(Vec3, Vec<[Vec3; 2]>)> {
    if !(g.spacing.is_finite() && g.spacing > 0.0 && g.half_extent.is_finite()) {
        return Err(Error::Invalid(format!(
            "render: ground_grid.spacing must be finite and > 0 (got {}), half_extent finite (got {})",
            g.spacing, g.half_extent
        )));
    }
    let e = g.half_extent.abs();
    let k = (e / g.spacing).floor() as i64;
    if k > 100_000 {
        return Err(Error::Invalid(format!(
            "render: ground_grid has {} lines per axis; raise spacing",
            2 * k + 1
        )));
    }
    let mut segments = Vec::with_capacity(2 * (2 * k as usize + 1));
    for m in -k..=k {
        let u = m as f32 * g.spacing;
        segments.push([Vec3::new(u, 0.0, -e), Vec3::new(u, 0.0, e)]);
        segments.push([Vec3::new(-e, 0.0, u), Vec3::new(e, 0.0, u)]);
    }
    Ok((srgb3_to_linear(g.color), segments))
}

/// Renders `scene` on the CPU. See the module doc for the pipeline.
pub fn render_cpu(scene: &Scene, opts: &RenderOptions) -> Result<RgbImage> {
    opts.validate()?;
    let light = sun_direction(&scene.lights)?;
    let s = opts.samples;
    let (sw, sh) = (opts.width * s, opts.height * s);
    let cam = &opts.camera;

    // 1. Merge the objects; remember each triangle's object and each object's colour.
    let mut merged = Mesh::default();
    let mut tri_obj: Vec<u32> = Vec::new();
    let mut shaders: Vec<Shader> = Vec::new();
    let mut slice_meshes: Vec<Mesh> = Vec::new();
    for obj in &scene.objects {
        if let Object::FieldSlice {
            field,
            axis,
            index,
            colormap,
        } = obj
        {
            check_field(field)?;
            let index = index.resolve(*axis, field.spec.dims[axis.dim()])?;
            slice_meshes.push(slice_quad(field, *axis, index));
            shaders.push(Shader::Slice {
                field: field.clone(),
                axis: *axis,
                index,
                colormap: *colormap,
            });
        } else if let Object::Mesh { color, .. } = obj {
            shaders.push(Shader::Lambert(Vec3::from_array(*color)));
        }
    }
    let mut slices = slice_meshes.iter();
    for (k, obj) in scene.objects.iter().enumerate() {
        let mesh: &Mesh = match obj {
            Object::Mesh { mesh, .. } => mesh,
            Object::FieldSlice { .. } => slices.next().expect("one quad per slice"),
        };
        let base = merged.positions.len() as u32;
        merged.positions.extend_from_slice(&mesh.positions);
        merged.normals.extend_from_slice(&vertex_normals(mesh));
        merged
            .triangles
            .extend(mesh.triangles.iter().map(|t| t.map(|v| v + base)));
        tri_obj.extend(std::iter::repeat_n(k as u32, mesh.triangles.len()));
    }

    // 2. Rasterise.
    let (map, ids) = if merged.triangles.is_empty() {
        (
            DepthMap::empty(*cam, sw, sh),
            vec![u32::MAX; sw as usize * sh as usize],
        )
    } else {
        rasterize_triangle_ids(&merged, cam, sw, sh, &RasterOptions::default())?
    };

    // 3. Shade.
    let bg = srgb3_to_linear(scene.background);
    let frame = cam.frame();
    let persp = cam.is_perspective();
    let lights = scene.lights;
    let shade = |idx: usize| -> Vec3 {
        let t = ids[idx];
        if t == u32::MAX {
            return bg;
        }
        let (i, j) = ((idx % sw as usize) as u32, (idx / sw as usize) as u32);
        let p = map.unproject(i as f32 + 0.5, j as f32 + 0.5, map.depth[idx]);
        let tri = merged.triangles[t as usize];
        let shader = &shaders[tri_obj[t as usize] as usize];
        if let Shader::Slice {
            field,
            axis,
            index,
            colormap,
        } = shader
        {
            return slice_color(field, *axis, *index, *colormap, p);
        }
        let l = barycentric(p, merged.triangle(t as usize));
        let mut n = (merged.normals[tri[0] as usize] * l[0]
            + merged.normals[tri[1] as usize] * l[1]
            + merged.normals[tri[2] as usize] * l[2])
            .normalize_or_zero();
        if n == Vec3::ZERO {
            // Degenerate normals: fall back to the face normal.
            let [a, b, c] = merged.triangle(t as usize);
            n = (b - a).cross(c - a).normalize_or_zero();
        }
        let to_cam = if persp { frame.eye - p } else { -frame.forward };
        if n.dot(to_cam) < 0.0 {
            n = -n;
        }
        let Shader::Lambert(c) = *shader else {
            unreachable!()
        };
        let k = lights.ambient + lights.sun * n.dot(light).max(0.0);
        (c * k).clamp(Vec3::ZERO, Vec3::ONE)
    };
    let n = sw as usize * sh as usize;
    let mut buf = vec![Vec3::ZERO; n];
    let threads = std::thread::available_parallelism()
        .map(|t| t.get())
        .unwrap_or(1)
        .clamp(1, 16);
    let chunk = n.div_ceil(threads).max(1);
    std::thread::scope(|sc| {
        for (c, out) in buf.chunks_mut(chunk).enumerate() {
            let shade = &shade;
            sc.spawn(move || {
                for (o, v) in out.iter_mut().enumerate() {
                    *v = shade(c * chunk + o);
                }
            });
        }
    });

    // 4. Lines: ground grid, then wireframes (drawn last, on top of the grid).
    let mut lines = LineCanvas {
        map: &map,
        buf: &mut buf,
        width: s as i32, // line width in samples ≈ one output pixel
    };
    if let Some(g) = &scene.ground_grid {
        let (color, segments) = grid_segments(g)?;
        for [a, b] in segments {
            lines.segment(a, b, color);
        }
    }
    for obj in &scene.objects {
        if let Object::Mesh {
            mesh,
            wireframe: true,
            ..
        } = obj
        {
            for tri in &mesh.triangles {
                for e in 0..3 {
                    let (a, b) = (tri[e], tri[(e + 1) % 3]);
                    // Shared edges are drawn twice with the same colour: idempotent.
                    lines.segment(
                        mesh.positions[a as usize],
                        mesh.positions[b as usize],
                        WIRE_COLOR,
                    );
                }
            }
        }
    }

    // 5. Box-downsample and encode.
    let mut img = RgbImage::new(opts.width, opts.height);
    let inv = 1.0 / (s * s) as f32;
    for y in 0..opts.height {
        for x in 0..opts.width {
            let mut acc = Vec3::ZERO;
            for dy in 0..s {
                let row = (y * s + dy) as usize * sw as usize;
                for dx in 0..s {
                    acc += buf[row + (x * s + dx) as usize];
                }
            }
            let c = acc * inv;
            img.put_pixel(
                x,
                y,
                Rgb([
                    linear_to_srgb(c.x),
                    linear_to_srgb(c.y),
                    linear_to_srgb(c.z),
                ]),
            );
        }
    }
    Ok(img)
}

/// The linear colour of the slice cell containing world point `p` (on the slice plane).
fn slice_color(field: &DistanceField, axis: Axis, index: u32, colormap: Colormap, p: Vec3) -> Vec3 {
    let c = field.spec.to_cell(p).round();
    let mut cell = UVec3::ZERO;
    for d in 0..3 {
        let n = field.spec.dims[d];
        cell[d] = (c[d].max(0.0) as u32).min(n - 1);
    }
    cell[axis.dim()] = index;
    cell_color(field, cell, colormap)
}

/// The linear colour of one cell of a drawn field slice: its distance in cells through
/// `colormap` (0 at the surface, `band` at the band's edge), far cells grey.
pub(crate) fn cell_color(field: &DistanceField, cell: UVec3, colormap: Colormap) -> Vec3 {
    let i = field.spec.index(cell);
    let rgb = if field.is_far(i) {
        FAR_GREY.0
    } else {
        colormap.sample(field.dist[i] / field.spec.cell / field.band)
    };
    srgb3_to_linear(rgb)
}

/// Depth-tested line drawing into the linear sample buffer.
struct LineCanvas<'a> {
    map: &'a DepthMap,
    buf: &'a mut [Vec3],
    /// Line width in samples.
    width: i32,
}

impl LineCanvas<'_> {
    /// Draws the world segment `a`–`b`: clipped to the near plane (perspective) and to the
    /// image, walked one sample at a time, each stamp depth-tested with a small bias.
    fn segment(&mut self, a: Vec3, b: Vec3, color: Vec3) {
        let cam = &self.map.camera;
        let fr = cam.frame();
        let (mut a, mut b) = (a, b);
        let near = cam
            .near
            .max(if cam.is_perspective() { 1e-4 } else { f32::MIN });
        if cam.is_perspective() {
            let (za, zb) = (fr.to_view(a).z, fr.to_view(b).z);
            if za < near && zb < near {
                return;
            }
            if za < near {
                a = a + (b - a) * ((near - za) / (zb - za));
            } else if zb < near {
                b = b + (a - b) * ((near - zb) / (za - zb));
            }
        }
        let (Some((ax, ay, az)), Some((bx, by, bz))) = (self.map.pixel_of(a), self.map.pixel_of(b))
        else {
            return;
        };
        let persp = cam.is_perspective();
        // Interpolated depth quantity: linear in screen space (1/depth for perspective).
        let (qa, qb) = if persp {
            (1.0 / az, 1.0 / bz)
        } else {
            (az, bz)
        };
        // Liang–Barsky clip of the screen segment to the image plus a margin.
        let (w, h) = (self.map.width as f32, self.map.height as f32);
        let m = self.width as f32 + 1.0;
        let (dx, dy) = (bx - ax, by - ay);
        let (mut t0, mut t1) = (0.0f32, 1.0f32);
        for (p, q) in [
            (-dx, ax + m),
            (dx, w + m - ax),
            (-dy, ay + m),
            (dy, h + m - ay),
        ] {
            if p == 0.0 {
                if q < 0.0 {
                    return;
                }
            } else {
                let r = q / p;
                if p < 0.0 {
                    t0 = t0.max(r);
                } else {
                    t1 = t1.min(r);
                }
            }
        }
        // Empty, or NaN from a degenerate segment.
        if !matches!(
            t0.partial_cmp(&t1),
            Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)
        ) {
            return;
        }
        let len = ((t1 - t0) * dx.abs().max(dy.abs())).ceil().max(1.0) as u32;
        let half = self.width / 2;
        for k in 0..=len {
            let t = t0 + (t1 - t0) * (k as f32 / len as f32);
            let (px, py) = (ax + dx * t, ay + dy * t);
            let q = qa + (qb - qa) * t;
            let depth = if persp { 1.0 / q } else { q };
            let (cx, cy) = (px.floor() as i32, py.floor() as i32);
            for oy in -half..self.width - half {
                for ox in -half..self.width - half {
                    let (i, j) = (cx + ox, cy + oy);
                    if i < 0 || j < 0 || i >= self.map.width as i32 || j >= self.map.height as i32 {
                        continue;
                    }
                    let idx = self.map.index(i as u32, j as u32);
                    let zd = self.map.depth[idx];
                    if depth <= zd + LINE_BIAS_REL * zd.abs() + 1e-5 {
                        self.buf[idx] = color;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::glam::Mat4;
    use imprint_core::mesh::primitives::{cuboid, plane};

    fn srgb3(c: Vec3) -> [u8; 3] {
        [
            linear_to_srgb(c.x),
            linear_to_srgb(c.y),
            linear_to_srgb(c.z),
        ]
    }

    fn close(a: [u8; 3], b: [u8; 3]) -> bool {
        a.iter()
            .zip(b)
            .all(|(x, y)| (*x as i32 - y as i32).abs() <= 1)
    }

    fn ortho_front(half_height: f32) -> Camera {
        Camera::orthographic(Vec3::Z * 5.0, Vec3::ZERO, Vec3::Y, half_height).unwrap()
    }

    fn scene(objects: Vec<Object>, sun_direction: Vec3) -> Scene {
        Scene {
            objects,
            lights: Lights {
                sun_direction,
                sun: 0.7,
                ambient: 0.2,
            },
            background: [20, 40, 60],
            ground_grid: None,
        }
    }

    fn opts(w: u32, h: u32, samples: u32, camera: Camera) -> RenderOptions {
        RenderOptions {
            width: w,
            height: h,
            samples,
            camera,
        }
    }

    #[test]
    fn srgb_round_trips_every_level() {
        for c in 0..=255u8 {
            assert_eq!(linear_to_srgb(srgb_to_linear(c)), c);
        }
    }

    #[test]
    fn cube_lit_from_the_camera_has_the_exact_lambert_colour() {
        let color = [0.8, 0.5, 0.2];
        let sc = scene(
            vec![Object::mesh(cuboid(Vec3::splat(0.5), 2), color)],
            Vec3::Z,
        );
        let img = render_cpu(&sc, &opts(64, 48, 1, ortho_front(1.0))).unwrap();
        let want = srgb3(Vec3::from_array(color) * (0.2 + 0.7));
        let got = img.get_pixel(32, 24).0;
        assert!(close(got, want), "{got:?} vs {want:?}");
        // 24 px per unit: the cube covers pixels x in [20, 44), y in [12, 36).
        for (x, y) in [(0, 0), (63, 47), (10, 24), (53, 24), (32, 5), (32, 42)] {
            assert_eq!(img.get_pixel(x, y).0, sc.background, "({x}, {y})");
        }
        // Inside everywhere else: the same colour.
        for (x, y) in [(20, 12), (43, 35), (25, 30)] {
            assert!(close(img.get_pixel(x, y).0, want));
        }
    }

    #[test]
    fn face_tilted_60_degrees_gets_half_the_sun() {
        let color = [0.6, 0.6, 0.9];
        let mut p = plane(2.0, 2);
        // Normal +y rotated by 60° about x: (0, cos 60°, sin 60°) · (0, 1, 0) = 0.5.
        p.transform(Mat4::from_rotation_x(60f32.to_radians()));
        let sc = scene(vec![Object::mesh(p, color)], Vec3::Y);
        let cam = Camera::orthographic(Vec3::Y * 5.0, Vec3::ZERO, Vec3::Z, 1.0).unwrap();
        let img = render_cpu(&sc, &opts(32, 32, 2, cam)).unwrap();
        let want = srgb3(Vec3::from_array(color) * (0.2 + 0.7 * 0.5));
        let got = img.get_pixel(16, 16).0;
        assert!(close(got, want), "{got:?} vs {want:?}");
        // And lit from behind (sun below): only ambient, the normal flips towards the camera.
        let sc = scene(
            vec![Object::mesh(
                {
                    let mut p = plane(2.0, 2);
                    p.transform(Mat4::from_rotation_x(60f32.to_radians()));
                    p
                },
                color,
            )],
            -Vec3::Y,
        );
        let img = render_cpu(&sc, &opts(32, 32, 1, cam)).unwrap();
        let want = srgb3(Vec3::from_array(color) * 0.2);
        assert!(close(img.get_pixel(16, 16).0, want));
    }

    #[test]
    fn supersampling_blends_only_edge_pixels() {
        let color = [0.9, 0.9, 0.9];
        // 16 px per unit: the cube's right edge x = 0.5 falls on pixel boundary 40; shifted by
        // 0.3 px it covers 0.3 of pixel 40 (1/2 of the samples at s = 2, 1/4 at s = 4; the
        // same 0.3 px shift in y makes the top and bottom rows partial too).
        let mut c = cuboid(Vec3::splat(0.5), 1);
        c.transform(Mat4::from_translation(Vec3::new(
            0.3 / 16.0,
            0.3 / 16.0,
            0.0,
        )));
        let c = Arc::new(c);
        let sc = scene(vec![Object::mesh(c.clone(), color)], Vec3::Z);
        let cam = ortho_front(1.5);
        let img = |s| render_cpu(&sc, &opts(64, 48, s, cam)).unwrap();
        let (i1, i2, i4) = (img(1), img(2), img(4));
        let obj = srgb3(Vec3::from_array(color) * 0.9);
        let bg = sc.background;
        let p1 = i1.get_pixel(40, 24).0;
        assert!(p1 == bg || close(p1, obj), "samples 1: {p1:?}");
        let p4 = i4.get_pixel(40, 24).0;
        for k in 0..3 {
            let (lo, hi) = (bg[k].min(obj[k]), bg[k].max(obj[k]));
            assert!(p4[k] > lo + 5 && p4[k] + 5 < hi, "samples 4: {p4:?}");
        }
        // Wherever samples 2 and 4 differ, the samples-1 image is not uniform around the pixel.
        let mut diffs = 0;
        for y in 0..48u32 {
            for x in 0..64u32 {
                if i2.get_pixel(x, y) != i4.get_pixel(x, y) {
                    diffs += 1;
                    let c0 = i1.get_pixel(x, y);
                    let edge = (y.saturating_sub(1)..=(y + 1).min(47)).any(|yy| {
                        (x.saturating_sub(1)..=(x + 1).min(63)).any(|xx| i1.get_pixel(xx, yy) != c0)
                    });
                    assert!(edge, "({x}, {y}) differs but is not an edge pixel");
                }
            }
        }
        assert!(diffs > 0);
    }

    #[test]
    fn nearer_object_wins_regardless_of_order_and_bytes_repeat() {
        let mut near = cuboid(Vec3::splat(0.5), 1);
        near.transform(Mat4::from_translation(Vec3::new(0.3, 0.0, 1.0)));
        let far = cuboid(Vec3::splat(0.5), 1);
        let red = [0.9, 0.1, 0.1];
        let blue = [0.1, 0.1, 0.9];
        let (near, far) = (Arc::new(near), Arc::new(far));
        let a = scene(
            vec![
                Object::mesh(near.clone(), red),
                Object::mesh(far.clone(), blue),
            ],
            Vec3::Z,
        );
        let b = scene(
            vec![Object::mesh(far, blue), Object::mesh(near, red)],
            Vec3::Z,
        );
        let o = opts(64, 48, 2, ortho_front(1.0));
        let ia = render_cpu(&a, &o).unwrap();
        let ib = render_cpu(&b, &o).unwrap();
        assert_eq!(ia, ib);
        assert_eq!(ia, render_cpu(&a, &o).unwrap());
        let red_px = srgb3(Vec3::from_array(red) * 0.9);
        let blue_px = srgb3(Vec3::from_array(blue) * 0.9);
        // 24 px per unit. Overlap (x in [-0.2, 0.5]): red. Only far (x in [-0.5, -0.2)): blue.
        assert!(close(ia.get_pixel(34, 24).0, red_px));
        assert!(close(ia.get_pixel(23, 24).0, blue_px));
    }

    #[test]
    fn wireframe_and_grid_are_depth_tested() {
        let mut c = cuboid(Vec3::splat(0.5), 1);
        c.transform(Mat4::from_translation(Vec3::Y * 0.5));
        let mut sc = scene(
            vec![Object::mesh(c, [0.8, 0.8, 0.8]).with_wireframe(true)],
            Vec3::Z,
        );
        sc.ground_grid = Some(GroundGrid {
            spacing: 0.25,
            half_extent: 2.0,
            color: [255, 255, 0],
        });
        let cam = orbit(Vec3::Y * 0.5, 4.0, 30.0, 20.0, 40.0).unwrap();
        let img = render_cpu(&sc, &opts(96, 72, 2, cam)).unwrap();
        let plain = {
            let mut s2 = sc.clone();
            s2.objects[0] = s2.objects[0].clone().with_wireframe(false);
            s2.ground_grid = None;
            render_cpu(&s2, &opts(96, 72, 2, cam)).unwrap()
        };
        // Somewhere the wireframe darkens the cube; no grid yellow lands inside the cube
        // silhouette where the cube is in front (pixel at the cube's projected centre).
        let dm = DepthMap::empty(cam, 96, 72);
        let (cx, cy, _) = dm.pixel_of(Vec3::new(0.2, 0.5, 0.2)).unwrap();
        let p = img.get_pixel(cx as u32, cy as u32).0;
        assert!(
            !(p[0] > 200 && p[1] > 200 && p[2] < 100),
            "grid shows through: {p:?}"
        );
        let darker = img
            .pixels()
            .zip(plain.pixels())
            .filter(|(a, b)| a.0[0] + 40 < b.0[0] && a.0[2] + 40 < b.0[2])
            .count();
        assert!(darker > 50, "{darker}");
        let yellow = img
            .pixels()
            .filter(|p| p.0[0] > 150 && p.0[1] > 150 && p.0[2] < 100)
            .count();
        assert!(yellow > 50, "{yellow}");
    }

    #[test]
    fn bad_options_name_the_field() {
        let sc = Scene::default();
        let cam = ortho_front(1.0);
        for (o, field) in [
            (opts(0, 10, 1, cam), "width"),
            (opts(10, 16385, 1, cam), "height"),
            (opts(10, 10, 0, cam), "samples"),
            (opts(10, 10, 5, cam), "samples"),
        ] {
            match render_cpu(&sc, &o) {
                Err(Error::Invalid(m)) => assert!(m.contains(field), "{m}"),
                r => panic!("{r:?}"),
            }
        }
        // An empty scene is the background.
        let img = render_cpu(&sc, &opts(8, 4, 2, cam)).unwrap();
        assert!(img.pixels().all(|p| p.0 == sc.background));
    }

    #[test]
    fn field_slice_is_drawn_at_its_plane_with_the_colormap() {
        use imprint_core::GridSpec;
        // 4 x 4 x 3 cells of 1 unit, cell centres at (-1.5 + a, -1.5 + b, -1 + c); the middle
        // Z plane (c = 1) is z = 0. Distance 0.5 a cells, x = 3 far.
        let spec = GridSpec::new(Vec3::new(-1.5, -1.5, -1.0), 1.0, UVec3::new(4, 4, 3)).unwrap();
        let n = spec.len();
        let mut dist = vec![0.0; n];
        let mut nearest = vec![0u32; n];
        for i in 0..n {
            let c = spec.coords(i);
            dist[i] = 0.5 * c.x as f32;
            if c.x == 3 {
                nearest[i] = DistanceField::FAR;
                dist[i] = 4.0;
            }
        }
        let field = Arc::new(DistanceField {
            spec,
            band: 4.0,
            dist,
            nearest,
            points: Arc::new(vec![Vec3::ZERO]),
            faces: None,
            inside: None,
            cells: Default::default(),
        });
        let obj = Object::FieldSlice {
            field,
            axis: Axis::Z,
            index: SliceIndex::Middle,
            colormap: Colormap::Viridis,
        };
        // A red cube behind the slice plane is hidden; a green one in front hides the slice.
        let mut behind = cuboid(Vec3::splat(0.3), 1);
        behind.transform(Mat4::from_translation(Vec3::new(-1.5, -1.5, -0.8)));
        let mut front = cuboid(Vec3::splat(0.3), 1);
        front.transform(Mat4::from_translation(Vec3::new(1.5, 1.5, 0.8)));
        let sc = scene(
            vec![
                Object::mesh(behind, [1.0, 0.0, 0.0]),
                obj,
                Object::mesh(front, [0.0, 1.0, 0.0]),
            ],
            Vec3::Z,
        );
        // 10 px per unit, image centre = world (0, 0).
        let img = render_cpu(&sc, &opts(40, 40, 1, ortho_front(2.0))).unwrap();
        let px = |a: u32, b: u32| {
            let (x, y) = (-1.5 + a as f32, -1.5 + b as f32);
            img.get_pixel((20.0 + 10.0 * x) as u32, (20.0 - 10.0 * y) as u32)
                .0
        };
        for a in 0..3 {
            let want = Colormap::Viridis.sample(0.5 * a as f32 / 4.0);
            assert!(
                close(px(a, 1), want),
                "cell {a}: {:?} vs {want:?}",
                px(a, 1)
            );
        }
        assert_eq!(px(3, 1), FAR_GREY.0);
        assert!(
            close(px(0, 0), Colormap::Viridis.sample(0.0)),
            "cube behind shows"
        );
        let g = px(3, 3);
        assert!(g[1] > 200 && g[0] < 10, "cube in front hidden: {g:?}");
        // The slice spans the cells' full extent, [-2, 2]^2: the whole image, no background.
        assert!(img.pixels().all(|p| p.0 != sc.background));
    }
}
