//! What a node kind is: a [`Node`] (the description the file gives: ports, checks, schedule)
//! and a [`Stage`] (the object that runs it, frame by frame, and keeps its state). Each node
//! kind is one module in [`crate::nodes`]; the plan and the executor know kinds only through
//! these two traits.

use crate::diagnostics::Source;
use crate::report::NodeReport;
use crate::schedule::Schedule;
use crate::value::{BoundaryIn, FieldIn, HeightsIn, MeshIn, Value, Values};
use imprint_core::{Aabb, Error};
use imprint_gpu::GpuContext;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Where a node runs. `Auto` takes a hardware GPU when there is one, the CPU otherwise (a
/// software Vulkan adapter is never picked by `Auto`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
pub enum Backend {
    #[default]
    Auto,
    Cpu,
    Gpu,
}

/// The resource types that flow along edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PortType {
    Mesh,
    Boundary,
    DistanceField,
    HeightField,
}

impl std::fmt::Display for PortType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            PortType::Mesh => "Mesh",
            PortType::Boundary => "Boundary",
            PortType::DistanceField => "DistanceField",
            PortType::HeightField => "HeightField",
        })
    }
}

/// One input port: its name in the file, the node it names, the type it expects.
#[derive(Clone, Copy, Debug)]
pub struct Port<'a> {
    pub port: &'static str,
    pub node: &'a str,
    pub ty: PortType,
}

impl<'a> Port<'a> {
    pub fn new(port: &'static str, node: &'a str, ty: PortType) -> Self {
        Port { port, node, ty }
    }
}

/// When a node computes (the executor's rule, and `imprint check`'s table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Trigger {
    /// A function of time alone (a Mesh): on the first frame, then every frame if it moves.
    Time { moves: bool },
    /// On its keyframes when an input has a new value (and on its first frame).
    Inputs,
    /// Every frame: it carries state from frame to frame (cloth, ground, snow, skin).
    EveryFrame,
    /// A writer: on its keyframes.
    Writes,
}

/// What a sweep compares between runs for a node's output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Track {
    /// Distances at probe points.
    Field,
    /// Vertex positions of a simulated or deformed mesh.
    Vertices,
    /// Heights of a height field.
    Heights,
}

/// A node kind as the file declares it.
pub trait Node: Any {
    fn kind(&self) -> &'static str;
    /// Typed input ports, in the file's order.
    fn inputs(&self) -> Vec<Port<'_>>;
    /// The output's type, or `None` for a writer.
    fn output(&self) -> Option<PortType>;
    /// `enabled` as the file sets it.
    fn enabled(&self) -> bool;
    fn trigger(&self) -> Trigger;
    /// `every`, `offset`, `split`, `interpolate` as the file sets them.
    fn schedule(&self) -> Schedule {
        Schedule::default()
    }
    /// The per-node backend override, for nodes with two paths.
    fn backend(&self) -> Option<Backend> {
        None
    }
    /// Whether the node can run on the GPU (the others always run on the CPU).
    fn has_gpu_path(&self) -> bool {
        false
    }
    /// What a sweep compares of this node's output, if anything.
    fn track(&self) -> Option<Track> {
        None
    }
    /// Whether it writes a file from the whole run at its end (an animated GLB, a contact
    /// sheet, a GIF): that file depends on every frame, so a run cut into frame ranges that
    /// run apart cannot write it (`imprint farm` chains such ranges instead).
    fn writes_whole_run(&self) -> bool {
        false
    }
    /// The box the node's mesh sweeps over the run, when it is known before running.
    fn swept_bounds(&self, _ctx: &CheckCtx<'_>) -> imprint_core::Result<Option<Aabb>> {
        Ok(None)
    }
    /// Whether [`Node::swept_bounds`] gives the box before running (it then returns `Some`):
    /// a `Fit` grid over this node's output needs it, and `check` refuses one where it is not.
    fn swept_bounds_known(&self) -> bool {
        false
    }
    /// Value ranges and assets, checked before anything runs.
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()>;
    /// What the user should know before running (after `check` passed): e.g. a substep
    /// beyond the estimated stable one.
    fn warnings(&self, _ctx: &CheckCtx<'_>) -> Vec<String> {
        Vec::new()
    }
    /// The object that runs the node.
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>>;
    fn as_any(&self) -> &dyn Any;
}

/// A node at run time: its state between frames.
pub trait Stage: Send {
    /// One frame. `ctx.first`: the node has no value yet; `ctx.key`: a keyframe of its
    /// schedule; `ctx.changed`: an input has a new value since it last took its inputs in.
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step>;
    /// Whether its work runs on the GPU.
    fn on_gpu(&self) -> bool {
        false
    }
    /// Whole-run output (a contact sheet, a GIF), after the last frame; returns the files
    /// written (for the run's manifest).
    fn finish(&mut self, _report: &mut NodeReport) -> imprint_core::Result<Vec<PathBuf>> {
        Ok(Vec::new())
    }
    /// The state it carries between frames, for a checkpoint (empty: none). `values`: every
    /// node's current value (a stage may note which of its own references are the same).
    fn save(&self, _values: &Values) -> imprint_core::Result<Vec<u8>> {
        Ok(Vec::new())
    }
    /// Takes back what [`Stage::save`] gave; `values` are already restored.
    fn load(&mut self, _bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        Ok(())
    }
}

/// What a node did on a frame.
#[derive(Default)]
pub struct Step {
    /// A new value for consumers (their inputs changed); `None`: they keep the last one.
    pub published: Option<Value>,
    /// It computed or wrote something (its time is recorded).
    pub worked: bool,
    /// It took its inputs' current values in (so they count as seen).
    pub consumed: bool,
    /// Files it wrote (the run's manifest lists them, so a rerun can remove stale ones).
    pub files: Vec<PathBuf>,
    /// Time inside the run that is not the stage's (error measurement), ms.
    pub untimed_ms: f64,
}

impl Step {
    /// Nothing done; consumers keep the last value.
    pub fn idle() -> Self {
        Step::default()
    }

    /// Computed from the current inputs and published `value`.
    pub fn computed(value: Value) -> Self {
        Step {
            published: Some(value),
            worked: true,
            consumed: true,
            ..Default::default()
        }
    }

    /// A writer wrote `files`.
    pub fn wrote(files: Vec<PathBuf>) -> Self {
        Step {
            worked: true,
            files,
            ..Default::default()
        }
    }
}

/// What a node sees of the pipeline while its values are checked.
pub struct CheckCtx<'a> {
    pub source: &'a Source,
    /// The node's name.
    pub name: &'a str,
    pub base_dir: &'a Path,
    pub fps: f32,
    pub frames: u32,
    /// Any node of the file by name.
    pub lookup: &'a dyn Fn(&str) -> Option<&'a dyn Node>,
}

impl CheckCtx<'_> {
    /// An invalid value of field `field`, located in the file.
    pub fn fail(&self, field: &str, msg: impl std::fmt::Display) -> crate::Error {
        self.fail_with(field, msg, None)
    }

    /// [`CheckCtx::fail`] with a hint.
    pub fn fail_with(
        &self,
        field: &str,
        msg: impl std::fmt::Display,
        help: Option<String>,
    ) -> crate::Error {
        self.source
            .error(
                self.source.field_span(self.name, field),
                format!("node '{}': {msg}", self.name),
                "invalid value",
                help,
            )
            .into()
    }

    /// A file the node reads, relative to the pipeline's folder, that must exist.
    pub fn existing_file(&self, field: &str, what: &str, path: &str) -> crate::Result<PathBuf> {
        let full = self.base_dir.join(path);
        if full.is_file() {
            return Ok(full);
        }
        Err(self
            .source
            .error(
                self.source.field_span(self.name, field),
                format!("node '{}': {what} not found: {}", self.name, full.display()),
                "missing file",
                Some("paths are relative to the pipeline file's folder".into()),
            )
            .into())
    }

    /// A `Fit` grid (field `field`) over the output of node `mesh`: refused before running
    /// unless that node knows the box it sweeps over the run up front (a Mesh node), as the
    /// run could not fit the grid. `explicit` is the kind's `Explicit` grid as the file
    /// writes it, and `origin` what its origin is, for the fix.
    pub fn fit_needs_swept_box(
        &self,
        field: &str,
        mesh: &str,
        explicit: &str,
        origin: &str,
    ) -> crate::Result<()> {
        // An input that names no node is the plan's error, reported before this.
        let Some(node) = (self.lookup)(mesh) else {
            return Ok(());
        };
        if node.swept_bounds_known() {
            return Ok(());
        }
        Err(self.fail_with(
            field,
            format!(
                "Fit needs the box '{mesh}' sweeps over the run before running, and '{mesh}' \
                 is a {} node, computed frame by frame",
                node.kind()
            ),
            Some(format!(
                "give the grid explicitly, covering the box '{mesh}' stays in: \
                 grid: {explicit} ({origin}); Fit works on the output of a Mesh node"
            )),
        ))
    }

    /// Node `name` of the file, downcast to its kind's type.
    pub fn node_as<T: Node>(&self, name: &str) -> Option<&T> {
        (self.lookup)(name).and_then(|n| n.as_any().downcast_ref::<T>())
    }
}

/// What a node sees while its stage is built.
pub struct BuildCtx<'a> {
    pub check: CheckCtx<'a>,
    /// The run's output folder.
    pub out: &'a Path,
    /// The backend asked for this node (command line, node, file).
    pub want: Backend,
    /// The GPU, once a node chose it.
    pub gpu: &'a mut Option<&'static GpuContext>,
    /// Swept boxes found so far, by node.
    pub swept: &'a mut BTreeMap<String, Aabb>,
    /// What the user should know (printed by the binary, kept in the report).
    pub warnings: &'a mut Vec<String>,
}

impl BuildCtx<'_> {
    pub fn name(&self) -> &str {
        self.check.name
    }

    /// Whether this node runs on the GPU, choosing the device if so.
    pub fn choose_gpu(&mut self) -> imprint_core::Result<Option<&'static GpuContext>> {
        let node = self.check.name;
        match self.want {
            Backend::Cpu => Ok(None),
            Backend::Gpu => {
                let ctx = GpuContext::shared().map_err(|e| {
                    Error::Gpu(format!("node '{node}' asks for backend Gpu, but {e}"))
                })?;
                *self.gpu = Some(ctx);
                Ok(Some(ctx))
            }
            Backend::Auto => match GpuContext::shared() {
                Ok(ctx) if !ctx.is_software() => {
                    *self.gpu = Some(ctx);
                    Ok(Some(ctx))
                }
                _ => Ok(None),
            },
        }
    }

    /// The box Mesh node `mesh` sweeps over the run, if it is known before running.
    pub fn swept_bounds(&mut self, mesh: &str) -> imprint_core::Result<Option<Aabb>> {
        if let Some(b) = self.swept.get(mesh) {
            return Ok(Some(*b));
        }
        let Some(node) = (self.check.lookup)(mesh) else {
            return Ok(None);
        };
        let found = node.swept_bounds(&self.check)?;
        if let Some(b) = found {
            self.swept.insert(mesh.to_string(), b);
        }
        Ok(found)
    }

    pub fn warn(&mut self, message: String) {
        self.warnings
            .push(format!("node '{}': {message}", self.check.name));
    }

    /// A typed handle on the Mesh node `name` (the plan checked the type).
    pub fn mesh_in(&self, name: &str) -> MeshIn {
        MeshIn::new(name)
    }
    pub fn boundary_in(&self, name: &str) -> BoundaryIn {
        BoundaryIn::new(name)
    }
    pub fn field_in(&self, name: &str) -> FieldIn {
        FieldIn::new(name)
    }
    pub fn heights_in(&self, name: &str) -> HeightsIn {
        HeightsIn::new(name)
    }
}

/// What a node sees on one frame.
pub struct FrameCtx<'a> {
    pub name: &'a str,
    pub frame: u32,
    /// `frame / fps`, s.
    pub time: f32,
    pub fps: f32,
    /// The run's first frame.
    pub first_frame: u32,
    /// The node has no value yet.
    pub first: bool,
    /// The node's current value, lent for the frame (a node may reuse its buffers when it
    /// publishes a new one; what it leaves here is kept if it publishes nothing).
    pub own: Option<Value>,
    pub key: bool,
    pub changed: bool,
    pub values: &'a Values,
    pub gpu: Option<&'static GpuContext>,
    /// The node's entry in the report (its metrics).
    pub report: &'a mut NodeReport,
}

impl FrameCtx<'_> {
    /// A stage's error named after this node and frame, its kind (and exit code) kept.
    pub fn at_node(&self, e: Error) -> Error {
        let (node, frame) = (self.name, self.frame);
        match e {
            Error::Numerical { message, hint, .. } => Error::Numerical {
                node: node.to_string(),
                frame,
                message,
                hint,
            },
            Error::Invalid(m) => Error::Invalid(format!("node '{node}', frame {frame}: {m}")),
            Error::Run(m) => Error::Run(format!("node '{node}', frame {frame}: {m}")),
            other => other,
        }
    }

    /// A failed self-check of this node on this frame: `message` says what is wrong, `hint`
    /// what to change.
    pub fn numerical(&self, message: impl Into<String>, hint: impl Into<String>) -> Error {
        Error::Numerical {
            node: self.name.to_string(),
            frame: self.frame,
            message: message.into(),
            hint: hint.into(),
        }
    }

    /// Sets one of the node's metrics in the report.
    pub fn metric(&mut self, key: &str, value: impl Into<serde_json::Value>) {
        self.report.metrics.insert(key.into(), value.into());
    }

    /// Appends one frame's metrics to the node's `per_frame` list in the report.
    pub fn push_per_frame(&mut self, frame_metrics: serde_json::Value) {
        let per_frame = self
            .report
            .metrics
            .entry("per_frame".into())
            .or_insert_with(|| serde_json::Value::Array(Vec::new()));
        if let serde_json::Value::Array(a) = per_frame {
            a.push(frame_metrics);
        }
    }

    /// Adds `n` to the integer metric `key`.
    pub fn count(&mut self, key: &str, n: u64) {
        let now = self
            .report
            .metrics
            .get(key)
            .and_then(|v| v.as_u64())
            .unwrap_or(0);
        self.metric(key, now + n);
    }

    /// A run warning of kind `key`, given once per node and run: the first time, `message()`
    /// goes to the node's report (`warnings`, as `KEY: MESSAGE (first at frame F)`) and from
    /// there to the run's [`crate::report::Report::warnings`]; later calls with the same key do
    /// nothing (a checkpoint keeps what was given, so a resumed run does not repeat it).
    /// Returns whether it warned. For what a self-check counts rather than stops on: count
    /// it every frame ([`FrameCtx::count`]) and warn once.
    pub fn warn_once(&mut self, key: &str, message: impl FnOnce() -> String) -> bool {
        let prefix = format!("{key}: ");
        if self.report.warnings.iter().any(|w| w.starts_with(&prefix)) {
            return false;
        }
        let frame = self.frame;
        self.report
            .warnings
            .push(format!("{prefix}{} (first at frame {frame})", message()));
        true
    }
}

/// Serialises a stage's state for a checkpoint (the one binary format of checkpoints).
pub fn save_state<T: Serialize>(state: &T) -> imprint_core::Result<Vec<u8>> {
    postcard::to_allocvec(state).map_err(|e| Error::Run(format!("checkpoint: {e}")))
}

/// Reads what [`save_state`] wrote.
pub fn load_state<T: for<'de> Deserialize<'de>>(bytes: &[u8]) -> imprint_core::Result<T> {
    postcard::from_bytes(bytes).map_err(|e| {
        Error::Invalid(format!(
            "checkpoint: a node's state does not read back ({e}); was it written by another \
             version of imprint?"
        ))
    })
}
