//! The time-against-error harness behind BENCHMARKS.md.
//!
//!     cargo run --release -p imprint-benches --bin harness -- [--only a,b] [--repeat N] [--out BENCHMARKS.md]
//!
//! Sections (see `SECTIONS`): `field` — (1) H Table 1 at 128^3, a = 3 on teapot, bunny and
//! cow, both boundary variants, (2) one shape at 10k, 100k and 1M triangles (H's claim: field
//! cost follows area, not triangle count); `baselines` — (3) the same meshes and grid through
//! OpenVDB and Open3D, in the same run, via benches/compare/baselines.py; `gpu` — (4) the GPU
//! path when an adapter exists; `render` — (5) frames and depth maps; … `stages_gpu` — (12)
//! each stage with a GPU path (cloth, ground, snow, skinning), GPU against CPU per frame.
//!
//! Each section is written to `benches/results/<name>.md` with its own date, machine and load,
//! so one section can be re-measured without re-running (or losing) the others;
//! BENCHMARKS.md is assembled from all of them plus `benches/notes.md`.
//! Every time is a median of `repeat` runs after one warm-up, with the error it costs.

use imprint_benches::*;
use imprint_core::mesh::primitives;
use imprint_core::{BoundaryVariant, GridSpec, Mesh};
use imprint_stages::metrics::field_error;
use imprint_stages::sdf::FieldBuilder;
use imprint_stages::voxel::cpu::Voxelizer;
use std::fmt::Write;
use std::path::PathBuf;

/// The sections, in the order BENCHMARKS.md shows them: (name for `--only`, what it covers).
const SECTIONS: [(&str, &str); 12] = [
    (
        "field",
        "distance fields on the CPU: H Table 1 and triangle-count scaling",
    ),
    (
        "baselines",
        "the same fields through OpenVDB and Open3D, same run",
    ),
    ("gpu", "the GPU voxelise + field path"),
    ("render", "frames and depth maps, CPU and GPU"),
    ("cloth", "the cloth against Taichi, and H's bunny scene"),
    ("schedule", "schedules: H Table 1 columns (c) and (d)"),
    ("ground", "the ground and snow stages"),
    ("drape", "depth-buffer draping"),
    (
        "colliders",
        "the cloth's colliders: distance field and depth maps",
    ),
    ("skin", "skinning: particles, LBS and DQS"),
    (
        "stages_gpu",
        "each stage with a GPU path, GPU against CPU per frame",
    ),
    ("view", "the live viewer under Xvfb: fps held, sim/draw/UI"),
];

/// What `--help` prints, and what a flag it does not know gets.
fn usage() -> String {
    let sections: Vec<String> = SECTIONS
        .iter()
        .map(|(name, what)| format!("  {name:<11} {what}"))
        .collect();
    format!(
        "usage: harness [--only SECTION[,SECTION…]] [--repeat N] [--out FILE] [--assemble]\n\
         Measures the sections (all without --only; N repeats, default 15), writes\n\
         benches/results/SECTION.md and assembles FILE (default BENCHMARKS.md); --assemble\n\
         measures nothing and only assembles.\nsections:\n{}",
        sections.join("\n")
    )
}

/// Refuses flags the harness does not know (a typo must not start an hour of measuring).
fn check_flags(args: &[String]) {
    let mut rest = args.iter().skip(1);
    while let Some(a) = rest.next() {
        match a.as_str() {
            "--help" | "-h" => {
                println!("{}", usage());
                std::process::exit(0);
            }
            "--only" | "--repeat" | "--out" => {
                rest.next();
            }
            "--assemble" => {}
            other => {
                eprintln!("error: unknown argument {other}\n{}", usage());
                std::process::exit(2);
            }
        }
    }
}

fn main() {
    // As the `imprint` binary runs its stages.
    imprint_core::pool::retain_freed_memory();
    let args: Vec<String> = std::env::args().collect();
    check_flags(&args);
    let arg = |k: &str| {
        args.iter()
            .position(|a| a == k)
            .and_then(|i| args.get(i + 1))
            .cloned()
    };
    let repeat: usize = arg("--repeat").map_or(15, |s| s.parse().expect("--repeat N"));
    let out = PathBuf::from(arg("--out").unwrap_or_else(|| "BENCHMARKS.md".into()));
    // `--assemble`: re-measure nothing, rebuild BENCHMARKS.md from the results and notes.
    let assemble = args.iter().any(|a| a == "--assemble");
    let only: Vec<String> = arg("--only").filter(|_| !assemble).map_or_else(
        || SECTIONS.iter().map(|s| s.0.to_string()).collect(),
        |s| s.split(',').map(str::to_string).collect(),
    );
    for o in &only {
        assert!(
            SECTIONS.iter().any(|s| s.0 == o),
            "--only {o}: sections are {:?}",
            SECTIONS.map(|s| s.0)
        );
    }
    let root = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let results = root.join("benches/results");

    let mut totals = Vec::new();
    for (name, _) in SECTIONS {
        if assemble || !only.iter().any(|o| o == name) {
            continue;
        }
        let machine = Machine::detect();
        let body = match name {
            "field" => field_section(&root, repeat, &mut totals),
            "baselines" => {
                if totals.is_empty() {
                    totals = ours_for_baselines(&root, repeat);
                }
                format!(
                    "## 3. Against what users would pick instead (same meshes, same grid, same run)\n\n{}",
                    baselines(&root, &totals, repeat.min(5))
                )
            }
            "gpu" => format!("## 4. GPU path\n\n{}", gpu_table(&root, repeat)),
            "render" => imprint_benches::render::section(&root, repeat),
            "cloth" => imprint_benches::cloth::section(&root, repeat),
            "schedule" => imprint_benches::schedule::section(&root, repeat),
            "ground" => imprint_benches::ground_snow::section(&root, repeat),
            "drape" => imprint_benches::drape::section(&root, repeat),
            "colliders" => imprint_benches::colliders::section(&root, repeat),
            "skin" => imprint_benches::skin::section(&root, repeat),
            "stages_gpu" => imprint_benches::stages_gpu::section(&root, repeat),
            "view" => imprint_benches::view::section(&root, repeat),
            _ => unreachable!(),
        };
        let stamp = format!(
            "*Measured {} with `cargo run --release -p imprint-benches --bin harness -- --only {name} \
             --repeat {repeat}` on {}; load average {} at start, {} at end.*\n\n",
            today(),
            machine.describe(),
            machine.load,
            Machine::detect().load
        );
        // The section's heading line, then the stamp, then the rest.
        let (head, rest) = body.split_once('\n').unwrap_or((&body, ""));
        let text = format!("{head}\n\n{stamp}{}\n", rest.trim());
        let path = results.join(format!("{name}.md"));
        imprint_core::io::atomic_write_bytes(&path, text.as_bytes()).expect("write section");
        eprintln!("section {name} written to {}", path.display());
    }

    // BENCHMARKS.md: every section's latest results, then the hand-written reading.
    let mut md = String::from(
        "# Benchmarks\n\nAssembled by `cargo run --release -p imprint-benches --bin harness` from \
         `benches/results/*.md` (one file per section, each stamped with its date, machine and \
         load; `--only NAME[,NAME]` re-measures some and keeps the rest) and the hand-written \
         `benches/notes.md`. Times are medians after one warm-up; every time is given with the \
         error it costs.\n\n",
    );
    for (name, what) in SECTIONS {
        match std::fs::read_to_string(results.join(format!("{name}.md"))) {
            Ok(t) => md += &t,
            Err(_) => {
                let _ = writeln!(md, "## {name}\n\nNot measured yet ({what}).\n");
            }
        }
        md.push('\n');
    }
    if let Ok(notes) = std::fs::read_to_string(root.join("benches/notes.md")) {
        md += &notes;
    }
    imprint_core::io::atomic_write_bytes(&out, md.as_bytes()).expect("write BENCHMARKS.md");
    eprintln!("wrote {}", out.display());
}

/// Today's date (UTC), from `date`, for the section stamps.
fn today() -> String {
    std::process::Command::new("date")
        .args(["-u", "+%Y-%m-%d"])
        .output()
        .ok()
        .and_then(|o| String::from_utf8(o.stdout).ok())
        .map_or_else(|| "(date unknown)".into(), |s| s.trim().to_string())
}

type Ours = Vec<(&'static str, f64, Mesh, imprint_core::DistanceField)>;

/// Imprint's time and field on the baselines' meshes, when the field section did not run.
fn ours_for_baselines(root: &std::path::Path, repeat: usize) -> Ours {
    ["teapot", "stanford-bunny", "cow"]
        .into_iter()
        .map(|name| {
            let mesh = load(root, name);
            let r = measure(&mesh, 128, 3.0, BoundaryVariant::Closest, repeat);
            (name, r.voxelise_ms + r.field_ms, mesh, r.field)
        })
        .collect()
}

/// Tables 1 and 2; fills `totals` for the baselines.
fn field_section(root: &std::path::Path, repeat: usize, totals: &mut Ours) -> String {
    let mut md = String::new();
    writeln!(md, "## 1. H Table 1 at 128³, a = 3 (CPU)\n").unwrap();
    writeln!(
        md,
        "Errors are against the exact closest point on the triangles (BVH), over every cell \
         whose exact distance is within the band, in cells. Grid fitted to the mesh: 128 cells \
         along the longest side of its box grown by 10% per side. H's figures (GeForce 7800 \
         GTX, 2007) for comparison: teapot 8,753 points, (a) 14.1 ms, (b) 17.1 ms; rabbit 8,109 \
         points, 28.1 / 15.6 ms.\n"
    )
    .unwrap();
    writeln!(md, "| mesh | triangles | variant | boundary points | voxelise ms | field ms | total ms | band cells | p99 err | max err | median err | far |").unwrap();
    writeln!(
        md,
        "|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    )
    .unwrap();
    for name in ["teapot", "stanford-bunny", "cow"] {
        let mesh = load(root, name);
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
    md
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
