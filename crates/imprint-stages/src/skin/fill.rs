//! The adaptive close-packed particle fill (T §(3)①, docs/methods.md §6).
//!
//! **T's method.** Pack the mesh's bounding box with close-packed particles, keep those inside
//! (parity of the surface crossings along x, counted on the y-z projection), remove the ones
//! near the surface and fill again with smaller particles: large particles deep inside, small
//! ones near the surface, so far fewer particles than a uniform fill of the small size for
//! thick bodies (not for plates, where every large particle is near the surface).
//!
//! **Where T is thin, our choices.**
//! - *The lattice.* Face-centred cubic (FCC): a cube of side `a` holds 4 particles (its min
//!   corner and the centres of the three faces meeting there), nearest neighbours `a/√2`
//!   apart, so touching radius `a/(2√2)`. FCC lattices nest: FCC(a) ⊂ FCC(a/2), so the levels
//!   (cube sides `a_k = a_0 / 2^k`) are one octree. [`FillParams::radius`] is the *finest*
//!   radius; level 0 (the coarsest) has radius `radius · 2^(levels−1)`.
//! - *Near the surface.* A level-k cube is kept whole (its 4 particles) when it lies entirely
//!   inside: its centre is inside and farther from the surface than its half-diagonal (the
//!   exact distance, [`imprint_core::bvh::Bvh::closest_within`]). A cube that far from the
//!   surface with its centre outside is dropped; any other cube is split into its 8 children.
//!   At the finest level a straddling cube keeps each of its 4 particles whose centre is
//!   inside by T's test ([`crate::drape::InsideTest::odd_along_x`]; a centre exactly on the
//!   surface counts as outside). Each point of a level's lattice belongs to exactly one cube
//!   (half-open cubes), so no particle appears twice.
//! - *The lattice's origin* is the box's min corner less an irrational-ish fraction of a finest
//!   cube, so axis-aligned faces (a box's) do not pass through rows of centres.
//! - *Volume.* Each particle owns its lattice Voronoi cell, `a_k³/4`; the particle volume is
//!   the sum. Whole cubes own their exact volume, so the only error is the finest level's
//!   centre-inside rule at the surface (a midpoint rule). Measured at finest radius 0.01:
//!   +0.33% on a torus (tube radius 0.1), +0.13% on the cow (1 m long), +0.08% on a sphere
//!   of radius 0.3.
//! - *Counts* at finest radius 0.01 with 3 levels: sphere r 0.3, 8924 adaptive vs 19928
//!   uniform; torus 7675 vs 10419; cow 5887 vs 8323. A plate thinner than a coarse cube's
//!   diagonal gains nothing (T's remark): every cube there is split to the finest level.
//! - *Uniform count* (for the report) is the count a fill at the finest radius everywhere
//!   would give, obtained without building it: a whole level-k cube holds `4 · 8^(L−1−k)`
//!   finest particles, all inside.
//!
//! **Cost.** One inside test and one bounded closest-point query per visited cube; the
//! visited cubes are the kept ones plus those along the surface, O(area / finest cell²).
//!
//! **Determinism.** Root cubes are visited in z, y, x order and children in a fixed order;
//! the particle list is the same on every run and thread count (root cubes are tested in
//! parallel and their particles concatenated in root order).

use crate::drape::InsideTest;
use glam::Vec3;
use imprint_core::bvh::Bvh;
use imprint_core::{Error, Mesh, Result};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// How the mesh is filled. Every field may be left out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct FillParams {
    /// Radius of the *finest* (surface) particles, m. Default 0.01 (a tenth of a limb of
    /// radius 0.1).
    pub radius: f32,
    /// Number of radius levels, each twice the previous; 1 is a uniform fill. Default 3.
    pub levels: u32,
}

impl Default for FillParams {
    fn default() -> Self {
        FillParams {
            radius: 0.01,
            levels: 3,
        }
    }
}

/// More levels than this is a typo (a level-0 cube would be 2^15 finest cubes across).
pub const MAX_LEVELS: u32 = 16;
/// A finest lattice over the mesh's box with more sites than this is refused before filling
/// (the adaptive fill visits the surface's share of them; a uniform one all the inside).
pub const MAX_LATTICE: f64 = 4e9;

impl FillParams {
    /// Checks every number; errors name the field.
    pub fn validate(&self) -> Result<()> {
        if !(self.radius.is_finite() && self.radius > 0.0) {
            return Err(Error::Invalid(format!(
                "fill.radius = {}: must be a positive length (the finest particles' radius, m)",
                self.radius
            )));
        }
        if self.levels == 0 || self.levels > MAX_LEVELS {
            return Err(Error::Invalid(format!(
                "fill.levels = {}: must be between 1 and {MAX_LEVELS}",
                self.levels
            )));
        }
        Ok(())
    }

    /// The FCC cube side at `level` (0 is the coarsest).
    pub fn cube_side(&self, level: u32) -> f32 {
        let finest = 2.0 * std::f32::consts::SQRT_2 * self.radius;
        finest * (1u64 << (self.levels - 1 - level)) as f32
    }
}

/// What the fill made.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FillReport {
    /// Particles a fill at the finest radius everywhere would have.
    pub uniform_count: usize,
    /// Particles of the adaptive fill.
    pub adaptive_count: usize,
    /// Particles per level, coarsest first.
    pub per_level: Vec<usize>,
    /// Radius per level, coarsest first, m.
    pub radii: Vec<f32>,
    /// Sum of the particles' owned volumes (`a_k³/4` each), m³.
    pub particle_volume: f64,
    /// The closed mesh's volume (divergence theorem), m³.
    pub mesh_volume: f64,
}

/// The particles of a fill, in a fixed order.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Fill {
    pub positions: Vec<Vec3>,
    pub radii: Vec<f32>,
    /// Each particle's level (0 is the coarsest).
    pub levels: Vec<u8>,
    /// Each particle's owned volume, m³.
    pub volumes: Vec<f32>,
    pub report: FillReport,
}

/// One root cube's kept particles (position, level) and whole cubes per level.
type RootCubes = (Vec<(Vec3, u8)>, Vec<u64>);

/// The 4 FCC points of a cube of side 1 (min corner, then the three face centres there).
const FCC: [Vec3; 4] = [
    Vec3::ZERO,
    Vec3::new(0.5, 0.5, 0.0),
    Vec3::new(0.5, 0.0, 0.5),
    Vec3::new(0.0, 0.5, 0.5),
];

/// Fills a closed mesh with adaptive close-packed particles.
pub fn fill(mesh: &Mesh, params: &FillParams) -> Result<Fill> {
    params.validate()?;
    let bounds = mesh.bounds();
    if mesh.triangles.is_empty() || bounds.is_empty() {
        return Err(Error::Invalid(
            "particle fill: the mesh is empty (a closed mesh is needed)".into(),
        ));
    }
    let levels = params.levels;
    let a_fine = params.cube_side(levels - 1);
    let a0 = params.cube_side(0);
    let origin = bounds.min - a_fine * Vec3::new(0.382, 0.291, 0.237);
    let n = ((bounds.max - origin) / a0)
        .ceil()
        .as_uvec3()
        .max(glam::UVec3::ONE);
    let roots = n.x as u64 * n.y as u64 * n.z as u64;
    let fine_cells = ((bounds.size() / a_fine).ceil() + 1.0).as_dvec3();
    let sites = 4.0 * fine_cells.x * fine_cells.y * fine_cells.z;
    if sites > MAX_LATTICE {
        return Err(Error::Invalid(format!(
            "fill.radius = {}: too small for a mesh of size {} (the finest lattice over its box \
             would have {sites:.2e} sites, more than {MAX_LATTICE:e})",
            params.radius,
            bounds.size()
        )));
    }
    let inside = InsideTest::new(mesh);
    let bvh = Bvh::new(mesh);
    let mut cubes = Vec::with_capacity(roots as usize);
    for z in 0..n.z {
        for y in 0..n.y {
            for x in 0..n.x {
                cubes.push(origin + Vec3::new(x as f32, y as f32, z as f32) * a0);
            }
        }
    }
    // Per root cube: the kept particles (position, level) and the kept whole cubes per level.
    let per_root: Vec<RootCubes> = cubes
        .par_iter()
        .map(|&c| {
            let mut out = Vec::new();
            let mut whole = vec![0u64; levels as usize];
            visit(c, 0, params, &inside, &bvh, &mut out, &mut whole);
            (out, whole)
        })
        .collect();
    let mut positions = Vec::new();
    let mut lv = Vec::new();
    let mut whole = vec![0u64; levels as usize];
    let mut fine_kept_partial = 0u64;
    for (ps, w) in &per_root {
        for &(p, l) in ps {
            positions.push(p);
            lv.push(l);
        }
        for (k, c) in w.iter().enumerate() {
            whole[k] += c;
        }
    }
    let radii_per_level: Vec<f32> = (0..levels)
        .map(|k| params.cube_side(k) / (2.0 * std::f32::consts::SQRT_2))
        .collect();
    let mut per_level = vec![0usize; levels as usize];
    for &l in &lv {
        per_level[l as usize] += 1;
    }
    // Finest particles not in a whole cube are the partial cubes' kept ones.
    fine_kept_partial += per_level[levels as usize - 1] as u64 - 4 * whole[levels as usize - 1];
    let uniform: u64 = whole
        .iter()
        .enumerate()
        .map(|(k, &w)| w * 4 * 8u64.pow(levels - 1 - k as u32))
        .sum::<u64>()
        + fine_kept_partial;
    let radii: Vec<f32> = lv.iter().map(|&l| radii_per_level[l as usize]).collect();
    let volumes: Vec<f32> = lv
        .iter()
        .map(|&l| params.cube_side(l as u32).powi(3) / 4.0)
        .collect();
    let particle_volume = lv
        .iter()
        .map(|&l| (params.cube_side(l as u32) as f64).powi(3) / 4.0)
        .sum();
    if positions.is_empty() {
        return Err(Error::Invalid(format!(
            "fill.radius = {}: no particle fits inside the mesh (is it closed? make the radius smaller)",
            params.radius
        )));
    }
    let report = FillReport {
        uniform_count: uniform as usize,
        adaptive_count: positions.len(),
        per_level,
        radii: radii_per_level,
        particle_volume,
        mesh_volume: super::measure::volume(mesh),
    };
    Ok(Fill {
        positions,
        radii,
        levels: lv,
        volumes,
        report,
    })
}

/// One cube of side `cube_side(level)` at min corner `c`: kept whole, dropped, or split.
fn visit(
    c: Vec3,
    level: u32,
    params: &FillParams,
    inside: &InsideTest,
    bvh: &Bvh,
    out: &mut Vec<(Vec3, u8)>,
    whole: &mut [u64],
) {
    let a = params.cube_side(level);
    let centre = c + Vec3::splat(0.5 * a);
    let half_diag = 0.5 * 3f32.sqrt() * a;
    if bvh.closest_within(centre, half_diag).is_none() {
        // The whole cube is on one side of the surface.
        if inside.odd_along_x(centre) == Some(true) {
            for f in FCC {
                out.push((c + f * a, level as u8));
            }
            whole[level as usize] += 1;
        }
        return;
    }
    if level + 1 == params.levels {
        for f in FCC {
            let p = c + f * a;
            if inside.odd_along_x(p) == Some(true) {
                out.push((p, level as u8));
            }
        }
        return;
    }
    let h = 0.5 * a;
    for k in 0..8u32 {
        let o = Vec3::new((k & 1) as f32, ((k >> 1) & 1) as f32, ((k >> 2) & 1) as f32);
        visit(c + o * h, level + 1, params, inside, bvh, out, whole);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives;

    #[test]
    fn box_volume_and_counts() {
        let m = primitives::cuboid(Vec3::new(0.3, 0.2, 0.25), 2);
        let f = fill(
            &m,
            &FillParams {
                radius: 0.01,
                levels: 3,
            },
        )
        .unwrap();
        let r = &f.report;
        assert!((r.mesh_volume - 0.12).abs() < 1e-6, "{}", r.mesh_volume);
        assert!(
            (r.particle_volume / r.mesh_volume - 1.0).abs() < 0.03,
            "{r:?}"
        );
        assert!(r.adaptive_count < r.uniform_count, "{r:?}");
        assert_eq!(r.per_level.iter().sum::<usize>(), r.adaptive_count);
        // No particle twice.
        let mut keys: Vec<[u32; 3]> = f
            .positions
            .iter()
            .map(|p| p.to_array().map(f32::to_bits))
            .collect();
        keys.sort_unstable();
        keys.dedup();
        assert_eq!(keys.len(), f.positions.len());
    }

    #[test]
    fn one_level_is_uniform() {
        let m = primitives::uv_sphere(0.2, 24, 12);
        let f = fill(
            &m,
            &FillParams {
                radius: 0.02,
                levels: 1,
            },
        )
        .unwrap();
        assert_eq!(f.report.uniform_count, f.report.adaptive_count);
    }

    #[test]
    fn a_radius_too_small_is_refused() {
        let m = primitives::cuboid(Vec3::splat(1.0), 1);
        let e = fill(
            &m,
            &FillParams {
                radius: 1e-4,
                levels: 3,
            },
        )
        .unwrap_err();
        assert!(e.to_string().contains("fill.radius"), "{e}");
    }

    #[test]
    fn bad_params_name_the_field() {
        let e = FillParams {
            radius: 0.0,
            levels: 2,
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("fill.radius"));
        let e = FillParams {
            radius: 0.1,
            levels: 0,
        }
        .validate()
        .unwrap_err();
        assert!(e.to_string().contains("fill.levels"));
    }
}
