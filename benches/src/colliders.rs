//! Section 10 of BENCHMARKS.md: the cloth's two colliders on the same scene — the body's
//! distance field (H) and its depth maps read every substep (T's draping test, beyond T as a
//! collider) — what each costs to build and per frame, and how well each keeps the cloth out
//! (by the exact inside test of the body) and lets it come to rest.
//!
//! `pipelines/cloth_colliders.ron`'s scene without the render: a 40 × 40 cloth (0.8 m)
//! dropped on the cow (size 1), 24 substeps, ε = 8 mm, 48 frames at 24 fps.

use crate::median;
use glam::Vec3;
use imprint_core::raster::rasterize_depth_with;
use imprint_core::{BoundaryVariant, GridSpec, Mesh};
use imprint_stages::cloth::{ClothParams, ClothSim, Collision, Material, Shape};
use imprint_stages::drape::{DepthCamera, DepthColliderParams, InsideTest};
use imprint_stages::voxel::cpu::Voxelizer;
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

const FRAMES: u32 = 48;
const FPS: f32 = 24.0;

fn cloth() -> ClothSim {
    let mut p = ClothParams::new(
        Shape::Grid {
            size: [0.8, 0.8],
            resolution: [40, 40],
            center: Vec3::new(0.0, 0.95, 0.0),
            normal: Vec3::Y,
        },
        Material::Harada {
            k_structural: 60.0,
            k_shear: 15.0,
            k_bend: None,
        },
    );
    p.mass = 0.001;
    p.damping = 0.995;
    p.collision = Collision {
        epsilon: 0.008,
        friction: 0.4,
        ground: Some(0.0),
    };
    p.substeps = 24;
    ClothSim::from_assets(&p, &Default::default()).expect("cloth")
}

/// What a run left: median cloth ms per frame, particles inside the body (exact test) at the
/// end and the most in any frame, contacts at the end, and the kinetic energy of the last
/// frame.
struct Outcome {
    cloth_ms: f64,
    inside_end: usize,
    inside_most: usize,
    contacts: u32,
    kinetic: f64,
}

fn run(test: &InsideTest, mut step: impl FnMut(&mut ClothSim, u32) -> (f64, u32, f64)) -> Outcome {
    let mut sim = cloth();
    let mut times = Vec::new();
    let (mut most, mut contacts, mut kinetic) = (0, 0, 0.0);
    for f in 0..FRAMES {
        let (ms, c, k) = step(&mut sim, f);
        times.push(ms);
        let inside = sim.positions().iter().filter(|p| test.inside(**p)).count();
        most = most.max(inside);
        (contacts, kinetic) = (c, k);
    }
    Outcome {
        cloth_ms: median(times),
        inside_end: sim.positions().iter().filter(|p| test.inside(**p)).count(),
        inside_most: most,
        contacts,
        kinetic,
    }
}

pub fn section(root: &Path, repeat: usize) -> String {
    let mut cow = Mesh::load_obj(&root.join("assets/meshes/cow.obj")).expect("cow");
    let fit = cow.fit_transform(1.0, Vec3::new(0.0, 0.38, 0.0));
    cow.transform(fit);
    let test = InsideTest::new(&cow);
    let eps = 0.008;
    let mut s = String::from("## 10. The cloth's colliders: distance field against depth maps\n\n");
    let _ = writeln!(
        s,
        "`pipelines/cloth_colliders.ron`'s scene without the render: a 40 × 40 cloth (0.8 m, \
         Harada springs, 24 substeps, ε = 8 mm, friction 0.4) dropped on the cow (size 1, {} \
         triangles), {FRAMES} frames at {FPS} fps. **build**: once for this static body (a \
         deforming body pays it every frame), median of {repeat}; **cloth ms**: median per \
         frame; **inside**: cloth particles inside the cow by the exact inside test (the \
         parity of three axis rays), at the end and the most in any frame; **kinetic**: the \
         cloth's kinetic energy in the last frame (how well it comes to rest; J). The field \
         is built signed (the cow is closed: its inside cells are marked, and the cloth takes \
         a particle found inside out through the nearest surface) and unsigned (the particle \
         remembers its side), to show what the sign costs and buys.\n",
        cow.triangles.len()
    );
    let _ = writeln!(
        s,
        "| collider | build ms | cloth ms per frame | inside at end | inside, most | contacts at end | kinetic at end |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
    // The distance field: 96³ over the cow's box, band 3 (as the pipeline); signed (the
    // default for a closed mesh) and unsigned (the sign's cost, in build and in the cloth).
    let spec = GridSpec::fit(&cow.bounds(), 96, 0.15).expect("grid");
    for signed in [true, false] {
        let mut vox = Voxelizer::new(spec).expect("voxeliser");
        vox.signed = signed;
        let mut build_field = || {
            let b = vox.run(&cow, BoundaryVariant::Closest).expect("voxelise");
            imprint_stages::sdf::build_field_cpu(&b, 3.0).expect("field")
        };
        let field_ms = crate::median_ms(repeat, || {
            std::hint::black_box(build_field());
        });
        let field = build_field();
        assert_eq!(field.inside.is_some(), signed);
        let o = run(&test, |sim, f| {
            let t = Instant::now();
            let m = sim
                .step_frame(&[&field], &[&field], f, 1.0 / FPS)
                .expect("field cloth");
            (t.elapsed().as_secs_f64() * 1e3, m.contacts, m.kinetic)
        });
        let label = if signed { "signed" } else { "unsigned" };
        row(
            &mut s,
            &format!("distance field 96³, band 3, {label}"),
            field_ms,
            &o,
        );
    }
    for res in [256, 512] {
        let params = DepthColliderParams {
            views: vec![Vec3::NEG_Y, Vec3::NEG_Z, Vec3::X],
            resolution: res,
        };
        let camera = DepthCamera::new(&cow.bounds(), &params, eps).expect("camera");
        let pose_ms = crate::median_ms(repeat, || {
            std::hint::black_box(camera.pose(&cow, rasterize_depth_with).expect("pose"));
        });
        let pose = camera.pose(&cow, rasterize_depth_with).expect("pose");
        let o = run(&test, |sim, f| {
            let t = Instant::now();
            let m = sim
                .step_frame_between(&[], &[camera.collider(None, &pose)], f, 1.0 / FPS)
                .expect("depth-map cloth");
            (t.elapsed().as_secs_f64() * 1e3, m.contacts, m.kinetic)
        });
        row(
            &mut s,
            &format!("depth maps, 3 lines at {res}², dilated by ε"),
            pose_ms,
            &o,
        );
    }
    s
}

fn row(s: &mut String, label: &str, build_ms: f64, o: &Outcome) {
    eprintln!(
        "colliders: {label}: build {build_ms:.1} ms, cloth {:.2} ms",
        o.cloth_ms
    );
    let _ = writeln!(
        s,
        "| {label} | {build_ms:.1} | {:.2} | {} | {} | {} | {:.2e} |",
        o.cloth_ms, o.inside_end, o.inside_most, o.contacts, o.kinetic
    );
}
