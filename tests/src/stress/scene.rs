//! Scenes from a seed: pipeline text (and a rig file) with up to four parts side by side, each
//! in its own patch of the world so that they do not touch one another:
//!
//! - **cloth** (at the origin): a body (a shipped mesh or a primitive, fitted) under random
//!   rigid keys, breathe, twist and bend, and a grid cloth dropped on it, colliding with the
//!   body's distance field or its depth maps;
//! - **ground** (around x = 3): a stamp pressed into a ground and dragged along a random path
//!   (rigid keys), sand, snow or a custom material, settled or fully relaxed;
//! - **snow** (around x = −3): snow falling on a mesh and a flat ground, from a random
//!   direction, jitter, rate and repose angle; when both are present, the ground may take the
//!   snow in (`accumulate`) and the stamp is dragged through it there instead;
//! - **skin** (a limb at the origin, shown at z = 3): a capped cylinder on a rig of two or three
//!   bones in a random pose over time (bends, twists, keyed rotations, a moving root), skinned
//!   by particles, linear blend or dual quaternions.
//!
//! Ranges (each part drawn with its own chance, at least one part; 10-30 frames at 24 fps):
//! - body: cow, bunny, Suzanne, teapot, sphere, box, torus, fitted to 0.4-0.8 m; breathe
//!   (2-8%, 0.6-2 s), twist and bend (±30°, periodic 1.2-2.5 s or constant), rigid keys (2-4
//!   keys 0.25-0.5 s apart, steps of ±0.1 size, ±20°, scale 0.85-1.15): surface speeds of
//!   about 1 m/s at most, what the cloth's contact follows (a faster body makes it explode by
//!   design, and the stage says so);
//! - collider: a 24-56³ field (band 2-4 cells) or depth maps (64-160², T's top, front and side
//!   and up to two more views);
//! - cloth: 10-28 × 10-28 particles, 0.8-1.6 × the body's width, dropped 2-30 cm above its
//!   reach, Harada (k 10-120) or Tokoi, 1-4 g particles, ε 4-15 mm but, on a closed body, no
//!   smaller than a field's cell (the contact's resolution: below it thin parts hold
//!   particles, and the Cloth node warns), friction 0-0.6, substeps
//!   24-64 and at least four times what the stability estimate asks (stiffness halved until
//!   that asks at most 32);
//! - ground: 48-128² cells of 8-20 mm, 3-15 cm deep, sand, snow or custom (θ 20-60°, α 1 or
//!   0-1), settled or fully relaxed; a sphere, box, cow or torus of 0.1-0.3 m pressed 5-50 mm
//!   and dragged 1-3 legs at 0.2-1.2 m/s, sometimes lifted out;
//! - snow: 24-64² cells of 2-5 cm, down or tilted up to 27°, 1-8 directions, jitter 0-25°,
//!   64-160² maps, 5-50 mm/s, repose 25-60° (or 90°), 0-24 passes, on a (moving) mesh;
//! - skin: 2-3 bones along a 0.6-1.1 m limb of radius 7-12 cm; bends of 15-100°, twists up to
//!   ±180°, keyed turns of ±60° (half starting away from rest), a moving root; particles,
//!   linear blend or dual quaternions; the particles' turns kept to a limb's pace.
//!
//! Everything runs on the CPU (`backend: Cpu`). Each part's output is kept by one writer that
//! writes on the last frame only (a node that reaches no writer is pruned), so the scene
//! computes every frame and writes almost nothing. Numbers are rounded to 4 decimals before
//! anything is computed from them, so the text says exactly what the generator used.

use super::{Rng, r4};
use glam::Vec3;
use imprint_stages::cloth::{ClothAssets, ClothParams, ClothSim, Material, Shape};
use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// Frames per second of every scene (the particle skin's default substeps suit 24).
pub const FPS: f32 = 24.0;

/// The most substeps a cloth's springs may need; stiffer materials are softened until they fit.
const MAX_CLOTH_SUBSTEPS: u32 = 32;

/// A generated scene.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    pub seed: u64,
    pub frames: u32,
    /// The pipeline file's text.
    pub pipeline: String,
    /// The rig file's text, when the scene skins a limb (written as [`Scene::rig_file`]).
    pub rig: Option<String>,
    /// One line per part: what was drawn.
    pub parts: Vec<String>,
}

impl Scene {
    /// The pipeline file's name.
    pub fn file(seed: u64) -> String {
        format!("seed-{seed}.ron")
    }

    /// The rig file's name (beside the pipeline, which names it relatively).
    pub fn rig_file(seed: u64) -> String {
        format!("seed-{seed}.rig.ron")
    }

    /// The scene of `seed`: the same text for the same seed.
    pub fn generate(seed: u64) -> Scene {
        let mut rng = Rng::new(seed);
        let frames = rng.int(10, 30);
        let mut b = Builder {
            nodes: BTreeMap::new(),
            parts: Vec::new(),
            frames,
            rig: None,
            seed,
        };
        let mut want = [
            rng.chance(0.6),
            rng.chance(0.5),
            rng.chance(0.4),
            rng.chance(0.35),
        ];
        if !want.iter().any(|&w| w) {
            want[rng.int(0, 3) as usize] = true;
        }
        let [cloth, ground, snow, skin] = want;
        if cloth {
            b.cloth(&mut rng);
        }
        let snow_grid = snow.then(|| b.snow(&mut rng));
        if ground {
            // Fresh snow the stamp then presses into, on the snow's cells.
            let on_snow = snow_grid.filter(|_| rng.chance(0.5));
            b.ground(&mut rng, on_snow);
        }
        if skin {
            b.skin(&mut rng);
        }
        let mut text = String::new();
        let _ = writeln!(
            text,
            "// imprint scene stress, seed {seed} (generated by imprint_tests::stress::scene; \
             tests/tests/stress.rs)."
        );
        for p in &b.parts {
            let _ = writeln!(text, "// {p}");
        }
        let _ = writeln!(
            text,
            "//\n//   imprint run {} --out out/seed-{seed}",
            Self::file(seed)
        );
        let _ = writeln!(
            text,
            "Pipeline(\n    frames: {frames},\n    fps: {},\n    backend: Cpu,\n    seed: {seed},\n    nodes: {{",
            f(FPS)
        );
        for (name, node) in &b.nodes {
            let _ = writeln!(text, "        \"{name}\": {node},");
        }
        text += "    },\n)\n";
        Scene {
            seed,
            frames,
            pipeline: text,
            rig: b.rig,
            parts: b.parts,
        }
    }

    /// Writes the scene into `dir` (the rig first, then the pipeline, each under a temporary
    /// name renamed into place), with `header` (comment lines, e.g. what failed) on top of the
    /// pipeline; returns the pipeline's path.
    pub fn write(&self, dir: &Path, header: &str) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(dir)?;
        let io = |e: imprint_core::Error| std::io::Error::other(e.to_string());
        if let Some(rig) = &self.rig {
            imprint_core::io::atomic_write_bytes(
                &dir.join(Self::rig_file(self.seed)),
                rig.as_bytes(),
            )
            .map_err(io)?;
        }
        let path = dir.join(Self::file(self.seed));
        let text = format!("{header}{}", self.pipeline);
        imprint_core::io::atomic_write_bytes(&path, text.as_bytes()).map_err(io)?;
        Ok(path)
    }
}

/// A number as the pipeline text holds it.
fn f(x: f32) -> String {
    let s = format!("{:.4}", r4(x as f64));
    if s == "-0.0000" { "0.0000".into() } else { s }
}

fn v3(v: Vec3) -> String {
    format!("({}, {}, {})", f(v.x), f(v.y), f(v.z))
}

/// The scene under construction.
struct Builder {
    nodes: BTreeMap<String, String>,
    parts: Vec<String>,
    frames: u32,
    rig: Option<String>,
    seed: u64,
}

/// A cell grid on the ground plane shared by a snow ground and a ground.
#[derive(Clone, Copy, Debug)]
struct Grid {
    cell: f32,
    n: [u32; 2],
    /// World (x, z) of the centre of cell (0, 0).
    origin: [f32; 2],
    /// The bare ground's height, m.
    height: f32,
}

impl Grid {
    fn size(&self) -> [f32; 2] {
        [
            r4(self.n[0] as f64 * self.cell as f64),
            r4(self.n[1] as f64 * self.cell as f64),
        ]
    }

    /// A grid of `n` cells of `cell` m centred on (x, z).
    fn centred(cell: f32, n: [u32; 2], x: f32, z: f32, height: f32) -> Grid {
        let o = |c: f32, n: u32| r4(c as f64 - 0.5 * (n - 1) as f64 * cell as f64);
        Grid {
            cell,
            n,
            origin: [o(x, n[0]), o(z, n[1])],
            height,
        }
    }

    /// The world (x, z) box of the cells' centres, shrunk by `margin` on every side.
    fn inner(&self, margin: f32) -> ([f32; 2], [f32; 2]) {
        let hi = |k: usize| self.origin[k] + (self.n[k] - 1) as f32 * self.cell - margin;
        (
            [self.origin[0] + margin, self.origin[1] + margin],
            [hi(0), hi(1)],
        )
    }
}

/// What a Mesh node is made of.
#[derive(Clone, Copy, Debug)]
enum Body {
    /// A shipped OBJ (`assets/meshes/<name>.obj`).
    Obj(&'static str),
    Sphere {
        segments: u32,
        rings: u32,
    },
    Box {
        size: Vec3,
        subdivisions: u32,
    },
    Torus {
        minor: f32,
        segments: u32,
        sides: u32,
    },
}

/// Torus ring radius (the tube's is drawn).
const TORUS_MAJOR: f32 = 0.35;

impl Body {
    fn random(rng: &mut Rng, choices: &[&'static str]) -> Body {
        match *rng.pick(choices) {
            "sphere" => Body::Sphere {
                segments: rng.int(16, 32),
                rings: rng.int(8, 16),
            },
            "box" => Body::Box {
                size: Vec3::new(
                    rng.range(0.3, 1.0),
                    rng.range(0.3, 1.0),
                    rng.range(0.3, 1.0),
                ),
                subdivisions: rng.int(2, 8),
            },
            "torus" => Body::Torus {
                minor: rng.range(0.08, 0.18),
                segments: rng.int(16, 32),
                sides: rng.int(8, 16),
            },
            name => Body::Obj(name),
        }
    }

    /// Whether the body has an inside (the shipped cow and the primitives; the bunny, the
    /// teapot and Suzanne are open): only there is a particle inside a failure, and only
    /// there does ε need to reach a field's cell.
    fn closed(&self) -> bool {
        !matches!(self, Body::Obj(n) if *n != "cow")
    }

    fn name(&self) -> &'static str {
        match self {
            Body::Obj(n) => n,
            Body::Sphere { .. } => "sphere",
            Body::Box { .. } => "box",
            Body::Torus { .. } => "torus",
        }
    }

    /// The `path:` or `primitive:` field.
    fn source(&self) -> String {
        match *self {
            Body::Obj(name) => format!("path: \"{}\"", mesh_path(name).display()),
            Body::Sphere { segments, rings } => {
                format!("primitive: Sphere(radius: 0.5, segments: {segments}, rings: {rings})")
            }
            Body::Box { size, subdivisions } => format!(
                "primitive: Box(size: {}, subdivisions: {subdivisions})",
                v3(size)
            ),
            Body::Torus {
                minor,
                segments,
                sides,
            } => format!(
                "primitive: Torus(major: {}, minor: {}, segments: {segments}, sides: {sides})",
                f(TORUS_MAJOR),
                f(minor)
            ),
        }
    }

    /// The rest mesh's box before fitting.
    fn extent(&self) -> Vec3 {
        match *self {
            Body::Obj(name) => obj_extent(name),
            Body::Sphere { .. } => Vec3::ONE,
            Body::Box { size, .. } => size,
            Body::Torus { minor, .. } => {
                let r = 2.0 * (TORUS_MAJOR + minor);
                Vec3::new(r, 2.0 * minor, r)
            }
        }
    }

    /// The box after `fit: (size: size)`.
    fn fitted(&self, size: f32) -> Vec3 {
        let e = self.extent();
        e * (size / e.max_element())
    }

    /// The node text.
    fn node(&self, size: f32, center: Vec3, motion: &[String]) -> String {
        let mut s = format!(
            "Mesh({}, fit: (size: {}, center: {})",
            self.source(),
            f(size),
            v3(center)
        );
        if !motion.is_empty() {
            let _ = write!(s, ", motion: [{}]", motion.join(", "));
        }
        s + ")"
    }
}

/// A shipped mesh, by absolute path (a reproduction file runs from wherever it is written).
fn mesh_path(name: &str) -> PathBuf {
    let p = crate::asset(&format!("meshes/{name}.obj"));
    p.canonicalize().unwrap_or(p)
}

/// The box of a shipped mesh as loaded (read once per process).
fn obj_extent(name: &'static str) -> Vec3 {
    static EXTENTS: OnceLock<std::sync::Mutex<BTreeMap<&'static str, Vec3>>> = OnceLock::new();
    let map = EXTENTS.get_or_init(Default::default);
    let mut m = map.lock().unwrap_or_else(|e| e.into_inner());
    *m.entry(name)
        .or_insert_with(|| crate::mesh(name).bounds().size())
}

const AXES: [&str; 3] = ["X", "Y", "Z"];

/// Deformations (breathe, twist, bend, in a random order) then rigid keys, each drawn with its
/// own chance; `size` is the fitted body's longest side.
///
/// Speeds are kept to what a cloth's contact follows at the substeps drawn: the body's surface
/// moves at about 1 m/s at most (a faster one makes the cloth explode by design, and the
/// stage's error says so: "contact moved particles too far per substep").
fn motions(rng: &mut Rng, duration: f32, size: f32, parts: &mut Vec<String>) -> Vec<String> {
    let mut m = Vec::new();
    if rng.chance(0.45) {
        // Surface speed ≤ a · size/2 · 2π / period ≈ 0.3 m/s.
        let (a, p) = (rng.range(0.02, 0.08), rng.range(0.6, 2.0));
        m.push(format!("Breathe(amplitude: {}, period: {})", f(a), f(p)));
    }
    if rng.chance(0.4) {
        // ≤ 30° · size/√2 · 2π / 1.2 s ≈ 1.1 m/s at the high end.
        let axis = rng.pick(&AXES);
        let d = rng.range(-30.0, 30.0);
        let mut s = format!("Twist(axis: {axis}, degrees: {}", f(d));
        if rng.chance(0.7) {
            let _ = write!(s, ", period: {}", f(rng.range(1.2, 2.5)));
        }
        m.push(s + ")");
    }
    if rng.chance(0.35) {
        let axis = *rng.pick(&AXES);
        let d = rng.range(-30.0, 30.0);
        let mut s = format!("Bend(axis: {axis}, degrees: {}", f(d));
        if rng.chance(0.5) {
            let others: Vec<&str> = AXES.iter().copied().filter(|a| *a != axis).collect();
            let _ = write!(s, ", toward: {}", rng.pick(&others));
        }
        if rng.chance(0.7) {
            let _ = write!(s, ", period: {}", f(rng.range(1.2, 2.5)));
        }
        m.push(s + ")");
    }
    // A random order of the deformations (each keeps its meaning whatever precedes it).
    for i in (1..m.len()).rev() {
        m.swap(i, rng.int(0, i as u32) as usize);
    }
    if rng.chance(0.6) {
        // A walk: keys 0.25-0.5 s apart, each moving ≤ 0.1 size and turning ≤ 20° about one
        // axis from the last (≤ 80°/s), scaling ≤ 8%.
        let keys = rng.int(2, 4);
        let axis = if rng.chance(0.5) {
            rng.pick(&AXES).to_string()
        } else {
            v3(Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(0.2, 1.0),
                rng.range(-1.0, 1.0),
            ))
        };
        let (mut t, mut at, mut turn, mut scale) = (0.0f32, Vec3::ZERO, 0.0f32, 1.0f32);
        let mut s = "Rigid(keys: [(time: 0.0)".to_string();
        for _ in 1..keys {
            t = r4((t + rng.range(0.25, 0.5).min(duration.max(0.3))) as f64);
            at += Vec3::new(
                rng.range(-0.1, 0.1),
                rng.range(-0.03, 0.06),
                rng.range(-0.1, 0.1),
            ) * size;
            turn += rng.range(-20.0, 20.0);
            scale = (scale + rng.range(-0.08, 0.08)).clamp(0.85, 1.15);
            let _ = write!(
                s,
                ", (time: {}, translate: {}, rotate: (axis: {axis}, degrees: {}), scale: {})",
                f(t),
                v3(at),
                f(turn),
                f(scale)
            );
        }
        m.push(s + "])");
    }
    let names: Vec<&str> = m
        .iter()
        .map(|s| s.split('(').next().unwrap_or(""))
        .collect();
    if !names.is_empty() {
        parts.push(format!("  motion: {}", names.join(" → ")));
    }
    m
}

/// A writer that keeps `node` (and what feeds it) running and writes on the last frame only.
fn keeper(kind: &str, node: &str, frames: u32) -> String {
    let when = format!("every: {frames}, offset: {}", frames - 1);
    match kind {
        "mesh" => format!("WriteMesh(mesh: \"{node}\", format: Ply, {when})"),
        _ => format!("WriteHeightmap(heights: \"{node}\", formats: [Npy], {when})"),
    }
}

impl Builder {
    fn duration(&self) -> f32 {
        self.frames as f32 / FPS
    }

    fn add(&mut self, name: &str, node: String) {
        self.nodes.insert(name.to_string(), node);
    }

    /// A body with a cloth dropped on it.
    fn cloth(&mut self, rng: &mut Rng) {
        let body = Body::random(
            rng,
            &[
                "cow",
                "cow",
                "stanford-bunny",
                "suzanne",
                "teapot",
                "sphere",
                "sphere",
                "box",
                "torus",
            ],
        );
        let size = rng.range(0.4, 0.8);
        let fitted = body.fitted(size);
        let center = Vec3::new(0.0, r4(0.5 * fitted.y as f64) + rng.range(0.0, 0.15), 0.0);
        self.parts.push(format!(
            "cloth: on a {} (size {}) at {}",
            body.name(),
            f(size),
            v3(center)
        ));
        let motion = motions(rng, self.duration(), size, &mut self.parts);
        self.add("body", body.node(size, center, &motion));
        let (collider, resolved) = self.collider(rng, fitted);
        // The cloth: a grid above anything the body's motions can reach at the start.
        let n = [rng.int(10, 28), rng.int(10, 28)];
        let side = fitted.x.max(fitted.z);
        let csize = [
            r4((side * rng.range(0.8, 1.6)) as f64),
            r4((side * rng.range(0.8, 1.6)) as f64),
        ];
        let drop = rng.range(0.02, 0.3);
        let top = center.y + 0.55 * fitted.length() * 1.15;
        let ccenter = Vec3::new(
            rng.range(-0.15, 0.15) * side,
            r4((top + drop) as f64),
            rng.range(-0.15, 0.15) * side,
        );
        let normal = if rng.chance(0.3) {
            Vec3::new(rng.range(-0.3, 0.3), 1.0, rng.range(-0.3, 0.3))
        } else {
            Vec3::Y
        };
        let mass = rng.range(0.001, 0.004);
        let damping = rng.range(0.98, 0.998);
        let tokoi = rng.chance(0.3);
        let mut k = if tokoi {
            [
                rng.range(500.0, 6000.0),
                rng.range(5000.0, 50000.0),
                rng.range(0.0, 0.0005),
            ]
        } else {
            let ks = rng.range(10.0, 120.0);
            [
                ks,
                r4((ks * rng.range(0.1, 0.3)) as f64),
                if rng.chance(0.3) {
                    r4((ks * rng.range(0.05, 0.2)) as f64)
                } else {
                    0.0
                },
            ]
        };
        let material = |k: &[f32; 3]| {
            if tokoi {
                Material::Tokoi {
                    a_compress: k[0],
                    b_stretch: k[1],
                    bend_c: k[2],
                    anisotropy: None,
                }
            } else {
                Material::Harada {
                    k_structural: k[0],
                    k_shear: k[1],
                    k_bend: (k[2] > 0.0).then_some(k[2]),
                }
            }
        };
        // Substeps: at least what the stability estimate asks (an explicit integrator blows
        // up past its step: that is the user's setting, not a bug), softening what needs too
        // many.
        let needed = |k: &[f32; 3]| {
            let mut p = ClothParams::new(
                Shape::Grid {
                    size: csize,
                    resolution: n,
                    center: ccenter,
                    normal,
                },
                material(k),
            );
            p.mass = mass;
            p.damping = damping;
            ClothSim::from_assets(&p, &ClothAssets::default())
                .expect("a generated cloth builds")
                .stability()
                .substeps_for(1.0 / FPS)
        };
        while needed(&k) > MAX_CLOTH_SUBSTEPS {
            k = [r4(k[0] as f64 / 2.0), r4(k[1] as f64 / 2.0), k[2]];
            if !tokoi {
                k[2] = r4(k[2] as f64 / 2.0);
            }
        }
        let need = needed(&k);
        // Four times the springs' need at least: contact with a moving body moves particles
        // too (the stage's hint doubles the substeps for that; twice still left about one
        // scene in a hundred exploding where the body pinches the cloth, and four times
        // none of those, harada_cloth.ron's bunny takes five).
        let substeps = rng.int(24, 64).max(4 * need);
        let material_text = if tokoi {
            format!(
                "Tokoi(a_compress: {}, b_stretch: {}, bend_c: {})",
                f(k[0]),
                f(k[1]),
                f(k[2])
            )
        } else if k[2] > 0.0 {
            format!(
                "Harada(k_structural: {}, k_shear: {}, k_bend: {})",
                f(k[0]),
                f(k[1]),
                f(k[2])
            )
        } else {
            format!("Harada(k_structural: {}, k_shear: {})", f(k[0]), f(k[1]))
        };
        let (eps, friction) = (rng.range(0.004, 0.015), rng.range(0.0, 0.6));
        let eps = if body.closed() {
            ((eps.max(resolved) as f64 * 1e4).ceil() / 1e4) as f32
        } else {
            eps
        };
        self.parts.push(format!(
            "  cloth: {}x{} grid {}x{} m from y {}, {material_text}, mass {}, damping {}, \
             {substeps} substeps (springs stable from {need}), epsilon {}, friction {}",
            n[0],
            n[1],
            f(csize[0]),
            f(csize[1]),
            f(ccenter.y),
            f(mass),
            f(damping),
            f(eps),
            f(friction)
        ));
        self.add(
            "cloth",
            format!(
                "Cloth({collider}, params: (shape: Grid(size: ({}, {}), resolution: ({}, {}), \
                 center: {}, normal: {}), material: {material_text}, mass: {}, damping: {}, \
                 collision: (epsilon: {}, friction: {}, ground: 0.0), substeps: {substeps}))",
                f(csize[0]),
                f(csize[1]),
                n[0],
                n[1],
                v3(ccenter),
                v3(normal),
                f(mass),
                f(damping),
                f(eps),
                f(friction)
            ),
        );
        let frames = self.frames;
        self.add("keep_cloth", keeper("mesh", "cloth", frames));
    }

    /// Snow on a mesh and a flat ground around x = −3; returns the ground's cells.
    fn snow(&mut self, rng: &mut Rng) -> Grid {
        let cell = rng.range(0.02, 0.05);
        let n = [rng.int(24, 64), rng.int(24, 64)];
        let grid = Grid::centred(cell, n, -3.0, 0.0, rng.range(0.0, 0.1));
        let size = grid.size();
        let body = Body::random(
            rng,
            &[
                "teapot",
                "stanford-bunny",
                "suzanne",
                "cow",
                "sphere",
                "box",
                "torus",
            ],
        );
        let bsize = r4((size[0].min(size[1]) * rng.range(0.3, 0.6)) as f64);
        let fitted = body.fitted(bsize);
        let center = Vec3::new(
            -3.0 + rng.range(-0.1, 0.1) * size[0],
            r4((grid.height + 0.5 * fitted.y) as f64) + rng.range(0.0, 0.2),
            rng.range(-0.1, 0.1) * size[1],
        );
        self.parts.push(format!(
            "snow: on a {} (size {}) and a {}x{} ground of {} m cells at height {}",
            body.name(),
            f(bsize),
            n[0],
            n[1],
            f(cell),
            f(grid.height)
        ));
        let motion = if rng.chance(0.35) {
            motions(rng, self.duration(), bsize, &mut self.parts)
        } else {
            Vec::new()
        };
        self.add("snow_body", body.node(bsize, center, &motion));
        let direction = if rng.chance(0.4) {
            Vec3::NEG_Y
        } else {
            Vec3::new(rng.range(-0.5, 0.5), -1.0, rng.range(-0.5, 0.5))
        };
        let repose = if rng.chance(0.2) {
            90.0
        } else {
            rng.range(25.0, 60.0)
        };
        let params = format!(
            "direction: {}, directions: {}, jitter_degrees: {}, seed: {}, resolution: {}, \
             rate: {}, repose_degrees: {}, relax_passes: {}",
            v3(direction),
            rng.int(1, 8),
            f(rng.range(0.0, 25.0)),
            rng.int(0, 1000),
            rng.int(64, 160),
            f(rng.range(0.005, 0.05)),
            f(repose),
            rng.int(0, 24)
        );
        self.parts.push(format!("  snow: {params}"));
        self.add(
            "snow",
            format!(
                "Snow(meshes: [\"snow_body\"], ground: (size: ({}, {}), resolution: ({}, {}), \
                 origin: ({}, {}), height: {}), params: ({params}))",
                f(size[0]),
                f(size[1]),
                n[0],
                n[1],
                f(grid.origin[0]),
                f(grid.origin[1]),
                f(grid.height)
            ),
        );
        let frames = self.frames;
        self.add("keep_snow", keeper("heights", "snow", frames));
        grid
    }

    /// The cloth's collider for a body of box `fitted`: a distance field (with its Voxelize
    /// node) or depth maps; its text in the Cloth node, and a field's cell (about; 0 for depth
    /// maps).
    fn collider(&mut self, rng: &mut Rng, fitted: Vec3) -> (String, f32) {
        let by_field = rng.chance(0.7);
        // A field's cell (about): its contact is exact to about a cell, so for a closed body
        // ε is drawn no smaller (the Cloth node warns below it). Depth maps keep the ε drawn:
        // the check allows them a texel (see `check`).
        let mut resolved = 0.0f32;
        let collider = if by_field {
            let (res, pad, band) = (rng.int(24, 56), rng.range(0.1, 0.2), rng.range(2.0, 4.0));
            // Fit: the swept box's longest side (the body's, grown by its motion) with padding.
            resolved = 1.3 * fitted.max_element() * (1.0 + 2.0 * pad) / res as f32;
            self.add(
                "vox",
                format!(
                    "Voxelize(mesh: \"body\", grid: Fit(resolution: {res}, padding: {}))",
                    f(pad)
                ),
            );
            self.add(
                "field",
                format!(
                    "DistanceField(boundary: \"vox\", band: {}, measure: Never)",
                    f(band)
                ),
            );
            self.parts.push(format!(
                "  collider: distance field {res}³, band {}",
                f(band)
            ));
            "colliders: [\"field\"]".to_string()
        } else {
            // T's three axes (top, front, side: fewer leave a body's sides unseen, a known
            // limit of the method), in a random order, and up to two more directions.
            let mut views: Vec<String> = ["(0, -1, 0)", "(0, 0, -1)", "(1, 0, 0)"]
                .map(String::from)
                .to_vec();
            for i in (1..views.len()).rev() {
                views.swap(i, rng.int(0, i as u32) as usize);
            }
            for _ in 0..rng.int(0, 2) {
                views.push(v3(Vec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 0.2),
                    rng.range(-1.0, 1.0),
                )));
            }
            let res = rng.int(64, 160);
            self.parts.push(format!(
                "  collider: depth maps {res}², {} views",
                views.len()
            ));
            format!(
                "depth_colliders: [(body: \"body\", params: (views: [{}], resolution: {res}))]",
                views.join(", ")
            )
        };
        (collider, resolved)
    }

    /// A stamp pressed into a ground and dragged along a path: on its own ground around
    /// x = 3, or on `snow`'s cells taking the snow in.
    fn ground(&mut self, rng: &mut Rng, snow: Option<Grid>) {
        let grid = snow.unwrap_or_else(|| {
            let cell = rng.range(0.008, 0.02);
            let n = [rng.int(48, 128), rng.int(48, 128)];
            Grid::centred(cell, n, 3.0, 0.0, rng.range(0.03, 0.15))
        });
        let size = grid.size();
        let material = match rng.int(0, 9) {
            0..=3 => "Preset(Sand)".to_string(),
            4..=6 => "Preset(Snow)".to_string(),
            _ => {
                // Half of them α = 1 (mass exact), half any α (mass moves by what is
                // compressed away).
                let alpha = if rng.chance(0.5) {
                    1.0
                } else {
                    rng.range(0.0, 1.0)
                };
                format!(
                    "Custom(repose_degrees: {}, slump_iterations: {}, displace_ratio: {})",
                    f(rng.range(20.0, 60.0)),
                    rng.int(1, 8),
                    f(alpha)
                )
            }
        };
        let relaxation = if rng.chance(0.15) { "Full" } else { "Settle" };
        let stamp = Body::random(rng, &["sphere", "sphere", "box", "cow", "torus"]);
        let ssize = rng.range(0.1, 0.3).min(0.4 * size[0].min(size[1]));
        let ssize = r4(ssize as f64);
        let fitted = stamp.fitted(ssize);
        let depth = rng.range(
            0.005,
            (0.6 * fitted.y).min(0.05).min(0.8 * grid.height.max(0.02)),
        );
        let margin = 0.5 * fitted.x.max(fitted.z) * 1.5 + 3.0 * grid.cell;
        let (lo, hi) = grid.inner(margin);
        let inside = |p: [f32; 2]| [p[0].clamp(lo[0], hi[0]), p[1].clamp(lo[1], hi[1])];
        let mid = [0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])];
        let spread = [
            0.5 * (hi[0] - lo[0]).max(0.0),
            0.5 * (hi[1] - lo[1]).max(0.0),
        ];
        let start = inside([
            r4((mid[0] + rng.range(-1.0, 1.0) * spread[0]) as f64),
            r4((mid[1] + rng.range(-1.0, 1.0) * spread[1]) as f64),
        ]);
        let y = r4((grid.height + 0.5 * fitted.y - depth) as f64);
        let center = Vec3::new(start[0], y, start[1]);
        // The drag: legs of random direction and speed, the depth varying a little, and
        // sometimes a lift out at the end.
        let speed = rng.range(0.2, 1.2);
        let legs = rng.int(1, 3);
        let mut keys = vec!["(time: 0.0)".to_string()];
        let (mut t, mut at) = (0.0f32, start);
        for _ in 0..legs {
            let dt = rng.range(0.1, 0.3);
            let angle = rng.range(0.0, std::f32::consts::TAU);
            let to = inside([
                r4((at[0] + speed * dt * angle.cos()) as f64),
                r4((at[1] + speed * dt * angle.sin()) as f64),
            ]);
            t = r4((t + dt) as f64);
            at = to;
            keys.push(format!(
                "(time: {}, translate: ({}, {}, {}), rotate: (axis: Y, degrees: {}))",
                f(t),
                f(to[0] - start[0]),
                f(rng.range(-0.3, 0.3) * depth),
                f(to[1] - start[1]),
                f(rng.range(-30.0, 30.0))
            ));
        }
        let lift = rng.chance(0.3);
        if lift {
            keys.push(format!(
                "(time: {}, translate: ({}, {}, {}))",
                f(t + 0.1),
                f(at[0] - start[0]),
                f(depth + 0.05),
                f(at[1] - start[1])
            ));
        }
        self.parts.push(format!(
            "ground: {} {}x{} cells of {} m at height {}{}, {relaxation}; a {} (size {}) \
             pressed {} m, dragged {legs} leg(s) at {} m/s{}",
            material,
            grid.n[0],
            grid.n[1],
            f(grid.cell),
            f(grid.height),
            if snow.is_some() {
                ", taking the snow in"
            } else {
                ""
            },
            stamp.name(),
            f(ssize),
            f(depth),
            f(speed),
            if lift { ", then lifted" } else { "" }
        ));
        let motion = [format!("Rigid(keys: [{}])", keys.join(", "))];
        self.add("stamp", stamp.node(ssize, center, &motion));
        let accumulate = if snow.is_some() {
            ", accumulate: \"snow\""
        } else {
            ""
        };
        self.add(
            "ground",
            format!(
                "Ground(objects: [\"stamp\"]{accumulate}, params: (size: ({}, {}), \
                 resolution: ({}, {}), origin: ({}, {}), initial: Flat({}), material: {material}, \
                 relaxation: {relaxation}))",
                f(size[0]),
                f(size[1]),
                grid.n[0],
                grid.n[1],
                f(grid.origin[0]),
                f(grid.origin[1]),
                f(grid.height)
            ),
        );
        let frames = self.frames;
        self.add("keep_ground", keeper("heights", "ground", frames));
    }

    /// A limb on a rig in a random pose over time.
    fn skin(&mut self, rng: &mut Rng) {
        let bones = rng.int(2, 3);
        let length = rng.range(0.6, 1.1);
        let radius = rng.range(0.07, 0.12);
        let segments = rng.int(12, 32);
        let rings = bones * 2 * rng.int(2, 4);
        let method = *rng.pick(&["Particles()", "Linear()", "DualQuaternion()"]);
        let bone = r4(length as f64 / bones as f64);
        let mut rig = String::from(
            "// The rig of a generated stress scene (imprint_tests::stress).\nRig(\n    bones: [\n",
        );
        for b in 0..bones {
            let (h, t) = (b as f32 * bone, (b + 1) as f32 * bone);
            let parent = if b > 0 {
                format!(", parent: \"b{}\"", b - 1)
            } else {
                String::new()
            };
            let _ = writeln!(
                rig,
                "        (name: \"b{b}\", head: ({}, 0, 0), tail: ({}, 0, 0){parent}),",
                f(h),
                f(t)
            );
        }
        rig += "    ],\n    animation: [\n";
        let mut what = Vec::new();
        let dur = self.duration();
        // Particles follow their bones through a soft pull (`bone_stiffness`), so they lag by
        // about damping / stiffness × the bone's speed; past `max_deviation` the stage stops
        // with a blow-up. Their turns are kept to a limb's pace (a bend's far end moving
        // about 1 m/s, a twist 270°/s), the blends' to 360°/s.
        let particles = method == "Particles()";
        let (bend_speed, twist_speed) = if particles {
            (90.0, 270.0)
        } else {
            (360.0, 360.0)
        };
        // A ramp over [start, start + duration] for a turn of `degrees` at `speed` °/s at most
        // (smoothstep peaks at 1.5 × the mean speed).
        let ramp = |rng: &mut Rng, degrees: f32, speed: f32| {
            let least = 1.5 * degrees.abs() / speed;
            (
                rng.range(0.0, 0.3 * dur),
                r4(rng.range(0.15, 0.6 * dur.max(0.3)).max(least) as f64 + 0.0001),
            )
        };
        for b in 1..bones {
            if rng.chance(0.75) {
                let a = rng.range(0.0, std::f32::consts::TAU);
                let axis = Vec3::new(rng.range(-0.2, 0.2), a.cos(), a.sin());
                let d = rng.range(15.0, 100.0) * rng.sign();
                let (s, du) = ramp(rng, d, bend_speed);
                let _ = writeln!(
                    rig,
                    "        Bend(bone: \"b{b}\", axis: {}, degrees: {}, start: {}, duration: {}),",
                    v3(axis),
                    f(d),
                    f(s),
                    f(du)
                );
                what.push(format!("b{b} bend {}°", f(d)));
            }
            if rng.chance(0.5) {
                let d = rng.range(-180.0, 180.0);
                let (s, du) = ramp(rng, d, twist_speed);
                let _ = writeln!(
                    rig,
                    "        Twist(bone: \"b{b}\", degrees: {}, start: {}, duration: {}),",
                    f(d),
                    f(s),
                    f(du)
                );
                what.push(format!("b{b} twist {}°", f(d)));
            }
            if rng.chance(0.3) {
                // No jumps (Step) for particles, and keys far enough apart for the bends'
                // pace. Half the tracks start away from the rest pose.
                let interp = if particles {
                    *rng.pick(&["Linear", "Smooth"])
                } else {
                    *rng.pick(&["Step", "Linear", "Smooth"])
                };
                let axis = v3(Vec3::new(
                    rng.range(-1.0, 1.0),
                    rng.range(-1.0, 1.0),
                    rng.range(0.1, 1.0),
                ));
                let mut keys = Vec::new();
                let (mut t, mut last) = (0.0f32, 0.0f32);
                let from_rest = rng.chance(0.5);
                for k in 0..rng.int(2, 3) {
                    let d = if k == 0 && from_rest {
                        0.0
                    } else {
                        rng.range(-60.0, 60.0)
                    };
                    if k > 0 {
                        let least = 1.5 * (d - last).abs() / bend_speed;
                        t = r4((t + rng.range(0.1, 0.3).max(least)) as f64 + 0.0001);
                    }
                    keys.push(format!(
                        "(time: {}, rotation: (axis: {axis}, degrees: {}))",
                        f(t),
                        f(d)
                    ));
                    last = d;
                }
                let _ = writeln!(
                    rig,
                    "        Keys(bone: \"b{b}\", interpolation: {interp}, keys: [{}]),",
                    keys.join(", ")
                );
                what.push(format!(
                    "b{b} keys ({interp}, from {})",
                    if from_rest { "rest" } else { "a pose" }
                ));
            }
        }
        if rng.chance(0.3) {
            // The whole limb moved: rigid, so volume is kept whatever the method.
            let (reach, turn) = if particles { (0.1, 20.0) } else { (0.2, 45.0) };
            let tr = v3(Vec3::new(
                rng.range(-reach, reach),
                rng.range(-reach, reach),
                rng.range(-reach, reach),
            ));
            let rot = f(rng.range(-turn, turn));
            let _ = writeln!(
                rig,
                "        Keys(bone: \"b0\", keys: [(time: 0.0, translation: (0, 0, 0), rotation: (axis: (0, 1, 0), degrees: 0)), (time: {}, translation: {tr}, rotation: (axis: (0, 1, 0), degrees: {rot}))]),",
                f(dur)
            );
            what.push("b0 moves".into());
        }
        rig += "    ],\n)\n";
        self.parts.push(format!(
            "skin: {method} on a limb r {} length {}, {segments}x{rings}, {bones} bones: {}",
            f(radius),
            f(length),
            if what.is_empty() {
                "at rest".to_string()
            } else {
                what.join(", ")
            }
        ));
        self.add(
            "limb",
            format!(
                "Mesh(primitive: Cylinder(radius: {}, length: {}, segments: {segments}, rings: {rings}))",
                f(radius),
                f(length)
            ),
        );
        self.add(
            "skin",
            format!(
                "Skin(mesh: \"limb\", rig: \"{}\", method: {method}, offset: (0, 0, 3))",
                Scene::rig_file(self.seed)
            ),
        );
        let frames = self.frames;
        self.add("keep_skin", keeper("mesh", "skin", frames));
        self.rig = Some(rig);
    }
}
