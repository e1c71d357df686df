//! Section 11 of BENCHMARKS.md: skinning (T §(3)) — particle skinning beside linear blend
//! (LBS) and dual quaternion (DQS) skinning on the same limb and rig, ms per frame and what
//! each keeps of the joint; and the adaptive fill's particle counts against a uniform fill.
//!
//! The limb: a capped cylinder (radius 0.1, length 1), 96 segments × 104 rings (about 10k
//! vertices), driven by `assets/rigs/limb.ron` (bend 90° over 1 s, then twist 180° over 1 s)
//! at 24 fps for 60 frames. Particles: T's fill at a finest radius that gives about 5k
//! particles, the default forces (beyond T) and T's own set.

use crate::median;
use glam::Vec3;
use imprint_core::Mesh;
use imprint_core::mesh::primitives::{cylinder, torus};
use imprint_stages::skin::fill::{FillParams, fill};
use imprint_stages::skin::particles::{ParticleParams, ParticleSkin};
use imprint_stages::skin::rig::Rig;
use imprint_stages::skin::{blend, measure, weights};
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

const FPS: f32 = 24.0;
const FRAMES: u32 = 60;

/// One method's run: median ms per frame, and at the last frame the volume and the joint's
/// section as ratios to the rest pose.
struct Outcome {
    ms: f64,
    volume: f64,
    section: f64,
}

/// The joint's section (the plane through the lower bone's head halving the bend) and the
/// volume of `mesh` posed by `rig` at `t`.
fn measures(rig: &Rig, mesh: &Mesh, t: Option<f32>) -> (f64, f64) {
    let seg = match t {
        Some(t) => rig.posed_segments(&rig.pose(t)),
        None => rig.rest_segments(),
    };
    let dir = |(h, t): (Vec3, Vec3)| (t - h).normalize();
    let n = (dir(seg[0]) + dir(seg[1]))
        .try_normalize()
        .unwrap_or(dir(seg[1]));
    (
        measure::volume(mesh),
        measure::cross_section_area(mesh, seg[1].0, n),
    )
}

fn run(rig: &Rig, rest: &Mesh, mut frame: impl FnMut(u32, f32) -> Mesh) -> Outcome {
    let (v0, s0) = measures(rig, rest, None);
    let mut times = Vec::new();
    let mut last = rest.clone();
    for f in 0..FRAMES {
        let t = Instant::now();
        last = frame(f, (f + 1) as f32 / FPS);
        times.push(t.elapsed().as_secs_f64() * 1e3);
    }
    let (v, s) = measures(rig, &last, Some(FRAMES as f32 / FPS));
    Outcome {
        ms: median(times),
        volume: v / v0,
        section: s / s0,
    }
}

pub fn section(root: &Path, _repeat: usize) -> String {
    let rig = imprint_graph::rig::load(&root.join("assets/rigs/limb.ron"))
        .expect("limb rig")
        .rig;
    let limb = cylinder(0.1, 1.0, 96, 104);
    let segments = rig.rest_segments();
    let mut s = String::from("## 11. Skinning (CPU)\n\n");
    let _ = writeln!(
        s,
        "The limb: a capped cylinder (radius 0.1, length 1), {} vertices, {} triangles, driven \
         by `assets/rigs/limb.ron` (bend 90° at the middle over 1 s, then twist the lower bone \
         180° over 1 s), {FRAMES} frames at {FPS} fps. **ms per frame**: median over the run \
         (particles: the frame's substeps and the vertices; blends: the vertices and their \
         normals). **volume** and **joint section**: the last frame's, as ratios to the rest \
         pose (the section through the joint, on the plane halving the bend). Goal (issue): \
         5k particles driving 10k vertices in ≤ 8 ms per frame.\n",
        limb.positions.len(),
        limb.triangles.len()
    );
    let _ = writeln!(
        s,
        "| method | particles | ms per frame | volume | joint section |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|");
    let w = weights::automatic(&limb.positions, &segments, &Default::default());
    let blend_row = |s: &mut String, label: &str, dual: bool| {
        let o = run(&rig, &limb, |_, t| {
            let pose = rig.pose(t);
            let mut m = limb.clone();
            m.positions = if dual {
                blend::dqs(&limb.positions, &w, &pose.skin)
            } else {
                blend::lbs(&limb.positions, &w, &pose.skin)
            };
            m.compute_normals();
            m
        });
        eprintln!("skin: {label}: {:.2} ms", o.ms);
        let _ = writeln!(
            s,
            "| {label} | – | {:.2} | {:.3} | {:.3} |",
            o.ms, o.volume, o.section
        );
    };
    blend_row(&mut s, "LBS (automatic weights)", false);
    blend_row(&mut s, "DQS (automatic weights)", true);
    let fill_params = FillParams {
        radius: 0.0093,
        ..Default::default()
    };
    for (label, params) in [
        (
            "particles, defaults (corotated springs, pressure)",
            ParticleParams {
                fill: fill_params.clone(),
                ..Default::default()
            },
        ),
        (
            "particles, T's set (distance springs)",
            ParticleParams {
                fill: fill_params.clone(),
                ..ParticleParams::t_method()
            },
        ),
    ] {
        let mut sim = ParticleSkin::new(&limb, &segments, &params).expect("particle skin");
        let mut prev = rig.pose(0.0).skin;
        let o = run(&rig, &limb, |f, t| {
            let pose = rig.pose(t);
            sim.step_frame(&prev, &pose.skin, f, 1.0 / FPS)
                .expect("particle skin frame");
            prev = pose.skin;
            sim.mesh()
        });
        eprintln!("skin: {label}: {:.2} ms", o.ms);
        let _ = writeln!(
            s,
            "| {label} | {} | {:.2} | {:.3} | {:.3} |",
            sim.fill_report().adaptive_count,
            o.ms,
            o.volume,
            o.section
        );
    }
    fill_counts(&mut s, root);
    s
}

/// Adaptive against uniform fills (T's motivation: far fewer particles for thick bodies).
fn fill_counts(s: &mut String, root: &Path) {
    let cow = {
        let mut m = Mesh::load_obj(&root.join("assets/meshes/cow.obj")).expect("cow");
        let t = m.fit_transform(1.0, Vec3::ZERO);
        m.transform(t);
        m
    };
    let _ = writeln!(
        s,
        "\nThe fill (3 levels, finest radius r): particles of the adaptive fill against a uniform \
         fill at r, and the particles' owned volume against the mesh's.\n"
    );
    let _ = writeln!(
        s,
        "| mesh | r | adaptive | uniform | adaptive / uniform | volume error | fill ms |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
    let meshes = [
        ("limb (above)", cylinder(0.1, 1.0, 96, 104), 0.0093),
        ("torus (0.5, 0.2)", torus(0.5, 0.2, 128, 64), 0.01),
        ("cow (size 1)", cow, 0.01),
    ];
    for (name, mesh, radius) in meshes {
        let params = FillParams {
            radius,
            ..Default::default()
        };
        let t = Instant::now();
        let f = fill(&mesh, &params).expect("fill");
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let r = &f.report;
        let _ = writeln!(
            s,
            "| {name} | {radius} | {} | {} | {:.2} | {:+.2}% | {ms:.0} |",
            r.adaptive_count,
            r.uniform_count,
            r.adaptive_count as f64 / r.uniform_count as f64,
            100.0 * (r.particle_volume / r.mesh_volume - 1.0)
        );
    }
}
