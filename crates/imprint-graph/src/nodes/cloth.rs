//! `Cloth`: a mass-spring cloth pushed by distance fields (blended over each frame) and by
//! bodies read through depth maps; CPU or GPU (fields only).

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
    load_state, save_state,
};
use crate::schema::defaults;
use crate::value::{FieldData, FieldIn, FieldValue, MeshIn, Value, Values};
use glam::Vec3;
use imprint_core::DistanceField;
use imprint_gpu::GpuContext;
use imprint_stages::cloth::attach::Attachment;
use imprint_stages::cloth::gpu::{GpuCloth, GpuCollider};
use imprint_stages::cloth::{Body, ClothParams, ClothSim};
use imprint_stages::drape::{DepthBody, DepthBodyState};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ClothNode {
    /// DistanceField nodes the cloth collides with, applied in this order each substep.
    #[serde(default)]
    pub colliders: Vec<String>,
    /// Bodies the cloth collides with through depth maps (T's draping test every substep,
    /// `imprint_stages::drape::collider`), applied after `colliders` each substep. A cloth
    /// with depth colliders runs on the CPU.
    #[serde(default)]
    pub depth_colliders: Vec<DepthColliderNode>,
    /// Shape, material, pins, contact, substeps: `imprint_stages::cloth::ClothParams`.
    pub params: ClothParams,
    /// A Mesh node the pins ride on (a cape's top edge on a skinned character's shoulders):
    /// on the first frame each pinned particle is tied to the body's nearest surface point,
    /// and from then on follows it, turning with the surface
    /// (`imprint_stages::cloth::attach`). Without it pins stay where they are.
    #[serde(default)]
    pub pins_follow: Option<String>,
    /// Where the cloth is stepped: `Auto`, `Cpu` or `Gpu` (distance-field colliders only);
    /// null: the pipeline's `backend`.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

/// A body read through depth maps by a cloth.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DepthColliderNode {
    /// The Mesh node of the body (any closed mesh, possibly deforming).
    pub body: String,
    /// Views and map resolution: `imprint_stages::drape::DepthColliderParams`.
    #[serde(default)]
    pub params: imprint_stages::drape::DepthColliderParams,
}

impl Node for ClothNode {
    fn kind(&self) -> &'static str {
        "Cloth"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        let fields = self
            .colliders
            .iter()
            .map(|f| Port::new("colliders", f, PortType::DistanceField));
        let bodies = self
            .depth_colliders
            .iter()
            .map(|d| Port::new("depth_colliders", &d.body, PortType::Mesh));
        let follow = self
            .pins_follow
            .iter()
            .map(|m| Port::new("pins_follow", m, PortType::Mesh));
        fields.chain(bodies).chain(follow).collect()
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
        // The GPU cloth reads distance fields only.
        self.depth_colliders.is_empty()
    }
    fn track(&self) -> Option<Track> {
        Some(Track::Vertices)
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        self.params.validate().map_err(|e| ctx.fail("params", e))?;
        if self.pins_follow.is_some() && self.params.pins.is_empty() {
            return Err(ctx.fail(
                "pins_follow",
                "the cloth has no pins to follow the body with; add pins to params (e.g. \
                 pins: [Region(min: (..), max: (..))] around where it hangs)",
            ));
        }
        for d in &self.depth_colliders {
            d.params
                .validate()
                .map_err(|e| ctx.fail("depth_colliders", e))?;
        }
        if !self.depth_colliders.is_empty() && self.backend == Some(Backend::Gpu) {
            return Err(ctx.fail(
                "backend",
                "the GPU cloth reads distance-field colliders only; a cloth with \
                 depth_colliders runs on the CPU (set backend: Cpu, or leave it out)",
            ));
        }
        Ok(())
    }
    /// Explicit integrators have a largest stable step: said before anything runs.
    fn warnings(&self, ctx: &CheckCtx<'_>) -> Vec<String> {
        let sim = ClothSim::new(&self.params, ctx.base_dir);
        let said = sim.map(|s| s.stability().warning(self.params.substeps, 1.0 / ctx.fps));
        match said {
            Ok(w) => w.into_iter().collect(),
            Err(e) => vec![e.to_string()],
        }
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let name = ctx.name().to_string();
        let sim = ClothSim::new(&self.params, ctx.check.base_dir)
            .map_err(|e| imprint_core::Error::Invalid(format!("node '{name}': {e}")))?
            .with_name(name.clone());
        let gpu = self.gpu_cloth(ctx, &sim)?;
        let mut depth = Vec::with_capacity(self.depth_colliders.len());
        for d in &self.depth_colliders {
            let swept = ctx.swept.get(&d.body).copied();
            let eps = self.params.collision.epsilon;
            let body = DepthBody::new(d.params.clone(), eps, swept);
            depth.push((ctx.mesh_in(&d.body), body));
        }
        Ok(Box::new(ClothStage {
            follow: self.pins_follow.as_ref().map(|m| ctx.mesh_in(m)),
            attachment: None,
            colliders: self.colliders.iter().map(|c| ctx.field_in(c)).collect(),
            sim: Box::new(sim),
            previous: Vec::new(),
            gpu,
            depth,
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl ClothNode {
    /// The GPU cloth, when the node runs there (`Auto` falls back to the CPU when the GPU
    /// cannot take this cloth).
    fn gpu_cloth(&self, ctx: &mut BuildCtx<'_>, sim: &ClothSim) -> crate::Result<Option<GpuPath>> {
        if !self.depth_colliders.is_empty() {
            if ctx.want == Backend::Gpu || (ctx.want == Backend::Auto && ctx.gpu.is_some()) {
                ctx.warn(
                    "runs on the CPU: the GPU cloth reads distance-field colliders only, and \
                     it has depth_colliders"
                        .into(),
                );
            }
            return Ok(None);
        }
        let Some(gpu) = ctx.choose_gpu()? else {
            return Ok(None);
        };
        match GpuCloth::new(gpu, sim) {
            Ok(g) => Ok(Some(GpuPath {
                gpu,
                cloth: Box::new(g.with_name(ctx.name().to_string())),
                previous: Vec::new(),
            })),
            Err(e) if ctx.want == Backend::Auto => {
                ctx.warn(format!("runs on the CPU: {e}"));
                Ok(None)
            }
            Err(e) => Err(e.into()),
        }
    }
}

/// The GPU cloth and the colliders it saw last frame (made once per field value: a static
/// field is not uploaded again, and a GPU-built one never leaves the GPU).
struct GpuPath {
    gpu: &'static GpuContext,
    cloth: Box<GpuCloth>,
    previous: Vec<(Arc<FieldValue>, Arc<GpuCollider>)>,
}

impl GpuPath {
    /// The collider of field value `v` on the GPU.
    fn collider(&self, v: &FieldValue) -> imprint_core::Result<GpuCollider> {
        match &v.data {
            FieldData::Gpu(f) => GpuCollider::from_gpu_field(self.gpu, f),
            _ => GpuCollider::from_field(self.gpu, &*v.cpu(Some(self.gpu))?),
        }
    }
}

struct ClothStage {
    /// The body the pins ride on, and where they sit on it (tied on the first frame).
    follow: Option<MeshIn>,
    attachment: Option<Attachment>,
    colliders: Vec<FieldIn>,
    /// The simulation (on the GPU path, a mirror of the GPU's state once per frame).
    sim: Box<ClothSim>,
    /// The colliders' fields at the end of the previous frame: the start of this one.
    previous: Vec<Arc<DistanceField>>,
    gpu: Option<GpuPath>,
    /// Bodies read through depth maps (CPU cloth only).
    depth: Vec<(MeshIn, DepthBody)>,
}

/// A cloth collider over one frame: start field (if blending), end field, span of the blend.
type BodyFields = (Option<Arc<DistanceField>>, Arc<DistanceField>, (f32, f32));

impl Stage for ClothStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if ctx.first {
            self.warn_coarse_fields(ctx)?;
        }
        self.lead_pins(ctx)?;
        let m = match &mut self.gpu {
            Some(g) => step_gpu(g, &mut self.sim, &self.colliders, ctx)?,
            None => self.step_cpu(ctx)?,
        };
        self.warn_band_misses(ctx, &m);
        ctx.push_per_frame(m);
        ctx.metric("particles", self.sim.len());
        Ok(Step::computed(Value::Mesh(Arc::new(self.sim.to_mesh()))))
    }

    fn save(&self, values: &Values) -> imprint_core::Result<Vec<u8>> {
        // A field that is still its collider's value is saved as that (the cloth reads a
        // collider that did not change as static, not as a blend of two equal fields).
        let mut saved: Vec<Option<Arc<DistanceField>>> = Vec::new();
        for (k, c) in self.colliders.iter().enumerate() {
            let now = values.field(c)?;
            saved.push(match &self.gpu {
                Some(g) => match g.previous.get(k) {
                    Some((v, _)) if Arc::ptr_eq(v, now) => None,
                    Some((v, _)) => Some(v.cpu(Some(g.gpu))?),
                    None => continue,
                },
                None => match self.previous.get(k) {
                    Some(f) if matches!(&now.data, FieldData::Cpu(v) if Arc::ptr_eq(v, f)) => None,
                    Some(f) => Some(f.clone()),
                    None => continue,
                },
            });
        }
        let depth: Vec<DepthBodyState> = self.depth.iter().map(|(_, d)| d.state()).collect();
        save_state(&(&*self.sim, saved, depth, &self.attachment))
    }

    fn load(&mut self, bytes: &[u8], values: &Values) -> imprint_core::Result<()> {
        type Saved = (
            ClothSim,
            Vec<Option<Arc<DistanceField>>>,
            Vec<DepthBodyState>,
            Option<Attachment>,
        );
        let (sim, saved, depth, attachment): Saved = load_state(bytes)?;
        self.attachment = attachment;
        let mut previous = Vec::with_capacity(saved.len());
        for (f, c) in saved.into_iter().zip(&self.colliders) {
            previous.push(match f {
                Some(f) => FieldValue::new(FieldData::Cpu(f)),
                None => values.field(c)?.clone(),
            });
        }
        *self.sim = sim;
        for ((_, body), s) in self.depth.iter_mut().zip(depth) {
            body.set_state(s)?;
        }
        match &mut self.gpu {
            Some(g) => {
                *g.cloth = GpuCloth::new(g.gpu, &self.sim)?;
                g.previous = Vec::with_capacity(previous.len());
                for v in previous {
                    let up = Arc::new(g.collider(&v)?);
                    g.previous.push((v, up));
                }
            }
            None => {
                self.previous = previous
                    .iter()
                    .map(|v| v.cpu(None))
                    .collect::<imprint_core::Result<_>>()?;
            }
        }
        Ok(())
    }

    fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }
}

impl ClothStage {
    /// Sets where the pins must be at the frame's end: on the body they follow, tied to it
    /// where they are on the first frame.
    fn lead_pins(&mut self, ctx: &FrameCtx<'_>) -> imprint_core::Result<()> {
        let Some(follow) = &self.follow else {
            return Ok(());
        };
        let body = ctx.values.mesh(follow)?;
        if self.attachment.is_none() {
            let now = self.sim.positions();
            let pins: Vec<Vec3> = self.sim.pinned().iter().map(|&i| now[i as usize]).collect();
            self.attachment = Some(Attachment::new(body, &pins)?);
        }
        let targets = self
            .attachment
            .as_ref()
            .expect("tied above")
            .targets(body)?;
        self.sim.set_pin_targets(&targets)?;
        if let Some(g) = &mut self.gpu {
            g.cloth.set_pin_targets(&targets)?;
        }
        Ok(())
    }

    /// A field is exact to about a cell: where its cells are wider than ε, a part of the body
    /// thinner than a cell (a horn, a leg) can hold a particle inside while the field reads
    /// it outside. Said once, with the resolution that would resolve ε.
    fn warn_coarse_fields(&self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<()> {
        let eps = self.sim.params().collision.epsilon;
        for c in &self.colliders {
            let spec = match &ctx.values.field(c)?.data {
                FieldData::Cpu(f) => f.spec,
                FieldData::Gpu(g) => g.spec,
                FieldData::Blend { b, .. } => b.spec,
            };
            if spec.cell > eps {
                let longest = spec.dims.max_element() as f32;
                let needed = (longest * spec.cell / eps).ceil() as u32;
                let field = c.node().to_string();
                ctx.warn_once(&format!("coarse field '{field}'"), || {
                    format!(
                        "field '{field}' has cells of {:.1} mm, wider than ε = {:.1} mm: a part \
                         of the body thinner than a cell can hold cloth particles inside; a \
                         grid of about {needed} cells along its longest side (or ε ≥ the cell) \
                         keeps them out",
                        spec.cell * 1e3,
                        eps * 1e3
                    )
                });
            }
        }
        Ok(())
    }

    /// A contact that blended a field far from the particle with a near one (a band miss)
    /// means the body moved farther between two fields than their band less ε, and the near
    /// field was read alone: particles can be left inside. The metrics count them per frame;
    /// said once, with the fix.
    fn warn_band_misses(&self, ctx: &mut FrameCtx<'_>, m: &serde_json::Value) {
        let Some(n) = m["band_misses"].as_u64().filter(|&n| n > 0) else {
            return;
        };
        let eps = self.sim.params().collision.epsilon;
        ctx.warn_once("band misses", || {
            format!(
                "{n} contacts read one collider field alone because the other was far from the \
                 particle: between two fields the body moved farther than the band less ε \
                 (ε = {:.1} mm), so particles can be left inside; widen the field's `band` (to \
                 more than ε plus the body's motion between the two fields: a frame's, or \
                 `every` frames' for an interpolated field) or build the field more often",
                eps * 1e3
            )
        });
    }

    /// One frame on the CPU: per collider, the two fields the frame blends between and its
    /// span of the blend (last frame's and this frame's field, or an interpolated node's two
    /// builds around the frame); then the depth-map bodies.
    fn step_cpu(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<serde_json::Value> {
        let mut ends: Vec<BodyFields> = Vec::with_capacity(self.colliders.len());
        for (k, c) in self.colliders.iter().enumerate() {
            let v = ctx.values.field(c)?;
            ends.push(match &v.data {
                FieldData::Blend {
                    a,
                    b,
                    a_key,
                    every,
                    weight,
                } => {
                    let s0 = if ctx.frame == ctx.first_frame {
                        *weight
                    } else {
                        (ctx.frame as i64 - 1 - a_key) as f32 / *every as f32
                    };
                    (Some(a.clone()), b.clone(), (s0, *weight))
                }
                _ => (self.previous.get(k).cloned(), v.cpu(ctx.gpu)?, (0.0, 1.0)),
            });
        }
        let bodies: Vec<Body> = ends
            .iter()
            .map(|(start, end, span)| Body {
                start: start.as_deref(),
                end,
                span: *span,
            })
            .collect();
        let mut poses = Vec::with_capacity(self.depth.len());
        for (mesh, body) in &mut self.depth {
            poses.push(body.poses(ctx.values.mesh(mesh)?)?);
        }
        let depth_colliders: Vec<_> = self
            .depth
            .iter()
            .zip(&poses)
            .filter_map(|((_, body), (start, end))| {
                Some(body.camera()?.collider(start.as_deref(), end))
            })
            .collect();
        let dt = 1.0 / ctx.fps;
        let m = self
            .sim
            .step_frame_between(&bodies, &depth_colliders, ctx.frame, dt)?;
        self.previous = ends.into_iter().map(|(_, e, _)| e).collect();
        Ok(serde_json::to_value(m).expect("plain data"))
    }
}

/// One frame on the GPU. Interpolated colliders arrive as fields blended at the frame's end
/// (and last frame's end is this frame's start); GPU-built fields stay on the GPU. The CPU
/// simulator mirrors the GPU's state once per frame (one read-back, which also gives the
/// mesh), with the metrics the GPU measured.
fn step_gpu(
    g: &mut GpuPath,
    sim: &mut ClothSim,
    colliders: &[FieldIn],
    ctx: &mut FrameCtx<'_>,
) -> imprint_core::Result<serde_json::Value> {
    let mut now = Vec::with_capacity(colliders.len());
    for (k, c) in colliders.iter().enumerate() {
        let v = ctx.values.field(c)?;
        let up = match g.previous.get(k) {
            Some((p, u)) if Arc::ptr_eq(p, v) => u.clone(),
            _ => Arc::new(g.collider(v)?),
        };
        now.push((v.clone(), up));
    }
    let start: Vec<&GpuCollider> = g.previous.iter().map(|(_, u)| &**u).collect();
    let end: Vec<&GpuCollider> = now.iter().map(|(_, u)| &**u).collect();
    let gm = g
        .cloth
        .step_frame(g.gpu, &start, &end, ctx.frame, 1.0 / ctx.fps)?;
    g.previous = now;
    let m =
        sim.adopt_gpu_frame_resident(g.cloth.read_state(g.gpu)?, g.cloth.read_side(g.gpu)?, &gm)?;
    Ok(serde_json::to_value(m).expect("plain data"))
}
