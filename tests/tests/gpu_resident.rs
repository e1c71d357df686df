//! Resources that stay on the device: a GPU distance field made into a cloth collider on the
//! GPU (`GpuCollider::from_gpu_field`), the GPU cloth's residual contacts measured on the GPU
//! (`ClothSim::adopt_gpu_frame_resident`), and depth maps consumed where they were rendered
//! (`GpuRasterizer::depth_map_resident`, `GpuGround::step_resident`,
//! `GpuSnowArrival::arrival_resident`). Each is held to the path that reads back and uploads
//! again: the same bits, and the traffic counted by `imprint_gpu::transfer`. Every test skips,
//! with a note, without a GPU adapter (`IMPRINT_REQUIRE_GPU=1` makes that a failure).

use glam::Vec3;
use imprint_core::mesh::primitives::uv_sphere;
use imprint_core::{BoundaryVariant, GridSpec, Mesh};
use imprint_gpu::test_context;
use imprint_gpu::transfer::{self, Transfers};
use imprint_stages::cloth::ClothParams;
use imprint_stages::cloth::gpu::{GpuCloth, GpuCollider};
use imprint_stages::sdf::gpu::{GpuField, build_field_gpu};
use imprint_stages::voxel::gpu::voxelize_gpu;
use imprint_tests::cloth::{grid, harada, sim};

const FPS: f32 = 60.0;

fn bits(v: &[[f32; 4]]) -> Vec<[u32; 4]> {
    v.iter().map(|c| c.map(f32::to_bits)).collect()
}

/// A field of `mesh` built on the GPU: a `res`-cell grid fitted around it, band 4.
fn gpu_field(
    ctx: &imprint_gpu::GpuContext,
    mesh: &Mesh,
    res: u32,
    padding: f32,
    variant: BoundaryVariant,
) -> GpuField {
    let spec = GridSpec::fit(&mesh.bounds(), res, padding).unwrap();
    let b = voxelize_gpu(ctx, mesh, &spec, variant).unwrap();
    build_field_gpu(ctx, &b, 4.0).unwrap()
}

#[test]
fn collider_from_a_gpu_field_is_the_read_back_one_bit_for_bit() {
    let Some(ctx) = test_context() else { return };
    let teapot = imprint_tests::mesh("teapot");
    let sphere = uv_sphere(0.3, 32, 16);
    for (name, mesh) in [("teapot", &teapot), ("sphere", &sphere)] {
        for variant in [BoundaryVariant::Centre, BoundaryVariant::Closest] {
            let f = gpu_field(ctx, mesh, 32, 0.1, variant);
            let t0 = transfer::snapshot();
            let resident = GpuCollider::from_gpu_field(ctx, &f).unwrap();
            let d = transfer::snapshot().since(&t0);
            assert_eq!((d.read_back_bytes, d.field_read_backs), (0, 0), "{d:?}");
            let cpu = f.to_cpu(ctx).unwrap();
            let uploaded = GpuCollider::from_field(ctx, &cpu).unwrap();
            assert_eq!(transfer::snapshot().since(&t0).field_read_backs, 1);
            let a: Vec<[f32; 4]> = ctx.read_buffer(&resident.cells).unwrap();
            let b: Vec<[f32; 4]> = ctx.read_buffer(&uploaded.cells).unwrap();
            assert_eq!(a.len(), b.len());
            let differ = bits(&a)
                .iter()
                .zip(&bits(&b))
                .filter(|(x, y)| x != y)
                .count();
            let near = cpu.band_cells();
            eprintln!(
                "{name} {variant:?}: {} cells ({near} in the band), {differ} differ; \
                 uploaded {} B for the resident collider",
                a.len(),
                d.uploaded_bytes
            );
            assert_eq!(differ, 0, "{name} {variant:?}");
            assert!(near > 100, "{name} {variant:?}: the band is empty");
            assert_eq!(
                (resident.spec, resident.band),
                (uploaded.spec, uploaded.band)
            );
        }
    }
}

/// A 16 x 16 cloth dropped from 0.15 above a sphere of radius 0.3, 16 substeps per frame.
fn drop_params() -> ClothParams {
    let mut p = ClothParams::new(
        grid([1.0, 1.0], [16, 16], Vec3::new(0.0, 0.45, 0.0), Vec3::Y),
        harada(60.0, 15.0),
    );
    p.substeps = 16;
    p.damping = 0.995;
    p.collision.epsilon = 0.01;
    p.collision.friction = 0.5;
    p
}

/// The GPU's residual contacts against the same state that `adopt_gpu_frame` measures on the
/// CPU against the read-back field: every other metric is the same to the bit, and `close` /
/// `close_max_depth` agree within what the CPU-vs-GPU test allows (their difference is
/// printed).
#[test]
fn resident_cloth_metrics_are_the_cpu_measured_ones() {
    let Some(ctx) = test_context() else { return };
    let p = drop_params();
    let sphere = uv_sphere(0.3, 48, 24);
    let f = gpu_field(ctx, &sphere, 40, 0.3, BoundaryVariant::Closest);
    let collider = GpuCollider::from_gpu_field(ctx, &f).unwrap();
    let field = f.to_cpu(ctx).unwrap();
    let mut gpu = GpuCloth::new(ctx, &sim(&p)).unwrap();
    let (mut on_cpu, mut resident) = (sim(&p), sim(&p));
    let (mut worst_close, mut worst_depth, mut touched) = (0u32, 0.0f32, 0u32);
    for frame in 0..30 {
        let gm = gpu
            .step_frame(ctx, &[&collider], &[&collider], frame, 1.0 / FPS)
            .unwrap();
        let (state, side) = (gpu.read_state(ctx).unwrap(), gpu.read_side(ctx).unwrap());
        let a = on_cpu
            .adopt_gpu_frame(state.clone(), side.clone(), &[&field], &gm)
            .unwrap();
        let b = resident.adopt_gpu_frame_resident(state, side, &gm).unwrap();
        let dc = a.close.abs_diff(b.close);
        let dd = (a.close_max_depth - b.close_max_depth).abs();
        if a.close != b.close || a.close_max_depth != b.close_max_depth {
            eprintln!(
                "frame {frame}: close CPU {} GPU {}, close_max_depth CPU {:e} GPU {:e}",
                a.close, b.close, a.close_max_depth, b.close_max_depth
            );
        }
        assert!(dc <= 2 + a.contacts / 8, "frame {frame}: {a:?} vs {b:?}");
        assert!(
            dd <= 1e-3 * p.collision.epsilon,
            "frame {frame}: {a:?} vs {b:?}"
        );
        worst_close = worst_close.max(dc);
        worst_depth = worst_depth.max(dd);
        touched += (a.close > 0) as u32;
        let same = imprint_stages::cloth::ClothFrameMetrics {
            close: a.close,
            close_max_depth: a.close_max_depth,
            ..b
        };
        assert_eq!(a, same, "frame {frame}");
    }
    eprintln!(
        "30 frames: residual contacts differ by at most {worst_close} particles and \
         {worst_depth:e} m; {touched} frames with contacts"
    );
    assert!(
        touched >= 5,
        "the cloth reached the sphere in {touched} frames"
    );
    assert_eq!(on_cpu.positions(), resident.positions());
}

/// A GPU field made into a collider on the device and a GPU cloth stepped against it: no
/// field is read back, and each frame reads back exactly the cloth's own output: its
/// per-particle flags (36 bytes a particle, the frame's metrics), its state (current and
/// previous positions) and its contacts' side memory (16 bytes a particle and collider).
#[test]
fn resident_cloth_reads_back_only_its_own_state() {
    let Some(ctx) = test_context() else { return };
    let p = drop_params();
    let sphere = uv_sphere(0.3, 48, 24);
    let frames = 6;
    let f = gpu_field(ctx, &sphere, 32, 0.3, BoundaryVariant::Closest);
    let cloth = sim(&p);
    let n = cloth.len() as u64;
    let mut gpu = GpuCloth::new(ctx, &cloth).unwrap();
    let mut mirror = sim(&p);

    let t0 = transfer::snapshot();
    let collider = GpuCollider::from_gpu_field(ctx, &f).unwrap();
    let mut per_frame = Vec::new();
    for frame in 0..frames {
        let t = transfer::snapshot();
        let gm = gpu
            .step_frame(ctx, &[&collider], &[&collider], frame, 1.0 / FPS)
            .unwrap();
        mirror
            .adopt_gpu_frame_resident(
                gpu.read_state(ctx).unwrap(),
                gpu.read_side(ctx).unwrap(),
                &gm,
            )
            .unwrap();
        per_frame.push(transfer::snapshot().since(&t));
    }
    let total = transfer::snapshot().since(&t0);
    let frame_bytes = n * 36 + 2 * n * 16 + n * 16;
    eprintln!("resident: {total:?}; per frame {:?}", per_frame[1]);
    assert_eq!(total.field_read_backs, 0);
    assert_eq!(total.read_back_bytes, frames as u64 * frame_bytes);
    for t in &per_frame {
        assert_eq!(t.read_back_bytes, frame_bytes);
    }

    // The same frames through the CPU, as the executor does today: one field read-back and
    // a collider uploaded again.
    let mut gpu2 = GpuCloth::new(ctx, &cloth).unwrap();
    let t1 = transfer::snapshot();
    let field = f.to_cpu(ctx).unwrap();
    let collider2 = GpuCollider::from_field(ctx, &field).unwrap();
    for frame in 0..frames {
        gpu2.step_frame(ctx, &[&collider2], &[&collider2], frame, 1.0 / FPS)
            .unwrap();
        gpu2.read_state(ctx).unwrap();
        gpu2.read_side(ctx).unwrap();
    }
    let old: Transfers = transfer::snapshot().since(&t1);
    eprintln!("through the CPU: {old:?}");
    assert_eq!(old.field_read_backs, 1);
    assert!(old.read_back_bytes > total.read_back_bytes + f.spec.len() as u64 * 16);
    assert!(old.uploaded_bytes >= f.spec.len() as u64 * 16);
    assert_eq!(
        gpu.read_positions(ctx).unwrap(),
        gpu2.read_positions(ctx).unwrap()
    );
}

/// The contact shader's integer versions of the ground's two f64 steps (metres to height
/// units, and the carry α · removed), against Rust's f64 on values chosen to sit on and
/// around every rounding boundary: f32 heights within a few ulps of (k + ½) units for many k
/// and units (some units powers of two, where exact ties occur), random heights, and the
/// edges (zeros, negatives, NaN, subnormals, beyond the clamp).
#[test]
fn the_contact_shaders_integer_roundings_are_f64s() {
    let Some(ctx) = test_context() else { return };
    use imprint_stages::ground::gpu::{carry_on_gpu, units_on_gpu};
    let mut rng = 0x1234_5678_9abc_def0u64;
    let mut next = move || {
        rng = rng
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        rng >> 11
    };
    let units_cpu = |m: f32, unit: f64| -> i32 {
        ((m as f64 / unit).round() as i64).clamp(0, i32::MAX as i64 - 1) as i32
    };
    let mut checked = 0;
    for unit in [
        1e-5,
        1e-4,
        2.5e-6,
        2f64.powi(-17),
        1e-3 / 3.0,
        0.01,
        7.3e-6,
        1.0,
    ] {
        let mut m: Vec<f32> = vec![
            0.0,
            -0.0,
            -1.0,
            f32::NAN,
            f32::MIN_POSITIVE,
            1e-45,
            1e30,
            3e38,
            (unit * 0.25) as f32,
            (unit * 0.5) as f32,
            (unit * 2147483646.5) as f32,
            (unit * 2147483647.0) as f32,
            (unit * 4294967296.0) as f32,
        ];
        let mut ks: Vec<f64> = (0..40).map(|k| k as f64).collect();
        ks.extend((0..400).map(|_| (next() % 3_000_000) as f64));
        ks.extend((0..100).map(|_| (next() % 2_147_483_647) as f64));
        for k in ks {
            let centre = ((k + 0.5) * unit) as f32;
            let mut x = centre;
            for _ in 0..3 {
                x = f32::from_bits(x.to_bits().saturating_sub(1));
            }
            for _ in 0..7 {
                m.push(x);
                x = f32::from_bits(x.to_bits() + 1);
            }
        }
        m.extend((0..2000).map(|_| (next() as f64 / (1u64 << 53) as f64 * 20.0) as f32));
        let gpu = units_on_gpu(ctx, unit, &m).unwrap();
        let wrong: Vec<_> = m
            .iter()
            .zip(&gpu)
            .filter(|(x, g)| units_cpu(**x, unit) != **g)
            .map(|(x, g)| (*x, units_cpu(*x, unit), *g))
            .take(10)
            .collect();
        assert!(wrong.is_empty(), "unit {unit}: (m, CPU, GPU) {wrong:?}");
        checked += m.len();
    }
    for alpha in [1.0f32, 0.6, 0.3, 1.0 / 3.0, 0.999_999_94, 1e-30, 0.0] {
        let mut r: Vec<u32> = (1..200).collect();
        r.extend([i32::MAX as u32, i32::MAX as u32 - 1, 1 << 30, (1 << 30) + 1]);
        r.extend((0..3000).map(|_| (next() % i32::MAX as u64) as u32 + 1));
        let gpu = carry_on_gpu(ctx, alpha, &r).unwrap();
        for (&removed, &g) in r.iter().zip(&gpu) {
            let want = (alpha as f64 * removed as i64 as f64).round() as u64;
            assert_eq!(g, want, "alpha {alpha}, removed {removed}");
        }
        checked += r.len();
    }
    eprintln!("{checked} conversions equal");
}

/// Steps one GPU ground with `raster.depth_map` (read back, bottoms and carries uploaded) and
/// one with `step_resident` through `scene`: the same metrics and heights after every frame,
/// bit for bit. The resident path's read-back is the old one's without the depth maps, plus
/// the 32-byte contact box on each frame an object was rasterised; no map is uploaded either.
fn ground_both_ways(
    ctx: &imprint_gpu::GpuContext,
    p: &imprint_stages::ground::GroundParams,
    frames: u32,
    scene: impl Fn(u32) -> Vec<Mesh>,
) -> (Transfers, Transfers) {
    use imprint_gpu::raster::GpuRasterizer;
    use imprint_stages::ground::gpu::GpuGround;
    let cpu = imprint_tests::ground::sim(p);
    let mut old = GpuGround::from_sim(ctx, &cpu).unwrap();
    let mut new = GpuGround::from_sim(ctx, &cpu).unwrap();
    let (mut r_old, mut r_new) = (
        GpuRasterizer::new(ctx).unwrap(),
        GpuRasterizer::new(ctx).unwrap(),
    );
    let (mut t_old, mut t_new) = (Transfers::default(), Transfers::default());
    let mut contact_frames = 0;
    for f in 0..frames {
        let meshes = scene(f);
        let refs: Vec<&Mesh> = meshes.iter().collect();
        let (mut map_bytes, mut maps) = (0u64, 0u32);
        let t = transfer::snapshot();
        let mo = old
            .step_with(ctx, &refs, |m, c, w, h, o| {
                map_bytes += (w as u64 * 8).next_multiple_of(256) * h as u64;
                maps += 1;
                r_old.depth_map(ctx, m, c, w, h, o)
            })
            .unwrap();
        let d_old = transfer::snapshot().since(&t);
        let t = transfer::snapshot();
        let mn = new.step_resident(ctx, &mut r_new, &refs).unwrap();
        let d_new = transfer::snapshot().since(&t);
        assert_eq!(mn, mo, "frame {f}: metrics");
        assert_eq!(
            new.heights_units(),
            old.heights_units(),
            "frame {f}: heights"
        );
        let boxed = if maps > 0 { 32 } else { 0 };
        assert_eq!(
            d_new.read_back_bytes,
            d_old.read_back_bytes - map_bytes + boxed,
            "frame {f}: read-backs {d_new:?} vs {d_old:?} with {maps} maps of {map_bytes} B"
        );
        assert!(d_new.uploaded_bytes < d_old.uploaded_bytes, "frame {f}");
        // O's slump runs on the GPU; `Settle` reads the heights and the contact mask back and
        // settles on the CPU, so the shape below is the slump's.
        let labelled = p.relaxation == imprint_stages::ground::Relaxation::Labelled;
        if mo.contact_cells > 0 {
            contact_frames += 1;
        }
        if labelled && mo.contact_cells > 0 {
            // Beyond the output heights, only the box and the frame's stats words (read
            // after the contours, between slump batches and at the end) come back.
            let heights = 4 * p.resolution[0] as u64 * p.resolution[1] as u64;
            let stats = 4 * (8 + 2 * p.material.values().slump_iterations as u64);
            let rest = d_new.read_back_bytes - heights - 32;
            assert!(
                rest.is_multiple_of(stats) && rest / stats >= 2,
                "frame {f}: {d_new:?}"
            );
        }
        for (acc, d) in [(&mut t_old, d_old), (&mut t_new, d_new)] {
            acc.uploaded_bytes += d.uploaded_bytes;
            acc.read_back_bytes += d.read_back_bytes;
            acc.field_read_backs += d.field_read_backs;
        }
    }
    assert!(contact_frames > 0);
    (t_old, t_new)
}

#[test]
fn resident_ground_is_the_read_back_ground_bit_for_bit() {
    let Some(ctx) = test_context() else { return };
    use imprint_stages::ground::{Material, Preset, Relaxation};
    use imprint_tests::ground::{cuboid_at, params, sphere};
    const H0: f32 = 0.1;
    let rolling = |f: u32| {
        let x = if f < 10 {
            -0.15 + 0.015 * f as f32
        } else {
            -0.15 + 0.015 * (19 - f) as f32 + 0.004
        };
        vec![sphere(
            0.08,
            Vec3::new(x, H0 + 0.08 - 0.025, 0.01 * (f % 3) as f32),
        )]
    };
    let custom = Material::Custom {
        repose_degrees: 40.0,
        slump_iterations: 8,
        displace_ratio: 0.6,
    };
    let settles = Material::Custom {
        repose_degrees: 35.0,
        slump_iterations: 200,
        displace_ratio: 1.0,
    };
    for (name, material, frames) in [
        ("sand", Material::Preset(Preset::Sand), 12),
        ("custom alpha 0.6", custom, 8),
        ("custom 200 passes", settles, 3),
    ] {
        for relaxation in [Relaxation::Labelled, Relaxation::Settle] {
            let mut p = params(64, 0.01, H0, material);
            p.relaxation = relaxation;
            let (o, n) = ground_both_ways(ctx, &p, frames, rolling);
            eprintln!(
                "{name}, {relaxation:?}: {frames} frames equal; read back {o:?}, resident {n:?}"
            );
        }
    }
    // Two objects, one of them above the ground for the first frames (not rasterised), and
    // a box pressed into snow.
    let p = params(96, 0.005, H0, Material::Preset(Preset::Snow));
    let two = |f: u32| {
        let half = Vec3::new(0.05, 0.05, 0.03);
        let y = H0 + 0.05 - 0.005 * (f + 1) as f32;
        vec![
            cuboid_at(half, Vec3::new(0.0025 + 0.005 * (f / 2) as f32, y, 0.0025)),
            sphere(0.04, Vec3::new(-0.12, H0 + 0.06 - 0.01 * f as f32, -0.1)),
        ]
    };
    let (o, n) = ground_both_ways(ctx, &p, 6, two);
    eprintln!("box and sphere in snow: 6 frames equal; read back {o:?}, resident {n:?}");
}

/// A ball above a bumpy 48 x 48 ground of 2 cm cells (the scene of the GPU snow tests).
fn ball_over_ground() -> (Mesh, imprint_core::HeightField) {
    use glam::{UVec2, Vec2};
    let mut ball = uv_sphere(0.15, 24, 12);
    ball.transform(glam::Mat4::from_translation(Vec3::new(-0.1, 0.45, -0.1)));
    let (n, cell) = (48u32, 0.02f32);
    let ground =
        imprint_core::HeightField::from_fn(Vec2::splat(-0.5), cell, UVec2::splat(n), |i, k| {
            let (x, z) = (i as f32 * cell, k as f32 * cell);
            let bumps = 0.02 * ((7.0 * x).sin() * (5.0 * z).cos() + 1.0);
            bumps + 0.3 * (-(x - 0.1 * z - 0.4).powi(2) / 0.002).exp()
        })
        .unwrap();
    (ball, ground)
}

/// The arrival counts from depth maps read where they were rendered are those from the maps
/// read back and uploaded, receiver by receiver, and only the counts come back: no map is
/// read back or uploaded.
#[test]
fn resident_snow_arrival_counts_as_the_read_back_one() {
    let Some(ctx) = test_context() else { return };
    use imprint_gpu::raster::GpuRasterizer;
    use imprint_stages::snow::arrival::gather;
    use imprint_stages::snow::gpu::GpuSnowArrival;
    use imprint_stages::snow::{SnowParams, SnowSim};
    let (ball, ground) = ball_over_ground();
    let p = SnowParams {
        directions: 16,
        jitter_degrees: 20.0,
        resolution: 100,
        ..Default::default()
    };
    let sim = SnowSim::new(&p).unwrap();
    let (occluder, receivers) = gather(&[&ball], Some(&ground));
    let mut raster = GpuRasterizer::new(ctx).unwrap();
    let mut look_ups = GpuSnowArrival::new();
    let t = transfer::snapshot();
    let old = look_ups
        .arrival_with(
            ctx,
            &occluder,
            &receivers,
            sim.directions(),
            &p,
            |m, c, w, h, o| raster.depth_map(ctx, m, c, w, h, o),
        )
        .unwrap();
    let d_old = transfer::snapshot().since(&t);
    let t = transfer::snapshot();
    let new = look_ups
        .arrival_resident(
            ctx,
            &mut raster,
            &occluder,
            &receivers,
            sim.directions(),
            &p,
        )
        .unwrap();
    let d_new = transfer::snapshot().since(&t);
    assert_eq!(new, old);
    let n = receivers.points.len() as u64;
    let res = p.resolution as u64;
    let k = sim.directions().len() as u64;
    let map_back = (res * 8).next_multiple_of(256) * res;
    eprintln!(
        "{n} receivers, {k} directions: read back {d_old:?}, resident {d_new:?}; \
         {} reached",
        new.counts.iter().filter(|&&c| c > 0).count()
    );
    assert_eq!(d_new.read_back_bytes, 4 * n);
    assert_eq!(d_old.read_back_bytes, 4 * n + k * map_back);
    assert!(d_old.uploaded_bytes >= d_new.uploaded_bytes + k * res * res * 4);
}

/// A snow step with the resident arrival leaves the same snow, to the bit, as one with the
/// read-back arrival.
#[test]
fn resident_snow_step_is_the_read_back_step() {
    let Some(ctx) = test_context() else { return };
    use imprint_gpu::raster::GpuRasterizer;
    use imprint_stages::snow::gpu::{GpuSnowArrival, GpuSnowRelax};
    use imprint_stages::snow::{SnowParams, SnowSim};
    let (ball, ground) = ball_over_ground();
    let p = SnowParams {
        directions: 8,
        jitter_degrees: 15.0,
        resolution: 96,
        rate: 0.05,
        relax_passes: 16,
        ..Default::default()
    };
    let mut a = SnowSim::new(&p).unwrap();
    let mut b = a.clone();
    let mut raster = GpuRasterizer::new(ctx).unwrap();
    let (mut look_ups, mut relax) = (GpuSnowArrival::new(), GpuSnowRelax::new());
    for _ in 0..3 {
        a.step_with_parts(
            &[&ball],
            Some(&ground),
            0.25,
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
            relax.relaxer(ctx),
        )
        .unwrap();
        let mut look_ups2 = GpuSnowArrival::new();
        b.step_with_parts(
            &[&ball],
            Some(&ground),
            0.25,
            look_ups2.resident(ctx, &mut raster),
            relax.relaxer(ctx),
        )
        .unwrap();
        let (ga, gb) = (a.ground().unwrap(), b.ground().unwrap());
        assert_eq!(ga.units, gb.units);
        assert!(
            ga.residual
                .iter()
                .zip(&gb.residual)
                .all(|(x, y)| x.to_bits() == y.to_bits())
        );
        let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(a.mesh_depth(0)), bits(b.mesh_depth(0)));
    }
    assert!(a.ground().unwrap().volume() > 0.0);
}
