//! Shared pieces of the benchmark harness: timing, machine description, baselines, GPU table.

pub mod cloth;
pub mod colliders;
pub mod drape;
pub mod ground_snow;
pub mod render;
pub mod schedule;
pub mod skin;
pub mod stages_gpu;
pub mod view;

use imprint_core::{BoundaryVariant, DistanceField, GridSpec, Mesh};
use imprint_stages::metrics::FieldError;
use imprint_stages::{sdf::cpu::build_field_cpu, voxel::cpu::voxelize_cpu};
use std::fmt::Write;
use std::path::Path;
use std::time::Instant;

pub struct Run {
    pub points: usize,
    pub voxelise_ms: f64,
    pub field_ms: f64,
    pub error: FieldError,
    pub field: DistanceField,
}

/// The median of `v` (the upper of the two middle values for an even count; NaN when empty).
pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v.get(v.len() / 2).copied().unwrap_or(f64::NAN)
}

/// Median wall time of `repeat` calls, in ms.
pub fn median_ms(repeat: usize, mut f: impl FnMut()) -> f64 {
    median(
        (0..repeat.max(1))
            .map(|_| {
                let s = Instant::now();
                f();
                s.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

pub struct Machine {
    pub cpu: String,
    pub cores: usize,
    pub load: String,
}

impl Machine {
    pub fn detect() -> Self {
        let cpu = std::fs::read_to_string("/proc/cpuinfo")
            .ok()
            .and_then(|s| {
                s.lines()
                    .find(|l| l.starts_with("model name"))
                    .map(|l| l.split(':').nth(1).unwrap_or("").trim().to_string())
            })
            .unwrap_or_else(|| "unknown CPU".into());
        let load = std::fs::read_to_string("/proc/loadavg")
            .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
            .unwrap_or_else(|_| "unknown".into());
        Machine {
            cpu,
            cores: std::thread::available_parallelism().map_or(1, |n| n.get()),
            load,
        }
    }

    pub fn describe(&self) -> String {
        format!(
            "{} ({} cores visible, {} rayon threads)",
            self.cpu,
            self.cores,
            rayon::current_num_threads()
        )
    }
}

/// Grid JSON in the form `benches/compare/baselines.py` reads.
pub fn grid_json(spec: &GridSpec) -> String {
    serde_json::json!({
        "origin": [spec.origin.x, spec.origin.y, spec.origin.z],
        "cell_size": spec.cell,
        "dims": [spec.dims.x, spec.dims.y, spec.dims.z],
    })
    .to_string()
}

/// Runs `benches/compare/baselines.py` on each mesh (same grid, same run) and returns the
/// markdown section: OpenVDB `meshToLevelSet` and Open3D's exact distance, as ratios to ours.
pub fn baselines(root: &Path, ours: &[(&str, f64, Mesh, DistanceField)], repeat: usize) -> String {
    let mut s = String::new();
    let script = root.join("benches/compare/baselines.py");
    let tmp = std::env::temp_dir().join(format!("imprint-baselines-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).expect("temp dir");
    let _ = writeln!(
        s,
        "Each baseline builds the same band (half-width 3 cells) on the same 128³ grid from the \
         same mesh in its own coordinates; `benches/compare/baselines.py` times only the library \
         call (median of {repeat} after a warm-up). OpenVDB: `createLevelSetFromPolygons` \
         (meshToLevelSet, TBB on all cores), unsigned = |level set|; each call makes a new grid, \
         and its **first call** in the process (TBB's start, fresh memory) is shown apart. \
         Open3D: `RaycastingScene` exact distance on imprint's band cells (BVH build included). \
         Imprint **steady** = voxelise + field with the buffers of the frame before (table 1, \
         Closest variant: a frame-by-frame run); **one-shot** = a new `Voxelizer` and \
         `FieldBuilder` per call (every buffer allocated, the mesh's closedness tested; freed \
         after the timer, as the script frees OpenVDB's grids), median of {repeat} in this \
         warm process, timed just before the baselines: the footing of OpenVDB's median. \
         Ratios are baseline time / imprint time. Errors in cells against the exact distance \
         on imprint's band cells.\n"
    );
    let _ = writeln!(
        s,
        "| mesh | imprint steady ms | imprint one-shot ms | OpenVDB ms | OpenVDB first call ms | OpenVDB / imprint steady | OpenVDB / imprint one-shot | OpenVDB err p99 / max | imprint err p99 / max | Open3D exact ms | Open3D / imprint steady |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut versions = String::new();
    for (name, ours_ms, mesh, field) in ours {
        let one_shot_ms = one_shot_ms(mesh, &field.spec, field.band, repeat);
        let grid = tmp.join(format!("{name}.grid.json"));
        let dist = tmp.join(format!("{name}.dist.npy"));
        let result = tmp.join(format!("{name}.json"));
        std::fs::write(&grid, grid_json(&field.spec)).expect("grid json");
        let d = field.spec.dims;
        imprint_render::write_npy_f32(
            &dist,
            &[d.z as usize, d.y as usize, d.x as usize],
            &field.dist,
        )
        .expect("dist npy");
        let mesh_path = root.join(format!("assets/meshes/{name}.obj"));
        let status = std::process::Command::new("python3")
            .arg(&script)
            .args([
                "--mesh",
                mesh_path.to_str().unwrap(),
                "--grid",
                grid.to_str().unwrap(),
            ])
            .args(["--band", "3", "--dist-npy", dist.to_str().unwrap()])
            .args([
                "--repeat",
                &repeat.to_string(),
                "--out",
                result.to_str().unwrap(),
            ])
            .status();
        let json: Option<serde_json::Value> = status
            .ok()
            .filter(|st| st.success())
            .and_then(|_| std::fs::read(&result).ok())
            .and_then(|b| serde_json::from_slice(&b).ok());
        let Some(j) = json else {
            let _ = writeln!(
                s,
                "| {name} | {ours_ms:.1} | {one_shot_ms:.1} | not run: `python3 {}` failed (run benches/compare/install.sh) | | | | | | | |",
                script.display()
            );
            continue;
        };
        let vdb = &j["baselines"]["openvdb"];
        let o3d = &j["baselines"]["open3d"];
        let acc = &j["accuracy"];
        let f = |v: &serde_json::Value| v.as_f64();
        let cell = |v: Option<f64>| v.map_or("–".to_string(), |x| format!("{x:.1}"));
        let ratio_to =
            |v: Option<f64>, to: f64| v.map_or("–".to_string(), |x| format!("{:.0}×", x / to));
        let ratio = |v: Option<f64>| ratio_to(v, *ours_ms);
        let err = |k: &str| match (f(&acc[k]["abs_p99"]), f(&acc[k]["abs_max"])) {
            (Some(p), Some(m)) => format!("{p:.3} / {m:.3}"),
            _ => "–".into(),
        };
        let _ = writeln!(
            s,
            "| {name} | {ours_ms:.1} | {one_shot_ms:.1} | {} | {} | {} | {} | {} | {} | {} | {} |",
            cell(f(&vdb["median_ms"])),
            cell(f(&vdb["cold_ms"])),
            ratio(f(&vdb["median_ms"])),
            ratio_to(f(&vdb["median_ms"]), one_shot_ms),
            err("openvdb_vs_exact"),
            err("imprint_vs_exact"),
            cell(f(&o3d["median_ms"])),
            ratio(f(&o3d["median_ms"])),
        );
        if versions.is_empty() {
            versions = format!(
                "OpenVDB {} ({}), Open3D {} ({}), Python {}.",
                vdb["version"].as_str().unwrap_or("unavailable"),
                vdb["module"].as_str().unwrap_or("-"),
                o3d["version"].as_str().unwrap_or("unavailable"),
                o3d["package"].as_str().unwrap_or("-"),
                j["python_version"].as_str().unwrap_or("?")
            );
        }
    }
    let _ = writeln!(s, "\nVersions: {versions}");
    let _ = std::fs::remove_dir_all(&tmp);
    s
}

/// Voxelise + field of `mesh` on `spec` with nothing kept between calls (a new voxeliser and
/// field builder each time, as a one-shot `imprint field` has), median of `repeat`, ms. Each
/// call's field is freed after its timer stops, as `baselines.py` frees OpenVDB's grids.
fn one_shot_ms(mesh: &Mesh, spec: &GridSpec, band: f32, repeat: usize) -> f64 {
    let times = (0..repeat.max(1))
        .map(|_| {
            let s = Instant::now();
            let boundary = voxelize_cpu(mesh, spec, BoundaryVariant::Closest).expect("voxelise");
            let field = build_field_cpu(&boundary, band).expect("field");
            let ms = s.elapsed().as_secs_f64() * 1e3;
            drop(std::hint::black_box((boundary, field)));
            ms
        })
        .collect();
    median(times)
}

/// GPU voxelise + field times (wall clock around submit and wait) when an adapter exists, with
/// the error of the read-back field: on a GPU at 128³ and 256³ (issue 5/7's figures), on a
/// software adapter at 64³ only (it is slow).
pub fn gpu_table(root: &Path, repeat: usize) -> String {
    use imprint_stages::sdf::gpu::build_field_gpu;
    use imprint_stages::voxel::gpu::voxelize_gpu;
    let mut s = String::new();
    let ctx = match imprint_gpu::GpuContext::shared() {
        Ok(c) => c,
        Err(e) => {
            let _ = writeln!(s, "No GPU adapter on this machine ({e}); no GPU figures.");
            return s;
        }
    };
    let grids: &[u32] = if ctx.is_software() {
        &[64]
    } else {
        &[128, 256]
    };
    let repeat = if ctx.is_software() {
        repeat.min(3)
    } else {
        repeat
    };
    let _ = writeln!(
        s,
        "Adapter: {}. Grids fitted as in table 1 (the cells along the box's longest side), a = \
         3, Closest; times are wall clock from submit to completion (median of {repeat}), \
         read-back excluded; error of the read-back field against the exact distance.\n",
        adapter_label(ctx),
    );
    let _ = writeln!(
        s,
        "| mesh | grid | voxelise ms | field ms | total ms | CPU total ms (same grid) | p99 err | max err |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|---:|");
    let meshes = ["teapot", "stanford-bunny", "cow"];
    for (&res, name) in grids
        .iter()
        .flat_map(|r| meshes.iter().map(move |m| (r, m)))
    {
        let mesh = Mesh::load_obj(&root.join(format!("assets/meshes/{name}.obj"))).expect("mesh");
        let spec = GridSpec::fit(&mesh.bounds(), res, 0.1).expect("grid");
        let variant = imprint_core::BoundaryVariant::Closest;
        let run = || -> imprint_core::Result<(f64, f64, imprint_stages::sdf::gpu::GpuField)> {
            let t = Instant::now();
            let b = voxelize_gpu(ctx, &mesh, &spec, variant)?;
            ctx.wait()?;
            let tv = t.elapsed().as_secs_f64() * 1e3;
            let t = Instant::now();
            let f = build_field_gpu(ctx, &b, 3.0)?;
            ctx.wait()?;
            Ok((tv, t.elapsed().as_secs_f64() * 1e3, f))
        };
        let mut tv = Vec::new();
        let mut tf = Vec::new();
        let mut last = None;
        let mut failed = None;
        for _ in 0..=repeat {
            match run() {
                Ok((a, b, f)) => {
                    tv.push(a);
                    tf.push(b);
                    last = Some(f);
                }
                Err(e) => {
                    failed = Some(e);
                    break;
                }
            }
        }
        let Some(field) = last.filter(|_| failed.is_none()) else {
            let _ = writeln!(
                s,
                "| {name} | {res}³ | failed: {} | | | | | |",
                failed.map_or(String::new(), |e| e.to_string())
            );
            continue;
        };
        // Drop the warm-up run.
        tv.remove(0);
        tf.remove(0);
        let med = |v: &mut Vec<f64>| {
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        let (v, f) = (med(&mut tv), med(&mut tf));
        let cpu = {
            let mut vox = imprint_stages::voxel::cpu::Voxelizer::new(spec).expect("voxeliser");
            median_ms(repeat, || {
                let b = vox.run(&mesh, variant).expect("voxelise");
                std::hint::black_box(imprint_stages::sdf::build_field_cpu(&b, 3.0).expect("field"));
            })
        };
        let err = field
            .to_cpu(ctx)
            .map(|f| imprint_stages::metrics::field_error(&f, &mesh));
        let (p99, max) = err.map_or(("–".into(), "–".into()), |e| {
            (format!("{:.3}", e.p99), format!("{:.3}", e.max))
        });
        let _ = writeln!(
            s,
            "| {name} | {res}³ | {v:.2} | {f:.2} | {:.2} | {cpu:.2} | {p99} | {max} |",
            v + f
        );
    }
    s
}

/// The adapter's name, marked when it is a software one (its times are no GPU figure).
pub fn adapter_label(ctx: &imprint_gpu::GpuContext) -> String {
    let software = if ctx.is_software() {
        " (software Vulkan: correct, not fast; not a GPU figure)"
    } else {
        ""
    };
    format!("{}{software}", ctx.adapter_name())
}
