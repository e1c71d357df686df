//! Pins that ride on a deforming body: a cape's top edge on a character's shoulders.
//!
//! Each pinned particle is tied, once, to the body's surface point nearest to it: a triangle,
//! barycentric coordinates in it, and the particle's offset from that point in the
//! triangle's own frame (along its first edge, across it, along its normal). On every later
//! pose of the same mesh (same triangles; the positions move, as a skinned mesh's do) the
//! pin's target is that surface point again plus the same offset in the posed triangle's
//! frame, so the pin turns with the surface as well as moving with it (exactly, under a
//! rigid motion). [`super::ClothSim::set_pin_targets`] then leads the pins there over the
//! frame's substeps.

use glam::Vec3;
use imprint_core::bvh::Bvh;
use imprint_core::geom::barycentric;
use imprint_core::{Error, Mesh, Result};
use serde::{Deserialize, Serialize};

/// Where each pinned particle sits on a body.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Attachment {
    /// Per pin: the triangle, its barycentric coordinates, the offset in its frame.
    ties: Vec<(u32, [f32; 3], Vec3)>,
    /// The body's triangle count when tied (a body whose topology changes cannot carry pins).
    triangles: usize,
}

impl Attachment {
    /// Ties each of `points` (the pinned particles' positions) to the nearest point of
    /// `body`'s surface.
    pub fn new(body: &Mesh, points: &[Vec3]) -> Result<Self> {
        if body.triangles.is_empty() {
            return Err(Error::Invalid(
                "cloth: the body the pins follow has no triangles".into(),
            ));
        }
        let bvh = Bvh::new(body);
        let ties = points
            .iter()
            .map(|&p| {
                let c = bvh.closest(p);
                let tri = body.triangle(c.triangle as usize);
                let l = barycentric(c.point, tri);
                let f = frame(tri);
                let o = p - c.point;
                (
                    c.triangle,
                    l,
                    Vec3::new(o.dot(f[0]), o.dot(f[1]), o.dot(f[2])),
                )
            })
            .collect();
        Ok(Attachment {
            ties,
            triangles: body.triangles.len(),
        })
    }

    /// The pins' targets on `body` posed anew (same triangles as when tied).
    pub fn targets(&self, body: &Mesh) -> Result<Vec<Vec3>> {
        if body.triangles.len() != self.triangles {
            return Err(Error::Invalid(format!(
                "cloth: the body the pins follow had {} triangles when they were tied and has \
                 {} now; pins can follow a deforming mesh, not one whose triangles change",
                self.triangles,
                body.triangles.len()
            )));
        }
        Ok(self
            .ties
            .iter()
            .map(|&(t, l, o)| {
                let tri = body.triangle(t as usize);
                let on = tri[0] * l[0] + tri[1] * l[1] + tri[2] * l[2];
                let f = frame(tri);
                on + f[0] * o.x + f[1] * o.y + f[2] * o.z
            })
            .collect())
    }
}

/// A triangle's orthonormal frame: its first edge, the in-plane direction across it, its
/// normal (zeros for a degenerate triangle, which then carries its pins without turning
/// them).
fn frame([a, b, c]: [Vec3; 3]) -> [Vec3; 3] {
    let n = (b - a).cross(c - a).normalize_or_zero();
    let e = (b - a).normalize_or_zero();
    [e, n.cross(e), n]
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Affine3A, Quat};
    use imprint_core::mesh::primitives;

    /// A rigid motion of the body carries the pins rigidly: the targets are the tied points
    /// moved by the same rotation and translation.
    #[test]
    fn pins_follow_a_rigid_motion_exactly() {
        let body = primitives::uv_sphere(0.5, 24, 12);
        let points = [
            Vec3::new(0.0, 0.6, 0.0),
            Vec3::new(0.55, 0.1, 0.0),
            Vec3::new(-0.1, -0.2, 0.52),
        ];
        let a = Attachment::new(&body, &points).unwrap();
        // Unmoved: the targets are the points themselves.
        for (t, p) in a.targets(&body).unwrap().iter().zip(&points) {
            assert!(t.distance(*p) < 1e-5, "{t} vs {p}");
        }
        let m = Affine3A::from_rotation_translation(
            Quat::from_axis_angle(Vec3::new(1.0, 2.0, 0.5).normalize(), 1.1),
            Vec3::new(0.3, -1.0, 2.0),
        );
        let mut moved = body.clone();
        for p in &mut moved.positions {
            *p = m.transform_point3(*p);
        }
        for (t, p) in a.targets(&moved).unwrap().iter().zip(&points) {
            let want = m.transform_point3(*p);
            assert!(t.distance(want) < 1e-5, "{t} vs {want}");
        }
    }

    #[test]
    fn a_body_with_other_triangles_is_refused() {
        let a = Attachment::new(&primitives::uv_sphere(0.5, 24, 12), &[Vec3::Y]).unwrap();
        let err = a.targets(&primitives::uv_sphere(0.5, 12, 6)).unwrap_err();
        assert!(err.to_string().contains("triangles"), "{err}");
    }
}
