//! The CPU snow stage (T §(1), docs/methods.md §5) against answers known in advance: flat
//! ground gets a uniform layer; a slope below the repose angle gets depth ∝ cos φ; nothing
//! lands under a roof in vertical fall; with K jittered directions the coverage beside the
//! roof's edge follows the ring's penumbra F(a) = 1/2 + asin(a)/π to within 1/K and a texel;
//! stabilisation conserves the snow to the quantum; a point pour settles to the cone of
//! height (3V tan²θ / π)^(1/3); the same bytes on one and two threads. Each runs in about a
//! second or less in release; the timing test is ignored.

use glam::{Mat4, UVec2, Vec2, Vec3};
use imprint_core::mesh::primitives::{plane, uv_sphere};
use imprint_core::{Error, HeightField, Mesh};
use imprint_stages::snow::arrival::{arrival_cpu, gather};
use imprint_stages::snow::{QUANTUM, SnowParams, SnowSim};
use std::time::Instant;

/// Rate × time of the tests' snowfall: 1 mm, thin enough that no slope it makes is steep.
const RATE: f32 = 0.001;
const STEPS: u32 = 4;
const DT: f32 = 0.25;
const FALLEN: f32 = RATE * STEPS as f32 * DT;

fn params(directions: u32, jitter_degrees: f32) -> SnowParams {
    SnowParams {
        directions,
        jitter_degrees,
        rate: RATE,
        ..Default::default()
    }
}

/// Runs the tests' snowfall over a scene; returns the simulator.
fn snowfall(p: &SnowParams, meshes: &[&Mesh], ground: Option<&HeightField>) -> SnowSim {
    let mut sim = SnowSim::new(p).unwrap();
    for _ in 0..STEPS {
        sim.step(meshes, ground, DT).unwrap();
    }
    sim
}

/// A flat ground of `n` × `n` cells spanning [-1, 1]² (cell centres on the edges), at y = 0.
fn flat_ground(n: u32) -> HeightField {
    HeightField::constant(
        Vec2::splat(-1.0),
        2.0 / (n - 1) as f32,
        UVec2::splat(n),
        0.0,
    )
    .unwrap()
}

/// A horizontal roof at height `h` over x ∈ [-3, 0], z ∈ [-3, 3]: its edge x = 0 crosses the
/// middle of [`flat_ground`], its other edges lie far outside it.
fn roof(h: f32) -> Mesh {
    Mesh::new(
        vec![
            Vec3::new(-3.0, h, -3.0),
            Vec3::new(0.0, h, -3.0),
            Vec3::new(0.0, h, 3.0),
            Vec3::new(-3.0, h, 3.0),
        ],
        vec![[0, 2, 1], [0, 3, 2]],
        "roof",
    )
    .unwrap()
}

/// The texel of the depth maps over the roof scene (the maps span its bounds' projection).
fn roof_texel(p: &SnowParams, h: f32) -> f32 {
    let g = flat_ground(3).to_mesh();
    let mut scene = roof(h);
    scene.append(&g);
    let dir = imprint_stages::snow::fall_directions(p)[0];
    let cam =
        imprint_stages::snow::arrival::snow_camera(&scene.bounds(), dir, p.resolution).unwrap();
    2.0 * cam.half_height_scale() / p.resolution as f32
}

#[test]
fn flat_ground_gets_a_uniform_layer() {
    let p = params(16, 10.0);
    let ground = flat_ground(64);
    let sim = snowfall(&p, &[], Some(&ground));
    let g = sim.ground().unwrap();
    let t = g.thickness();
    assert!(t.iter().all(|&x| x == t[0]), "not uniform");
    assert!((t[0] / FALLEN - 1.0).abs() < 1e-5, "{} vs {FALLEN}", t[0]);
    // The same on a flat mesh.
    let sheet = plane(2.0, 16);
    let sim = snowfall(&p, &[&sheet], None);
    let d = sim.mesh_depth(0);
    assert!(d.iter().all(|&x| x == d[0]), "not uniform");
    assert!((d[0] / FALLEN - 1.0).abs() < 1e-5, "{} vs {FALLEN}", d[0]);
    let cover = sim.cover(&[&sheet]).unwrap();
    for (a, b) in cover.meshes[0].mesh.positions.iter().zip(&sheet.positions) {
        assert!((a.y - b.y - d[0]).abs() < 1e-7);
    }
}

/// A mesh plane and a ground height field, each tilted by φ below the repose angle (38°):
/// the depth along the normal is FALLEN cos φ within 2% (it is exact to rounding: the plane is
/// open, P = 1, and cos φ is the deposit's factor); the ground's vertical column is FALLEN
/// and nothing slides.
#[test]
fn slopes_below_repose_get_depth_proportional_to_cos() {
    let p = params(16, 10.0);
    for deg in [0.0f32, 10.0, 20.0, 30.0, 36.0] {
        let phi = deg.to_radians();
        let mut sheet = plane(2.0, 24);
        sheet.transform(Mat4::from_rotation_z(phi));
        let sim = snowfall(&p, &[&sheet], None);
        for &d in sim.mesh_depth(0) {
            let ratio = d / (FALLEN * phi.cos());
            assert!(
                (ratio - 1.0).abs() < 0.02,
                "φ = {deg}°: mesh depth ratio {ratio}"
            );
        }
        let ramp = HeightField::from_fn(Vec2::splat(-1.0), 1.0 / 32.0, UVec2::splat(65), |i, _| {
            phi.tan() * i as f32 / 32.0
        })
        .unwrap();
        let mut sim = SnowSim::new(&p).unwrap();
        let mut moved = 0;
        for _ in 0..STEPS {
            moved += sim.step(&[], Some(&ramp), DT).unwrap().relax.moved;
        }
        assert_eq!(moved, 0, "φ = {deg}°: snow slid below the repose angle");
        for t in sim.ground().unwrap().thickness() {
            // Depth along the normal: the vertical column times n_y = cos φ.
            let ratio = t * phi.cos() / (FALLEN * phi.cos());
            assert!(
                (ratio - 1.0).abs() < 0.02,
                "φ = {deg}°: ground ratio {ratio}"
            );
        }
    }
}

#[test]
fn nothing_falls_under_a_roof_in_vertical_fall() {
    let p = params(1, 0.0);
    let (ground, top) = (flat_ground(129), roof(1.0));
    let sim = snowfall(&p, &[&top], Some(&ground));
    let texel = roof_texel(&p, 1.0);
    let t = sim.ground().unwrap().thickness();
    let (mut under, mut open) = (0, 0);
    for k in 0..ground.dims.y {
        for i in 0..ground.dims.x {
            let x = ground.position(i, k).x;
            let got = t[ground.index(i, k)];
            if x < -texel {
                assert_eq!(got, 0.0, "cell ({i},{k}) at x = {x} is under the roof");
                under += 1;
            } else if x > texel {
                assert!((got / FALLEN - 1.0).abs() < 1e-5, "cell ({i},{k}): {got}");
                open += 1;
            }
        }
    }
    assert!(under > 7000 && open > 7000, "{under} {open}");
    for &d in sim.mesh_depth(0) {
        assert!((d / FALLEN - 1.0).abs() < 1e-5, "the roof's top: {d}");
    }
}

/// The ring's penumbra: a ground point at signed distance x outside a straight edge at
/// height H is reached from the fraction F(x / (H tan α)) of the cone's azimuths, with
/// F(a) = 1/2 + asin(a)/π on [-1, 1] (0 below, 1 above). K evenly spaced azimuths give that
/// fraction to within 1/K; the depth map places the edge and the point each to within half a
/// texel, a texel / cos α on the ground.
#[test]
fn jittered_coverage_beside_a_roof_edge_follows_the_ring() {
    let f = |a: f32| 0.5 + a.clamp(-1.0, 1.0).asin() / std::f32::consts::PI;
    let h = 1.0;
    let (ground, top) = (flat_ground(129), roof(h));
    for (k, alpha, seed) in [
        (16u32, 20.0f32, 0u64),
        (16, 20.0, 7),
        (32, 30.0, 3),
        (8, 15.0, 1),
    ] {
        let mut p = params(k, alpha);
        p.seed = seed;
        let sim = snowfall(&p, &[&top], Some(&ground));
        let r = h * alpha.to_radians().tan();
        let tau = roof_texel(&p, h) / alpha.to_radians().cos();
        let t = sim.ground().unwrap().thickness();
        let (mut worst, mut sum_err, mut n_pen) = (0f32, 0f32, 0);
        for kk in 0..ground.dims.y {
            for i in 0..ground.dims.x {
                let x = ground.position(i, kk).x;
                let got = t[ground.index(i, kk)] / FALLEN;
                let (lo, hi) = (
                    f((x - tau) / r) - 1.0 / k as f32,
                    f((x + tau) / r) + 1.0 / k as f32,
                );
                assert!(
                    got >= lo - 1e-5 && got <= hi + 1e-5,
                    "K = {k}, α = {alpha}°: x = {x}: coverage {got} outside [{lo}, {hi}]"
                );
                worst = worst.max((got - f(x / r)).abs());
                if x.abs() < r {
                    sum_err += (got - f(x / r)).abs();
                    n_pen += 1;
                }
            }
        }
        println!(
            "K = {k}, α = {alpha}°, seed {seed}: penumbra half-width {r:.3} m, texel on the \
             ground {tau:.4} m; worst |P − F| = {worst:.4} (1/K = {:.4}), mean in the \
             penumbra {:.4}",
            1.0 / k as f32,
            sum_err / n_pen as f32
        );
    }
}

/// Pseudo-random numbers in [0, 1), reproducible.
fn noise(i: u64, k: u64) -> f32 {
    let v = (i * 3 + k + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    (v >> 40) as f32 / (1u64 << 24) as f32
}

/// A bumpy ground with a ridge steeper than the repose angle.
fn bumpy_ground(n: u32) -> HeightField {
    let cell = 0.02;
    HeightField::from_fn(Vec2::splat(-0.5), cell, UVec2::splat(n), |i, k| {
        let x = i as f32 * cell;
        0.05 * noise(i as u64, k as u64 * 1000) + 0.3 * (-(x - 0.4).powi(2) / 0.002).exp()
    })
    .unwrap()
}

#[test]
fn stabilisation_conserves_the_snow_exactly() {
    let ground = bumpy_ground(48);
    let mut sim = SnowSim::new(&SnowParams::default()).unwrap();
    sim.set_ground(&ground).unwrap();
    for c in 0..300u64 {
        let cell = UVec2::new((noise(c, 1) * 48.0) as u32, (noise(c, 2) * 48.0) as u32);
        sim.pour(cell, 2e-6 * noise(c, 3) as f64).unwrap();
    }
    let before = sim.ground().unwrap().total_units();
    let mut moved = 0;
    for _ in 0..20 {
        let r = sim.relax(25);
        moved += r.moved;
        assert_eq!(sim.ground().unwrap().total_units(), before);
    }
    assert!(moved > before / 2, "moved {moved} of {before}");
    // Snowfall on the same ground: the stabilisation inside each step adds nothing either.
    let mut p = params(8, 15.0);
    p.rate = 0.05;
    p.relax_passes = 0;
    let mut sim = SnowSim::new(&p).unwrap();
    for _ in 0..5 {
        sim.step(&[], Some(&ground), 0.2).unwrap();
        let before = sim.ground().unwrap().total_units();
        let r = sim.relax(50);
        assert!(r.moved > 0);
        assert_eq!(sim.ground().unwrap().total_units(), before);
    }
}

/// V poured onto one cell of flat ground in portions, stabilised in between and to rest at
/// the end: the pile's top is (3V tan²θ / π)^(1/3) within 5%.
#[test]
fn a_point_pour_settles_to_the_cone() {
    let (n, cell, theta) = (81u32, 0.01f32, 35.0f32);
    let ground = HeightField::constant(Vec2::ZERO, cell, UVec2::splat(n), 0.0).unwrap();
    let p = SnowParams {
        repose_degrees: theta,
        ..Default::default()
    };
    let tan = theta.to_radians().tan();
    // A cone of base radius 28 cells.
    let h = 28.0 * cell * tan;
    let volume = std::f64::consts::PI * (h as f64).powi(3) / (3.0 * tan as f64 * tan as f64);
    let mut sim = SnowSim::new(&p).unwrap();
    sim.set_ground(&ground).unwrap();
    let mut poured = 0u64;
    for _ in 0..20 {
        poured += sim.pour(UVec2::splat(n / 2), volume / 20.0).unwrap() as u64;
        sim.relax(100);
    }
    let rest = sim.relax(100_000);
    assert!(rest.settled, "{rest:?}");
    let g = sim.ground().unwrap();
    assert_eq!(g.total_units(), poured);
    let v = poured as f64 * QUANTUM as f64 * (cell * cell) as f64;
    let want = (3.0 * v * (tan * tan) as f64 / std::f64::consts::PI).cbrt() as f32;
    let top = g.thickness().into_iter().fold(0.0, f32::max);
    let centre = g.thickness()[g.base.index(n / 2, n / 2)];
    println!(
        "cone: V = {v:.3e} m³, top {top:.4} m (centre {centre:.4}) vs {want:.4} m: {:+.2}%; \
         {} passes to rest",
        100.0 * (top / want - 1.0),
        rest.passes
    );
    assert_eq!(top, centre);
    assert!((top / want - 1.0).abs() < 0.05);
}

#[test]
fn same_bytes_on_one_and_two_threads() {
    let run = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(threads);
        pool.build().unwrap().install(|| {
            let mut ball = uv_sphere(0.15, 32, 16);
            ball.transform(Mat4::from_translation(Vec3::new(0.0, 0.4, 0.0)));
            let ground = bumpy_ground(48);
            let mut p = params(8, 15.0);
            p.rate = 0.05;
            p.resolution = 256;
            let mut sim = SnowSim::new(&p).unwrap();
            let mut moved = 0;
            for _ in 0..5 {
                moved += sim.step(&[&ball], Some(&ground), 0.2).unwrap().relax.moved;
            }
            let cover = sim.cover(&[&ball]).unwrap();
            let g = sim.ground().unwrap();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            (
                moved,
                g.units.clone(),
                bits(&g.residual),
                bits(sim.mesh_depth(0)),
                cover,
                sim.arrival().unwrap().counts.clone(),
            )
        })
    };
    let one = run(1);
    assert!(one.0 > 0, "the ridge should shed snow");
    assert_eq!(one, run(2));
}

#[test]
fn a_changed_scene_is_refused_with_the_reason() {
    let p = params(1, 0.0);
    let ball = uv_sphere(0.3, 8, 4);
    let mut sim = SnowSim::new(&p).unwrap();
    sim.step(&[&ball], Some(&flat_ground(8)), 0.1).unwrap();
    let other = uv_sphere(0.3, 9, 4);
    let e = sim.step(&[&other], Some(&flat_ground(8)), 0.1).unwrap_err();
    assert!(
        matches!(e, Error::Invalid(_)) && e.to_string().contains("mesh 0"),
        "{e}"
    );
    let e = sim.step(&[&ball], Some(&flat_ground(9)), 0.1).unwrap_err();
    assert!(e.to_string().contains("ground"), "{e}");
    let e = sim.step(&[&ball], None, 0.1).unwrap_err();
    assert!(e.to_string().contains("ground"), "{e}");
    let e = sim.step(&[&ball], Some(&flat_ground(8)), -1.0).unwrap_err();
    assert!(e.to_string().contains("duration"), "{e}");
    let e = SnowSim::new(&SnowParams {
        directions: 0,
        ..Default::default()
    })
    .unwrap_err();
    assert!(e.to_string().contains("directions"), "{e}");
}

/// The benchmark's scene: 512² depth maps, 16 directions, a sphere on a ground, ~50k
/// triangles. Prints milliseconds (median of 5) for the arrival alone and a whole step.
#[test]
#[ignore]
fn timing_512_16_directions_50k_triangles() {
    let mut ball = uv_sphere(0.5, 160, 125);
    ball.transform(Mat4::from_translation(Vec3::new(0.0, 0.6, 0.0)));
    let p = SnowParams::default();
    for n in [72u32, 512] {
        let ground = HeightField::constant(
            Vec2::splat(-1.5),
            3.0 / (n - 1) as f32,
            UVec2::splat(n),
            0.0,
        )
        .unwrap();
        let (occluder, receivers) = gather(&[&ball], Some(&ground));
        let dirs = imprint_stages::snow::fall_directions(&p);
        let median = |mut v: Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let mut arrival = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            std::hint::black_box(arrival_cpu(&occluder, &receivers, &dirs, &p).unwrap());
            arrival.push(t.elapsed().as_secs_f64() * 1e3);
        }
        let mut sim = SnowSim::new(&p).unwrap();
        let mut step = Vec::new();
        for _ in 0..5 {
            let t = Instant::now();
            sim.step(&[&ball], Some(&ground), 1.0 / 60.0).unwrap();
            step.push(t.elapsed().as_secs_f64() * 1e3);
        }
        println!(
            "snow timing, {} threads: {} triangles ({} sphere + {n}² ground), {} receivers, \
             {}² maps x {} directions: arrival {:.1} ms, step {:.1} ms (median of 5)",
            rayon::current_num_threads(),
            occluder.triangles.len(),
            ball.triangles.len(),
            receivers.points.len(),
            p.resolution,
            dirs.len(),
            median(arrival),
            median(step)
        );
        if n == 512 {
            // Stabilisation with snow moving everywhere: piles on every 8th cell.
            for k in (0..n).step_by(8) {
                for i in (0..n).step_by(8) {
                    sim.pour(UVec2::new(i, k), 1e-4).unwrap();
                }
            }
            let t = Instant::now();
            let r = sim.relax(16);
            println!(
                "snow timing: stabilisation on {n}², {} passes moving {} quanta: {:.1} ms per pass",
                r.passes,
                r.moved,
                t.elapsed().as_secs_f64() * 1e3 / r.passes as f64
            );
        }
    }
}
