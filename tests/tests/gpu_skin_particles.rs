//! The GPU particle substeps (`skin::gpu_particles::GpuParticleSkin`) against the CPU's
//! `ParticleSkin::step_frame` with T's forces, on a coarsely filled two-bone limb bent 90°
//! over 6 frames and held for 6: the same particle positions per frame. Both sides are f32;
//! they differ only by the GPU's rounding (fused multiply-adds, `length`, division), which
//! the damped motion keeps from growing. Measured on lavapipe (378 particles, 24 substeps a
//! frame): max |GPU − CPU| 6e-8 to 1.2e-7 per frame (about one ulp of coordinates near 0.7),
//! not growing over the 12 frames; the tolerance is 2e-5 of the limb's radius (2e-6 m, 16×
//! the measured, headroom for a GPU that contracts differently). A GPU that dropped or
//! mis-scaled a force would miss by far more: the test checks that a CPU run with the bone
//! pull halved, or without pair or bone damping, lands at least 20× the tolerance away
//! (measured 8e-2, 2.2e-3, 1.4e-1). The same with the defaults (corotated springs with the
//! per-particle rotation fit, pressure: measured 1.2e-7 to 1.4e-7; without pressure or with
//! the spring halved the CPU lands 1.3e-2 and 4.5e-2 away) and with distance springs plus
//! pressure (measured up to 1.2e-7); and the vertices computed on the GPU, both vertex rules
//! (measured up to 1.8e-7; the two rules differ by 1e-2 on the CPU). Skips
//! without a GPU adapter (`IMPRINT_REQUIRE_GPU=1` makes that a failure). Small scene: CI
//! runs this on a software rasteriser (Mesa lavapipe).

use glam::{Affine3A, Vec3};
use imprint_gpu::test_context;
use imprint_stages::skin::fill::FillParams;
use imprint_stages::skin::gpu_particles::GpuParticleSkin;
use imprint_stages::skin::particles::{ParticleParams, ParticleSkin, VertexRotation};
use imprint_tests::skin::{bend, two_bone_limb};

const R: f32 = 0.1;
const LEN: f32 = 1.0;
const DT: f32 = 1.0 / 24.0;
/// Largest allowed |GPU − CPU| per particle, as a fraction of the limb's radius.
const TOL: f32 = 2e-5;
const FRAMES: u32 = 12;

fn max_diff(a: &[Vec3], b: &[Vec3]) -> f32 {
    assert_eq!(a.len(), b.len());
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

fn coarse_t() -> ParticleParams {
    ParticleParams {
        fill: FillParams {
            radius: 0.025,
            levels: 2,
        },
        ..ParticleParams::t_method()
    }
}

/// The CPU's positions after each frame.
fn cpu_run(skin: &mut ParticleSkin, pose: &dyn Fn(u32) -> Vec<Affine3A>) -> Vec<Vec<Vec3>> {
    (0..FRAMES)
        .map(|f| {
            skin.step_frame(&pose(f), &pose(f + 1), f, DT).unwrap();
            skin.positions().to_vec()
        })
        .collect()
}

#[test]
fn gpu_particles_match_the_cpu_through_a_bend() {
    let Some(ctx) = test_context() else { return };
    let (mesh, rig) = two_bone_limb(R, LEN, 16, 10);
    let pose = |f: u32| bend(&rig, 90.0 * (f.min(6) as f32 / 6.0)).skin;
    let mut cpu = ParticleSkin::new(&mesh, &rig.rest_segments(), &coarse_t()).unwrap();
    let mut gpu = GpuParticleSkin::new(ctx, &cpu).unwrap();
    println!(
        "{} particles, {} neighbour entries, {} substeps per frame",
        gpu.particles(),
        cpu.neighbour_count(),
        cpu.params().substeps
    );
    let rest = cpu.positions().to_vec();
    let cpu_frames = cpu_run(&mut cpu, &pose);
    let mut worst = 0.0f32;
    for (f, want) in cpu_frames.iter().enumerate() {
        let f = f as u32;
        gpu.step_frame(ctx, &pose(f), &pose(f + 1), f, DT).unwrap();
        let got = gpu.read_positions(ctx).unwrap();
        let err = max_diff(&got, want);
        let moved = max_diff(want, &rest);
        println!(
            "frame {f:>2}: max |GPU - CPU| = {err:.2e} (= {:.2e} R; largest move from rest {moved:.3})",
            err / R
        );
        assert!(err <= TOL * R, "frame {f}: max |GPU - CPU| {err}");
        worst = worst.max(err);
    }
    println!("worst {worst:.2e}, tolerance {:.0e}", TOL * R);
    // The particles really moved (far beyond the tolerance).
    let moved = max_diff(&cpu_frames[FRAMES as usize - 1], &rest);
    assert!(moved > 0.3, "moved {moved}");
    // A GPU that got a force wrong would fail: changing the bone pull or the pair damping
    // on the CPU moves the particles by far more than the tolerance.
    for (name, params) in [
        (
            "bone pull halved",
            ParticleParams {
                bone_stiffness: 0.5 * coarse_t().bone_stiffness,
                ..coarse_t()
            },
        ),
        (
            "no pair damping",
            ParticleParams {
                damping: 0.0,
                ..coarse_t()
            },
        ),
        (
            "no bone damping",
            ParticleParams {
                bone_damping: 0.0,
                ..coarse_t()
            },
        ),
    ] {
        let mut other = ParticleSkin::new(&mesh, &rig.rest_segments(), &params).unwrap();
        let frames = cpu_run(&mut other, &pose);
        let d = frames
            .iter()
            .zip(&cpu_frames)
            .map(|(a, b)| max_diff(a, b))
            .fold(0.0, f32::max);
        println!("CPU with {name}: max difference from the reference {d:.2e}");
        assert!(d > 20.0 * TOL * R, "{name}: only {d}");
    }
}

/// The GPU against the CPU through the same bend, particles and vertices (the vertices on
/// the GPU too); returns the largest difference of either.
fn compare(ctx: &imprint_gpu::GpuContext, name: &str, params: &ParticleParams) -> f32 {
    let (mesh, rig) = two_bone_limb(R, LEN, 16, 10);
    let pose = |f: u32| bend(&rig, 90.0 * (f.min(6) as f32 / 6.0)).skin;
    let mut cpu = ParticleSkin::new(&mesh, &rig.rest_segments(), params).unwrap();
    let mut gpu = GpuParticleSkin::new(ctx, &cpu).unwrap();
    let mut worst = 0.0f32;
    for f in 0..FRAMES {
        cpu.step_frame(&pose(f), &pose(f + 1), f, DT).unwrap();
        gpu.step_frame(ctx, &pose(f), &pose(f + 1), f, DT).unwrap();
        let err = max_diff(&gpu.read_positions(ctx).unwrap(), cpu.positions());
        let verr = max_diff(&gpu.vertices(ctx).unwrap(), &cpu.vertices());
        println!("{name}, frame {f:>2}: max |GPU - CPU| particles {err:.2e}, vertices {verr:.2e}");
        worst = worst.max(err).max(verr);
    }
    println!("{name}: worst {worst:.2e}");
    worst
}

/// The defaults (corotated springs with per-particle rotations, pressure), and distance
/// springs with pressure: the rotation fit and the volume change run on the GPU too.
#[test]
fn gpu_particles_match_the_cpu_with_rotations_and_pressure() {
    let Some(ctx) = test_context() else { return };
    let fill = coarse_t().fill;
    let defaults = ParticleParams {
        fill: fill.clone(),
        ..Default::default()
    };
    let err = compare(ctx, "defaults", &defaults);
    assert!(err <= TOL * R, "defaults: {err}");
    // A GPU without the pressure or with a mis-scaled corotated spring would fail: on the
    // CPU those land far beyond the tolerance. (Distance springs in the corotated ones'
    // place blow up at the defaults' step, on the CPU too, so cannot be compared.)
    let (mesh, rig) = two_bone_limb(R, LEN, 16, 10);
    let pose = |f: u32| bend(&rig, 90.0 * (f.min(6) as f32 / 6.0)).skin;
    let mut reference = ParticleSkin::new(&mesh, &rig.rest_segments(), &defaults).unwrap();
    let want = cpu_run(&mut reference, &pose);
    for (name, params) in [
        (
            "no pressure",
            ParticleParams {
                volume_stiffness: 0.0,
                ..defaults.clone()
            },
        ),
        (
            "spring stiffness halved",
            ParticleParams {
                stiffness: 0.5 * defaults.stiffness,
                ..defaults.clone()
            },
        ),
    ] {
        let mut other = ParticleSkin::new(&mesh, &rig.rest_segments(), &params).unwrap();
        let d = cpu_run(&mut other, &pose)
            .iter()
            .zip(&want)
            .map(|(a, b)| max_diff(a, b))
            .fold(0.0, f32::max);
        println!("CPU defaults with {name}: max difference from the reference {d:.2e}");
        assert!(d > 20.0 * TOL * R, "{name}: only {d}");
    }
    let distance_pressure = ParticleParams {
        volume_stiffness: 2000.0,
        ..coarse_t()
    };
    let err = compare(ctx, "T + pressure", &distance_pressure);
    assert!(err <= TOL * R, "T + pressure: {err}");
    let t_particle_rot = ParticleParams {
        vertex_rotation: VertexRotation::Particle,
        ..coarse_t()
    };
    let err = compare(ctx, "T, vertices by particle rotation", &t_particle_rot);
    assert!(err <= TOL * R, "T, vertices by particle rotation: {err}");
    // A GPU turning the vertex offsets by the wrong rotation would fail: the two rules'
    // vertices differ by far more than the tolerance after the bend.
    let mut by_bone = ParticleSkin::new(&mesh, &rig.rest_segments(), &coarse_t()).unwrap();
    let mut by_particle = ParticleSkin::new(&mesh, &rig.rest_segments(), &t_particle_rot).unwrap();
    for f in 0..FRAMES {
        by_bone.step_frame(&pose(f), &pose(f + 1), f, DT).unwrap();
        by_particle
            .step_frame(&pose(f), &pose(f + 1), f, DT)
            .unwrap();
    }
    let d = max_diff(&by_bone.vertices(), &by_particle.vertices());
    println!("CPU vertices, bone vs particle rotation: max difference {d:.2e}");
    assert!(d > 20.0 * TOL * R, "vertex rotations: only {d}");
}
