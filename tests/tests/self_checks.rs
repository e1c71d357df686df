//! The stages' self-checks on their own (the graph's side, a run stopped or counted and
//! warned once, is `crates/imprint-graph/tests/self_checks.rs`): a state that breaks the
//! check is made by editing a stage's saved state (serde), and a clean run passes it.
//! - snow: no vertex deeper than what fell, no more snow on the ground than fell on it;
//! - skin: no particle beyond its reach from its bone's target;
//! - drape: the vertices left inside the body are counted (`DrapeReport::inside_after`).

use glam::{Affine3A, Mat4, UVec2, Vec2, Vec3};
use imprint_core::mesh::primitives::{cuboid, uv_sphere};
use imprint_core::{Error, HeightField, Mesh};
use imprint_stages::drape::{DrapeParams, drape_cpu};
use imprint_stages::skin::particles::{ParticleParams, ParticleSkin};
use imprint_stages::snow::{SnowParams, SnowSim};
use imprint_tests::skin::{bend, two_bone_limb};

/// `$v` with `$edit` applied to its JSON form (a state no step made), of `$v`'s type.
macro_rules! edited {
    ($t:ty, $v:expr, $edit:expr) => {{
        let mut j = serde_json::to_value(&$v).unwrap();
        let edit: &dyn Fn(&mut serde_json::Value) = &$edit;
        edit(&mut j);
        serde_json::from_value::<$t>(j).unwrap()
    }};
}

fn numerical_message(e: Error) -> String {
    match e {
        Error::Numerical { message, hint, .. } => {
            assert!(!hint.is_empty());
            message
        }
        e => panic!("expected a numerical error, got {e}"),
    }
}

// ---- snow -------------------------------------------------------------------------------

/// A ball over a flat ground, 8 steps of snow.
fn snowy() -> SnowSim {
    let p = SnowParams {
        directions: 4,
        resolution: 64,
        rate: 0.01,
        ..Default::default()
    };
    let ground = HeightField::constant(Vec2::splat(-1.0), 0.1, UVec2::new(21, 21), 0.0).unwrap();
    let mut ball = uv_sphere(0.4, 16, 8);
    ball.transform(Mat4::from_translation(Vec3::new(0.0, 0.8, 0.0)));
    let mut sim = SnowSim::new(&p).unwrap();
    for _ in 0..8 {
        sim.step(&[&ball], Some(&ground), 0.1).unwrap();
        sim.check().unwrap();
    }
    sim
}

#[test]
fn snow_that_fell_passes_its_check() {
    let sim = snowy();
    let f = sim.fallen();
    assert_eq!(f.steps, 8);
    assert!((f.depth - 0.008).abs() < 1e-6, "{f:?}");
    // The ball's top vertex faces straight up under open sky: exactly what fell.
    let top = sim.mesh_depth(0).iter().copied().fold(0.0f32, f32::max);
    assert!(top <= f.depth && top > 0.99 * f.depth, "{top} vs {f:?}");
    // The ground holds what the deposit put there, stabilised or not.
    let g = sim.ground().unwrap();
    assert!((g.total_quanta() - f.ground_quanta).abs() <= 1e-9 * f.ground_quanta);
    let c = sim.check().unwrap();
    assert!(!c.any(), "{c:?}");
}

#[test]
fn snow_deeper_than_what_fell_is_an_error() {
    let sim = snowy();
    let deep = edited!(SnowSim, sim, |j| j["meshes"][0][3] = 0.5.into());
    let m = numerical_message(deep.check().unwrap_err());
    assert!(
        m.contains("vertex 3") && m.contains("more than fell"),
        "{m}"
    );
    // A cell with more snow than fell on the whole field, out of nowhere.
    let heap = edited!(SnowSim, sim, |j| {
        let u = &mut j["ground"]["units"][7];
        *u = (u.as_u64().unwrap() + 10).into();
    });
    let m = numerical_message(heap.check().unwrap_err());
    assert!(m.contains("the ground holds"), "{m}");
    // A pour is snow put there: it counts as fallen.
    let mut poured = sim.clone();
    poured.pour(UVec2::new(10, 10), 1e-4).unwrap();
    poured.check().unwrap();
}

/// Within f32 rounding of the bound (a vertex a few ulps above it): counted, not an error.
#[test]
fn snow_a_few_ulps_over_is_counted() {
    let sim = snowy();
    let depth = sim.fallen().depth;
    let over = edited!(SnowSim, sim, |j| {
        j["meshes"][0][0] = (f32::from_bits(depth.to_bits() + 2) as f64).into()
    });
    let c = over.check().unwrap();
    assert_eq!(c.vertices_over, 1, "{c:?}");
}

// ---- skin -------------------------------------------------------------------------------

#[test]
fn skin_particle_beyond_its_reach_is_an_error() {
    let (mesh, rig) = two_bone_limb(0.1, 1.0, 16, 10);
    let p = ParticleParams {
        substeps: 18,
        ..Default::default()
    };
    let mut skin = ParticleSkin::new(&mesh, &rig.rest_segments(), &p).unwrap();
    let rest: Vec<Affine3A> = bend(&rig, 0.0).skin;
    skin.check_reach(&rest).unwrap();
    // A few frames bending to 30°: still within reach of the bent pose.
    let mut last = rest.clone();
    for f in 0..6 {
        let pose = bend(&rig, 5.0 * (f + 1) as f32).skin;
        skin.step_frame(&last, &pose, f, 1.0 / 24.0).unwrap();
        last = pose;
    }
    skin.check_reach(&last).unwrap();
    // A particle moved 1 m off its target, against a reach of 0.05 × the box diagonal.
    let tight = ParticleParams {
        max_deviation: 0.05,
        ..p.clone()
    };
    let near = ParticleSkin::new(&mesh, &rig.rest_segments(), &tight).unwrap();
    near.check_reach(&rest).unwrap();
    let moved = edited!(ParticleSkin, near, |j| {
        for key in ["x", "xa"] {
            let y = &mut j[key][4][1];
            *y = (y.as_f64().unwrap() + 1.0).into();
        }
    });
    let m = numerical_message(moved.check_reach(&rest).unwrap_err());
    assert!(
        m.contains("particle 4") && m.contains("beyond the reach"),
        "{m}"
    );
    // Stepping from there: the substeps name it too (as a blow-up).
    let mut moved = moved;
    let e = moved.step_frame(&rest, &rest, 0, 1.0 / 24.0).unwrap_err();
    assert!(numerical_message(e).contains("particle 4"));
    assert!(near.reach() > 0.0 && skin.reach() > near.reach());
}

// ---- drape ------------------------------------------------------------------------------

fn part(half: Vec3, centre: Vec3) -> Mesh {
    let mut m = cuboid(half, 2);
    m.transform(Mat4::from_translation(centre));
    m
}

#[test]
fn drape_counts_the_vertices_it_leaves_inside() {
    let params = DrapeParams {
        resolution: 64,
        ..Default::default()
    };
    let mut garment = uv_sphere(0.05, 8, 4).positions;
    let n = garment.len();
    // A plain box: every vertex pushed out, none left inside.
    let plain = part(Vec3::splat(0.3), Vec3::ZERO);
    let r = drape_cpu(&plain, &mut garment.clone(), &params).unwrap();
    assert_eq!((r.inside, r.inside_after), (n, 0), "{r:?}");
    // Slabs above, below, in front and behind: every push from the middle crosses three
    // surfaces, so no view resolves a vertex and all stay inside.
    let mut boxed = plain.clone();
    for s in [-1.0f32, 1.0] {
        boxed.append(&part(
            Vec3::new(0.3, 0.05, 0.3),
            Vec3::new(0.0, 0.4 * s, 0.0),
        ));
        boxed.append(&part(
            Vec3::new(0.3, 0.3, 0.05),
            Vec3::new(0.0, 0.0, 0.4 * s),
        ));
    }
    let r = drape_cpu(&boxed, &mut garment, &params).unwrap();
    assert_eq!((r.unresolved, r.inside_after), (n, n), "{r:?}");
}
