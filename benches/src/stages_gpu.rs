//! Section 12 of BENCHMARKS.md: every stage with a GPU path, per frame on the GPU and on the
//! CPU, on the same scene in the same run, with how far the two paths' outputs end apart.
//!
//! - Cloth: the sphere drop of `tests/tests/gpu_cloth.rs` (`imprint_tests::cloth`) at 32² and
//!   128² particles (and 256² on a GPU), `GpuCloth::step_frame` against `ClothSim::step_frame`.
//! - Ground: §8's rolling sphere on 256² cells, `GpuGround::step_resident` (the Ground
//!   node's GPU path) against `GroundSim::step`, with Settle (the default) and Labelled.
//! - Snow: §8's snow scene, `SnowSim::step_with_parts` with the GPU arrival and
//!   stabilisation (the Snow node's GPU path) against `SnowSim::step`.
//! - Skinning: §11's limb and rig, `GpuBlend` (LBS, DQS) and `GpuParticleSkin` against
//!   `blend::lbs` / `blend::dqs` and `ParticleSkin`.
//! - H's scene through the executor, on a GPU only: §7's every-frame run on each backend.
//!
//! Both paths are stepped in turn, frame by frame, so they see the same frames; a frame's
//! GPU time is the wall clock around the stage's call, which submits and waits for the GPU.

use crate::{adapter_label, median, median_ms};
use glam::{Mat4, UVec2, Vec2, Vec3};
use imprint_core::mesh::primitives::{cylinder, uv_sphere};
use imprint_core::{HeightField, Mesh, Result};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::cloth::gpu::{GpuCloth, GpuCollider};
use imprint_stages::ground::gpu::GpuGround;
use imprint_stages::ground::{GroundSim, Material, Preset, Relaxation};
use imprint_stages::skin::blend;
use imprint_stages::skin::fill::FillParams;
use imprint_stages::skin::gpu::{BlendMethod, GpuBlend};
use imprint_stages::skin::gpu_particles::GpuParticleSkin;
use imprint_stages::skin::particles::{ParticleParams, ParticleSkin};
use imprint_stages::skin::rig::Rig;
use imprint_stages::skin::weights::{self, Weights};
use imprint_stages::snow::gpu::{GpuSnowArrival, GpuSnowRelax};
use imprint_stages::snow::{SnowParams, SnowSim};
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

/// The cloth drop starts 0.15 m above the sphere and first touches it near frame 15
/// (`tests/tests/gpu_cloth.rs`): the frames before are warm-up, so the timed frames have
/// contact (free fall alone would flatter both paths).
const CLOTH_WARMUP: u32 = 16;
const CLOTH_FPS: f32 = 60.0;
/// Skinning frames per second (§11's).
const SKIN_FPS: f32 = 24.0;

/// One table row: what ran, its median ms per frame on each path, what the GPU time covers,
/// and the largest difference of the outputs after the timed frames.
struct Row {
    stage: &'static str,
    scene: String,
    cpu_ms: f64,
    gpu_ms: f64,
    covers: String,
    error: String,
}

/// Wall ms of one call, or its error.
fn timed(f: impl FnOnce() -> Result<()>) -> Result<f64> {
    let t = Instant::now();
    f()?;
    Ok(t.elapsed().as_secs_f64() * 1e3)
}

/// Steps both paths through `warmup + repeat` frames, the CPU's then the GPU's for each
/// frame (so that both see the same frames and neither runs beside the other), and returns
/// the median ms per timed frame (CPU, GPU). `warmup` is at least 1: the first frame builds
/// pipelines and caches.
fn lockstep(
    warmup: u32,
    repeat: usize,
    mut cpu: impl FnMut(u32) -> Result<()>,
    mut gpu: impl FnMut(u32) -> Result<()>,
) -> Result<(f64, f64)> {
    let warmup = warmup.max(1);
    let (mut tc, mut tg) = (Vec::new(), Vec::new());
    for f in 0..warmup + repeat.max(1) as u32 {
        let c = timed(|| cpu(f))?;
        let g = timed(|| gpu(f))?;
        if f >= warmup {
            tc.push(c);
            tg.push(g);
        }
    }
    Ok((median(tc), median(tg)))
}

/// Largest distance between corresponding points.
fn max_distance(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

/// Largest absolute difference between corresponding values.
fn max_abs(a: &[f32], b: &[f32]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f32::max)
}

/// The section's markdown: one line and no table where no adapter exists (a CPU-only
/// machine has nothing to compare), else the table; a stage that fails gets a row saying so.
pub fn section(root: &Path, repeat: usize) -> String {
    let mut s = String::from("## 12. GPU stages per frame\n\n");
    let ctx = match GpuContext::shared() {
        Ok(c) => c,
        Err(e) => {
            let _ = writeln!(
                s,
                "No GPU adapter on this machine ({e}); no GPU stage figures."
            );
            return s;
        }
    };
    intro(&mut s, ctx, repeat);
    let _ = writeln!(
        s,
        "| stage | scene | CPU ms | GPU ms | CPU / GPU | the GPU time covers | max abs(GPU − CPU) after the run |"
    );
    let _ = writeln!(s, "|---|---|---:|---:|---:|---|---|");
    let mut rows: Vec<(&str, Result<Row>)> = Vec::new();
    // 256² on a GPU only (issue 5/7's figure): a software adapter takes seconds a frame.
    let cloths: &[u32] = if ctx.is_software() {
        &[32, 128]
    } else {
        &[32, 128, 256]
    };
    for &n in cloths {
        rows.push(("cloth", cloth_row(ctx, n, repeat)));
    }
    for relaxation in [Relaxation::Settle, Relaxation::Labelled] {
        rows.push(("ground", ground_row(ctx, relaxation, repeat)));
    }
    rows.push(("snow", snow_row(ctx, repeat)));
    if !ctx.is_software() {
        // 72 frames of 128³ builds: minutes on a software adapter.
        rows.push(("H's scene", harada_row(root)));
    }
    rows.extend(skin_rows(root, ctx, repeat));
    for (stage, row) in rows {
        let line = match row {
            Ok(r) => format!(
                "| {} | {} | {:.2} | {:.2} | {:.2}× | {} | {} |",
                r.stage,
                r.scene,
                r.cpu_ms,
                r.gpu_ms,
                r.cpu_ms / r.gpu_ms,
                r.covers,
                r.error
            ),
            Err(e) => format!("| {stage} | failed: {e} | | | | | |"),
        };
        eprintln!("stages_gpu: {line}");
        let _ = writeln!(s, "{line}");
    }
    s
}

/// H's scene through the executor (§7's every-frame run: the bunny's 128³ field rebuilt every
/// frame, §6.2's benchmark cloth), on the GPU backend and on the CPU: mean ms per frame over
/// frames 1… of one run each (not a median: the frames differ), the render switched off.
fn harada_row(root: &Path) -> Result<Row> {
    use imprint_graph::schema::Backend;
    let fail = |e: String| imprint_core::Error::Invalid(format!("H's scene: {e}"));
    let (cpu_ms, cpu) = crate::schedule::every_frame_on(root, Backend::Cpu).map_err(fail)?;
    let (gpu_ms, gpu) = crate::schedule::every_frame_on(root, Backend::Gpu).map_err(fail)?;
    Ok(Row {
        stage: "H's scene",
        scene: "`pipelines/harada_cloth.ron`, 72 frames, field every frame, 16 substeps, \
                springs halved (§7's every-frame run), render off"
            .into(),
        cpu_ms,
        gpu_ms,
        covers: "the executor's frame: mesh motion, voxelise, field, cloth, the GPU's \
                 read-backs for the cloth's mesh each frame"
            .into(),
        error: format!(
            "{:.1e} m (particle positions after the last frame; the cloth's chaos carries \
             rounding far, §7)",
            max_distance(&gpu, &cpu)
        ),
    })
}

/// The section's reading: the adapter, how frames are timed, what the error is.
fn intro(s: &mut String, ctx: &GpuContext, repeat: usize) {
    let _ = writeln!(
        s,
        "Adapter: {}. Each stage's GPU path and its CPU path run the same scene in the same \
         run, stepped in turn frame by frame (so both see the same frames). **CPU ms**, **GPU \
         ms**: median wall time per frame over {repeat} frames after a warm-up (one frame, or \
         as stated), the GPU's from the stage's call to its completion (every call below \
         submits and waits; what it reads back is stated, and is what the stage's own use \
         reads back); **CPU / GPU** > 1: the GPU path is faster. **max abs(GPU − CPU)**: the \
         largest difference of the two paths' outputs after the last timed frame, in the \
         output's units. The CPU paths use every core (rayon).\n",
        adapter_label(ctx)
    );
}

/// The sphere drop of `tests/tests/gpu_cloth.rs` with an `n` × `n` cloth: 1 m square,
/// 0.15 m above a sphere of radius 0.3 read from its exact field (2 cm cells, band 4),
/// Harada springs 60 / 15 N/m, 16 substeps, damping 0.995, ε = 1 cm, friction 0.5.
fn cloth_row(ctx: &GpuContext, n: u32, repeat: usize) -> Result<Row> {
    use imprint_tests::cloth::{grid, harada, sim, sphere_drop_field};
    let mut p = imprint_stages::cloth::ClothParams::new(
        grid([1.0, 1.0], [n, n], Vec3::new(0.0, 0.45, 0.0), Vec3::Y),
        harada(60.0, 15.0),
    );
    p.substeps = 16;
    p.damping = 0.995;
    p.collision.epsilon = 0.01;
    p.collision.friction = 0.5;
    let field = sphere_drop_field();
    let collider = GpuCollider::from_field(ctx, &field)?;
    let mut cpu = sim(&p);
    let mut gpu = GpuCloth::new(ctx, &cpu)?;
    let dt = 1.0 / CLOTH_FPS;
    let (cpu_ms, gpu_ms) = lockstep(
        CLOTH_WARMUP,
        repeat,
        |f| cpu.step_frame(&[&field], &[&field], f, dt).map(|_| ()),
        |f| {
            gpu.step_frame(ctx, &[&collider], &[&collider], f, dt)
                .map(|_| ())
        },
    )?;
    let x = gpu.read_positions(ctx)?;
    let read_ms = median_ms(repeat, || {
        std::hint::black_box(gpu.read_positions(ctx).expect("cloth read-back"));
    });
    Ok(Row {
        stage: "cloth",
        scene: format!(
            "sphere drop, {n}² particles, 16 substeps at {CLOTH_FPS} fps, frames \
             {CLOTH_WARMUP}… (in contact)"
        ),
        cpu_ms,
        gpu_ms,
        covers: format!(
            "`GpuCloth::step_frame`: params upload, 16 substep dispatches, residual pass, \
             per-particle flags read back; the positions' read-back not included \
             ({read_ms:.2} ms)"
        ),
        error: format!(
            "{:.1e} m (particle positions, after frame {}: grows with the frames, as contact \
             amplifies rounding)",
            max_distance(&x, &cpu.positions()),
            CLOTH_WARMUP as usize + repeat.max(1) - 1
        ),
    })
}

/// §8's rolling sphere: radius 1/10 of the field (0.256 m) sunk 1/40 of it into Sand flat at
/// 0.1 m on 256² cells of 1 cm, crossing the field in 48 frames.
fn ground_row(ctx: &GpuContext, relaxation: Relaxation, repeat: usize) -> Result<Row> {
    let (n, cell, h0) = (256u32, 0.01f32, 0.1f32);
    let mut p = imprint_tests::ground::params(n, cell, h0, Material::Preset(Preset::Sand));
    p.relaxation = relaxation;
    let size = n as f32 * cell;
    let (r, depth) = (0.1 * size, 0.025 * size);
    let base = uv_sphere(r, 64, 32);
    let body = |f: u32| {
        let x = -0.3 * size + 0.6 * size * (f % 48) as f32 / 48.0;
        let mut m = base.clone();
        m.transform(Mat4::from_translation(Vec3::new(x, h0 + r - depth, 0.0)));
        m
    };
    let mut cpu = GroundSim::new(&p, Path::new("."))?;
    let mut gpu = GpuGround::from_sim(ctx, &cpu)?;
    let mut raster = GpuRasterizer::new(ctx)?;
    let (cpu_ms, gpu_ms) = lockstep(
        1,
        repeat,
        |f| cpu.step(&[&body(f)]).map(|_| ()),
        |f| gpu.step_resident(ctx, &mut raster, &[&body(f)]).map(|_| ()),
    )?;
    let (hc, hg) = (cpu.heights_units(), gpu.heights_units());
    let differ = hc.iter().zip(hg).filter(|(a, b)| a != b).count();
    let most = hc.iter().zip(hg).map(|(a, b)| a.abs_diff(*b)).max();
    let (label, covers) = match relaxation {
        Relaxation::Settle => (
            "Settle (default)",
            "press, contour maps, displacement on the GPU; heights read back; settle on the CPU",
        ),
        _ => (
            "Labelled (O, En 5)",
            "press, contour maps, displacement, slump on the GPU; heights read back",
        ),
    };
    Ok(Row {
        stage: "ground",
        scene: format!("rolling sphere, {n}² cells, Sand, {label}"),
        cpu_ms,
        gpu_ms,
        covers: format!(
            "`GpuGround::step_resident`: contact from GPU depth maps (never read back), \
             {covers} (the CPU: `GroundSim::step`, CPU depth maps)"
        ),
        error: format!(
            "{:.1e} m (heights; {differ} of {} cells differ)",
            most.unwrap_or(0) as f64 * gpu.grid().unit,
            hc.len()
        ),
    })
}

/// §8's snow: a 40,000-triangle sphere (radius 0.5, 0.6 above) on a flat 72² ground, default
/// parameters (16 jittered directions, 512² maps), steps of 1/60 s.
fn snow_row(ctx: &GpuContext, repeat: usize) -> Result<Row> {
    let mut ball = uv_sphere(0.5, 160, 125);
    ball.transform(Mat4::from_translation(Vec3::new(0.0, 0.6, 0.0)));
    let ground = HeightField::constant(Vec2::splat(-1.5), 3.0 / 71.0, UVec2::splat(72), 0.0)?;
    let p = SnowParams::default();
    let mut cpu = SnowSim::new(&p)?;
    let mut gpu = cpu.clone();
    let mut raster = GpuRasterizer::new(ctx)?;
    let mut relax = GpuSnowRelax::new();
    let dt = 1.0f32 / 60.0;
    let frames = 1 + repeat.max(1);
    let (cpu_ms, gpu_ms) = lockstep(
        1,
        repeat,
        |_| cpu.step(&[&ball], Some(&ground), dt).map(|_| ()),
        |_| {
            let mut look_ups = GpuSnowArrival::new();
            let arrival = look_ups.resident(ctx, &mut raster);
            gpu.step_with_parts(&[&ball], Some(&ground), dt, arrival, relax.relaxer(ctx))
                .map(|_| ())
        },
    )?;
    let ground_diff = match (cpu.ground(), gpu.ground()) {
        (Some(c), Some(g)) => max_abs(&c.thickness(), &g.thickness()),
        _ => f32::NAN,
    };
    let mesh_diff = max_abs(cpu.mesh_depth(0), gpu.mesh_depth(0));
    Ok(Row {
        stage: "snow",
        scene: format!(
            "{}-triangle sphere on 72² ground, {} directions at {}²",
            ball.triangles.len(),
            p.directions,
            p.resolution
        ),
        cpu_ms,
        gpu_ms,
        covers: "`SnowSim::step_with_parts` as the Snow node: GPU depth maps (never read \
                 back) and look-ups, counts read back, deposit on the CPU, stabilisation on \
                 the GPU (snow uploaded and read back)"
            .into(),
        error: format!(
            "{ground_diff:.1e} m (ground snow), {mesh_diff:.1e} m (mesh snow), of {:.1e} m \
             fallen",
            p.rate as f64 * dt as f64 * frames as f64
        ),
    })
}

/// §11's limb (capped cylinder r 0.1, length 1, 96 × 104) and `assets/rigs/limb.ron`: the
/// two blends and the particle skinning with the defaults.
fn skin_rows(root: &Path, ctx: &GpuContext, repeat: usize) -> Vec<(&'static str, Result<Row>)> {
    let rig = imprint_graph::rig::load(&root.join("assets/rigs/limb.ron"))
        .expect("limb rig")
        .rig;
    let limb = cylinder(0.1, 1.0, 96, 104);
    let w = weights::automatic(&limb.positions, &rig.rest_segments(), &Default::default());
    vec![
        (
            "LBS",
            blend_row(ctx, &rig, &limb, &w, BlendMethod::Linear, repeat),
        ),
        (
            "DQS",
            blend_row(ctx, &rig, &limb, &w, BlendMethod::DualQuaternion, repeat),
        ),
        ("particles", particles_row(ctx, &rig, &limb, repeat)),
    ]
}

/// One blend on both paths; the pose of frame f is the rig's at (f + 1) / 24 s. Positions
/// only on both sides (the normals are recomputed on the CPU either way).
fn blend_row(
    ctx: &GpuContext,
    rig: &Rig,
    limb: &Mesh,
    w: &Weights,
    method: BlendMethod,
    repeat: usize,
) -> Result<Row> {
    let mut gpu = GpuBlend::new(ctx, &limb.positions, w, rig.bones.len())?;
    let pose = |f: u32| rig.pose((f + 1) as f32 / SKIN_FPS).skin;
    let cpu_blend = |f: u32| match method {
        BlendMethod::Linear => blend::lbs(&limb.positions, w, &pose(f)),
        BlendMethod::DualQuaternion => blend::dqs(&limb.positions, w, &pose(f)),
    };
    let (mut out_c, mut out_g) = (Vec::new(), Vec::new());
    let (cpu_ms, gpu_ms) = lockstep(
        1,
        repeat,
        |f| {
            out_c = cpu_blend(f);
            Ok(())
        },
        |f| {
            out_g = gpu.skin(ctx, method, &pose(f))?;
            Ok(())
        },
    )?;
    let last = pose(repeat as u32);
    let dispatch_ms = median_ms(repeat, || {
        gpu.dispatch(ctx, method, &last).expect("blend dispatch");
        ctx.wait().expect("blend wait");
    });
    let name = match method {
        BlendMethod::Linear => "LBS",
        BlendMethod::DualQuaternion => "DQS",
    };
    Ok(Row {
        stage: "skinning",
        scene: format!("{name}, limb of {} vertices, 2 bones", limb.positions.len()),
        cpu_ms,
        gpu_ms,
        covers: format!(
            "`GpuBlend::skin` as the Skin node: bones upload, one dispatch, positions read \
             back; without the read-back {dispatch_ms:.2} ms"
        ),
        error: format!("{:.1e} m (vertex positions)", max_distance(&out_g, &out_c)),
    })
}

/// The particle skinning with the default forces (corotated springs, pressure) at §11's
/// finest radius (about 5k particles); each frame's substeps and then the vertices.
fn particles_row(ctx: &GpuContext, rig: &Rig, limb: &Mesh, repeat: usize) -> Result<Row> {
    let params = ParticleParams {
        fill: FillParams {
            radius: 0.0093,
            ..Default::default()
        },
        ..Default::default()
    };
    let mut cpu = ParticleSkin::new(limb, &rig.rest_segments(), &params)?;
    let mut gpu = GpuParticleSkin::new(ctx, &cpu)?;
    let pose = |f: u32| rig.pose(f as f32 / SKIN_FPS).skin;
    let dt = 1.0 / SKIN_FPS;
    let (mut out_c, mut out_g) = (Vec::new(), Vec::new());
    let (cpu_ms, gpu_ms) = lockstep(
        1,
        repeat,
        |f| {
            cpu.step_frame(&pose(f), &pose(f + 1), f, dt)?;
            out_c = cpu.vertices();
            Ok(())
        },
        |f| {
            gpu.step_frame(ctx, &pose(f), &pose(f + 1), f, dt)?;
            out_g = gpu.vertices(ctx)?;
            Ok(())
        },
    )?;
    Ok(Row {
        stage: "skinning",
        scene: format!(
            "particles (defaults), {} particles, {} substeps, limb of {} vertices",
            gpu.particles(),
            params.substeps,
            limb.positions.len()
        ),
        cpu_ms,
        gpu_ms,
        covers: "`GpuParticleSkin::step_frame` (bone transforms upload, 3 dispatches a \
                 substep, blow-up flag read back) then `vertices` (2 dispatches, vertices \
                 read back), as the Skin node"
            .into(),
        error: format!("{:.1e} m (vertex positions)", max_distance(&out_g, &out_c)),
    })
}
