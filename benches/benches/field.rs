//! Criterion benches of the distance-field kernels on the CPU: voxelise and field build for
//! the teapot and the bunny at 128^3, band 3 (the H Table 1 setting).

use criterion::{Criterion, criterion_group, criterion_main};
use imprint_core::{BoundaryVariant, GridSpec, Mesh};
use imprint_stages::sdf::build_field_cpu;
use imprint_stages::voxel::cpu::Voxelizer;
use std::hint::black_box;

fn load(name: &str) -> Mesh {
    let p = format!("{}/../assets/meshes/{name}.obj", env!("CARGO_MANIFEST_DIR"));
    Mesh::load_obj(std::path::Path::new(&p)).expect("mesh loads")
}

fn field(c: &mut Criterion) {
    let mut g = c.benchmark_group("field_128_a3");
    g.sample_size(20);
    for name in ["teapot", "stanford-bunny"] {
        let mesh = load(name);
        let spec = GridSpec::fit(&mesh.bounds(), 128, 0.1).unwrap();
        let mut vox = Voxelizer::new(spec).unwrap();
        g.bench_function(format!("{name}/voxelize"), |b| {
            b.iter(|| black_box(vox.run(&mesh, BoundaryVariant::Closest).unwrap()))
        });
        let boundary = vox.run(&mesh, BoundaryVariant::Closest).unwrap();
        g.bench_function(format!("{name}/field"), |b| {
            b.iter(|| black_box(build_field_cpu(&boundary, 3.0).unwrap()))
        });
    }
    g.finish();
}

criterion_group!(benches, field);
criterion_main!(benches);
