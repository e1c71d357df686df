//! Scenes shared by the CPU golden test and the CPU-vs-GPU frame test.

use imprint_core::glam::{Mat4, Vec3};
use imprint_core::mesh::primitives::{torus, uv_sphere};
use imprint_render::frame::{GroundGrid, Lights, Object, Scene};

/// A sphere resting on the ground at the left, a wireframed torus standing at the right, a
/// ground grid, the sun from the upper left front.
pub fn sphere_torus_scene() -> Scene {
    let mut sphere = uv_sphere(0.5, 32, 16);
    sphere.transform(Mat4::from_translation(Vec3::new(-0.6, 0.5, 0.0)));
    let mut ring = torus(0.45, 0.15, 20, 8);
    ring.transform(
        Mat4::from_translation(Vec3::new(0.7, 0.6, 0.0))
            * Mat4::from_rotation_x(90f32.to_radians()),
    );
    Scene {
        objects: vec![
            Object::mesh(sphere, [0.8, 0.25, 0.2]),
            Object::mesh(ring, [0.2, 0.45, 0.8]).with_wireframe(true),
        ],
        lights: Lights {
            sun_direction: Vec3::new(-0.6, 1.0, 0.5),
            sun: 0.8,
            ambient: 0.2,
        },
        background: [235, 238, 242],
        ground_grid: Some(GroundGrid {
            spacing: 0.5,
            half_extent: 3.0,
            color: [120, 120, 120],
        }),
    }
}
