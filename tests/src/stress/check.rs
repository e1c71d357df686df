//! Runs a pipeline file in-process (as `imprint run` loads it) and checks invariants on what
//! every frame published:
//!
//! - **finite**: every node's value is finite, and no frame fails (the executor stops a run
//!   with `Error::Numerical` on a non-finite value; any error is a failure, printed);
//! - **cloth-inside-body**: no vertex of a cloth lies inside a closed body it collides with
//!   (a distance field's mesh, through its Voxelize node, or a depth-map body), by the exact
//!   inside test ([`InsideTest`]) on the body as published that frame; a body is closed when
//!   every edge borders an even number of triangles (`Mesh::is_closed`), which is what the
//!   test needs; open bodies (the teapot, the bunny, Suzanne) are skipped and noted. The depth
//!   of a vertex inside is its exact distance to the surface ([`Bvh`]). A depth-map body is
//!   seen a texel at a time (T's method): vertices inside by less than a texel (the body's
//!   diagonal over the maps' resolution) are counted, not failed; a field's body gets nothing;
//! - **ground-mass**, **ground-slope**: a Ground node's exact mass (integer height units): it
//!   stays what it was plus what `accumulate` added (α = 1), or moves by exactly what the frame
//!   compressed away (α < 1, `removed − displaced`); the report's `mass_units` and the sum of
//!   the published heights in units agree with it; and no two 4-neighbouring cells that no
//!   object holds this frame differ by more than tan θ · cell plus one unit
//!   ([`crate::ground::worst_free_difference`]);
//! - **snow-mass**: a Snow node's ground snow (quanta, whole and fractional) grows each frame
//!   by exactly what fell on it (rate · dt · P · cos φ per cell, measured vertically) less what
//!   slid off the domain, which is nothing: its border is closed, so the stabilisation must
//!   keep the whole quanta bit for bit; the report's `ground_snow_volume` agrees;
//! - **skin-volume**: a Skin node's posed mesh keeps its volume within [`skin_volume_bounds`]
//!   of the rest mesh's, and the report's `volume_ratio` says the same.
//!
//! The Ground and Snow nodes publish only heights, not their integer state, contact maps or
//! the snow that fell; the checker steps a **shadow** simulator beside each (the same stage on
//! the CPU, fed the same published inputs) and first checks that the shadow's heights equal
//! the node's, bit for bit (**ground-shadow**, **snow-shadow**), then reads what it needs from
//! the shadow.

use crate::ground::worst_free_difference;
use imprint_core::bvh::Bvh;
use imprint_core::{HeightField, Mesh};
use imprint_graph::exec::RunOptions;
use imprint_graph::schema::{NodeSpec, SkinMethod};
use imprint_graph::value::Value;
use imprint_graph::{Executor, Plan};
use imprint_stages::drape::InsideTest;
use imprint_stages::ground::{GroundSim, rise};
use imprint_stages::skin::measure;
use imprint_stages::snow::arrival::arrival_cpu;
use imprint_stages::snow::relax::{self, Scratch};
use imprint_stages::snow::{QUANTUM, SnowSim};
use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

/// One invariant broken by one node: the first frame, how many frames, and the worst case.
#[derive(Clone, Debug)]
pub struct Failure {
    pub invariant: &'static str,
    pub node: String,
    pub first_frame: u32,
    pub frames: u32,
    /// The worst frame and what it broke by (in the invariant's own measure: mm, units, …).
    pub worst_frame: u32,
    pub worst: f64,
    pub detail: String,
}

impl std::fmt::Display for Failure {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ('{}'): frames {}.. ({} frame(s)); worst at frame {}: {}",
            self.invariant, self.node, self.first_frame, self.frames, self.worst_frame, self.detail
        )
    }
}

/// What a run did and broke.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// Frames that ran to the end and were checked.
    pub frames_run: u32,
    pub failures: Vec<Failure>,
    /// What was not checked and why (an open body), once each.
    pub notes: Vec<String>,
    /// Node-frames each invariant was checked on.
    pub checked: BTreeMap<&'static str, u32>,
    /// The range (lowest, highest) of what the checks measured, by name (how close the
    /// scenes came to a bound).
    pub ranges: BTreeMap<String, (f64, f64)>,
    pub ms: f64,
}

impl Outcome {
    /// Records that `invariant` broke at `frame` by `worst` (kept per invariant and node).
    fn fail(
        &mut self,
        invariant: &'static str,
        node: &str,
        frame: u32,
        worst: f64,
        detail: String,
    ) {
        if let Some(f) = self
            .failures
            .iter_mut()
            .find(|f| f.invariant == invariant && f.node == node)
        {
            f.frames += 1;
            if worst > f.worst {
                (f.worst_frame, f.worst, f.detail) = (frame, worst, detail);
            }
            return;
        }
        self.failures.push(Failure {
            invariant,
            node: node.to_string(),
            first_frame: frame,
            frames: 1,
            worst_frame: frame,
            worst,
            detail,
        });
    }

    fn checked(&mut self, invariant: &'static str) {
        *self.checked.entry(invariant).or_default() += 1;
    }

    fn measured(&mut self, what: &str, v: f64) {
        let r = self
            .ranges
            .entry(what.to_string())
            .or_insert((f64::INFINITY, f64::NEG_INFINITY));
        *r = (r.0.min(v), r.1.max(v));
    }

    /// Adds `other`'s counts and ranges to this one's (a summary over runs).
    pub fn merge_counts(&mut self, other: &Outcome) {
        for (k, n) in &other.checked {
            *self.checked.entry(k).or_default() += n;
        }
        for (k, &(lo, hi)) in &other.ranges {
            self.measured(k, lo);
            self.measured(k, hi);
        }
    }

    fn note(&mut self, note: String) {
        if !self.notes.contains(&note) {
            self.notes.push(note);
        }
    }
}

/// Volume over rest volume a skinning method must keep, as (lowest, highest): the particles
/// hold it (T §(3); the particle tests allow ±5% under a 180° twist), dual quaternions nearly
/// (they lose some inside a bend and bulge outside it), linear blend loses it at twisted
/// joints (the candy wrapper: 79% at one 180° twist, README; two joints of a three-bone limb
/// lose more) but does not collapse. Over 1,000 generated scenes: particles 0.976-1.002,
/// dual quaternions 0.911-1.024, linear blend 0.520-1.000.
pub fn skin_volume_bounds(method: &SkinMethod) -> (f64, f64) {
    match method {
        SkinMethod::Particles(_) => (0.95, 1.05),
        SkinMethod::DualQuaternion { .. } => (0.85, 1.15),
        SkinMethod::Linear { .. } => (0.4, 1.1),
    }
}

/// Loads `path` as `imprint run` does, runs every frame into `out` on the CPU (whatever the
/// file's backend) and checks the invariants after each (see the module doc).
pub fn run_file(path: &Path, out: &Path) -> Outcome {
    let start = Instant::now();
    let mut o = Outcome::default();
    match imprint_graph::load(path, &[]) {
        Ok(plan) => run_plan(&plan, out, &mut o),
        Err(e) => o.fail("valid pipeline", "-", 0, 1.0, e.to_string()),
    }
    o.ms = start.elapsed().as_secs_f64() * 1e3;
    o
}

fn run_plan(plan: &Plan, out: &Path, o: &mut Outcome) {
    // The CPU: the shadows below are the CPU stages, which the GPU paths are tested against.
    let opts = RunOptions {
        out: out.to_path_buf(),
        backend: Some(imprint_graph::node::Backend::Cpu),
        ..Default::default()
    };
    let mut ex = match Executor::new(plan, opts) {
        Ok(ex) => ex,
        Err(e) => return o.fail("run", "-", 0, 1.0, format!("the stages do not build: {e}")),
    };
    let mut checks = match Checks::new(plan) {
        Ok(c) => c,
        Err(e) => return o.fail("run", "-", 0, 1.0, format!("the shadows do not build: {e}")),
    };
    while !ex.done() {
        let frame = ex.next_frame();
        if let Err(e) = ex.step() {
            let node = match &e {
                imprint_graph::Error::Core(imprint_core::Error::Numerical { node, .. }) => {
                    node.clone()
                }
                _ => "-".into(),
            };
            o.fail(
                "finite",
                &node,
                frame,
                1.0,
                format!("the frame failed: {e}"),
            );
            return;
        }
        checks.frame(&ex, frame, o);
        o.frames_run += 1;
    }
    if let Err(e) = ex.finish() {
        o.fail("run", "-", plan.file.frames, 1.0, format!("finish: {e}"));
    }
}

/// A node's current value as a mesh.
fn mesh_of(ex: &Executor, node: &str) -> Option<Arc<Mesh>> {
    match ex.value(node) {
        Some(Value::Mesh(m)) => Some(m),
        _ => None,
    }
}

/// A node's current value as heights.
fn heights_of(ex: &Executor, node: &str) -> Option<Arc<HeightField>> {
    match ex.value(node) {
        Some(Value::Heights(h)) => Some(h),
        _ => None,
    }
}

/// The last entry of a node's `per_frame` metrics in the report.
fn last_metrics(ex: &Executor, node: &str) -> Option<serde_json::Value> {
    let r = ex.report();
    r.nodes
        .get(node)?
        .metrics
        .get("per_frame")?
        .as_array()?
        .last()
        .cloned()
}

fn same_bits(a: &[f32], b: &[f32]) -> Option<usize> {
    if a.len() != b.len() {
        return Some(a.len().min(b.len()));
    }
    a.iter()
        .zip(b)
        .position(|(x, y)| x.to_bits() != y.to_bits())
}

struct ClothCheck {
    node: String,
    /// The Mesh-valued nodes it collides with, and for a depth-map body its maps' resolution
    /// (the method is exact to a texel; a field's body, to nothing: `None`).
    bodies: Vec<(String, Option<u32>)>,
    closed: BTreeMap<String, bool>,
}

struct GroundShadow {
    node: String,
    sim: GroundSim,
    alpha_one: bool,
    objects: Vec<String>,
    accumulate: Option<String>,
    last: Option<Arc<HeightField>>,
    mass: i64,
}

struct SnowShadow {
    node: String,
    sim: SnowSim,
    ground: HeightField,
    meshes: Vec<String>,
    scratch: Scratch,
    /// Quanta on the ground after the last frame (whole + fractions).
    quanta: f64,
}

struct SkinCheck {
    node: String,
    mesh: String,
    method: &'static str,
    bounds: (f64, f64),
    rest_volume: Option<f64>,
}

struct Checks {
    running: Vec<String>,
    fps: f32,
    cloths: Vec<ClothCheck>,
    grounds: Vec<GroundShadow>,
    snows: Vec<SnowShadow>,
    skins: Vec<SkinCheck>,
}

impl Checks {
    fn new(plan: &Plan) -> imprint_core::Result<Self> {
        let spec = |n: &str| plan.file.nodes.get(n);
        let mut c = Checks {
            running: plan.order.clone(),
            fps: plan.file.fps,
            cloths: Vec::new(),
            grounds: Vec::new(),
            snows: Vec::new(),
            skins: Vec::new(),
        };
        for name in &plan.order {
            match &plan.file.nodes[name] {
                NodeSpec::Cloth(cl) => {
                    // A field's body: the mesh behind its Voxelize node.
                    let mut bodies: Vec<(String, Option<u32>)> = cl
                        .colliders
                        .iter()
                        .filter_map(|f| match spec(f)? {
                            NodeSpec::DistanceField(d) => match spec(&d.boundary)? {
                                NodeSpec::Voxelize(v) => Some((v.mesh.clone(), None)),
                                _ => None,
                            },
                            _ => None,
                        })
                        .collect();
                    bodies.extend(
                        cl.depth_colliders
                            .iter()
                            .map(|d| (d.body.clone(), Some(d.params.resolution))),
                    );
                    c.cloths.push(ClothCheck {
                        node: name.clone(),
                        bodies,
                        closed: BTreeMap::new(),
                    });
                }
                NodeSpec::Ground(g) => {
                    let sim = GroundSim::new(&g.params, &plan.base_dir)?;
                    c.grounds.push(GroundShadow {
                        node: name.clone(),
                        mass: sim.mass(),
                        sim,
                        alpha_one: g.params.material.values().displace_ratio == 1.0,
                        objects: g.objects.clone(),
                        accumulate: g.accumulate.clone(),
                        last: None,
                    });
                }
                NodeSpec::Snow(s) => {
                    if let Some(ground) = &s.ground {
                        c.snows.push(SnowShadow {
                            node: name.clone(),
                            sim: SnowSim::new(&s.params)?,
                            ground: ground.height_field()?,
                            meshes: s.meshes.clone(),
                            scratch: Scratch::default(),
                            quanta: 0.0,
                        });
                    }
                }
                NodeSpec::Skin(s) => {
                    if let Some(mesh) = &s.mesh {
                        c.skins.push(SkinCheck {
                            node: name.clone(),
                            mesh: mesh.clone(),
                            method: match &s.method {
                                SkinMethod::Particles(_) => "particles",
                                SkinMethod::Linear { .. } => "linear blend",
                                SkinMethod::DualQuaternion { .. } => "dual quaternion",
                            },
                            bounds: skin_volume_bounds(&s.method),
                            rest_volume: None,
                        });
                    }
                }
                _ => {}
            }
        }
        Ok(c)
    }

    fn frame(&mut self, ex: &Executor, frame: u32, o: &mut Outcome) {
        for name in &self.running {
            o.checked("finite");
            if let Some(bad) = ex.value(name).and_then(|v| v.first_non_finite()) {
                o.fail("finite", name, frame, 1.0, bad);
            }
        }
        for c in &mut self.cloths {
            cloth_frame(c, ex, frame, o);
        }
        for g in &mut self.grounds {
            ground_frame(g, ex, frame, o);
        }
        let dt = 1.0 / self.fps;
        for s in &mut self.snows {
            snow_frame(s, ex, frame, dt, o);
        }
        for s in &mut self.skins {
            skin_frame(s, ex, frame, o);
        }
    }
}

fn cloth_frame(c: &mut ClothCheck, ex: &Executor, frame: u32, o: &mut Outcome) {
    let Some(cloth) = mesh_of(ex, &c.node) else {
        return o.fail("run", &c.node, frame, 1.0, "no cloth mesh published".into());
    };
    for (b, maps) in &c.bodies {
        let Some(body) = mesh_of(ex, b) else {
            o.note(format!(
                "'{}': body '{b}' has no mesh value (pruned?)",
                c.node
            ));
            continue;
        };
        let closed = *c
            .closed
            .entry(b.clone())
            .or_insert_with(|| !body.triangles.is_empty() && body.is_closed());
        if !closed {
            o.note(format!(
                "'{}': body '{b}' is open, so the inside test does not apply",
                c.node
            ));
            continue;
        }
        let test = InsideTest::new(&body);
        let inside: Vec<usize> = (0..cloth.positions.len())
            .filter(|&i| test.inside(cloth.positions[i]))
            .collect();
        o.checked("cloth-inside-body");
        o.measured("cloth: particles inside a closed body", inside.len() as f64);
        if inside.is_empty() {
            continue;
        }
        let bvh = Bvh::new(&body);
        let (worst, depth) = inside
            .iter()
            .map(|&i| (i, bvh.closest(cloth.positions[i]).distance))
            .fold((0, 0.0f32), |a, b| if b.1 > a.1 { b } else { a });
        // Depth maps see the body a texel at a time (the box's diagonal over the maps'
        // resolution): particles within a texel of its surface are the method's, counted.
        if let Some(res) = maps {
            let texel = body.bounds().size().length() / *res as f32;
            if depth <= texel {
                o.measured(
                    "cloth: particles within a depth-map texel inside",
                    inside.len() as f64,
                );
                continue;
            }
        }
        let mean = inside
            .iter()
            .map(|&i| bvh.closest(cloth.positions[i]).distance as f64)
            .sum::<f64>()
            / inside.len() as f64;
        o.fail(
            "cloth-inside-body",
            &c.node,
            frame,
            depth as f64 * 1e3,
            format!(
                "{} of {} particles inside '{b}', deepest {:.2} mm (particle {worst} at {}), \
                 mean {:.2} mm",
                inside.len(),
                cloth.positions.len(),
                depth * 1e3,
                cloth.positions[worst],
                mean * 1e3
            ),
        );
    }
}

fn ground_frame(g: &mut GroundShadow, ex: &Executor, frame: u32, o: &mut Outcome) {
    let node = g.node.clone();
    // What the node does, on the shadow: the layer's rise first, then the objects' press.
    let before = g.sim.mass();
    if let Some(a) = &g.accumulate {
        let Some(now) = heights_of(ex, a) else {
            return o.fail(
                "ground-shadow",
                &node,
                frame,
                1.0,
                format!("no heights from '{a}'"),
            );
        };
        if let Some(last) = &g.last
            && let Err(e) = g.sim.add_heights(&rise(&now, last))
        {
            return o.fail("ground-shadow", &node, frame, 1.0, e.to_string());
        }
        g.last = Some(now);
    }
    let added = g.sim.mass() - before;
    let objects: Vec<Arc<Mesh>> = g.objects.iter().filter_map(|m| mesh_of(ex, m)).collect();
    let refs: Vec<&Mesh> = objects.iter().map(|m| &**m).collect();
    let m = match g.sim.step(&refs) {
        Ok(m) => m,
        Err(e) => return o.fail("ground-shadow", &node, frame, 1.0, e.to_string()),
    };
    let Some(published) = heights_of(ex, &node) else {
        return o.fail(
            "ground-shadow",
            &node,
            frame,
            1.0,
            "no heights published".into(),
        );
    };
    if let Some(j) = same_bits(&published.heights, &g.sim.to_height_field().heights) {
        o.fail(
            "ground-shadow",
            &node,
            frame,
            1.0,
            format!("the published heights differ from the CPU shadow's first at cell {j}"),
        );
    }
    // Mass, exact.
    let mass = g.sim.mass();
    let unit = g.sim.grid().unit;
    let from_published: i64 = published
        .heights
        .iter()
        .map(|&h| (h as f64 / unit).round() as i64)
        .sum();
    let reported = last_metrics(ex, &node)
        .and_then(|m| m.get("mass_units").and_then(|v| v.as_i64()))
        .unwrap_or(i64::MIN);
    let expected = if g.alpha_one {
        g.mass + added
    } else {
        g.mass + added - m.removed_units + m.displaced_units
    };
    if mass != expected || reported != mass || from_published != mass {
        let rule = if g.alpha_one {
            "α = 1: last frame's + what the layer added"
        } else {
            "last frame's + added − removed + displaced"
        };
        o.fail(
            "ground-mass",
            &node,
            frame,
            (mass - expected).abs().max((reported - mass).abs()) as f64,
            format!(
                "mass {mass} units, expected {expected} ({rule}: {} + {added} − {} + {}); the \
                 report says {reported}, the published heights sum to {from_published}",
                g.mass, m.removed_units, m.displaced_units
            ),
        );
    }
    o.checked("ground-mass");
    o.measured("ground: mass − expected, units", (mass - expected) as f64);
    o.measured("ground: contact cells", m.contact_cells as f64);
    g.mass = mass;
    // Slopes between free neighbours.
    if let Some(t) = g.sim.threshold_units() {
        let d = worst_free_difference(&g.sim);
        o.checked("ground-slope");
        o.measured(
            "ground: steepest free step / (tan θ · cell + 1 unit)",
            d as f64 / (t + 1) as f64,
        );
        if d > t + 1 {
            o.fail(
                "ground-slope",
                &node,
                frame,
                (d - t - 1) as f64,
                format!(
                    "two free neighbours differ by {d} units = {:.4} m, more than tan θ · cell + \
                     one unit = {} units",
                    d as f64 * unit,
                    t + 1
                ),
            );
        }
    }
}

fn snow_frame(s: &mut SnowShadow, ex: &Executor, frame: u32, dt: f32, o: &mut Outcome) {
    let node = s.node.clone();
    let meshes: Vec<Arc<Mesh>> = s.meshes.iter().filter_map(|m| mesh_of(ex, m)).collect();
    let refs: Vec<&Mesh> = meshes.iter().map(|m| &**m).collect();
    // What fell this frame (quanta), and the whole quanta before and after the stabilisation.
    let mut fell = 0.0f64;
    let mut relaxed: Option<(u64, u64)> = None;
    let scratch = &mut s.scratch;
    let stepped = s.sim.step_with_parts(
        &refs,
        Some(&s.ground),
        dt,
        |occluder, receivers, directions, params| {
            let a = arrival_cpu(occluder, receivers, directions, params)?;
            let (fall, gain) = (params.fall(), params.rate * dt);
            fell = receivers
                .ground()
                .map(|i| {
                    let n = receivers.normals[i];
                    let column = gain * a.probability(i) * (-n.dot(fall)).max(0.0) / n.y;
                    column as f64 / QUANTUM as f64
                })
                .sum();
            Ok(a)
        },
        |ground, tan, units, passes| {
            let total = |u: &[u32]| u.iter().map(|&q| q as u64).sum::<u64>();
            let before = total(units);
            let r = relax::relax(ground, tan, units, passes, scratch);
            relaxed = Some((before, total(units)));
            Ok(r)
        },
    );
    if let Err(e) = stepped {
        return o.fail("snow-shadow", &node, frame, 1.0, e.to_string());
    }
    let Some(g) = s.sim.ground() else {
        return o.fail("snow-shadow", &node, frame, 1.0, "no ground snow".into());
    };
    let Some(published) = heights_of(ex, &node) else {
        return o.fail(
            "snow-shadow",
            &node,
            frame,
            1.0,
            "no heights published".into(),
        );
    };
    if let Some(j) = same_bits(&published.heights, &g.surface().heights) {
        o.fail(
            "snow-shadow",
            &node,
            frame,
            1.0,
            format!("the published surface differs from the CPU shadow's first at cell {j}"),
        );
    }
    if let Some((before, after)) = relaxed
        && before != after
    {
        o.fail(
            "snow-mass",
            &node,
            frame,
            before.abs_diff(after) as f64,
            format!(
                "the stabilisation turned {before} whole quanta into {after}; with a closed \
                 border nothing slides off the domain"
            ),
        );
    }
    let quanta = g.total_units() as f64 + g.residual.iter().map(|&r| r as f64).sum::<f64>();
    let gained = quanta - s.quanta;
    let tol = 1e-4 * g.units.len() as f64 + 1e-6 * fell;
    if (gained - fell).abs() > tol {
        o.fail(
            "snow-mass",
            &node,
            frame,
            (gained - fell).abs(),
            format!(
                "the ground gained {gained:.4} quanta, but {fell:.4} fell on it (none can slide \
                 off: the border is closed); tolerance {tol:.4}"
            ),
        );
    }
    o.checked("snow-mass");
    o.measured("snow: quanta fallen per frame", fell);
    o.measured("snow: (gained − fell) / tolerance", (gained - fell) / tol);
    if let Some((_, after)) = relaxed {
        o.measured("snow: whole quanta on the ground", after as f64);
    }
    s.quanta = quanta;
    let reported = last_metrics(ex, &node)
        .and_then(|m| m.get("ground_snow_volume").and_then(|v| v.as_f64()))
        .unwrap_or(f64::NAN);
    let volume = g.volume();
    // A NaN (no figure in the report) fails too.
    let agrees = (reported - volume).abs() <= 1e-12 * volume.abs().max(1e-12);
    if !agrees {
        o.fail(
            "snow-mass",
            &node,
            frame,
            (reported - volume).abs(),
            format!("the report says {reported} m³ of ground snow, the shadow holds {volume} m³"),
        );
    }
}

fn skin_frame(s: &mut SkinCheck, ex: &Executor, frame: u32, o: &mut Outcome) {
    let (Some(rest), Some(posed)) = (mesh_of(ex, &s.mesh), mesh_of(ex, &s.node)) else {
        return o.fail("run", &s.node, frame, 1.0, "no skinned mesh".into());
    };
    let rest_volume = *s.rest_volume.get_or_insert_with(|| measure::volume(&rest));
    let ratio = measure::volume(&posed) / rest_volume;
    let (lo, hi) = s.bounds;
    o.checked("skin-volume");
    o.measured(&format!("skin: volume / rest ({})", s.method), ratio);
    if !(lo..=hi).contains(&ratio) {
        o.fail(
            "skin-volume",
            &s.node,
            frame,
            (ratio - ratio.clamp(lo, hi)).abs(),
            format!("volume {ratio:.4} of rest, outside [{lo}, {hi}]"),
        );
    }
    let reported = last_metrics(ex, &s.node)
        .and_then(|m| m.get("volume_ratio").and_then(|v| v.as_f64()))
        .unwrap_or(f64::NAN);
    let agrees = (reported - ratio).abs() <= 1e-5;
    if !agrees {
        o.fail(
            "skin-volume",
            &s.node,
            frame,
            (reported - ratio).abs(),
            format!("the report says volume {reported:.6} of rest, the mesh measures {ratio:.6}"),
        );
    }
}
