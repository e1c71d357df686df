//! Schedules through the executor: which frames each node computes on (`frames_run` in the
//! report), what static and switched-off nodes do, and what an interpolated field's consumers
//! see, against the arithmetic of `imprint_graph::schedule` and exact blends.

use imprint_core::DistanceField;
use imprint_graph::Plan;
use imprint_graph::exec::{Observed, Observer, RunOptions, run, run_observed};
use imprint_graph::report::Report;
use std::collections::BTreeMap;
use std::sync::Arc;

mod common;
use common::plan;

fn run_plan(p: &Plan) -> Report {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        out: dir.path().to_path_buf(),
        ..Default::default()
    };
    run(p, &opts, &mut |_, _| {}).unwrap()
}

fn frames_run(r: &Report, node: &str) -> Vec<u32> {
    r.nodes[node].frames_run.clone()
}

/// A small sphere that breathes (it changes every frame), voxelised on a 16³ grid.
const BREATHING: &str = r#"
    "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8),
                 motion: [Breathe(amplitude: 0.1, period: 1.0)]),
    "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 16)),"#;

#[test]
fn every_offset_and_split_compute_on_exactly_the_scheduled_frames() {
    let p = plan(
        12,
        &format!(
            r#"{BREATHING}
    "a": DistanceField(boundary: "vox", measure: Never, every: 4, offset: 1),
    "b": DistanceField(boundary: "vox", measure: Never, every: 4, split: 3),
    "wa": WriteField(field: "a", npy: false, every: 3, offset: 2),
    "wb": WriteField(field: "b", npy: false, every: 12),"#
        ),
    );
    let r = run_plan(&p);
    assert_eq!(frames_run(&r, "vox"), (0..12).collect::<Vec<_>>());
    // The first frame always computes; then keyframes 1, 5, 9.
    assert_eq!(frames_run(&r, "a"), [0, 1, 5, 9]);
    // Whole on frame 0; then keyframes 4 and 8 in three parts each.
    assert_eq!(frames_run(&r, "b"), [0, 4, 5, 6, 8, 9, 10]);
    assert_eq!(frames_run(&r, "wa"), [2, 5, 8, 11]);
    assert_eq!(frames_run(&r, "wb"), [0]);
    // The table `imprint check` prints follows the same rules.
    let table = p.schedule_table(12);
    let row = |n: &str| {
        table
            .lines()
            .find(|l| l.starts_with(&format!("{n} ")))
            .unwrap()
            .split_whitespace()
            .nth(1)
            .unwrap()
            .to_string()
    };
    assert_eq!(row("a"), "##...#...#..");
    assert_eq!(row("b"), "#...123.123.");
    assert_eq!(row("wa"), "..w..w..w..w");
}

#[test]
fn a_static_meshs_boundary_and_field_are_built_once_in_a_hundred_frames() {
    let p = plan(
        100,
        r#"
    "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8)),
    "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 16)),
    "field": DistanceField(boundary: "vox", measure: Never),
    "w": WriteField(field: "field", npy: false, every: 25),"#,
    );
    let r = run_plan(&p);
    for n in ["ball", "vox", "field"] {
        assert_eq!(frames_run(&r, n), [0], "{n}");
    }
    assert_eq!(frames_run(&r, "w"), [0, 25, 50, 75]);
    assert!(p.static_nodes().contains("field"));
}

#[test]
fn changing_one_input_reruns_exactly_its_dependants() {
    let p = plan(
        6,
        &format!(
            r#"{BREATHING}
    "still": Mesh(primitive: Box(size: (0.4, 0.4, 0.4))),
    "vox_still": Voxelize(mesh: "still", grid: Fit(resolution: 16)),
    "f_still": DistanceField(boundary: "vox_still", measure: Never),
    "field": DistanceField(boundary: "vox", measure: Never, every: 2),
    "w1": WriteField(field: "f_still", npy: false),
    "w2": WriteField(field: "field", npy: false),"#
        ),
    );
    let r = run_plan(&p);
    for n in ["still", "vox_still", "f_still"] {
        assert_eq!(frames_run(&r, n), [0], "{n}");
    }
    assert_eq!(frames_run(&r, "vox"), [0, 1, 2, 3, 4, 5]);
    assert_eq!(frames_run(&r, "field"), [0, 2, 4]);
}

#[test]
fn disabled_and_pruned_nodes_never_run_and_lost_writers_are_warned_about() {
    let p = plan(
        3,
        &format!(
            r#"{BREATHING}
    "field": DistanceField(boundary: "vox", measure: Never, enabled: false),
    "other": DistanceField(boundary: "vox", measure: Never),
    "w": WriteField(field: "field", npy: false),
    "m": WriteMesh(mesh: "ball"),"#
        ),
    );
    let pruned: BTreeMap<&str, &str> = p
        .pruned
        .iter()
        .map(|(n, w)| (n.as_str(), w.as_str()))
        .collect();
    assert!(pruned["field"].contains("disabled"), "{pruned:?}");
    assert!(pruned["w"].contains("switched off"), "{pruned:?}");
    assert!(pruned["other"].contains("reaches no writer"), "{pruned:?}");
    assert!(
        p.warnings
            .iter()
            .any(|w| w.contains("'w'") && w.contains("'field'")),
        "{:?}",
        p.warnings
    );
    let r = run_plan(&p);
    for n in ["field", "other", "w"] {
        assert!(!r.nodes.contains_key(n), "{n} ran");
    }
    assert_eq!(frames_run(&r, "m"), [0, 1, 2]);
}

/// Every field a run shows, by node and frame.
#[derive(Default)]
struct Fields(BTreeMap<(String, u32), Arc<DistanceField>>);

impl Observer for Fields {
    fn observe(&mut self, node: &str, frame: u32, value: Observed<'_>) {
        if let Observed::Field(f) = value {
            self.0
                .insert((node.to_string(), frame), Arc::new(f.clone()));
        }
    }
}

fn observe(p: &Plan) -> (Report, Fields) {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        out: dir.path().to_path_buf(),
        ..Default::default()
    };
    let mut fields = Fields::default();
    let r = run_observed(p, &opts, &mut |_, _| {}, Some(&mut fields)).unwrap();
    (r, fields)
}

#[test]
fn an_interpolated_field_is_the_exact_blend_of_the_builds_around_each_frame() {
    let nodes = |sched: &str| {
        format!(
            r#"{BREATHING}
    "field": DistanceField(boundary: "vox", measure: Never{sched}),
    "w": WriteField(field: "field", npy: false),"#
        )
    };
    // The reference builds every frame; the interpolated one every 4 frames, 4 ahead.
    let (_, every) = observe(&plan(13, &nodes("")));
    let p = plan(13, &nodes(", every: 4, split: 2, interpolate: true"));
    // Its boundary and mesh only feed it: it evaluates them itself, ahead of time.
    assert!(p.pruned.iter().any(|(n, _)| n == "vox"), "{:?}", p.pruned);
    let (r, interp) = observe(&p);
    let key = |f: u32| every.0[&("field".to_string(), f)].clone();
    for f in 0..13u32 {
        // The segment holds the step from f - 1 to f (frame 0: f itself).
        let a = if f == 0 { 0 } else { 4 * ((f - 1) / 4) };
        let w = (f - a) as f32 / 4.0;
        let (fa, fb) = (key(a), key(a + 4));
        let got = &interp.0[&("field".to_string(), f)];
        // The ball is closed: its fields are signed, and the blend is of signed distances.
        assert!(got.inside.is_some(), "frame {f}");
        for i in 0..got.dist.len() {
            let (sa, sb) = (fa.signed_distance(i), fb.signed_distance(i));
            let want = sa + (sb - sa) * w;
            assert_eq!(
                got.dist[i].to_bits(),
                want.abs().to_bits(),
                "frame {f}, cell {i}"
            );
            assert_eq!(got.is_inside(i), Some(want < 0.0), "frame {f}, cell {i}");
        }
    }
    // Builds: keyframes 0 and 4 whole on frame 0; keyframe 8's two parts on frames 4 and 5
    // (first needed on frame 5, which steps from 4 toward 8); 12's on 8 and 9; 16's on 12.
    assert_eq!(frames_run(&r, "field"), [0, 4, 5, 8, 9, 12]);
    let table = p.schedule_table(13);
    assert!(table.contains("field  #...12..12..1 "), "{table}");
}

/// The cloth's particles on every frame.
#[derive(Default)]
struct Cloth(Vec<Vec<glam::Vec3>>);

impl Observer for Cloth {
    fn observe(&mut self, node: &str, _frame: u32, value: Observed<'_>) {
        if let (Observed::Mesh(m), "cloth") = (value, node) {
            self.0.push(m.positions.clone());
        }
    }
}

/// The largest distance between the cloth's particles in runs of `a` and `b`, any frame.
fn cloth_deviation(a: &Plan, b: &Plan) -> f32 {
    let dir = tempfile::tempdir().unwrap();
    let opts = RunOptions {
        out: dir.path().to_path_buf(),
        ..Default::default()
    };
    let mut runs = Vec::new();
    for p in [a, b] {
        let mut c = Cloth::default();
        run_observed(p, &opts, &mut |_, _| {}, Some(&mut c)).unwrap();
        runs.push(c);
    }
    let mut worst = 0.0f32;
    for (a, b) in runs[0].0.iter().zip(&runs[1].0) {
        for (p, q) in a.iter().zip(b) {
            worst = worst.max((*p - *q).length());
        }
    }
    worst
}

/// A cloth pinned at its corners, pushed up by a sphere rising at 0.06 m/s (heavily damped,
/// so its shape follows the sphere rather than its own history): with the field built every
/// 4 frames and interpolated (split in 2) the cloth stays within a small fraction of ε of the
/// run that rebuilds the field every frame; without interpolation the field jumps every 4
/// frames (up to 7.5 mm behind the sphere) and the cloth follows the jumps.
///
/// The sphere moves 10 mm between builds, no more than ε: a resting particle is then never
/// inside the later build. Where it is (a body moving more than ε between builds), an
/// unsigned field's vectors within a cell of that build's surface decide the side, and can
/// decide wrongly and push the cloth in; a signed field does not (the next test).
#[test]
fn an_interpolated_collider_moves_the_cloth_as_the_every_frame_field_does() {
    let nodes = |sched: &str| {
        format!(
            r#"
    "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 32, rings: 16),
                 motion: [Rigid(keys: [(time: 0), (time: 1, translate: (0, 0.06, 0))])]),
    "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 48)),
    "field": DistanceField(boundary: "vox", band: 4, measure: Never{sched}),
    "cloth": Cloth(colliders: ["field"], params: (
        shape: Grid(size: (0.8, 0.8), resolution: (12, 12), center: (0, 0.32, 0)),
        material: Harada(k_structural: 20.0, k_shear: 5.0),
        pins: [Indices([0, 11, 132, 143])],
        damping: 0.97,
        collision: (epsilon: 0.01, friction: 0.3),
        substeps: 16)),
    "m": WriteMesh(mesh: "cloth", every: 100),"#
        )
    };
    let deviation = |sched: &str| cloth_deviation(&plan(24, &nodes("")), &plan(24, &nodes(sched)));
    let interpolated = deviation(", every: 4, split: 2, interpolate: true");
    let jumping = deviation(", every: 4");
    eprintln!("max deviation: interpolated {interpolated:.2e} m, jumping {jumping:.2e} m");
    assert!(interpolated < 0.1 * 0.01, "{interpolated}");
    assert!(jumping > 3.0 * interpolated, "{jumping} vs {interpolated}");
}

/// The limit above, lifted: the sphere moves 20 mm between builds (twice ε) on 21 mm cells. A
/// resting particle ends up inside the later build; the signed field knows it is inside and
/// takes it out the nearest way, and the unsigned one (`signed: false`) reads the crossing
/// from the particle's memory, so both keep to the every-frame run (the unsigned one strayed
/// by centimetres before a crossing had to be a sweep the surface could make). At 40 mm
/// between builds (4ε) only the sign still does.
#[test]
fn with_the_sign_interpolating_past_epsilon_keeps_the_cloth_out() {
    let nodes = |signed: bool, rise: f32, sched: &str| {
        format!(
            r#"
    "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 32, rings: 16),
                 motion: [Rigid(keys: [(time: 0), (time: 1, translate: (0, {rise}, 0))])]),
    "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 40), signed: {signed}),
    "field": DistanceField(boundary: "vox", band: 4, measure: Never{sched}),
    "cloth": Cloth(colliders: ["field"], params: (
        shape: Grid(size: (0.8, 0.8), resolution: (12, 12), center: (0, 0.32, 0)),
        material: Harada(k_structural: 20.0, k_shear: 5.0),
        pins: [Indices([0, 11, 132, 143])],
        damping: 0.97,
        collision: (epsilon: 0.01, friction: 0.3),
        substeps: 16)),
    "m": WriteMesh(mesh: "cloth", every: 100),"#
        )
    };
    let interpolated = ", every: 4, split: 2, interpolate: true";
    let deviation = |signed: bool, rise: f32| {
        cloth_deviation(
            &plan(24, &nodes(signed, rise, "")),
            &plan(24, &nodes(signed, rise, interpolated)),
        )
    };
    for rise in [0.12, 0.24] {
        let (signed, unsigned) = (deviation(true, rise), deviation(false, rise));
        eprintln!(
            "rise {rise} m: max deviation from the every-frame run: signed {signed:.2e} m, \
             unsigned {unsigned:.2e} m"
        );
        assert!(signed < 0.5 * 0.01, "{signed}");
        if rise < 0.2 {
            assert!(unsigned < 0.5 * 0.01, "{unsigned}");
        } else {
            assert!(unsigned > 3.0 * signed, "{unsigned} vs {signed}");
        }
    }
}
