//! Error metrics of a distance field against the exact distance to the mesh.
//!
//! The reference is the exact closest point on the triangles. The cells measured are those
//! whose *exact* distance is within the band, so a field that leaves band cells far is caught
//! (`far_fraction`) rather than silently skipped.
//!
//! The exact distances are splatted from the triangles rather than queried cell by cell
//! through a BVH (whose boxes overlap near the surface, so that a query opens many: most of a
//! one-shot `imprint field`'s time). Each cell looks as far as the field's own distance (a
//! distance to a point of the surface, so no nearer than the exact one where the field is
//! right), at most the band; each triangle visits the cells of its bounding sphere grown by
//! the band whose reach can meet that sphere, its closest points a batch at a time
//! ([`imprint_core::closest`], the bits of [`closest_point_on_triangle`]), and each cell keeps
//! the smallest squared distance, which does not depend on the order. A cell that found no
//! triangle within its reach (the field read nearer than the surface there) is queried
//! through the BVH, so a wrong field is measured as exactly as a right one. The grid is cut
//! into z-slabs as in the voxeliser, one task each: no atomics, and the same bytes on any
//! number of threads.
//!
//! [`closest_point_on_triangle`]: imprint_core::geom::closest_point_on_triangle

use crate::voxel::cpu::SlabBins;
use glam::{UVec3, Vec3};
use imprint_core::bvh::Bvh;
use imprint_core::closest::Batch;
use imprint_core::{DistanceField, GridSpec, Mesh};
use rayon::prelude::*;
use serde::Serialize;
use std::sync::OnceLock;

/// z-layers per slab task: 4 layers of 128² squared distances are 256 KiB.
const SLAB_LAYERS: usize = 4;

/// Distance error over the band, in cells.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize)]
pub struct FieldError {
    /// Cells whose exact distance is within the band.
    pub band_cells: usize,
    pub max: f32,
    pub p99: f32,
    pub median: f32,
    pub mean: f32,
    /// Fraction of band cells the field left far.
    pub far_fraction: f32,
}

/// Measures `field` against the exact distance to `mesh`.
pub fn field_error(field: &DistanceField, mesh: &Mesh) -> FieldError {
    summarise(&band_errors(field, mesh))
}

/// The statistics of each band cell's (error in cells, left far), in cell order.
fn summarise(results: &[(f32, bool)]) -> FieldError {
    let band_cells = results.len();
    let far = results.iter().filter(|r| r.1).count();
    let mut errors: Vec<f32> = results.iter().filter(|r| !r.1).map(|r| r.0).collect();
    if errors.is_empty() {
        return FieldError {
            band_cells,
            far_fraction: if band_cells > 0 { 1.0 } else { 0.0 },
            ..Default::default()
        };
    }
    let mean = (errors.iter().map(|&e| e as f64).sum::<f64>() / errors.len() as f64) as f32;
    let max = errors.iter().copied().fold(0.0, f32::max);
    let p99 = percentile(&mut errors, 0.99);
    let median = percentile(&mut errors, 0.5);
    FieldError {
        band_cells,
        max,
        p99,
        median,
        mean,
        far_fraction: far as f32 / band_cells as f32,
    }
}

/// Per candidate cell (in increasing index) whose exact distance is within the band: the
/// field's error there in cells, or (∞, true) where the field left it far.
fn band_errors(field: &DistanceField, mesh: &Mesh) -> Vec<(f32, bool)> {
    let spec = field.spec;
    let limit = field.band * spec.cell;
    let mask = candidate_mask(field);
    let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
        .map(|t| mesh.triangle(t))
        .collect();
    // Each triangle's bounding sphere (centroid, radius), and the layers its ball grown by the
    // band reaches.
    let balls: Vec<(Vec3, f32)> = tris
        .par_iter()
        .map(|t| {
            let g = (t[0] + t[1] + t[2]) / 3.0;
            (g, t.iter().map(|v| v.distance(g)).fold(0.0, f32::max))
        })
        .collect();
    let nz = spec.dims.z as i32;
    let layers: Vec<(i32, i32)> = balls
        .iter()
        .map(|&(g, r)| {
            let (lo, hi) = index_range(&spec, 2, g.z, ball(r, limit, spec.cell));
            (lo.max(0), hi.min(nz - 1))
        })
        .collect();
    let bins = SlabBins::by_layers::<{ SLAB_LAYERS as u32 }>(nz as usize, &layers);
    // Cells the splat leaves open are queried; the tree is built only if one is.
    let bvh = OnceLock::new();
    let query = |p: Vec3| {
        let bvh = bvh.get_or_init(|| Bvh::new(mesh));
        bvh.closest_within(p, limit).map(|c| c.distance)
    };
    let parts: Vec<Vec<(f32, bool)>> = (0..(nz as usize).div_ceil(SLAB_LAYERS))
        .into_par_iter()
        .map(|slab| {
            let z = slab * SLAB_LAYERS..((slab + 1) * SLAB_LAYERS).min(nz as usize);
            let scene = Slab {
                field,
                mask: &mask,
                tris: &tris,
                balls: &balls,
                limit,
                z,
            };
            let reach = scene.reach();
            let d2 = scene.closest_d2(bins.of(slab), &reach);
            scene.errors(&d2, &reach, &query)
        })
        .collect();
    parts.concat()
}

/// `r` with a margin for rounding (a thousandth of a cell `h`, far above the rounding of
/// coordinates, radii and cell centres), so that the tests on it never drop a cell within `r`.
fn grow(r: f32, h: f32) -> f32 {
    r * (1.0 + 1e-5) + 1e-3 * h
}

/// A triangle's ball (bounding radius `r` grown by the band `limit`) with a thousandth of a
/// cell to spare again: every cell [`grow`] keeps lies inside it.
fn ball(r: f32, limit: f32, h: f32) -> f32 {
    grow(r + limit, h) + 1e-3 * h
}

/// The cells along `axis` whose centres lie within `r` of `c` (first, last).
fn index_range(spec: &GridSpec, axis: usize, c: f32, r: f32) -> (i32, i32) {
    // A multiplication, not a division (one per row): the ranges only need to hold the cells
    // [`grow`] keeps, and its margin is far above the difference.
    let (o, inv) = (spec.origin[axis], 1.0 / spec.cell);
    let (lo, hi) = ((c - r - o) * inv, (c + r - o) * inv);
    // `ceil` and `floor` without their library calls (x86-64's baseline has no rounding
    // instruction): a conversion truncates towards zero, then a step where it went the wrong
    // way. (Far outside an i32, the conversion saturates, as the ranges are clamped anyway.)
    let (l, u) = (lo as i32, hi as i32);
    (l + ((l as f32) < lo) as i32, u - ((u as f32) > hi) as i32)
}

/// Cells per run of a row that [`near_cells`] tests at once.
const RUN: usize = 16;

/// Bit `k` set where cell `x0 + k` of a row (`dy`, `dz` from its centres to the triangle's
/// centroid `g`) is a candidate whose `reach` can meet the triangle's bounding sphere of
/// radius `r`. A fixed number of cells, so that the loop becomes a few vector instructions;
/// the caller masks off those past the row's run.
fn near_cells(
    reach: &[f32; RUN],
    x0: i32,
    (dy, dz): (f32, f32),
    (g, r): (Vec3, f32),
    spec: &GridSpec,
) -> u32 {
    let yz = dy * dy + dz * dz;
    let mut bits = 0u32;
    for (k, &reach) in reach.iter().enumerate() {
        let dx = spec.origin.x + (x0 + k as i32) as f32 * spec.cell - g.x;
        let within = grow(reach + r, spec.cell);
        bits |= (((reach >= 0.0) & (dx * dx + yz <= within * within)) as u32) << k;
    }
    bits
}

/// One slab task of [`band_errors`]: its layers `z`, the field, the candidate cells and the
/// triangles.
struct Slab<'a> {
    field: &'a DistanceField,
    mask: &'a [bool],
    tris: &'a [[Vec3; 3]],
    balls: &'a [(Vec3, f32)],
    limit: f32,
    z: std::ops::Range<usize>,
}

impl Slab<'_> {
    /// The slab's cells' first index and count.
    fn cells(&self) -> (usize, usize) {
        let nxy = (self.field.spec.dims.x * self.field.spec.dims.y) as usize;
        (self.z.start * nxy, self.z.len() * nxy)
    }

    /// Per cell of the slab, how far the splat looks for its nearest triangle: the field's own
    /// distance (a distance to a point of the surface, so at least the exact one where the
    /// field is right) and a hair, at most the band; the band where the field left the cell
    /// far; −1 off the candidates, and for [`RUN`] cells past the slab (so that a run read
    /// from any of its cells is whole). Where no triangle is found that near, the cell is
    /// queried.
    fn reach(&self) -> Vec<f32> {
        let (base, len) = self.cells();
        let (f, slack) = (self.field, 1e-3 * self.field.spec.cell);
        let mut reach: Vec<f32> = (base..base + len)
            .map(|i| match (self.mask[i], f.is_far(i)) {
                (false, _) => -1.0,
                (true, true) => self.limit,
                (true, false) => (f.dist[i] + slack).min(self.limit),
            })
            .collect();
        reach.resize(len + RUN, -1.0);
        reach
    }

    /// Per cell of the slab, the smallest squared distance to the triangles that may lie
    /// within its `reach` (∞ where none): each triangle's ball grown by the band visited row
    /// by row, a cell taken when its reach can meet the triangle's bounding sphere, the closest
    /// points a batch at a time.
    fn closest_d2(&self, tris: &[u32], reach: &[f32]) -> Vec<f32> {
        let spec = &self.field.spec;
        let (nx, ny) = (spec.dims.x as i32, spec.dims.y as i32);
        let nxy = (nx * ny) as usize;
        let (base, len) = self.cells();
        let mut d2 = vec![f32::INFINITY; len];
        // (cell, triangle) pairs of any triangles, a batch at a time; the minima do not depend
        // on the order.
        let mut batch = Batch::<u32>::default();
        let mut keep = |cell: u32, _: Vec3, e: f32| {
            let d = &mut d2[cell as usize];
            *d = d.min(e);
        };
        for &t in tris {
            let tri = self.tris[t as usize];
            let (g, r) = self.balls[t as usize];
            let ball = ball(r, self.limit, spec.cell);
            let (zlo, zhi) = index_range(spec, 2, g.z, ball);
            let (ylo, yhi) = index_range(spec, 1, g.y, ball);
            let zs = zlo.max(self.z.start as i32)..=zhi.min(self.z.end as i32 - 1);
            for z in zs {
                let dz = spec.origin.z + z as f32 * spec.cell - g.z;
                for y in ylo.max(0)..=yhi.min(ny - 1) {
                    let dy = spec.origin.y + y as f32 * spec.cell - g.y;
                    let w2 = ball * ball - dy * dy - dz * dz;
                    if w2 < 0.0 {
                        continue;
                    }
                    let (xlo, xhi) = index_range(spec, 0, g.x, w2.sqrt());
                    let (xlo, xhi) = (xlo.max(0), xhi.min(nx - 1));
                    if xlo > xhi {
                        continue;
                    }
                    let row = (y * nx) as usize + z as usize * nxy - base;
                    // Runs of cells: which may meet the triangle, a few instructions for all;
                    // then those cells' closest points.
                    for x0 in (xlo..=xhi).step_by(RUN) {
                        let first = row + x0 as usize;
                        let run = &reach[first..first + RUN];
                        let len = ((xhi - x0 + 1) as usize).min(RUN);
                        let mut bits =
                            near_cells(run.try_into().expect("a run"), x0, (dy, dz), (g, r), spec)
                                & (u32::MAX >> (32 - len));
                        while bits != 0 {
                            let k = bits.trailing_zeros();
                            bits &= bits - 1;
                            let at = UVec3::new(x0 as u32 + k, y as u32, z as u32);
                            let cell = (first + k as usize) as u32;
                            if batch.push(spec.center(at), tri, cell) {
                                batch.run(&mut keep);
                            }
                        }
                    }
                }
            }
        }
        batch.run(&mut keep);
        d2
    }

    /// The slab's candidate cells within the band of the mesh, in increasing index, with the
    /// field's error there: a cell whose splat found a triangle within its reach has its exact
    /// squared distance (a nearer triangle would be within reach too); the others ask `query`
    /// for their exact distance.
    fn errors(
        &self,
        d2: &[f32],
        reach: &[f32],
        query: &(impl Fn(Vec3) -> Option<f32> + Sync),
    ) -> Vec<(f32, bool)> {
        let (base, _) = self.cells();
        let (f, h) = (self.field, self.field.spec.cell);
        let limit2 = self.limit * self.limit;
        let mut out = Vec::new();
        for (k, (&d2, &reach)) in d2.iter().zip(&reach[..d2.len()]).enumerate() {
            let i = base + k;
            if reach < 0.0 {
                continue;
            }
            let exact = if d2 <= reach * reach || reach >= self.limit {
                (d2 <= limit2).then(|| d2.sqrt())
            } else {
                query(f.spec.center(f.spec.coords(i)))
            };
            let Some(exact) = exact else { continue };
            out.push(if f.is_far(i) {
                (f32::INFINITY, true)
            } else {
                ((f.dist[i] - exact).abs() / h, false)
            });
        }
        out
    }
}

/// The `q`-quantile (nearest rank) of `values`; reorders them.
pub fn percentile(values: &mut [f32], q: f64) -> f32 {
    if values.is_empty() {
        return 0.0;
    }
    let k = ((q * values.len() as f64).ceil() as usize).clamp(1, values.len()) - 1;
    *values.select_nth_unstable_by(k, f32::total_cmp).1
}

/// Every cell that could be within the band of the surface: the cube of reach
/// ceil(band + sqrt(3)/2) around each surface cell (the surface lies inside its surface cells).
fn candidate_mask(field: &DistanceField) -> Vec<bool> {
    let spec = field.spec;
    let (nx, ny, nz) = (spec.dims.x as i64, spec.dims.y as i64, spec.dims.z as i64);
    let r = (field.band + 0.8661).ceil() as i64;
    let mut mask = vec![false; spec.len()];
    let mut surface = vec![false; spec.len()];
    for p in field.points.iter() {
        if let Some(c) = spec.cell_of(*p) {
            surface[spec.index(c)] = true;
        }
    }
    // Boundary points of the centre variant sit on their cells; closest points may sit just
    // across a face, so also mark the cell each point rounds to (done above) and dilate by r.
    for (i, _) in surface.iter().enumerate().filter(|(_, s)| **s) {
        let c = spec.coords(i).as_i64vec3();
        for z in (c.z - r).max(0)..=(c.z + r).min(nz - 1) {
            for y in (c.y - r).max(0)..=(c.y + r).min(ny - 1) {
                let row = (z * ny + y) * nx;
                let lo = (c.x - r).max(0);
                let hi = (c.x + r).min(nx - 1);
                mask[(row + lo) as usize..=(row + hi) as usize].fill(true);
            }
        }
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives;
    use imprint_core::{BoundaryVariant, GridSpec};

    /// The BVH query per candidate cell that the splat replaced: the same numbers, bit for bit.
    fn by_queries(field: &DistanceField, mesh: &Mesh) -> Vec<(f32, bool)> {
        let bvh = Bvh::new(mesh);
        let (spec, limit) = (field.spec, field.band * field.spec.cell);
        let mask = candidate_mask(field);
        (0..spec.len())
            .filter(|&i| mask[i])
            .filter_map(|i| {
                let exact = bvh
                    .closest_within(spec.center(spec.coords(i)), limit)?
                    .distance;
                Some(if field.is_far(i) {
                    (f32::INFINITY, true)
                } else {
                    ((field.dist[i] - exact).abs() / spec.cell, false)
                })
            })
            .collect()
    }

    fn field_of(
        mesh: &Mesh,
        spec: &GridSpec,
        band: f32,
        variant: BoundaryVariant,
    ) -> DistanceField {
        let b = crate::voxel::voxelize_cpu(mesh, spec, variant).unwrap();
        crate::sdf::build_field_cpu(&b, band).unwrap()
    }

    fn same_as_queries(mesh: &Mesh, spec: &GridSpec, band: f32) {
        same_for(&field_of(mesh, spec, band, BoundaryVariant::Closest), mesh);
    }

    fn same_for(field: &DistanceField, mesh: &Mesh) {
        let (got, want) = (band_errors(field, mesh), by_queries(field, mesh));
        assert!(
            want.len() > 100,
            "a test with few band cells: {}",
            want.len()
        );
        assert_eq!(got.len(), want.len());
        for (k, (g, w)) in got.iter().zip(&want).enumerate() {
            assert!(
                g.1 == w.1 && g.0.to_bits() == w.0.to_bits(),
                "{k}: {g:?} vs {w:?}"
            );
        }
    }

    /// Small triangles and large ones (a box's two per face, wider than the grid), a mesh
    /// reaching past the grid's sides, bands of one and four cells, on a grid whose dimensions
    /// differ per axis and whose origin is no multiple of its cell.
    #[test]
    fn splat_gives_the_queries_numbers() {
        let spec = GridSpec::new(Vec3::splat(-0.47), 0.031, glam::UVec3::new(31, 29, 27)).unwrap();
        same_as_queries(&primitives::uv_sphere(0.3, 24, 12), &spec, 3.0);
        same_as_queries(&primitives::uv_sphere(0.3, 24, 12), &spec, 1.0);
        let mut off = primitives::uv_sphere(0.35, 16, 8);
        off.positions
            .iter_mut()
            .for_each(|p| *p += Vec3::new(0.3, -0.2, 0.1));
        same_as_queries(&off, &spec, 4.0);
        same_as_queries(&primitives::cuboid(Vec3::new(0.5, 0.3, 0.4), 1), &spec, 3.0);
        same_as_queries(&primitives::torus(0.25, 0.08, 32, 12), &spec, 3.0);
    }

    /// Where the field reads nearer than the surface (H's cell centres as boundary points, or a
    /// field spoiled on purpose), the cells the splat cannot settle are queried: the same
    /// numbers still.
    #[test]
    fn fields_nearer_than_the_surface_are_measured_the_same() {
        let spec = GridSpec::new(Vec3::splat(-0.47), 0.031, glam::UVec3::new(31, 29, 27)).unwrap();
        let mesh = primitives::torus(0.25, 0.08, 32, 12);
        same_for(&field_of(&mesh, &spec, 3.0, BoundaryVariant::Centre), &mesh);
        let mut spoiled = field_of(&mesh, &spec, 3.0, BoundaryVariant::Closest);
        for (i, d) in spoiled.dist.iter_mut().enumerate() {
            if i % 3 == 0 {
                *d *= 0.5;
            }
        }
        same_for(&spoiled, &mesh);
    }
}
