//! Cloth pins that ride a body (`Cloth(pins_follow: ...)`): a cape-like cloth pinned over a
//! box that turns 60° about y and slides 0.3 m; the pinned particles must move exactly as
//! the box does (the rigid motion of their first-frame positions about the box's centre),
//! and the free part hangs on.

use glam::{Quat, Vec3};
use imprint_graph::diagnostics::Source;
use imprint_graph::exec::RunOptions;
use imprint_graph::value::Value;
use imprint_graph::{Executor, parse};
use std::path::Path;

#[test]
fn pinned_particles_move_with_the_body() {
    let text = r#"Pipeline(frames: 25, fps: 24, backend: Cpu, nodes: {
        "box": Mesh(primitive: Box(size: (0.4, 0.2, 0.4), subdivisions: 2),
                    fit: (size: 0.4, center: (0, 0.5, 0)),
                    motion: [Rigid(keys: [(time: 0.0),
                        (time: 1.0, translate: (0.3, 0, 0), rotate: (axis: Y, degrees: 60))])]),
        "cape": Cloth(pins_follow: "box", params: (
            shape: Grid(size: (0.3, 0.3), resolution: (10, 10), center: (0, 0.62, 0.05),
                        normal: (0, 1, 0)),
            pins: [Region(min: (-0.2, 0.6, -0.2), max: (0.2, 0.64, -0.08))],
            material: Harada(k_structural: 40.0, k_shear: 10.0),
            mass: 0.002, damping: 0.995, substeps: 16)),
        "obj": WriteMesh(mesh: "cape", every: 100000),
    })"#;
    let plan = parse(
        Source {
            name: "pins.ron".into(),
            text: text.into(),
        },
        Path::new("."),
    )
    .unwrap();
    let out = std::env::temp_dir().join(format!("imprint-pins-{}", std::process::id()));
    let opts = RunOptions {
        out: out.clone(),
        ..Default::default()
    };
    let mut ex = Executor::new(&plan, opts).unwrap();
    let cape = |ex: &Executor| match ex.value("cape") {
        Some(Value::Mesh(m)) => m.positions.clone(),
        _ => panic!("no cloth"),
    };
    ex.step().unwrap();
    let start = cape(&ex);
    // The pins: the particles whose start lies in the pinned region (the region is above
    // the box top, at y 0.6, in its -z half).
    let pinned: Vec<usize> = (0..start.len())
        .filter(|&i| start[i].z <= -0.08 && start[i].z >= -0.2 && start[i].y > 0.6)
        .collect();
    assert!(pinned.len() >= 10, "{} pins", pinned.len());
    for _ in 1..25 {
        ex.step().unwrap();
    }
    let end = cape(&ex);
    std::fs::remove_dir_all(&out).ok();
    // Frame 24 is t = 1: the box has turned 60° about y through its centre and slid 0.3 m.
    let centre = Vec3::new(0.0, 0.5, 0.0);
    let turn = Quat::from_rotation_y(60f32.to_radians());
    for &i in &pinned {
        let want = turn * (start[i] - centre) + centre + Vec3::new(0.3, 0.0, 0.0);
        assert!(
            end[i].distance(want) < 1e-4,
            "pin {i}: {} vs {want}",
            end[i]
        );
    }
    let free_moved = (0..end.len())
        .filter(|i| !pinned.contains(i))
        .map(|i| (end[i] - start[i]).length())
        .fold(0.0f32, f32::max);
    assert!(free_moved > 0.1, "the free part follows: {free_moved} m");
}
