//! The GPU ground against the CPU reference: the same `i32` heights bit for bit and the same
//! frame metrics, frame after frame, for a sphere rolling through sand (the preset, and a
//! custom material with α = 0.6 so the carry rounding and a second threshold are exercised),
//! with the CPU and with the GPU rasteriser for the contact view, and for a box pressed
//! deeper and deeper into snow. `Full` relaxation is refused. Every test skips, with a note,
//! without a GPU adapter (`IMPRINT_REQUIRE_GPU=1` makes that a failure). Small fields: CI
//! runs these on a software rasteriser (Mesa lavapipe).

use glam::Vec3;
use imprint_core::Error;
use imprint_gpu::raster::GpuRasterizer;
use imprint_gpu::test_context;
use imprint_stages::ground::gpu::GpuGround;
use imprint_stages::ground::{GroundParams, GroundSim, Material, Preset, Relaxation};
use imprint_tests::ground::{cuboid_at, params, sim, sphere};
use std::time::Instant;

const H0: f32 = 0.1;

/// Steps `cpu` and `gpu` through `scene(f)` for `frames` frames and asserts equal heights and
/// metrics after each; returns the wall milliseconds per frame (CPU, GPU) and the slump
/// passes of each frame.
fn compare(
    ctx: &imprint_gpu::GpuContext,
    p: &GroundParams,
    frames: u32,
    scene: impl Fn(u32) -> imprint_core::Mesh,
    gpu_raster: bool,
) -> (f64, f64, Vec<u32>) {
    let mut cpu = sim(p);
    let mut gpu = GpuGround::from_sim(ctx, &cpu).unwrap();
    let mut raster = GpuRasterizer::new(ctx).unwrap();
    let (mut t_cpu, mut t_gpu) = (0.0, 0.0);
    let mut slumped = 0;
    let mut passes = Vec::new();
    for f in 0..frames {
        let mesh = scene(f);
        let t = Instant::now();
        let mc = if gpu_raster {
            cpu.step_with(&[&mesh], |m, c, w, h, o| {
                raster.depth_map(ctx, m, c, w, h, o)
            })
        } else {
            cpu.step(&[&mesh])
        }
        .unwrap();
        t_cpu += t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let mg = if gpu_raster {
            gpu.step_with(ctx, &[&mesh], |m, c, w, h, o| {
                raster.depth_map(ctx, m, c, w, h, o)
            })
        } else {
            gpu.step(ctx, &[&mesh])
        }
        .unwrap();
        t_gpu += t.elapsed().as_secs_f64() * 1e3;
        assert_eq!(mg, mc, "frame {f}: metrics");
        if let Some(j) = (0..cpu.heights_units().len())
            .find(|&j| cpu.heights_units()[j] != gpu.heights_units()[j])
        {
            panic!(
                "frame {f}: cell {j}: CPU {} GPU {}",
                cpu.heights_units()[j],
                gpu.heights_units()[j]
            );
        }
        assert!(mc.contact_cells > 0, "frame {f}: {mc:?}");
        slumped += mc.slumped_units;
        passes.push(mc.slump_iterations);
    }
    assert_eq!(gpu.frame(), cpu.frame());
    assert_eq!(gpu.mass(), cpu.mass());
    let back = gpu.to_sim(p).unwrap();
    assert_eq!(back.heights_units(), cpu.heights_units());
    println!("  slump moved {slumped} units over {frames} frames; passes per frame {passes:?}");
    (t_cpu / frames as f64, t_gpu / frames as f64, passes)
}

/// A sphere of radius 8 cm sunk 2.5 cm, rolling 1.5 cm a frame across a 64 x 64 field of
/// 1 cm cells (the second half of the roll runs back over the track's start).
fn rolling(f: u32) -> imprint_core::Mesh {
    let x = if f < 10 {
        -0.15 + 0.015 * f as f32
    } else {
        -0.15 + 0.015 * (19 - f) as f32 + 0.004
    };
    sphere(0.08, Vec3::new(x, H0 + 0.08 - 0.025, 0.01 * (f % 3) as f32))
}

#[test]
fn rolling_sphere_in_sand_matches_the_cpu_bit_for_bit() {
    let Some(ctx) = test_context() else { return };
    let custom = Material::Custom {
        repose_degrees: 40.0,
        slump_iterations: 8,
        displace_ratio: 0.6,
    };
    // Enough passes that the slump comes to rest before the last: the early stop.
    let settles = Material::Custom {
        repose_degrees: 35.0,
        slump_iterations: 200,
        displace_ratio: 1.0,
    };
    for (name, material, frames) in [
        ("sand", Material::Preset(Preset::Sand), 16),
        ("custom alpha 0.6", custom, 8),
        ("custom 200 passes", settles, 3),
    ] {
        let p = params(64, 0.01, H0, material);
        let (c, g, passes) = compare(ctx, &p, frames, rolling, false);
        if name == "custom 200 passes" {
            assert!(passes.iter().any(|&n| n > 0 && n < 200), "{passes:?}");
        }
        println!(
            "{name}: {frames} frames equal; ms per frame, CPU {c:.1}, GPU path {g:.1} \
             (wall time on {}, a software rasteriser when lavapipe)",
            ctx.adapter_name()
        );
    }
}

#[test]
fn gpu_rasterised_contact_gives_the_same_ground() {
    let Some(ctx) = test_context() else { return };
    let p = params(48, 0.01, H0, Material::Preset(Preset::Sand));
    let scene = |f: u32| sphere(0.06, Vec3::new(-0.1 + 0.02 * f as f32, H0 + 0.04, 0.0));
    compare(ctx, &p, 6, scene, true);
}

/// A 10 x 6 cm box pressed 5 mm deeper every frame into 96 x 96 cells of snow (no slump, no
/// displacement: the walls stay), shifted by a cell every other frame.
#[test]
fn box_pressed_into_snow_matches_the_cpu_bit_for_bit() {
    let Some(ctx) = test_context() else { return };
    let p = params(96, 0.005, H0, Material::Preset(Preset::Snow));
    let scene = |f: u32| {
        let half = Vec3::new(0.05, 0.05, 0.03);
        let y = H0 + 0.05 - 0.005 * (f + 1) as f32;
        cuboid_at(half, Vec3::new(0.0025 + 0.005 * (f / 2) as f32, y, 0.0025))
    };
    let (c, g, _) = compare(ctx, &p, 6, scene, false);
    println!(
        "snow box: 6 frames equal; ms per frame, CPU {c:.1}, GPU path {g:.1} (wall time on {})",
        ctx.adapter_name()
    );
}

#[test]
fn full_relaxation_is_refused_on_the_gpu() {
    let Some(ctx) = test_context() else { return };
    let mut p = params(16, 0.01, H0, Material::Preset(Preset::Sand));
    p.relaxation = Relaxation::Full;
    let cpu = GroundSim::new(&p, std::path::Path::new(".")).unwrap();
    let e = GpuGround::from_sim(ctx, &cpu).unwrap_err();
    assert!(
        matches!(&e, Error::Invalid(m) if m.contains("Full") && m.contains("GPU")),
        "{e}"
    );
}
