//! The GPU parts of the snow stage (`imprint_stages::snow::gpu`) against the CPU's. The
//! stabilisation (`imprint_stages::snow::relax`): the same whole quanta in every cell, bit
//! for bit, and the same report (passes, quanta moved, settled) after every call, for a point
//! pour relaxing into a cone and for snowfall (and scattered pours) on bumpy ground with a
//! ridge steeper than the repose angle; the snow is conserved to the quantum; the shader's
//! division is IEEE's. The arrival look-ups: the same counts (to a stated tolerance), and a
//! step with GPU depth maps, look-ups and stabilisation snows as the CPU's step. Every test skips,
//! with a note, without a GPU adapter (`IMPRINT_REQUIRE_GPU=1` makes that a failure). Small
//! grids: CI runs these on a software rasteriser (Mesa lavapipe).

use glam::{UVec2, Vec2};
use imprint_core::HeightField;
use imprint_core::mesh::primitives::uv_sphere;
use imprint_core::raster::rasterize_depth_with;
use imprint_gpu::raster::GpuRasterizer;
use imprint_gpu::{GpuContext, test_context};
use imprint_stages::snow::arrival::{arrival_cpu, gather};
use imprint_stages::snow::gpu::GpuSnowArrival;
use imprint_stages::snow::gpu::GpuSnowRelax;
use imprint_stages::snow::{QUANTUM, RelaxReport, SnowParams, SnowSim};
use std::time::{Duration, Instant};

/// The GPU step's worst depth difference from the CPU's, as a fraction of the snow fallen:
/// a receiver that one of the 8 directions reaches on one path and not on the other, in
/// every step. Measured on Mesa lavapipe: 0 (the same counts, depths and quanta to the bit).
const TOL_DEPTH: f32 = 1.0 / 8.0;

/// Reproducible numbers in [0, 1): a 64-bit LCG's top 24 bits.
struct Lcg(u64);

impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `n` × `n` cells of 2 cm: rough bumps (up to 4 cm) and a ridge 30 cm high whose flanks are
/// far steeper than the repose angle.
fn bumpy_ground(n: u32) -> HeightField {
    let cell = 0.02;
    let mut rng = Lcg(n as u64);
    let bumps: Vec<f32> = (0..n * n).map(|_| 0.04 * rng.next()).collect();
    HeightField::from_fn(Vec2::splat(-0.5), cell, UVec2::splat(n), |i, k| {
        let (x, z) = (i as f32 * cell, k as f32 * cell);
        let ridge = 0.3 * (-(x - 0.1 * z - 0.4).powi(2) / 0.002).exp();
        bumps[(k * n + i) as usize] + ridge
    })
    .unwrap()
}

/// Heavy snowfall (5 cm/s) from 8 directions jittered by 15°.
fn snowfall(resolution: u32, relax_passes: u32) -> SnowParams {
    SnowParams {
        directions: 8,
        jitter_degrees: 15.0,
        resolution,
        rate: 0.05,
        relax_passes,
        ..Default::default()
    }
}

/// Run times of the two paths, summed.
#[derive(Default)]
struct Times {
    cpu: Duration,
    gpu: Duration,
}

/// `passes` passes on both simulators (the CPU's, then the GPU's): the same report and the
/// same snow, to the bit.
fn relax_both(
    cpu: &mut SnowSim,
    gpu: &mut SnowSim,
    (ctx, relaxer): (&GpuContext, &mut GpuSnowRelax),
    passes: u32,
    times: &mut Times,
    what: &str,
) -> RelaxReport {
    let t = Instant::now();
    let rc = cpu.relax(passes);
    times.cpu += t.elapsed();
    let t = Instant::now();
    let rg = gpu.relax_with(passes, relaxer.relaxer(ctx)).unwrap();
    times.gpu += t.elapsed();
    assert_eq!(rg, rc, "{what}");
    assert_same_snow(cpu, gpu, what);
    rg
}

/// The two simulators' ground snow must be the same to the bit.
fn assert_same_snow(cpu: &SnowSim, gpu: &SnowSim, what: &str) {
    let (c, g) = (cpu.ground().unwrap(), gpu.ground().unwrap());
    if c.units != g.units {
        let differ = c.units.iter().zip(&g.units).filter(|(a, b)| a != b).count();
        let first = c.units.iter().zip(&g.units).position(|(a, b)| a != b);
        panic!("{what}: {differ} cells differ, the first at {first:?}");
    }
    assert!(
        c.residual
            .iter()
            .zip(&g.residual)
            .all(|(a, b)| a.to_bits() == b.to_bits()),
        "{what}: residuals differ"
    );
}

/// V poured onto one cell of flat ground in portions, stabilised in between (100 passes, not a
/// multiple of the GPU's batch) and to rest at the end: the GPU's quanta are the CPU's after
/// every call, the reports are equal, every quantum poured is still there, and the pile's top
/// is the cone's (3V tan²θ / π)^(1/3) within 5%.
#[test]
fn a_point_pour_relaxes_into_the_same_cone() {
    let Some(ctx) = test_context() else { return };
    let (n, cell, theta) = (65u32, 0.01f32, 35.0f32);
    let ground = HeightField::constant(Vec2::ZERO, cell, UVec2::splat(n), 0.0).unwrap();
    let p = SnowParams {
        repose_degrees: theta,
        ..Default::default()
    };
    let tan = theta.to_radians().tan();
    // A cone of base radius 20 cells.
    let h = 20.0 * cell * tan;
    let volume = std::f64::consts::PI * (h as f64).powi(3) / (3.0 * tan as f64 * tan as f64);
    let mut cpu = SnowSim::new(&p).unwrap();
    cpu.set_ground(&ground).unwrap();
    let mut gpu = cpu.clone();
    let mut relaxer = GpuSnowRelax::new();
    let mut times = Times::default();
    let (mut poured, mut passes) = (0u64, 0);
    for portion in 0..10 {
        let q = cpu.pour(UVec2::splat(n / 2), volume / 10.0).unwrap();
        assert_eq!(gpu.pour(UVec2::splat(n / 2), volume / 10.0).unwrap(), q);
        poured += q as u64;
        let what = format!("portion {portion}");
        let r = relax_both(
            &mut cpu,
            &mut gpu,
            (ctx, &mut relaxer),
            100,
            &mut times,
            &what,
        );
        passes += r.passes;
    }
    let gpus = (ctx, &mut relaxer);
    let rest = relax_both(&mut cpu, &mut gpu, gpus, 100_000, &mut times, "to rest");
    assert!(rest.settled, "{rest:?}");
    passes += rest.passes;
    let g = gpu.ground().unwrap();
    assert_eq!(g.total_units(), poured);
    let v = poured as f64 * QUANTUM as f64 * (cell * cell) as f64;
    let want = (3.0 * v * (tan * tan) as f64 / std::f64::consts::PI).cbrt() as f32;
    let top = g.thickness().into_iter().fold(0.0, f32::max);
    passes += rest.passes;
    eprintln!(
        "cone on {n}²: top {top:.4} m vs {want:.4} m ({:+.2}%); {passes} passes: CPU {:?}, \
         GPU {:?} on {} (software: {})",
        100.0 * (top / want - 1.0),
        times.cpu,
        times.gpu,
        ctx.adapter_name(),
        ctx.is_software()
    );
    assert!((top / want - 1.0).abs() < 0.05, "top {top} vs {want}");
}

/// Scattered pours on bumpy ground relaxed in calls of 25 passes, then snowfall from 8
/// jittered directions with the stabilisation of each step on the GPU
/// (`SnowSim::step_with_parts`, the arrival on the CPU): the same quanta, remainders and reports as the CPU's
/// `SnowSim::step`, and no quantum lost.
#[test]
fn snowfall_on_bumpy_ground_relaxes_the_same() {
    let Some(ctx) = test_context() else { return };
    let n = 48;
    let ground = bumpy_ground(n);
    let mut relaxer = GpuSnowRelax::new();

    let mut times = Times::default();
    let mut cpu = SnowSim::new(&SnowParams::default()).unwrap();
    cpu.set_ground(&ground).unwrap();
    let mut rng = Lcg(7);
    for _ in 0..300 {
        let cell = UVec2::new(
            (rng.next() * n as f32) as u32,
            (rng.next() * n as f32) as u32,
        );
        cpu.pour(cell, 2e-6 * rng.next() as f64).unwrap();
    }
    let mut gpu = cpu.clone();
    let before = cpu.ground().unwrap().total_units();
    let mut moved = 0;
    for call in 0..8 {
        let what = format!("pours, call {call}");
        let r = relax_both(
            &mut cpu,
            &mut gpu,
            (ctx, &mut relaxer),
            25,
            &mut times,
            &what,
        );
        assert_eq!(gpu.ground().unwrap().total_units(), before);
        moved += r.moved;
    }
    assert!(moved > before / 2, "moved {moved} of {before}");

    let p = snowfall(SnowParams::default().resolution, 40);
    let mut cpu = SnowSim::new(&p).unwrap();
    let mut gpu = cpu.clone();
    let mut moved = 0;
    for step in 0..5 {
        let sc = cpu.step(&[], Some(&ground), 0.2).unwrap();
        let sg = gpu
            .step_with_parts(&[], Some(&ground), 0.2, arrival_cpu, relaxer.relaxer(ctx))
            .unwrap();
        assert_eq!(sg, sc, "step {step}");
        assert_same_snow(&cpu, &gpu, &format!("step {step}"));
        moved += sg.relax.moved;
        // More passes after the step's: they conserve the fresh snow to the quantum.
        let before = gpu.ground().unwrap().total_units();
        let what = format!("step {step}, 30 more passes");
        relax_both(
            &mut cpu,
            &mut gpu,
            (ctx, &mut relaxer),
            30,
            &mut times,
            &what,
        );
        assert_eq!(gpu.ground().unwrap().total_units(), before);
    }
    assert!(moved > 0, "the ridge shed nothing");
}

/// The shader's integer division (`div_rn` in `shaders/snow/relax.wgsl`, which the shares
/// depend on) against the CPU's f32 division, bit for bit: quotients a / b with a <= b over
/// many magnitudes, exact quotients, and ties of the rounding.
#[test]
fn the_shaders_division_is_ieee_division() {
    let Some(ctx) = test_context() else { return };
    let mut pairs: Vec<[f32; 2]> = Vec::new();
    let mut rng = Lcg(9);
    for _ in 0..20_000 {
        let b = (rng.next() + 0.001) * 10f32.powi((rng.next() * 12.0) as i32 - 4);
        let a = b * (rng.next() + 1e-3).min(1.0);
        pairs.push([a, b]);
    }
    for (a, b) in [(1.0, 1.0), (1.0, 3.0), (2.0, 3.0), (5.0, 7.0), (0.5, 1.0)] {
        pairs.push([a, b]);
    }
    // Ties of the rounding cannot occur for quotients of 24-bit significands except when exact;
    // near-ties: b one ulp either side of a power of two.
    for e in -3..10 {
        let p = 2f32.powi(e);
        for b in [
            f32::from_bits(p.to_bits() - 1),
            p,
            f32::from_bits(p.to_bits() + 1),
        ] {
            for a in [1.0f32, 1.5, 0.75, 1.0 + f32::EPSILON] {
                let a = a * p * 0.5;
                if a <= b {
                    pairs.push([a, b]);
                }
            }
        }
    }
    let src = "
@group(0) @binding(6) var<storage, read> div_in: array<vec2<f32>>;
@group(0) @binding(7) var<storage, read_write> div_out: array<f32>;
@compute @workgroup_size(64)
fn check_div(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i < arrayLength(&div_out) {
        div_out[i] = div_rn(div_in[i].x, div_in[i].y);
    }
}";
    let pipeline = ctx
        .pipeline(
            "div_rn check",
            &[
                include_str!("../../shaders/common/dispatch.wgsl"),
                include_str!("../../shaders/snow/relax.wgsl"),
                src,
            ],
            "check_div",
        )
        .unwrap();
    let input = ctx.storage_buffer("div in", &pairs).unwrap();
    let output = ctx
        .zeroed_buffer("div out", pairs.len() as u64 * 4)
        .unwrap();
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    imprint_gpu::record_pass(
        ctx,
        &mut encoder,
        "div_rn check",
        &pipeline,
        &[(6, &input), (7, &output)],
        imprint_gpu::Dispatch::Threads(pairs.len() as u32),
        None,
    );
    imprint_gpu::submit(ctx, encoder, None);
    let got: Vec<f32> = ctx.read_buffer(&output).unwrap();
    let wrong: Vec<_> = pairs
        .iter()
        .zip(&got)
        .filter(|([a, b], q)| (a / b).to_bits() != q.to_bits())
        .take(5)
        .collect();
    assert!(wrong.is_empty(), "{} pairs, wrong: {wrong:?}", pairs.len());
}

/// The scene of the arrival tests: a ball above the bumpy ground.
fn ball_over_ground() -> (imprint_core::Mesh, HeightField) {
    let mut ball = uv_sphere(0.15, 24, 12);
    ball.transform(glam::Mat4::from_translation(glam::Vec3::new(
        -0.1, 0.45, -0.1,
    )));
    (ball, bumpy_ground(48))
}

/// Receivers whose counts differ, and by how much at most.
fn count_differences(a: &[u32], b: &[u32]) -> (usize, u32) {
    let differ = a.iter().zip(b).filter(|(x, y)| x != y).count();
    let most = a.iter().zip(b).map(|(x, y)| x.abs_diff(*y)).max();
    (differ, most.unwrap_or(0))
}

/// The look-ups on the GPU from the CPU's depth maps against the CPU's, receiver by receiver
/// (a ball's vertices and the cells of the bumpy ground under it, 16 jittered directions):
/// the counts are whole numbers from f32 projections that a shader compiler may fuse, so a
/// receiver at a threshold may flip by one direction; measured on Mesa lavapipe: none of the
/// 2570 receivers. Allowed: 1% of the receivers, by at most one direction each.
#[test]
fn gpu_look_ups_count_as_the_cpu() {
    let Some(ctx) = test_context() else { return };
    let (ball, ground) = ball_over_ground();
    let p = SnowParams {
        directions: 16,
        jitter_degrees: 20.0,
        resolution: 128,
        ..Default::default()
    };
    let sim = SnowSim::new(&p).unwrap();
    let (occluder, receivers) = gather(&[&ball], Some(&ground));
    let t = Instant::now();
    let cpu = arrival_cpu(&occluder, &receivers, sim.directions(), &p).unwrap();
    let t_cpu = t.elapsed();
    let t = Instant::now();
    let gpu = GpuSnowArrival::new()
        .arrival_with(
            ctx,
            &occluder,
            &receivers,
            sim.directions(),
            &p,
            rasterize_depth_with,
        )
        .unwrap();
    let t_gpu = t.elapsed();
    assert_eq!(gpu.directions, cpu.directions);
    let (differ, most) = count_differences(&cpu.counts, &gpu.counts);
    let reached = cpu.counts.iter().filter(|&&c| c > 0).count();
    eprintln!(
        "arrival: {} receivers ({reached} reached), {differ} counts differ (at most by {most}); \
         CPU maps + CPU look-ups {t_cpu:?}, CPU maps + GPU look-ups {t_gpu:?}",
        cpu.counts.len()
    );
    assert!(reached > cpu.counts.len() / 2 && reached < cpu.counts.len());
    assert!(
        differ * 100 <= cpu.counts.len() && most <= 1,
        "{differ} differ, by {most}"
    );
}

/// Snowfall on the ball and the bumpy ground, every part on the GPU but the deposit (GPU depth
/// maps, GPU look-ups, GPU stabilisation) against the CPU's `SnowSim::step`: the depths agree
/// to within [`TOL_DEPTH`] of the snow fallen (the two rasterisers may differ at triangle
/// edges, and the look-ups' f32 may be fused, which can flip a receiver's count by one of the
/// 8 directions: rate · dt / 8 per step), and the volumes to 1%. Measured on Mesa lavapipe:
/// no difference at all (printed).
#[test]
fn a_gpu_step_snows_as_the_cpu() {
    let Some(ctx) = test_context() else { return };
    let (ball, ground) = ball_over_ground();
    let p = snowfall(96, 16);
    let mut cpu = SnowSim::new(&p).unwrap();
    let mut gpu = cpu.clone();
    let mut raster = GpuRasterizer::new(ctx).unwrap();
    let mut look_ups = GpuSnowArrival::new();
    let mut relaxer = GpuSnowRelax::new();
    let (steps, dt) = (4, 0.25);
    for _ in 0..steps {
        cpu.step(&[&ball], Some(&ground), dt).unwrap();
        gpu.step_with_parts(
            &[&ball],
            Some(&ground),
            dt,
            |occluder, receivers, directions, params| {
                look_ups.arrival_with(
                    ctx,
                    occluder,
                    receivers,
                    directions,
                    params,
                    |m, c, w, h, o| raster.depth_map(ctx, m, c, w, h, o),
                )
            },
            relaxer.relaxer(ctx),
        )
        .unwrap();
    }
    let worst = |a: &[f32], b: &[f32]| {
        a.iter()
            .zip(b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max)
    };
    let mesh = worst(cpu.mesh_depth(0), gpu.mesh_depth(0));
    let (tc, tg) = (
        cpu.ground().unwrap().thickness(),
        gpu.ground().unwrap().thickness(),
    );
    let ground_worst = worst(&tc, &tg);
    let differ = tc.iter().zip(&tg).filter(|(a, b)| a != b).count();
    let fallen = p.rate * steps as f32 * dt;
    let (vc, vg) = (
        cpu.ground().unwrap().volume(),
        gpu.ground().unwrap().volume(),
    );
    eprintln!(
        "GPU step vs CPU after {steps} steps ({fallen} m fallen): ball depth worst {mesh:.2e} m, \
         ground thickness worst {ground_worst:.2e} m ({differ} of {} cells differ), volume \
         {vc:.6e} vs {vg:.6e} m³",
        tc.len()
    );
    assert!(mesh <= TOL_DEPTH * fallen, "ball: {mesh}");
    assert!(ground_worst <= TOL_DEPTH * fallen, "ground: {ground_worst}");
    assert!((vc - vg).abs() <= 0.01 * vc, "volume {vc} vs {vg}");
}
