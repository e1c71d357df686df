//! The executor: an object that runs a plan one frame at a time. It builds each node's stage
//! once, then per frame runs the nodes wave by wave (a wave: nodes whose inputs all come from
//! earlier waves, so no path joins two of them), the nodes of a wave at once on the rayon
//! pool. A node reads its inputs' current values and publishes a new value or nothing; a
//! consumer's inputs changed when a producer published since it last took them in. The
//! results never depend on the wave's order or the thread count: each node reads only what
//! earlier waves published, and the executor applies a wave's results in plan order.

mod checkpoint;
mod options;
mod reload;
mod wave;

pub use checkpoint::{CHECKPOINT_FILE, Checkpoint, checkpoint_path};
pub use options::{Observed, Observer, RunOptions};

use crate::node::{BuildCtx, CheckCtx, Stage};
use crate::plan::Plan;
use crate::report::{NodeReport, Report};
use crate::schedule::Schedule;
use crate::value::{Value, Values};
use imprint_core::{Aabb, Error};
use imprint_gpu::GpuContext;
use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::path::PathBuf;
use std::time::Instant;

/// A running node: its stage, what it last took in, its report.
pub(crate) struct Slot {
    pub name: String,
    /// Its input nodes, in port order.
    pub(crate) inputs: Vec<String>,
    pub(crate) schedule: Schedule,
    pub stage: Box<dyn Stage>,
    pub report: NodeReport,
    /// Its inputs' versions when it last took them in.
    pub seen: Option<Vec<u64>>,
}

/// What one frame did: its time, and each node's (for a live view).
#[derive(Clone, Debug)]
pub struct FrameSummary {
    pub frame: u32,
    pub ms: f64,
    /// (node, ms, computed or wrote) in plan order.
    pub nodes: Vec<(String, f64, bool)>,
}

/// Runs a plan frame by frame; see the module doc.
pub struct Executor {
    pub(crate) plan: Plan,
    pub(crate) opts: RunOptions,
    pub(crate) frames: Range<u32>,
    /// The next frame [`Executor::step`] runs.
    pub(crate) next: u32,
    pub(crate) gpu: Option<&'static GpuContext>,
    pub(crate) slots: Vec<Slot>,
    /// Indices into `slots`, wave by wave.
    pub(crate) waves: Vec<Vec<usize>>,
    pub(crate) values: Values,
    /// Each node's output version: it goes up with every value the node publishes.
    pub(crate) versions: BTreeMap<String, u64>,
    /// The boxes Mesh nodes sweep over the run (fitted grids use them).
    pub(crate) swept: BTreeMap<String, Aabb>,
    /// The report's run-wide part (its nodes are the slots').
    pub(crate) report: Report,
    pub(crate) started: Instant,
    /// Checkpoints kept in memory for `seek`, by next frame, and how often.
    kept: BTreeMap<u32, Vec<u8>>,
    keep_every: u32,
    /// Run a wave's nodes at once (the default), or one after the other in plan order.
    pub(crate) concurrent: bool,
    /// The files each writer wrote in this run (for the run's manifest).
    pub(crate) written: BTreeMap<String, BTreeSet<PathBuf>>,
}

impl Executor {
    /// Builds every running node's stage (loading meshes and rigs, choosing backends).
    pub fn new(plan: &Plan, opts: RunOptions) -> crate::Result<Self> {
        let frames = opts.frames.clone().unwrap_or(0..plan.file.frames);
        if frames.is_empty() || frames.end > plan.file.frames {
            return Err(Error::Invalid(format!(
                "--frames {}..{} is outside the pipeline's 0..{}",
                frames.start, frames.end, plan.file.frames
            ))
            .into());
        }
        let mut ex = Executor {
            plan: plan.clone(),
            next: frames.start,
            frames,
            opts,
            gpu: None,
            slots: Vec::new(),
            waves: Vec::new(),
            values: Values::default(),
            versions: BTreeMap::new(),
            swept: BTreeMap::new(),
            report: Report {
                schema_version: crate::report::REPORT_SCHEMA_VERSION,
                imprint_version: crate::report::program_version(),
                overrides: plan.overrides.clone(),
                pipeline: plan.source.name.clone(),
                fps: plan.file.fps,
                threads: rayon::current_num_threads(),
                pruned: plan.pruned.clone(),
                warnings: plan.warnings.clone(),
                ..Default::default()
            },
            started: Instant::now(),
            kept: BTreeMap::new(),
            keep_every: 0,
            concurrent: true,
            written: BTreeMap::new(),
        };
        for name in &plan.order {
            let slot = ex.build_slot(name)?;
            ex.slots.push(slot);
        }
        ex.waves = wave::waves(&ex.slots);
        ex.report.adapter = ex.gpu.map(|g| g.adapter_name());
        tracing::info!(
            "{} node(s) in {} wave(s), frames {}..{}, {} thread(s)",
            ex.slots.len(),
            ex.waves.len(),
            ex.frames.start,
            ex.frames.end,
            ex.report.threads
        );
        Ok(ex)
    }

    /// Node `name`'s stage, built fresh.
    pub(crate) fn build_slot(&mut self, name: &str) -> crate::Result<Slot> {
        let plan = &self.plan;
        let spec = plan.file.nodes[name].node();
        let want = self
            .opts
            .backend
            .or(spec.backend())
            .unwrap_or(plan.file.backend);
        let lookup = |n: &str| plan.file.nodes.get(n).map(|s| s.node());
        let mut ctx = BuildCtx {
            check: CheckCtx {
                source: &plan.source,
                name,
                base_dir: &plan.base_dir,
                fps: plan.file.fps,
                frames: plan.file.frames,
                lookup: &lookup,
            },
            out: &self.opts.out,
            want,
            gpu: &mut self.gpu,
            swept: &mut self.swept,
            warnings: &mut self.report.warnings,
        };
        let stage = spec.build(&mut ctx)?;
        let backend = if stage.on_gpu() { "gpu" } else { "cpu" };
        tracing::info!("node '{name}': {} on the {backend}", spec.kind());
        Ok(Slot {
            name: name.to_string(),
            inputs: spec.inputs().iter().map(|p| p.node.to_string()).collect(),
            schedule: spec.schedule(),
            report: NodeReport {
                kind: spec.kind().to_string(),
                backend: backend.to_string(),
                ..Default::default()
            },
            stage,
            seen: None,
        })
    }

    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The frames this executor runs.
    pub fn frames(&self) -> Range<u32> {
        self.frames.clone()
    }

    /// The next frame [`Executor::step`] runs.
    pub fn next_frame(&self) -> u32 {
        self.next
    }

    /// Whether every frame has run.
    pub fn done(&self) -> bool {
        self.next >= self.frames.end
    }

    /// Node `name`'s current value (what its consumers see), if it has one.
    pub fn value(&self, name: &str) -> Option<Value> {
        self.values.get(name)
    }

    /// Runs each wave's nodes at once (`true`, the default) or one after the other in plan
    /// order; the results are the same.
    pub fn set_concurrent(&mut self, concurrent: bool) {
        self.concurrent = concurrent;
    }

    /// The running nodes, wave by wave: no path joins two nodes of a wave.
    pub fn waves(&self) -> Vec<Vec<String>> {
        let name = |i: &usize| self.slots[*i].name.clone();
        self.waves
            .iter()
            .map(|w| w.iter().map(name).collect())
            .collect()
    }

    /// The GPU, when a node runs there (to read GPU values back).
    pub fn gpu(&self) -> Option<&'static GpuContext> {
        self.gpu
    }

    /// The report so far.
    pub fn report(&self) -> Report {
        let mut r = self.report.clone();
        r.nodes = self
            .slots
            .iter()
            .map(|s| (s.name.clone(), s.report.clone()))
            .collect();
        r.wall_ms = self.started.elapsed().as_secs_f64() * 1e3;
        r
    }

    /// Runs the next frame.
    pub fn step(&mut self) -> crate::Result<FrameSummary> {
        self.step_observed(None)
    }

    /// [`Executor::step`], showing every node's value to `observer` after it ran.
    pub fn step_observed(
        &mut self,
        mut observer: Option<&mut dyn Observer>,
    ) -> crate::Result<FrameSummary> {
        if self.done() {
            return Err(Error::Invalid(format!(
                "the run is over: frames {}..{} have run",
                self.frames.start, self.frames.end
            ))
            .into());
        }
        let frame = self.next;
        let start = Instant::now();
        let mut observed_ms = 0.0;
        let mut summary = FrameSummary {
            frame,
            ms: 0.0,
            nodes: Vec::new(),
        };
        for w in 0..self.waves.len() {
            let ran = self.run_wave(w, frame)?;
            for (i, ms, worked) in ran {
                summary.nodes.push((self.slots[i].name.clone(), ms, worked));
                if let Some(obs) = observer.as_deref_mut() {
                    observed_ms += self.observe(obs, i, frame)?;
                }
            }
        }
        summary
            .nodes
            .sort_by_key(|(n, ..)| self.plan.order.iter().position(|o| o == n));
        self.next += 1;
        summary.ms = start.elapsed().as_secs_f64() * 1e3 - observed_ms;
        self.report.frames.push(frame);
        self.report.frame_ms.push(summary.ms);
        tracing::debug!("frame {frame}: {:.2} ms", summary.ms);
        for (name, ms, worked) in &summary.nodes {
            tracing::trace!(
                "frame {frame}: node '{name}' {ms:.3} ms{}",
                if *worked { "" } else { " (idle)" }
            );
        }
        self.keep_if_due()?;
        Ok(summary)
    }

    /// Shows slot `i`'s value to `obs`; returns the time it took (not the frame's), ms.
    fn observe(&self, obs: &mut dyn Observer, i: usize, frame: u32) -> crate::Result<f64> {
        let name = &self.slots[i].name;
        if !obs.wants(name) {
            return Ok(0.0);
        }
        let t = Instant::now();
        match self.values.get(name) {
            Some(Value::Mesh(m)) => obs.observe(name, frame, Observed::Mesh(&m)),
            Some(Value::Heights(h)) => obs.observe(name, frame, Observed::Heights(&h)),
            Some(Value::Field(f)) => obs.observe(name, frame, Observed::Field(&*f.cpu(self.gpu)?)),
            Some(Value::Boundary(_)) | None => {}
        }
        Ok(t.elapsed().as_secs_f64() * 1e3)
    }

    /// The files each writer wrote in this run so far, by node.
    pub fn written(&self) -> &BTreeMap<String, BTreeSet<PathBuf>> {
        &self.written
    }

    /// Whole-run outputs (contact sheets, GIFs) after the last frame; the final report.
    pub fn finish(&mut self) -> crate::Result<Report> {
        for slot in &mut self.slots {
            let files = slot.stage.finish(&mut slot.report)?;
            self.report.files_written += files.len();
            self.written
                .entry(slot.name.clone())
                .or_default()
                .extend(files);
        }
        Ok(self.report())
    }
}
