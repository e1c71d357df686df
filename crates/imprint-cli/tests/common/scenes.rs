//! Scenes and output comparisons the run, resume and farm tests share.
#![allow(dead_code)] // Each test binary uses some of them.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

pub fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// Every stateful node kind in one small scene: cloths against an interpolated, split field
/// of a breathing bunny, and against a static cow's field and a field built every 3 frames
/// (a collider that did not change is read as static, not as a blend of equal fields: on the
/// cow's back the two differ), a
/// cloth against a body's depth maps, snow on a ground that a rolling
/// ball presses (taking the snow in), particle skinning; writers of every kind, with a
/// contact sheet and a GIF, some on every other frame.
pub fn stateful_scene(frames: u32) -> String {
    stateful_scene_on(frames, "Cpu")
}

/// [`stateful_scene`] with the file's backend `backend`.
pub fn stateful_scene_on(frames: u32, backend: &str) -> String {
    let root = root();
    let bunny = root.join("assets/meshes/stanford-bunny.obj");
    let rig = root.join("assets/rigs/limb.ron");
    let cow = root.join("assets/meshes/cow.obj");
    format!(
        r#"Pipeline(
    frames: {frames},
    fps: 24,
    backend: {backend},
    nodes: {{
        "bunny": Mesh(path: "{bunny}", fit: (size: 0.6, center: (0, 0.3, 0)),
                      motion: [Breathe(amplitude: 0.05, period: 1.0), Twist(axis: Y, degrees: 20, period: 1.0)]),
        "vox": Voxelize(mesh: "bunny", grid: Fit(resolution: 32, padding: 0.15)),
        "field_i": DistanceField(boundary: "vox", band: 2.5, measure: Never, every: 4, split: 2,
                                 interpolate: true),
        "field": DistanceField(boundary: "vox", band: 2.5, every: 3, offset: 1, measure: Every(2)),
        "cloth": Cloth(colliders: ["field_i"], params: (
            shape: Grid(size: (0.7, 0.7), resolution: (12, 12), center: (0, 0.75, 0), normal: (0, 1, 0)),
            material: Harada(k_structural: 30.0, k_shear: 7.5), mass: 0.002, damping: 0.99,
            collision: (epsilon: 0.01, friction: 0.4, ground: 0.0), substeps: 8)),
        "rock": Mesh(path: "{cow}", fit: (size: 0.6, center: (0.6, 0.2, 0.5))),
        "rock_vox": Voxelize(mesh: "rock", grid: Fit(resolution: 24, padding: 0.3)),
        "rock_field": DistanceField(boundary: "rock_vox", band: 2.5, measure: Never),
        "cloth_k": Cloth(colliders: ["rock_field", "field"], params: (
            shape: Grid(size: (0.4, 0.4), resolution: (10, 10), center: (0.6, 0.42, 0.5), normal: (0, 1, 0)),
            material: Harada(k_structural: 30.0, k_shear: 7.5), mass: 0.002, damping: 0.99,
            collision: (epsilon: 0.01, friction: 0.4, ground: 0.0), substeps: 8)),
        "draped": Cloth(depth_colliders: [(body: "bunny", params: (resolution: 64))], params: (
            shape: Grid(size: (0.7, 0.7), resolution: (10, 10), center: (0, 0.8, 0), normal: (0, 1, 0)),
            material: Harada(k_structural: 30.0, k_shear: 7.5), mass: 0.002, damping: 0.99,
            collision: (epsilon: 0.01, friction: 0.4, ground: 0.0), substeps: 8)),
        "ball": Mesh(primitive: Sphere(radius: 0.1, segments: 16, rings: 8),
                     fit: (size: 0.2, center: (-0.4, 0.07, 0.0)),
                     motion: [Rigid(keys: [(time: 0.0), (time: 1.0, translate: (0.8, 0, 0))])]),
        "snow": Snow(meshes: ["ball"], ground: (size: (1.0, 1.0), resolution: (40, 40), height: 0.05),
                     params: (directions: 2, resolution: 64, rate: 0.05)),
        "ground": Ground(objects: ["ball"], accumulate: "snow",
                         params: (size: (1.0, 1.0), resolution: (40, 40), initial: Flat(0.05),
                                  material: Preset(Sand))),
        "prints": Ground(objects: ["ball"],
                         params: (size: (1.0, 1.0), resolution: (40, 40), initial: Flat(0.05),
                                  material: Preset(Snow))),
        "limb": Mesh(primitive: Cylinder(radius: 0.1, length: 1.0, segments: 12, rings: 10)),
        "skin": Skin(mesh: "limb", rig: "{rig}", method: Particles(), offset: (0.8, 0, 0)),
        "render": Render(
            objects: [Mesh(mesh: "bunny"), Mesh(mesh: "cloth"), Mesh(mesh: "draped"),
                      Mesh(mesh: "cloth_k"),
                      Mesh(mesh: "skin"), HeightField(heights: "ground"),
                      FieldSlice(field: "field", axis: Z)],
            camera: Orbit(distance: 2.5, spin: 20), width: 96, height: 72, samples: 1,
            every: 2, contact_sheet: (every: 1, columns: 3, width: 48), gif: (width: 64)),
        "cloth_obj": WriteMesh(mesh: "cloth", format: Ply),
        "cloth_k_obj": WriteMesh(mesh: "cloth_k", format: Ply),
        "draped_obj": WriteMesh(mesh: "draped", format: Ply, every: 2),
        "skin_obj": WriteMesh(mesh: "skin", every: 3),
        "heights": WriteHeightmap(heights: "ground", formats: [Npy, Png16]),
        "prints_h": WriteHeightmap(heights: "prints", formats: [Npy], every: 2),
        "fields": WriteField(field: "field", every: 2, slices: [(axis: X)]),
    }},
)
"#,
        bunny = bunny.display(),
        rig = rig.display(),
        cow = cow.display(),
    )
}

/// Every file under `dir` but the report, the manifest and the checkpoint, with its bytes.
pub fn outputs(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let run_files = ["report.json", "manifest.json", "checkpoint.bin"];
    super::files_under(dir)
        .into_iter()
        .filter(|p| !run_files.contains(&p.file_name().unwrap().to_str().unwrap()))
        .map(|p| {
            let bytes = std::fs::read(dir.join(&p)).unwrap();
            (p, bytes)
        })
        .collect()
}

pub fn assert_same_outputs(whole: &Path, pieces: &Path) {
    assert_same_files(whole, pieces, 30);
}

/// The same files with the same bytes under both folders (run files aside), more than
/// `at_least` of them.
pub fn assert_same_files(whole: &Path, pieces: &Path, at_least: usize) {
    let (a, b) = (outputs(whole), outputs(pieces));
    assert_eq!(
        a.keys().collect::<Vec<_>>(),
        b.keys().collect::<Vec<_>>(),
        "the same files"
    );
    let differ: Vec<_> = a
        .iter()
        .filter(|(k, v)| b[*k] != **v)
        .map(|(k, _)| k)
        .collect();
    assert!(differ.is_empty(), "files that differ: {differ:?}");
    assert!(a.len() > at_least, "{} files", a.len());
}

/// A sweep's CSV without its timing columns (`frame_ms_*`, `*_ms_per_frame`) and the Pareto
/// front they decide: what two sweeps of the same inputs agree on to the byte.
pub fn untimed_csv(csv: &str) -> Vec<Vec<String>> {
    let mut lines = csv
        .lines()
        .map(|l| l.split(',').map(String::from).collect::<Vec<_>>());
    let header = lines.next().unwrap();
    let keep: Vec<usize> = (0..header.len())
        .filter(|&i| {
            let h = &header[i];
            !(h.starts_with("frame_ms_") || h.ends_with("_ms_per_frame") || h == "pareto")
        })
        .collect();
    std::iter::once(header)
        .chain(lines)
        .map(|r| keep.iter().map(|&i| r[i].clone()).collect())
        .collect()
}
