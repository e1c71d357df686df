//! The GPU voxeliser and distance field against the CPU reference (same cells, same points,
//! same field), against an analytic plane, and at the device's limits. Every test skips, with
//! a note, on a machine without a GPU adapter; `IMPRINT_REQUIRE_GPU=1` makes that a failure.
//! Grids stay small (<= 48^3): CI runs these on a software rasteriser (Mesa lavapipe).

use glam::{UVec3, Vec3};
use imprint_core::geom::closest_point_on_triangle;
use imprint_core::mesh::primitives;
use imprint_core::{Boundary, BoundaryVariant, DistanceField, Error, GridSpec, Mesh};
use imprint_gpu::{GpuContext, GpuTimer, test_context};
use imprint_stages::sdf::build_field_cpu;
use imprint_stages::sdf::gpu::{build_field_gpu, build_field_gpu_timed};
use imprint_stages::voxel::gpu::{GpuBoundary, voxelize_gpu, voxelize_gpu_timed};
use imprint_stages::voxel::voxelize_cpu;

const VARIANTS: [BoundaryVariant; 2] = [BoundaryVariant::Centre, BoundaryVariant::Closest];
const BANDS: [f32; 3] = [1.0, 2.5, 3.0];

fn teapot() -> Mesh {
    Mesh::load_obj(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../assets/meshes/teapot.obj"
    )))
    .expect("teapot loads")
}

/// Same surface cells exactly; points within 1e-5 cells; the same owning faces, or where they
/// differ, faces equally near the cell centre (a tie between triangles that rounding decides).
fn assert_same_boundary(name: &str, cpu: &Boundary, gpu: &Boundary) {
    assert_eq!(cpu.spec, gpu.spec);
    assert_eq!(cpu.variant, gpu.variant);
    if cpu.cells != gpu.cells {
        let only_cpu: Vec<_> = cpu
            .cells
            .iter()
            .filter(|c| gpu.cells.binary_search(c).is_err())
            .collect();
        let only_gpu: Vec<_> = gpu
            .cells
            .iter()
            .filter(|c| cpu.cells.binary_search(c).is_err())
            .collect();
        panic!(
            "{name}: surface cells differ ({} CPU, {} GPU); only CPU: {:?}; only GPU: {:?}",
            cpu.len(),
            gpu.len(),
            &only_cpu[..only_cpu.len().min(10)],
            &only_gpu[..only_gpu.len().min(10)]
        );
    }
    let cell = cpu.spec.cell;
    let worst = cpu
        .points
        .iter()
        .zip(gpu.points.iter())
        .map(|(a, b)| (*a - *b).length() / cell)
        .fold(0.0f32, f32::max);
    assert!(
        worst <= 1e-5,
        "{name}: boundary points differ by {worst} cells"
    );
    assert_eq!(cpu.faces.len(), cpu.len(), "{name}: CPU faces");
    assert_eq!(gpu.faces.len(), gpu.len(), "{name}: GPU faces");
    let spec = cpu.spec;
    let mut swapped = 0;
    for (k, (fc, fg)) in cpu.faces.iter().zip(gpu.faces.iter()).enumerate() {
        if fc != fg {
            let x = spec.coords(cpu.cells[k] as usize).as_vec3();
            let d = |f: &[Vec3; 3]| {
                let [a, b, c] = f.map(|v| spec.to_cell(v));
                (closest_point_on_triangle(x, a, b, c) - x).length()
            };
            assert!(
                (d(fc) - d(fg)).abs() <= 1e-5,
                "{name}: point {k} owned by different faces"
            );
            swapped += 1;
        }
    }
    assert!(
        swapped * 100 <= cpu.len(),
        "{name}: {swapped} owning faces differ"
    );
}

/// Same band (except within 1e-4 cells of its edge), distances and vectors within 1e-4 cells.
fn assert_same_field(name: &str, cpu: &DistanceField, gpu: &DistanceField) {
    assert_eq!(cpu.spec, gpu.spec);
    assert_eq!(cpu.band, gpu.band);
    assert_eq!(cpu.points.len(), gpu.points.len(), "{name}: point counts");
    assert_eq!(
        cpu.faces.is_some(),
        gpu.faces.is_some(),
        "{name}: refinement"
    );
    let moved = cpu
        .points
        .iter()
        .zip(gpu.points.iter())
        .map(|(a, b)| (*a - *b).length() / cpu.spec.cell)
        .fold(0.0f32, f32::max);
    assert!(
        moved <= 1e-5,
        "{name}: fields built from points {moved} cells apart"
    );
    let h = cpu.spec.cell;
    let a = cpu.band;
    let (mut edge, mut in_band) = (0, 0);
    for i in 0..cpu.spec.len() {
        match (cpu.is_far(i), gpu.is_far(i)) {
            (true, true) => {
                assert_eq!(cpu.dist[i], gpu.dist[i], "{name}: far value of cell {i}");
            }
            (false, false) => {
                in_band += 1;
                let (dc, dg) = (cpu.dist[i] / h, gpu.dist[i] / h);
                assert!(
                    (dc - dg).abs() <= 1e-4,
                    "{name}: cell {i} distance {dg} vs CPU {dc} cells"
                );
                let dv = (cpu.vector(i) - gpu.vector(i)).length() / h;
                assert!(
                    dv <= 1e-4,
                    "{name}: cell {i} vector {} vs CPU {} (nearest {} vs {})",
                    gpu.vector(i) / h,
                    cpu.vector(i) / h,
                    gpu.nearest[i],
                    cpu.nearest[i]
                );
            }
            (cpu_far, _) => {
                // Only a cell on the band's edge may fall on either side of it.
                let d = if cpu_far { gpu.dist[i] } else { cpu.dist[i] } / h;
                assert!(
                    (d - a).abs() <= 1e-4,
                    "{name}: cell {i} at {d} cells is {} on the CPU but not on the GPU",
                    if cpu_far { "far" } else { "in the band" }
                );
                edge += 1;
            }
        }
    }
    assert!(in_band > 0, "{name}: empty band");
    assert!(
        edge * 1000 <= in_band,
        "{name}: {edge} edge cells disagree of {in_band}"
    );
}

/// Voxelises and builds fields on both paths for every variant and band, comparing them.
fn check_against_cpu(ctx: &GpuContext, name: &str, mesh: &Mesh, resolution: u32) {
    let spec = GridSpec::fit(&mesh.bounds(), resolution, 0.1).unwrap();
    for variant in VARIANTS {
        let cpu_b = voxelize_cpu(mesh, &spec, variant).unwrap();
        let gpu_b = voxelize_gpu(ctx, mesh, &spec, variant).unwrap();
        let tag = format!("{name} {variant:?}");
        assert_same_boundary(&tag, &cpu_b, &gpu_b.to_cpu(ctx).unwrap());
        for band in BANDS {
            let cpu_f = build_field_cpu(&cpu_b, band).unwrap();
            let gpu_f = build_field_gpu(ctx, &gpu_b, band)
                .unwrap()
                .to_cpu(ctx)
                .unwrap();
            assert_same_field(&format!("{tag} a={band}"), &cpu_f, &gpu_f);
        }
        // A CPU boundary uploaded gives the same field on the GPU.
        let up = GpuBoundary::from_cpu(ctx, &cpu_b).unwrap();
        assert_same_boundary(&format!("{tag} uploaded"), &cpu_b, &up.to_cpu(ctx).unwrap());
        let gpu_f = build_field_gpu(ctx, &up, 2.5).unwrap().to_cpu(ctx).unwrap();
        let cpu_f = build_field_cpu(&cpu_b, 2.5).unwrap();
        assert_same_field(&format!("{tag} uploaded a=2.5"), &cpu_f, &gpu_f);
    }
}

#[test]
fn sphere_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    check_against_cpu(ctx, "sphere", &primitives::uv_sphere(0.7, 48, 24), 40);
}

#[test]
fn torus_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    check_against_cpu(ctx, "torus", &primitives::torus(0.6, 0.25, 48, 24), 40);
}

#[test]
fn teapot_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    check_against_cpu(ctx, "teapot", &teapot(), 48);
}

/// A grid-aligned box: faces exactly on cell planes and edges on cell edges, where ties
/// between triangles and between points are exact.
#[test]
fn axis_aligned_box_matches_cpu() {
    let Some(ctx) = test_context() else { return };
    let mesh = primitives::cuboid(Vec3::new(0.5, 0.375, 0.25), 4);
    let spec = GridSpec::new(Vec3::splat(-0.75), 1.0 / 16.0, UVec3::splat(25)).unwrap();
    for variant in VARIANTS {
        let cpu_b = voxelize_cpu(&mesh, &spec, variant).unwrap();
        let gpu_b = voxelize_gpu(ctx, &mesh, &spec, variant).unwrap();
        assert_same_boundary(
            &format!("box {variant:?}"),
            &cpu_b,
            &gpu_b.to_cpu(ctx).unwrap(),
        );
        let cpu_f = build_field_cpu(&cpu_b, 2.5).unwrap();
        let gpu_f = build_field_gpu(ctx, &gpu_b, 2.5)
            .unwrap()
            .to_cpu(ctx)
            .unwrap();
        assert_same_field(&format!("box {variant:?}"), &cpu_f, &gpu_f);
    }
}

/// The plane z = z0 gives distance |z - z0| exactly (with closest points), without the CPU.
#[test]
fn plane_distance_is_exact() {
    let Some(ctx) = test_context() else { return };
    let z0 = 0.4321;
    let mut mesh = primitives::plane(4.0, 2);
    // plane() lies in x-z at y = 0: turn it to face +z and lift it to z0.
    mesh.transform(
        glam::Mat4::from_translation(Vec3::Z * z0)
            * glam::Mat4::from_rotation_x(std::f32::consts::FRAC_PI_2),
    );
    let spec = GridSpec::new(Vec3::ZERO, 1.0 / 24.0, UVec3::splat(24)).unwrap();
    let band = 3.0;
    let b = voxelize_gpu(ctx, &mesh, &spec, BoundaryVariant::Closest).unwrap();
    let f = build_field_gpu(ctx, &b, band).unwrap().to_cpu(ctx).unwrap();
    let mut checked = 0;
    for i in 0..spec.len() {
        let x = spec.center(spec.coords(i));
        let exact = (x.z - z0).abs() / spec.cell;
        if exact <= band - 1e-3 {
            assert!(!f.is_far(i), "cell {i} at {exact} cells left far");
            let got = f.dist[i] / spec.cell;
            assert!(
                (got - exact).abs() < 1e-4,
                "cell {i}: {got} vs exact {exact}"
            );
            let v = f.vector(i) / spec.cell;
            assert!(
                (v - Vec3::Z * (z0 - x.z) / spec.cell).length() < 1e-4,
                "cell {i}: vector {v}"
            );
            checked += 1;
        } else if exact > band + 1e-3 {
            assert!(f.is_far(i), "cell {i} at {exact} cells is in the band");
            assert_eq!(f.dist[i], f.far_value());
            assert_eq!(f.vector(i), Vec3::ZERO);
        }
    }
    assert_eq!(checked, 6 * 24 * 24);
}

/// Two runs give the same bytes (atomics in any order make the same minima).
#[test]
fn results_are_deterministic() {
    let Some(ctx) = test_context() else { return };
    let mesh = teapot();
    let spec = GridSpec::fit(&mesh.bounds(), 32, 0.1).unwrap();
    let run = || {
        let b = voxelize_gpu(ctx, &mesh, &spec, BoundaryVariant::Closest).unwrap();
        let f = build_field_gpu(ctx, &b, 2.5).unwrap();
        (
            ctx.read_buffer::<u32>(&b.points).unwrap(),
            ctx.read_buffer::<u32>(&f.field).unwrap(),
            ctx.read_buffer::<u32>(&f.nearest_cell).unwrap(),
        )
    };
    assert!(run() == run());
}

/// A mesh entirely outside the grid: no surface cells, every cell far.
#[test]
fn mesh_outside_the_grid_gives_an_all_far_field() {
    let Some(ctx) = test_context() else { return };
    let mut mesh = primitives::uv_sphere(0.5, 16, 8);
    mesh.transform(glam::Mat4::from_translation(Vec3::splat(10.0)));
    let spec = GridSpec::new(Vec3::ZERO, 0.1, UVec3::splat(8)).unwrap();
    let b = voxelize_gpu(ctx, &mesh, &spec, BoundaryVariant::Closest).unwrap();
    assert!(b.to_cpu(ctx).unwrap().is_empty());
    let f = build_field_gpu(ctx, &b, 2.0).unwrap().to_cpu(ctx).unwrap();
    assert_eq!(f.band_cells(), 0);
    assert!(f.dist.iter().all(|&d| d == f.far_value()));
}

#[test]
fn bad_band_is_invalid() {
    let Some(ctx) = test_context() else { return };
    let mesh = primitives::uv_sphere(0.5, 16, 8);
    let spec = GridSpec::fit(&mesh.bounds(), 8, 0.1).unwrap();
    let b = voxelize_gpu(ctx, &mesh, &spec, BoundaryVariant::Closest).unwrap();
    for band in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        let e = build_field_gpu(ctx, &b, band).unwrap_err();
        assert!(matches!(e, Error::Invalid(_)), "band {band}: {e}");
    }
}

/// Grids whose buffers the device cannot bind are refused with a typed error before anything
/// is allocated, by both stages; nothing panics.
#[test]
fn grid_beyond_device_limits_is_an_error() {
    let Some(ctx) = test_context() else { return };
    let mesh = primitives::uv_sphere(0.5, 16, 8);
    // Just over the largest binding (16 bytes per cell), and far over the 32-bit cell index.
    let cells = ctx.max_storage_bytes() / 16 + 1;
    let z = cells.div_ceil(4096 * 4096).max(1) as u32;
    for dims in [UVec3::new(4096, 4096, z), UVec3::splat(4096)] {
        let spec = GridSpec::new(Vec3::ZERO, 0.01, dims).unwrap();
        for e in [
            voxelize_gpu(ctx, &mesh, &spec, BoundaryVariant::Closest).unwrap_err(),
            build_field_gpu(
                ctx,
                &GpuBoundary {
                    spec,
                    variant: BoundaryVariant::Closest,
                    points: ctx.zeroed_buffer("tiny", 16).unwrap(),
                    owner: ctx.zeroed_buffer("tiny", 16).unwrap(),
                    faces: ctx.zeroed_buffer("tiny", 48).unwrap(),
                    faces_world: Default::default(),
                    inside: None,
                },
                2.0,
            )
            .unwrap_err(),
        ] {
            assert!(matches!(e, Error::TooLarge { .. }), "{dims}: {e}");
            let msg = e.to_string();
            assert!(
                msg.contains(&format!("{}x{}x{}", dims.x, dims.y, dims.z)),
                "{msg}"
            );
        }
    }
}

/// Not a check: prints GPU timings of a 64^3 sphere (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn report_timings_sphere_64() {
    let Some(ctx) = test_context() else { return };
    let mesh = primitives::uv_sphere(0.7, 96, 48);
    let spec = GridSpec::fit(&mesh.bounds(), 64, 0.1).unwrap();
    println!(
        "adapter: {} (software: {})",
        ctx.adapter_name(),
        ctx.is_software()
    );
    for variant in VARIANTS {
        for round in 0..3 {
            let mut timer = GpuTimer::new(ctx);
            let b = voxelize_gpu_timed(
                ctx,
                &mesh,
                &spec,
                variant,
                mesh.is_closed(),
                Some(&mut timer),
            )
            .unwrap();
            let tv = timer.wait(ctx).unwrap();
            let f = build_field_gpu_timed(ctx, &b, 3.0, Some(&mut timer)).unwrap();
            let tf = timer.wait(ctx).unwrap();
            let t0 = std::time::Instant::now();
            let cpu_b = voxelize_cpu(&mesh, &spec, variant).unwrap();
            let cv = t0.elapsed();
            let t0 = std::time::Instant::now();
            let cpu_f = build_field_cpu(&cpu_b, 3.0).unwrap();
            let cf = t0.elapsed();
            println!(
                "{variant:?} round {round}: voxelize GPU {:?} (wall {:?}) {:?}; field GPU {:?} (wall {:?}) {:?}; \
                 CPU voxelize {cv:?} field {cf:?}; {} points, {} band cells",
                tv.gpu(),
                tv.wall,
                tv.passes,
                tf.gpu(),
                tf.wall,
                tf.passes,
                cpu_b.len(),
                cpu_f.band_cells()
            );
            let _ = f;
        }
    }
}
