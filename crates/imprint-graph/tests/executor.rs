//! The executor as an object: stepped frame by frame, reloaded with a changed plan (keeping
//! the state of unchanged nodes), sought back through its checkpoints, and running
//! independent nodes at once with the same bytes as one after the other, on 1 or 2 threads.

use imprint_core::Mesh;
use imprint_graph::exec::RunOptions;
use imprint_graph::value::Value;
use imprint_graph::{Executor, Plan};
use std::path::{Path, PathBuf};
use std::sync::Arc;

mod common;
use common::plan;

fn executor(p: &Plan, out: &Path) -> Executor {
    let opts = RunOptions {
        out: out.to_path_buf(),
        ..Default::default()
    };
    Executor::new(p, opts).unwrap()
}

fn mesh(ex: &Executor, node: &str) -> Arc<Mesh> {
    match ex.value(node) {
        Some(Value::Mesh(m)) => m,
        _ => panic!("'{node}' has no mesh"),
    }
}

fn bits(m: &Mesh) -> Vec<u32> {
    m.positions
        .iter()
        .flat_map(|p| p.to_array())
        .map(f32::to_bits)
        .collect()
}

fn mean_height(m: &Mesh) -> f32 {
    m.positions.iter().map(|p| p.y).sum::<f32>() / m.positions.len() as f32
}

/// A cloth falling freely (no collider) and a render of it in `color`.
fn falling(stiffness: f32, color: &str) -> Plan {
    plan(
        12,
        &format!(
            r#""cloth": Cloth(params: (
                shape: Grid(size: (0.5, 0.5), resolution: (8, 8), center: (0, 1.0, 0), normal: (0, 1, 0)),
                material: Harada(k_structural: {stiffness:?}, k_shear: 5.0), mass: 0.002,
                damping: 0.99, substeps: 8)),
            "render": Render(objects: [Mesh(mesh: "cloth", color: {color})],
                             camera: Orbit(distance: 3.0), width: 32, height: 24, samples: 1),"#
        ),
    )
}

/// Reloading a plan whose render colour changed keeps the cloth falling (the same bytes as a
/// run that was never reloaded); one whose stiffness changed starts the cloth again from rest
/// (the bytes of a new run's first frame), and the render follows it.
#[test]
fn reload_keeps_unchanged_nodes_and_restarts_changed_ones() {
    let dir = tempfile::tempdir().unwrap();
    let base = falling(20.0, "(0.8, 0.4, 0.3)");
    let mut straight = executor(&base, &dir.path().join("a"));
    let mut reloaded = executor(&base, &dir.path().join("b"));
    for _ in 0..5 {
        straight.step().unwrap();
        reloaded.step().unwrap();
    }
    let before = mean_height(&mesh(&reloaded, "cloth"));

    let recoloured = falling(20.0, "(0.2, 0.9, 0.3)");
    let rebuilt = reloaded.reload(&recoloured).unwrap();
    assert_eq!(rebuilt, ["render"]);
    straight.step().unwrap();
    reloaded.step().unwrap();
    assert_eq!(
        bits(&mesh(&straight, "cloth")),
        bits(&mesh(&reloaded, "cloth"))
    );
    assert!(
        mean_height(&mesh(&reloaded, "cloth")) < before,
        "still falling"
    );

    let stiffer = falling(40.0, "(0.2, 0.9, 0.3)");
    let rebuilt = reloaded.reload(&stiffer).unwrap();
    assert_eq!(rebuilt, ["cloth", "render"]);
    reloaded.step().unwrap();
    let mut fresh = executor(&stiffer, &dir.path().join("c"));
    fresh.step().unwrap();
    assert_eq!(
        bits(&mesh(&fresh, "cloth")),
        bits(&mesh(&reloaded, "cloth"))
    );
    assert!(
        mean_height(&mesh(&reloaded, "cloth")) > before,
        "back near the start"
    );
    assert_eq!(reloaded.next_frame(), 7);
    // The render drew the restarted cloth on frame 6.
    assert!(dir.path().join("b/frames/0006.png").exists());
}

/// Two cloths on one sphere's field and two grounds under one ball, with writers: the pairs
/// share a wave (no path joins them), and running the waves' nodes at once on 2 threads, one
/// after the other, or on 1 thread gives the same values and files, byte for byte.
#[test]
fn concurrent_nodes_equal_sequential_ones() {
    let scene = plan(
        8,
        r#""ball": Mesh(primitive: Sphere(radius: 0.2, segments: 16, rings: 8),
                        fit: (size: 0.4, center: (0, 0.2, 0)),
                        motion: [Rigid(keys: [(time: 0.0), (time: 0.4, translate: (0.1, -0.05, 0))])]),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 24, padding: 0.2)),
        "field": DistanceField(boundary: "vox", band: 2.5, measure: Never),
        "a": Cloth(colliders: ["field"], params: (
            shape: Grid(size: (0.5, 0.5), resolution: (10, 10), center: (0, 0.45, 0), normal: (0, 1, 0)),
            material: Harada(k_structural: 30.0, k_shear: 7.5), mass: 0.002, damping: 0.99,
            collision: (epsilon: 0.01, friction: 0.4, ground: 0.0), substeps: 8)),
        "b": Cloth(colliders: ["field"], params: (
            shape: Grid(size: (0.4, 0.4), resolution: (9, 9), center: (0.05, 0.5, 0), normal: (0, 1, 0)),
            material: Harada(k_structural: 50.0, k_shear: 10.0), mass: 0.002, damping: 0.99,
            collision: (epsilon: 0.01, friction: 0.2, ground: 0.0), substeps: 8)),
        "sand": Ground(objects: ["ball"], params: (size: (1.0, 1.0), resolution: (48, 48),
                       initial: Flat(0.02), material: Preset(Sand))),
        "snow": Ground(objects: ["ball"], params: (size: (1.0, 1.0), resolution: (48, 48),
                       initial: Flat(0.02), material: Preset(Snow))),
        "render": Render(objects: [Mesh(mesh: "a"), Mesh(mesh: "b"), HeightField(heights: "sand")],
                         camera: Orbit(distance: 2.0), width: 48, height: 36, samples: 1),
        "mesh_a": WriteMesh(mesh: "a", format: Ply),
        "mesh_b": WriteMesh(mesh: "b", format: Ply),
        "h_sand": WriteHeightmap(heights: "sand", formats: [Npy]),
        "h_snow": WriteHeightmap(heights: "snow", formats: [Npy]),"#,
    );
    let dir = tempfile::tempdir().unwrap();
    let run = |name: &str, threads: usize, concurrent: bool| -> (PathBuf, Vec<Vec<u32>>) {
        let out = dir.path().join(name);
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut ex = executor(&scene, &out);
            ex.set_concurrent(concurrent);
            let waves = ex.waves();
            let together = |a: &str, b: &str| {
                waves
                    .iter()
                    .any(|w| w.iter().any(|n| n == a) && w.iter().any(|n| n == b))
            };
            assert!(together("a", "b") && together("sand", "snow"), "{waves:?}");
            let mut seen = Vec::new();
            while !ex.done() {
                ex.step().unwrap();
                seen.push(bits(&mesh(&ex, "a")));
                seen.push(bits(&mesh(&ex, "b")));
            }
            ex.finish().unwrap();
            (out, seen)
        })
    };
    let (out, values) = run("concurrent", 2, true);
    for (name, threads, concurrent) in [("sequential", 2, false), ("one_thread", 1, true)] {
        let (other, other_values) = run(name, threads, concurrent);
        assert!(values == other_values, "{name}: cloth positions differ");
        let files = files(&out);
        assert_eq!(
            files.len(),
            8 * 7,
            "frames, two meshes and two height maps with their sidecars per frame"
        );
        assert_eq!(files, self::files(&other), "{name}: written files differ");
    }
}

fn files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else {
                out.push((
                    p.strip_prefix(dir).unwrap().to_path_buf(),
                    std::fs::read(&p).unwrap(),
                ));
            }
        }
    }
    out.sort();
    out
}

/// Seeking back to a frame (from the nearest checkpoint kept in memory, or from the start
/// when none is that early) and stepping on gives the values the run had there, bit for bit.
#[test]
fn seek_goes_back_through_kept_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let p = falling(20.0, "(0.8, 0.4, 0.3)");
    let mut ex = executor(&p, dir.path());
    ex.keep_every(4);
    let mut after = Vec::new();
    for _ in 0..10 {
        ex.step().unwrap();
        after.push(bits(&mesh(&ex, "cloth")));
    }
    // Back to 6 (from the checkpoint kept before frame 4), then frame 6 again.
    ex.seek(6).unwrap();
    assert_eq!(ex.next_frame(), 6);
    assert_eq!(bits(&mesh(&ex, "cloth")), after[5]);
    ex.step().unwrap();
    assert_eq!(bits(&mesh(&ex, "cloth")), after[6]);
    // Back to 2: before any kept checkpoint but the first frame's, so from the start.
    ex.seek(2).unwrap();
    assert_eq!(bits(&mesh(&ex, "cloth")), after[1]);
    // Forward again, past where it was.
    ex.seek(11).unwrap();
    assert_eq!(ex.next_frame(), 11);
    assert!(ex.seek(13).is_err(), "frame 13 is past the run's 12");
}
