//! The CPU voxeliser and distance field against exact answers: analytic planes and spheres,
//! the exact closest point on the triangles, and the cases real meshes bring (open, flipped,
//! duplicated, unwelded, degenerate, on grid planes, bigger than the grid, empty).

use glam::{UVec3, Vec3};
use imprint_core::mesh::primitives;
use imprint_core::{Aabb, BoundaryVariant, DistanceField, GridSpec, Mesh, Sampling};
use imprint_stages::metrics::field_error;
use imprint_stages::sdf::build_field_cpu;
use imprint_stages::voxel::voxelize_cpu;
use imprint_tests::mesh;

fn field(m: &Mesh, spec: &GridSpec, variant: BoundaryVariant, band: f32) -> DistanceField {
    let b = voxelize_cpu(m, spec, variant).unwrap();
    build_field_cpu(&b, band).unwrap()
}

/// A tilted plane (not aligned with the grid) through the grid's middle: one triangle much
/// larger than the grid, so every cell's foot point lies on it.
fn tilted_plane() -> (Mesh, Vec3, Vec3) {
    let n = Vec3::new(0.3, 0.2, 1.0).normalize();
    let p0 = Vec3::new(0.51, 0.47, 0.503);
    let u = n.any_orthonormal_vector();
    let v = n.cross(u);
    let corners = vec![p0 + 8.0 * u, p0 - 4.0 * u + 7.0 * v, p0 - 4.0 * u - 7.0 * v];
    (Mesh::new(corners, vec![[0, 1, 2]], "plane").unwrap(), n, p0)
}

#[test]
fn plane_distance_is_exact_with_closest_points() {
    let (m, n, p0) = tilted_plane();
    let spec = GridSpec::new(Vec3::splat(0.0), 1.0 / 32.0, UVec3::splat(33)).unwrap();
    let f = field(&m, &spec, BoundaryVariant::Closest, 3.0);
    let mut checked = 0;
    for i in 0..spec.len() {
        let x = spec.center(spec.coords(i));
        let exact = (x - p0).dot(n).abs() / spec.cell;
        // The plane is clipped to the grid: skip cells whose foot point lies outside it.
        let foot = x - (x - p0).dot(n) * n;
        if spec.cell_of(foot).is_none() {
            continue;
        }
        if exact <= 2.9 {
            assert!(!f.is_far(i), "cell {i} at {exact} cells left far");
            let got = f.dist[i] / spec.cell;
            assert!(
                (got - exact).abs() < 2e-4,
                "cell {i}: {got} vs exact {exact}"
            );
            // The vector points to the plane along -n or +n with the same length.
            let v = f.vector(i) / spec.cell;
            assert!((v.length() - exact).abs() < 2e-4);
            checked += 1;
        }
        if exact > 3.01 {
            assert!(f.is_far(i), "cell {i} at {exact} cells is in the band");
            assert_eq!(f.dist[i], f.far_value());
        }
    }
    assert!(checked > 5000, "{checked}");
    // Sampling "A" (vectors) is exact on a plane between cells; "B" (distances) is not
    // exact only near the surface where |d| has a kink.
    let p = p0 + n * 1.37 * spec.cell + Vec3::new(0.013, -0.007, 0.0);
    let exact = (p - p0).dot(n).abs();
    let a = f.sample(p, Sampling::Vector);
    assert!(
        a.in_band && (a.distance - exact).abs() < 1e-4 * spec.cell,
        "{a:?} vs {exact}"
    );
    // "B" blends distances: exact where all 8 corners lie on one side (|d| is linear there),
    // but it cannot reach 0 on the surface between cells, where A can.
    let b = f.sample(p, Sampling::Distance);
    assert!(
        b.in_band && (b.distance - exact).abs() < 1e-4 * spec.cell,
        "{b:?} vs {exact}"
    );
    let on = p0 + Vec3::new(0.011, 0.013, 0.0);
    let on = on - (on - p0).dot(n) * n;
    let a = f.sample(on, Sampling::Vector);
    let b = f.sample(on, Sampling::Distance);
    assert!(
        a.distance < 1e-4 * spec.cell,
        "A is exact on the surface: {a:?}"
    );
    assert!(b.distance > 0.05 * spec.cell, "B is not: {b:?}");
}

#[test]
fn centre_variant_is_accurate_to_a_cell_only() {
    let (m, n, p0) = tilted_plane();
    let spec = GridSpec::new(Vec3::ZERO, 1.0 / 32.0, UVec3::splat(33)).unwrap();
    let f = field(&m, &spec, BoundaryVariant::Centre, 3.0);
    let mut worst: f32 = 0.0;
    for i in 0..spec.len() {
        let exact = (spec.center(spec.coords(i)) - p0).dot(n).abs() / spec.cell;
        if exact <= 2.0 && !f.is_far(i) {
            worst = worst.max((f.dist[i] / spec.cell - exact).abs());
        }
    }
    // H's points sit on cell centres: errors approach half a cell but no more than sqrt(3)/2.
    assert!(worst > 0.2 && worst <= 0.87, "{worst}");
}

#[test]
fn sphere_field_matches_analytic_distance() {
    let r = 0.7;
    let m = primitives::uv_sphere(r, 256, 128);
    let spec = GridSpec::fit(&m.bounds(), 48, 0.1).unwrap();
    let f = field(&m, &spec, BoundaryVariant::Closest, 3.0);
    // Facets sag below the analytic sphere by at most r(1 - cos(pi/128)) ~ 2e-4 r.
    let sag = r * (1.0 - (std::f32::consts::PI / 128.0).cos());
    let mut n = 0;
    for i in 0..spec.len() {
        if f.is_far(i) {
            continue;
        }
        let x = spec.center(spec.coords(i));
        let exact = (x.length() - r).abs();
        let err = (f.dist[i] - exact).abs() / spec.cell;
        // Distances are refined to one triangle (the nearest point's owner): where the foot
        // point lies on a neighbouring facet, up to ~0.2 cell remains.
        assert!(err < 0.2 + sag / spec.cell, "cell {i}: err {err} cells");
        n += 1;
    }
    assert!(n > 10_000);
    let e = field_error(&f, &m);
    // Only cells at the band's very edge may be left far (their nearest point is a hair
    // beyond `a` while the surface is within it).
    assert!(e.far_fraction < 0.02, "{e:?}");
    assert!(e.p99 < 0.1 && e.max < 0.3, "{e:?}");
}

#[test]
fn open_meshes_meet_the_p99_goal() {
    // The goal (issue 1/7) is p99 <= 0.1 and max <= 0.3 cell at 128^3. p99 is met; max is
    // not yet (0.3-0.55: cells whose foot point lies on a triangle other than the nearest
    // point's owner), see BENCHMARKS.md. Cells the band leaves far sit at its very edge
    // (exact distance within a few tenths of a cell of `a`), about 1% of the band.
    for name in ["teapot", "suzanne"] {
        let m = mesh(name);
        let spec = GridSpec::fit(&m.bounds(), 128, 0.1).unwrap();
        let f = field(&m, &spec, BoundaryVariant::Closest, 3.0);
        let e = field_error(&f, &m);
        assert!(e.band_cells > 10_000, "{name}: {e:?}");
        assert!(e.far_fraction < 0.02, "{name}: {e:?}");
        assert!(
            e.p99 <= 0.1 && e.max <= 0.6 && e.median < 1e-3,
            "{name}: {e:?}"
        );
    }
}

/// Field equality up to rounding: same band, distances within `tol` cells.
fn assert_same_field(a: &DistanceField, b: &DistanceField, tol: f32, what: &str) {
    assert_eq!(a.spec, b.spec);
    let mut band_diff = 0;
    for i in 0..a.dist.len() {
        if a.is_far(i) != b.is_far(i) {
            // Only cells right at the band edge may differ by rounding.
            let d = a.dist[i].min(b.dist[i]) / a.spec.cell;
            assert!(
                (d - a.band).abs() < 1e-3,
                "{what}: cell {i} band differs at {d} cells"
            );
            band_diff += 1;
            continue;
        }
        let e = (a.dist[i] - b.dist[i]).abs() / a.spec.cell;
        assert!(e <= tol, "{what}: cell {i} differs by {e} cells");
    }
    assert!(band_diff < 10, "{what}: {band_diff} band-edge cells differ");
}

#[test]
fn flipped_duplicated_and_unwelded_triangles_give_the_same_field() {
    let m = mesh("teapot");
    let spec = GridSpec::fit(&m.bounds(), 40, 0.1).unwrap();
    let base = field(&m, &spec, BoundaryVariant::Closest, 2.5);

    let mut flipped = m.clone();
    for t in flipped.triangles.iter_mut().step_by(2) {
        t.swap(1, 2);
    }
    // Flipping reorders a triangle's vertices, so near-ties between triangles may resolve the
    // other way by rounding, and a cell's refinement may start from another triangle: both
    // results stay within the method's own error, far below the p99 goal of 0.1 cell.
    let f = field(&flipped, &spec, BoundaryVariant::Closest, 2.5);
    assert_same_field(&base, &f, 0.05, "flipped");
    let same = (0..f.dist.len())
        .filter(|&i| (f.dist[i] - base.dist[i]).abs() < 1e-4 * spec.cell)
        .count();
    assert!(
        same as f64 > 0.999 * f.dist.len() as f64,
        "{same} of {}",
        f.dist.len()
    );

    let mut doubled = m.clone();
    let tris = doubled.triangles.clone();
    doubled.triangles.extend(tris);
    let d = field(&doubled, &spec, BoundaryVariant::Closest, 2.5);
    assert_eq!(d.dist, base.dist, "duplicated triangles change nothing");

    let mut soup = Mesh::default();
    for t in 0..m.triangles.len() {
        let [a, b, c] = m.triangle(t);
        let k = soup.positions.len() as u32;
        soup.positions.extend([a, b, c]);
        soup.triangles.push([k, k + 1, k + 2]);
    }
    let s = field(&soup, &spec, BoundaryVariant::Closest, 2.5);
    assert_eq!(s.dist, base.dist, "unwelded soup");
    assert_eq!(s.nearest, base.nearest);
}

#[test]
fn degenerate_triangles_are_harmless() {
    let m = primitives::uv_sphere(0.5, 48, 24);
    let spec = GridSpec::fit(&m.bounds(), 32, 0.1).unwrap();
    let base = field(&m, &spec, BoundaryVariant::Closest, 3.0);
    let mut d = m.clone();
    // Zero-area triangles made of surface vertices: repeated vertices and collinear ones.
    for t in 0..200u32 {
        let [a, b, _] = m.triangles[t as usize];
        d.triangles.push([a, a, a]);
        d.triangles.push([a, b, a]);
        d.triangles.push([b, a, b]);
    }
    let f = field(&d, &spec, BoundaryVariant::Closest, 3.0);
    // They lie on the surface (vertices and edges), so the field does not get worse.
    let e = field_error(&f, &m);
    let e0 = field_error(&base, &m);
    assert!(
        e.max <= e0.max + 1e-5 && e.p99 <= e0.p99 + 1e-5,
        "{e:?} vs {e0:?}"
    );
}

#[test]
fn triangles_on_grid_planes_leave_no_gaps() {
    // A box whose faces lie exactly on cell faces (x = 2.5, 10.5 …) and on cell centres.
    let spec = GridSpec::new(Vec3::ZERO, 1.0, UVec3::splat(16)).unwrap();
    for (lo, hi) in [
        (Vec3::splat(2.5), Vec3::splat(10.5)),
        (Vec3::splat(3.0), Vec3::splat(11.0)),
    ] {
        let half = (hi - lo) / 2.0;
        let mut m = primitives::cuboid(half, 3);
        m.transform(glam::Mat4::from_translation((lo + hi) / 2.0));
        let b = voxelize_cpu(&m, &spec, BoundaryVariant::Closest).unwrap();
        // Exactly the cells whose closed box touches the box's surface.
        let touches = |c: UVec3| {
            let x = c.as_vec3();
            let cell = Aabb {
                min: x - 0.5,
                max: x + 0.5,
            };
            let inter_min = cell.min.max(lo);
            let inter_max = cell.max.min(hi);
            let overlaps = inter_min.cmple(inter_max).all();
            let inside_strictly = cell.min.cmpgt(lo).all() && cell.max.cmplt(hi).all();
            overlaps && !inside_strictly
        };
        let expected: Vec<u32> = (0..spec.len())
            .filter(|&i| touches(spec.coords(i)))
            .map(|i| i as u32)
            .collect();
        assert_eq!(b.cells, expected, "box {lo}..{hi}");
        // Every boundary point lies on the box surface.
        for p in b.points.iter() {
            let d = (p - lo).min(hi - p).abs().min_element();
            assert!(d < 1e-5, "{p}");
        }
    }
}

#[test]
fn mesh_bigger_than_the_grid_is_clipped() {
    let m = primitives::uv_sphere(3.0, 64, 32);
    let spec = GridSpec::new(Vec3::new(2.5, -0.5, -0.5), 0.05, UVec3::splat(20)).unwrap();
    let f = field(&m, &spec, BoundaryVariant::Closest, 3.0);
    assert!(f.band_cells() > 0);
    assert!(f.points.iter().all(|p| p.is_finite()));
}

#[test]
fn empty_mesh_is_a_clear_error() {
    let e = Mesh::new(vec![Vec3::ZERO], vec![], "empty.obj").unwrap_err();
    assert_eq!(e.exit_code(), 2);
    assert!(e.to_string().contains("no triangles"), "{e}");
}

#[test]
fn thread_count_does_not_change_a_byte() {
    let m = mesh("suzanne");
    let spec = GridSpec::fit(&m.bounds(), 48, 0.1).unwrap();
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| field(&m, &spec, BoundaryVariant::Closest, 3.0))
    };
    let one = run(1);
    let three = run(3);
    assert_eq!(one.dist, three.dist);
    assert_eq!(one.nearest, three.nearest);
    assert_eq!(*one.points, *three.points);
}

#[test]
fn boundary_points_scale_with_area_not_triangle_count() {
    // H's headline: the same shape at 10x the triangles gives nearly the same boundary.
    let coarse = primitives::uv_sphere(0.5, 64, 32);
    let fine = primitives::uv_sphere(0.5, 256, 128);
    let spec = GridSpec::fit(&coarse.bounds(), 64, 0.1).unwrap();
    let a = voxelize_cpu(&coarse, &spec, BoundaryVariant::Closest)
        .unwrap()
        .len() as f32;
    let b = voxelize_cpu(&fine, &spec, BoundaryVariant::Closest)
        .unwrap()
        .len() as f32;
    assert!((a - b).abs() / b < 0.02, "{a} vs {b}");
}

/// A field built in parts (one per frame, as `split` schedules it) is the field built at
/// once, bit for bit, for any number of parts, with and without the triangle refinement.
#[test]
fn a_field_built_in_parts_is_the_field_built_at_once() {
    let m = mesh("suzanne");
    for variant in [BoundaryVariant::Closest, BoundaryVariant::Centre] {
        let spec = GridSpec::fit(&m.bounds(), 40, 0.1).unwrap();
        let b = voxelize_cpu(&m, &spec, variant).unwrap();
        let whole = build_field_cpu(&b, 3.0).unwrap();
        let mut builder = imprint_stages::sdf::FieldBuilder::default();
        for parts in [2u32, 3, 7, 40, 41] {
            let mut build = builder.start(&b, 3.0).unwrap();
            for p in 0..parts {
                build.run_part(p, parts);
            }
            let f = build.finish(&mut builder);
            assert_eq!(f.nearest, whole.nearest, "{variant:?}, {parts} parts");
            let same = f
                .dist
                .iter()
                .zip(&whole.dist)
                .all(|(a, b)| a.to_bits() == b.to_bits());
            assert!(same, "{variant:?}, {parts} parts: distances differ");
        }
    }
}

/// The per-cell vectors the cloth samples are the scalar closest-point vectors bit for bit,
/// and a field computing them into the buffer a recycled field gave back (only its band cells
/// written) has the cells of one computed afresh: the body moved, the variant changed, the
/// band changed (a buffer of another far value is not used). So are its distances and
/// nearest points, built into the recycled field's buffers (cleaned on its spans only).
#[test]
fn cells_in_a_recycled_buffer_are_the_cells_computed_afresh() {
    let m = mesh("suzanne");
    let spec = GridSpec::fit(&m.bounds(), 40, 0.3).unwrap();
    let mut builder = imprint_stages::sdf::FieldBuilder::default();
    let bits = |c: &[glam::Vec4]| -> Vec<u32> {
        c.iter()
            .flat_map(|v| v.to_array().map(f32::to_bits))
            .collect()
    };
    let steps = [
        (Vec3::ZERO, BoundaryVariant::Closest, 3.0),
        (Vec3::new(0.11, -0.07, 0.05), BoundaryVariant::Closest, 3.0),
        (Vec3::new(-0.13, 0.02, 0.09), BoundaryVariant::Centre, 3.0),
        (Vec3::new(0.04, 0.12, -0.1), BoundaryVariant::Closest, 2.0),
        (Vec3::new(0.0, 0.05, 0.0), BoundaryVariant::Closest, 2.0),
    ];
    for (k, (shift, variant, band)) in steps.into_iter().enumerate() {
        let mut moved = m.clone();
        moved.positions.iter_mut().for_each(|p| *p += shift);
        let b = voxelize_cpu(&moved, &spec, variant).unwrap();
        // Every other field built in three parts (the row spans the cells use come from
        // each part's refinement).
        let f = if k % 2 == 1 {
            let mut build = builder.start(&b, band).unwrap();
            (0..3).for_each(|part| build.run_part(part, 3));
            build.finish(&mut builder)
        } else {
            builder.build(&b, band).unwrap()
        };
        // Built into the buffers of the field before it (cleaned only on that field's
        // spans), it is the field built afresh.
        let fresh = build_field_cpu(&b, band).unwrap();
        assert_eq!(f.nearest, fresh.nearest, "step {k}");
        let dist_bits = |f: &DistanceField| f.dist.iter().map(|d| d.to_bits()).collect::<Vec<_>>();
        assert_eq!(dist_bits(&f), dist_bits(&fresh), "step {k}");
        let afresh = f.clone();
        assert_eq!(bits(f.cells()), bits(afresh.cells()), "step {k}");
        // Counted in the builder's row spans, and in a copy (which has none) over every cell.
        let far = imprint_core::DistanceField::FAR;
        let band = f.nearest.iter().filter(|&&n| n != far).count();
        assert_eq!(
            (f.band_cells(), afresh.band_cells()),
            (band, band),
            "step {k}"
        );
        for (i, c) in f.cells().iter().enumerate() {
            let v = f.vector(i).to_array().map(f32::to_bits);
            assert_eq!(
                c.truncate().to_array().map(f32::to_bits),
                v,
                "step {k}, cell {i}"
            );
        }
        for field in [&f, &afresh] {
            assert_far_bricks_hold(field, &format!("step {k}"));
        }
        builder.recycle(f);
    }
}

/// Where [`imprint_core::field::FarBricks`] says a read is plainly far, the eight cells it
/// reads are exactly `(0, 0, 0, -far)`; and it says so for most reads away from the body (it
/// is not empty).
fn assert_far_bricks_hold(f: &imprint_core::DistanceField, what: &str) {
    let far = glam::Vec4::new(0.0, 0.0, 0.0, -f.far_value())
        .to_array()
        .map(f32::to_bits);
    let (cells, bricks) = (f.cells(), f.far_bricks());
    let [nx, ny, nz] = f.spec.dims.to_array().map(|d| d as usize);
    let (mut skipped, mut plainly_far) = (0, 0);
    for (x, y, z) in
        (0..nz - 1).flat_map(|z| (0..ny - 1).flat_map(move |y| (0..nx - 1).map(move |x| (x, y, z))))
    {
        let corners =
            (0..8).map(|k| (x + (k & 1)) + nx * (y + (k >> 1 & 1)) + nx * ny * (z + (k >> 2)));
        let all = corners
            .clone()
            .all(|i| cells[i].to_array().map(f32::to_bits) == far);
        if bricks.all_far([x, y, z]) {
            assert!(
                all,
                "{what}: cell ({x}, {y}, {z}) read as plainly far, but is not"
            );
            skipped += 1;
        }
        plainly_far += all as usize;
    }
    assert!(
        skipped * 2 > plainly_far,
        "{what}: {skipped} reads skipped of {plainly_far} plainly far"
    );
}

/// Near the middle of a gap the cells' vectors point to different walls and their blend is
/// short; sampling "A" then reads the lower bound from the blended distances instead
/// (`vector_distance`): never more than the exact distance, and short of it by no more than
/// twice the spread (the blend of the corners' distances is within one spread of the exact
/// distance, and the bound one spread below that): √3 cells at most, where the vector's
/// length alone fell to a tenth of the distance or less.
#[test]
fn in_the_middle_of_a_gap_a_reads_no_shorter_than_its_bound() {
    let spec = GridSpec::new(Vec3::splat(-0.1), 0.01, UVec3::new(21, 21, 21)).unwrap();
    // Walls y = -0.025 and y = 0.035: the gap's middle, y = 0.005, lies on a face between
    // cells (their centres are at whole centimetres).
    let mid = 0.005;
    let walls = |p: Vec3| Vec3::new(p.x, if p.y < mid { -0.025 } else { 0.035 }, p.z);
    let f = DistanceField::from_closest_points(spec, 4.0, walls);
    let mut worst_len: f32 = 1.0;
    for k in 0..=20 {
        let y = mid - 0.005 + 0.0005 * k as f32;
        let p = Vec3::new(0.0012, y, -0.0031);
        let exact = 0.03 - (y - mid).abs();
        let a = f.sample(p, Sampling::Vector);
        assert!(a.in_band, "{p}");
        assert!(
            a.distance <= exact + 1e-6,
            "{p}: {} > exact {exact}",
            a.distance
        );
        let worst = 3.0f32.sqrt() * spec.cell;
        assert!(
            a.distance >= exact - worst,
            "{p}: {} vs {exact}",
            a.distance
        );
        worst_len = worst_len.min(a.vector.length() / exact);
    }
    // The vector's length alone: down to zero on the face between the cells.
    assert!(worst_len < 0.1, "{worst_len}");
}
