//! An exact inside test for a closed mesh: the parity of the surface crossings of a ray.
//!
//! One ray per axis (+x, +y, +z) and a majority vote of the three, so that a ray grazing an
//! edge or lying in a face plane is outvoted by the other two. Each ray is answered in the
//! mesh's projection along its axis: the triangles are binned in a 2D grid of that
//! projection, and a triangle is crossed when its projection covers the point (a half-open
//! rule on edges, so a point on an edge shared by two triangles is counted by exactly one) and
//! its plane lies beyond the point along the axis. The cells are about square, the size of an
//! average triangle's projected box; a cell's list carries each triangle's projected box, which
//! rejects most of the list (by comparisons, without branches) before the exact test.
//!
//! Meaningful for closed (watertight) bodies, as is "inside". Pieces that touch along shared
//! faces (boxes stacked into a U) are fine: each shared face is crossed twice, which keeps the
//! parity. Pieces that overlap are not (a point inside two of them counts as outside).
//!
//! A coarse voxel grid over the body answers most points without a ray (same answers): a
//! cell no triangle's bounding box comes near (a margin around the cell) lies in one
//! surface-free region with its face-adjacent far cells, and for a mesh whose edges each
//! border an even number of triangles (a closed surface, or several) the ray parity is the
//! same at every point of such a region. Each region is decided by the exact test at a few of
//! its cell centres (and left to the exact test when they disagree); points in near cells,
//! beyond the grid, or of a mesh that is not closed take the exact test.

use glam::{DVec2, DVec3, Vec2, Vec3, Vec4};
use imprint_core::{Aabb, Mesh};

/// The inside test of one closed mesh.
pub struct InsideTest {
    axes: [AxisGrid; 3],
    cells: Option<CellGrid>,
}

/// Voxel states: near the surface (ask the rays), inside, outside.
const NEAR: u8 = 0;
const INSIDE: u8 = 1;
const OUTSIDE: u8 = 2;

/// The voxel grid of far cells with their answers.
struct CellGrid {
    min: DVec3,
    inv: f64,
    n: [usize; 3],
    state: Vec<u8>,
}

impl CellGrid {
    fn index(&self, p: Vec3) -> Option<usize> {
        let f = (p.as_dvec3() - self.min) * self.inv;
        let n = self.n.map(|k| k as f64);
        if !(f.x >= 0.0 && f.y >= 0.0 && f.z >= 0.0 && f.x < n[0] && f.y < n[1] && f.z < n[2]) {
            return None;
        }
        let (i, j, k) = (f.x as usize, f.y as usize, f.z as usize);
        Some((k * self.n[1] + j) * self.n[0] + i)
    }

    /// The grid of `tris` (all finite) within `bounds` with its far cells (not yet decided) and
    /// their regions: face-adjacent far cells, in scan order.
    fn far_regions(tris: &[[Vec3; 3]], bounds: &Aabb) -> Option<(Self, Vec<Vec<u32>>)> {
        let ext = (bounds.max - bounds.min).as_dvec3();
        let longest = ext.max_element();
        if !(longest > 0.0 && longest.is_finite()) {
            return None;
        }
        let res = ((tris.len() as f64).cbrt() * 3.0).clamp(16.0, 128.0);
        let cell = longest / res;
        // One padding cell on each side, so that points just outside the body hit far cells.
        let min = bounds.min.as_dvec3() - DVec3::splat(cell);
        let n = [0, 1, 2].map(|a| ((ext[a] / cell).ceil() as usize).max(1) + 2);
        let inv = 1.0 / cell;
        let margin = 0.05 * cell;
        let total = n[0] * n[1] * n[2];
        let mut state = vec![OUTSIDE; total];
        let clampi = |x: f64, a: usize| (x.floor().max(0.0) as usize).min(n[a] - 1);
        for t in tris {
            let lo = t[0].min(t[1]).min(t[2]).as_dvec3() - DVec3::splat(margin);
            let hi = t[0].max(t[1]).max(t[2]).as_dvec3() + DVec3::splat(margin);
            let l = [0, 1, 2].map(|a| clampi((lo[a] - min[a]) * inv, a));
            let h = [0, 1, 2].map(|a| clampi((hi[a] - min[a]) * inv, a));
            for k in l[2]..=h[2] {
                for j in l[1]..=h[1] {
                    for i in l[0]..=h[0] {
                        state[(k * n[1] + j) * n[0] + i] = NEAR;
                    }
                }
            }
        }
        // Regions of face-adjacent far cells, in scan order.
        let mut label = vec![u32::MAX; total];
        let mut regions: Vec<Vec<u32>> = Vec::new();
        let mut stack = Vec::new();
        for start in 0..total {
            if state[start] == NEAR || label[start] != u32::MAX {
                continue;
            }
            let r = regions.len() as u32;
            let mut cells = Vec::new();
            label[start] = r;
            stack.push(start);
            while let Some(c) = stack.pop() {
                cells.push(c as u32);
                let i = c % n[0];
                let j = (c / n[0]) % n[1];
                let k = c / (n[0] * n[1]);
                let mut visit = |d: usize| {
                    if state[d] != NEAR && label[d] == u32::MAX {
                        label[d] = r;
                        stack.push(d);
                    }
                };
                if i > 0 {
                    visit(c - 1);
                }
                if i + 1 < n[0] {
                    visit(c + 1);
                }
                if j > 0 {
                    visit(c - n[0]);
                }
                if j + 1 < n[1] {
                    visit(c + n[0]);
                }
                if k > 0 {
                    visit(c - n[0] * n[1]);
                }
                if k + 1 < n[2] {
                    visit(c + n[0] * n[1]);
                }
            }
            regions.push(cells);
        }
        Some((CellGrid { min, inv, n, state }, regions))
    }

    /// Decides each far region by `exact` at up to three of its cell centres (first, middle,
    /// last found), which must agree; a region where they do not is left to the exact test.
    fn decide(&mut self, regions: &[Vec<u32>], exact: impl Fn(Vec3) -> bool) {
        let n = self.n;
        let centre = |c: usize| {
            let ijk = DVec3::new(
                (c % n[0]) as f64,
                ((c / n[0]) % n[1]) as f64,
                (c / (n[0] * n[1])) as f64,
            );
            (self.min + (ijk + 0.5) / self.inv).as_vec3()
        };
        for cells in regions {
            let picks = [0, cells.len() / 2, cells.len() - 1];
            let answers = picks.map(|k| exact(centre(cells[k] as usize)));
            let s = if answers.iter().all(|&a| a == answers[0]) {
                if answers[0] { INSIDE } else { OUTSIDE }
            } else {
                NEAR
            };
            for &c in cells {
                self.state[c as usize] = s;
            }
        }
    }
}

impl InsideTest {
    /// The test with its voxel grid of far cells: worth it for many queries spread through
    /// and around the body.
    pub fn new(mesh: &Mesh) -> Self {
        let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        let bounds = mesh.bounds();
        // The three axes' bins and the grid's far regions are independent: built side by side.
        let (axes, far) = rayon::join(
            || AxisGrid::all(&tris, &bounds),
            || {
                let finite = tris.iter().flatten().all(|v| v.is_finite());
                if finite && !tris.is_empty() && !bounds.is_empty() && mesh.is_closed() {
                    CellGrid::far_regions(&tris, &bounds)
                } else {
                    None
                }
            },
        );
        let mut test = InsideTest { axes, cells: None };
        if let Some((mut grid, regions)) = far {
            grid.decide(&regions, |p| test.exact(p));
            test.cells = Some(grid);
        }
        test
    }

    /// The test by the rays alone (same answers as [`InsideTest::new`]'s): for queries near
    /// the surface (a garment on a body), which the grid would leave to the rays anyway, at
    /// about half the set-up cost.
    pub fn rays_only(mesh: &Mesh) -> Self {
        let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        InsideTest {
            axes: AxisGrid::all(&tris, &mesh.bounds()),
            cells: None,
        }
    }

    /// Whether `p` is inside the body (two of the three rays cross its surface an odd number
    /// of times).
    /// A point exactly on the surface (a ray meets a triangle at the point itself) is outside.
    pub fn inside(&self, p: Vec3) -> bool {
        if let Some(g) = &self.cells
            && let Some(c) = g.index(p)
        {
            match g.state[c] {
                INSIDE => return true,
                OUTSIDE => return false,
                _ => {}
            }
        }
        self.exact(p)
    }

    /// The parity of the surface crossings of the one ray from `p` along +x (T's fill test,
    /// which projects the triangles on the y-z plane and counts them along x): `Some(true)`
    /// when odd (inside a closed mesh), `None` when `p` lies on a triangle the ray meets.
    /// Edges are owned half-open, so a ray through an edge shared by two triangles, or
    /// through a vertex, counts one crossing there.
    pub fn odd_along_x(&self, p: Vec3) -> Option<bool> {
        self.axes[0].odd_crossings(p)
    }

    /// The surface crossings of the ray from `p` along axis `axis` (0, 1, 2 for x, y, z),
    /// towards + when `positive`: the distances of those within `reach` of `p` go to `out`
    /// (cleared first; unsorted); returns the parity of all of them (odd: inside by this one
    /// ray), `None` when `p` lies on a triangle the ray meets. One walk of the triangle list of
    /// the cell `p` projects into (what [`InsideTest::exact`] reads for that axis).
    pub fn ray_crossings(
        &self,
        p: Vec3,
        axis: usize,
        positive: bool,
        reach: f64,
        out: &mut Vec<f64>,
    ) -> Option<bool> {
        out.clear();
        let mut ray = Ray::new(p[axis] as f64, positive, reach);
        match self.axes[axis].each_hit(p, |w| ray.add(w, out)) {
            Some(false) => None,
            _ => Some(ray.odd),
        }
    }

    /// [`InsideTest::ray_crossings`] at the point `lines` were kept for, read from them.
    pub fn ray_crossings_kept(
        &self,
        lines: &Lines,
        axis: usize,
        positive: bool,
        reach: f64,
        out: &mut Vec<f64>,
    ) -> Option<bool> {
        out.clear();
        let mut ray = Ray::new(lines.at[axis] as f64, positive, reach);
        lines.w[axis]
            .iter()
            .all(|&w| ray.add(w, out))
            .then_some(ray.odd)
    }

    /// [`InsideTest::exact`] at `p`, keeping the crossings of the three axis lines through
    /// `p` in `lines` (complete when `p` is inside) for [`InsideTest::exact_on_lines`] and
    /// [`InsideTest::ray_crossings_kept`].
    pub fn exact_keeping(&self, p: Vec3, lines: &mut Lines) -> bool {
        lines.at = p;
        let mut votes = 0;
        for (g, kept) in self.axes.iter().zip(&mut lines.w) {
            kept.clear();
            let pw = p[g.axis] as f64;
            let mut odd = false;
            let all = g.each_hit(p, |w| {
                kept.push(w);
                odd ^= w > pw;
                w != pw
            });
            if all == Some(false) {
                return false;
            }
            votes += odd as u32;
        }
        votes >= 2
    }

    /// [`InsideTest::exact`] at `q`, reading the ray along an axis from `lines` where `q` lies
    /// on that axis's line through the point they were kept for (its other two coordinates
    /// the same): a point pushed along an axis needs two walks, not three.
    pub fn exact_on_lines(&self, q: Vec3, lines: &Lines) -> bool {
        let mut votes = 0;
        for g in &self.axes {
            let on_line =
                g.uv.iter()
                    .all(|&a| q[a].to_bits() == lines.at[a].to_bits());
            let odd = if on_line {
                let qw = q[g.axis] as f64;
                let w = &lines.w[g.axis];
                (!w.contains(&qw)).then(|| w.iter().filter(|&&w| w > qw).count() % 2 == 1)
            } else {
                g.odd_crossings(q)
            };
            match odd {
                None => return false,
                Some(odd) => votes += odd as u32,
            }
        }
        votes >= 2
    }

    /// [`InsideTest::inside`] by the three rays, without the voxel grid.
    pub fn exact(&self, p: Vec3) -> bool {
        let mut votes = 0;
        for g in &self.axes {
            match g.odd_crossings(p) {
                None => return false,
                Some(odd) => votes += odd as u32,
            }
        }
        votes >= 2
    }

    /// [`InsideTest::exact`] at a point where the ray along `axis` is known to cross the
    /// surface an even number of times: inside only when both other rays cross it an odd
    /// number of times (neither lying on the surface). One or two rays instead of three.
    pub fn exact_even_along(&self, p: Vec3, axis: usize) -> bool {
        [1, 2]
            .into_iter()
            .all(|k| self.axes[(axis + k) % 3].odd_crossings(p) == Some(true))
    }
}

/// The crossings of the three axis lines through one point (axis coordinates, both ways from
/// it, in list order), kept by [`InsideTest::exact_keeping`].
#[derive(Default)]
pub struct Lines {
    at: Vec3,
    w: [Vec<f64>; 3],
}

/// The crossings of one ray as [`InsideTest::ray_crossings`] gathers them.
struct Ray {
    from: f64,
    positive: bool,
    reach: f64,
    odd: bool,
}

impl Ray {
    fn new(from: f64, positive: bool, reach: f64) -> Self {
        Ray {
            from,
            positive,
            reach,
            odd: false,
        }
    }

    /// Takes the crossing of the line at `w`; false when it is the ray's origin.
    #[inline]
    fn add(&mut self, w: f64, out: &mut Vec<f64>) -> bool {
        let s = if self.positive {
            w - self.from
        } else {
            self.from - w
        };
        if s > 0.0 {
            self.odd = !self.odd;
            if s <= self.reach {
                out.push(s);
            }
        }
        s != 0.0
    }
}

/// The triangles projected along one axis, binned in a 2D grid of about square cells.
struct AxisGrid {
    axis: usize,
    /// The two other axes (u, v).
    uv: [usize; 2],
    min: DVec2,
    cell: DVec2,
    n: [usize; 2],
    /// Triangle lists per cell, as ranges into `boxes` and `items`.
    starts: Vec<u32>,
    /// Per list entry, the triangle's projected box as (lo.u, lo.v, −hi.u, −hi.v): the
    /// projection r lies in it when (r.u, r.v, −r.u, −r.v) is not below it, one 4-wide
    /// comparison. Read before the triangle itself: most of a list is rejected from this one
    /// contiguous stream.
    boxes: Vec<Vec4>,
    /// Per list entry, the triangle.
    items: Vec<u32>,
    tris: Vec<Tri2>,
}

/// A cell's side in average projected triangle boxes: finer cells mean shorter lists (fewer
/// triangles to reject per query) but more entries to build, as each triangle is listed in
/// every cell its box meets.
const CELL_PER_EXTENT: f64 = 1.0;
/// Most cells per triangle kept (a few large triangles among many small ones).
const MAX_CELLS_PER_TRIANGLE: f64 = 4.0;
/// Most cells along one side of an axis grid.
const MAX_SIDE: usize = 4096;

/// A triangle as its ray sees it: counter-clockwise projection and the axis coordinate of
/// its corners. Kept in f32, as the mesh gives them (half the memory the queries read; the
/// arithmetic is in f64, from the same values).
#[derive(Clone, Copy)]
struct Tri2 {
    p: [Vec2; 3],
    w: [f32; 3],
}

impl Tri2 {
    #[inline]
    fn p(&self, k: usize) -> DVec2 {
        self.p[k].as_dvec2()
    }
}

impl AxisGrid {
    /// The grids of the three axes, built side by side.
    fn all(tris: &[[Vec3; 3]], bounds: &Aabb) -> [Self; 3] {
        let (x, (y, z)) = rayon::join(
            || AxisGrid::new(tris, bounds, 0),
            || {
                rayon::join(
                    || AxisGrid::new(tris, bounds, 1),
                    || AxisGrid::new(tris, bounds, 2),
                )
            },
        );
        [x, y, z]
    }

    fn new(tris: &[[Vec3; 3]], bounds: &Aabb, axis: usize) -> Self {
        let uv = [(axis + 1) % 3, (axis + 2) % 3];
        let proj = |v: Vec3| DVec2::new(v[uv[0]] as f64, v[uv[1]] as f64);
        let mut kept = Vec::with_capacity(tris.len());
        for t in tris {
            let mut p = t.map(|v| Vec2::new(v[uv[0]], v[uv[1]]));
            let mut w = t.map(|v| v[axis]);
            let d = p.map(|q| q.as_dvec2());
            let area = (d[1] - d[0]).perp_dot(d[2] - d[0]);
            if area == 0.0 || !area.is_finite() {
                continue; // parallel to the ray: never crossed
            }
            if area < 0.0 {
                p.swap(1, 2);
                w.swap(1, 2);
            }
            kept.push(Tri2 { p, w });
        }
        let min = if bounds.is_empty() {
            DVec2::ZERO
        } else {
            proj(bounds.min)
        };
        let size = if bounds.is_empty() {
            DVec2::ONE
        } else {
            (proj(bounds.max) - min).max(DVec2::splat(1e-9))
        };
        // About square cells the size of an average triangle's projected box: a triangle is
        // listed in a few cells whatever the projection's aspect (a torus seen edge-on is a
        // long thin band), and a cell's list holds a few layers' worth of triangles.
        let extent: f64 = kept
            .iter()
            .map(|t| {
                let d = t.p[0].max(t.p[1]).max(t.p[2]) - t.p[0].min(t.p[1]).min(t.p[2]);
                d.max_element() as f64
            })
            .sum::<f64>()
            / kept.len().max(1) as f64;
        let fine = (size.x * size.y / (kept.len() as f64 * MAX_CELLS_PER_TRIANGLE).max(1.0)).sqrt();
        let side = (CELL_PER_EXTENT * extent).max(fine);
        let n = [0, 1].map(|a| ((size[a] / side).ceil() as usize).clamp(1, MAX_SIDE));
        let cell = size / DVec2::new(n[0] as f64, n[1] as f64);
        // `as` truncates, which is the floor for c >= 0 (and 0 below, as the clamp would be).
        let cell_of = |q: DVec2| {
            let c = (q - min) / cell;
            [
                (c.x.max(0.0) as usize).min(n[0] - 1),
                (c.y.max(0.0) as usize).min(n[1] - 1),
            ]
        };
        let mut counts = vec![0u32; n[0] * n[1] + 1];
        let mut boxes: Vec<(Vec2, Vec2, [usize; 2], [usize; 2])> = kept
            .iter()
            .map(|t| {
                let lo = t.p[0].min(t.p[1]).min(t.p[2]);
                let hi = t.p[0].max(t.p[1]).max(t.p[2]);
                (lo, hi, cell_of(lo.as_dvec2()), cell_of(hi.as_dvec2()))
            })
            .collect();
        // The triangles in the order of the cells their boxes start in: a query reads the
        // triangles of a few neighbouring cells, then close together in memory, not spread
        // over the mesh's order. (The answers do not depend on the order of a list.)
        let mut order: Vec<u32> = (0..kept.len() as u32).collect();
        order.sort_by_key(|&t| {
            let l = boxes[t as usize].2;
            l[1] * n[0] + l[0]
        });
        kept = order.iter().map(|&t| kept[t as usize]).collect();
        boxes = order.iter().map(|&t| boxes[t as usize]).collect();
        for (_, _, l, h) in &boxes {
            for j in l[1]..=h[1] {
                for c in &mut counts[j * n[0] + l[0] + 1..=j * n[0] + h[0] + 1] {
                    *c += 1;
                }
            }
        }
        for k in 1..counts.len() {
            counts[k] += counts[k - 1];
        }
        let mut fill = counts.clone();
        let total = *counts.last().unwrap() as usize;
        let (mut entry_boxes, mut items) = (vec![Vec4::ZERO; total], vec![0u32; total]);
        for (t, &(lo, hi, l, h)) in boxes.iter().enumerate() {
            let b = Vec4::new(lo.x, lo.y, -hi.x, -hi.y);
            for j in l[1]..=h[1] {
                for c in j * n[0] + l[0]..=j * n[0] + h[0] {
                    entry_boxes[fill[c] as usize] = b;
                    items[fill[c] as usize] = t as u32;
                    fill[c] += 1;
                }
            }
        }
        AxisGrid {
            axis,
            uv,
            min,
            cell,
            n,
            starts: counts,
            boxes: entry_boxes,
            items,
            tris: kept,
        }
    }

    /// Calls `visit` with the axis coordinate of each place where the line through `p` along
    /// the axis crosses a triangle (both ways from `p`, in no particular order) until it
    /// returns false; `None` beyond the box (no triangle there), else whether all were
    /// visited. A triangle whose projected box does not hold `p`'s projection is not crossed
    /// (the premise of the binning, taken down from cells to single boxes).
    #[inline]
    fn each_hit(&self, p: Vec3, mut visit: impl FnMut(f64) -> bool) -> Option<bool> {
        let r = Vec2::new(p[self.uv[0]], p[self.uv[1]]);
        let q = r.as_dvec2();
        let c = ((q - self.min) / self.cell).floor();
        // Beyond the box: no triangle. On its far side: the last cell (as the binning clamps).
        if !(c.x >= 0.0 && c.y >= 0.0 && c.x <= self.n[0] as f64 && c.y <= self.n[1] as f64) {
            return None;
        }
        let cell =
            (c.y as usize).min(self.n[1] - 1) * self.n[0] + (c.x as usize).min(self.n[0] - 1);
        let range = self.starts[cell] as usize..self.starts[cell + 1] as usize;
        let key = Vec4::new(r.x, r.y, -r.x, -r.y);
        // 32 boxes at a time into a bit mask, without a branch per box (whether a box holds
        // the point is a coin toss the branch predictor loses), then the triangles of the set
        // bits.
        for (boxes, items) in self.boxes[range.clone()]
            .chunks(32)
            .zip(self.items[range].chunks(32))
        {
            let mut mask = boxes.iter().enumerate().fold(0u32, |m, (k, b)| {
                m | ((b.cmple(key).bitmask() == 0b1111) as u32) << k
            });
            while mask != 0 {
                let k = mask.trailing_zeros() as usize;
                mask &= mask - 1;
                if let Some(w) = crossing(&self.tris[items[k] as usize], q)
                    && !visit(w)
                {
                    return Some(false);
                }
            }
        }
        Some(true)
    }

    /// Whether the ray from `p` along the axis crosses the surface an odd number of times;
    /// `None` when `p` lies on a triangle the ray meets.
    fn odd_crossings(&self, p: Vec3) -> Option<bool> {
        let pw = p[self.axis] as f64;
        let mut odd = false;
        match self.each_hit(p, |w| {
            odd ^= w > pw;
            w != pw
        }) {
            Some(false) => None,
            _ => Some(odd),
        }
    }
}

/// Where the ray through `q` crosses the triangle (its axis coordinate), if it does. An edge
/// owns the points on it when it runs "up" (dv > 0, or dv = 0 and du < 0): of two triangles
/// sharing an edge (traversed in opposite directions), exactly one owns it.
#[inline]
fn crossing(t: &Tri2, q: DVec2) -> Option<f64> {
    // All three edges, then one branch: which edge rejects a point is unpredictable, and a
    // mispredicted branch costs more than the arithmetic it skips.
    let edge = |k: usize| {
        let a = t.p((k + 1) % 3);
        let c = t.p((k + 2) % 3);
        let d = c - a;
        let e = d.perp_dot(q - a);
        let owns = d.y > 0.0 || (d.y == 0.0 && d.x < 0.0);
        (e, e > 0.0 || (e == 0.0 && owns))
    };
    let ((e0, k0), (e1, k1), (e2, k2)) = (edge(0), edge(1), edge(2));
    let sum = e0 + e1 + e2;
    if !(k0 & k1 & k2 & (sum > 0.0)) {
        return None;
    }
    let w = t.w.map(f64::from);
    Some((e0 * w[0] + e1 * w[1] + e2 * w[2]) / sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::{cuboid, torus, uv_sphere};

    /// A deterministic generator of uniform numbers in [0, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        fn vec(&mut self) -> Vec3 {
            Vec3::new(self.next(), self.next(), self.next())
        }
    }

    /// A uniform point on a random triangle of `mesh`.
    fn point_on(mesh: &Mesh, rng: &mut Rng) -> Vec3 {
        let tri = mesh.triangle((rng.next() * mesh.triangles.len() as f32) as usize);
        let (u, v) = (rng.next(), rng.next());
        let (u, v) = if u + v > 1.0 {
            (1.0 - u, 1.0 - v)
        } else {
            (u, v)
        };
        tri[0] + u * (tri[1] - tri[0]) + v * (tri[2] - tri[0])
    }

    fn boxed(min: Vec3, max: Vec3) -> Mesh {
        let mut m = cuboid(0.5 * (max - min), 2);
        let c = 0.5 * (min + max);
        for p in &mut m.positions {
            *p += c;
        }
        m
    }

    /// Checks the grid's answers against the rays on random points in and around the bounds,
    /// on the triangles, near them (several scales) and at the vertices; returns the share of
    /// the points the grid answered.
    fn same_as_exact(mesh: &Mesh, seed: u64) -> f64 {
        let t = InsideTest::new(mesh);
        let grid = t.cells.as_ref().expect("closed mesh: grid built");
        let b = mesh.bounds();
        let (lo, size) = (b.min - 0.2 * (b.max - b.min), 1.4 * (b.max - b.min));
        let mut rng = Rng(seed);
        let mut points: Vec<Vec3> = mesh.positions.clone();
        for _ in 0..100_000 {
            points.push(lo + rng.vec() * size);
        }
        for _ in 0..100_000 {
            let on = point_on(mesh, &mut rng);
            points.push(on);
            let scale = [1e-1, 1e-2, 1e-3, 1e-5, 1e-7][(rng.next() * 5.0) as usize];
            points.push(on + (rng.vec() - 0.5) * scale);
        }
        // Points on a lattice (grazing rays through edges and face planes of boxes).
        for i in 0..=24 {
            for j in 0..=24 {
                for k in 0..=24 {
                    points.push(lo + Vec3::new(i as f32, j as f32, k as f32) / 24.0 * size);
                }
            }
        }
        let mut fast = 0usize;
        for &p in &points {
            assert_eq!(t.inside(p), t.exact(p), "{p:?}");
            if grid.index(p).is_some_and(|c| grid.state[c] != NEAR) {
                fast += 1;
            }
        }
        fast as f64 / points.len() as f64
    }

    #[test]
    fn grid_answers_equal_exact() {
        let tor = same_as_exact(&torus(0.5, 0.2, 250, 100), 1);
        let cube = same_as_exact(&cuboid(Vec3::new(0.5, 0.3, 0.2), 4), 2);
        let mut u = boxed(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.3, 0.8));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.0), Vec3::new(0.5, 1.0, 0.6)));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.7), Vec3::new(0.5, 1.0, 0.8)));
        let ub = same_as_exact(&u, 3);
        // The grid does answer a good share (not only the rays).
        for share in [tor, cube, ub] {
            assert!(share > 0.05, "{tor} {cube} {ub}");
        }
    }

    /// The bins and the boxes drop only triangles the ray cannot cross: each axis's answer
    /// equals that of a walk over all its triangles, at random points, on and near the
    /// triangles (several scales) and at the vertices.
    #[test]
    fn bins_answer_as_all_triangles() {
        let mut u = boxed(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.3, 0.8));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.0), Vec3::new(0.5, 1.0, 0.6)));
        for (mesh, seed) in [(torus(0.5, 0.2, 60, 24), 5), (u, 6)] {
            let t = InsideTest::rays_only(&mesh);
            let b = mesh.bounds();
            let (lo, size) = (b.min - 0.1 * (b.max - b.min), 1.2 * (b.max - b.min));
            let mut rng = Rng(seed);
            let mut points: Vec<Vec3> = mesh.positions.clone();
            for _ in 0..4_000 {
                points.push(lo + rng.vec() * size);
                let on = point_on(&mesh, &mut rng);
                points.push(on);
                let scale = [1e-2, 1e-4, 1e-6, 1e-7][(rng.next() * 4.0) as usize];
                points.push(on + (rng.vec() - 0.5) * scale);
            }
            for g in &t.axes {
                for &p in &points {
                    let q = DVec2::new(p[g.uv[0]] as f64, p[g.uv[1]] as f64);
                    let pw = p[g.axis] as f64;
                    let mut all = Some(false);
                    for tri in &g.tris {
                        match crossing(tri, q) {
                            Some(w) if w == pw => {
                                all = None;
                                break;
                            }
                            Some(w) if w > pw => all = all.map(|o| !o),
                            _ => {}
                        }
                    }
                    assert_eq!(g.odd_crossings(p), all, "axis {} at {p:?}", g.axis);
                }
            }
        }
    }

    #[test]
    fn open_mesh_has_no_grid() {
        let mut m = cuboid(Vec3::splat(0.5), 2);
        m.triangles.pop();
        assert!(InsideTest::new(&m).cells.is_none());
    }

    #[test]
    fn sphere_and_touching_boxes() {
        let s = InsideTest::new(&uv_sphere(1.0, 32, 16));
        assert!(s.inside(Vec3::ZERO));
        assert!(s.inside(Vec3::new(0.3, -0.5, 0.6)));
        assert!(!s.inside(Vec3::new(0.8, 0.8, 0.0)));
        assert!(!s.inside(Vec3::new(3.0, 0.0, 0.0)));
        // Two unit boxes sharing the face x = 0: the shared face is crossed twice.
        let mut m = cuboid(Vec3::splat(0.5), 3);
        let mut right = m.clone();
        for p in &mut m.positions {
            p.x -= 0.5;
        }
        for p in &mut right.positions {
            p.x += 0.5;
        }
        m.append(&right);
        let t = InsideTest::new(&m);
        for x in [-0.9, -0.5 + 1e-3, 0.1, 0.7] {
            assert!(t.inside(Vec3::new(x, 0.1, -0.2)), "{x}");
        }
        assert!(!t.inside(Vec3::new(1.2, 0.0, 0.0)));
        // Exactly on the surface: outside.
        assert!(!t.inside(Vec3::new(1.0, 0.0, 0.0)));
    }
}
