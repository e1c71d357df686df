//! The GPU frame renderer (`imprint_render::gpu_frame::GpuRenderer`) against the CPU renderer
//! (`render_cpu`) on the same scenes.
//!
//! Where they may differ, and why:
//! - surfaces without anti-aliasing (`samples: 1`): coverage follows the same fill rules (see
//!   `tests/tests/gpu_raster.rs`: identical on lavapipe) and the shading is the same formula,
//!   so the images agree to rounding (measured: at most 1 level);
//! - surfaces with anti-aliasing: the CPU box-filters 2×2 (or s×s) shaded samples on a
//!   regular grid, the GPU takes 4 MSAA coverage samples on the rotated standard pattern and
//!   shades once per pixel (both average in linear space), so edge pixels differ by up to a
//!   quarter of the contrast across the edge, interiors by rounding;
//! - lines (ground grid, wireframes): the CPU stamps s×s-sample squares along each line, so
//!   its lines get heavier with the slope (about 1.5 px of ink per column at 45° for s = 2)
//!   and the DDA steps differ from the hardware's line rules; the GPU draws 1-pixel hardware
//!   lines (about 1.2 px per column at 45° on lavapipe with MSAA). Lines are thus the largest
//!   difference, and are compared separately from the surfaces.
//!
//! Each comparison bounds (a) the mean absolute difference of each channel over the image, in
//! levels, and (b) the share of pixels whose largest channel difference is ≤ `NEAR` (8)
//! levels. Measured on Mesa lavapipe (LLVM 15), worst of the scenes here, and the bounds:
//!
//! | comparison                    | measured mean | measured near | bound mean | bound near |
//! |-------------------------------|---------------|---------------|------------|------------|
//! | surfaces, samples 1           | 0.012 (max 1) | 100 %         | 0.1        | 99.5 %     |
//! | surfaces, samples 2 / MSAA 4× | 0.76          | 96.4 %        | 1.5        | 94 %       |
//! | with lines, samples 1         | 4.2           | 96.8 %        | 7          | 94 %       |
//! | with lines, samples 2 / MSAA  | 8.5           | 80.1 %        | 13         | 72 %       |
//!
//! (The 1280×720 bunny with the default grid, samples 2: mean 1.3, 97.0 % near; see the
//! ignored timing test.)
//!
//! On a failure (or always, with `IMPRINT_WRITE_DIFF=1`) the CPU image, the GPU image and
//! their difference (×8 on black) are written to `target/gpu-frame-diff/` and named in the
//! message. Every test skips, with a note, on a
//! machine without a GPU adapter; `IMPRINT_REQUIRE_GPU=1` makes that a failure.

use image::{Rgb, RgbImage};
use imprint_core::glam::{Mat4, UVec3, Vec3};
use imprint_core::mesh::primitives::{cuboid, uv_sphere};
use imprint_core::{Camera, DistanceField, Error, GridSpec, Mesh};
use imprint_gpu::test_context;
use imprint_render::frame::{GroundGrid, Object, RenderOptions, Scene, orbit, render_cpu};
use imprint_render::gpu_frame::GpuRenderer;
use imprint_render::{Axis, Colormap, SliceIndex};
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod common;
use common::sphere_torus_scene;

/// A pixel is "near" when its largest channel difference is at most this many levels.
const NEAR: u8 = 8;

/// Bounds of one comparison: the mean absolute difference of each channel (levels) is at most
/// `max_mean`, and at least `min_near` of the pixels are near.
#[derive(Clone, Copy, Debug)]
struct Bounds {
    max_mean: f64,
    min_near: f64,
}

/// Whole scenes, lines included, with 4× MSAA against 2×2 supersampling.
const LINES_MSAA: Bounds = Bounds {
    max_mean: 13.0,
    min_near: 0.72,
};
/// Whole scenes without anti-aliasing on either side.
const LINES_1X: Bounds = Bounds {
    max_mean: 7.0,
    min_near: 0.94,
};
/// Surfaces only (no grid, no wireframe), 4× MSAA against 2×2 supersampling.
const SURFACES_MSAA: Bounds = Bounds {
    max_mean: 1.5,
    min_near: 0.94,
};
/// Surfaces only, without anti-aliasing.
const SURFACES_1X: Bounds = Bounds {
    max_mean: 0.1,
    min_near: 0.995,
};

fn crate_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// How two images differ.
#[derive(Debug)]
struct Diff {
    /// Mean absolute difference per channel, in levels.
    mean: [f64; 3],
    /// Share of pixels whose largest channel difference is ≤ `NEAR`.
    near: f64,
    /// Share of identical pixels.
    equal: f64,
    /// Largest channel difference anywhere.
    max: u8,
}

fn diff(cpu: &RgbImage, gpu: &RgbImage) -> (Diff, RgbImage) {
    assert_eq!(cpu.dimensions(), gpu.dimensions());
    let mut img = RgbImage::new(cpu.width(), cpu.height());
    let mut sum = [0u64; 3];
    let (mut near, mut equal, mut max) = (0usize, 0usize, 0u8);
    for (x, y, c) in cpu.enumerate_pixels() {
        let g = gpu.get_pixel(x, y);
        let d: [u8; 3] = std::array::from_fn(|k| c.0[k].abs_diff(g.0[k]));
        for k in 0..3 {
            sum[k] += d[k] as u64;
        }
        let m = *d.iter().max().unwrap();
        near += (m <= NEAR) as usize;
        equal += (m == 0) as usize;
        max = max.max(m);
        img.put_pixel(x, y, Rgb(d.map(|v| v.saturating_mul(8))));
    }
    let n = (cpu.width() * cpu.height()) as f64;
    let d = Diff {
        mean: sum.map(|s| s as f64 / n),
        near: near as f64 / n,
        equal: equal as f64 / n,
        max,
    };
    (d, img)
}

/// Compares the two renders; on a failure writes both images and the difference and names
/// them. Returns the measured difference.
fn check(name: &str, cpu: &RgbImage, gpu: &RgbImage, bounds: Bounds) -> Diff {
    let Bounds { max_mean, min_near } = bounds;
    let (d, img) = diff(cpu, gpu);
    eprintln!(
        "{name}: mean |difference| per channel {:.3?} levels, {:.2} % of pixels within {NEAR} \
         levels, {:.2} % equal, largest {}",
        d.mean,
        100.0 * d.near,
        100.0 * d.equal,
        d.max
    );
    let write = std::env::var_os("IMPRINT_WRITE_DIFF").is_some();
    let ok = d.mean.iter().all(|m| *m <= max_mean) && d.near >= min_near;
    if !ok || write {
        let out = crate_dir().join("../../target/gpu-frame-diff");
        std::fs::create_dir_all(&out).unwrap();
        let paths = ["cpu", "gpu", "diff"].map(|k| out.join(format!("{name}_{k}.png")));
        cpu.save(&paths[0]).unwrap();
        gpu.save(&paths[1]).unwrap();
        img.save(&paths[2]).unwrap();
        assert!(
            ok,
            "{name}: GPU differs from CPU: {d:?} (bounds: mean <= {max_mean} per channel, \
             >= {min_near} of pixels within {NEAR} levels); wrote {}, {} and {}",
            paths[0].display(),
            paths[1].display(),
            paths[2].display()
        );
    }
    d
}

/// The scene without its ground grid and wireframes.
fn without_lines(scene: &Scene) -> Scene {
    let mut s = scene.clone();
    s.ground_grid = None;
    s.objects = s
        .objects
        .into_iter()
        .map(|o| o.with_wireframe(false))
        .collect();
    s
}

fn golden_options(samples: u32) -> RenderOptions {
    RenderOptions {
        width: 128,
        height: 96,
        samples,
        camera: orbit(Vec3::new(0.0, 0.4, 0.0), 3.6, 25.0, 15.0, 40.0).unwrap(),
    }
}

/// Renders `scene` on both sides and checks the difference; then the same without lines.
fn compare_scene(
    ctx: &imprint_gpu::GpuContext,
    r: &mut GpuRenderer,
    name: &str,
    scene: &Scene,
    opts: &RenderOptions,
) {
    let msaa = opts.samples > 1;
    let s = opts.samples;
    let cpu = render_cpu(scene, opts).unwrap();
    let gpu = r.render(ctx, scene, opts).unwrap();
    check(
        &format!("{name}_s{s}"),
        &cpu,
        &gpu,
        if msaa { LINES_MSAA } else { LINES_1X },
    );
    let surfaces = without_lines(scene);
    let cpu = render_cpu(&surfaces, opts).unwrap();
    let gpu = r.render(ctx, &surfaces, opts).unwrap();
    check(
        &format!("{name}_surfaces_s{s}"),
        &cpu,
        &gpu,
        if msaa { SURFACES_MSAA } else { SURFACES_1X },
    );
}

#[test]
fn golden_scene_matches_the_cpu() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRenderer::new(ctx).unwrap();
    let scene = sphere_torus_scene();
    for samples in [2, 1] {
        compare_scene(
            ctx,
            &mut r,
            "sphere_torus_grid",
            &scene,
            &golden_options(samples),
        );
    }
    // The same frame twice gives the same bytes, also after other sizes and sample counts.
    let opts = golden_options(2);
    let a = r.render(ctx, &scene, &opts).unwrap();
    r.render(ctx, &scene, &RenderOptions { width: 50, ..opts })
        .unwrap();
    assert_eq!(r.render(ctx, &scene, &opts).unwrap(), a);
}

/// A distance field on 6 x 5 x 4 cells of 0.25 units: distance 0.3 a cells (x = a), far cells at
/// a = 5.
fn field() -> Arc<DistanceField> {
    let spec = GridSpec::new(Vec3::new(-0.625, 0.125, -0.375), 0.25, UVec3::new(6, 5, 4)).unwrap();
    let n = spec.len();
    let mut dist = vec![0.0; n];
    let mut nearest = vec![0u32; n];
    for i in 0..n {
        let c = spec.coords(i);
        dist[i] = 0.3 * (c.x + c.y) as f32 * spec.cell;
        if c.x == 5 {
            nearest[i] = DistanceField::FAR;
            dist[i] = 4.0;
        }
    }
    Arc::new(DistanceField {
        spec,
        band: 3.0,
        dist,
        nearest,
        points: Arc::new(vec![Vec3::ZERO]),
        faces: None,
        inside: None,
        cells: Default::default(),
    })
}

/// A field slice standing in the z plane, a cube in front of part of it, a sphere behind it,
/// and a ground grid, in perspective and orthographic views.
#[test]
fn field_slice_scene_matches_the_cpu() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRenderer::new(ctx).unwrap();
    let mut cube = cuboid(Vec3::splat(0.2), 2);
    cube.transform(Mat4::from_translation(Vec3::new(0.3, 0.5, 0.4)));
    let mut ball = uv_sphere(0.35, 24, 12);
    ball.transform(Mat4::from_translation(Vec3::new(-0.3, 0.6, -0.6)));
    let scene = Scene {
        objects: vec![
            Object::mesh(ball, [0.9, 0.6, 0.1]),
            Object::FieldSlice {
                field: field(),
                axis: Axis::Z,
                index: SliceIndex::Middle,
                colormap: Colormap::Viridis,
            },
            Object::mesh(cube, [0.3, 0.8, 0.3]).with_wireframe(true),
        ],
        ground_grid: Some(GroundGrid::default()),
        ..Scene::default()
    };
    let cams = [
        (
            "persp",
            orbit(Vec3::new(0.0, 0.5, 0.0), 2.5, 20.0, -25.0, 45.0).unwrap(),
        ),
        (
            "ortho",
            Camera::orthographic(
                Vec3::new(0.5, 1.5, 3.0),
                Vec3::new(0.0, 0.5, 0.0),
                Vec3::Y,
                0.9,
            )
            .unwrap(),
        ),
    ];
    for (name, camera) in cams {
        for samples in [2, 1] {
            let opts = RenderOptions {
                width: 120,
                height: 90,
                samples,
                camera,
            };
            compare_scene(ctx, &mut r, &format!("field_slice_{name}"), &scene, &opts);
        }
    }
}

#[test]
fn bad_input_gives_the_cpu_errors() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRenderer::new(ctx).unwrap();
    let good = sphere_torus_scene();
    let cam = golden_options(1).camera;
    let opts = |width, height, samples| RenderOptions {
        width,
        height,
        samples,
        camera: cam,
    };
    let mut no_sun = good.clone();
    no_sun.lights.sun_direction = Vec3::ZERO;
    let mut bad_grid = good.clone();
    bad_grid.ground_grid = Some(GroundGrid {
        spacing: 0.0,
        ..GroundGrid::default()
    });
    let cases = [
        (&good, opts(0, 10, 1)),
        (&good, opts(10, 16385, 1)),
        (&good, opts(10, 10, 0)),
        (&good, opts(10, 10, 5)),
        (&good, opts(5000, 10, 4)),
        (&no_sun, opts(10, 10, 1)),
        (&bad_grid, opts(10, 10, 1)),
    ];
    for (scene, o) in cases {
        let cpu = render_cpu(scene, &o).unwrap_err();
        let gpu = r.render(ctx, scene, &o).unwrap_err();
        assert!(matches!(gpu, Error::Invalid(_)), "{gpu}");
        assert_eq!(gpu.to_string(), cpu.to_string());
    }
    // Still usable; an empty scene is the background.
    let img = r.render(ctx, &Scene::default(), &opts(8, 4, 2)).unwrap();
    assert!(img.pixels().all(|p| p.0 == Scene::default().background));
}

/// Prints the time of one 1280×720 frame of the Stanford bunny with samples 2 on the GPU
/// (4× MSAA) and on the CPU (2×2 supersampling), and writes both images.
/// `cargo test --release -p imprint-render --test gpu_frame -- --ignored --nocapture`
#[test]
#[ignore]
fn bunny_1280x720_timing_gpu_vs_cpu() {
    let Some(ctx) = test_context() else { return };
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
    let runs = 5;
    let t = std::time::Instant::now();
    let mut r = GpuRenderer::new(ctx).unwrap();
    let gpu = r.render(ctx, &scene, &opts).unwrap();
    let first = t.elapsed().as_secs_f64() * 1e3;
    let t = std::time::Instant::now();
    for _ in 0..runs {
        std::hint::black_box(r.render(ctx, &scene, &opts).unwrap());
    }
    let gpu_ms = t.elapsed().as_secs_f64() * 1e3 / runs as f64;
    let cpu = render_cpu(&scene, &opts).unwrap();
    let t = std::time::Instant::now();
    for _ in 0..runs {
        std::hint::black_box(render_cpu(&scene, &opts).unwrap());
    }
    let cpu_ms = t.elapsed().as_secs_f64() * 1e3 / runs as f64;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!(
        "bunny ({tris} triangles) 1280x720 samples 2: GPU ({}) {gpu_ms:.1} ms per frame \
         (first frame, with pipeline creation, {first:.1} ms); CPU {cpu_ms:.1} ms per frame \
         ({threads} threads); mean of {runs}",
        ctx.adapter_name()
    );
    let (d, _) = diff(&cpu, &gpu);
    println!("bunny GPU vs CPU: {d:?}");
    let out = crate_dir().join("../../target/gpu-frame-diff");
    std::fs::create_dir_all(&out).unwrap();
    gpu.save(out.join("bunny_1280x720_gpu.png")).unwrap();
    cpu.save(out.join("bunny_1280x720_cpu.png")).unwrap();
}
