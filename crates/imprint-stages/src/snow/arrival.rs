//! Where snow arrives (T §(1)): snow is found like a shadow. For each of the K fall
//! directions the whole scene is rendered into an orthographic depth map looking along the
//! fall (a shadow map); a point is reached from that direction when it is the first surface
//! the map sees there. The arrival probability of a point is the fraction of the directions
//! that reach it.
//!
//! **Receivers** are the points snow is counted at: every mesh vertex, then every cell centre
//! of the ground (the surface ground + snow), each with its normal ([`gather`]). The same
//! surfaces are the occluders: one mesh made of the meshes and the ground's lattice mesh
//! ([`HeightField::to_mesh`]), rasterised by `imprint_core::raster` (or any rasteriser with its
//! signature: the GPU one, through [`arrival_with`]).
//!
//! **The test for one point and one direction d:**
//! - the point must face the fall: c = n · (−d) > 0 (snow does not land on the back of a
//!   surface, nor on an open sheet's underside);
//! - its depth along d must be at most the map's depth at the texel its projection falls in
//!   (nearest texel, as a shadow map) plus a bias, `texel × (bias_texels + min(tan β, 8))`
//!   with cos β = c. The slope term: the texel centre lies up to √2/2 texel from the point in
//!   the image plane, where the surface's depth changes by up to (√2/2) texel · tan β; a full
//!   texel per unit of tan β covers that and the rasteriser's interpolation. The constant
//!   term (default one texel) covers points at creases, where the texel's surface is a
//!   neighbouring face. Clamping tan β at 8 (β ≈ 83°) keeps grazing points from seeing
//!   through occluders; they get almost no snow anyway (the deposit has the factor cos φ).
//! - an uncovered texel means nothing is in the way.
//!
//! Points are reached or not as whole integers per direction, summed in a u32 per receiver:
//! the result is the same on any number of threads.

use super::params::SnowParams;
use glam::Vec3;
use imprint_core::camera::Frame;
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{Aabb, Camera, HeightField, Mesh, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::f64::consts::TAU;

/// The slope term of the depth bias stops growing here (tan β = 8, β ≈ 83°).
pub const MAX_BIAS_SLOPE: f32 = 8.0;

/// The fall directions, unit vectors pointing the way snow moves.
///
/// With `jitter_degrees` = α > 0 they are K directions on the cone of half-angle α around
/// `direction`, evenly spaced in azimuth: direction i is `normalize(d + tan α (cos ψᵢ e₁ +
/// sin ψᵢ e₂))` with ψᵢ = 2π (i + r) / K, e₁, e₂ a fixed orthonormal pair perpendicular to
/// d, and r ∈ [0, 1) a hash of `seed` (the whole ring turns with the seed). Seen from a
/// point, the sky patches snow comes from form a ring: a steady wind of fixed strength from a
/// direction that changes evenly around the compass.
///
/// Why a ring and not a filled disc: any half-plane of the ring's azimuths holds the expected
/// fraction of the K evenly spaced directions to within 1/K (an arc of length L holds ⌊KL/2π⌋
/// or ⌈KL/2π⌉ of them), so coverage beside a straight edge is within 1/K of its expectation.
/// A low-discrepancy spiral filling the disc measured up to 2.3/K off for K = 16.
///
/// With α = 0 every direction is `direction`, so one direction is returned (one depth map
/// stands for all K).
pub fn fall_directions(params: &SnowParams) -> Vec<Vec3> {
    let d = params.fall().as_dvec3().normalize();
    if params.jitter_degrees == 0.0 {
        return vec![d.as_vec3()];
    }
    let (e1, e2) = d.any_orthonormal_pair();
    let t = (params.jitter_degrees as f64).to_radians().tan();
    let r = unit_from_seed(params.seed);
    let k = params.directions as f64;
    (0..params.directions)
        .map(|i| {
            let psi = TAU * (i as f64 + r) / k;
            (d + t * (psi.cos() * e1 + psi.sin() * e2))
                .normalize()
                .as_vec3()
        })
        .collect()
}

/// A number in [0, 1) from a seed (SplitMix64's finaliser): no global RNG, same on every
/// machine.
fn unit_from_seed(seed: u64) -> f64 {
    let mut z = seed.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// The points snow is counted at, with their unit normals: the vertices of each mesh in turn,
/// then the ground's cell centres (x fastest).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Receivers {
    pub points: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    /// Receivers of mesh m are `mesh_starts[m]..mesh_starts[m + 1]`; the ground's start at
    /// the last entry.
    pub mesh_starts: Vec<usize>,
}

impl Receivers {
    /// The receivers of mesh `m`.
    pub fn mesh(&self, m: usize) -> std::ops::Range<usize> {
        self.mesh_starts[m]..self.mesh_starts[m + 1]
    }

    /// The receivers of the ground (empty without one).
    pub fn ground(&self) -> std::ops::Range<usize> {
        *self.mesh_starts.last().unwrap_or(&0)..self.points.len()
    }
}

/// A mesh's vertex normals: its own when it has one per vertex, else computed.
pub fn vertex_normals(mesh: &Mesh) -> Cow<'_, [Vec3]> {
    if mesh.normals.len() == mesh.positions.len() {
        Cow::Borrowed(&mesh.normals)
    } else {
        let mut m = mesh.clone();
        m.compute_normals();
        Cow::Owned(m.normals)
    }
}

/// The scene as one occluder mesh (the meshes, then the ground's lattice) and its receivers.
pub fn gather(meshes: &[&Mesh], ground: Option<&HeightField>) -> (Mesh, Receivers) {
    let mut occluder = Mesh::default();
    let mut rec = Receivers::default();
    for mesh in meshes {
        rec.mesh_starts.push(rec.points.len());
        rec.points.extend_from_slice(&mesh.positions);
        rec.normals.extend_from_slice(&vertex_normals(mesh));
        occluder.append(mesh);
    }
    rec.mesh_starts.push(rec.points.len());
    if let Some(g) = ground {
        let lattice = g.to_mesh();
        rec.points.extend_from_slice(&lattice.positions);
        rec.normals.extend_from_slice(&lattice.normals);
        occluder.append(&lattice);
    }
    (occluder, rec)
}

/// How many of the directions reach each receiver.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Arrival {
    /// Per receiver (the order of [`Receivers`]).
    pub counts: Vec<u32>,
    /// The number of directions rendered.
    pub directions: u32,
}

impl Arrival {
    /// The arrival probability of receiver `i`: the fraction of the directions reaching it.
    pub fn probability(&self, i: usize) -> f32 {
        self.counts[i] as f32 / self.directions as f32
    }
}

/// The orthographic camera looking along `dir` whose square `resolution`² image holds the
/// whole of `bounds` with a texel to spare on each side, and whose depth range holds it too.
pub fn snow_camera(bounds: &Aabb, dir: Vec3, resolution: u32) -> Result<Camera> {
    let c = bounds.center();
    let r = (0.5 * bounds.size().length()).max(1e-6);
    let up = if dir.z.abs() < 0.9 {
        Vec3::NEG_Z
    } else {
        Vec3::Y
    };
    let margin = 0.01 * r;
    let eye = c - dir * (r + margin);
    let frame = Camera::orthographic(eye, eye + dir, up, 1.0)?.frame();
    let mut half = 0f32;
    for m in 0..8 {
        let pick = |bit: u32, lo: f32, hi: f32| if m & bit == 0 { lo } else { hi };
        let corner = Vec3::new(
            pick(1, bounds.min.x, bounds.max.x),
            pick(2, bounds.min.y, bounds.max.y),
            pick(4, bounds.min.z, bounds.max.z),
        );
        let v = frame.to_view(corner);
        half = half.max(v.x.abs()).max(v.y.abs());
    }
    let half = half.max(1e-6 * r) * (1.0 + 2.0 / resolution as f32);
    Camera::orthographic(eye, eye + dir, up, half)?.with_depth_range(0.0, 2.0 * (r + margin))
}

/// A depth map's projection, set up once for many points (the rasteriser's pixel convention,
/// `DepthMap::pixel_of`, for a square orthographic map).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Lookup {
    pub(crate) frame: Frame,
    /// Pixels per world unit.
    pub(crate) k: f32,
    /// Half the image side, pixels.
    pub(crate) centre: f32,
    pub(crate) res: u32,
    pub(crate) texel: f32,
}

impl Lookup {
    pub(crate) fn new(map: &DepthMap) -> Self {
        Self::for_camera(&map.camera, map.height)
    }

    /// The projection of a square `res`² map rendered with `camera`.
    pub(crate) fn for_camera(camera: &Camera, res: u32) -> Self {
        let k = res as f32 / (2.0 * camera.half_height_scale());
        Lookup {
            frame: camera.frame(),
            k,
            centre: 0.5 * res as f32,
            res,
            texel: 1.0 / k,
        }
    }

    /// Pixel coordinates (x right, y down) and view depth of a world point.
    #[inline]
    pub(crate) fn project(&self, p: Vec3) -> (f32, f32, f32) {
        let v = self.frame.to_view(p);
        (self.centre + v.x * self.k, self.centre - v.y * self.k, v.z)
    }
}

/// Whether the point `p` with unit normal `n` is reached along `dir` (see the module doc).
#[inline]
fn reaches(map: &DepthMap, look: &Lookup, p: Vec3, n: Vec3, dir: Vec3, bias_texels: f32) -> bool {
    let c = -n.dot(dir);
    if c.is_nan() || c <= 0.0 {
        return false;
    }
    let (px, py, depth) = look.project(p);
    let last = look.res as f32 - 1.0;
    let i = px.floor().clamp(0.0, last) as u32;
    let j = py.floor().clamp(0.0, last) as u32;
    match map.get(i, j) {
        None => true,
        Some(seen) => {
            let tan = ((1.0 - c * c).max(0.0).sqrt() / c).min(MAX_BIAS_SLOPE);
            depth <= seen + look.texel * (bias_texels + tan)
        }
    }
}

/// The arrival counts on the CPU (`imprint_core::raster`).
pub fn arrival_cpu(
    occluder: &Mesh,
    receivers: &Receivers,
    directions: &[Vec3],
    params: &SnowParams,
) -> Result<Arrival> {
    arrival_with(
        occluder,
        receivers,
        directions,
        params,
        rasterize_depth_with,
    )
}

/// The arrival counts through any rasteriser with the signature of
/// `imprint_core::raster::rasterize_depth_with`: one `resolution`² map per direction.
pub fn arrival_with(
    occluder: &Mesh,
    receivers: &Receivers,
    directions: &[Vec3],
    params: &SnowParams,
    mut rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
) -> Result<Arrival> {
    let mut counts = vec![0u32; receivers.points.len()];
    let bounds = occluder.bounds();
    if !counts.is_empty() && !bounds.is_empty() {
        let res = params.resolution;
        for &dir in directions {
            let cam = snow_camera(&bounds, dir, res)?;
            let map = rasterize(occluder, &cam, res, res, &RasterOptions::default())?;
            let look = Lookup::new(&map);
            counts
                .par_iter_mut()
                .zip(receivers.points.par_iter().zip(&receivers.normals))
                .with_min_len(1024)
                .for_each(|(count, (&p, &n))| {
                    if reaches(&map, &look, p, n, dir, params.bias_texels) {
                        *count += 1;
                    }
                });
        }
    }
    Ok(Arrival {
        counts,
        directions: directions.len() as u32,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::uv_sphere;
    use imprint_core::raster::rasterize_depth;

    #[test]
    fn directions_lie_on_the_cone_evenly_and_turn_with_the_seed() {
        let mut p = SnowParams {
            directions: 12,
            jitter_degrees: 20.0,
            ..Default::default()
        };
        let dirs = fall_directions(&p);
        assert_eq!(dirs.len(), 12);
        let mut mean = Vec3::ZERO;
        for d in &dirs {
            assert!((d.length() - 1.0).abs() < 1e-6);
            let angle = d.dot(Vec3::NEG_Y).acos().to_degrees();
            assert!((angle - 20.0).abs() < 1e-3, "{angle}");
            mean += *d;
        }
        // Evenly spread in azimuth: the horizontal parts cancel.
        assert!(Vec3::new(mean.x, 0.0, mean.z).length() < 1e-5, "{mean}");
        p.seed = 1;
        assert_ne!(fall_directions(&p), dirs);
        assert_eq!(fall_directions(&p), fall_directions(&p));
        p.jitter_degrees = 0.0;
        assert_eq!(fall_directions(&p), vec![Vec3::NEG_Y]);
    }

    /// The hand-written projection agrees with the rasteriser's `pixel_of`, and the camera
    /// sees every vertex of the scene inside its image.
    #[test]
    fn lookup_matches_pixel_of_and_the_camera_frames_the_scene() {
        let mesh = uv_sphere(0.7, 24, 12);
        for dir in [
            Vec3::NEG_Y,
            Vec3::new(0.3, -1.0, 0.2).normalize(),
            Vec3::NEG_Z,
        ] {
            let cam = snow_camera(&mesh.bounds(), dir, 64).unwrap();
            let map = rasterize_depth(&mesh, &cam, 64, 64).unwrap();
            let look = Lookup::new(&map);
            for &p in &mesh.positions {
                let (x, y, z) = look.project(p);
                let (x2, y2, z2) = map.pixel_of(p).unwrap();
                assert!((x - x2).abs() < 1e-3 && (y - y2).abs() < 1e-3 && (z - z2).abs() < 1e-5);
                assert!(
                    x > 0.5 && x < 63.5 && y > 0.5 && y < 63.5 && z > 0.0,
                    "{x} {y}"
                );
            }
        }
    }

    /// A closed sphere: the upper half is reached from above, the lower half is not (it faces
    /// away), and nothing is reached from a direction it faces away from.
    #[test]
    fn a_sphere_is_reached_on_top_only() {
        let mesh = uv_sphere(1.0, 48, 24);
        let (occ, rec) = gather(&[&mesh], None);
        let p = SnowParams {
            jitter_degrees: 0.0,
            resolution: 128,
            ..Default::default()
        };
        let a = arrival_cpu(&occ, &rec, &fall_directions(&p), &p).unwrap();
        assert_eq!(a.directions, 1);
        for (i, pt) in rec.points.iter().enumerate() {
            if pt.y > 0.05 {
                assert_eq!(a.counts[i], 1, "{pt}");
            } else if pt.y < -0.05 {
                assert_eq!(a.counts[i], 0, "{pt}");
            }
        }
    }
}
