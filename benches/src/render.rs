//! Section 5 of BENCHMARKS.md: frames and depth maps.
//!
//! - Frame time at 1280×720 for the Stanford bunny (69,451 triangles) on the CPU renderer at
//!   1–4× supersampling per axis, each with its error: the mean and 99th-percentile absolute
//!   difference (sRGB levels) from the 4× picture, the anti-aliasing it buys.
//! - The same frame through the GPU renderer (MSAA 4×) when an adapter exists, with its
//!   difference from the CPU's 2× picture.
//! - Depth maps at 512² of a 50k-triangle sphere and of the bunny: CPU rasteriser, and the
//!   GPU rasteriser (with read-back) with its depth error against the CPU map. The later
//!   depth-buffer stages need ≤ 5 ms per map on the CPU.

use crate::median_ms;
use image::RgbImage;
use imprint_core::mesh::primitives;
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{Camera, Mesh};
use imprint_render::frame::{GroundGrid, Object, RenderOptions, Scene, orbit, render_cpu};
use std::fmt::Write;
use std::path::Path;

/// Mean and 99th percentile of the largest per-channel difference, in sRGB levels.
fn image_diff(a: &RgbImage, b: &RgbImage) -> (f64, u8) {
    let mut d: Vec<u8> = a
        .pixels()
        .zip(b.pixels())
        .map(|(p, q)| (0..3).map(|k| p.0[k].abs_diff(q.0[k])).max().unwrap_or(0))
        .collect();
    let mean = d.iter().map(|&v| v as f64).sum::<f64>() / d.len().max(1) as f64;
    d.sort_unstable();
    (mean, d[(d.len() * 99 / 100).min(d.len() - 1)])
}

/// Coverage mismatches and the largest depth difference over pixels both maps cover.
fn depth_diff(a: &DepthMap, b: &DepthMap) -> (usize, f32) {
    let mut mismatched = 0;
    let mut worst = 0.0f32;
    for i in 0..a.depth.len() {
        if a.coverage[i] != b.coverage[i] {
            mismatched += 1;
        } else if a.coverage[i] {
            worst = worst.max((a.depth[i] - b.depth[i]).abs());
        }
    }
    (mismatched, worst)
}

fn bunny_scene(root: &Path) -> (Scene, Camera) {
    let mut mesh =
        Mesh::load_obj(&root.join("assets/meshes/stanford-bunny.obj")).expect("bunny mesh");
    let t = mesh.fit_transform(1.0, glam::Vec3::new(0.0, 0.5, 0.0));
    mesh.transform(t);
    let scene = Scene {
        objects: vec![Object::mesh(mesh, [0.8, 0.5, 0.38])],
        ground_grid: Some(GroundGrid::default()),
        ..Default::default()
    };
    let cam = orbit(glam::Vec3::new(0.0, 0.45, 0.0), 2.4, 18.0, 35.0, 40.0).expect("camera");
    (scene, cam)
}

pub fn section(root: &Path, repeat: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "## 5. Frames and depth maps\n");
    let (scene, cam) = bunny_scene(root);
    let opts = |samples| RenderOptions {
        width: 1280,
        height: 720,
        samples,
        camera: cam,
    };
    let gpu = imprint_gpu::GpuContext::shared().ok();
    let adapter = gpu.map_or("none".to_string(), crate::adapter_label);

    // Frames.
    let _ = writeln!(
        s,
        "Bunny (69,451 triangles) plus the ground grid at 1280×720, the main job's camera. \
         CPU: `render_cpu` (supersampling per axis, box filter in linear light). Error: mean / \
         p99 of the largest per-channel difference in sRGB levels (0–255) from the CPU's 4× \
         picture. GPU adapter: {adapter}; GPU times are wall clock from upload to the read-back \
         image, MSAA 4× (the renderer's mode for samples > 1); its error is against the CPU's 2× \
         picture. Median of {} runs.\n",
        repeat.min(7)
    );
    let _ = writeln!(
        s,
        "| renderer | anti-aliasing | ms per frame | diff mean | diff p99 |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|");
    let reference = render_cpu(&scene, &opts(4)).expect("render");
    let mut cpu2 = None;
    for samples in 1..=4 {
        let mut img = render_cpu(&scene, &opts(samples)).expect("render");
        let ms = median_ms(repeat.min(7), || {
            img = render_cpu(&scene, &opts(samples)).expect("render")
        });
        let (mean, p99) = image_diff(&img, &reference);
        let _ = writeln!(
            s,
            "| CPU | {samples}×{samples} supersampling | {ms:.1} | {mean:.2} | {p99} |"
        );
        if samples == 2 {
            cpu2 = Some(img);
        }
    }
    if let Some(ctx) = gpu {
        match imprint_render::gpu_frame::GpuRenderer::new(ctx) {
            Ok(mut r) => {
                for samples in [1, 2] {
                    let mut img = r.render(ctx, &scene, &opts(samples)).expect("gpu render");
                    let ms = median_ms(repeat.min(7), || {
                        img = r.render(ctx, &scene, &opts(samples)).expect("gpu render")
                    });
                    let (mean, p99) =
                        image_diff(&img, cpu2.as_ref().expect("CPU 2x rendered above"));
                    let aa = if samples > 1 { "MSAA 4×" } else { "none" };
                    let _ = writeln!(
                        s,
                        "| GPU | {aa} | {ms:.1} | {mean:.2} (vs CPU 2×) | {p99} |"
                    );
                }
            }
            Err(e) => {
                let _ = writeln!(s, "| GPU | – | failed: {e} | | |");
            }
        }
    }

    // Depth maps.
    let _ = writeln!(
        s,
        "\nDepth maps at 512², orthographic from above (the depth-buffer stages' view) and \
         perspective (the main job's camera). The CPU map is the reference (exact coverage by \
         the top-left rule); the GPU column includes upload and read-back, and its error is \
         the coverage mismatches and the largest depth difference against the CPU map, in \
         world units. Goal for the later stages: ≤ 5 ms per map on the CPU.\n"
    );
    let _ = writeln!(
        s,
        "| mesh | triangles | view | CPU ms | GPU ms | GPU coverage mismatches | GPU max depth diff |"
    );
    let _ = writeln!(s, "|---|---:|---|---:|---:|---:|---:|");
    let mut sphere = primitives::uv_sphere(0.5, 160, 157);
    sphere.transform(glam::Mat4::from_translation(glam::Vec3::new(0.0, 0.5, 0.0)));
    let bunny = match &scene.objects[0] {
        Object::Mesh { mesh, .. } => (**mesh).clone(),
        _ => unreachable!(),
    };
    let above = Camera::orthographic(
        glam::Vec3::new(0.0, 2.0, 0.0),
        glam::Vec3::new(0.0, 0.0, 0.0),
        glam::Vec3::NEG_Z,
        0.6,
    )
    .expect("camera")
    .with_depth_range(0.0, 3.0)
    .expect("camera");
    let mut raster = gpu.and_then(|c| imprint_gpu::raster::GpuRasterizer::new(c).ok());
    let ro = RasterOptions::default();
    for (name, mesh) in [("sphere", &sphere), ("stanford-bunny", &bunny)] {
        for (view, cam) in [("ortho, above", above), ("perspective", cam)] {
            let mut map = rasterize_depth_with(mesh, &cam, 512, 512, &ro).expect("depth");
            let cpu_ms = median_ms(repeat, || {
                map = rasterize_depth_with(mesh, &cam, 512, 512, &ro).expect("depth")
            });
            let (gpu_ms, mism, dd) = match (gpu, raster.as_mut()) {
                (Some(ctx), Some(r)) => {
                    let mut g = r
                        .depth_map(ctx, mesh, &cam, 512, 512, &ro)
                        .expect("gpu depth");
                    let ms = median_ms(repeat.min(7), || {
                        g = r
                            .depth_map(ctx, mesh, &cam, 512, 512, &ro)
                            .expect("gpu depth")
                    });
                    let (m, d) = depth_diff(&g, &map);
                    (format!("{ms:.2}"), m.to_string(), format!("{d:.2e}"))
                }
                _ => ("–".into(), "–".into(), "–".into()),
            };
            let _ = writeln!(
                s,
                "| {name} | {} | {view} | {cpu_ms:.2} | {gpu_ms} | {mism} | {dd} |",
                mesh.triangles.len()
            );
            eprintln!("render: depth {name} {view} done");
        }
    }
    s
}
