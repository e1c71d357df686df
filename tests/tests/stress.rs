//! Scene stress (issue 15 item 4): scenes generated from a seed (`imprint_tests::stress`) run
//! in-process, with invariants checked after every frame (finite values, no cloth particle
//! inside a closed body, exact ground mass and settled slopes, snow mass equal to what fell,
//! skin volume in bounds). A failing seed is printed and written as a pipeline that reproduces
//! it, `target/stress-failures/seed-<n>.ron` (`imprint run` runs it).
//!
//!   cargo test --release -p imprint-tests --test stress                 # the CI seeds
//!   cargo test --release -p imprint-tests --test stress -- --ignored    # 1,000 seeds
//!   IMPRINT_STRESS_SEEDS=17,40..45 cargo test --release -p imprint-tests --test stress \
//!       -- --nocapture chosen_seeds                                       # some seeds, verbose
//!   IMPRINT_STRESS_FILE=target/stress-failures/seed-9.ron cargo test ... chosen_seeds
//!                                                     # one pipeline file through the checks

use imprint_tests::stress::check::run_file;
use imprint_tests::stress::{Outcome, Scene};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The seeds every CI run checks.
const CI_SEEDS: std::ops::Range<u64> = 0..64;

/// Where failing seeds are written: `target/stress-failures/`.
fn failure_dir() -> PathBuf {
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    tmp.parent().unwrap_or(tmp).join("stress-failures")
}

/// Seeds from `IMPRINT_STRESS_SEEDS` ("3,17,40..60"), if set.
fn seeds_from_env() -> Option<Vec<u64>> {
    let s = std::env::var("IMPRINT_STRESS_SEEDS").ok()?;
    let mut seeds = Vec::new();
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        match part.split_once("..") {
            Some((a, b)) => seeds.extend(a.parse::<u64>().unwrap()..b.parse::<u64>().unwrap()),
            None => seeds.push(part.parse().unwrap()),
        }
    }
    Some(seeds)
}

/// The header of a reproduction: what failed, and how to run it.
fn header(scene: &Scene, o: &Outcome) -> String {
    let mut h = format!(
        "// FAILED (imprint scene stress, seed {}): {} invariant(s) broken in {} of {} frames\n",
        scene.seed,
        o.failures.len(),
        o.frames_run,
        scene.frames
    );
    for f in &o.failures {
        h += &format!("//   {f}\n");
    }
    h + "//\n"
}

/// Runs `seeds` one after the other; prints one line per seed, writes each failing one under
/// [`failure_dir`] and fails at the end naming them all.
fn run_seeds(seeds: &[u64], verbose: bool) {
    let tmp = tempfile::tempdir().unwrap();
    let started = Instant::now();
    let mut failed: Vec<(u64, PathBuf, Outcome)> = Vec::new();
    let mut slowest = (0u64, 0.0f64);
    let mut all = Outcome::default();
    for &seed in seeds {
        let scene = Scene::generate(seed);
        let dir = tmp.path().join(format!("seed-{seed}"));
        let path = scene.write(&dir, "").unwrap();
        let o = run_file(&path, &dir.join("out"));
        let _ = std::fs::remove_dir_all(&dir);
        all.merge_counts(&o);
        if o.ms > slowest.1 {
            slowest = (seed, o.ms);
        }
        let parts: Vec<&str> = scene
            .parts
            .iter()
            .filter(|p| !p.starts_with(' '))
            .map(|p| p.split(':').next().unwrap_or(""))
            .collect();
        eprintln!(
            "seed {seed:>4}: {:>2}/{} frames {:>6.0} ms [{}] {}",
            o.frames_run,
            scene.frames,
            o.ms,
            parts.join(" "),
            if o.failures.is_empty() {
                "ok".to_string()
            } else {
                let mut names: Vec<&str> = o.failures.iter().map(|f| f.invariant).collect();
                names.dedup();
                format!("FAILED: {}", names.join(", "))
            }
        );
        if verbose {
            for p in &scene.parts {
                eprintln!("      {p}");
            }
            for n in &o.notes {
                eprintln!("      note: {n}");
            }
        }
        if o.failures.is_empty() {
            // A reproduction left by an earlier run of this seed is stale now.
            let _ = std::fs::remove_file(failure_dir().join(Scene::file(seed)));
            let _ = std::fs::remove_file(failure_dir().join(Scene::rig_file(seed)));
        } else {
            let repro = scene.write(&failure_dir(), &header(&scene, &o)).unwrap();
            for f in &o.failures {
                eprintln!("      {f}");
            }
            eprintln!(
                "      reproduce: imprint run {} --out out/seed-{seed}",
                repro.display()
            );
            failed.push((seed, repro, o));
        }
    }
    eprintln!("checked (node-frames): {:?}", all.checked);
    for (what, (lo, hi)) in &all.ranges {
        eprintln!("  {what}: {lo:.4} .. {hi:.4}");
    }
    eprintln!(
        "{} seed(s) in {:.1} s (slowest: seed {} in {:.0} ms), {} failed",
        seeds.len(),
        started.elapsed().as_secs_f64(),
        slowest.0,
        slowest.1,
        failed.len()
    );
    if !failed.is_empty() {
        let list: Vec<String> = failed
            .iter()
            .map(|(seed, path, o)| {
                let mut names: Vec<&str> = o.failures.iter().map(|f| f.invariant).collect();
                names.dedup();
                format!("  seed {seed}: {} ({})", names.join(", "), path.display())
            })
            .collect();
        panic!(
            "{} of {} seed(s) broke an invariant:\n{}",
            failed.len(),
            seeds.len(),
            list.join("\n")
        );
    }
}

#[test]
fn scenes_keep_their_invariants() {
    let seeds: Vec<u64> = CI_SEEDS.collect();
    run_seeds(&seeds, false);
}

/// A thousand seeds (minutes): `-- --ignored`.
#[test]
#[ignore]
fn a_thousand_scenes_keep_their_invariants() {
    let seeds: Vec<u64> = (0..1000).collect();
    run_seeds(&seeds, false);
}

/// The seeds of `IMPRINT_STRESS_SEEDS`, with each scene's parts and notes, and the pipeline
/// file `IMPRINT_STRESS_FILE` (a reproduction, perhaps cut down by hand) checked the same way
/// (nothing without them).
#[test]
fn chosen_seeds() {
    if let Some(seeds) = seeds_from_env() {
        run_seeds(&seeds, true);
    }
    if let Ok(file) = std::env::var("IMPRINT_STRESS_FILE") {
        let out = tempfile::tempdir().unwrap();
        let o = run_file(Path::new(&file), out.path());
        eprintln!(
            "{file}: {} frame(s) checked in {:.0} ms",
            o.frames_run, o.ms
        );
        for n in &o.notes {
            eprintln!("  note: {n}");
        }
        for f in &o.failures {
            eprintln!("  {f}");
        }
        assert!(o.failures.is_empty(), "{file} broke an invariant");
    }
}

#[test]
fn the_same_seed_gives_the_same_scene() {
    for seed in [0, 1, 7, 123, 999, u64::MAX] {
        assert_eq!(Scene::generate(seed), Scene::generate(seed), "seed {seed}");
    }
    let texts: std::collections::BTreeSet<String> =
        (0..50).map(|s| Scene::generate(s).pipeline).collect();
    assert_eq!(texts.len(), 50, "50 seeds give 50 scenes");
}

/// Every part of the generator is drawn over the CI seeds, and every scene is a valid
/// pipeline (checked without running it).
#[test]
fn the_ci_seeds_cover_every_part() {
    let tmp = tempfile::tempdir().unwrap();
    let mut seen = std::collections::BTreeMap::<&str, u32>::new();
    for seed in CI_SEEDS {
        let scene = Scene::generate(seed);
        let path = scene.write(tmp.path(), "").unwrap();
        if let Err(e) = imprint_graph::load(&path, &[]) {
            panic!("seed {seed}: {e}\n{}", scene.pipeline);
        }
        let text = &scene.pipeline;
        for (part, needle) in [
            ("cloth", "Cloth("),
            ("field collider", "colliders: [\"field\"]"),
            ("depth collider", "depth_colliders"),
            ("ground", "Ground("),
            ("sand", "Preset(Sand)"),
            ("snow ground", "Preset(Snow)"),
            ("custom ground", "Custom("),
            ("full relaxation", "relaxation: Full"),
            ("ground on snow", "accumulate"),
            ("snow", "Snow("),
            ("skin", "Skin("),
            ("particles", "Particles()"),
            ("lbs", "Linear()"),
            ("dqs", "DualQuaternion()"),
            ("rigid keys", "Rigid("),
            ("breathe", "Breathe("),
            ("twist", "Twist("),
            ("bend", "Bend("),
            ("cow", "cow.obj"),
            ("bunny", "stanford-bunny.obj"),
            ("suzanne", "suzanne.obj"),
            ("teapot", "teapot.obj"),
            ("sphere", "Sphere("),
            ("box", "Box("),
            ("torus", "Torus("),
            ("tokoi", "Tokoi("),
        ] {
            if text.contains(needle) {
                *seen.entry(part).or_default() += 1;
            } else {
                seen.entry(part).or_default();
            }
        }
    }
    let missing: Vec<_> = seen.iter().filter(|(_, n)| **n == 0).collect();
    eprintln!("parts over the CI seeds: {seen:?}");
    assert!(missing.is_empty(), "never drawn: {missing:?}");
}

/// The inside test applies to the closed bodies only: the cow and the primitives are closed,
/// the teapot, the bunny and Suzanne are not (assets/meshes/README.md).
#[test]
fn closed_bodies_are_told_from_open_ones() {
    use imprint_core::mesh::primitives::{cuboid, cylinder, torus, uv_sphere};
    for (name, closed) in [
        ("cow", true),
        ("teapot", false),
        ("stanford-bunny", false),
        ("suzanne", false),
    ] {
        assert_eq!(imprint_tests::mesh(name).is_closed(), closed, "{name}");
    }
    assert!(uv_sphere(0.5, 16, 8).is_closed());
    assert!(cuboid(glam::Vec3::splat(0.3), 4).is_closed());
    assert!(torus(0.35, 0.1, 16, 8).is_closed());
    assert!(cylinder(0.1, 1.0, 16, 8).is_closed());
}

/// The checker is not vacuous: a cloth started inside a closed sphere with no collider is
/// caught by the inside test, and its reproduction runs as a pipeline.
#[test]
fn a_cloth_inside_a_body_is_caught() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("inside.ron");
    std::fs::write(
        &path,
        r#"Pipeline(frames: 3, fps: 24, backend: Cpu, nodes: {
            "ball": Mesh(primitive: Sphere(radius: 0.5, segments: 24, rings: 12),
                         fit: (size: 1.0, center: (0, 1, 0))),
            "body_field": Voxelize(mesh: "ball", grid: Fit(resolution: 16, padding: 0.2)),
            "field": DistanceField(boundary: "body_field", band: 2, measure: Never),
            "c2": Cloth(colliders: ["field"], params: (
                shape: Grid(size: (0.2, 0.2), resolution: (4, 4), center: (0, 1.0, 0), normal: (0, 1, 0)),
                material: Harada(k_structural: 20.0, k_shear: 5.0), substeps: 8,
                collision: (epsilon: 0.001, friction: 0.0))),
            "keep": WriteMesh(mesh: "c2", every: 3, offset: 2),
            "keep_ball": WriteMesh(mesh: "ball", every: 3, offset: 2),
        })"#,
    )
    .unwrap();
    let o = run_file(&path, &dir.path().join("out"));
    eprintln!("{o:#?}");
    assert_eq!(o.frames_run, 3);
    // The small cloth starts at the sphere's centre, 0.5 m deep: the field pushes it out only
    // within its band, so it stays inside.
    let f = o
        .failures
        .iter()
        .find(|f| f.invariant == "cloth-inside-body" && f.node == "c2")
        .expect("caught");
    assert!(f.worst > 100.0, "{f}");
}
