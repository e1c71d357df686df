//! Golden-image test of the CPU frame renderer, and the bunny timing (ignored).
//!
//! The reference PNGs live in `tests/golden/`. To (re)generate them after a deliberate change
//! to the renderer, run
//!
//! ```text
//! IMPRINT_BLESS=1 cargo test --release -p imprint-render --test frame_golden
//! ```
//!
//! then LOOK at the new PNG before committing it. On a mismatch the test writes
//! `target/golden-diff/<name>_actual.png` and `<name>_diff.png` (differences amplified ×8 on
//! black) and names them in the failure message.

use image::{Rgb, RgbImage};
use imprint_core::Mesh;
use imprint_core::glam::Vec3;
use imprint_render::frame::{GroundGrid, Object, RenderOptions, Scene, orbit, render_cpu};
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod common;
use common::sphere_torus_scene;

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Compares `actual` with `tests/golden/<name>.png`: at least 99.5 % of the pixels must have
/// a largest channel difference ≤ 2 (and the sizes must match).
fn check_golden(name: &str, actual: &RgbImage) {
    let golden = crate_dir().join("tests/golden").join(format!("{name}.png"));
    if std::env::var_os("IMPRINT_BLESS").is_some() {
        actual.save(&golden).unwrap();
        eprintln!("blessed {}", golden.display());
        return;
    }
    let expected = image::open(&golden)
        .unwrap_or_else(|e| {
            panic!(
                "cannot read {}: {e}; generate it with IMPRINT_BLESS=1",
                golden.display()
            )
        })
        .to_rgb8();
    let same_size = expected.dimensions() == actual.dimensions();
    let mut bad = 0usize;
    let mut diff = RgbImage::new(actual.width(), actual.height());
    if same_size {
        for (x, y, a) in actual.enumerate_pixels() {
            let e = expected.get_pixel(x, y);
            let d: [u8; 3] = std::array::from_fn(|k| a.0[k].abs_diff(e.0[k]));
            if d.iter().any(|v| *v > 2) {
                bad += 1;
            }
            diff.put_pixel(x, y, Rgb(d.map(|v| v.saturating_mul(8))));
        }
    }
    let total = (actual.width() * actual.height()) as usize;
    if !same_size || bad as f64 > 0.005 * total as f64 {
        // target/ of the workspace: two levels above the crate.
        let out = crate_dir().join("../../target/golden-diff");
        std::fs::create_dir_all(&out).unwrap();
        let (pa, pd) = (
            out.join(format!("{name}_actual.png")),
            out.join(format!("{name}_diff.png")),
        );
        actual.save(&pa).unwrap();
        diff.save(&pd).unwrap();
        panic!(
            "{name}: {} ({bad} of {total} pixels differ by more than 2 levels; sizes {:?} vs {:?}); \
             wrote {} and {}",
            golden.display(),
            actual.dimensions(),
            expected.dimensions(),
            pa.display(),
            pd.display()
        );
    }
}

#[test]
fn golden_sphere_torus_grid() {
    let camera = orbit(Vec3::new(0.0, 0.4, 0.0), 3.6, 25.0, 15.0, 40.0).unwrap();
    let opts = RenderOptions {
        width: 128,
        height: 96,
        samples: 2,
        camera,
    };
    let img = render_cpu(&sphere_torus_scene(), &opts).unwrap();
    check_golden("sphere_torus_grid", &img);
}

/// Prints the time to render the Stanford bunny at 1280×720 with samples 2 (CPU).
/// `cargo test --release -p imprint-render --test frame_golden -- --ignored --nocapture`
#[test]
#[ignore]
fn bunny_1280x720_timing() {
    let path = crate_dir().join("../../assets/meshes/stanford-bunny.obj");
    let mut bunny = Mesh::load_obj(Path::new(&path)).unwrap();
    bunny.transform(bunny.fit_transform(1.0, Vec3::new(0.0, 0.5, 0.0)));
    let tris = bunny.triangles.len();
    let scene = Scene {
        objects: vec![Object::mesh(Arc::new(bunny), [0.75, 0.7, 0.6])],
        ground_grid: Some(GroundGrid::default()),
        ..Scene::default()
    };
    let camera = orbit(Vec3::new(0.0, 0.45, 0.0), 2.2, 20.0, 30.0, 40.0).unwrap();
    let opts = RenderOptions {
        width: 1280,
        height: 720,
        samples: 2,
        camera,
    };
    let img = render_cpu(&scene, &opts).unwrap(); // warm-up
    let runs = 3;
    let t = std::time::Instant::now();
    for _ in 0..runs {
        std::hint::black_box(render_cpu(&scene, &opts).unwrap());
    }
    let ms = t.elapsed().as_secs_f64() * 1e3 / runs as f64;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "bunny ({tris} triangles) 1280x720 samples 2, CPU: {ms:.1} ms per frame ({threads} threads)"
    );
    let out = crate_dir().join("../../target/golden-diff");
    std::fs::create_dir_all(&out).unwrap();
    img.save(out.join("bunny_1280x720.png")).unwrap();
}
