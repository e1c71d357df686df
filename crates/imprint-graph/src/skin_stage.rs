//! The Skin node between frames: its rig, its rest mesh, the method's state (automatic
//! weights for the blends, the particle simulation), and what it measures each frame.
//!
//! **Rest mesh.** The rig's bound OBJ, or the input Mesh node's first value: the rig's bones
//! are in the same space, so a fitted Mesh node must be fitted where the rig's bones are.
//!
//! **Measures** (`report.json`, per frame): the posed mesh's volume over the rest volume, and
//! for each joint (a bone with a parent) the area of the mesh's section by the plane through
//! the joint that halves the angle between the two bones, over the same at rest. The
//! candy-wrapper collapse of LBS under a twist shows as a section ratio near 0, the loss at
//! a bend as a volume ratio below 1.

use crate::schema::{SkinMethod, SkinNode};
use glam::{Affine3A, Vec3};
use imprint_core::{Error, Mesh, Result};
use imprint_gpu::GpuContext;
use imprint_stages::skin::gpu::{BlendMethod, GpuBlend};
use imprint_stages::skin::gpu_particles::GpuParticleSkin;
use imprint_stages::skin::particles::ParticleSkin;
use imprint_stages::skin::rig::{Pose, Rig};
use imprint_stages::skin::weights::{self, Weights};
use imprint_stages::skin::{blend, measure};
use serde_json::{Map, Value, json};
use std::path::Path;
use std::sync::Arc;

/// A Skin node's state.
pub struct SkinStage {
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
    pub fn new(
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
        })
    }

    /// Whether the node's work runs on the GPU.
    pub fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }

    /// The posed mesh at frame `frame` (time `frame / fps`) and the frame's metrics. `input`
    /// is the node's Mesh input, if it has one (read on the first frame only: the rest pose).
    pub fn frame(
        &mut self,
        input: Option<&Arc<Mesh>>,
        frame: u32,
        fps: f32,
    ) -> Result<(Mesh, Value)> {
        let (time, dt_frame) = (frame as f32 / fps, 1.0 / fps);
        let rest = match (&self.rest, input) {
            (Some(r), _) => r.clone(),
            (None, Some(m)) => {
                self.rest = Some(m.clone());
                m.clone()
            }
            (None, None) => unreachable!("the plan checks that a Skin node has a mesh"),
        };
        if self.state.is_none() {
            self.state = Some(self.build(&rest)?);
            let identity = vec![glam::Quat::IDENTITY; self.rig.bones.len()];
            self.rest_measures = Some(measures(
                &self.rig,
                &rest,
                &self.rig.pose_local(&identity, Vec3::ZERO),
            ));
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
                let ctx = self.gpu;
                // One frame on whichever path the node runs on; the CPU reports its metrics.
                let mut step = |start: &[Affine3A],
                                end: &[Affine3A],
                                k: u32,
                                metrics: Option<&mut Map<String, Value>>|
                 -> Result<()> {
                    match (ctx, gpu.as_mut()) {
                        (Some(ctx), Some(g)) => g.step_frame(ctx, start, end, k, dt_frame),
                        _ => {
                            let m = sim.step_frame(start, end, k, dt_frame)?;
                            if let (Some(out), Value::Object(o)) =
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
        let (volume, sections) = measures(&self.rig, &mesh, &pose);
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
        metrics.insert("joints".into(), Value::Object(joints));
        self.last_skin = Some(pose.skin);
        if self.offset != Vec3::ZERO {
            for p in &mut mesh.positions {
                *p += self.offset;
            }
        }
        Ok((mesh, Value::Object(metrics)))
    }

    /// What the node reports once (the particle fill's counts), as (key, value) pairs.
    pub fn summary(&self) -> Vec<(String, Value)> {
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
                let sim = ParticleSkin::new(rest, &segments, p)
                    .map_err(|e| match e {
                        Error::Invalid(m) => Error::Invalid(format!("node '{}': {m}", self.name)),
                        e => e,
                    })?
                    .with_name(&self.name);
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

/// The mesh's volume and its section at each joint (bones with a parent, file order), the
/// plane through the bone's head halving the angle between it and its parent.
fn measures(rig: &Rig, mesh: &Mesh, pose: &Pose) -> (f64, Vec<f64>) {
    let seg = rig.posed_segments(pose);
    let sections = (0..rig.bones.len())
        .filter_map(|b| {
            let parent = rig.index(rig.bones[b].parent.as_deref()?)?;
            let dir = |(h, t): (Vec3, Vec3)| (t - h).normalize_or_zero();
            let (dp, db) = (dir(seg[parent]), dir(seg[b]));
            let normal = (dp + db).try_normalize().unwrap_or(db);
            Some(measure::cross_section_area(mesh, seg[b].0, normal))
        })
        .collect();
    (measure::volume(mesh), sections)
}
