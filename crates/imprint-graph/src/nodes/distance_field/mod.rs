//! `DistanceField`: the narrow-band distance field of a boundary, built on keyframes, split
//! over frames, or built ahead and interpolated (`builds.rs`); its error against the exact
//! distance measured on the frames `measure` names.

mod builds;

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger, load_state,
    save_state,
};
use crate::nodes::voxelize::VoxelizeNode;
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::{BoundaryIn, BoundaryValue, FieldData, FieldValue, MeshIn, Value, Values};
use builds::{Ahead, BuildState, FieldSchedule, Published};
use imprint_core::{DistanceField, Error, Mesh};
use imprint_gpu::GpuContext;
use imprint_stages::mesh::{MeshParams, MeshSource};
use imprint_stages::voxel::cpu::Voxelizer;
use imprint_stages::voxel::gpu::GpuBoundary;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;
use std::time::Instant;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct FieldNode {
    /// The Voxelize node whose boundary the field is built from.
    pub boundary: String,
    /// Half-width of the band, in cells (H's `a`).
    #[serde(default = "default_band")]
    pub band: f32,
    /// Where the field is built: `Auto`, `Cpu` or `Gpu`; null: the pipeline's `backend`.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// On which frames the error against the exact distance is measured (costly: one exact
    /// closest-point query per band cell).
    #[serde(default)]
    pub measure: Measure,
    /// Compute on frames where (frame - offset) mod every = 0 (and on the run's first
    /// frame); consumers reuse the last result in between.
    #[serde(default = "defaults::one")]
    pub every: u32,
    /// Shifts the `every` cycle: frames where (frame - offset) mod every = 0 are built.
    #[serde(default)]
    pub offset: u32,
    /// Spread each build over this many frames (z-slabs, the same field as one build);
    /// the result appears on the last of them. At most `every`.
    #[serde(default = "defaults::one")]
    pub split: u32,
    /// Consumers see the linear blend in time of the two builds around each frame (H eq.
    /// 13-14); builds are made `every` frames ahead, from the mesh at their own time, so the
    /// blend adds no lag. Needs the boundary's mesh to be a `Mesh` node (a function of time).
    #[serde(default)]
    pub interpolate: bool,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

fn default_band() -> f32 {
    3.0
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
pub enum Measure {
    Never,
    /// The first frame run.
    #[default]
    First,
    /// Every k-th frame run, starting with the first.
    Every(u32),
}

impl Node for FieldNode {
    fn kind(&self) -> &'static str {
        "DistanceField"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![Port::new("boundary", &self.boundary, PortType::Boundary)]
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::DistanceField)
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::Inputs
    }
    fn schedule(&self) -> Schedule {
        Schedule {
            split: self.split,
            interpolate: self.interpolate,
            ..Schedule::every(self.every, self.offset)
        }
    }
    fn backend(&self) -> Option<Backend> {
        self.backend
    }
    fn has_gpu_path(&self) -> bool {
        true
    }
    fn track(&self) -> Option<crate::node::Track> {
        Some(crate::node::Track::Field)
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        if !(self.band.is_finite() && self.band > 0.0) {
            return Err(ctx.fail(
                "band",
                format!(
                    "band must be a finite number of cells > 0, got {}",
                    self.band
                ),
            ));
        }
        if let Measure::Every(0) = self.measure {
            return Err(ctx.fail("measure", "Every(k) needs k >= 1"));
        }
        if self.interpolate {
            let mesh = ctx
                .node_as::<VoxelizeNode>(&self.boundary)
                .map(|v| v.mesh.as_str());
            if let Some(mesh) = mesh.filter(|m| ctx.node_as::<MeshParams>(m).is_none()) {
                let kind = (ctx.lookup)(mesh).map_or("missing", |n| n.kind());
                return Err(ctx.fail_with(
                    "interpolate",
                    format!(
                        "interpolate builds fields ahead of time from the mesh at a later \
                         time, but '{}' reads '{mesh}', a {kind} node computed frame by frame",
                        self.boundary
                    ),
                    Some("interpolate fields of Mesh nodes only, or use every without it".into()),
                ));
            }
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let voxelize = ctx
            .check
            .node_as::<VoxelizeNode>(&self.boundary)
            .ok_or_else(|| not_voxelize(&self.boundary))?
            .clone();
        let ahead = if self.interpolate {
            ahead(&voxelize, &self.boundary, ctx)?
        } else {
            None
        };
        let sc = self.schedule();
        // Split and interpolated builds run on the CPU (in parts, ahead of time).
        let gpu = if sc.split == 1 && !sc.interpolate {
            ctx.choose_gpu()?
        } else {
            None
        };
        Ok(Box::new(FieldStage {
            input: ctx.boundary_in(&self.boundary),
            gpu,
            measure: self.measure,
            mesh: ctx.mesh_in(&voxelize.mesh),
            measured: 0,
            builds: 0,
            sched: Box::new(FieldSchedule::new(sc, self.band, ahead)),
            held: None,
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

fn not_voxelize(node: &str) -> Error {
    Error::Invalid(format!("'{node}' is not a Voxelize node"))
}

/// The mesh and voxeliser an interpolated field evaluates at keyframe times.
fn ahead(v: &VoxelizeNode, boundary: &str, ctx: &mut BuildCtx<'_>) -> crate::Result<Option<Ahead>> {
    let mesh = ctx.check.node_as::<MeshParams>(&v.mesh).ok_or_else(|| {
        Error::Invalid(format!("interpolate needs '{}' to be a Mesh node", v.mesh))
    })?;
    let source = MeshSource::new(mesh, ctx.check.base_dir)?;
    let spec = v.grid_spec(boundary, ctx)?;
    let mut voxelizer = Voxelizer::new(spec)?;
    voxelizer.signed = v.signed;
    Ok(Some(Ahead {
        mesh: Box::new(source),
        variant: v.variant,
        voxelizer,
        fps: ctx.check.fps,
    }))
}

struct FieldStage {
    input: BoundaryIn,
    gpu: Option<&'static GpuContext>,
    measure: Measure,
    /// The Mesh node behind the boundary: the exact reference for error measurement.
    mesh: MeshIn,
    measured: u32,
    /// Builds finished so far (`Measure::Every` counts these).
    builds: u32,
    /// Builds, parts of builds and interpolation.
    sched: Box<FieldSchedule>,
    /// The last build's field while someone else still held it (a cloth keeps the previous
    /// frame's field for its blend): its buffers go to the build after next.
    held: Option<Arc<FieldValue>>,
}

impl Stage for FieldStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        let (mut step, published) = if self.sched.schedule.interpolate {
            let is_static = self
                .sched
                .ahead
                .as_ref()
                .is_some_and(|a| a.mesh.is_static());
            let s = self.sched.step_interpolated(
                ctx.frame as i64,
                ctx.first_frame as i64,
                is_static,
            )?;
            (step_of(s.worked, s.began), s.published)
        } else if let Some(gpu) = self.gpu {
            return self.run_gpu(ctx, gpu);
        } else {
            self.run_cpu(ctx)?
        };
        let new_build = matches!(published, Some(Published::One(_)));
        if let Some(p) = published {
            let data = match p {
                Published::One(f) => FieldData::Cpu(f),
                Published::Blend {
                    a,
                    b,
                    a_key,
                    every,
                    weight,
                } => FieldData::Blend {
                    a,
                    b,
                    a_key,
                    every,
                    weight,
                },
            };
            // A static interpolated field publishes the same build again: no change.
            let same = match (&data, &ctx.own) {
                (FieldData::Cpu(n), Some(Value::Field(o))) => {
                    matches!(&o.data, FieldData::Cpu(o) if Arc::ptr_eq(n, o))
                }
                _ => false,
            };
            if !same {
                step.published = Some(Value::Field(FieldValue::new(data)));
            }
        }
        if step.worked || new_build {
            step.untimed_ms = self.measure_finished(ctx, &step, new_build)?;
        }
        Ok(step)
    }

    fn save(&self, _values: &Values) -> imprint_core::Result<Vec<u8>> {
        save_state(&(self.measured, self.builds, self.sched.state()))
    }

    fn load(&mut self, bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        let (measured, builds, state): (u32, u32, BuildState) = load_state(bytes)?;
        self.measured = measured;
        self.builds = builds;
        self.sched.set_state(state);
        Ok(())
    }

    fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }
}

fn step_of(worked: bool, consumed: bool) -> Step {
    Step {
        worked,
        consumed,
        ..Step::default()
    }
}

impl FieldStage {
    /// A whole build on the GPU on keyframes whose input changed.
    fn run_gpu(&mut self, ctx: &mut FrameCtx<'_>, gpu: &GpuContext) -> imprint_core::Result<Step> {
        if !(ctx.first || (ctx.key && ctx.changed)) {
            return Ok(Step::idle());
        }
        let gb = match ctx.values.boundary(&self.input)? {
            BoundaryValue::Gpu(g) => g.clone(),
            BoundaryValue::Cpu(c) => Arc::new(GpuBoundary::from_cpu(gpu, c)?),
        };
        let f = imprint_stages::sdf::gpu::build_field_gpu(gpu, &gb, self.sched.band)?;
        gpu.wait()?;
        let value = FieldValue::new(FieldData::Gpu(Arc::new(f)));
        let mut step = Step::computed(Value::Field(value.clone()));
        step.untimed_ms = self.measure_finished(ctx, &step, true)?;
        Ok(step)
    }

    /// Builds on the CPU, whole or in parts.
    fn run_cpu(
        &mut self,
        ctx: &mut FrameCtx<'_>,
    ) -> imprint_core::Result<(Step, Option<Published>)> {
        let sc = self.sched.schedule;
        let builds = ctx.first || (ctx.key && ctx.changed);
        // Last build's field, if nobody holds it any more, lends its buffers; else the one
        // before it, which a cloth has let go of by now (a fresh field's buffers cost page
        // faults on every frame).
        if builds
            && sc.split == 1
            && let Some(Value::Field(own)) = ctx.own.take()
        {
            let older = self.held.take();
            match FieldValue::try_take(own) {
                Ok(f) => self.sched.builder.recycle(f),
                Err(shared) => {
                    self.held = Some(shared.clone());
                    ctx.own = Some(Value::Field(shared));
                }
            }
            if let Some(Ok(f)) = older.map(FieldValue::try_take) {
                self.sched.builder.recycle(f);
            }
        }
        let (values, gpu) = (ctx.values, ctx.gpu);
        let input = &self.input;
        let s = self
            .sched
            .step(ctx.frame as i64, ctx.first, ctx.changed, || {
                values.boundary(input)?.cpu(gpu)
            })?;
        Ok((step_of(s.worked, s.began), s.published))
    }
}

/// A build finished this frame: on the CPU, or a GPU value read back only to be measured.
enum Finished {
    Cpu(Arc<DistanceField>),
    Gpu(Arc<FieldValue>),
}

impl FieldStage {
    /// Counts the builds finished this frame and measures them when due, with the mesh each
    /// was made from; returns the time measuring took, ms.
    fn measure_finished(
        &mut self,
        ctx: &mut FrameCtx<'_>,
        step: &Step,
        new_build: bool,
    ) -> imprint_core::Result<f64> {
        let sc = self.sched.schedule;
        if sc.split > 1 && !sc.interpolate {
            ctx.metric(
                "error_cells",
                "not measured: a split build's mesh is gone when it finishes",
            );
        }
        // A build split over frames read the mesh of its first frame, which is gone.
        let finished: Vec<(Finished, Arc<Mesh>)> = if sc.interpolate {
            let f = &self.sched.finished;
            f.iter()
                .map(|(f, m)| (Finished::Cpu(f.clone()), m.clone()))
                .collect()
        } else if let (true, 1, Some(Value::Field(v))) = (new_build, sc.split, &step.published) {
            let mesh = ctx.values.mesh(&self.mesh)?.clone();
            let f = match &v.data {
                FieldData::Cpu(f) => Finished::Cpu(f.clone()),
                _ => Finished::Gpu(v.clone()),
            };
            vec![(f, mesh)]
        } else {
            Vec::new()
        };
        let mut ms = 0.0;
        for (field, mesh) in finished {
            self.builds += 1;
            let due = match self.measure {
                Measure::Never => false,
                Measure::First => self.measured == 0,
                Measure::Every(k) => (self.builds - 1).is_multiple_of(k),
            };
            let field = match field {
                Finished::Cpu(f) => f,
                // A GPU field comes back only to be measured.
                Finished::Gpu(v) if due => v.cpu(ctx.gpu)?,
                Finished::Gpu(_) => continue,
            };
            ctx.metric("band_cells", field.band_cells());
            ctx.metric("boundary_points", field.points.len());
            if due {
                let t = Instant::now();
                self.measure_one(ctx, &field, &mesh)?;
                ms += t.elapsed().as_secs_f64() * 1e3;
            }
        }
        ctx.report.measure_ms += ms;
        Ok(ms)
    }

    /// The field's error against the exact distance to `mesh`, into the report.
    fn measure_one(
        &mut self,
        ctx: &mut FrameCtx<'_>,
        field: &DistanceField,
        mesh: &Mesh,
    ) -> imprint_core::Result<()> {
        let err = imprint_stages::metrics::field_error(field, mesh);
        self.measured += 1;
        let worst = ctx
            .report
            .metrics
            .get("error_max_cells")
            .and_then(|v| v.as_f64())
            .unwrap_or(0.0);
        ctx.metric("error_frame", ctx.frame);
        ctx.metric(
            "error_cells",
            serde_json::to_value(err).expect("plain data"),
        );
        ctx.metric("error_max_cells", worst.max(err.max as f64));
        ctx.metric("frames_measured", self.measured);
        if !err.max.is_finite() {
            return Err(Error::Numerical {
                node: ctx.name.to_string(),
                frame: ctx.frame,
                message: "the field's error against the exact distance is not finite".into(),
                hint: "check the mesh for huge coordinates; lower the resolution".into(),
            });
        }
        Ok(())
    }
}
