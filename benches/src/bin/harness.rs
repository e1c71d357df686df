//! The time-against-error harness behind BENCHMARKS.md.
//!
//!     cargo run --release -p imprint-benches --bin harness -- [--repeat N] [--out BENCHMARKS.md]
//!
//! Tables: (1) H Table 1 at 128^3, a = 3 on teapot, bunny and cow, both boundary variants;
//! (2) one shape at 10k, 100k and 1M triangles (H's claim: field cost follows area, not
//! triangle count); (3) the same meshes and grid through OpenVDB and Open3D, in the same run,
//! via benches/compare/baselines.py; (4) the GPU path when an adapter exists.
//! Every time is a median of `repeat` runs after one warm-up, with the error it costs.

use imprint_benches::*;
use imprint_core::mesh::primitives;
use imprint_core::{BoundaryVariant, GridSpec, Mesh};
use imprint_stages::metrics::field_error;
use imprint_stages::sdf::FieldBuilder;
use imprint_stages::voxel::cpu::Voxelizer;
use std::fmt::Write;
use std::path::PathBuf;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let repeat: usize = arg("--repeat").map_or(15, |s| s.parse().expect("--repeat N"));
    let out = PathBuf::from(arg("--out").unwrap_or_else(|| "BENCHMARKS.md".into()));
    let skip_baselines = args.iter().any(|a| a == "--no-baselines");
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));

    let mut md = String::new();
    let machine = Machine::detect();
    writeln!(md, "# Benchmarks\n").unwrap();
    writeln!(
        md,
        "Written by `cargo run --release -p imprint-benches --bin harness -- --repeat {repeat}` \
         on {}. Times are medians of {repeat} runs after one warm-up; errors are against the exact \
         closest point on the triangles (BVH), over every cell whose exact distance is within the \
         band, in cells. Load average at start: {}.\n",
        machine.describe(),
        machine.load
    )
    .unwrap();

    // (1) H Table 1.
    writeln!(md, "## 1. H Table 1 at 128³, a = 3 (CPU)\n").unwrap();
    writeln!(
        md,
        "Grid fitted to the mesh: 128 cells along the longest side of its box grown by 10% per side. \
         H's figures (GeForce 7800 GTX, 2007) for comparison: teapot 8,753 points, (a) 14.1 ms, \
         (b) 17.1 ms; rabbit 8,109 points, 28.1 / 15.6 ms.\n"
    )
    .unwrap();
    writeln!(md, "| mesh | triangles | variant | boundary points | voxelise ms | field ms | total ms | band cells | p99 err | max err | median err | far |").unwrap();
    writeln!(
        md,
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    .unwrap();
    let mut totals = Vec::new();
    for name in ["teapot", "stanford-bunny", "cow"] {
        let mesh = load(&root, name);
        for variant in [BoundaryVariant::Centre, BoundaryVariant::Closest] {
            let r = measure(&mesh, 128, 3.0, variant, repeat);
            writeln!(
                md,
                "| {name} | {} | {variant:?} | {} | {:.2} | {:.2} | {:.2} | {} | {:.3} | {:.3} | {:.3} | {:.4} |",
                mesh.triangles.len(), r.points, r.voxelise_ms, r.field_ms, r.voxelise_ms + r.field_ms,
                r.error.band_cells, r.error.p99, r.error.max, r.error.median, r.error.far_fraction
            )
            .unwrap();
            if variant == BoundaryVariant::Closest {
                totals.push((name, r.voxelise_ms + r.field_ms, mesh.clone(), r.field));
            }
            eprintln!("table 1: {name} {variant:?} done");
        }
    }

    // (2) Same shape, more triangles.
    writeln!(
        md,
        "\n## 2. One shape at 10k, 100k and 1M triangles (sphere, 128³, a = 3, Closest)\n"
    )
    .unwrap();
    writeln!(
        md,
        "| triangles | boundary points | voxelise ms | field ms | p99 err | max err |"
    )
    .unwrap();
    writeln!(md, "|---:|---:|---:|---:|---:|---:|").unwrap();
    for (seg, rings) in [(100u32, 51u32), (317, 159), (1000, 501)] {
        let mesh = primitives::uv_sphere(0.5, seg, rings);
        let r = measure(&mesh, 128, 3.0, BoundaryVariant::Closest, repeat.min(7));
        writeln!(
            md,
            "| {} | {} | {:.2} | {:.2} | {:.3} | {:.3} |",
            mesh.triangles.len(),
            r.points,
            r.voxelise_ms,
            r.field_ms,
            r.error.p99,
            r.error.max
        )
        .unwrap();
        eprintln!("table 2: {} triangles done", mesh.triangles.len());
    }

    // (3) Baselines.
    writeln!(
        md,
        "\n## 3. Against what users would pick instead (same meshes, same grid, same run)\n"
    )
    .unwrap();
    if skip_baselines {
        writeln!(md, "Skipped (--no-baselines).").unwrap();
    } else {
        md += &baselines(&root, &totals, repeat.min(5));
    }

    // (4) GPU.
    writeln!(md, "\n## 4. GPU path\n").unwrap();
    md += &gpu_table(&root, repeat);

    writeln!(md, "\nLoad average at end: {}.\n", Machine::detect().load).unwrap();
    // The hand-written reading of the figures.
    if let Ok(notes) = std::fs::read_to_string(root.join("benches/notes.md")) {
        md += &notes;
    }
    imprint_core::io::atomic_write_bytes(&out, md.as_bytes()).expect("write BENCHMARKS.md");
    eprintln!("wrote {}", out.display());
}

/// Times one mesh at one setting and measures its error.
fn measure(mesh: &Mesh, res: u32, band: f32, variant: BoundaryVariant, repeat: usize) -> Run {
    let spec = GridSpec::fit(&mesh.bounds(), res, 0.1).expect("grid");
    let mut vox = Voxelizer::new(spec).expect("voxeliser");
    let mut boundary = vox.run(mesh, variant).expect("voxelise");
    let voxelise_ms = median_ms(repeat, || {
        boundary = vox.run(mesh, variant).expect("voxelise")
    });
    // Steady state of a frame-by-frame run: the builder reuses the last field's buffers.
    let mut builder = FieldBuilder::default();
    let mut field = builder.build(&boundary, band).expect("field");
    let field_ms = median_ms(repeat, || {
        let old = std::mem::replace(&mut field, builder.build(&boundary, band).expect("field"));
        builder.recycle(old);
    });
    Run {
        points: boundary.len(),
        voxelise_ms,
        field_ms,
        error: field_error(&field, mesh),
        field,
    }
}

fn load(root: &std::path::Path, name: &str) -> Mesh {
    Mesh::load_obj(&root.join(format!("assets/meshes/{name}.obj"))).expect("mesh")
}
