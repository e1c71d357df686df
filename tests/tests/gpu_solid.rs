//! The signed field's inside cells: the GPU's solid voxelisation gives the CPU's bits, and a
//! GPU field read back carries them; the CPU's agree with the exact inside test.

use glam::Vec3;
use imprint_core::mesh::primitives;
use imprint_core::{BoundaryVariant, GridSpec, Mesh};
use imprint_stages::drape::inside::InsideTest;
use imprint_stages::sdf::build_field_cpu;
use imprint_stages::sdf::gpu::build_field_gpu;
use imprint_stages::voxel::gpu::voxelize_gpu;
use imprint_stages::voxel::voxelize_cpu;

fn meshes() -> Vec<(&'static str, Mesh)> {
    let mut cow = imprint_tests::mesh("cow");
    cow.transform(cow.fit_transform(0.5, Vec3::ZERO));
    vec![
        ("cow", cow),
        ("torus", primitives::torus(0.3, 0.08, 40, 16)),
        ("sphere", primitives::uv_sphere(0.3, 24, 12)),
    ]
}

#[test]
fn gpu_inside_bits_are_the_cpus() {
    let Some(ctx) = imprint_gpu::test_context() else {
        return;
    };
    for (name, mesh) in meshes() {
        let spec = GridSpec::fit(&mesh.bounds(), 40, 0.1).unwrap();
        let cpu = voxelize_cpu(&mesh, &spec, BoundaryVariant::Closest).unwrap();
        let gpu = voxelize_gpu(ctx, &mesh, &spec, BoundaryVariant::Closest).unwrap();
        let back = gpu.to_cpu(ctx).unwrap();
        let words = cpu.inside.as_ref().expect("a closed mesh is signed");
        assert!(words.iter().any(|&w| w != 0), "{name}: nothing inside");
        assert_eq!(back.inside.as_ref(), Some(words), "{name}");
        // The GPU field carries them to the CPU field it reads back as.
        let field = build_field_gpu(ctx, &gpu, 3.0)
            .unwrap()
            .to_cpu(ctx)
            .unwrap();
        assert_eq!(field.inside.as_ref(), Some(words), "{name}");
    }
    // An open mesh: no inside on either path.
    let open = primitives::plane(1.0, 4);
    let spec = GridSpec::fit(&open.bounds(), 16, 0.2).unwrap();
    assert!(
        voxelize_cpu(&open, &spec, BoundaryVariant::Closest)
            .unwrap()
            .inside
            .is_none()
    );
    let g = voxelize_gpu(ctx, &open, &spec, BoundaryVariant::Closest).unwrap();
    assert!(g.to_cpu(ctx).unwrap().inside.is_none());
}

/// The blend of the cells' signed distances tells inside from outside wherever the surface is
/// more than a cell away (within a cell, the surface's curvature over a cell may tip it).
#[test]
fn the_field_side_is_the_exact_inside_test_beyond_a_cell() {
    for (name, mesh) in meshes() {
        let spec = GridSpec::fit(&mesh.bounds(), 48, 0.1).unwrap();
        let b = voxelize_cpu(&mesh, &spec, BoundaryVariant::Closest).unwrap();
        let field = build_field_cpu(&b, 3.0).unwrap();
        let test = InsideTest::new(&mesh);
        let (lo, hi) = (spec.origin, spec.origin + spec.dims.as_vec3() * spec.cell);
        let mut checked = 0;
        for i in 0..20_000u64 {
            let h = |k: u64| {
                let v = (i * 3 + k + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                (v >> 40) as f32 / (1u64 << 24) as f32
            };
            let p = lo + (hi - lo) * Vec3::new(h(0), h(1), h(2));
            let sd = field.side(p).unwrap();
            // Only where the field knows the surface is more than a cell away.
            let s = field.sample(p, imprint_core::Sampling::Vector);
            if s.in_band && s.distance < spec.cell {
                continue;
            }
            checked += 1;
            assert_eq!(sd < 0.0, test.inside(p), "{name} at {p}: side {sd}");
        }
        assert!(checked > 10_000, "{name}: {checked}");
    }
}

/// Blending two signed fields blends the signed distances: a cell the surface passed between
/// the builds is inside where the blend is, and its distance is the blend's size.
#[test]
fn blended_signed_fields_follow_the_surface() {
    let spec = GridSpec::new(Vec3::splat(-0.5), 0.05, glam::UVec3::splat(21)).unwrap();
    let field = |r: f32| {
        let m = primitives::uv_sphere(r, 48, 24);
        build_field_cpu(
            &voxelize_cpu(&m, &spec, BoundaryVariant::Closest).unwrap(),
            3.0,
        )
        .unwrap()
    };
    let (a, b) = (field(0.2), field(0.3));
    let mid = imprint_core::DistanceField::blend(&a, &b, 0.5).unwrap();
    assert!(mid.inside.is_some());
    for i in 0..spec.len() {
        let r = spec.center(spec.coords(i)).length();
        let want = a.signed_distance(i) + (b.signed_distance(i) - a.signed_distance(i)) * 0.5;
        assert_eq!(mid.signed_distance(i), want, "cell {i}");
        // Between the radii, the blend puts the surface near 0.25.
        if (r - 0.25).abs() > 0.02 && r > 0.15 && r < 0.35 {
            assert_eq!(mid.is_inside(i), Some(r < 0.25), "cell {i} at radius {r}");
        }
    }
}
