//! Checkpoints are exact: a stage stepped k frames, written with postcard, read back and
//! stepped m more frames is bit for bit the stage stepped k + m frames without stopping
//! (positions, heights, fields, metrics, and every byte of the state itself).

use crate::cloth::{Body, ClothParams, ClothSim, Material, Pin, Shape, Wind};
use crate::ground::{GroundParams, GroundSim, Initial, Preset, Relaxation};
use crate::sdf::{FieldBuilder, build_field_cpu};
use crate::skin::particles::{ParticleParams, ParticleSkin, VertexRotation};
use crate::snow::{SnowParams, SnowSim};
use crate::voxel::voxelize_cpu;
use glam::{Affine3A, Mat4, UVec2, UVec3, Vec2, Vec3, Vec4};
use imprint_core::mesh::primitives::{cuboid, uv_sphere};
use imprint_core::{BoundaryVariant, DistanceField, GridSpec, HeightField, Mesh};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// Writes `v` with postcard and reads it back; the copy must write the same bytes.
fn reload<T: Serialize + DeserializeOwned>(v: &T) -> T {
    let bytes = postcard::to_allocvec(v).unwrap();
    let back: T = postcard::from_bytes(&bytes).unwrap();
    assert_eq!(
        postcard::to_allocvec(&back).unwrap(),
        bytes,
        "a reloaded state writes other bytes"
    );
    back
}

fn bytes<T: Serialize>(v: &T) -> Vec<u8> {
    postcard::to_allocvec(v).unwrap()
}

fn bits3(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

fn bits4(v: &[Vec4]) -> Vec<[u32; 4]> {
    v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

fn bits(v: &[f32]) -> Vec<u32> {
    v.iter().map(|x| x.to_bits()).collect()
}

/// Pseudo-random numbers in [0, 1), reproducible.
fn noise(i: u64, k: u64) -> f32 {
    let v = (i * 3 + k + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    (v >> 40) as f32 / (1u64 << 24) as f32
}

/// An exact field of the sphere (c, r) on the box [lo, hi].
fn sphere_field(c: Vec3, r: f32, lo: Vec3, hi: Vec3, cell: f32, band: f32) -> DistanceField {
    let dims = ((hi - lo) / cell).ceil().as_uvec3() + UVec3::ONE;
    let spec = GridSpec::new(lo, cell, dims).unwrap();
    DistanceField::from_closest_points(spec, band, |p| c + r * (p - c).normalize_or(Vec3::X))
}

const CLOTH_FRAMES: u32 = 30;
const CLOTH_STOP: u32 = 18;

/// A cloth pinned along one edge (pins led along a path), in wind, over a ground plane,
/// draped onto a sphere that rises and slides under it (fields blended per substep), frames
/// of two lengths (so the substep length changes between frames).
fn cloth_run(material: Material) {
    let fields: Vec<DistanceField> = (0..=CLOTH_FRAMES)
        .map(|f| {
            let t = f as f32 / CLOTH_FRAMES as f32;
            sphere_field(
                Vec3::new(0.08 * t, -0.12 + 0.06 * t, 0.0),
                0.25,
                Vec3::new(-0.6, -0.45, -0.6),
                Vec3::new(0.6, 0.3, 0.6),
                0.03,
                4.0,
            )
        })
        .collect();
    let dt = |f: u32| if f % 3 == 2 { 1.0 / 50.0 } else { 1.0 / 60.0 };
    let mut p = ClothParams::new(
        Shape::Grid {
            size: [0.9, 0.9],
            resolution: [16, 16],
            center: Vec3::new(0.0, 0.2, 0.0),
            normal: Vec3::Y,
        },
        material,
    );
    p.pins = vec![Pin::TopEdge, Pin::Indices(vec![0])];
    p.wind = Some(Wind {
        velocity: Vec3::new(0.4, 0.0, 0.3),
        drag: 0.5,
    });
    p.collision.ground = Some(-0.35);
    p.collision.epsilon = 0.01;
    p.collision.friction = 0.4;
    let probe = ClothSim::from_assets(&p, &Default::default()).unwrap();
    p.substeps = probe.stability().substeps_for(1.0 / 50.0).max(12);
    let start = ClothSim::from_assets(&p, &Default::default())
        .unwrap()
        .with_name("drape");
    let rest = start.shape().rest.clone();
    let pinned = start.pinned().to_vec();
    let run = |cloth: &mut ClothSim, frames: std::ops::Range<u32>| {
        let mut metrics = Vec::new();
        for f in frames {
            let shift = Vec3::new(0.03 * (0.4 * f as f32).sin(), 0.002 * f as f32, 0.0);
            let targets: Vec<Vec3> = pinned.iter().map(|&i| rest[i as usize] + shift).collect();
            cloth.set_pin_targets(&targets).unwrap();
            let body = Body {
                start: Some(&fields[f as usize]),
                end: &fields[f as usize + 1],
                span: (0.0, 1.0),
            };
            metrics.push(cloth.step_frame_between(&[body], &[], f, dt(f)).unwrap());
        }
        metrics
    };
    let mut whole = reload(&start);
    let mut all = run(&mut whole, 0..CLOTH_FRAMES);
    let mut part = reload(&start);
    run(&mut part, 0..CLOTH_STOP);
    let mut part = reload(&part);
    let rest_metrics = run(&mut part, CLOTH_STOP..CLOTH_FRAMES);
    assert!(
        all[CLOTH_STOP as usize..].iter().any(|m| m.contacts > 0),
        "the test needs contact after the checkpoint: {all:?}"
    );
    assert_eq!(bits4(&part.state().pos), bits4(&whole.state().pos));
    assert_eq!(bits4(&part.state().prev), bits4(&whole.state().prev));
    assert_eq!(
        bytes(&rest_metrics),
        bytes(&all.split_off(CLOTH_STOP as usize))
    );
    assert_eq!(bytes(&part), bytes(&whole), "the states differ");
    assert_eq!(part.params(), whole.params());
}

#[test]
fn cloth_resumes_bit_for_bit() {
    cloth_run(Material::Harada {
        k_structural: 60.0,
        k_shear: 15.0,
        k_bend: Some(4.0),
    });
    cloth_run(Material::Tokoi {
        a_compress: 2e3,
        b_stretch: 1e4,
        bend_c: 1e-3,
        anisotropy: None,
    });
}

/// A sphere pressed into sand and dragged across it (both relaxations), with material added
/// in fractions of a height unit between frames (the carried remainders).
#[test]
fn ground_resumes_bit_for_bit() {
    for relaxation in [Relaxation::Labelled, Relaxation::Full] {
        let (n, cell, h0) = (64u32, 0.01f32, 0.1f32);
        let mut p = GroundParams::new(
            [n as f32 * cell; 2],
            [n, n],
            crate::ground::Material::Preset(Preset::Sand),
        );
        p.initial = Initial::Flat(h0);
        p.relaxation = relaxation;
        let start = GroundSim::new(&p, std::path::Path::new(".")).unwrap();
        let (frames, stop) = (12u32, 7u32);
        let run = |g: &mut GroundSim, frames: std::ops::Range<u32>| {
            let mut metrics = Vec::new();
            for f in frames {
                let r = 0.08;
                let mut ball = uv_sphere(r, 64, 32);
                let c = Vec3::new(-0.15 + 0.025 * f as f32, h0 + r - 0.02, 0.01);
                ball.transform(Mat4::from_translation(c));
                metrics.push(g.step(&[&ball]).unwrap());
                let rise: Vec<f32> = (0..(n * n) as u64)
                    .map(|j| 3.3e-6 * noise(j, f as u64))
                    .collect();
                g.add_heights(&rise).unwrap();
            }
            metrics
        };
        let mut whole = start.clone();
        let mut all = run(&mut whole, 0..frames);
        let mut part = start.clone();
        run(&mut part, 0..stop);
        let mut part = reload(&part);
        let rest = run(&mut part, stop..frames);
        assert!(
            all[stop as usize..].iter().all(|m| m.contact_cells > 0),
            "{relaxation:?}: the sphere must press every frame"
        );
        assert!(
            all.iter().any(|m| m.slumped_units > 0),
            "{relaxation:?}: no slump"
        );
        assert_eq!(
            part.heights_units(),
            whole.heights_units(),
            "{relaxation:?}"
        );
        assert_eq!(bytes(&rest), bytes(&all.split_off(stop as usize)));
        assert_eq!(part.maps(), whole.maps());
        assert_eq!(
            bytes(&part),
            bytes(&whole),
            "{relaxation:?}: the states differ"
        );
    }
}

/// A ball over a bumpy ground with a ridge steeper than the repose angle: snow lands on both
/// and slides off the ridge; the ground under the snow is changed once after the checkpoint.
#[test]
fn snow_resumes_bit_for_bit() {
    let mut ball = uv_sphere(0.15, 32, 16);
    ball.transform(Mat4::from_translation(Vec3::new(0.0, 0.4, 0.0)));
    let cell = 0.02;
    let bumpy = |lift: f32| {
        HeightField::from_fn(Vec2::splat(-0.5), cell, UVec2::splat(48), |i, k| {
            let x = i as f32 * cell;
            0.05 * noise(i as u64, k as u64 * 1000)
                + 0.3 * (-(x - 0.4).powi(2) / 0.002).exp()
                + lift * (k as f32 * cell)
        })
        .unwrap()
    };
    let grounds = [bumpy(0.0), bumpy(0.05)];
    let p = SnowParams {
        directions: 8,
        jitter_degrees: 15.0,
        rate: 0.05,
        resolution: 256,
        ..Default::default()
    };
    let start = SnowSim::new(&p).unwrap();
    let (steps, stop) = (6usize, 3usize);
    let run = |sim: &mut SnowSim, steps: std::ops::Range<usize>| {
        steps
            .map(|s| {
                let g = &grounds[(s >= 4) as usize];
                let step = sim.step(&[&ball], Some(g), 0.2).unwrap();
                (step.directions, step.reached, step.relax)
            })
            .collect::<Vec<_>>()
    };
    let mut whole = start.clone();
    let mut all = run(&mut whole, 0..steps);
    let mut part = start.clone();
    run(&mut part, 0..stop);
    let mut part = reload(&part);
    let rest = run(&mut part, stop..steps);
    assert!(
        all[stop..].iter().all(|s| s.2.moved > 0),
        "the ridge should shed snow after the checkpoint: {all:?}"
    );
    assert_eq!(rest, all.split_off(stop));
    let (a, b) = (part.ground().unwrap(), whole.ground().unwrap());
    assert_eq!(a.units, b.units);
    assert_eq!(bits(&a.residual), bits(&b.residual));
    assert_eq!(bits(&a.base.heights), bits(&b.base.heights));
    assert_eq!(bits(part.mesh_depth(0)), bits(whole.mesh_depth(0)));
    assert_eq!(part.arrival(), whole.arrival());
    assert_eq!(part.time().to_bits(), whole.time().to_bits());
    assert_eq!(
        part.cover(&[&ball]).unwrap(),
        whole.cover(&[&ball]).unwrap()
    );
    assert_eq!(bytes(&part), bytes(&whole), "the states differ");
}

/// A bar of two bones bending at its middle, for T's forces and for the defaults (corotated
/// springs, pressure) with both vertex rotations.
#[test]
fn particle_skin_resumes_bit_for_bit() {
    let mesh: Mesh = cuboid(Vec3::new(0.3, 0.08, 0.08), 4);
    let bones = [
        (Vec3::new(-0.3, 0.0, 0.0), Vec3::ZERO),
        (Vec3::ZERO, Vec3::new(0.3, 0.0, 0.0)),
    ];
    let pose = |f: u32| {
        let a = 1.2 * (f.min(6) as f32 / 6.0);
        vec![Affine3A::IDENTITY, Affine3A::from_rotation_z(a)]
    };
    let cases = [
        ParticleParams::t_method(),
        ParticleParams {
            vertex_rotation: VertexRotation::Bone,
            ..Default::default()
        },
        ParticleParams {
            vertex_rotation: VertexRotation::Particle,
            ..Default::default()
        },
    ];
    for params in cases {
        let start = ParticleSkin::new(&mesh, &bones, &params)
            .unwrap()
            .with_name("arm");
        let (frames, stop) = (10u32, 4u32);
        let run = |s: &mut ParticleSkin, frames: std::ops::Range<u32>| {
            frames
                .map(|f| s.step_frame(&pose(f), &pose(f + 1), f, 1.0 / 24.0).unwrap())
                .collect::<Vec<_>>()
        };
        let mut whole = start.clone();
        let mut all = run(&mut whole, 0..frames);
        let mut part = start.clone();
        run(&mut part, 0..stop);
        let before = part.vertices();
        let mut part = reload(&part);
        // The vertices right after loading (they read the bones' last rotations).
        assert_eq!(bits3(&part.vertices()), bits3(&before), "{params:?}");
        let rest = run(&mut part, stop..frames);
        assert!(
            all.iter().any(|m| m.max_speed > 0.0),
            "{params:?}: the particles must move"
        );
        assert_eq!(
            bits3(part.positions()),
            bits3(whole.positions()),
            "{params:?}"
        );
        assert_eq!(
            bits3(&part.vertices()),
            bits3(&whole.vertices()),
            "{params:?}"
        );
        assert_eq!(bytes(&rest), bytes(&all.split_off(stop as usize)));
        assert_eq!(bytes(&part), bytes(&whole), "{params:?}: the states differ");
    }
}

/// A field built in three parts, written after the first and finished after loading (by
/// another builder), is the field built at once; and a field reloads to the same field.
#[test]
fn a_split_field_build_resumes_bit_for_bit() {
    let mut m = uv_sphere(0.4, 48, 24);
    m.append(&cuboid(Vec3::new(0.1, 0.5, 0.1), 2));
    for variant in [BoundaryVariant::Closest, BoundaryVariant::Centre] {
        let spec = GridSpec::fit(&m.bounds(), 28, 0.1).unwrap();
        let b = voxelize_cpu(&m, &spec, variant).unwrap();
        let whole = build_field_cpu(&b, 3.0).unwrap();
        // A builder with recycled buffers (stale values in them).
        let mut builder = FieldBuilder::default();
        builder.recycle(build_field_cpu(&b, 2.0).unwrap());
        builder.recycle(build_field_cpu(&b, 2.5).unwrap());
        let mut build = builder.start(&b, 3.0).unwrap();
        build.run_part(0, 3);
        let mut build = reload(&build);
        build.run_part(1, 3);
        build.run_part(2, 3);
        let f = build.finish(&mut FieldBuilder::default());
        assert_eq!(f.nearest, whole.nearest, "{variant:?}");
        assert_eq!(bits(&f.dist), bits(&whole.dist), "{variant:?}");
        assert_eq!(bits3(&f.points), bits3(&whole.points));
        assert_eq!(f.faces, whole.faces);
        assert_eq!(bytes(&f), bytes(&whole));

        // A whole field: the cells' cache is not written and comes back the same.
        let cells = bits4(whole.cells());
        let back = reload(&whole);
        assert_eq!(bits4(back.cells()), cells, "{variant:?}");
    }
}

/// Cloth parameters with every optional field set travel as RON text inside postcard and
/// come back equal, floats to the bit.
#[test]
fn cloth_params_survive_a_binary_checkpoint() {
    let mut p = ClothParams::new(
        Shape::Grid {
            size: [0.1 + 0.2, 1.0 / 3.0],
            resolution: [5, 7],
            center: Vec3::new(1e-30, -7.1e12, f32::MIN_POSITIVE / 4.0),
            normal: Vec3::Z,
        },
        Material::Harada {
            k_structural: 1.0e-7,
            k_shear: 3.4028235e38,
            k_bend: Some(0.1),
        },
    );
    p.wind = Some(Wind {
        velocity: Vec3::new(-0.0, 1.5, 2.0),
        drag: 0.3,
    });
    p.collision.ground = Some(-0.1);
    p.pins = vec![Pin::Region {
        min: Vec3::splat(-1.0),
        max: Vec3::splat(0.7),
    }];
    #[derive(serde::Serialize, serde::Deserialize)]
    struct Holder(#[serde(with = "super::ron_text")] ClothParams);
    // Every optional field left out (written as nothing in RON).
    let bare = ClothParams::new(
        p.shape.clone(),
        Material::Harada {
            k_structural: 1.0,
            k_shear: 0.5,
            k_bend: None,
        },
    );
    assert_eq!(reload(&Holder(bare.clone())).0, bare);
    let back = reload(&Holder(p.clone())).0;
    assert_eq!(back, p);
    let Shape::Grid { center, .. } = back.shape else {
        unreachable!()
    };
    assert_eq!(
        center.to_array().map(f32::to_bits),
        [1e-30f32, -7.1e12, f32::MIN_POSITIVE / 4.0].map(f32::to_bits)
    );
    assert_eq!(back.wind.unwrap().velocity.x.to_bits(), (-0.0f32).to_bits());
}
