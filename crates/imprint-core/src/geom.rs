//! Small geometric kernels shared by the voxeliser, the field and the exact reference.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// `x.floor()` as an integer, inlined: baseline x86-64 has no rounding instruction, so the
/// library `floorf` is a call, and range computations in the hot loops pay it per row.
/// Exact for |x| < 2^31.
#[inline(always)]
pub fn floor_i(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) > x { i - 1 } else { i }
}

/// `x.ceil()` as an integer, inlined (see [`floor_i`]).
#[inline(always)]
pub fn ceil_i(x: f32) -> i32 {
    let i = x as i32;
    if (i as f32) < x { i + 1 } else { i }
}

/// Axis-aligned box. `empty()` is the identity for `grow`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Aabb {
    pub min: Vec3,
    pub max: Vec3,
}

impl Aabb {
    pub fn empty() -> Self {
        Aabb {
            min: Vec3::splat(f32::INFINITY),
            max: Vec3::splat(f32::NEG_INFINITY),
        }
    }

    pub fn from_points(points: impl IntoIterator<Item = Vec3>) -> Self {
        let mut b = Self::empty();
        for p in points {
            b.grow(p);
        }
        b
    }

    pub fn grow(&mut self, p: Vec3) {
        self.min = self.min.min(p);
        self.max = self.max.max(p);
    }

    pub fn union(&self, o: &Aabb) -> Aabb {
        Aabb {
            min: self.min.min(o.min),
            max: self.max.max(o.max),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.min.cmpgt(self.max).any()
    }

    pub fn size(&self) -> Vec3 {
        self.max - self.min
    }

    pub fn center(&self) -> Vec3 {
        0.5 * (self.min + self.max)
    }

    /// Squared distance from `p` to the box (0 inside).
    pub fn distance_squared(&self, p: Vec3) -> f32 {
        let d = (self.min - p).max(p - self.max).max(Vec3::ZERO);
        d.length_squared()
    }
}

/// The point of triangle (a, b, c) closest to `p` (Ericson, Real-Time Collision Detection §5.1.5).
/// Degenerate triangles (zero area, repeated vertices) are handled: the result is then the
/// closest point on the segment or vertex they collapse to.
#[inline]
pub fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + v * ab;
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + w * ac;
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + w * (c - b);
    }
    let denom = va + vb + vc;
    if denom.abs() <= f32::MIN_POSITIVE || !denom.is_finite() {
        // Collinear vertices not caught above: fall back to the closest of the three edges.
        return closest_on_degenerate(p, a, b, c);
    }
    let inv = 1.0 / denom;
    let v = vb * inv;
    let w = vc * inv;
    a + ab * v + ac * w
}

/// Barycentric coordinates of `p` (assumed on the triangle's plane) in triangle `[a, b, c]`;
/// `[1, 0, 0]` for a zero-area triangle.
pub fn barycentric(p: Vec3, [a, b, c]: [Vec3; 3]) -> [f32; 3] {
    let (v0, v1, v2) = (b - a, c - a, p - a);
    let (d00, d01, d11) = (v0.dot(v0), v0.dot(v1), v1.dot(v1));
    let (d20, d21) = (v2.dot(v0), v2.dot(v1));
    let den = d00 * d11 - d01 * d01;
    if den == 0.0 {
        return [1.0, 0.0, 0.0];
    }
    let v = (d11 * d20 - d01 * d21) / den;
    let w = (d00 * d21 - d01 * d20) / den;
    [1.0 - v - w, v, w]
}

fn closest_on_segment(p: Vec3, a: Vec3, b: Vec3) -> Vec3 {
    let ab = b - a;
    let l2 = ab.length_squared();
    if l2 <= 0.0 {
        return a;
    }
    a + ab * ((p - a).dot(ab) / l2).clamp(0.0, 1.0)
}

fn closest_on_degenerate(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let cands = [
        closest_on_segment(p, a, b),
        closest_on_segment(p, b, c),
        closest_on_segment(p, c, a),
    ];
    let mut best = cands[0];
    for q in &cands[1..] {
        if (*q - p).length_squared() < (best - p).length_squared() {
            best = *q;
        }
    }
    best
}

/// Does triangle (a, b, c) touch the box `center ± half` (closed)? The separating-axis test of
/// Akenine-Möller (2001): 3 box axes, the triangle normal, and the 9 edge cross products.
/// Touching counts as overlap, so a triangle lying exactly on a cell face marks both cells.
#[inline]
pub fn triangle_box_overlap(center: Vec3, half: Vec3, a: Vec3, b: Vec3, c: Vec3) -> bool {
    let v0 = a - center;
    let v1 = b - center;
    let v2 = c - center;
    // Box axes.
    let mn = v0.min(v1).min(v2);
    let mx = v0.max(v1).max(v2);
    if mn.cmpgt(half).any() || mx.cmplt(-half).any() {
        return false;
    }
    let e0 = v1 - v0;
    let e1 = v2 - v1;
    let e2 = v0 - v2;
    // Nine edge/axis cross products.
    for e in [e0, e1, e2] {
        for axis in [
            Vec3::new(0.0, -e.z, e.y),
            Vec3::new(e.z, 0.0, -e.x),
            Vec3::new(-e.y, e.x, 0.0),
        ] {
            let p0 = axis.dot(v0);
            let p1 = axis.dot(v1);
            let p2 = axis.dot(v2);
            let r = half.x * axis.x.abs() + half.y * axis.y.abs() + half.z * axis.z.abs();
            let lo = p0.min(p1).min(p2);
            let hi = p0.max(p1).max(p2);
            if lo > r || hi < -r {
                return false;
            }
        }
    }
    // Triangle plane.
    let n = e0.cross(e1);
    let r = half.x * n.x.abs() + half.y * n.y.abs() + half.z * n.z.abs();
    let s = n.dot(v0);
    s.abs() <= r
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integer_floor_and_ceil_match_std() {
        for x in [
            -3.5f32,
            -3.0,
            -2.999,
            -0.2,
            -0.0,
            0.0,
            0.2,
            1.0,
            1.0001,
            7.5,
            1e6 + 0.5,
        ] {
            assert_eq!(floor_i(x), x.floor() as i32, "{x}");
            assert_eq!(ceil_i(x), x.ceil() as i32, "{x}");
        }
    }

    #[test]
    fn closest_point_regions() {
        let (a, b, c) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        // Face interior: projection.
        let q = closest_point_on_triangle(Vec3::new(0.25, 0.25, 2.0), a, b, c);
        assert!((q - Vec3::new(0.25, 0.25, 0.0)).length() < 1e-6);
        // Vertex region.
        assert_eq!(
            closest_point_on_triangle(Vec3::new(-1.0, -1.0, 0.5), a, b, c),
            a
        );
        // Edge region (hypotenuse).
        let q = closest_point_on_triangle(Vec3::new(1.0, 1.0, 0.0), a, b, c);
        assert!((q - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-6);
        // Degenerate: all three on a line; closest is on the segment a..b.
        let q = closest_point_on_triangle(Vec3::new(0.5, 1.0, 0.0), a, Vec3::X, Vec3::X * 0.5);
        assert!((q - Vec3::new(0.5, 0.0, 0.0)).length() < 1e-6);
        // Fully collapsed triangle.
        let q = closest_point_on_triangle(Vec3::ONE, b, b, b);
        assert_eq!(q, b);
    }

    #[test]
    fn box_overlap_cases() {
        let h = Vec3::splat(0.5);
        // A triangle lying exactly on the box face z = 0.5 touches the box.
        let z = 0.5;
        assert!(triangle_box_overlap(
            Vec3::ZERO,
            h,
            Vec3::new(-1.0, -1.0, z),
            Vec3::new(2.0, -1.0, z),
            Vec3::new(-1.0, 2.0, z)
        ));
        // Just beyond it does not.
        let z = 0.5001;
        assert!(!triangle_box_overlap(
            Vec3::ZERO,
            h,
            Vec3::new(-1.0, -1.0, z),
            Vec3::new(2.0, -1.0, z),
            Vec3::new(-1.0, 2.0, z)
        ));
        // A big triangle whose vertices are all outside but which cuts through the box.
        assert!(triangle_box_overlap(
            Vec3::ZERO,
            h,
            Vec3::new(-5.0, -5.0, 0.1),
            Vec3::new(5.0, -5.0, 0.1),
            Vec3::new(0.0, 5.0, 0.1)
        ));
        // A triangle whose bounding box overlaps the box but which misses it (diagonal).
        assert!(!triangle_box_overlap(
            Vec3::ZERO,
            h,
            Vec3::new(1.2, 0.0, 0.0),
            Vec3::new(0.0, 1.2, 0.0),
            Vec3::new(1.5, 1.5, 0.0)
        ));
    }
}
