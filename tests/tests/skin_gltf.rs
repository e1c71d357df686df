//! Skins from glTF files: a hand-made two-joint file (tests/data/two_joint.gltf: a root at the
//! origin, a child at (0, 1, 0) whose clip "Bend" turns it 90° about z over one second;
//! vertex A = (1, 0, 0) follows the root, B = (0, 2, 0) the child, C = (0.5, 1, 0) both
//! halves) skinned through `Skeleton` with the file's weights, against positions worked out
//! by hand; and a real character's walk pressing prints where its feet were.

use glam::Vec3;
use imprint_core::gltf::{ClipTime, Document};
use imprint_stages::skin::blend;
use imprint_stages::skin::skeleton::Skeleton;
use std::path::Path;
use std::sync::Arc;

fn two_joint() -> Skeleton {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/two_joint.gltf");
    let doc = Arc::new(Document::load(&path).unwrap());
    Skeleton::from_gltf(
        doc,
        Some("Bend"),
        ClipTime {
            speed: 1.0,
            looping: false,
            offset: 0.0,
        },
    )
    .unwrap()
}

fn assert_near(got: Vec3, want: Vec3, what: &str) {
    assert!(got.distance(want) < 1e-5, "{what}: {got} vs {want}");
}

/// At t = 1 the child has turned 90° about z through (0, 1, 0): B goes to (−1, 1, 0); C's
/// halves go to (0.5, 1, 0) and (0, 1.5, 0), so LBS puts it at their mean (0.25, 1.25, 0)
/// while DQS turns it by the blended 45°: (0.5 cos 45°, 1 + 0.5 sin 45°). At t = 0.5 the
/// child is at 45° (slerp of the keys), DQS then turns C by 22.5°.
#[test]
fn two_joints_skin_as_computed_by_hand() {
    let sk = two_joint();
    let rest = sk.bound_mesh().unwrap().clone();
    let w = sk.file_weights(rest.positions.len()).unwrap().unwrap();
    let idx = |p: Vec3| {
        rest.positions
            .iter()
            .position(|q| q.distance(p) < 1e-6)
            .unwrap()
    };
    let (a, b, c) = (
        idx(Vec3::X),
        idx(Vec3::new(0.0, 2.0, 0.0)),
        idx(Vec3::new(0.5, 1.0, 0.0)),
    );
    let (s45, s22, c22) = (
        std::f32::consts::FRAC_1_SQRT_2,
        (std::f32::consts::PI / 8.0).sin(),
        (std::f32::consts::PI / 8.0).cos(),
    );
    let skin = sk.pose(1.0).skin;
    let lbs = blend::lbs(&rest.positions, &w, &skin);
    let dqs = blend::dqs(&rest.positions, &w, &skin);
    assert_near(lbs[a], Vec3::X, "LBS A at 1 s");
    assert_near(lbs[b], Vec3::new(-1.0, 1.0, 0.0), "LBS B at 1 s");
    assert_near(lbs[c], Vec3::new(0.25, 1.25, 0.0), "LBS C at 1 s");
    assert_near(dqs[b], Vec3::new(-1.0, 1.0, 0.0), "DQS B at 1 s");
    assert_near(
        dqs[c],
        Vec3::new(0.5 * s45, 1.0 + 0.5 * s45, 0.0),
        "DQS C at 1 s",
    );
    let skin = sk.pose(0.5).skin;
    let lbs = blend::lbs(&rest.positions, &w, &skin);
    let dqs = blend::dqs(&rest.positions, &w, &skin);
    let half = Vec3::new(0.5 * s45, 1.0 + 0.5 * s45, 0.0);
    assert_near(
        lbs[c],
        (Vec3::new(0.5, 1.0, 0.0) + half) * 0.5,
        "LBS C at 0.5 s",
    );
    assert_near(
        dqs[c],
        Vec3::new(0.5 * c22, 1.0 + 0.5 * s22, 0.0),
        "DQS C at 0.5 s",
    );
    assert_near(dqs[b], Vec3::new(-s45, 1.0 + s45, 0.0), "DQS B at 0.5 s");
}

/// The file's joints are the bones: names, parents and segments (the child, a leaf, runs
/// on half its parent's length past its head).
#[test]
fn two_joints_are_the_bones() {
    let sk = two_joint();
    assert_eq!(sk.names, ["root", "child"]);
    assert_eq!(sk.parents, [None, Some(0)]);
    assert_near(sk.segments[0].0, Vec3::ZERO, "root head");
    assert_near(sk.segments[0].1, Vec3::Y, "root tail");
    assert_near(sk.segments[1].1, Vec3::new(0.0, 1.5, 0.0), "child tail");
}

/// A clip that is not there: the error lists the clips that are.
#[test]
fn an_unknown_clip_lists_the_clips() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("data/two_joint.gltf");
    let doc = Arc::new(Document::load(&path).unwrap());
    let err = Skeleton::from_gltf(doc, Some("Walk"), ClipTime::default()).unwrap_err();
    let msg = err.to_string();
    assert!(msg.contains("Walk") && msg.contains("Bend"), "{msg}");
}

/// A character from another exporter (assimp's FBX test rig, converted to glTF: a bar of 14
/// joints named Bone…Bone.013, its clip "Armature|ArmatureAction", in centimetres with a
/// scaled armature and mesh node) loads with a pipeline written for it and no code change:
/// fitted to 1.5 m, it bends by its clip (dual quaternions, which need the file's common
/// stretch moved out of its transforms) and presses its shape into sand.
#[test]
fn a_character_from_another_exporter_moves_and_presses_prints() {
    use imprint_graph::diagnostics::Source;
    use imprint_graph::exec::RunOptions;
    use imprint_graph::value::Value;
    use imprint_graph::{Executor, parse};
    let assets = Path::new(env!("CARGO_MANIFEST_DIR")).join("../assets/characters");
    let text = format!(
        r#"Pipeline(frames: 12, fps: 24, backend: Cpu, nodes: {{
            "bar": Skin(rig: "{}/bar_skeleton.glb", clip: "Armature|ArmatureAction",
                        method: DualQuaternion(), fit: (size: 1.5, center: (0, 0.12, 0))),
            "sand": Ground(objects: ["bar"], params: (size: (2.0, 1.0), resolution: (160, 80),
                           initial: Flat(0.1), material: Preset(Sand))),
            "h": WriteHeightmap(heights: "sand", formats: [Npy], every: 100000),
        }})"#,
        assets.display()
    );
    let plan = parse(
        Source {
            name: "bar.ron".into(),
            text,
        },
        Path::new("."),
    )
    .unwrap();
    let out = std::env::temp_dir().join(format!("imprint-bar-{}", std::process::id()));
    let opts = RunOptions {
        out: out.clone(),
        ..Default::default()
    };
    let mut ex = Executor::new(&plan, opts).unwrap();
    let mut tops = Vec::new();
    for frame in 0..12 {
        ex.step().unwrap();
        let Some(Value::Mesh(m)) = ex.value("bar") else {
            panic!("no mesh")
        };
        let b = m.bounds();
        if frame == 0 {
            assert!(
                (b.size().max_element() - 1.5).abs() < 1e-3,
                "fitted: {:?}",
                b.size()
            );
            assert!(
                (b.center() - Vec3::new(0.0, 0.12, 0.0)).length() < 1e-3,
                "{:?}",
                b.center()
            );
        }
        tops.push(b.max.y);
    }
    let Some(Value::Heights(h)) = ex.value("sand") else {
        panic!("no heights")
    };
    let lowest = h.heights.iter().copied().fold(f32::INFINITY, f32::min);
    std::fs::remove_dir_all(&out).ok();
    let swing = tops.iter().copied().fold(f32::MIN, f32::max)
        - tops.iter().copied().fold(f32::MAX, f32::min);
    assert!(swing > 0.05, "the clip moves it: top varies by {swing} m");
    assert!(lowest < 0.1 - 0.01, "it pressed the sand: lowest {lowest}");
}

/// The issue's acceptance test: a walk clip whose feet press prints where the feet were.
/// tests/data/walker.gltf (written by `make_walker.py` beside it) is a body box on two
/// inverted-pyramid feet whose clip "Walk" carries the root along +z at 0.5 m/s while the
/// feet take turns: planted 3 cm deep and still, lifted straight up, swung 0.5 m forward
/// 8 cm up, set straight down. Stood on 10 cm of snow, each planted foot's lowest vertex lies
/// within one cell of its print's deepest cell, that cell is as deep as the foot went, and
/// the snow farther than 10 cm from every planted foot is untouched.
#[test]
fn a_walk_presses_prints_where_the_feet_were() {
    use glam::Vec3Swizzles;
    use imprint_graph::diagnostics::Source;
    use imprint_graph::exec::RunOptions;
    use imprint_graph::value::Value;
    use imprint_graph::{Executor, parse};
    const SURFACE: f32 = 0.1;
    // 1 cm cells with centres on whole centimetres, where the fixture plants its feet.
    let text = format!(
        r#"Pipeline(frames: 48, fps: 24, backend: Cpu, nodes: {{
            "walker": Skin(rig: "{}/data/walker.gltf", clip: "Walk", method: Linear(),
                           offset: (0, {SURFACE}, 0)),
            "snow": Ground(objects: ["walker"], params: (size: (0.61, 1.61),
                           resolution: (61, 161), origin: (-0.3, -0.3),
                           initial: Flat({SURFACE}), material: Preset(Snow))),
            "h": WriteHeightmap(heights: "snow", formats: [Npy], every: 100000),
        }})"#,
        env!("CARGO_MANIFEST_DIR")
    );
    let source = Source {
        name: "walk.ron".into(),
        text,
    };
    let plan = parse(source, Path::new(".")).unwrap();
    let out = std::env::temp_dir().join(format!("imprint-walk-{}", std::process::id()));
    let opts = RunOptions {
        out: out.clone(),
        ..Default::default()
    };
    let mut ex = Executor::new(&plan, opts).unwrap();
    let mut feet: Vec<Vec<usize>> = Vec::new(); // vertices of the x < 0 foot, then x > 0
    let mut last = [None::<Vec3>; 2]; // each foot's lowest vertex at the last frame
    let mut plant = [None::<(u32, Vec3)>; 2]; // (first frame, lowest vertex) while planted
    let mut spots = Vec::new(); // every planted lowest vertex
    let mut checked = 0;
    let mut ground = None;
    for frame in 0..48 {
        ex.step().unwrap();
        let Some(Value::Mesh(m)) = ex.value("walker") else {
            panic!("no mesh")
        };
        let Some(Value::Heights(h)) = ex.value("snow") else {
            panic!("no heights")
        };
        if feet.is_empty() {
            let foot = |left: bool| {
                (0..m.positions.len())
                    .filter(|&v| {
                        let p = m.positions[v];
                        p.y < SURFACE + 0.2 && (p.x < 0.0) == left
                    })
                    .collect::<Vec<_>>()
            };
            feet = vec![foot(true), foot(false)];
        }
        for (f, verts) in feet.iter().enumerate() {
            let low = verts
                .iter()
                .map(|&v| m.positions[v])
                .min_by(|a, b| a.y.total_cmp(&b.y))
                .unwrap();
            let still = last[f].is_none_or(|q| q.xz().distance(low.xz()) < 1e-3);
            last[f] = Some(low);
            if low.y < SURFACE && still {
                plant[f].get_or_insert((frame, low));
                spots.push(low);
                continue;
            }
            let Some((from, at)) = plant[f].take() else {
                continue;
            };
            // The plant has ended (the foot lifted): its print, around where it stood.
            let cell = |x: f32, o: f32| ((x - o) / h.cell).round() as i64;
            let (ia, ka) = (cell(at.x, h.origin.x), cell(at.z, h.origin.y));
            let reach = (0.05 / h.cell).ceil() as i64;
            let mut deepest = (0, 0, f32::INFINITY);
            for k in ka - reach..=ka + reach {
                for i in ia - reach..=ia + reach {
                    if h.position(i as u32, k as u32).xz().distance(at.xz()) <= 0.05 {
                        let y = h.heights[h.index(i as u32, k as u32)];
                        if y < deepest.2 {
                            deepest = (i - ia, k - ka, y);
                        }
                    }
                }
            }
            let (di, dk, y) = deepest;
            println!(
                "{} foot planted frames {from}..{frame}: lowest vertex {at} over cell \
                 ({ia}, {ka}); deepest cell within 5 cm {y} m at ({di:+}, {dk:+}) from it, \
                 {:+.1e} m from the foot",
                ["right (x < 0)", "left (x > 0)"][f],
                y - at.y
            );
            assert!(di.abs() <= 1 && dk.abs() <= 1, "print off the foot");
            assert!((y - at.y).abs() <= 1e-4, "print depth {y} vs foot {}", at.y);
            checked += 1;
        }
        ground = Some(h);
    }
    std::fs::remove_dir_all(&out).ok();
    assert!(checked >= 4, "{checked} plants checked");
    let h = ground.unwrap();
    let mut pressed = 0;
    for k in 0..h.dims.y {
        for i in 0..h.dims.x {
            let p = h.position(i, k);
            let untouched = (p.y - SURFACE).abs() < 1e-6;
            pressed += usize::from(!untouched);
            let near = spots.iter().any(|s| s.xz().distance(p.xz()) <= 0.1);
            assert!(near || untouched, "a print where no foot stood: {p}");
        }
    }
    println!("{checked} plants, {pressed} cells pressed");
}
