//! CPU voxelisation: parallel over triangles, deterministic for any thread count.
//!
//! Each (triangle, candidate cell) pair yields the key (squared distance from the cell centre
//! to the triangle, triangle index); an atomic `fetch_min` per cell keeps the smallest key,
//! which does not depend on the order the pairs arrive in. The closest points are computed
//! eight pairs at a time ([`super::batch`], the scalar function's bits). An occupancy bitset then lists the
//! surface cells in increasing index without scanning the whole grid, and the scratch arrays
//! are reset only where they were touched, so a `Voxelizer` kept across frames costs time in
//! proportion to the surface, not the grid.

use super::batch::Batch;
use super::solid::ClosedCache;
use glam::{IVec3, UVec3, Vec3};
use imprint_core::geom::{ceil_i, closest_point_on_triangle, floor_i, triangle_box_overlap};
use imprint_core::{Boundary, BoundaryVariant, GridSpec, Mesh, Result};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};

/// Half-size of the closed cell box in the overlap test: a hair over 0.5 so that a triangle
/// lying exactly on a cell face marks both cells even after rounding.
pub const CELL_HALF: f32 = 0.5 + 1e-5;
const EMPTY: u64 = u64::MAX;

/// Cells, points and owning triangles of one run of occupancy words.
type BoundaryPart = (Vec<u32>, Vec<Vec3>, Vec<[Vec3; 3]>);
const TRIANGLES_PER_TASK: usize = 2048;
const WORDS_PER_TASK: usize = 256;

/// Voxelises meshes onto one grid, keeping its scratch arrays between calls.
pub struct Voxelizer {
    spec: GridSpec,
    /// Per cell: (d² bits << 32 | triangle), EMPTY when no triangle touches it.
    best: Vec<AtomicU64>,
    /// One bit per cell: touched by some triangle.
    occupied: Vec<AtomicU64>,
    /// Mark the cells inside a closed mesh ([`Boundary::inside`]: the field's sign); on by
    /// default, off where nothing reads the sign.
    pub signed: bool,
    closed: ClosedCache,
}

impl Voxelizer {
    pub fn new(spec: GridSpec) -> Result<Self> {
        spec.check_memory("voxelisation scratch", 9)?;
        let n = spec.len();
        Ok(Voxelizer {
            spec,
            best: (0..n).map(|_| AtomicU64::new(EMPTY)).collect(),
            occupied: (0..n.div_ceil(64)).map(|_| AtomicU64::new(0)).collect(),
            signed: true,
            closed: ClosedCache::default(),
        })
    }

    pub fn spec(&self) -> &GridSpec {
        &self.spec
    }

    /// The discrete boundary of `mesh` on this grid. Parts of the mesh outside the grid are
    /// clipped away.
    pub fn run(&mut self, mesh: &Mesh, variant: BoundaryVariant) -> Result<Boundary> {
        let spec = self.spec;
        let verts: Vec<Vec3> = mesh
            .positions
            .par_iter()
            .map(|&p| spec.to_cell(p))
            .collect();
        let dims = spec.dims.as_ivec3();
        let nx = spec.dims.x as usize;
        let nxy = nx * spec.dims.y as usize;
        let (best, occupied) = (&self.best, &self.occupied);

        // Pass 1: every (triangle, touched cell) pair proposes its key.
        mesh.triangles
            .par_chunks(TRIANGLES_PER_TASK)
            .enumerate()
            .for_each(|(chunk, tris)| {
                // (cell, triangle) pairs past the plane test, their closest points a batch at
                // a time; the proposals do not depend on the order.
                let mut batch = Batch::<(u32, u32)>::default();
                let propose = |(cell, ti): (u32, u32), d2: f32| {
                    // Outside the circumscribed sphere: no contact. Inside the inscribed
                    // one: contact. In between: the exact test.
                    if d2 > 3.0 * CELL_HALF * CELL_HALF {
                        return;
                    }
                    let cell = cell as usize;
                    if d2 > 0.25 {
                        let centre = spec.coords(cell).as_vec3();
                        let [a, b, c] = mesh.triangles[ti as usize].map(|i| verts[i as usize]);
                        if !triangle_box_overlap(centre, Vec3::splat(CELL_HALF), a, b, c) {
                            return;
                        }
                    }
                    // Plain loads first: x86 has no atomic min (it is a CAS loop) and most
                    // proposals lose or find the bit set.
                    let key = ((d2.to_bits() as u64) << 32) | ti as u64;
                    if key < best[cell].load(Relaxed) {
                        best[cell].fetch_min(key, Relaxed);
                    }
                    let bit = 1u64 << (cell % 64);
                    if occupied[cell / 64].load(Relaxed) & bit == 0 {
                        occupied[cell / 64].fetch_or(bit, Relaxed);
                    }
                };
                for (k, t) in tris.iter().enumerate() {
                    let ti = (chunk * TRIANGLES_PER_TASK + k) as u32;
                    let [a, b, c] = t.map(|i| verts[i as usize]);
                    let (mn, mx) = (a.min(b).min(c) - CELL_HALF, a.max(b).max(c) + CELL_HALF);
                    let lo = IVec3::new(ceil_i(mn.x), ceil_i(mn.y), ceil_i(mn.z)).max(IVec3::ZERO);
                    let hi = IVec3::new(floor_i(mx.x), floor_i(mx.y), floor_i(mx.z)).min(dims - 1);
                    // The triangle's plane is a separating axis: one dot product rejects the
                    // candidate cells it misses before any closest-point work (exact, like the rest).
                    let n = (b - a).cross(c - a);
                    let reach = CELL_HALF * (n.x.abs() + n.y.abs() + n.z.abs());
                    for z in lo.z..=hi.z {
                        for y in lo.y..=hi.y {
                            for x in lo.x..=hi.x {
                                let centre = Vec3::new(x as f32, y as f32, z as f32);
                                if n.dot(centre - a).abs() > reach {
                                    continue;
                                }
                                let cell = x as usize + nx * y as usize + nxy * z as usize;
                                if batch.push(centre, [a, b, c], (cell as u32, ti)) {
                                    batch.run(|t, _, d2| propose(t, d2));
                                }
                            }
                        }
                    }
                }
                batch.run(|t, _, d2| propose(t, d2));
            });

        // Pass 2: surface cells in increasing index; reset what was touched.
        let parts: Vec<BoundaryPart> = occupied
            .par_chunks(WORDS_PER_TASK)
            .enumerate()
            .map(|(chunk, words)| {
                let mut cells = Vec::new();
                let mut points = Vec::new();
                let mut faces = Vec::new();
                for (w, word) in words.iter().enumerate() {
                    let mut bits = word.swap(0, Relaxed);
                    while bits != 0 {
                        let bit = bits.trailing_zeros() as usize;
                        bits &= bits - 1;
                        let cell = (chunk * WORDS_PER_TASK + w) * 64 + bit;
                        let key = best[cell].swap(EMPTY, Relaxed);
                        let coords = spec.coords(cell);
                        let tri = mesh.triangles[(key & 0xffff_ffff) as usize];
                        let point = match variant {
                            BoundaryVariant::Centre => spec.center(coords),
                            BoundaryVariant::Closest => {
                                let [a, b, c] = tri.map(|i| verts[i as usize]);
                                let q = closest_point_on_triangle(coords.as_vec3(), a, b, c);
                                spec.origin + q * spec.cell
                            }
                        };
                        cells.push(cell as u32);
                        points.push(point);
                        faces.push(tri.map(|i| mesh.positions[i as usize]));
                    }
                }
                (cells, points, faces)
            })
            .collect();
        let total = parts.iter().map(|p| p.0.len()).sum();
        let mut cells = Vec::with_capacity(total);
        let mut points = Vec::with_capacity(total);
        let mut faces = Vec::with_capacity(total);
        for (c, p, f) in parts {
            cells.extend(c);
            points.extend(p);
            faces.extend(f);
        }
        let inside = (self.signed && self.closed.is_closed(mesh))
            .then(|| super::solid::inside_cells(&spec, &verts, &mesh.triangles));
        Ok(Boundary {
            spec,
            variant,
            cells,
            points,
            faces,
            inside,
        })
    }
}

/// One-shot voxelisation (allocates scratch for the grid; keep a [`Voxelizer`] across frames).
pub fn voxelize_cpu(mesh: &Mesh, spec: &GridSpec, variant: BoundaryVariant) -> Result<Boundary> {
    Voxelizer::new(*spec)?.run(mesh, variant)
}

/// Cell coordinates of a boundary's surface cell.
pub fn cell_coords(spec: &GridSpec, cell: u32) -> UVec3 {
    spec.coords(cell as usize)
}
