//! Section 6 of BENCHMARKS.md: the cloth.
//!
//! 1. **Against Taichi.** One scene, the same model on both sides: an N×N cloth (N = 64 and
//!    128) 1 m wide, structural + shear springs f = Y (l/l0 − 1) with Y = 1e4 (imprint:
//!    `stiffness_mode: Strain`, Harada k_structural = k_shear = 1e4), particle mass 1, Verlet
//!    damping 0.9995, dropped flat from y = 0.6 onto a sphere of radius 0.3 at the origin,
//!    cloth centre offset (0.031, 0.017) in x/z, ε = 0.005, friction b = 0.3, 60 frames per
//!    second, 32 substeps per frame, gravity −9.81, 60 frames (1 s). Imprint reads the sphere
//!    from an exact distance field (128³ cells of 6.25 mm over [−0.4, 0.4]³, band 3 cells,
//!    built once: the sphere does not move; also 64³, to show what the field's size costs);
//!    Taichi (CPU, `benches/compare/cloth_taichi.py`) tests the analytic sphere. Same run,
//!    both final mean heights, and Taichi in f64 for the spread f32 rounding alone makes.
//! 2. **H's scene.** `pipelines/harada_cloth.ron` (the breathing, twisting bunny, its 128³
//!    field rebuilt every frame, a 70×70 cloth) loaded with `imprint_graph::load` and
//!    overrides, then run stage by stage (the executor's calls, without its render and mesh
//!    writer) to time mesh motion, voxelise, field and cloth per frame.

use crate::median;
use glam::{UVec3, Vec3};
use imprint_core::{DistanceField, GridSpec};
use imprint_graph::schema::{GridChoice, NodeSpec};
use imprint_stages::cloth::{ClothParams, ClothSim, Material, Shape, StiffnessMode};
use imprint_stages::mesh::MeshSource;
use imprint_stages::sdf::FieldBuilder;
use imprint_stages::voxel::cpu::Voxelizer;
use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// The comparison scene's constants (Taichi gets the same on its command line).
const FRAMES: u32 = 60;
const FPS: f32 = 60.0;
const SUBSTEPS: u32 = 32;
const Y_STRAIN: f32 = 1e4;
const DAMPING: f32 = 0.9995;
const HEIGHT: f32 = 0.6;
const OFFSET: [f32; 2] = [0.031, 0.017];
const RADIUS: f32 = 0.3;
const EPSILON: f32 = 0.005;
const FRICTION: f32 = 0.3;
/// The sphere's field: `FIELD_RES`³ cells over [−FIELD_HALF, FIELD_HALF]³, band in cells.
const FIELD_RES: u32 = 128;
const FIELD_HALF: f32 = 0.4;
const FIELD_BAND: f32 = 3.0;

/// H's scene at 16 substeps: the shipped springs (60, 15) halved, which run all 72 frames.
const H_SUBSTEPS: u32 = 16;
const H_K_STRUCTURAL: f32 = 30.0;
const H_K_SHEAR: f32 = 7.5;

pub fn section(root: &Path, repeat: usize) -> String {
    let mut s = String::new();
    let _ = writeln!(s, "## 6. Cloth\n");
    versus_taichi(root, repeat, &mut s);
    harada_scene(root, repeat, &mut s);
    s
}

// ------------------------------------------------------------------ 1. against Taichi

fn comparison_params(n: u32) -> ClothParams {
    let mut p = ClothParams::new(
        Shape::Grid {
            size: [1.0, 1.0],
            resolution: [n, n],
            center: Vec3::new(OFFSET[0], HEIGHT, OFFSET[1]),
            normal: Vec3::Y,
        },
        Material::Harada {
            k_structural: Y_STRAIN,
            k_shear: Y_STRAIN,
            k_bend: None,
        },
    );
    p.stiffness_mode = StiffnessMode::Strain;
    p.mass = 1.0;
    p.damping = DAMPING;
    p.collision.epsilon = EPSILON;
    p.collision.friction = FRICTION;
    p.collision.ground = None;
    p.substeps = SUBSTEPS;
    p
}

/// The sphere's exact field on `res`³ cells over [−FIELD_HALF, FIELD_HALF]³: every cell
/// keeps its true closest point on the sphere.
fn sphere_field(res: u32) -> DistanceField {
    let cell = 2.0 * FIELD_HALF / res as f32;
    let spec = GridSpec::new(
        Vec3::splat(-FIELD_HALF + 0.5 * cell),
        cell,
        UVec3::splat(res),
    )
    .expect("sphere grid");
    DistanceField::from_closest_points(spec, FIELD_BAND, |p| {
        let l = p.length();
        if l > 0.0 {
            RADIUS * p / l
        } else {
            Vec3::new(RADIUS, 0.0, 0.0)
        }
    })
}

/// One imprint run of the comparison scene.
struct ImprintRun {
    total_ms: f64,
    frame_ms: Vec<f64>,
    mean_height: f64,
    /// Smallest |x| − r over the particles after the last frame.
    min_distance: f32,
    /// Largest over the frames of `inside` and `close_max_depth`.
    inside: u32,
    close_max_depth: f32,
    max_strain: f32,
    /// The one-time computation of the field's cells (`DistanceField::cells`), timed apart
    /// on a copy (when asked).
    cells_ms: Vec<f64>,
}

/// `field` None: the same cloth with no collider (springs and integration only: it falls).
/// `measure_cells`: also time, apart and outside `total_ms`, the computation of each field's
/// cells on a copy (use it on the untimed warm-up run).
fn run_imprint(n: u32, field: Option<&DistanceField>, measure_cells: bool) -> ImprintRun {
    let params = comparison_params(n);
    let mut sim = ClothSim::from_assets(&params, &Default::default()).expect("cloth");
    if let Some(w) = sim.stability().warning(SUBSTEPS, 1.0 / FPS) {
        eprintln!("cloth bench: comparison scene N = {n}: {w}");
    }
    let mut frame_ms = Vec::with_capacity(FRAMES as usize);
    let (mut inside, mut close, mut strain) = (0u32, 0f32, 0f32);
    let fields: Vec<&DistanceField> = field.into_iter().collect();
    let cells_ms: Vec<f64> = fields
        .iter()
        .filter(|_| measure_cells)
        .map(|f| time_cells(f.spec.dims.x))
        .collect();
    let mut total_ms = 0.0;
    for f in 0..FRAMES {
        let t = Instant::now();
        let m = sim
            .step_frame(&fields, &fields, f, 1.0 / FPS)
            .expect("comparison scene stays stable");
        let ms = t.elapsed().as_secs_f64() * 1e3;
        frame_ms.push(ms);
        total_ms += ms;
        inside = inside.max(m.inside);
        close = close.max(m.close_max_depth);
        strain = strain.max(m.max_strain);
    }
    let pos = sim.positions();
    ImprintRun {
        total_ms,
        frame_ms,
        mean_height: pos.iter().map(|p| p.y as f64).sum::<f64>() / pos.len() as f64,
        min_distance: pos
            .iter()
            .map(|p| p.length() - RADIUS)
            .fold(f32::INFINITY, f32::min),
        inside,
        close_max_depth: close,
        max_strain: strain,
        cells_ms,
    }
}

/// Times [`DistanceField::cells`], the per-cell vectors the cloth reads, computed once per
/// field: on the sphere's field at `res`³ built afresh (a copy would not know its band spans,
/// and would compute every cell), ms.
fn time_cells(res: u32) -> f64 {
    let fresh = sphere_field(res);
    let t = Instant::now();
    std::hint::black_box(fresh.cells());
    t.elapsed().as_secs_f64() * 1e3
}

/// Runs `benches/compare/cloth_taichi.py` (found the way `baselines()` finds baselines.py:
/// `python3`, which re-executes itself under install.sh's venv) and returns its JSON.
fn run_taichi(
    root: &Path,
    n: u32,
    repeat: usize,
    f64_reference: bool,
) -> Result<serde_json::Value, String> {
    let script = root.join("benches/compare/cloth_taichi.py");
    let out = std::env::temp_dir().join(format!(
        "imprint-cloth-taichi-{}-{n}{}.json",
        std::process::id(),
        if f64_reference { "-f64" } else { "" }
    ));
    let mut cmd = std::process::Command::new("python3");
    cmd.arg(&script)
        .args(["--n", &n.to_string()])
        .args(["--frames", &FRAMES.to_string()])
        .args(["--fps", &FPS.to_string()])
        .args(["--substeps", &SUBSTEPS.to_string()])
        .args(["--stiffness", &Y_STRAIN.to_string()])
        .args(["--mass", "1"])
        .args(["--damping", &DAMPING.to_string()])
        .args(["--height", &HEIGHT.to_string()])
        .args(["--offset-x", &OFFSET[0].to_string()])
        .args(["--offset-z", &OFFSET[1].to_string()])
        .args(["--radius", &RADIUS.to_string()])
        .args(["--epsilon", &EPSILON.to_string()])
        .args(["--friction", &FRICTION.to_string()])
        .args(["--repeat", &repeat.to_string()])
        .args(["--out", out.to_str().expect("utf-8 temp path")]);
    if f64_reference {
        cmd.arg("--f64");
    }
    let o = cmd
        .output()
        .map_err(|e| format!("`python3 {}`: {e}", script.display()))?;
    let json = std::fs::read(&out)
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok());
    let _ = std::fs::remove_file(&out);
    match json {
        Some(j) if o.status.success() => Ok(j),
        _ => Err(format!(
            "`python3 {}` failed ({}): {} (run benches/compare/install.sh)",
            script.display(),
            o.status,
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .unwrap_or("")
        )),
    }
}

fn versus_taichi(root: &Path, repeat: usize, s: &mut String) {
    let runs = repeat.clamp(1, 7);
    let _ = writeln!(
        s,
        "### 6.1 Against Taichi (CPU), same model, same run\n\n\
         An N×N cloth 1 m wide, structural + shear springs f = Y (l/l0 − 1) with Y = {Y_STRAIN:.0e} \
         (imprint: `stiffness_mode: Strain`, Harada k_structural = k_shear = Y), particle mass 1, \
         Verlet damping {DAMPING}, dropped flat from y = {HEIGHT} onto a sphere of radius \
         {RADIUS} at the origin, cloth centre offset ({}, {}) in x/z, ε = {EPSILON}, friction \
         b = {FRICTION}, {FPS} frames/s × {SUBSTEPS} substeps, gravity −9.81, {FRAMES} frames \
         (1 s). Imprint reads the sphere from an exact distance field over \
         [−{FIELD_HALF}, {FIELD_HALF}]³ (**field** {FIELD_RES}³ cells of {:.2} mm, the \
         benchmark; {}³ cells of {:.2} mm to show what the field's size costs), band \
         {FIELD_BAND} cells, built once outside the timing, as are its per-cell vectors \
         (`DistanceField::cells`, computed on the field's first read, in the warm-up run, and \
         kept with it: the sphere does not move). Taichi (`ti.init(arch=ti.cpu)`, \
         `benches/compare/cloth_taichi.py`, one kernel call per substep) tests the analytic \
         sphere with the same projection and friction (imprint's `contact::respond`). \
         **ms/frame** = total time of the {FRAMES} frames / {FRAMES}, median of {runs} runs \
         after one warm-up run (imprint) or after one untimed frame for the JIT compile \
         (Taichi); **median frame** = median single frame of the last run; **ns/p·s** = \
         ms/frame / (N² × {SUBSTEPS}). Heights are the mean y of the cloth after the last \
         frame; **Δh** = imprint − Taichi (both f32), and in brackets \
         Taichi f32 − Taichi f64 (the same script with `--f64`, one run): how far f32 \
         rounding alone moves this drape. Contact error (imprint, worst frame): `inside` = \
         most particles found inside the sphere in one substep, `close_max_depth` = how far \
         any particle was left closer than ε after a frame, and the largest spring strain; \
         **min gap** = smallest |x| − r at the end (ε = {EPSILON}). Goal (issue): ≤ 10 ns per \
         particle-substep with the distance-field collider and ≥ 4× faster than Taichi.\n",
        OFFSET[0],
        OFFSET[1],
        2e3 * FIELD_HALF / FIELD_RES as f32,
        FIELD_RES / 2,
        4e3 * FIELD_HALF / FIELD_RES as f32,
    );
    let _ = writeln!(
        s,
        "| N | particles | field | imprint ms/frame | median frame | imprint ns/p·s | Taichi ms/frame | median frame | Taichi ns/p·s | Taichi ms / imprint ms (goal ≥ 4) | imprint mean h | Taichi mean h | Δh mm [f32 − f64] | imprint inside / close_max_depth / max strain | min gap imprint / Taichi |"
    );
    let _ = writeln!(
        s,
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    let fields = [sphere_field(FIELD_RES), sphere_field(FIELD_RES / 2)];
    let mut version = String::from("unavailable");
    let mut breakdown = Vec::new();
    for n in [64u32, 128] {
        let particle_substeps = (n * n * SUBSTEPS) as f64;
        let taichi = run_taichi(root, n, runs, false);
        let reference = run_taichi(root, n, 1, true);
        let f = |j: &serde_json::Value, k: &str| j[k].as_f64().unwrap_or(f64::NAN);
        if let Err(e) = &taichi {
            eprintln!("cloth: Taichi N = {n}: {e}");
        }
        // Where the time goes: the same cloth with no collider.
        let free = median(
            (0..runs)
                .map(|_| run_imprint(n, None, false).total_ms / FRAMES as f64)
                .collect(),
        );
        breakdown.push(format!(
            "N = {n}: with no collider {:.1} ns/p·s ({free:.2} ms/frame)",
            free * 1e6 / particle_substeps
        ));
        for field in &fields {
            let res = field.spec.dims.x;
            let warm = run_imprint(n, Some(field), true);
            let mut last = None;
            let mut totals = Vec::new();
            for _ in 0..runs {
                let r = run_imprint(n, Some(field), false);
                totals.push(r.total_ms / FRAMES as f64);
                last = Some(r);
            }
            let r = last.expect("at least one run");
            let ours = median(totals);
            let ours_frame = median(r.frame_ms.clone());
            eprintln!("cloth: imprint N = {n}, field {res}³: {ours:.2} ms/frame");
            let once = warm.cells_ms.iter().sum::<f64>();
            let rest = ours - free;
            breakdown.push(format!(
                "N = {n}, field {res}³: {rest:.2} ms ({:.1} ns per particle-substep) for reading \
                 the field and the contact response, and the field's cells {once:.1} ms once",
                rest * 1e6 / particle_substeps
            ));
            let (t_cols, ratio, t_h, dh, t_gap) = match &taichi {
                Ok(j) => {
                    version = format!(
                        "Taichi {} (Python {}, {} threads)",
                        j["taichi_version"].as_str().unwrap_or("?"),
                        j["python_version"].as_str().unwrap_or("?"),
                        j["threads"]
                    );
                    let spread = match &reference {
                        Ok(r64) => format!(
                            " [{:+.2}]",
                            1e3 * (f(j, "mean_height") - f(r64, "mean_height"))
                        ),
                        Err(_) => String::new(),
                    };
                    (
                        format!(
                            "{:.2} | {:.2} | {:.1}",
                            f(j, "ms_per_frame"),
                            f(j, "median_frame_ms"),
                            f(j, "ns_per_particle_substep")
                        ),
                        format!("{:.2}×", f(j, "ms_per_frame") / ours),
                        format!("{:.4}", f(j, "mean_height")),
                        format!(
                            "{:+.2}{spread}",
                            1e3 * (r.mean_height - f(j, "mean_height"))
                        ),
                        format!("{:.5}", f(j, "min_sphere_distance")),
                    )
                }
                Err(e) => (
                    format!("not run: {e} | | "),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                    "–".into(),
                ),
            };
            let _ = writeln!(
                s,
                "| {n} | {} | {res}³ | {ours:.2} | {ours_frame:.2} | {:.1} | {t_cols} | {ratio} | {:.4} | {t_h} | {dh} | {} / {:.1e} / {:.3} | {:.5} / {t_gap} |",
                n * n,
                ours * 1e6 / particle_substeps,
                r.mean_height,
                r.inside,
                r.close_max_depth,
                r.max_strain,
                r.min_distance,
            );
        }
    }
    let _ = writeln!(
        s,
        "\nWhere imprint's time goes: the same cloth with no collider (median of {runs} runs), \
         what the collider adds to it, and what the field's per-cell vectors cost once \
         (`DistanceField::cells`, outside the timed runs; timed apart on a field built \
         afresh): {}.\n\n\
         Versions: {version}.\n",
        breakdown.join("; ")
    );
}

// ------------------------------------------------------------------ 2. H's scene

/// Per-frame stage times of one run of H's scene, and its cloth metrics.
#[derive(Default)]
struct SceneRun {
    mesh: Vec<f64>,
    voxelise: Vec<f64>,
    field: Vec<f64>,
    cloth: Vec<f64>,
    inside: u32,
    close_max_depth: f32,
    max_strain: f32,
    band_misses: u32,
    contacts_last: u32,
    boundary_points: usize,
    /// The cloth's error when it blew up (the run stops there).
    failed: Option<String>,
    /// Per frame, the new field's cells (`DistanceField::cells`), timed apart before the
    /// cloth reads them.
    fill_ms: Vec<f64>,
}

/// Runs the pipeline's bunny, boundary, field and cloth nodes frame by frame, as the
/// executor does (CPU backend), timing each stage.
/// `measure_fills`: also time the cache fills apart (outside the cloth's time; the run gets
/// slower, so use it on the untimed warm-up run).
fn run_scene(plan: &imprint_graph::Plan, measure_fills: bool) -> SceneRun {
    let node = |name: &str| &plan.file.nodes[name];
    let NodeSpec::Mesh(mesh_params) = node("bunny") else {
        panic!("harada_cloth.ron: 'bunny' is not a Mesh node")
    };
    let NodeSpec::Voxelize(vox_node) = node("boundary") else {
        panic!("harada_cloth.ron: 'boundary' is not a Voxelize node")
    };
    let NodeSpec::DistanceField(field_node) = node("field") else {
        panic!("harada_cloth.ron: 'field' is not a DistanceField node")
    };
    let NodeSpec::Cloth(cloth_node) = node("cloth") else {
        panic!("harada_cloth.ron: 'cloth' is not a Cloth node")
    };
    let frames = plan.file.frames;
    let fps = plan.file.fps;
    let source = MeshSource::new(mesh_params, &plan.base_dir).expect("bunny");
    // The executor's fitted grid: the box the mesh sweeps over the run.
    let step = frames.div_ceil(64).max(1) as usize;
    let times = (0..frames)
        .step_by(step)
        .chain([frames - 1])
        .map(|f| f as f32 / fps);
    let GridChoice::Fit {
        resolution,
        padding,
    } = vox_node.grid
    else {
        panic!("harada_cloth.ron: the boundary grid is not Fit")
    };
    let spec = GridSpec::fit(&source.sampled_bounds(times), resolution, padding).expect("grid");
    let mut vox = Voxelizer::new(spec).expect("voxeliser");
    let mut builder = FieldBuilder::default();
    let mut sim = ClothSim::new(&cloth_node.params, &plan.base_dir).expect("cloth");
    let mut run = SceneRun::default();
    let mut previous: Option<Arc<DistanceField>> = None;
    let ms = |t: Instant| t.elapsed().as_secs_f64() * 1e3;
    for f in 0..frames {
        let t = Instant::now();
        let mesh = source.at(f as f32 / fps);
        run.mesh.push(ms(t));
        let t = Instant::now();
        let boundary = vox.run(&mesh, vox_node.variant).expect("voxelise");
        run.voxelise.push(ms(t));
        run.boundary_points = boundary.len();
        let t = Instant::now();
        let field = Arc::new(builder.build(&boundary, field_node.band).expect("field"));
        run.field.push(ms(t));
        let start: Vec<&DistanceField> = previous.iter().map(|f| &**f).collect();
        if measure_fills {
            // On the field itself, as the cloth's first read computes them (into the cells
            // of the field recycled before it, its band spans only; a copy has no spare and
            // computes every cell): the step below then finds them computed.
            let t = Instant::now();
            std::hint::black_box(field.cells());
            run.fill_ms.push(ms(t));
        }
        let t = Instant::now();
        let m = match sim.step_frame(&start, &[&field], f, 1.0 / fps) {
            Ok(m) => m,
            Err(e) => {
                run.failed = Some(e.to_string());
                let done = run.cloth.len();
                run.mesh.truncate(done);
                run.voxelise.truncate(done);
                run.field.truncate(done);
                break;
            }
        };
        let _mesh = sim.to_mesh();
        run.cloth.push(ms(t));
        run.inside = run.inside.max(m.inside);
        run.close_max_depth = run.close_max_depth.max(m.close_max_depth);
        run.max_strain = run.max_strain.max(m.max_strain);
        run.band_misses += m.band_misses;
        run.contacts_last = m.contacts;
        // Two frames back is held by nobody now: its buffers go to the next build.
        if let Some(old) = previous
            .replace(field)
            .and_then(|f| Arc::try_unwrap(f).ok())
        {
            builder.recycle(old);
        }
    }
    run
}

fn harada_scene(root: &Path, repeat: usize, s: &mut String) {
    let path = root.join("pipelines/harada_cloth.ron");
    let runs = repeat.clamp(1, 5);
    let configs: [(&str, Vec<String>); 3] = [
        (
            "benchmark: H's substeps, springs halved",
            vec![
                format!("cloth.params.substeps={H_SUBSTEPS}"),
                format!(
                    "cloth.params.material=Harada(k_structural: {H_K_STRUCTURAL}, k_shear: {H_K_SHEAR})"
                ),
            ],
        ),
        (
            "H's substeps, shipped springs k 60 / 15",
            vec![format!("cloth.params.substeps={H_SUBSTEPS}")],
        ),
        ("as shipped", vec![]),
    ];
    let shipped = match imprint_graph::load(&path, &[]) {
        Ok(p) => p,
        Err(e) => {
            let _ = writeln!(
                s,
                "### 6.2 H's scene\n\n{} failed to load: {e}",
                path.display()
            );
            return;
        }
    };
    let shipped_substeps = match shipped.file.nodes.get("cloth") {
        Some(NodeSpec::Cloth(c)) => c.params.substeps,
        _ => 0,
    };
    let _ = writeln!(
        s,
        "### 6.2 H's scene: the breathing, twisting bunny under a 70×70 cloth\n\n\
         `pipelines/harada_cloth.ron` loaded with `imprint_graph::load` (overrides as \
         `--set` takes them), then its `bunny`, `boundary`, `field` and `cloth` nodes run \
         frame by frame on the CPU with the executor's calls (`MeshSource::at`, \
         `Voxelizer::run`, `FieldBuilder::build` with buffers recycled, \
         `ClothSim::step_frame` blending the previous and current fields, `to_mesh`); the \
         render and OBJ writer nodes are left out. Bunny (69,451 triangles) fitted to size 1 \
         at (0, 0.5, 0), breathing 5% and twisting 30° with a 2 s period; 128³ field \
         (Closest, band 3) rebuilt every frame; 4,900 particles, mass 1 g, damping 0.995, \
         ε = 0.008, friction 0.3, ground y = 0; {} frames at {} fps. Three configurations: \
         (1) the benchmark: H's {H_SUBSTEPS} substeps with the shipped springs halved, \
         k_structural = {H_K_STRUCTURAL}, k_shear = {H_K_SHEAR} N/m, which run all frames; \
         (2) H's {H_SUBSTEPS} substeps with the shipped springs (60 / 15 N/m); (3) the file \
         as shipped ({shipped_substeps} substeps). **warning** is imprint's stability estimate \
         for the springs (the warning `imprint run` prints on stderr; none = the springs alone \
         are within their stable step); a run that blows up stops with the `Error::Numerical` \
         shown, and its times are those of the frames before. Times are per frame: the \
         median over frames \
         1… of {runs} runs (frame 0 builds everything cold and has no previous field), mean \
         in brackets. Goal (issue): ≤ 12.5 ms per frame for voxelise + field + cloth (H: 63 \
         ms per frame on a GeForce 7800 GTX). Contact error, worst frame: `inside`, `close_max_depth` \
         (ε = 0.008), max strain, and band misses summed over the run. **of which field \
         cells** = the per-cell vectors of the frame's new field (`DistanceField::cells`, \
         computed once per field when the cloth first reads it, and reused next frame as the \
         blend's start), timed apart in the warm-up run on the field itself just before the \
         cloth reads it, so computed as in the run (into the buffer of the field recycled \
         before it; same statistics).\n",
        shipped.file.frames, shipped.file.fps,
    );
    let mut table = String::new();
    let _ = writeln!(
        table,
        "| configuration | warning | mesh ms | voxelise ms | field ms | cloth ms | voxelise + field + cloth ms | cloth ns/p·s | of which field cells ms | inside / close_max_depth / max strain / band misses | contacts at end |"
    );
    let _ = writeln!(
        table,
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
    );
    for (label, overrides) in &configs {
        let plan = match imprint_graph::load(&path, overrides) {
            Ok(p) => p,
            Err(e) => {
                let _ = writeln!(
                    table,
                    "| {label} | pipeline failed to load: {e} | | | | | | | | | |"
                );
                continue;
            }
        };
        let NodeSpec::Cloth(c) = &plan.file.nodes["cloth"] else {
            panic!("harada_cloth.ron: 'cloth' is not a Cloth node")
        };
        let sim = ClothSim::new(&c.params, &plan.base_dir).expect("cloth");
        let warning = sim
            .stability()
            .warning(c.params.substeps, 1.0 / plan.file.fps)
            .map_or("none".to_string(), |w| format!("**{w}**"));
        let est = *sim.stability();
        drop(sim);
        let mut pooled = SceneRun::default();
        let warm = run_scene(&plan, true);
        let fills = warm.fill_ms[1.min(warm.fill_ms.len())..].to_vec();
        // A run that blows up does so on the same substep every time (the simulator is
        // deterministic): its times are the warm-up run's, up to that frame.
        let measured: Vec<SceneRun> = if warm.failed.is_some() {
            vec![warm]
        } else {
            (0..runs).map(|_| run_scene(&plan, false)).collect()
        };
        for r in &measured {
            let from = 1.min(r.cloth.len());
            pooled.mesh.extend(&r.mesh[from..]);
            pooled.voxelise.extend(&r.voxelise[from..]);
            pooled.field.extend(&r.field[from..]);
            pooled.cloth.extend(&r.cloth[from..]);
        }
        let r = measured.last().expect("at least one run");
        let warning = match &r.failed {
            Some(e) => format!("{warning}; **blew up: {e}**"),
            None => warning,
        };
        let sum: Vec<f64> = (0..pooled.cloth.len())
            .map(|i| pooled.voxelise[i] + pooled.field[i] + pooled.cloth[i])
            .collect();
        let cell = |v: &[f64]| {
            format!(
                "{:.2} ({:.2})",
                median(v.to_vec()),
                v.iter().sum::<f64>() / v.len().max(1) as f64
            )
        };
        let (ks, kh) = match c.params.material {
            Material::Harada {
                k_structural,
                k_shear,
                ..
            } => (k_structural, k_shear),
            _ => (f32::NAN, f32::NAN),
        };
        let cloth_ns = median(pooled.cloth.clone()) * 1e6 / (4900.0 * c.params.substeps as f64);
        let _ = writeln!(
            table,
            "| {label}: k {ks} / {kh} N/m, {} substeps of {:.2e} s (estimated stable step {:.2e} s) | {warning} | {} | {} | {} | {} | {} | {cloth_ns:.1} | {} | {} / {:.1e} / {:.3} / {} | {} |",
            c.params.substeps,
            1.0 / (plan.file.fps * c.params.substeps as f32),
            est.dt_crit,
            cell(&pooled.mesh),
            cell(&pooled.voxelise),
            cell(&pooled.field),
            cell(&pooled.cloth),
            cell(&sum),
            cell(&fills),
            r.inside,
            r.close_max_depth,
            r.max_strain,
            r.band_misses,
            r.contacts_last,
        );
        eprintln!(
            "cloth: H's scene, {label}: {:.2} ms/frame (voxelise + field + cloth), {} boundary points",
            median(sum),
            r.boundary_points
        );
    }
    s.push_str(&table);
}
