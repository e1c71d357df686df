//! Ground (docs/methods.md §7, O) on the CPU: tests with known answers.
//!
//! Fields are flat at h0 = 0.1 m with 1 cm cells (5 mm where a radius is measured) and the
//! default height unit of 1e-5 m, so every depth below is a whole number of units.

use glam::Vec3;
use imprint_core::Mesh;
use imprint_stages::ground::contact::object_bottoms;
use imprint_stages::ground::{
    GroundParams, GroundSim, Material, NO_OBJECT, Preset, Relaxation, UNLABELLED,
};
use imprint_tests::ground::{cuboid_at, params, roll, sim, sphere, time_rolling_sphere};

const H0: f32 = 0.1;
const UNIT: f64 = 1e-5;
const H0U: i32 = 10_000;

fn sand() -> Material {
    Material::Preset(Preset::Sand)
}

fn snow() -> Material {
    Material::Preset(Preset::Snow)
}

/// World (x, z) of every cell's centre, with its index.
fn cells(g: &GroundSim) -> impl Iterator<Item = (usize, f32, f32)> + '_ {
    let grid = *g.grid();
    (0..grid.len()).map(move |j| {
        let c = grid.centre(j as u32 % grid.dims.x, j as u32 / grid.dims.x);
        (j, c.x, c.y)
    })
}

/// With α = 1 material is only moved: the integer sum of the heights is the same after
/// every frame of a sphere rolling through the sand (its rim ploughed ahead of it), in both
/// relaxation modes and with a custom steeper material, and everything pressed out reaches
/// the rim.
#[test]
fn mass_is_conserved_exactly_with_alpha_one() {
    let custom = Material::Custom {
        repose_degrees: 45.0,
        slump_iterations: 20,
        displace_ratio: 1.0,
    };
    for (material, relaxation) in [
        (sand(), Relaxation::Labelled),
        (sand(), Relaxation::Full),
        (custom, Relaxation::Labelled),
    ] {
        let mut p = params(96, 0.01, H0, material);
        p.relaxation = relaxation;
        let mut g = sim(&p);
        let before = g.mass();
        assert_eq!(before, 96 * 96 * H0U as i64);
        let frames = roll(&mut g, 0.1, 0.03, H0, -0.15, 0.02, 16);
        let mut slumped = 0;
        for m in &frames {
            assert!(m.contact_cells > 0 && m.removed_units > 0, "{m:?}");
            assert_eq!(m.displaced_units, m.removed_units, "{relaxation:?}: {m:?}");
            assert_eq!(m.mass_units, before, "{relaxation:?} frame {}", m.frame);
            slumped += m.slumped_units;
        }
        assert_eq!(g.mass(), before);
        assert!(slumped > 0, "{relaxation:?}: the rims slumped");
        let last = frames.last().unwrap();
        println!(
            "{material:?} {relaxation:?}: mass {before} units before and after 16 frames; last \
             frame removed {} units, slump moved {} units in {} passes, max slope {:.3}",
            last.removed_units, last.slumped_units, last.slump_iterations, last.max_slope
        );
    }
}

/// With α = 0 what the ground loses is exactly what the objects pressed out.
/// A box whose sides lie on cell boundaries, sunk d = 2 cm: analytically 20 × 20 cells ×
/// 2000 units = 800,000 units (8e-4 m³). A sphere: the sum of (ground − bottom) over the
/// contact cells of an independent contact pass, and the spherical cap π d² (3R − d) / 3
/// to within the faceting and the cells.
#[test]
fn alpha_zero_removes_exactly_the_penetrating_volume() {
    let p = params(64, 0.01, H0, snow());
    let mut g = sim(&p);
    let before = g.mass();
    let b = cuboid_at(
        Vec3::new(0.1, 0.05, 0.1),
        Vec3::new(0.0, H0 - 0.02 + 0.05, 0.0),
    );
    let m = g.step(&[&b]).unwrap();
    assert_eq!(m.contact_cells, 400);
    assert_eq!(m.removed_units, 800_000);
    assert_eq!(m.displaced_units, 0);
    assert_eq!(before - g.mass(), 800_000);
    // In m³ to the f32 cell size's precision.
    assert!(
        (m.removed_volume / 8e-4 - 1.0).abs() < 1e-6,
        "{}",
        m.removed_volume
    );

    let (r, d) = (0.15f32, 0.04f32);
    let ball = sphere(r, Vec3::new(0.013, H0 + r - d, -0.021));
    let mut g = sim(&params(64, 0.01, H0, snow()));
    let heights = g.heights_units().to_vec();
    let bt = object_bottoms(&[&ball], g.grid(), &heights)
        .unwrap()
        .unwrap();
    let mut pen = 0i64;
    for (j, &b) in bt.bottom.iter().enumerate() {
        let (x, y) = (j as u32 % bt.window.w, j as u32 / bt.window.w);
        let h = heights[bt.window.global(x, y, 64)];
        if b != NO_OBJECT && b < h {
            pen += (h - b) as i64;
        }
    }
    let before = g.mass();
    let m = g.step(&[&ball]).unwrap();
    assert_eq!(m.removed_units, pen);
    assert_eq!(before - g.mass(), pen);
    let (r, d) = (r as f64, d as f64);
    let cap = std::f64::consts::PI * d * d * (3.0 * r - d) / 3.0;
    let rel = (m.removed_volume - cap) / cap;
    println!(
        "sphere: removed {:.4e} m³ = Σ(ground − bottom) over the contact pass; cap {cap:.4e} \
         m³ ({:+.2}%)",
        m.removed_volume,
        100.0 * rel
    );
    assert!(rel.abs() < 0.02, "{rel}");
}

/// Snow (θ 90°, En 0, α 0): a box pressed 2 cm leaves a hole exactly 2 cm deep under its
/// footprint and the ground untouched elsewhere, so each wall drops the whole depth between
/// two neighbouring cells; the print stays as it is on later frames.
#[test]
fn snow_box_leaves_depth_exactly_d_with_vertical_walls() {
    let mut g = sim(&params(64, 0.01, H0, snow()));
    let b = cuboid_at(
        Vec3::new(0.1, 0.05, 0.06),
        Vec3::new(0.03, H0 - 0.02 + 0.05, 0.0),
    );
    g.step(&[&b]).unwrap();
    for _ in 0..3 {
        let m = g.step(&[]).unwrap();
        assert_eq!(m.contact_cells, 0);
    }
    let mut inside = 0;
    for (j, x, z) in cells(&g).collect::<Vec<_>>() {
        let under = (x - 0.03).abs() < 0.1 && z.abs() < 0.06;
        let want = if under { H0U - 2000 } else { H0U };
        assert_eq!(g.heights_units()[j], want, "cell at ({x}, {z})");
        inside += under as u32;
    }
    assert_eq!(inside, 20 * 12);
}

/// A sphere of radius R sunk d touches a disc of radius √(2Rd − d²): the farthest contact
/// cell centre, and the radius of a disc of the contact's area, are within one cell of it,
/// and every cell whose centre is a cell inside that radius is in contact.
#[test]
fn sphere_contact_radius_is_the_analytic_one_within_a_cell() {
    let cell = 0.005f32;
    for (r, d) in [(0.2f32, 0.05f32), (0.1, 0.01), (0.15, 0.08)] {
        let mut g = sim(&params(128, cell, H0, snow()));
        let (cx, cz) = (0.0011f32, -0.0023f32);
        let m = g
            .step(&[&sphere(r, Vec3::new(cx, H0 + r - d, cz))])
            .unwrap();
        let a = (2.0 * r * d - d * d).sqrt();
        let maps = g.maps().unwrap();
        let win = maps.window;
        let mut farthest = 0.0f32;
        for (j, &c) in maps.contact.iter().enumerate() {
            let p = g
                .grid()
                .centre(win.i0 + j as u32 % win.w, win.k0 + j as u32 / win.w);
            let rho = ((p.x - cx).powi(2) + (p.y - cz).powi(2)).sqrt();
            if c {
                farthest = farthest.max(rho);
            } else {
                assert!(rho > a - cell, "cell at {rho} m not in contact (a = {a})");
            }
        }
        let area_radius = (m.contact_cells as f32 * cell * cell / std::f32::consts::PI).sqrt();
        println!(
            "R {r} d {d}: analytic {a:.5} m, farthest contact centre {farthest:.5} m, \
             equal-area radius {area_radius:.5} m, cell {cell}"
        );
        assert!((farthest - a).abs() <= cell, "{farthest} vs {a}");
        assert!((area_radius - a).abs() <= cell, "{area_radius} vs {a}");
    }
}

/// The contour maps equal brute-force L1 distances over the whole field: inside, to the
/// nearest cell out of contact; outside, to the nearest contact cell minus one, for the
/// band's rings. An irregular contact (a sphere and a box overlapping) and one hanging over
/// the field's edge. The contact itself matches an independent contact pass.
#[test]
fn contour_maps_equal_an_exact_city_block_distance_transform() {
    let n = 64u32;
    let scenes: Vec<Vec<Mesh>> = vec![
        vec![
            sphere(0.1, Vec3::new(-0.05, H0 + 0.1 - 0.04, 0.0)),
            cuboid_at(
                Vec3::new(0.06, 0.05, 0.03),
                Vec3::new(0.08, H0 + 0.05 - 0.01, 0.06),
            ),
        ],
        vec![sphere(0.12, Vec3::new(-0.3, H0 + 0.12 - 0.05, 0.25))],
    ];
    for objects in &scenes {
        let p = params(n, 0.01, H0, sand());
        let band = p.slump_band;
        let mut g = sim(&p);
        let refs: Vec<&Mesh> = objects.iter().collect();
        let heights = g.heights_units().to_vec();
        let bt = object_bottoms(&refs, g.grid(), &heights).unwrap().unwrap();
        g.step(&refs).unwrap();
        let maps = g.maps().unwrap();
        let win = maps.window;
        // The contact on the whole field, from the independent pass.
        let mut contact = vec![false; (n * n) as usize];
        for (j, &b) in bt.bottom.iter().enumerate() {
            let gj = bt
                .window
                .global(j as u32 % bt.window.w, j as u32 / bt.window.w, n);
            contact[gj] = b < heights[gj];
        }
        assert_eq!(
            maps.contact.iter().filter(|&&c| c).count(),
            contact.iter().filter(|&&c| c).count()
        );
        let l1 = |a: usize, b: usize| {
            let (ax, az) = ((a as u32 % n) as i64, (a as u32 / n) as i64);
            let (bx, bz) = ((b as u32 % n) as i64, (b as u32 / n) as i64);
            ((ax - bx).abs() + (az - bz).abs()) as u32
        };
        let nearest = |j: usize, want: bool| {
            (0..contact.len())
                .filter(|&s| contact[s] == want)
                .map(|s| l1(j, s))
                .min()
                .unwrap()
        };
        let mut deepest = 0;
        for y in 0..win.h {
            for x in 0..win.w {
                let (j, gj) = ((y * win.w + x) as usize, win.global(x, y, n));
                assert_eq!(maps.contact[j], contact[gj]);
                let inner = if contact[gj] { nearest(gj, false) } else { 0 };
                assert_eq!(maps.inner[j], inner, "inner at ({x}, {y})");
                deepest = deepest.max(inner);
                let outer = match contact[gj] {
                    true => UNLABELLED,
                    false => match nearest(gj, true) {
                        d if d <= band => d - 1,
                        _ => UNLABELLED,
                    },
                };
                assert_eq!(maps.outer[j], outer, "outer at ({x}, {y})");
            }
        }
        assert!(deepest >= 3, "a contact several rings deep ({deepest})");
    }
}

/// After `Full` relaxation (and with the object lifted, so no cell is held) no neighbour
/// difference exceeds T + 1 unit, i.e. every slope is at most tan θ + unit / cell
/// (tan 30° + 0.001 here): after a sand print, and from a random field with slopes up to
/// 5. Mass is unchanged, and a cap too low for the random field is an error naming it that
/// leaves the ground as it was.
#[test]
fn full_relaxation_leaves_every_slope_within_theta() {
    let custom = Material::Custom {
        repose_degrees: 30.0,
        slump_iterations: 5,
        displace_ratio: 1.0,
    };
    let mut p = params(48, 0.01, H0, custom);
    p.relaxation = Relaxation::Full;
    let t = (30f64.to_radians().tan() * 0.01 / UNIT).floor() as i64;
    let check = |g: &GroundSim, what: &str| {
        let h = g.heights_units();
        let mut worst = 0;
        for j in 0..h.len() {
            if j % 48 + 1 < 48 {
                worst = worst.max((h[j] as i64 - h[j + 1] as i64).abs());
            }
            if j + 48 < h.len() {
                worst = worst.max((h[j] as i64 - h[j + 48] as i64).abs());
            }
        }
        println!(
            "{what}: steepest difference {worst} units (T = {t}), slope {:.5} (tan 30° = {:.5})",
            worst as f64 * UNIT / 0.01,
            30f64.to_radians().tan()
        );
        assert!(worst <= t + 1, "{what}: {worst} > {t} + 1");
    };

    let mut g = sim(&p);
    assert_eq!(g.threshold_units(), Some(t));
    let before = g.mass();
    let pressed = roll(&mut g, 0.1, 0.04, H0, 0.0, 0.0, 1);
    assert!(pressed[0].slump_iterations > 1 && pressed[0].slumped_units > 0);
    let m = g.step(&[]).unwrap();
    assert_eq!(g.mass(), before);
    assert!(m.max_slope as f64 <= 30f64.to_radians().tan() + UNIT / 0.01);
    check(&g, "sand print, object lifted");

    // A random field (an LCG) 0..5 cm high.
    let mut s = 99u64;
    let rough: Vec<i32> = (0..48 * 48)
        .map(|_| {
            s = s
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            ((s >> 33) % 5000) as i32
        })
        .collect();
    let mut tight = p.clone();
    tight.max_relax_iterations = 2;
    let mut stuck = GroundSim::from_units(&tight, rough.clone()).unwrap();
    let e = stuck.step(&[]).unwrap_err().to_string();
    assert!(e.contains("max_relax_iterations = 2"), "{e}");
    assert_eq!(stuck.heights_units(), &rough[..]);

    let mut g = GroundSim::from_units(&p, rough).unwrap();
    let before = g.mass();
    let m = g.step(&[]).unwrap();
    println!(
        "random field: at rest after {} iterations, {} units moved",
        m.slump_iterations, m.slumped_units
    );
    assert_eq!(g.mass(), before);
    check(&g, "random field");
    // At rest: a further frame moves nothing.
    let again = g.step(&[]).unwrap();
    assert_eq!((again.slump_iterations, again.slumped_units), (1, 0));
}

/// The field persists: a sphere rolled across snow in 1 cm steps leaves one continuous
/// trench of its depth along its path, and nothing changes away from it.
#[test]
fn tracks_accumulate_along_a_path() {
    let mut g = sim(&params(96, 0.01, H0, snow()));
    let (r, d) = (0.1f32, 0.02f32);
    for f in 0..51 {
        let c = Vec3::new(-0.25 + 0.01 * f as f32, H0 + r - d, 0.005);
        g.step(&[&sphere(r, c)]).unwrap();
    }
    let du = (d as f64 / UNIT).round() as i32;
    let h = g.heights_units().to_vec();
    let mut along = 0;
    for (j, x, z) in cells(&g).collect::<Vec<_>>() {
        if (z - 0.005).abs() < 1e-4 && x.abs() < 0.25 {
            // Under the path: the full depth, less the sphere's rise ≤ 5 mm off its lowest
            // point and its faceting (< 0.5 mm together).
            let depth = H0U - h[j];
            assert!(
                depth <= du && depth >= du - 50,
                "x = {x}: depth {depth} units"
            );
            along += 1;
        }
        if (z - 0.005).abs() > r + 0.02 || x.abs() > 0.25 + r + 0.02 {
            assert_eq!(h[j], H0U, "({x}, {z}) is off the path");
        }
    }
    assert_eq!(along, 50);
}

/// Same bytes whatever the number of threads, in both modes.
#[test]
fn thread_count_does_not_change_a_byte() {
    let run = |threads: usize, relaxation: Relaxation| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| {
                let mut p: GroundParams = params(64, 0.01, H0, sand());
                p.relaxation = relaxation;
                let mut g = sim(&p);
                let m = roll(&mut g, 0.08, 0.03, H0, -0.1, 0.015, 10);
                (g.heights_units().to_vec(), m)
            })
    };
    for mode in [Relaxation::Labelled, Relaxation::Full] {
        let (h1, m1) = run(1, mode);
        let (h2, m2) = run(2, mode);
        assert_eq!(h1, h2, "{mode:?}");
        assert_eq!(m1, m2, "{mode:?}");
    }
}

/// Milliseconds per contact frame of a sphere crossing the field. Not an assertion (timings
/// do not belong in tests): `cargo test --release -p imprint-tests --test ground_cpu --
/// --ignored --nocapture`.
#[test]
#[ignore]
fn timing_rolling_sphere() {
    let cases = [
        (
            "Sand, Labelled",
            256,
            0.01,
            sand(),
            Relaxation::Labelled,
            60,
        ),
        (
            "Snow, Labelled",
            256,
            0.01,
            snow(),
            Relaxation::Labelled,
            60,
        ),
        ("Sand, Full", 256, 0.01, sand(), Relaxation::Full, 20),
        (
            "Sand, Labelled",
            1024,
            0.0025,
            sand(),
            Relaxation::Labelled,
            30,
        ),
        (
            "Snow, Labelled",
            1024,
            0.0025,
            snow(),
            Relaxation::Labelled,
            30,
        ),
    ];
    for (name, n, cell, material, relaxation, frames) in cases {
        let mut p = params(n, cell, H0, material);
        p.relaxation = relaxation;
        let ms = time_rolling_sphere(&p, frames);
        println!(
            "ground {n}² ({name}), {frames} frames on {} rayon threads: {ms:.3} ms per contact frame",
            rayon::current_num_threads()
        );
    }
}
