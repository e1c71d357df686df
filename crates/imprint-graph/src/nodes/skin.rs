//! `Skin`: a mesh deformed by a rig (Tokoi's particle skinning with adaptive radii, or linear
//! blend or dual quaternion skinning), with its volume and joint sections per frame.
//!
//! **Rig.** The project's rig RON (bones, procedural bends and keys), or a glTF 2.0 file
//! (`.gltf`, `.glb`) with a skin: its joints are the bones, its clip (`clip: "Walk"`, played
//! at `speed`, looping unless `loop: false`, from `clip_offset` seconds) the animation, and
//! its own weights those of the blends (unless the method names automatic ones). Particles
//! are tied to the joint that the nearest vertex of the rest mesh follows most under the
//! file's weights (`ParticleSkin::bind_by_weights`); a rig RON ties them to the nearest bone
//! segment. See `imprint_stages::skin::skeleton`.
//!
//! **Rest mesh.** The rig's bound mesh (a RON's `mesh:`, a glTF's own mesh at its bind
//! pose), or the input Mesh node's first value: the rig's bones are in the same space, so a
//! fitted Mesh node must be fitted where the rig's bones are.
//!
//! **Measures** (`report.json`, per frame): the posed mesh's volume over the rest volume, and
//! each joint's section over the same at rest (`imprint_stages::skin::measure::joint_measures`).
//!
//! **Self-check** (particles): no particle beyond its reach from its bone's target
//! (`imprint_stages::skin::check`), a hard error: tested after every substep, and before the
//! first frame after a checkpoint against the pose it was saved with.

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
    load_state, save_state,
};
use crate::schema::defaults;
use crate::value::{MeshIn, Value, Values};
use glam::{Affine3A, Vec3};
use imprint_core::gltf::{ClipTime, Document};
use imprint_core::{Error, Mesh, Result};
use imprint_gpu::GpuContext;
use imprint_stages::skin::blend;
use imprint_stages::skin::gpu::{BlendMethod, GpuBlend};
use imprint_stages::skin::gpu_particles::GpuParticleSkin;
use imprint_stages::skin::measure::joint_measures;
use imprint_stages::skin::particles::ParticleSkin;
use imprint_stages::skin::skeleton::Skeleton;
use imprint_stages::skin::weights::{self, Weights};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value as Json, json};
use std::any::Any;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// The Skin node: which mesh, which rig, which method.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SkinNode {
    /// The Mesh node in the rig's rest pose (its first frame is taken as the rest). Leave it
    /// out to load the OBJ the rig file binds (`mesh:` in the rig).
    #[serde(default)]
    pub mesh: Option<String>,
    /// The rig file, relative to the pipeline file: a rig RON (bones, binding, animation) or
    /// a glTF (`.gltf`, `.glb`) with a skin.
    pub rig: String,
    /// A glTF rig's animation clip, by name (the error lists the file's); none holds the bind
    /// pose. Not for a rig RON, whose animation is in the file.
    #[serde(default)]
    pub clip: Option<String>,
    /// Clip seconds per pipeline second.
    #[serde(default = "defaults::one_f32")]
    pub speed: f32,
    /// Whether the clip starts over at its end (else it holds its last pose).
    #[serde(default = "defaults::yes", rename = "loop")]
    pub looping: bool,
    /// Clip time at the pipeline's time 0, s.
    #[serde(default)]
    pub clip_offset: f32,
    /// A glTF rig's character scaled uniformly so that the longest side of its box at the
    /// first frame is `size`, centred on `center` (`fit: (size: 1.8, center: (0, 0.9, 0))`):
    /// for files in other units or far from the origin. A rig RON's mesh is fitted on its
    /// Mesh node instead.
    #[serde(default)]
    pub fit: Option<imprint_stages::mesh::params::Fit>,
    /// `Particles(...)` (T, default parameters suit a limb of radius ~0.1 m),
    /// `Linear(...)` or `DualQuaternion(...)`.
    pub method: SkinMethod,
    /// Added to the output's positions (to stand several methods side by side), m.
    #[serde(default)]
    pub offset: (f32, f32, f32),
    /// A velocity added to the output's positions, m/s: carries a character whose clip walks
    /// in place (most do) across the scene. Match it to the clip's stride, or the feet
    /// slide: a planted foot then stands still.
    #[serde(default)]
    pub travel: (f32, f32, f32),
    /// Where the skinning runs (blends and particles): `Auto`, `Cpu` or `Gpu`; null: the
    /// pipeline's `backend`.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

/// How a Skin node deforms its mesh.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
pub enum SkinMethod {
    /// Tokoi's particle skinning: `imprint_stages::skin::particles::ParticleParams`.
    Particles(#[serde(default)] imprint_stages::skin::particles::ParticleParams),
    /// Linear blend skinning: the rig file's weights (glTF), or automatic ones (`weights:
    /// Distance(power: 4)`, the default for a rig RON).
    Linear {
        /// Automatic weights, e.g. `Distance(power: 4)`; null: the rig file's own weights
        /// (glTF), else `Distance(power: 4)`.
        #[serde(default)]
        weights: Option<imprint_stages::skin::weights::WeightMethod>,
    },
    /// Dual quaternion skinning, weighted as `Linear`.
    DualQuaternion {
        /// Automatic weights, e.g. `Distance(power: 4)`; null: the rig file's own weights
        /// (glTF), else `Distance(power: 4)`.
        #[serde(default)]
        weights: Option<imprint_stages::skin::weights::WeightMethod>,
    },
}

impl SkinNode {
    /// The skeleton of the rig file at `path` and the mesh the file binds, if any: a glTF
    /// (by extension or magic bytes) with the node's clip, or a rig RON.
    fn load(&self, path: &Path) -> crate::Result<(Skeleton, Option<Arc<Mesh>>)> {
        if is_gltf(path) {
            return self.load_gltf(path);
        }
        if self.fit.is_some() {
            return Err(Error::Invalid(format!(
                "fit: {} is a rig RON; fit the Mesh node it skins instead (and the rig's bones \
                 with it, in the rig file)",
                path.display()
            ))
            .into());
        }
        if let Some(clip) = &self.clip {
            return Err(Error::Invalid(format!(
                "clip \"{clip}\": {} is a rig RON, whose animation is in the file; clips \
                 are for glTF rigs",
                path.display()
            ))
            .into());
        }
        let loaded = crate::rig::load(path)?;
        let mesh = match &loaded.mesh {
            Some(m) => Some(Arc::new(imprint_core::load_mesh(m)?)),
            None => None,
        };
        Ok((Skeleton::from_rig(loaded.rig), mesh))
    }

    /// A glTF rig: its skin, posed by the node's clip and fitted when asked.
    fn load_gltf(&self, path: &Path) -> crate::Result<(Skeleton, Option<Arc<Mesh>>)> {
        let doc = Arc::new(Document::load(path)?);
        let time = ClipTime {
            speed: self.speed,
            looping: self.looping,
            offset: self.clip_offset,
        };
        // Fitted as the character stands at the pipeline's first frame (the file's bind
        // space may be far from where its clip puts it).
        let fit = match &self.fit {
            Some(f) => {
                let first = match self.clip.as_deref() {
                    Some(c) => {
                        let clip = doc.clip(c)?;
                        doc.posed_mesh(Some(clip), time.local(clip, 0.0))
                    }
                    None => doc.mesh.clone(),
                };
                Some(first.fit_transform(f.size, f.center))
            }
            None => None,
        };
        let mut skeleton = Skeleton::from_gltf(doc, self.clip.as_deref(), time)?;
        if let Some(m) = fit {
            skeleton = skeleton.fitted(glam::Affine3A::from_mat4(m));
        }
        let mesh = skeleton.bound_mesh().cloned();
        Ok((skeleton, mesh))
    }
}

/// Whether `path` is a glTF file: `.gltf` / `.glb`, or the GLB magic.
fn is_gltf(path: &Path) -> bool {
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase);
    if matches!(ext.as_deref(), Some("gltf" | "glb")) {
        return true;
    }
    let mut magic = [0u8; 4];
    std::fs::File::open(path)
        .and_then(|mut f| std::io::Read::read_exact(&mut f, &mut magic))
        .is_ok_and(|()| &magic == b"glTF")
}

impl Node for SkinNode {
    fn kind(&self) -> &'static str {
        "Skin"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        self.mesh
            .iter()
            .map(|m| Port::new("mesh", m, PortType::Mesh))
            .collect()
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::Mesh)
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::EveryFrame
    }
    fn backend(&self) -> Option<Backend> {
        self.backend
    }
    fn has_gpu_path(&self) -> bool {
        true
    }
    fn track(&self) -> Option<Track> {
        Some(Track::Vertices)
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        let full = ctx.base_dir.join(&self.rig);
        if !full.is_file() {
            return Err(ctx.fail("rig", format!("rig file not found: {}", full.display())));
        }
        // The rig file's own errors name its file (and for a RON, line and column).
        let (_, bound) = self.load(&full).map_err(|e| match e {
            crate::Error::Core(e) => ctx.fail("rig", e),
            e => e,
        })?;
        if self.mesh.is_none() && bound.is_none() {
            return Err(ctx.fail(
                "mesh",
                format!(
                    "give the Mesh node to skin (mesh: \"...\"), or bind one in {} (mesh: \"file.obj\")",
                    full.display()
                ),
            ));
        }
        if !(self.speed.is_finite() && self.clip_offset.is_finite()) {
            return Err(ctx.fail("speed", "speed and clip_offset must be finite"));
        }
        if let SkinMethod::Linear { weights: Some(w) }
        | SkinMethod::DualQuaternion { weights: Some(w) } = &self.method
        {
            w.validate().map_err(|e| ctx.fail("method", e))?;
        }
        let offset = Vec3::from(self.offset);
        if !offset.is_finite() {
            return Err(ctx.fail("offset", format!("offset {offset} must be finite")));
        }
        if let Some(f) = &self.fit
            && !(f.size.is_finite() && f.size > 0.0 && f.center.is_finite())
        {
            return Err(ctx.fail(
                "fit",
                format!("fit.size must be > 0 and finite, got {}", f.size),
            ));
        }
        let travel = Vec3::from(self.travel);
        if !travel.is_finite() {
            return Err(ctx.fail("travel", format!("travel {travel} must be finite")));
        }
        if let SkinMethod::Particles(p) = &self.method {
            p.validate().map_err(|e| ctx.fail("method", e))?;
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let gpu = ctx.choose_gpu()?;
        let input = self.mesh.as_ref().map(|m| ctx.mesh_in(m));
        let stage = SkinStage::new(ctx.name(), self, ctx.check.base_dir, gpu)?;
        Ok(Box::new(SkinNodeStage { input, stage }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// The Skin node at run time: its input and the skinning state.
struct SkinNodeStage {
    input: Option<MeshIn>,
    stage: SkinStage,
}

impl Stage for SkinNodeStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> Result<Step> {
        let mesh_in = match &self.input {
            Some(i) => Some(ctx.values.mesh(i)?.clone()),
            None => None,
        };
        let (mesh, m) = self
            .stage
            .frame(mesh_in.as_ref(), ctx.frame, ctx.fps)
            .map_err(|e| ctx.at_node(e))?;
        if ctx.first {
            for (k, v) in self.stage.summary() {
                ctx.metric(&k, v);
            }
        }
        ctx.push_per_frame(m);
        Ok(Step::computed(Value::Mesh(Arc::new(mesh))))
    }
    fn save(&self, _values: &Values) -> Result<Vec<u8>> {
        self.stage.save()
    }
    fn load(&mut self, bytes: &[u8], _values: &Values) -> Result<()> {
        self.stage.load(bytes)
    }
    fn on_gpu(&self) -> bool {
        self.stage.on_gpu()
    }
}

/// A Skin node's state.
struct SkinStage {
    name: String,
    anim: Animated,
    method: SkinMethod,
    offset: Vec3,
    travel: Vec3,
    /// The rest mesh, once known (the rig's binding at once, an input's on the first frame).
    rest: Option<Arc<Mesh>>,
    state: Option<State>,
    /// The bones' skinning transforms at the last frame's end: this frame's start.
    last_skin: Option<Vec<Affine3A>>,
    /// The rest volume and joint sections.
    rest_measures: Option<(f64, Vec<f64>)>,
    /// The GPU the node runs on, when it does.
    gpu: Option<&'static GpuContext>,
    /// Particles taken from a checkpoint, not yet checked against the pose they were saved
    /// with (see [`SkinStage::frame`]).
    check_loaded: bool,
}

/// The skeleton and how the method poses it.
struct Animated {
    skeleton: Skeleton,
    /// Dual quaternions and particles need rigid transforms.
    rigid: bool,
    /// Whether dropped joint scale was reported.
    warned: AtomicBool,
    node: String,
}

impl Animated {
    /// The skeleton's pose at time `t`, made rigid where the method needs it (a glTF
    /// joint's scale is dropped then, and said once).
    fn pose(&self, t: f32) -> imprint_stages::skin::rig::Pose {
        if !self.rigid {
            return self.skeleton.pose(t);
        }
        let (pose, dropped) = self.skeleton.rigid_pose(t);
        if dropped > 1e-3 && !self.warned.swap(true, Ordering::Relaxed) {
            tracing::warn!(
                "node '{}': the rig's joints scale by up to {:.1}% at {t:.3} s; \
                 dual quaternions and particles follow rotation and translation only (use \
                 method: Linear to follow scale)",
                self.node,
                100.0 * dropped
            );
        }
        pose
    }
}

enum State {
    Blend {
        weights: Weights,
        dual: bool,
        gpu: Option<Box<GpuBlend>>,
    },
    /// The CPU simulator (also the GPU's source, and its mesh's topology) and, when the node
    /// runs on the GPU, the simulation there.
    Particles(Box<ParticleSkin>, Option<Box<GpuParticleSkin>>),
}

impl SkinStage {
    /// Loads the rig (and the mesh it binds, when the node names none). With `gpu`, the node
    /// runs there (the blends, or the particles' substeps and vertices).
    fn new(
        name: &str,
        node: &SkinNode,
        base_dir: &Path,
        gpu: Option<&'static GpuContext>,
    ) -> crate::Result<Self> {
        let (skeleton, bound) = node.load(&base_dir.join(&node.rig))?;
        let rest = if node.mesh.is_none() { bound } else { None };
        Ok(SkinStage {
            name: name.to_string(),
            anim: Animated {
                skeleton,
                rigid: !matches!(node.method, SkinMethod::Linear { .. }),
                warned: AtomicBool::new(false),
                node: name.to_string(),
            },
            method: node.method.clone(),
            offset: Vec3::from(node.offset),
            travel: Vec3::from(node.travel),
            rest,
            state: None,
            last_skin: None,
            rest_measures: None,
            gpu,
            check_loaded: false,
        })
    }

    /// Whether the node's work runs on the GPU.
    pub fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }

    /// The rest mesh, the particles (when the method has them; read back from the GPU when
    /// they run there) and the last frame's bones.
    fn save(&self) -> Result<Vec<u8>> {
        let particles = match (&self.state, self.gpu) {
            (Some(State::Particles(sim, Some(g))), Some(ctx)) => {
                let mut now = (**sim).clone();
                g.read_into(ctx, &mut now)?;
                Some(now)
            }
            (Some(State::Particles(sim, _)), _) => Some((**sim).clone()),
            _ => None,
        };
        save_state(&(&self.rest, particles, &self.last_skin))
    }

    /// Takes back what [`SkinStage::save`] gave: the method's state is built again from the
    /// rest mesh (weights, GPU buffers), the particles are the saved ones.
    fn load(&mut self, bytes: &[u8]) -> Result<()> {
        type Saved = (
            Option<Arc<Mesh>>,
            Option<ParticleSkin>,
            Option<Vec<Affine3A>>,
        );
        let (rest, particles, last_skin): Saved = load_state(bytes)?;
        self.state = None;
        if let Some(rest) = rest {
            self.begin(&rest)?;
            self.rest = Some(rest);
        }
        if let (Some(State::Particles(sim, gpu)), Some(p)) = (&mut self.state, particles) {
            **sim = p;
            self.check_loaded = true;
            if let (Some(g), Some(ctx)) = (gpu, self.gpu) {
                **g = GpuParticleSkin::new(ctx, sim)?;
            }
        }
        self.last_skin = last_skin;
        Ok(())
    }

    /// The method's state and the rest measures, from the rest mesh.
    fn begin(&mut self, rest: &Mesh) -> Result<()> {
        self.state = Some(self.build(rest)?);
        self.rest_measures = Some(joint_measures(
            &self.anim.skeleton,
            rest,
            &self.anim.skeleton.rest_pose(),
        ));
        Ok(())
    }

    /// The posed mesh at frame `frame` (time `frame / fps`) and the frame's metrics. `input`
    /// is the node's Mesh input, if it has one (read on the first frame only: the rest pose).
    pub fn frame(
        &mut self,
        input: Option<&Arc<Mesh>>,
        frame: u32,
        fps: f32,
    ) -> Result<(Mesh, Json)> {
        let (time, dt_frame) = (frame as f32 / fps, 1.0 / fps);
        let rest = match (&self.rest, input) {
            (Some(r), _) => r.clone(),
            (None, Some(m)) => {
                self.rest = Some(m.clone());
                m.clone()
            }
            (None, None) => {
                return Err(Error::Invalid(format!(
                    "node '{}': no mesh to skin",
                    self.name
                )));
            }
        };
        if self.state.is_none() {
            self.begin(&rest)?;
        }
        let pose = self.anim.pose(time);
        let mut metrics = Map::new();
        let mut mesh = match self.state.as_mut().expect("built above") {
            State::Blend { weights, dual, gpu } => {
                let positions = match (self.gpu, gpu) {
                    (Some(ctx), Some(g)) => {
                        let method = if *dual {
                            BlendMethod::DualQuaternion
                        } else {
                            BlendMethod::Linear
                        };
                        g.skin(ctx, method, &pose.skin)?
                    }
                    _ if *dual => blend::dqs(&rest.positions, weights, &pose.skin),
                    _ => blend::lbs(&rest.positions, weights, &pose.skin),
                };
                let mut m = (*rest).clone();
                m.positions = positions;
                m.compute_normals();
                m
            }
            State::Particles(sim, gpu) => {
                // The self-check: no particle beyond its reach. The substeps test it after
                // each substep (a blow-up: raise substeps); particles a checkpoint gave are
                // tested first against the pose they were saved with, so that a state the
                // simulation did not make is named as such (a hard error, like the blow-up:
                // no approximation of the model puts a particle there).
                if std::mem::take(&mut self.check_loaded)
                    && let Some(saved) = &self.last_skin
                {
                    sim.check_reach(saved)?;
                }
                let ctx = self.gpu;
                // One frame on whichever path the node runs on; the CPU reports its metrics.
                let mut step = |start: &[Affine3A],
                                end: &[Affine3A],
                                k: u32,
                                metrics: Option<&mut Map<String, Json>>|
                 -> Result<()> {
                    match (ctx, gpu.as_mut()) {
                        (Some(ctx), Some(g)) => g.step_frame(ctx, start, end, k, dt_frame),
                        _ => {
                            let m = sim.step_frame(start, end, k, dt_frame)?;
                            if let (Some(out), Json::Object(o)) =
                                (metrics, serde_json::to_value(m).expect("plain data"))
                            {
                                out.extend(o);
                            }
                            Ok(())
                        }
                    }
                };
                // A run that starts after frame 0 first replays the frames before it: the
                // particles' state is their history (so the frame is the whole run's, to the
                // bit, and does not start from rest against a pose far from it).
                if self.last_skin.is_none() {
                    for k in 0..frame {
                        let p = self.anim.pose(k as f32 / fps).skin;
                        let start = self.last_skin.take().unwrap_or_else(|| p.clone());
                        step(&start, &p, k, None)?;
                        self.last_skin = Some(p);
                    }
                }
                let start = self.last_skin.as_deref().unwrap_or(&pose.skin);
                step(start, &pose.skin, frame, Some(&mut metrics))?;
                match (ctx, gpu.as_ref()) {
                    (Some(ctx), Some(g)) => {
                        let mut m = (*rest).clone();
                        m.positions = g.vertices(ctx)?;
                        m.compute_normals();
                        m
                    }
                    _ => sim.mesh(),
                }
            }
        };
        let (rest_volume, rest_sections) = self.rest_measures.as_ref().expect("built above");
        let (volume, sections) = joint_measures(&self.anim.skeleton, &mesh, &pose);
        metrics.insert("frame".into(), frame.into());
        metrics.insert("volume".into(), volume.into());
        metrics.insert("volume_ratio".into(), (volume / rest_volume).into());
        let mut joints = Map::new();
        for ((b, area), rest_area) in self.joints().zip(&sections).zip(rest_sections) {
            joints.insert(
                self.anim.skeleton.names[b].clone(),
                json!({ "section": area, "section_ratio": area / rest_area }),
            );
        }
        metrics.insert("joints".into(), Json::Object(joints));
        self.last_skin = Some(pose.skin);
        let shift = self.offset + self.travel * time;
        if shift != Vec3::ZERO {
            for p in &mut mesh.positions {
                *p += shift;
            }
        }
        Ok((mesh, Json::Object(metrics)))
    }

    /// What the node reports once (the particle fill's counts), as (key, value) pairs.
    pub fn summary(&self) -> Vec<(String, Json)> {
        match &self.state {
            Some(State::Particles(sim, _)) => {
                let f = sim.fill_report();
                vec![
                    ("particles".into(), f.adaptive_count.into()),
                    ("particles_uniform".into(), f.uniform_count.into()),
                    ("particles_per_level".into(), json!(f.per_level)),
                    ("particle_radii".into(), json!(f.radii)),
                    ("particle_volume".into(), f.particle_volume.into()),
                    ("mesh_volume".into(), f.mesh_volume.into()),
                ]
            }
            _ => Vec::new(),
        }
    }

    fn build(&self, rest: &Mesh) -> Result<State> {
        let segments = &self.anim.skeleton.segments;
        Ok(match &self.method {
            SkinMethod::Linear { weights: w } | SkinMethod::DualQuaternion { weights: w } => {
                let weights = match (w, self.anim.skeleton.file_weights(rest.positions.len())?) {
                    (None, Some(file)) => file,
                    (w, _) => weights::automatic(&rest.positions, segments, &w.unwrap_or_default()),
                };
                let gpu = match self.gpu {
                    Some(ctx) => Some(Box::new(GpuBlend::new(
                        ctx,
                        &rest.positions,
                        &weights,
                        segments.len(),
                    )?)),
                    None => None,
                };
                State::Blend {
                    weights,
                    dual: matches!(self.method, SkinMethod::DualQuaternion { .. }),
                    gpu,
                }
            }
            SkinMethod::Particles(p) => {
                let mut sim = ParticleSkin::new(rest, segments, p)
                    .map_err(|e| match e {
                        Error::Invalid(m) => Error::Invalid(format!("node '{}': {m}", self.name)),
                        e => e,
                    })?
                    .with_name(&self.name);
                let placing = match self.anim.skeleton.file_weights(rest.positions.len())? {
                    Some(file) => sim.bind_by_weights(&file)?,
                    None => sim.segment_weights(segments),
                };
                // The run's history starts at the rig's first pose, not necessarily its rest.
                sim.place(&placing, &self.anim.pose(0.0).skin)?;
                let gpu = match self.gpu {
                    Some(ctx) => Some(Box::new(GpuParticleSkin::new(ctx, &sim)?)),
                    None => None,
                };
                State::Particles(Box::new(sim), gpu)
            }
        })
    }

    /// The bones with a parent (the joints), in file order.
    fn joints(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.anim.skeleton.len()).filter(|&b| self.anim.skeleton.parents[b].is_some())
    }
}
