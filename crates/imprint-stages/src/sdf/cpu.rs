//! CPU distance field: each boundary point writes the ball of radius `a` around it (H §2).
//!
//! The grid is cut into slabs of a few z-layers, one task each. A slab visits, in increasing
//! index, every point that can reach it, and keeps per cell the strictly nearest point, so
//! ties go to the smaller index whatever the slab size or thread count: the result is the
//! same bytes on every machine. Working slab by slab keeps the written cells in cache.
//!
//! For a `Closest` boundary, each band cell's distance is then refined to the exact distance
//! to the triangle that owns its nearest point (see [`DistanceField`]); H's `Centre` boundary
//! keeps point distances, as published.

use glam::Vec3;
use imprint_core::geom::closest_point_on_triangle;
use imprint_core::{Boundary, BoundaryVariant, DistanceField, Error, Result};
use rayon::prelude::*;
use std::sync::Arc;

const SLAB_LAYERS: usize = 4;

/// The narrow-band field of half-width `band` cells around `boundary`.
pub fn build_field_cpu(boundary: &Boundary, band: f32) -> Result<DistanceField> {
    validate_band(band)?;
    let spec = boundary.spec;
    spec.check_memory("distance field", 8)?;
    let (nx, ny, nz) = (
        spec.dims.x as usize,
        spec.dims.y as usize,
        spec.dims.z as usize,
    );
    let nxy = nx * ny;
    let pts: Vec<Vec3> = boundary.points.par_iter().map(|&p| spec.to_cell(p)).collect();
    // Points are in increasing cell index, so their cell z is non-decreasing.
    let cell_z: Vec<usize> = boundary.cells.iter().map(|&c| c as usize / nxy).collect();
    let reach = (band + 0.8661).floor() as usize;
    let a2 = band * band;
    // d² <= a² exactly when d² < next_up(a²): the band includes its edge.
    let unset = f32::from_bits(a2.to_bits() + 1);
    let far = band * spec.cell;
    let refine = boundary.variant == BoundaryVariant::Closest;
    // Owning triangles in grid units, for the refinement.
    let faces: Vec<[Vec3; 3]> = if refine {
        boundary.faces.par_iter().map(|f| f.map(|v| spec.to_cell(v))).collect()
    } else {
        Vec::new()
    };

    let mut dist = vec![0f32; spec.len()];
    let mut nearest = vec![DistanceField::FAR; spec.len()];
    dist.par_chunks_mut(nxy * SLAB_LAYERS)
        .zip(nearest.par_chunks_mut(nxy * SLAB_LAYERS))
        .enumerate()
        .for_each(|(slab, (d2s, near))| {
            let z0 = slab * SLAB_LAYERS;
            let z1 = (z0 + SLAB_LAYERS).min(nz);
            d2s.fill(unset);
            let first = cell_z.partition_point(|&z| z + reach < z0);
            let last = cell_z.partition_point(|&z| z <= z1 - 1 + reach);
            for (pi, p) in pts.iter().enumerate().take(last).skip(first) {
                splat_point(*p, pi as u32, band, a2, z0, z1, nx, ny, d2s, near);
            }
            for (k, (d, n)) in d2s.iter_mut().zip(near.iter()).enumerate() {
                *d = if *n == DistanceField::FAR {
                    far
                } else if refine {
                    let x = Vec3::new((k % nx) as f32, ((k / nx) % ny) as f32, (z0 + k / nxy) as f32);
                    let [a, b, c] = faces[*n as usize];
                    (closest_point_on_triangle(x, a, b, c) - x).length() * spec.cell
                } else {
                    d.sqrt() * spec.cell
                };
            }
        });
    Ok(DistanceField {
        spec,
        band,
        dist,
        nearest,
        points: Arc::new(boundary.points.clone()),
        faces: refine.then(|| Arc::new(boundary.faces.clone())),
    })
}

/// Writes point `p` (grid units, index `pi`) into the cells of slab [z0, z1) within `band`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn splat_point(
    p: Vec3,
    pi: u32,
    band: f32,
    a2: f32,
    z0: usize,
    z1: usize,
    nx: usize,
    ny: usize,
    d2s: &mut [f32],
    near: &mut [u32],
) {
    const SLACK: f32 = 1e-3;
    let zlo = ((p.z - band - SLACK).ceil().max(z0 as f32)) as usize;
    let zhi = (p.z + band + SLACK).floor().min(z1 as f32 - 1.0);
    if zhi < zlo as f32 {
        return;
    }
    for z in zlo..=zhi as usize {
        let dz = z as f32 - p.z;
        let rz2 = a2 - dz * dz;
        if rz2 < -SLACK {
            continue;
        }
        let ry = rz2.max(0.0).sqrt();
        let ylo = (p.y - ry - SLACK).ceil().max(0.0) as usize;
        let yhi = (p.y + ry + SLACK).floor().min(ny as f32 - 1.0);
        if yhi < ylo as f32 {
            continue;
        }
        for y in ylo..=yhi as usize {
            let dy = y as f32 - p.y;
            let dyz2 = dy * dy + dz * dz;
            let rx = (a2 - dyz2).max(0.0).sqrt();
            let xlo = (p.x - rx - SLACK).ceil().max(0.0) as usize;
            let xhi = (p.x + rx + SLACK).floor().min(nx as f32 - 1.0);
            if xhi < xlo as f32 {
                continue;
            }
            let row = (z - z0) * nx * ny + y * nx;
            let d_row = &mut d2s[row + xlo..=row + xhi as usize];
            let n_row = &mut near[row + xlo..=row + xhi as usize];
            for (k, (d, n)) in d_row.iter_mut().zip(n_row.iter_mut()).enumerate() {
                let dx = (xlo + k) as f32 - p.x;
                let d2 = dx * dx + dyz2;
                if d2 < *d {
                    *d = d2;
                    *n = pi;
                }
            }
        }
    }
}

/// The band half-width must be a finite number of cells > 0.
pub fn validate_band(band: f32) -> Result<()> {
    if !(band.is_finite() && band > 0.0) {
        return Err(Error::Invalid(format!(
            "band must be a finite number of cells > 0, got {band}"
        )));
    }
    Ok(())
}
