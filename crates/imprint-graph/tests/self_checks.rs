//! Never silent, every stage: after each frame the ground, snow, drape and skin nodes check
//! themselves. A broken state stops the run with `Error::Numerical` naming the node and the
//! frame; a known approximation is counted per frame in the report and warned about once.
//! The shipped pipelines trip none of it.
//!
//! States no correct run makes are made by damaging a checkpoint (the stage's saved state,
//! decoded, changed and put back) or by changing an asset under `--resume`.

use glam::{Mat4, Vec3};
use imprint_core::Mesh;
use imprint_core::mesh::primitives::cuboid;
use imprint_graph::exec::{RunOptions, run};
use imprint_graph::report::Report;
use imprint_graph::value::ValuesSnapshot;
use imprint_graph::{Plan, load};
use imprint_stages::skin::particles::ParticleSkin;
use imprint_stages::snow::SnowSim;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod common;
use common::plan;

fn opts(out: &Path, frames: std::ops::Range<u32>) -> RunOptions {
    RunOptions {
        out: out.to_path_buf(),
        frames: Some(frames),
        ..Default::default()
    }
}

/// The run's error, which must be `Error::Numerical` of `node` at `frame`; returns its message.
fn numerical(r: imprint_graph::Result<Report>, node: &str, frame: u32) -> String {
    let (f, message) = numerical_at(r, node);
    assert_eq!(f, frame, "{message}");
    message
}

/// The run's error, which must be `Error::Numerical` of `node`; returns its frame and message.
fn numerical_at(r: imprint_graph::Result<Report>, node: &str) -> (u32, String) {
    match r {
        Err(imprint_graph::Error::Core(imprint_core::Error::Numerical {
            node: n,
            frame,
            message,
            hint,
        })) => {
            assert_eq!(n, node, "{message} (try: {hint})");
            assert!(!hint.is_empty());
            (frame, message)
        }
        Err(e) => panic!("expected a numerical error of '{node}', got: {e}"),
        Ok(_) => panic!("expected a numerical error of '{node}', the run passed"),
    }
}

/// The run-time warnings the report holds for `node` (each once).
fn node_warnings<'a>(r: &'a Report, node: &str) -> Vec<&'a String> {
    let prefix = format!("node '{node}': ");
    r.warnings
        .iter()
        .filter(|w| w.starts_with(&prefix))
        .collect()
}

fn per_frame<'a>(r: &'a Report, node: &str) -> &'a Vec<serde_json::Value> {
    r.nodes[node].metrics["per_frame"].as_array().unwrap()
}

// ---- damaging a checkpoint --------------------------------------------------------------

/// `imprint_graph::executor::Checkpoint`'s fields, in order (postcard is positional).
#[derive(Serialize, Deserialize)]
struct CheckpointFields {
    identity: String,
    first: u32,
    next: u32,
    versions: BTreeMap<String, u64>,
    seen: BTreeMap<String, Option<Vec<u64>>>,
    values: ValuesSnapshot,
    stages: BTreeMap<String, Vec<u8>>,
    report: String,
    observer: Vec<u8>,
}

/// Changes node `node`'s saved state in the checkpoint of `dir` with `edit`.
fn damage(dir: &Path, node: &str, edit: impl FnOnce(&[u8]) -> Vec<u8>) {
    let path = dir.join("checkpoint.bin");
    let bytes = std::fs::read(&path).unwrap();
    let body = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
    let mut c: CheckpointFields = postcard::from_bytes(&bytes[body..]).unwrap();
    let state = c.stages.get_mut(node).unwrap();
    *state = edit(state);
    let mut out = bytes[..body].to_vec();
    out.extend(postcard::to_allocvec(&c).unwrap());
    std::fs::write(&path, out).unwrap();
}

/// Edits a serde value through its JSON form.
fn edit_json<T: Serialize + for<'de> Deserialize<'de>>(
    v: &T,
    edit: impl FnOnce(&mut serde_json::Value),
) -> T {
    let mut j = serde_json::to_value(v).unwrap();
    edit(&mut j);
    serde_json::from_value(j).unwrap()
}

/// Runs `p` for `frames` frames keeping a checkpoint in `dir`, damages `node`'s state with
/// `edit`, and resumes for two more frames.
fn resume_damaged(
    p: &Plan,
    dir: &Path,
    frames: u32,
    node: &str,
    edit: impl FnOnce(&[u8]) -> Vec<u8>,
) -> imprint_graph::Result<Report> {
    let mut o = opts(dir, 0..frames);
    o.checkpoint_every = 1;
    run(p, &o, &mut |_, _| {}).unwrap();
    damage(dir, node, edit);
    let mut o = opts(dir, 0..frames + 2);
    o.resume = true;
    run(p, &o, &mut |_, _| {})
}

// ---- ground -----------------------------------------------------------------------------

/// A dragged box's heap leans on the box's held front face and stands taller than the start
/// height plus the box (`tests/tests/ground_settle.rs`): counted per frame, warned once, the
/// run goes on.
#[test]
fn ground_above_the_tallest_object_is_counted_and_warned_once() {
    // The scene of ground_settle.rs: a box 0.5 x 0.12 x 0.2 pressed 0.08 into sand 0.15
    // deep, dragged 0.45 m along x over 24 frames, under O's labelled passes (the default
    // settle spills what rises above the box over it, and stays within the bound).
    let p = plan(
        24,
        r#""box": Mesh(primitive: Box(size: (0.5, 0.12, 0.2), subdivisions: 1),
                      fit: (size: 0.5, center: (-0.225, 0.13, 0)),
                      motion: [Rigid(keys: [(time: 0.0), (time: 0.958333, translate: (0.45, 0, 0))])]),
           "sand": Ground(objects: ["box"], params: (size: (1.2, 1.2), resolution: (240, 240),
                          initial: Flat(0.15), material: Preset(Sand), relaxation: Labelled)),
           "out": WriteHeightmap(heights: "sand", formats: [Exr], every: 100),"#,
    );
    let dir = tempfile::tempdir().unwrap();
    let r = run(&p, &opts(dir.path(), 0..24), &mut |_, _| {}).unwrap();
    let above: Vec<u64> = per_frame(&r, "sand")
        .iter()
        .map(|f| f["above_bound_cells"].as_u64().unwrap())
        .collect();
    assert!(above.iter().any(|&n| n > 0), "{above:?}");
    let frames = above.iter().filter(|&&n| n > 0).count() as u64;
    assert_eq!(r.nodes["sand"].metrics["frames_above_bound"], frames);
    let w = node_warnings(&r, "sand");
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("above_bound_cells"), "{}", w[0]);
    assert_eq!(r.nodes["sand"].warnings.len(), 1);
}

/// A ground's heights above anything its frames could raise: the initial height image was
/// changed under `--resume` (the checkpoint's heights are the old image's).
#[test]
fn ground_above_what_frames_could_raise_stops_the_run() {
    let dir = tempfile::tempdir().unwrap();
    let image = dir.path().join("start.png");
    let n = 32;
    let field = |h: &dyn Fn(u32, u32) -> f32| {
        let heights = (0..n * n).map(|j| h(j % n, j / n)).collect();
        imprint_core::HeightField::new(glam::Vec2::ZERO, 0.01, glam::UVec2::new(n, n), heights)
            .unwrap()
    };
    let write = |hf: &imprint_core::HeightField| {
        imprint_render::heightmap::write_heightmap_png16(&image, hf).unwrap()
    };
    write(&field(&|i, _| i as f32));
    let p = plan(
        8,
        &format!(
            r#""ground": Ground(params: (size: (0.32, 0.32), resolution: ({n}, {n}),
                   initial: Image(path: {:?}, scale: 0.2), material: Preset(Snow))),
               "out": WriteHeightmap(heights: "ground", formats: [Exr], every: 100),"#,
            image.display().to_string()
        ),
    );
    let out = dir.path().join("run");
    let mut o = opts(&out, 0..2);
    o.checkpoint_every = 1;
    run(&p, &o, &mut |_, _| {}).unwrap();
    // A flat black image: the start is 0 m high everywhere now.
    write(&field(&|_, _| 0.0));
    let mut o = opts(&out, 0..4);
    o.resume = true;
    let m = numerical(run(&p, &o, &mut |_, _| {}), "ground", 2);
    assert!(m.contains("above anything the frames could raise"), "{m}");
}

// ---- snow -------------------------------------------------------------------------------

fn snow_plan() -> Plan {
    plan(
        8,
        r#""ball": Mesh(primitive: Sphere(radius: 0.2, segments: 16, rings: 8),
                       fit: (size: 0.4, center: (0, 0.3, 0))),
           "snow": Snow(meshes: ["ball"], ground: (size: (1.0, 1.0), resolution: (32, 32)),
                        params: (directions: 4, resolution: 64, rate: 0.05)),
           "ground": Ground(objects: [], accumulate: "snow",
                            params: (size: (1.0, 1.0), resolution: (32, 32), initial: Flat(0.0),
                                     material: Preset(Snow))),
           "snowy": Snow(meshes: ["ball"], params: (directions: 4, resolution: 64, rate: 0.05)),
           "out": WriteHeightmap(heights: "ground", formats: [Exr], every: 100),
           "mesh_out": WriteMesh(mesh: "snowy", every: 100),"#,
    )
}

/// Damages a snow node's saved `SnowSim` with `edit` (on its JSON form).
fn snow_edit(edit: impl FnOnce(&mut serde_json::Value)) -> impl FnOnce(&[u8]) -> Vec<u8> {
    |bytes| {
        let sim: SnowSim = postcard::from_bytes(bytes).unwrap();
        postcard::to_allocvec(&edit_json(&sim, edit)).unwrap()
    }
}

#[test]
fn snow_deeper_than_what_fell_stops_the_run() {
    let p = snow_plan();
    // A mesh vertex 1 m deep after 3 frames of 0.05 m/s.
    let dir = tempfile::tempdir().unwrap();
    let r = resume_damaged(
        &p,
        dir.path(),
        3,
        "snowy",
        snow_edit(|j| j["meshes"][0][5] = 1.0.into()),
    );
    let m = numerical(r, "snowy", 3);
    assert!(
        m.contains("vertex 5") && m.contains("more than fell"),
        "{m}"
    );
    // More snow on the ground than fell on it: a quantum column added to one cell.
    let dir = tempfile::tempdir().unwrap();
    let r = resume_damaged(
        &p,
        dir.path(),
        3,
        "snow",
        snow_edit(|j| {
            let u = &mut j["ground"]["units"][100];
            *u = (u.as_u64().unwrap() + 1000).into();
        }),
    );
    let m = numerical(r, "snow", 3);
    assert!(m.contains("the ground holds"), "{m}");
}

// ---- skin -------------------------------------------------------------------------------

fn skin_plan(params: &str) -> Plan {
    plan(
        6,
        &format!(
            r#""limb": Mesh(primitive: Cylinder(radius: 0.1, length: 1.0, segments: 16, rings: 8)),
               "skin": Skin(mesh: "limb", rig: "../../assets/rigs/limb.ron", method: Particles({params})),
               "out": WriteMesh(mesh: "skin", every: 100),"#
        ),
    )
}

/// A particle a damaged checkpoint put 5 m from its bone: named before the frame's substeps.
#[test]
fn skin_particle_beyond_its_reach_stops_the_run() {
    let p = skin_plan("");
    let dir = tempfile::tempdir().unwrap();
    let r = resume_damaged(&p, dir.path(), 2, "skin", |bytes| {
        type Saved = (
            Option<Arc<Mesh>>,
            Option<ParticleSkin>,
            Option<Vec<glam::Affine3A>>,
        );
        let (rest, skin, last): Saved = postcard::from_bytes(bytes).unwrap();
        let skin = edit_json(skin.as_ref().unwrap(), |j| {
            for key in ["x", "xa"] {
                let x = &mut j[key][7][1];
                *x = (x.as_f64().unwrap() + 5.0).into();
            }
        });
        postcard::to_allocvec(&(rest, Some(skin), last)).unwrap()
    });
    let m = numerical(r, "skin", 2);
    assert!(
        m.contains("particle 7") && m.contains("beyond the reach"),
        "{m}"
    );
}

/// A time step past the stable limit: the substeps' test stops the run, naming the node.
#[test]
fn skin_blow_up_stops_the_run() {
    let p = skin_plan("substeps: 1, stiffness: 4000000");
    let dir = tempfile::tempdir().unwrap();
    let (frame, m) = numerical_at(run(&p, &opts(dir.path(), 0..6), &mut |_, _| {}), "skin");
    assert!(frame < 6 && m.contains("blew up"), "frame {frame}: {m}");
    // The report written on failure says so too.
    let report = std::fs::read_to_string(dir.path().join("report.json")).unwrap();
    assert!(report.contains("blew up"), "{report}");
}

// ---- drape ------------------------------------------------------------------------------

/// A body whose views cannot push a point out of its middle: a box with a slab above, below,
/// in front and behind, so that every push from the middle crosses three surfaces.
fn boxed_in(dir: &Path) -> PathBuf {
    let part = |half: Vec3, c: Vec3| {
        let mut m = cuboid(half, 2);
        m.transform(Mat4::from_translation(c));
        m
    };
    let mut body = part(Vec3::splat(0.3), Vec3::ZERO);
    for s in [-1.0f32, 1.0] {
        body.append(&part(
            Vec3::new(0.3, 0.05, 0.3),
            Vec3::new(0.0, 0.4 * s, 0.0),
        ));
        body.append(&part(
            Vec3::new(0.3, 0.3, 0.05),
            Vec3::new(0.0, 0.0, 0.4 * s),
        ));
    }
    let path = dir.join("boxed_in.obj");
    imprint_render::mesh_io::write_obj(&path, &body, &Default::default()).unwrap();
    path
}

/// A small sphere garment moving inside the boxed-in body, draped every frame for 4 frames.
fn boxed_in_drape(body: &Path) -> Plan {
    plan(
        4,
        &format!(
            r#""body": Mesh(path: {:?}),
               "coat": Mesh(primitive: Sphere(radius: 0.05, segments: 8, rings: 4),
                            motion: [Rigid(keys: [(time: 0.0), (time: 1.0, translate: (0.05, 0, 0))])]),
               "fit": Drape(body: "body", garment: "coat", params: (resolution: 64)),
               "out": WriteMesh(mesh: "fit", every: 1),"#,
            body.display().to_string()
        ),
    )
}

/// Garment vertices left inside the body (no view resolves them, no fallback): counted per
/// frame and in all, warned once over a run that drapes every frame.
#[test]
fn drape_vertices_left_inside_are_counted_and_warned_once() {
    let dir = tempfile::tempdir().unwrap();
    let body = boxed_in(dir.path());
    let p = boxed_in_drape(&body);
    let r = run(&p, &opts(&dir.path().join("run"), 0..4), &mut |_, _| {}).unwrap();
    let inside: Vec<u64> = per_frame(&r, "fit")
        .iter()
        .map(|f| f["inside_after"].as_u64().unwrap())
        .collect();
    assert_eq!(inside.len(), 4, "the garment moves: it drapes every frame");
    assert!(inside.iter().all(|&n| n > 0), "{inside:?}");
    assert_eq!(
        r.nodes["fit"].metrics["inside_after"],
        inside.iter().sum::<u64>()
    );
    let w = node_warnings(&r, "fit");
    assert_eq!(w.len(), 1, "{w:?}");
    assert!(w[0].contains("left inside the body"), "{}", w[0]);
}

// ---- warn once across a resume ----------------------------------------------------------

/// A run resumed from a checkpoint does not warn again what its first part warned.
#[test]
fn a_resumed_run_does_not_warn_again() {
    let dir = tempfile::tempdir().unwrap();
    let body = boxed_in(dir.path());
    let p = boxed_in_drape(&body);
    let out = dir.path().join("run");
    let mut o = opts(&out, 0..2);
    o.checkpoint_every = 1;
    run(&p, &o, &mut |_, _| {}).unwrap();
    let mut o = opts(&out, 0..4);
    o.resume = true;
    let r = run(&p, &o, &mut |_, _| {}).unwrap();
    assert_eq!(node_warnings(&r, "fit").len(), 1, "{:?}", r.warnings);
    assert!(node_warnings(&r, "fit")[0].contains("first at frame 0"));
}

// ---- the shipped pipelines --------------------------------------------------------------

fn shipped(name: &str, frames: u32, overrides: &[&str]) -> Report {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../pipelines")
        .join(name);
    let overrides: Vec<String> = overrides.iter().map(|s| s.to_string()).collect();
    let p = load(&path, &overrides).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let mut o = opts(dir.path(), 0..frames);
    o.backend = Some(imprint_graph::node::Backend::Cpu);
    let r = run(&p, &o, &mut |_, _| {}).unwrap_or_else(|e| panic!("{name}: {e}"));
    assert_eq!(r.frames.len(), frames as usize, "{name}");
    r
}

/// What a report counted: every self-check's count over every node, and the run warnings.
fn tripped(r: &Report) -> Vec<String> {
    let mut out: Vec<String> = r.nodes.values().flat_map(|n| n.warnings.clone()).collect();
    for (name, n) in &r.nodes {
        for key in ["frames_above_bound", "frames_over_fallen", "inside_after"] {
            if let Some(v) = n.metrics.get(key) {
                out.push(format!("{name}: {key} = {v}"));
            }
        }
    }
    out
}

const SMALL_RENDER: [&str; 2] = ["render.width=64", "render.height=48"];

#[test]
fn shipped_ground_and_snow_pipelines_trip_no_check() {
    for (name, frames) in [("footprints.ron", 72), ("snowfall.ron", 96)] {
        let r = shipped(name, frames, &SMALL_RENDER);
        assert_eq!(tripped(&r), Vec::<String>::new(), "{name}");
    }
}

#[test]
fn shipped_drape_and_skin_pipelines_trip_no_check() {
    for (name, frames) in [("drape.ron", 24), ("skinning.ron", 60)] {
        let r = shipped(name, frames, &SMALL_RENDER);
        assert_eq!(tripped(&r), Vec::<String>::new(), "{name}");
    }
}

/// A sphere rising 25 mm a frame under a cloth, its field's band 1 cell (about 21 mm): the
/// blend of two frames' fields reads one far and one near, counted as band misses, and the
/// report says once how to fix it. With band 4 there are none, and no warning.
#[test]
fn a_band_narrower_than_the_motion_is_warned_of() {
    let scene = |band: u32| {
        plan(
            24,
            &format!(
                r#""ball": Mesh(primitive: Sphere(radius: 0.3, segments: 32, rings: 16),
                       motion: [Rigid(keys: [(time: 0), (time: 1, translate: (0, 0.6, 0))])]),
           "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 48)),
           "field": DistanceField(boundary: "vox", band: {band}, measure: Never),
           "cloth": Cloth(colliders: ["field"], params: (
               shape: Grid(size: (0.8, 0.8), resolution: (12, 12), center: (0, 0.32, 0)),
               material: Harada(k_structural: 20.0, k_shear: 5.0),
               pins: [Indices([0, 11, 132, 143])],
               collision: (epsilon: 0.01, friction: 0.3),
               substeps: 16)),
           "m": WriteMesh(mesh: "cloth", every: 100),"#
            ),
        )
    };
    for (band, misses) in [(1, true), (4, false)] {
        let dir = tempfile::tempdir().unwrap();
        let r = run(&scene(band), &opts(dir.path(), 0..12), &mut |_, _| {}).unwrap();
        let n: u64 = per_frame(&r, "cloth")
            .iter()
            .map(|f| f["band_misses"].as_u64().unwrap())
            .sum();
        let w = node_warnings(&r, "cloth");
        let warned: Vec<_> = w.iter().filter(|w| w.contains("band misses")).collect();
        assert_eq!(n > 0, misses, "band {band}: {n} band misses");
        assert_eq!(warned.len(), misses as usize, "band {band}: {w:?}");
        if misses {
            assert!(
                warned[0].contains("widen the field's `band`"),
                "{}",
                warned[0]
            );
        }
    }
}
