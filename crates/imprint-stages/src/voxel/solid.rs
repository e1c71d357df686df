//! Solid voxelisation: which cell centres lie inside a closed mesh, so that the distance field
//! carries a sign and the cloth can tell a particle that got into a thin part (an ear, a horn)
//! from one outside it.
//!
//! **Method.** The parity of a ray's crossings along +x, row by row (a row: the cell centres of
//! one (y, z)). Each triangle, projected on the y-z plane, marks in every row whose point it
//! covers the first cell past its crossing; an xor-prefix along the row then says, per cell,
//! whether an odd number of crossings lie before its centre. The cost is the rows the
//! triangles cover (about twice the body's silhouette in cells) plus one pass over the bits.
//!
//! **Exact where it matters.** A row through an edge shared by two triangles must be counted
//! once, or the parity of the whole rest of the row flips. Edge functions are computed from the
//! edge's lexicographically smaller end, so the two triangles get exactly opposite values, and
//! a point on an edge (value 0) belongs to the triangle on one fixed side of it (as if the row
//! were nudged by a fixed infinitesimal offset, which also settles rows through a vertex).
//! Projected triangles of zero area (parallel to x) are skipped: their neighbours' coverage
//! already has the right parity. A centre exactly on the surface counts as outside.
//!
//! **GPU twin.** `shaders/voxel/solid.wgsl` does the same operations in the same order on the
//! same grid-coordinate vertices (no fused multiply-adds), so both paths give the same bits.

use glam::{Vec2, Vec3};
use imprint_core::{GridSpec, Mesh};
use rayon::prelude::*;

const TRIANGLES_PER_TASK: usize = 2048;

/// Remembers whether a mesh is closed ([`Mesh::is_closed`] visits every edge): a body that
/// deforms keeps its triangles, so it is checked again only when they change.
#[derive(Default)]
pub struct ClosedCache {
    triangles: Vec<[u32; 3]>,
    closed: Option<bool>,
}

impl ClosedCache {
    pub fn is_closed(&mut self, mesh: &Mesh) -> bool {
        match self.closed {
            Some(c) if self.triangles == mesh.triangles => c,
            _ => {
                let c = mesh.is_closed();
                self.triangles = mesh.triangles.clone();
                self.closed = Some(c);
                c
            }
        }
    }
}

/// The edge function of `r` against the directed edge `p → q` (positive on its left), from the
/// edge's lexicographically smaller end: the edge read backwards gives exactly the negation.
#[inline(always)]
fn edge(p: Vec2, q: Vec2, r: Vec2) -> f32 {
    let orient = |p: Vec2, q: Vec2| (q.x - p.x) * (r.y - p.y) - (q.y - p.y) * (r.x - p.x);
    if p.x < q.x || (p.x == q.x && p.y <= q.y) {
        orient(p, q)
    } else {
        -orient(q, p)
    }
}

/// Whether a point with edge function `e` against the edge `d` (of a counter-clockwise
/// triangle) is covered: strictly inside, or on the edge and the triangle lies on the side a
/// fixed nudge of the point, (-1, δ) in (y, z), would move it to.
#[inline(always)]
fn covers(e: f32, d: Vec2) -> bool {
    e > 0.0 || (e == 0.0 && (d.y > 0.0 || (d.y == 0.0 && d.x > 0.0)))
}

/// The crossings of triangle `t` (grid coordinates) with the rows: (row, first cell past the
/// crossing) for each covered row whose crossing lies before the row's last cell.
fn crossings(t: [Vec3; 3], dims: glam::UVec3, out: &mut Vec<u32>) {
    let [a, mut b, mut c] = t;
    let yz = |v: Vec3| Vec2::new(v.y, v.z);
    let area = edge(yz(a), yz(b), yz(c));
    if !(area != 0.0) {
        return;
    }
    if area < 0.0 {
        std::mem::swap(&mut b, &mut c);
    }
    let (a2, b2, c2) = (yz(a), yz(b), yz(c));
    let lo = a2.min(b2).min(c2).ceil().max(Vec2::ZERO);
    let hi = a2
        .max(b2)
        .max(c2)
        .floor()
        .min(Vec2::new(dims.y as f32, dims.z as f32) - 1.0);
    let nx = dims.x as f32;
    let mut z = lo.y;
    while z <= hi.y {
        let mut y = lo.x;
        while y <= hi.x {
            let r = Vec2::new(y, z);
            let (e0, e1, e2) = (edge(b2, c2, r), edge(c2, a2, r), edge(a2, b2, r));
            if covers(e0, c2 - b2) && covers(e1, a2 - c2) && covers(e2, b2 - a2) {
                let den = (e0 + e1) + e2;
                let x = ((e0 * a.x + e1 * b.x) + e2 * c.x) / den;
                let first = (x.clamp(-1.0, nx).floor() + 1.0).max(0.0);
                if den > 0.0 && first < nx {
                    let row = y as u32 + dims.y * z as u32;
                    out.push(row * dims.x + first as u32);
                }
            }
            y += 1.0;
        }
        z += 1.0;
    }
}

/// The bitset ([`imprint_core::field::bit`]) of the cells of `spec` whose centres lie inside
/// the closed mesh with vertices `verts` (grid coordinates, `GridSpec::to_cell`) and
/// `triangles`. Same bits for any thread count.
pub fn inside_cells(spec: &GridSpec, verts: &[Vec3], triangles: &[[u32; 3]]) -> Vec<u32> {
    let dims = spec.dims;
    let mut marks: Vec<u32> = triangles
        .par_chunks(TRIANGLES_PER_TASK)
        .flat_map_iter(|tris| {
            let mut out = Vec::new();
            for t in tris {
                crossings(t.map(|i| verts[i as usize]), dims, &mut out);
            }
            out
        })
        .collect();
    marks.par_sort_unstable();
    let mut words = vec![0u32; spec.len().div_ceil(32)];
    // Marks sorted by cell are sorted by row; within a row, cells between the 1st and 2nd
    // odd-count marks, the 3rd and 4th… are inside.
    let nx = dims.x as usize;
    let mut k = 0;
    while k < marks.len() {
        let row = marks[k] as usize / nx;
        let end = (row + 1) * nx;
        let mut open: Option<usize> = None;
        while k < marks.len() && (marks[k] as usize) < end {
            let cell = marks[k] as usize;
            let mut n = 0;
            while k < marks.len() && marks[k] as usize == cell {
                n += 1;
                k += 1;
            }
            if n % 2 == 1 {
                open = match open {
                    None => Some(cell),
                    Some(start) => {
                        set_range(&mut words, start, cell);
                        None
                    }
                };
            }
        }
        if let Some(start) = open {
            set_range(&mut words, start, end);
        }
    }
    words
}

/// Sets bits `start..end`.
fn set_range(words: &mut [u32], start: usize, end: usize) {
    for i in start..end {
        words[i / 32] |= 1 << (i % 32);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::drape::inside::InsideTest;
    use imprint_core::field::bit;
    use imprint_core::mesh::primitives;

    /// Every cell centre agrees with the exact three-ray inside test.
    fn agrees_with_rays(mesh: &Mesh, res: u32) {
        let spec = GridSpec::fit(&mesh.bounds(), res, 0.1).unwrap();
        let verts: Vec<Vec3> = mesh.positions.iter().map(|&p| spec.to_cell(p)).collect();
        let words = inside_cells(&spec, &verts, &mesh.triangles);
        let test = InsideTest::new(mesh);
        let mut inside = 0;
        for i in 0..spec.len() {
            let p = spec.center(spec.coords(i));
            assert_eq!(bit(&words, i), test.inside(p), "cell {i} at {p}");
            inside += bit(&words, i) as usize;
        }
        assert!(inside > 0);
    }

    #[test]
    fn a_sphere_and_a_box_on_grids_through_their_edges() {
        agrees_with_rays(&primitives::uv_sphere(1.0, 24, 16), 21);
        agrees_with_rays(&primitives::torus(1.0, 0.3, 32, 12), 40);
        // Vertices on cell centres and rows along the box's edges: the tie rules decide.
        let b = primitives::cuboid(Vec3::splat(0.5), 2);
        let spec = GridSpec::new(Vec3::splat(-1.0), 0.25, glam::UVec3::splat(9)).unwrap();
        let verts: Vec<Vec3> = b.positions.iter().map(|&p| spec.to_cell(p)).collect();
        let words = inside_cells(&spec, &verts, &b.triangles);
        for i in 0..spec.len() {
            let p = spec.center(spec.coords(i));
            let strictly = p.abs().max_element() < 0.5 - 1e-6;
            let on_surface = (p.abs().max_element() - 0.5).abs() < 1e-6;
            if !on_surface {
                assert_eq!(bit(&words, i), strictly, "cell {i} at {p}");
            }
        }
    }

    #[test]
    fn the_cow_with_its_horns() {
        let path = format!("{}/../../assets/meshes/cow.obj", env!("CARGO_MANIFEST_DIR"));
        let mesh = Mesh::load_obj(std::path::Path::new(&path)).unwrap();
        assert!(mesh.is_closed(), "the cow is open");
        agrees_with_rays(&mesh, 48);
    }
}
