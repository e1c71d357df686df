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
use imprint_stages::cloth::gpu::{GpuCloth, GpuCollider};
use imprint_stages::cloth::ClothParams;
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
            assert_eq!((resident.spec, resident.band), (uploaded.spec, uploaded.band));
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
    assert!(touched >= 5, "the cloth reached the sphere in {touched} frames");
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
            .adopt_gpu_frame_resident(gpu.read_state(ctx).unwrap(), gpu.read_side(ctx).unwrap(), &gm)
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
