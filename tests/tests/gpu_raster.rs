//! The GPU depth rasteriser (`imprint_gpu::raster::GpuRasterizer`) against the CPU reference
//! (`imprint_core::raster::rasterize_depth_with`) and against analytic depth.
//!
//! What must agree, and how closely:
//! - coverage, except on silhouettes: a pixel covered on one side only must lie on the CPU
//!   map's coverage boundary (a 4-neighbour, or the image border, with the other coverage);
//!   such pixels are counted and bounded (a pixel centre within rounding of an edge);
//! - depth where both cover the pixel: within `ORTHO_TOL` (absolute, world units) for
//!   orthographic cameras and `PERSP_REL_TOL` (relative) for perspective ones, except on
//!   occlusion edges (one nearer surface's silhouette over another), where the two sides may
//!   see different surfaces: such pixels must have a CPU 4-neighbour whose depth jump is at
//!   least half the difference, and are counted and bounded too.
//!
//! Measured on Mesa lavapipe (llvmpipe, LLVM 15): coverage identical, pixel for pixel, on every
//! scene here (no silhouette or occlusion-edge pixels at all); depth bit-identical on most
//! pixels (median difference 0), 99th percentile 4e-7 relative (perspective) / 1e-6 world units
//! (orthographic), largest 1.9e-5 relative (a few pixels of the sphere) / 2e-6 world units (the
//! plane, also its error against the analytic depth). The tolerances leave a margin of ~10×
//! (perspective) and 50× (orthographic); the silhouette counts allow for hardware that snaps
//! or projects vertices a little differently.
//!
//! Every test skips, with a note, on a machine without a GPU adapter; `IMPRINT_REQUIRE_GPU=1`
//! makes that a failure. Images stay ≤ 256²: CI runs these on a software rasteriser.

use imprint_core::camera::Camera;
use imprint_core::glam::Vec3;
use imprint_core::mesh::primitives::uv_sphere;
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{Error, Mesh};
use imprint_gpu::raster::GpuRasterizer;
use imprint_gpu::{GpuContext, test_context};

/// Depth tolerance for orthographic cameras, world units (the scenes are ~1 unit deep).
const ORTHO_TOL: f32 = 1e-4;
/// Relative depth tolerance for perspective cameras.
const PERSP_REL_TOL: f32 = 2e-4;

const CULL: RasterOptions = RasterOptions { cull_back: true };
const BOTH: RasterOptions = RasterOptions { cull_back: false };

/// What [`compare`] found.
#[derive(Debug, Default)]
struct Agreement {
    covered_cpu: usize,
    covered_gpu: usize,
    /// Pixels covered on one side only (all on the CPU silhouette, or the test failed).
    silhouette: usize,
    /// Pixels covered on both sides whose depths differ beyond the tolerance (all on occlusion
    /// edges, or the test failed).
    occlusion: usize,
    /// Depth differences (absolute for orthographic, relative for perspective) over the other
    /// pixels covered on both sides: largest, 99th percentile, median.
    max_err: f32,
    p99_err: f32,
    median_err: f32,
}

/// Compares the GPU map with the CPU map (see the module doc); panics on a difference that is
/// not on a silhouette or an occlusion edge.
fn compare(name: &str, cpu: &DepthMap, gpu: &DepthMap) -> Agreement {
    assert_eq!((cpu.width, cpu.height), (gpu.width, gpu.height), "{name}");
    assert_eq!(cpu.camera, gpu.camera, "{name}");
    let (w, h) = (cpu.width as i64, cpu.height as i64);
    let persp = cpu.camera.is_perspective();
    let err = |a: f32, b: f32| {
        if persp {
            (a - b).abs() / a.abs().max(b.abs())
        } else {
            (a - b).abs()
        }
    };
    let tol = if persp { PERSP_REL_TOL } else { ORTHO_TOL };
    let cov = |i: i64, j: i64| {
        (0..w).contains(&i) && (0..h).contains(&j) && cpu.is_covered(i as u32, j as u32)
    };
    let mut errs = Vec::new();
    let mut a = Agreement {
        covered_cpu: cpu.covered_count(),
        covered_gpu: gpu.covered_count(),
        ..Default::default()
    };
    for j in 0..h {
        for i in 0..w {
            let (iu, ju) = (i as u32, j as u32);
            let n4 = [(i - 1, j), (i + 1, j), (i, j - 1), (i, j + 1)];
            let (c, g) = (cpu.get(iu, ju), gpu.get(iu, ju));
            match (c, g) {
                (Some(dc), Some(dg)) => {
                    assert!(dg.is_finite(), "{name}: GPU depth {dg} at ({i}, {j})");
                    let e = err(dc, dg);
                    if e <= tol {
                        errs.push(e);
                        continue;
                    }
                    let jump = n4.iter().any(|&(x, y)| {
                        cov(x, y)
                            && (cpu.get(x as u32, y as u32).unwrap() - dc).abs()
                                >= 0.5 * (dg - dc).abs()
                    });
                    assert!(
                        jump,
                        "{name}: depth at ({i}, {j}) CPU {dc} vs GPU {dg} (error {e:e} > {tol:e}), not on an occlusion edge"
                    );
                    a.occlusion += 1;
                }
                (None, None) => {}
                _ => {
                    let here = c.is_some();
                    let edge = n4.iter().any(|&(x, y)| cov(x, y) != here);
                    assert!(
                        edge,
                        "{name}: coverage at ({i}, {j}) CPU {here} vs GPU {}, not on the CPU silhouette",
                        !here
                    );
                    a.silhouette += 1;
                }
            }
        }
    }
    errs.sort_by(f32::total_cmp);
    let q = |f: f64| {
        errs.get(((errs.len() as f64 - 1.0) * f).round() as usize)
            .copied()
    };
    a.max_err = errs.last().copied().unwrap_or(0.0);
    a.p99_err = q(0.99).unwrap_or(0.0);
    a.median_err = q(0.5).unwrap_or(0.0);
    assert!(
        a.covered_cpu.abs_diff(a.covered_gpu) <= a.silhouette,
        "{name}: {a:?}"
    );
    eprintln!("{name}: {a:?}");
    a
}

fn both(
    ctx: &GpuContext,
    r: &mut GpuRasterizer,
    mesh: &Mesh,
    cam: &Camera,
    w: u32,
    h: u32,
    opts: &RasterOptions,
) -> (DepthMap, DepthMap) {
    let cpu = rasterize_depth_with(mesh, cam, w, h, opts).unwrap();
    let gpu = r.depth_map(ctx, mesh, cam, w, h, opts).unwrap();
    (cpu, gpu)
}

/// An `n` × `n` grid of quads over the parallelogram `origin + s u + t v`, s, t in [0, 1].
fn patch(origin: Vec3, u: Vec3, v: Vec3, n: u32) -> Mesh {
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.push(origin + u * (i as f32 / n as f32) + v * (j as f32 / n as f32));
        }
    }
    let id = |i: u32, j: u32| j * (n + 1) + i;
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    Mesh::new(pos, tris, "patch").unwrap()
}

fn bunny() -> Mesh {
    imprint_tests::mesh("stanford-bunny")
}

fn bunny_cameras(m: &Mesh) -> [Camera; 2] {
    let b = m.bounds();
    let (size, c) = (b.size().max_element(), b.center());
    [
        Camera::perspective(c + Vec3::new(0.5, 0.3, 2.0) * size, c, Vec3::Y, 40.0).unwrap(),
        Camera::orthographic(c + Vec3::new(-1.0, 0.4, 1.5) * size, c, Vec3::Y, 0.6 * size).unwrap(),
    ]
}

#[test]
fn orthographic_tilted_plane_has_the_analytic_depth() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRasterizer::new(ctx).unwrap();
    let cam = Camera::orthographic(
        Vec3::new(0.3, -0.2, 4.0),
        Vec3::new(0.1, 0.0, 0.0),
        Vec3::Y,
        1.3,
    )
    .unwrap();
    // Plane z = -1 + 0.3 x + 0.2 y as a 9 × 9 grid (shared edges everywhere), past the image.
    let f = |x: f32, y: f32| Vec3::new(x, y, -1.0 + 0.3 * x + 0.2 * y);
    let o = f(-6.0, -6.0);
    let m = patch(o, f(6.0, -6.0) - o, f(-6.0, 6.0) - o, 9);
    let (w, h) = (160, 120);
    let (cpu, gpu) = both(ctx, &mut r, &m, &cam, w, h, &BOTH);
    assert_eq!(gpu.covered_count(), (w * h) as usize);
    let a = compare("tilted plane", &cpu, &gpu);
    assert_eq!((a.silhouette, a.occlusion), (0, 0));
    // Against the ray-plane distance through each pixel centre.
    let n = Vec3::new(-0.3, -0.2, 1.0);
    let fwd = cam.frame().forward;
    let mut worst = 0.0f32;
    for j in 0..h {
        for i in 0..w {
            let origin = gpu.unproject(i as f32 + 0.5, j as f32 + 0.5, 0.0);
            let t = (Vec3::new(0.0, 0.0, -1.0) - origin).dot(n) / fwd.dot(n);
            worst = worst.max((gpu.get(i, j).unwrap() - t).abs());
        }
    }
    eprintln!("tilted plane: GPU vs analytic depth, worst {worst:e}");
    assert!(worst <= ORTHO_TOL, "{worst}");
}

#[test]
fn perspective_sphere_matches_the_cpu() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRasterizer::new(ctx).unwrap();
    let m = uv_sphere(1.0, 64, 32);
    let cam = Camera::perspective(Vec3::new(0.3, 0.4, 3.0), Vec3::ZERO, Vec3::Y, 50.0).unwrap();
    let (cpu, gpu) = both(ctx, &mut r, &m, &cam, 256, 192, &BOTH);
    let a = compare("sphere", &cpu, &gpu);
    assert!(a.covered_cpu > 10_000);
    assert!(a.silhouette <= 16, "{a:?}");
    assert_eq!(a.occlusion, 0, "{a:?}");
    // A closed surface: culling back faces changes nothing.
    let culled = r.depth_map(ctx, &m, &cam, 256, 192, &CULL).unwrap();
    assert_eq!(culled.coverage, gpu.coverage);
}

#[test]
fn bunny_matches_the_cpu_in_both_projections() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRasterizer::new(ctx).unwrap();
    let m = bunny();
    for (cam, name) in bunny_cameras(&m)
        .iter()
        .zip(["perspective", "orthographic"])
    {
        for opts in [BOTH, CULL] {
            let (cpu, gpu) = both(ctx, &mut r, &m, cam, 256, 256, &opts);
            let label = format!("bunny {name}, cull_back {}", opts.cull_back);
            let a = compare(&label, &cpu, &gpu);
            assert!(a.covered_cpu > 10_000, "{label}: {a:?}");
            assert!(a.silhouette <= 24, "{label}: {a:?}");
            assert!(a.occlusion <= 8, "{label}: {a:?}");
        }
    }
}

#[test]
fn cull_back_keeps_counter_clockwise_triangles() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRasterizer::new(ctx).unwrap();
    // Orthographic down -z over [0, 8]²: a counter-clockwise (front) triangle at depth 4 behind
    // a clockwise (back) one at depth 3, as in the CPU's test.
    let cam = Camera::orthographic(
        Vec3::new(4.0, 4.0, 5.0),
        Vec3::new(4.0, 4.0, 0.0),
        Vec3::Y,
        4.0,
    )
    .unwrap();
    let p = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
    let m = Mesh::new(
        vec![
            p(0.0, 0.0, 1.0),
            p(8.0, 0.0, 1.0),
            p(0.0, 8.0, 1.0),
            p(0.0, 0.0, 2.0),
            p(0.0, 8.0, 2.0),
            p(8.0, 0.0, 2.0),
        ],
        vec![[0, 1, 2], [3, 4, 5]],
        "two triangles",
    )
    .unwrap();
    let both_sides = r.depth_map(ctx, &m, &cam, 8, 8, &BOTH).unwrap();
    assert_eq!(both_sides.get(1, 6), Some(3.0));
    let culled = r.depth_map(ctx, &m, &cam, 8, 8, &CULL).unwrap();
    assert_eq!(culled.get(1, 6), Some(4.0));
    assert_eq!(culled, rasterize_depth_with(&m, &cam, 8, 8, &CULL).unwrap());
    assert_eq!(
        both_sides,
        rasterize_depth_with(&m, &cam, 8, 8, &BOTH).unwrap()
    );
}

#[test]
fn one_rasteriser_serves_many_sizes_and_meshes() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRasterizer::new(ctx).unwrap();
    let small = uv_sphere(1.0, 8, 4);
    let large = uv_sphere(1.0, 96, 48);
    let cam = Camera::perspective(Vec3::new(0.0, 0.5, 3.0), Vec3::ZERO, Vec3::Y, 45.0).unwrap();
    let mut results = Vec::new();
    for (m, w, h) in [
        (&small, 40, 30),
        (&large, 100, 60),
        (&small, 40, 30),
        (&large, 37, 53),
    ] {
        results.push(r.depth_map(ctx, m, &cam, w, h, &BOTH).unwrap());
    }
    // The same inputs give the same map, whatever came before (grown buffers, new targets).
    assert_eq!(results[0], results[2]);
    let fresh = GpuRasterizer::new(ctx)
        .unwrap()
        .depth_map(ctx, &large, &cam, 37, 53, &BOTH)
        .unwrap();
    assert_eq!(results[3], fresh);
    // An odd width (rows padded to 256 bytes on the GPU) reads back in place.
    compare(
        "odd size",
        &rasterize_depth_with(&large, &cam, 37, 53, &BOTH).unwrap(),
        &results[3],
    );
    // A mesh without triangles is refused as on the CPU, and the rasteriser stays usable.
    let empty = Mesh::default();
    let cpu_err = rasterize_depth_with(&empty, &cam, 16, 16, &BOTH).unwrap_err();
    let gpu_err = r.depth_map(ctx, &empty, &cam, 16, 16, &BOTH).unwrap_err();
    assert_eq!(gpu_err.to_string(), cpu_err.to_string());
    assert_eq!(
        r.depth_map(ctx, &small, &cam, 40, 30, &BOTH).unwrap(),
        results[0]
    );
}

#[test]
fn sizes_beyond_the_device_are_refused_naming_the_limit() {
    let Some(ctx) = test_context() else { return };
    let mut r = GpuRasterizer::new(ctx).unwrap();
    let m = uv_sphere(1.0, 8, 4);
    let cam = Camera::perspective(Vec3::new(0.0, 0.5, 3.0), Vec3::ZERO, Vec3::Y, 45.0).unwrap();
    let max = ctx.limits.max_texture_dimension_2d;
    for (w, h, field) in [
        (max + 1, 4, "width"),
        (4, max + 1, "height"),
        (0, 4, "width"),
    ] {
        match r.depth_map(ctx, &m, &cam, w, h, &BOTH) {
            Err(Error::Invalid(msg)) => {
                assert!(msg.contains(field), "{msg}");
                if w > 0 {
                    assert!(msg.contains(&max.to_string()), "{msg}");
                    assert!(msg.contains("max_texture_dimension_2d"), "{msg}");
                }
            }
            other => panic!("{w}x{h}: {other:?}"),
        }
    }
    // Still usable after the refusals.
    assert!(
        r.depth_map(ctx, &m, &cam, 8, 8, &BOTH)
            .unwrap()
            .covered_count()
            > 0
    );
}
