//! A bounding-volume hierarchy over a mesh's triangles for exact closest-point queries.
//! It is the reference: every field error in imprint is measured against it.

use crate::geom::closest_point_on_triangle;
use crate::{Aabb, Mesh};
use glam::Vec3;

const LEAF_SIZE: usize = 4;

#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: Aabb,
    /// Leaf: first triangle in `order`; inner: index of the left child (right = left + 1).
    start: u32,
    /// Leaf: triangle count (> 0); inner: 0.
    count: u32,
}

pub struct Bvh {
    nodes: Vec<Node>,
    order: Vec<u32>,
    tris: Vec<[Vec3; 3]>,
}

/// Result of a closest-point query.
#[derive(Clone, Copy, Debug)]
pub struct Closest {
    pub point: Vec3,
    pub distance: f32,
    pub triangle: u32,
}

impl Bvh {
    pub fn new(mesh: &Mesh) -> Self {
        let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        let centroids: Vec<Vec3> = tris.iter().map(|t| (t[0] + t[1] + t[2]) / 3.0).collect();
        let mut order: Vec<u32> = (0..tris.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * tris.len() / LEAF_SIZE + 1);
        nodes.push(Node {
            bounds: Aabb::empty(),
            start: 0,
            count: 0,
        });
        let mut stack = vec![(0usize, 0usize, tris.len())];
        while let Some((node, lo, hi)) = stack.pop() {
            let mut b = Aabb::empty();
            let mut cb = Aabb::empty();
            for &t in &order[lo..hi] {
                for v in tris[t as usize] {
                    b.grow(v);
                }
                cb.grow(centroids[t as usize]);
            }
            nodes[node].bounds = b;
            if hi - lo <= LEAF_SIZE {
                nodes[node].start = lo as u32;
                nodes[node].count = (hi - lo) as u32;
                continue;
            }
            // Median split on the longest axis of the centroid bounds.
            let axis = cb.size().max_position();
            let mid = (lo + hi) / 2;
            order[lo..hi].select_nth_unstable_by(mid - lo, |&a, &b| {
                centroids[a as usize][axis].total_cmp(&centroids[b as usize][axis])
            });
            let left = nodes.len();
            nodes.push(Node {
                bounds: Aabb::empty(),
                start: 0,
                count: 0,
            });
            nodes.push(Node {
                bounds: Aabb::empty(),
                start: 0,
                count: 0,
            });
            nodes[node].start = left as u32;
            nodes[node].count = 0;
            stack.push((left, lo, mid));
            stack.push((left + 1, mid, hi));
        }
        Bvh { nodes, order, tris }
    }

    /// The exact closest point on the mesh to `p`.
    pub fn closest(&self, p: Vec3) -> Closest {
        self.closest_within(p, f32::INFINITY)
            .expect("mesh is not empty")
    }

    /// The exact closest point on the mesh to `p` if it is within `max_distance`.
    pub fn closest_within(&self, p: Vec3, max_distance: f32) -> Option<Closest> {
        if self.tris.is_empty() {
            return None;
        }
        let mut best_d2 = max_distance * max_distance;
        let mut best: Option<(Vec3, u32)> = None;
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        stack.push(0);
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            if node.bounds.distance_squared(p) > best_d2 {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.start as usize..(node.start + node.count) as usize] {
                    let [a, b, c] = self.tris[t as usize];
                    let q = closest_point_on_triangle(p, a, b, c);
                    let d2 = (q - p).length_squared();
                    if d2 <= best_d2 {
                        best_d2 = d2;
                        best = Some((q, t));
                    }
                }
            } else {
                // Visit the nearer child first.
                let (l, r) = (node.start, node.start + 1);
                let dl = self.nodes[l as usize].bounds.distance_squared(p);
                let dr = self.nodes[r as usize].bounds.distance_squared(p);
                if dl < dr {
                    stack.push(r);
                    stack.push(l);
                } else {
                    stack.push(l);
                    stack.push(r);
                }
            }
        }
        best.map(|(point, triangle)| Closest {
            point,
            distance: best_d2.sqrt(),
            triangle,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::primitives;

    #[test]
    fn matches_brute_force() {
        let m = primitives::torus(1.0, 0.3, 24, 12);
        let bvh = Bvh::new(&m);
        let mut s = 12345u32;
        let mut rnd = || {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            (s >> 8) as f32 / (1 << 24) as f32 * 4.0 - 2.0
        };
        for _ in 0..200 {
            let p = Vec3::new(rnd(), rnd(), rnd());
            let brute = (0..m.triangles.len())
                .map(|t| {
                    let [a, b, c] = m.triangle(t);
                    (closest_point_on_triangle(p, a, b, c) - p).length()
                })
                .fold(f32::INFINITY, f32::min);
            assert!((bvh.closest(p).distance - brute).abs() < 1e-6);
        }
    }
}
