//! Error metrics of a distance field against the exact distance to the mesh.
//!
//! The reference is the exact closest point on the triangles (a BVH query per cell). The cells
//! measured are those whose *exact* distance is within the band, so a field that leaves band
//! cells far is caught (`far_fraction`) rather than silently skipped.

use imprint_core::bvh::Bvh;
use imprint_core::{DistanceField, Mesh};
use rayon::prelude::*;
use serde::Serialize;

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

/// Measures `field` against the exact distance to `mesh` (pass a [`Bvh`] built once with
/// [`field_error_with`] when measuring many frames of a static mesh).
pub fn field_error(field: &DistanceField, mesh: &Mesh) -> FieldError {
    field_error_with(field, &Bvh::new(mesh))
}

pub fn field_error_with(field: &DistanceField, bvh: &Bvh) -> FieldError {
    let spec = field.spec;
    let h = spec.cell;
    let limit = field.band * h;
    let candidates = candidate_cells(field);
    let results: Vec<(f32, bool)> = candidates
        .par_iter()
        .filter_map(|&cell| {
            let centre = spec.center(spec.coords(cell as usize));
            let exact = bvh.closest_within(centre, limit)?.distance;
            let i = cell as usize;
            Some(if field.is_far(i) {
                (f32::INFINITY, true)
            } else {
                ((field.dist[i] - exact).abs() / h, false)
            })
        })
        .collect();
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
fn candidate_cells(field: &DistanceField) -> Vec<u32> {
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
    mask.iter()
        .enumerate()
        .filter(|(_, m)| **m)
        .map(|(i, _)| i as u32)
        .collect()
}
