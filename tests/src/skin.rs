//! Skinning test pieces shared by the skinning tests (blends and particles): a two-bone
//! limb (a capped cylinder along +x with its joint at the middle), its joint ring, poses
//! that twist or bend the lower bone, and ring measures.

use glam::{Quat, Vec3};
use imprint_core::Mesh;
use imprint_core::mesh::primitives;
use imprint_stages::skin::rig::{Bone, Pose, Rig};
use imprint_stages::skin::weights::{self, Weights};

/// A limb: a capped cylinder of `radius` from x = 0 to x = `length` (`segments` around,
/// `rings` quads along, even so that a vertex ring lies on the joint), and a rig of two bones
/// along its axis, "upper" [0, length/2] and its child "lower" [length/2, length].
pub fn two_bone_limb(radius: f32, length: f32, segments: u32, rings: u32) -> (Mesh, Rig) {
    assert!(
        rings.is_multiple_of(2),
        "an even number of rings puts one on the joint"
    );
    let mesh = primitives::cylinder(radius, length, segments, rings);
    let joint = Vec3::new(0.5 * length, 0.0, 0.0);
    let rig = Rig {
        bones: vec![
            Bone {
                name: "upper".into(),
                head: Vec3::ZERO,
                tail: joint,
                parent: None,
            },
            Bone {
                name: "lower".into(),
                head: joint,
                tail: Vec3::new(length, 0.0, 0.0),
                parent: Some("upper".into()),
            },
        ],
        mesh: None,
        animation: vec![],
    };
    rig.validate().expect("the limb rig is valid");
    (mesh, rig)
}

/// The joint of a [`two_bone_limb`] rig (the lower bone's head).
pub fn joint(rig: &Rig) -> Vec3 {
    rig.bones[1].head
}

/// Indices of the side vertices on the plane x = `x` (the joint ring at x = length/2).
pub fn ring(mesh: &Mesh, x: f32) -> Vec<usize> {
    let tol = 1e-6 * mesh.bounds().size().max_element();
    let radial = |p: &Vec3| p.y.hypot(p.z);
    let max_r = mesh.positions.iter().map(radial).fold(0.0f32, f32::max);
    (0..mesh.positions.len())
        .filter(|&i| {
            let p = mesh.positions[i];
            (p.x - x).abs() <= tol && radial(&p) > 0.5 * max_r
        })
        .collect()
}

/// The lower bone twisted by `degrees` about its own axis (+x), the upper at rest.
pub fn twist(rig: &Rig, degrees: f32) -> Pose {
    let axis = (rig.bones[1].tail - rig.bones[1].head).normalize();
    let q = Quat::from_axis_angle(axis, degrees.to_radians());
    rig.pose_local(&[Quat::IDENTITY, q], Vec3::ZERO)
}

/// The lower bone bent by `degrees` about +z (toward +y: the inner side is +y).
pub fn bend(rig: &Rig, degrees: f32) -> Pose {
    let q = Quat::from_axis_angle(Vec3::Z, degrees.to_radians());
    rig.pose_local(&[Quat::IDENTITY, q], Vec3::ZERO)
}

/// Hard weights split at the joint plane x = `joint_x`: below it "upper" (bone 0) alone,
/// above it "lower" (bone 1) alone, and on it `1 − w` for upper and `w` for lower.
pub fn joint_weights(mesh: &Mesh, joint_x: f32, w: f32) -> Weights {
    let tol = 1e-6 * mesh.bounds().size().max_element();
    let lists: Vec<Vec<(u32, f32)>> = mesh
        .positions
        .iter()
        .map(|p| {
            if (p.x - joint_x).abs() <= tol {
                vec![(0, 1.0 - w), (1, w)]
            } else if p.x < joint_x {
                vec![(0, 1.0)]
            } else {
                vec![(1, 1.0)]
            }
        })
        .collect();
    weights::from_lists(&lists, 2).expect("valid weights")
}

/// The mesh with its positions replaced (triangles kept), for the measures.
pub fn with_positions(mesh: &Mesh, positions: Vec<Vec3>) -> Mesh {
    let mut m = mesh.clone();
    m.positions = positions;
    m.compute_normals();
    m
}

/// (smallest, largest) distance of the ring's posed vertices to their centroid (f64): the
/// ring's radius, which is the same for all of them when the ring stays a circle.
pub fn ring_radius(positions: &[Vec3], ring: &[usize]) -> (f64, f64) {
    let c = ring
        .iter()
        .map(|&i| positions[i].as_dvec3())
        .sum::<glam::DVec3>()
        / ring.len() as f64;
    ring.iter()
        .map(|&i| (positions[i].as_dvec3() - c).length())
        .fold((f64::INFINITY, 0.0f64), |(lo, hi), d| {
            (lo.min(d), hi.max(d))
        })
}
