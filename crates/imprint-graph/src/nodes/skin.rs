//! `Skin`: a mesh deformed by a rig (Tokoi's particle skinning with adaptive radii, or linear
//! blend or dual quaternion skinning), with its volume and joint sections per frame.
//!
//! **Rest mesh.** The rig's bound OBJ, or the input Mesh node's first value: the rig's bones
//! are in the same space, so a fitted Mesh node must be fitted where the rig's bones are.
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
use imprint_core::{Error, Mesh, Result};
use imprint_gpu::GpuContext;
use imprint_stages::skin::blend;
use imprint_stages::skin::gpu::{BlendMethod, GpuBlend};
use imprint_stages::skin::gpu_particles::GpuParticleSkin;
use imprint_stages::skin::measure::joint_measures;
use imprint_stages::skin::particles::ParticleSkin;
use imprint_stages::skin::rig::Rig;
use imprint_stages::skin::weights::{self, Weights};
use serde::{Deserialize, Serialize};
use serde_json::{Map, Value as Json, json};
use std::any::Any;
use std::path::Path;
use std::sync::Arc;

/// The Skin node: which mesh, which rig, which method.
#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct SkinNode {
    /// The Mesh node in the rig's rest pose (its first frame is taken as the rest). Leave it
    /// out to load the OBJ the rig file binds (`mesh:` in the rig).
    #[serde(default)]
    pub mesh: Option<String>,
    /// The rig file (RON: bones, binding, animation), relative to the pipeline file.
    pub rig: String,
    /// `Particles(...)` (T, default parameters suit a limb of radius ~0.1 m),
    /// `Linear(...)` or `DualQuaternion(...)`.
    pub method: SkinMethod,
    /// Added to the output's positions (to stand several methods side by side), m.
    #[serde(default)]
    pub offset: (f32, f32, f32),
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

/// How a Skin node deforms its mesh.
#[derive(Clone, Debug, Deserialize, Serialize)]
pub enum SkinMethod {
    /// Tokoi's particle skinning: `imprint_stages::skin::particles::ParticleParams`.
    Particles(#[serde(default)] imprint_stages::skin::particles::ParticleParams),
    /// Linear blend skinning with automatic weights.
    Linear {
        #[serde(default)]
        weights: imprint_stages::skin::weights::WeightMethod,
    },
    /// Dual quaternion skinning with automatic weights.
    DualQuaternion {
        #[serde(default)]
        weights: imprint_stages::skin::weights::WeightMethod,
    },
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
        // The rig file's own errors name its file, line and column.
        let loaded = crate::rig::load(&full)?;
        if self.mesh.is_none() && loaded.mesh.is_none() {
            return Err(ctx.fail(
                "mesh",
                format!(
                    "give the Mesh node to skin (mesh: \"...\"), or bind one in {} (mesh: \"file.obj\")",
                    full.display()
                ),
            ));
        }
        let offset = Vec3::from(self.offset);
        if !offset.is_finite() {
            return Err(ctx.fail("offset", format!("offset {offset} must be finite")));
        }
        match &self.method {
            SkinMethod::Particles(p) => p.validate(),
            SkinMethod::Linear { weights } | SkinMethod::DualQuaternion { weights } => {
                weights.validate()
            }
        }
        .map_err(|e| ctx.fail("method", e))?;
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
    rig: Rig,
    method: SkinMethod,
    offset: Vec3,
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
        let loaded = crate::rig::load(&base_dir.join(&node.rig))?;
        let rest = match (&node.mesh, &loaded.mesh) {
            (None, Some(path)) => Some(Arc::new(Mesh::load_obj(path)?)),
            _ => None,
        };
        Ok(SkinStage {
            name: name.to_string(),
            rig: loaded.rig,
            method: node.method.clone(),
            offset: Vec3::from(node.offset),
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
        let identity = vec![glam::Quat::IDENTITY; self.rig.bones.len()];
        self.rest_measures = Some(joint_measures(
            &self.rig,
            rest,
            &self.rig.pose_local(&identity, Vec3::ZERO),
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
        let pose = self.rig.pose(time);
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
                        let p = self.rig.pose(k as f32 / fps).skin;
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
        let (volume, sections) = joint_measures(&self.rig, &mesh, &pose);
        metrics.insert("frame".into(), frame.into());
        metrics.insert("volume".into(), volume.into());
        metrics.insert("volume_ratio".into(), (volume / rest_volume).into());
        let mut joints = Map::new();
        for ((b, area), rest_area) in self.joints().zip(&sections).zip(rest_sections) {
            joints.insert(
                self.rig.bones[b].name.clone(),
                json!({ "section": area, "section_ratio": area / rest_area }),
            );
        }
        metrics.insert("joints".into(), Json::Object(joints));
        self.last_skin = Some(pose.skin);
        if self.offset != Vec3::ZERO {
            for p in &mut mesh.positions {
                *p += self.offset;
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
        let segments = self.rig.rest_segments();
        Ok(match &self.method {
            SkinMethod::Linear { weights: w } | SkinMethod::DualQuaternion { weights: w } => {
                let weights = weights::automatic(&rest.positions, &segments, w);
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
                let mut sim = ParticleSkin::new(rest, &segments, p)
                    .map_err(|e| match e {
                        Error::Invalid(m) => Error::Invalid(format!("node '{}': {m}", self.name)),
                        e => e,
                    })?
                    .with_name(&self.name);
                // The run's history starts at the rig's first pose, not necessarily its rest.
                sim.place(&segments, &self.rig.pose(0.0).skin)?;
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
        (0..self.rig.bones.len()).filter(|&b| self.rig.bones[b].parent.is_some())
    }
}
