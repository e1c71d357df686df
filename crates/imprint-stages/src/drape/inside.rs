//! An exact inside test for a closed mesh: the parity of the surface crossings of a ray.
//!
//! One ray per axis (+x, +y, +z) and a majority vote of the three, so that a ray grazing an
//! edge or lying in a face plane is outvoted by the other two. Each ray is answered in the
//! mesh's projection along its axis: the triangles are binned in a 2D grid of that
//! projection, and a triangle is crossed when its projection covers the point (a half-open
//! rule on edges, so a point on an edge shared by two triangles is counted by exactly one) and
//! its plane lies beyond the point along the axis.
//!
//! Meaningful for closed (watertight) bodies, as is "inside". Pieces that touch along shared
//! faces (boxes stacked into a U) are fine: each shared face is crossed twice, which keeps the
//! parity. Pieces that overlap are not (a point inside two of them counts as outside).

use glam::{DVec2, Vec3};
use imprint_core::{Aabb, Mesh};

/// The inside test of one closed mesh.
pub struct InsideTest {
    axes: [AxisGrid; 3],
}

impl InsideTest {
    pub fn new(mesh: &Mesh) -> Self {
        let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        let bounds = mesh.bounds();
        InsideTest {
            axes: [0, 1, 2].map(|a| AxisGrid::new(&tris, &bounds, a)),
        }
    }

    /// Whether `p` is inside the body (two of the three rays cross its surface an odd number
    /// of times).
    /// A point exactly on the surface (a ray meets a triangle at the point itself) is outside.
    pub fn inside(&self, p: Vec3) -> bool {
        let mut votes = 0;
        for g in &self.axes {
            match g.odd_crossings(p) {
                None => return false,
                Some(odd) => votes += odd as u32,
            }
        }
        votes >= 2
    }
}

/// The triangles projected along one axis, binned in a square-ish 2D grid.
struct AxisGrid {
    axis: usize,
    /// The two other axes (u, v).
    uv: [usize; 2],
    min: DVec2,
    cell: DVec2,
    n: [usize; 2],
    /// Triangle lists per cell, as ranges into `items`.
    starts: Vec<u32>,
    items: Vec<u32>,
    tris: Vec<Tri2>,
}

/// A triangle as its ray sees it: counter-clockwise projection and the axis coordinate of
/// its corners.
#[derive(Clone, Copy)]
struct Tri2 {
    p: [DVec2; 3],
    w: [f64; 3],
}

impl AxisGrid {
    fn new(tris: &[[Vec3; 3]], bounds: &Aabb, axis: usize) -> Self {
        let uv = [(axis + 1) % 3, (axis + 2) % 3];
        let proj = |v: Vec3| DVec2::new(v[uv[0]] as f64, v[uv[1]] as f64);
        let mut kept = Vec::with_capacity(tris.len());
        for t in tris {
            let mut p = t.map(proj);
            let mut w = t.map(|v| v[axis] as f64);
            let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
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
        let side = ((kept.len() as f64).sqrt().ceil() as usize).clamp(1, 256);
        let n = [side, side];
        let cell = size / DVec2::new(n[0] as f64, n[1] as f64);
        let cell_of = |q: DVec2| {
            let c = ((q - min) / cell).floor();
            [
                (c.x.max(0.0) as usize).min(n[0] - 1),
                (c.y.max(0.0) as usize).min(n[1] - 1),
            ]
        };
        let mut counts = vec![0u32; n[0] * n[1] + 1];
        let ranges: Vec<([usize; 2], [usize; 2])> = kept
            .iter()
            .map(|t| {
                let lo = t.p[0].min(t.p[1]).min(t.p[2]);
                let hi = t.p[0].max(t.p[1]).max(t.p[2]);
                (cell_of(lo), cell_of(hi))
            })
            .collect();
        for (lo, hi) in &ranges {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    counts[j * n[0] + i + 1] += 1;
                }
            }
        }
        for k in 1..counts.len() {
            counts[k] += counts[k - 1];
        }
        let mut fill = counts.clone();
        let mut items = vec![0u32; *counts.last().unwrap() as usize];
        for (t, (lo, hi)) in ranges.iter().enumerate() {
            for j in lo[1]..=hi[1] {
                for i in lo[0]..=hi[0] {
                    let c = j * n[0] + i;
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
            items,
            tris: kept,
        }
    }

    /// Whether the ray from `p` along the axis crosses the surface an odd number of times;
    /// `None` when `p` lies on a triangle the ray meets.
    fn odd_crossings(&self, p: Vec3) -> Option<bool> {
        let q = DVec2::new(p[self.uv[0]] as f64, p[self.uv[1]] as f64);
        let c = ((q - self.min) / self.cell).floor();
        // Beyond the box: no triangle. On its far side: the last cell (as the binning clamps).
        if !(c.x >= 0.0 && c.y >= 0.0 && c.x <= self.n[0] as f64 && c.y <= self.n[1] as f64) {
            return Some(false);
        }
        let cell =
            (c.y as usize).min(self.n[1] - 1) * self.n[0] + (c.x as usize).min(self.n[0] - 1);
        let range = self.starts[cell] as usize..self.starts[cell + 1] as usize;
        let pw = p[self.axis] as f64;
        let mut odd = false;
        for &t in &self.items[range] {
            let t = &self.tris[t as usize];
            match crossing(t, q) {
                Some(w) if w == pw => return None,
                Some(w) if w > pw => odd = !odd,
                _ => {}
            }
        }
        Some(odd)
    }
}

/// Where the ray through `q` crosses the triangle (its axis coordinate), if it does. An edge
/// owns the points on it when it runs "up" (dv > 0, or dv = 0 and du < 0): of two triangles
/// sharing an edge (traversed in opposite directions), exactly one owns it.
fn crossing(t: &Tri2, q: DVec2) -> Option<f64> {
    let mut b = [0f64; 3];
    for (k, bk) in b.iter_mut().enumerate() {
        let a = t.p[(k + 1) % 3];
        let c = t.p[(k + 2) % 3];
        let d = c - a;
        let e = d.perp_dot(q - a);
        let owns = d.y > 0.0 || (d.y == 0.0 && d.x < 0.0);
        if e < 0.0 || (e == 0.0 && !owns) {
            return None;
        }
        *bk = e;
    }
    let sum = b[0] + b[1] + b[2];
    if sum <= 0.0 {
        return None;
    }
    Some((b[0] * t.w[0] + b[1] * t.w[1] + b[2] * t.w[2]) / sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::{cuboid, uv_sphere};

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
