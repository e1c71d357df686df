//! Section 11 of BENCHMARKS.md: skinning (T §(3)) — particle skinning beside linear blend
//! (LBS) and dual quaternion (DQS) skinning on the same limb and rig, ms per frame and what
//! each keeps of the joint; and the adaptive fill's particle counts against a uniform fill.
//!
//! The limb: a capped cylinder (radius 0.1, length 1), 96 segments × 104 rings (about 10k
//! vertices), driven by `assets/rigs/limb.ron` (bend 90° over 1 s, then twist 180° over 1 s)
//! at 24 fps for 60 frames. Particles: T's fill at a finest radius that gives about 5k
//! particles, the default forces (beyond T) and T's own set.
//!
//! Then a character from a file: `assets/characters/wuson.glb` (assimp's test quadruped, 37
//! joints) walking by its clip "Wuson_Walk", as `pipelines/character_walk.ron` skins it: what
//! loading costs, what each method costs per frame with the file's weights, and what each
//! changes (volume against rest; the particles' distance from LBS).

use crate::{median, median_ms};
use glam::{Affine3A, Vec3};
use imprint_core::Mesh;
use imprint_core::gltf::{ClipTime, Document};
use imprint_core::mesh::primitives::{cylinder, torus};
use imprint_stages::metrics::percentile;
use imprint_stages::skin::fill::{FillParams, fill};
use imprint_stages::skin::particles::{ParticleParams, ParticleSkin};
use imprint_stages::skin::rig::Rig;
use imprint_stages::skin::skeleton::Skeleton;
use imprint_stages::skin::weights::Weights;
use imprint_stages::skin::{blend, measure, weights};
use std::fmt::Write;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

const FPS: f32 = 24.0;
const FRAMES: u32 = 60;

/// One method's run: median ms per frame, and at the last frame the volume and the joint's
/// section as ratios to the rest pose.
struct Outcome {
    ms: f64,
    volume: f64,
    section: f64,
}

/// The joint's section (the plane through the lower bone's head halving the bend) and the
/// volume of `mesh` posed by `rig` at `t`.
fn measures(rig: &Rig, mesh: &Mesh, t: Option<f32>) -> (f64, f64) {
    let seg = match t {
        Some(t) => rig.posed_segments(&rig.pose(t)),
        None => rig.rest_segments(),
    };
    let dir = |(h, t): (Vec3, Vec3)| (t - h).normalize();
    let n = (dir(seg[0]) + dir(seg[1]))
        .try_normalize()
        .unwrap_or(dir(seg[1]));
    (
        measure::volume(mesh),
        measure::cross_section_area(mesh, seg[1].0, n),
    )
}

/// Runs frames `0..frames` in order (each may depend on the last: the particles' do) and
/// returns the median ms of those from `warm_up` on, and the last frame's result. The one
/// per-frame timer of this section, so the limb's and the character's figures compare.
fn per_frame<T>(frames: u32, warm_up: u32, mut frame: impl FnMut(u32) -> T) -> (f64, T) {
    let mut times = Vec::new();
    let mut last = None;
    for f in 0..frames {
        let t = Instant::now();
        let out = frame(f);
        if f >= warm_up {
            times.push(t.elapsed().as_secs_f64() * 1e3);
        }
        last = Some(out);
    }
    (median(times), last.expect("at least one frame"))
}

/// `rest` with blended `positions` and their normals: what a blend's frame delivers, so
/// its time compares with the particles' (whose `mesh()` computes normals too).
fn posed_mesh(rest: &Mesh, positions: Vec<Vec3>) -> Mesh {
    let mut m = rest.clone();
    m.positions = positions;
    m.compute_normals();
    m
}

fn run(rig: &Rig, rest: &Mesh, mut frame: impl FnMut(u32, f32) -> Mesh) -> Outcome {
    let (v0, s0) = measures(rig, rest, None);
    let (ms, last) = per_frame(FRAMES, 0, |f| frame(f, (f + 1) as f32 / FPS));
    let (v, s) = measures(rig, &last, Some(FRAMES as f32 / FPS));
    Outcome {
        ms,
        volume: v / v0,
        section: s / s0,
    }
}

pub fn section(root: &Path, repeat: usize) -> String {
    let rig = imprint_graph::rig::load(&root.join("assets/rigs/limb.ron"))
        .expect("limb rig")
        .rig;
    let limb = cylinder(0.1, 1.0, 96, 104);
    let segments = rig.rest_segments();
    let mut s = String::from("## 11. Skinning (CPU)\n\n");
    let _ = writeln!(
        s,
        "The limb: a capped cylinder (radius 0.1, length 1), {} vertices, {} triangles, driven \
         by `assets/rigs/limb.ron` (bend 90° at the middle over 1 s, then twist the lower bone \
         180° over 1 s), {FRAMES} frames at {FPS} fps. **ms per frame**: median over the run \
         (particles: the frame's substeps and the vertices; blends: the vertices and their \
         normals). **volume** and **joint section**: the last frame's, as ratios to the rest \
         pose (the section through the joint, on the plane halving the bend). Goal (issue): \
         5k particles driving 10k vertices in ≤ 8 ms per frame.\n",
        limb.positions.len(),
        limb.triangles.len()
    );
    let _ = writeln!(
        s,
        "| method | particles | ms per frame | volume | joint section |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|");
    let w = weights::automatic(&limb.positions, &segments, &Default::default());
    let blend_row = |s: &mut String, label: &str, dual: bool| {
        let o = run(&rig, &limb, |_, t| {
            let pose = rig.pose(t);
            let blended = if dual { blend::dqs } else { blend::lbs };
            posed_mesh(&limb, blended(&limb.positions, &w, &pose.skin))
        });
        eprintln!("skin: {label}: {:.2} ms", o.ms);
        let _ = writeln!(
            s,
            "| {label} | – | {:.2} | {:.3} | {:.3} |",
            o.ms, o.volume, o.section
        );
    };
    blend_row(&mut s, "LBS (automatic weights)", false);
    blend_row(&mut s, "DQS (automatic weights)", true);
    let fill_params = FillParams {
        radius: 0.0093,
        ..Default::default()
    };
    for (label, params) in [
        (
            "particles, defaults (corotated springs, pressure)",
            ParticleParams {
                fill: fill_params.clone(),
                ..Default::default()
            },
        ),
        (
            "particles, T's set (distance springs)",
            ParticleParams {
                fill: fill_params.clone(),
                ..ParticleParams::t_method()
            },
        ),
    ] {
        let mut sim = ParticleSkin::new(&limb, &segments, &params).expect("particle skin");
        let mut prev = rig.pose(0.0).skin;
        let o = run(&rig, &limb, |f, t| {
            let pose = rig.pose(t);
            sim.step_frame(&prev, &pose.skin, f, 1.0 / FPS)
                .expect("particle skin frame");
            prev = pose.skin;
            sim.mesh()
        });
        eprintln!("skin: {label}: {:.2} ms", o.ms);
        let _ = writeln!(
            s,
            "| {label} | {} | {:.2} | {:.3} | {:.3} |",
            sim.fill_report().adaptive_count,
            o.ms,
            o.volume,
            o.section
        );
    }
    fill_counts(&mut s, root);
    character(&mut s, root, repeat);
    s
}

/// Adaptive against uniform fills (T's motivation: far fewer particles for thick bodies).
fn fill_counts(s: &mut String, root: &Path) {
    let cow = {
        let mut m = Mesh::load_obj(&root.join("assets/meshes/cow.obj")).expect("cow");
        let t = m.fit_transform(1.0, Vec3::ZERO);
        m.transform(t);
        m
    };
    let _ = writeln!(
        s,
        "\nThe fill (3 levels, finest radius r): particles of the adaptive fill against a uniform \
         fill at r, and the particles' owned volume against the mesh's.\n"
    );
    let _ = writeln!(
        s,
        "| mesh | r | adaptive | uniform | adaptive / uniform | volume error | fill ms |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
    let meshes = [
        ("limb (above)", cylinder(0.1, 1.0, 96, 104), 0.0093),
        ("torus (0.5, 0.2)", torus(0.5, 0.2, 128, 64), 0.01),
        ("cow (size 1)", cow, 0.01),
    ];
    for (name, mesh, radius) in meshes {
        let params = FillParams {
            radius,
            ..Default::default()
        };
        let t = Instant::now();
        let f = fill(&mesh, &params).expect("fill");
        let ms = t.elapsed().as_secs_f64() * 1e3;
        let r = &f.report;
        let _ = writeln!(
            s,
            "| {name} | {radius} | {} | {} | {:.2} | {:+.2}% | {ms:.0} |",
            r.adaptive_count,
            r.uniform_count,
            r.adaptive_count as f64 / r.uniform_count as f64,
            100.0 * (r.particle_volume / r.mesh_volume - 1.0)
        );
    }
}

/// The character and the fill radius `pipelines/character_walk.ron` skins it with.
const CHARACTER: &str = "assets/characters/wuson.glb";
const CLIP: &str = "Wuson_Walk";
const CHARACTER_FILL: f32 = 0.03;

/// The character as a Skin node holds it, and what loading it cost.
struct Character {
    skeleton: Skeleton,
    /// The file's mesh welded by position: what every method skins.
    mesh: Arc<Mesh>,
    weights: Weights,
    file_vertices: usize,
    clip_s: f32,
    load_ms: f64,
    skeleton_ms: f64,
}

/// `make()` once (the warm-up, kept) and the median ms of `repeat` more: how this section
/// times one-off setup (a load, a skeleton, a fill), so those figures compare.
fn setup<T>(repeat: usize, mut make: impl FnMut() -> T) -> (T, f64) {
    let kept = make();
    (kept, median_ms(repeat, || drop(make())))
}

fn load_character(root: &Path, repeat: usize) -> Character {
    let path = root.join(CHARACTER);
    let (doc, load_ms) = setup(repeat, || Document::load(&path).expect("wuson.glb"));
    let doc = Arc::new(doc);
    let time = ClipTime {
        speed: 1.0,
        looping: true,
        offset: 0.0,
    };
    let (skeleton, skeleton_ms) = setup(repeat, || {
        Skeleton::from_gltf(doc.clone(), Some(CLIP), time).expect("wuson skeleton")
    });
    let mesh = skeleton.bound_mesh().expect("a glTF skin's mesh").clone();
    let weights = skeleton.file_weights(mesh.positions.len());
    Character {
        weights: weights
            .expect("wuson weights")
            .expect("a glTF skin's weights"),
        file_vertices: doc.mesh.positions.len(),
        clip_s: doc.clip(CLIP).expect("the walk").duration(),
        skeleton,
        mesh,
        load_ms,
        skeleton_ms,
    }
}

/// The particles as the Skin node starts them: filled, tied to bones by the file's
/// weights, placed at the walk's first pose.
fn particle_setup(c: &Character, params: &ParticleParams) -> ParticleSkin {
    let mut sim = ParticleSkin::new(&c.mesh, &c.skeleton.segments, params).expect("particles");
    let w = sim.bind_by_weights(&c.weights).expect("bind by weights");
    sim.place(&w, &c.skeleton.rigid_pose(0.0).0.skin)
        .expect("place");
    sim
}

/// Median and 99th percentile of the distances between like vertices of `a` and `b`.
fn distances(a: &Mesh, b: &Mesh) -> (f32, f32) {
    let mut d: Vec<f32> = (a.positions.iter().zip(&b.positions))
        .map(|(p, q)| p.distance(*q))
        .collect();
    (percentile(&mut d, 0.5), percentile(&mut d, 0.99))
}

/// One row of the character's table; what a step does not have is a dash.
#[derive(Default)]
struct Row {
    particles: Option<usize>,
    setup_ms: Option<f64>,
    frame_ms: Option<f64>,
    /// Signed volume over the rest mesh's.
    volume: Option<f64>,
    /// Median and 99th percentile of the distance from LBS's vertices, m.
    from_lbs: Option<(f32, f32)>,
}

impl Row {
    /// A one-off step: its time only.
    fn setup(ms: f64) -> Self {
        Row {
            setup_ms: Some(ms),
            ..Row::default()
        }
    }

    /// A per-frame step, and the volume it leaves when it makes a mesh.
    fn frame(ms: f64, volume: Option<f64>) -> Self {
        Row {
            frame_ms: Some(ms),
            volume,
            ..Row::default()
        }
    }

    fn write(&self, s: &mut String, label: &str) {
        fn cell<T>(v: Option<T>, f: impl Fn(T) -> String) -> String {
            v.map_or_else(|| "–".into(), f)
        }
        let ms = |v: f64| format!("{v:.3}");
        let line = format!(
            "| {label} | {} | {} | {} | {} | {} | {} |",
            cell(self.particles, |n| n.to_string()),
            cell(self.setup_ms, ms),
            cell(self.frame_ms, ms),
            cell(self.volume, |v| format!("{v:.3}")),
            cell(self.from_lbs, |d| format!("{:.4}", d.0)),
            cell(self.from_lbs, |d| format!("{:.4}", d.1)),
        );
        eprintln!("skin: wuson: {line}");
        let _ = writeln!(s, "{line}");
    }
}

/// Per method, the median ms per frame of the walk and its last frame's mesh.
struct Walk {
    frames: u32,
    pose_ms: f64,
    lbs: (f64, Mesh),
    dqs: (f64, Mesh),
    particles: (f64, Mesh),
    particle_count: usize,
    particle_setup_ms: f64,
}

/// The walk's poses at the frame boundaries k/FPS, k = 0..=frames (made before the timed
/// frames, which time posing in a row of its own): as posed, and made rigid.
type Poses = Vec<Vec<Affine3A>>;

/// Frame k runs from k/FPS to (k+1)/FPS: frame 0 warms up, `repeat` more are timed.
fn walk(c: &Character, repeat: usize) -> Walk {
    let frames = repeat.max(1) as u32 + 1;
    let at = |k: u32| k as f32 / FPS;
    let posed: Poses = (0..=frames).map(|k| c.skeleton.pose(at(k)).skin).collect();
    let rigid: Poses = (0..=frames)
        .map(|k| c.skeleton.rigid_pose(at(k)).0.skin)
        .collect();
    let (pose_ms, _) = per_frame(frames, 1, |k| c.skeleton.pose(at(k + 1)));
    let blend_frames = |blended: fn(&[Vec3], &Weights, &[Affine3A]) -> Vec<Vec3>, poses: &Poses| {
        per_frame(frames, 1, |k| {
            let skin = &poses[k as usize + 1];
            posed_mesh(&c.mesh, blended(&c.mesh.positions, &c.weights, skin))
        })
    };
    let params = ParticleParams {
        fill: FillParams {
            radius: CHARACTER_FILL,
            ..Default::default()
        },
        ..Default::default()
    };
    let (mut sim, particle_setup_ms) = setup(repeat, || particle_setup(c, &params));
    let particles = per_frame(frames, 1, |k| {
        let (a, b) = (&rigid[k as usize], &rigid[k as usize + 1]);
        sim.step_frame(a, b, k, 1.0 / FPS).expect("particle frame");
        sim.mesh()
    });
    Walk {
        frames,
        pose_ms,
        lbs: blend_frames(blend::lbs, &posed),
        dqs: blend_frames(blend::dqs, &rigid),
        particles,
        particle_count: sim.fill_report().adaptive_count,
        particle_setup_ms,
    }
}

/// The character's table: what loading costs, then per frame of the walk what posing and
/// each method cost and what each changes. LBS against DQS is no error (both only
/// approximate a deformation the file does not state), so the blends' error column is the
/// volume they keep; the particles' is also their distance from LBS, the file's own skinning.
fn character(s: &mut String, root: &Path, repeat: usize) {
    let c = load_character(root, repeat);
    let w = walk(&c, repeat);
    character_intro(s, &c, &w, repeat);
    let rest = measure::volume(&c.mesh);
    let vol = |m: &Mesh| Some(measure::volume(m) / rest);
    Row::setup(c.load_ms).write(s, "load (`Document::load`)");
    Row::setup(c.skeleton_ms).write(s, "skeleton (`Skeleton::from_gltf`)");
    Row::frame(w.pose_ms, None).write(s, "posing (`Skeleton::pose`)");
    Row::frame(w.lbs.0, vol(&w.lbs.1)).write(s, "LBS (file weights)");
    Row::frame(w.dqs.0, vol(&w.dqs.1)).write(s, "DQS (file weights, rigid pose)");
    Row {
        particles: Some(w.particle_count),
        setup_ms: Some(w.particle_setup_ms),
        frame_ms: Some(w.particles.0),
        volume: vol(&w.particles.1),
        from_lbs: Some(distances(&w.particles.1, &w.lbs.1)),
    }
    .write(
        s,
        &format!("particles, defaults (fill r = {CHARACTER_FILL})"),
    );
}

/// What the character's table measures, and on what.
fn character_intro(s: &mut String, c: &Character, w: &Walk, repeat: usize) {
    let last = w.frames as f32 / FPS;
    let _ = writeln!(
        s,
        "\nA character from a file: `{CHARACTER}` (assimp's test quadruped; licence in \
         `assets/characters/LICENSE`), {} vertices in the file, {} after welding by position \
         (the file splits them along UV seams; only the welded mesh is closed), {} triangles, {} \
         joints, walking by its clip \"{CLIP}\" ({:.2} s, looped) at {FPS} fps with the file's \
         weights, as `pipelines/character_walk.ron` skins it. **setup ms**: median of {repeat} \
         after one untimed (load: read and decode; skeleton: weld, joint segments; particles: \
         `ParticleSkin::new` (the fill) + `bind_by_weights` + `place` at the first pose). **ms \
         per frame**: median of {repeat} frames after a warm-up frame (frame k runs from \
         k/{FPS} to (k+1)/{FPS} s; the last ends at {last:.3} s); the poses are made outside \
         the blends' and particles' frames (posing is its own row); blends: vertices and \
         normals; particles: the frame's {} substeps and `mesh()`. **volume**: the last \
         frame's signed volume over the rest mesh's. **from LBS**: the median and \
         99th-percentile distance (m) of the particles' vertices from LBS's in that frame.\n",
        c.file_vertices,
        c.mesh.positions.len(),
        c.mesh.triangles.len(),
        c.skeleton.len(),
        c.clip_s,
        ParticleParams::default().substeps,
    );
    let _ = writeln!(
        s,
        "| step | particles | setup ms | ms per frame | volume | from LBS, median | from LBS, p99 |"
    );
    let _ = writeln!(s, "|---|---:|---:|---:|---:|---:|---:|");
}
