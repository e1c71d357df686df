//! Linear blend and dual quaternion skinning on a two-bone limb, automatic weights, and the
//! measures (volume, cross-section, self-intersection) the skinning claims are checked with.

use glam::{Affine3A, Quat, Vec3};
use imprint_core::mesh::primitives;
use imprint_stages::skin::blend::{dqs, lbs};
use imprint_stages::skin::measure::{
    cross_section_area, inner_self_intersections, self_intersecting_pairs, volume,
};
use imprint_stages::skin::weights::{WeightMethod, Weights, automatic};
use imprint_tests::skin::{
    bend, joint, joint_weights, ring, ring_radius, twist, two_bone_limb, with_positions,
};
use std::f64::consts::TAU;

const R: f32 = 0.1;

type Blend = fn(&[Vec3], &Weights, &[Affine3A]) -> Vec<Vec3>;
const L: f32 = 1.0;

/// LBS under a twist of θ about the bone axis, w = ½ on the joint ring: the ring's radius
/// factor is √(w² + (1−w)² + 2w(1−w) cos θ) (the blend of a point and its copy turned by θ
/// about the axis: |w + (1−w)e^{iθ}|). The formula is for rotation about the axis through the
/// ring's centre, so it is the twist case (a bend moves the centre and squashes the ring
/// unevenly).
#[test]
fn lbs_twist_shrinks_the_joint_ring_by_the_blend_factor() {
    let (mesh, rig) = two_bone_limb(R, L, 64, 16);
    let j = joint(&rig);
    let ring = ring(&mesh, j.x);
    assert_eq!(ring.len(), 64);
    for w in [0.5f64, 0.3] {
        let weights = joint_weights(&mesh, j.x, w as f32);
        let mut worst = 0.0f64;
        for deg in [0.0f64, 30.0, 90.0, 135.0, 180.0, 225.0, 300.0] {
            let out = lbs(&mesh.positions, &weights, &twist(&rig, deg as f32).skin);
            // Distance to the axis (the ring's centroid stays on it).
            let (lo, hi) = ring
                .iter()
                .map(|&i| out[i].as_dvec3())
                .map(|p| p.y.hypot(p.z) / R as f64)
                .fold((f64::INFINITY, 0.0f64), |(a, b), d| (a.min(d), b.max(d)));
            let th = deg.to_radians();
            let expect = (w * w + (1.0 - w).powi(2) + 2.0 * w * (1.0 - w) * th.cos()).sqrt();
            let err = (lo - expect).abs().max((hi - expect).abs());
            // Relative to the factor, absolute (in radii) where the factor is 0.
            let rel = err / expect.max(1.0);
            println!(
                "LBS w = {w} twist {deg}°: factor {hi:.9} expected {expect:.9}, error {err:.2e}"
            );
            assert!(
                rel < 1e-6,
                "w = {w}, {deg}°: factor in [{lo}, {hi}], expected {expect}"
            );
            worst = worst.max(rel);
        }
        println!("LBS w = {w}: worst relative factor error {worst:.2e}");
    }
    // The candy wrapper: at 180° with w = ½ the ring collapses onto the axis.
    let weights = joint_weights(&mesh, j.x, 0.5);
    let out = lbs(&mesh.positions, &weights, &twist(&rig, 180.0).skin);
    assert!(ring_radius(&out, &ring).1 < 1e-6 * R as f64);
}

/// DQS keeps the joint ring a circle of radius r under a 90° twist, a 90° bend and a twist
/// just short of 180°.
#[test]
fn dqs_keeps_the_joint_ring_radius() {
    let (mesh, rig) = two_bone_limb(R, L, 64, 16);
    let j = joint(&rig);
    let ring = ring(&mesh, j.x);
    let weights = joint_weights(&mesh, j.x, 0.5);
    for (name, pose) in [
        ("twist 90°", twist(&rig, 90.0)),
        ("twist 179.9°", twist(&rig, 179.9)),
        ("bend 90°", bend(&rig, 90.0)),
        ("bend 179.9°", bend(&rig, 179.9)),
    ] {
        let out = dqs(&mesh.positions, &weights, &pose.skin);
        let (lo, hi) = ring_radius(&out, &ring);
        let err = (lo / R as f64 - 1.0).abs().max((hi / R as f64 - 1.0).abs());
        println!(
            "DQS {name}: ring radius factor in [{:.8}, {:.8}], error {err:.2e}",
            lo / R as f64,
            hi / R as f64
        );
        assert!(err < 1e-5, "{name}: radius in [{lo}, {hi}], r = {R}");
        // LBS at the same pose does not keep it (the contrast the test is about).
        let out = lbs(&mesh.positions, &weights, &pose.skin);
        let (lo, _) = ring_radius(&out, &ring);
        assert!(lo < 0.75 * R as f64, "LBS {name}: smallest radius {lo}");
    }
}

/// Sweeping the twist 179° → 181° in 0.1° steps: DQS flips (the sign fix against the vertex's
/// most-weighted bone changes side at 180°) and a joint vertex jumps by about the diameter;
/// LBS moves continuously.
#[test]
fn dqs_flips_past_180_degrees_and_lbs_does_not() {
    let (mesh, rig) = two_bone_limb(R, L, 64, 16);
    let j = joint(&rig);
    let ring = ring(&mesh, j.x);
    let weights = joint_weights(&mesh, j.x, 0.5);
    let sweep: Vec<f32> = (0..=20).map(|i| 179.0 + 0.1 * i as f32).collect();
    let largest_step = |skin: Blend| {
        let mut prev: Option<Vec<Vec3>> = None;
        let mut best = (0.0f32, 0.0f32);
        for &deg in &sweep {
            let out = skin(&mesh.positions, &weights, &twist(&rig, deg).skin);
            if let Some(p) = &prev {
                let step = ring
                    .iter()
                    .map(|&i| (out[i] - p[i]).length())
                    .fold(0.0f32, f32::max);
                if step > best.0 {
                    best = (step, deg);
                }
            }
            prev = Some(out);
        }
        best
    };
    let (dq_jump, dq_at) = largest_step(dqs);
    let (lb_jump, _) = largest_step(lbs);
    println!(
        "twist sweep 179°→181° by 0.1°: DQS largest step {:.4} r = {:.4} diameters (at {dq_at}°), LBS largest step {:.2e} r",
        dq_jump / R,
        dq_jump / (2.0 * R),
        lb_jump / R
    );
    assert!(
        dq_jump > 1.9 * R,
        "DQS jump {dq_jump}, diameter {}",
        2.0 * R
    );
    assert!(
        (180.0..=180.15).contains(&dq_at),
        "the flip is at 180°, got {dq_at}"
    );
    // A 0.1° step of a rigid turn moves a ring vertex by r·0.0017; LBS at 180° is slower still.
    assert!(lb_jump < 0.01 * R, "LBS step {lb_jump}");
}

/// Every bone moved by the same rigid motion: both blends reproduce it.
#[test]
fn rigid_motion_is_reproduced() {
    let (mesh, rig) = two_bone_limb(R, L, 32, 8);
    let q = Quat::from_axis_angle(Vec3::new(1.0, -2.0, 0.5).normalize(), 2.2);
    let t = Vec3::new(0.3, -0.7, 1.1);
    let pose = rig.pose_local(&[q, Quat::IDENTITY], t);
    let expect: Vec<Vec3> = mesh
        .positions
        .iter()
        .map(|p| pose.skin[0].transform_point3(*p))
        .collect();
    let auto = automatic(
        &mesh.positions,
        &rig.rest_segments(),
        &WeightMethod::default(),
    );
    for w in [auto, joint_weights(&mesh, joint(&rig).x, 0.5)] {
        for (name, out) in [
            ("LBS", lbs(&mesh.positions, &w, &pose.skin)),
            ("DQS", dqs(&mesh.positions, &w, &pose.skin)),
        ] {
            let err = out
                .iter()
                .zip(&expect)
                .map(|(a, b)| (*a - *b).length())
                .fold(0.0f32, f32::max);
            println!("{name} rigid motion: largest error {:.2e} r", err / R);
            assert!(err < 1e-5 * R, "{name}: {err}");
        }
    }
}

#[test]
fn automatic_weights_are_normalised_local_and_deterministic() {
    let (mesh, rig) = two_bone_limb(R, L, 32, 16);
    let segs = rig.rest_segments();
    let w = automatic(&mesh.positions, &segs, &WeightMethod::default());
    assert_eq!(w.len(), mesh.positions.len());
    for v in 0..w.len() {
        let list = w.of(v);
        assert!(!list.is_empty() && list.len() <= 4, "vertex {v}: {list:?}");
        let sum: f32 = list.iter().map(|e| e.1).sum();
        assert!((sum - 1.0).abs() < 1e-6, "vertex {v}: sum {sum}");
        assert!(list.windows(2).all(|p| p[0].1 >= p[1].1));
    }
    // Side vertices at the middle of each bone (x = L/4, 3L/4) belong to it.
    for (bone, x) in [(0u32, 0.25 * L), (1, 0.75 * L)] {
        let mid = ring(&mesh, x);
        assert_eq!(mid.len(), 32);
        for &v in &mid {
            let (b, wt) = w.of(v)[0];
            assert_eq!(b, bone, "vertex {v}");
            assert!(wt > 0.95, "vertex {v}: weight {wt} for bone {b}");
        }
    }
    // On the joint plane, an even split.
    for &v in &ring(&mesh, 0.5 * L) {
        let list = w.of(v);
        assert!(
            list.len() == 2 && (list[0].1 - 0.5).abs() < 1e-6,
            "{list:?}"
        );
    }
    // Four bones: at most four influences; the same result twice (bit for bit).
    let many: Vec<(Vec3, Vec3)> = (0..6)
        .map(|i| {
            let a = Vec3::new(0.2 * i as f32, 0.05 * (i % 2) as f32, 0.0);
            (a, a + Vec3::new(0.2, 0.0, 0.01))
        })
        .collect();
    let a = automatic(
        &mesh.positions,
        &many,
        &WeightMethod::Distance { power: 2.0 },
    );
    let b = automatic(
        &mesh.positions,
        &many,
        &WeightMethod::Distance { power: 2.0 },
    );
    assert_eq!(a, b);
    assert!((0..a.len()).all(|v| a.of(v).len() <= 4));
    assert!((0..a.len()).any(|v| a.of(v).len() == 4));
    assert!(WeightMethod::Distance { power: 0.0 }.validate().is_err());
}

#[test]
fn volumes_match_the_polyhedra() {
    // Box: exact.
    let b = primitives::cuboid(Vec3::new(0.5, 1.0, 1.5), 3);
    assert!((volume(&b) - 6.0).abs() < 1e-9, "{}", volume(&b));
    // Cylinder: the n-gon prism, (n/2) r² sin(2π/n) · length, exactly for the polyhedron.
    for n in [8u32, 64] {
        let c = primitives::cylinder(0.3, 2.0, n, 6);
        let exact = n as f64 / 2.0 * 0.09 * (TAU / n as f64).sin() * 2.0;
        let rel = (volume(&c) - exact).abs() / exact;
        println!(
            "cylinder n = {n}: volume {} exact {exact} rel {rel:.1e}",
            volume(&c)
        );
        assert!(rel < 1e-6, "n = {n}: {} vs {exact}", volume(&c));
    }
    // Sphere: the UV sphere's polyhedron, summed exactly band by band (cones and frusta
    // between latitude polygons, as tetrahedra from the centre), and within tessellation
    // error of 4/3 π r³.
    let (segs, rings, r) = (48u32, 24u32, 0.7f64);
    let s = primitives::uv_sphere(r as f32, segs, rings);
    let poly = sphere_polyhedron_volume(r, segs, rings);
    let v = volume(&s);
    assert!((v - poly).abs() / poly < 1e-6, "{v} vs {poly}");
    let ball = 4.0 / 3.0 * std::f64::consts::PI * r.powi(3);
    assert!(v < ball && (ball - v) / ball < 0.01, "{v} vs {ball}");
}

/// The UV sphere's exact volume: each quad (a, b, d, c) as two tetrahedra from the centre.
fn sphere_polyhedron_volume(r: f64, segs: u32, rings: u32) -> f64 {
    use glam::DVec3;
    let p = |ring: u32, s: u32| {
        let phi = std::f64::consts::PI * ring as f64 / rings as f64;
        let th = TAU * s as f64 / segs as f64;
        r * DVec3::new(phi.sin() * th.cos(), phi.cos(), phi.sin() * th.sin())
    };
    let tet = |a: DVec3, b: DVec3, c: DVec3| a.dot(b.cross(c)).abs() / 6.0;
    let mut v = 0.0;
    for ring in 0..rings {
        for s in 0..segs {
            let (a, b, c, d) = (
                p(ring, s),
                p(ring, s + 1),
                p(ring + 1, s),
                p(ring + 1, s + 1),
            );
            v += tet(a, b, d) + tet(a, d, c);
        }
    }
    v
}

#[test]
fn cylinder_section_is_the_polygon() {
    for n in [6u32, 64] {
        let c = primitives::cylinder(0.25, 1.0, n, 4);
        let exact = n as f64 / 2.0 * 0.0625 * (TAU / n as f64).sin();
        // Between rings, on a ring (x = 0.5: through vertices), and turned.
        for x in [0.3f32, 0.5] {
            let a = cross_section_area(&c, Vec3::new(x, 0.0, 0.0), Vec3::X);
            assert!(
                (a - exact).abs() / exact < 1e-6,
                "n = {n}, x = {x}: {a} vs {exact}"
            );
        }
        let a = cross_section_area(&c, Vec3::new(0.4, 0.01, 0.0), -Vec3::X);
        assert!((a - exact).abs() / exact < 1e-6, "{a} vs {exact}");
        // An oblique cut of a prism: the section is the polygon stretched by 1/cos.
        let tilt = Vec3::new(1.0, 0.2, 0.0);
        let a = cross_section_area(&c, Vec3::new(0.5, 0.0, 0.0), tilt);
        let stretched = exact * tilt.length() as f64 / tilt.x as f64;
        assert!(
            (a - stretched).abs() / stretched < 1e-5,
            "{a} vs {stretched}"
        );
    }
}

#[test]
fn self_intersection_finds_a_fold_and_none_at_rest() {
    let (mesh, rig) = two_bone_limb(R, L, 32, 16);
    assert!(self_intersecting_pairs(&mesh).is_empty());
    // Fold the lower half back through the upper half: every vertex past the joint turned
    // 170° about z through the joint (hard weights): the halves cross.
    let j = joint(&rig);
    let weights = joint_weights(&mesh, j.x, 1.0);
    let folded = with_positions(
        &mesh,
        lbs(&mesh.positions, &weights, &bend(&rig, 170.0).skin),
    );
    let pairs = self_intersecting_pairs(&folded);
    println!("folded 170°: {} crossing triangle pairs", pairs.len());
    assert!(!pairs.is_empty());
    assert!(inner_self_intersections(&folded, j, Vec3::Y) > 0);
    // Bent 90° with DQS and automatic weights: no crossing on the inner side.
    let w = automatic(
        &mesh.positions,
        &rig.rest_segments(),
        &WeightMethod::default(),
    );
    let bent = with_positions(&mesh, dqs(&mesh.positions, &w, &bend(&rig, 90.0).skin));
    let inner = inner_self_intersections(&bent, j, Vec3::Y);
    assert_eq!(inner, 0, "DQS bent 90°: inner-side crossings");
    let lb = with_positions(&mesh, lbs(&mesh.positions, &w, &bend(&rig, 90.0).skin));
    println!(
        "bent 90° (automatic weights): DQS {inner} inner crossings, LBS {}",
        inner_self_intersections(&lb, j, Vec3::Y)
    );
}
