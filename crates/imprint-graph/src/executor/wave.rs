//! One wave of a frame: its nodes run at once on the rayon pool, each with its inputs'
//! versions, whether they changed since it last took them in, and its own value lent; their
//! results are applied in plan order, so the outcome does not depend on the thread count.

use super::{Executor, Slot};
use crate::node::{FrameCtx, Step};
use crate::report::FrameTransfers;
use crate::value::{Value, Values};
use imprint_gpu::GpuContext;
use imprint_gpu::transfer;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::time::Instant;

impl Executor {
    /// Runs wave `w` of `frame`: its nodes at once, their results applied in plan order.
    /// Returns (slot, ms, worked) per node.
    pub(super) fn run_wave(
        &mut self,
        w: usize,
        frame: u32,
    ) -> crate::Result<Vec<(usize, f64, bool)>> {
        let wave = &self.waves[w];
        let mut jobs: Vec<Job> = Vec::with_capacity(wave.len());
        for &i in wave {
            let slot = &self.slots[i];
            let inputs: Vec<u64> = slot
                .inputs
                .iter()
                .map(|n| self.versions.get(n).copied().unwrap_or(0))
                .collect();
            let changed = slot.seen.as_ref() != Some(&inputs);
            let own = self.values.take(&slot.name);
            jobs.push(Job {
                slot: i,
                inputs,
                changed,
                own,
                warned: slot.report.warnings.len(),
                outcome: None,
            });
        }
        let ctx = Shared {
            values: &self.values,
            gpu: self.gpu,
            frame,
            fps: self.plan.file.fps,
            first_frame: self.frames.start,
        };
        let mut slots: Vec<&mut Slot> = self
            .slots
            .iter_mut()
            .enumerate()
            .filter(|(i, _)| wave.contains(i))
            .map(|(_, s)| s)
            .collect();
        if self.concurrent {
            slots
                .par_iter_mut()
                .zip(jobs.par_iter_mut())
                .for_each(|(slot, job)| job.run(slot, &ctx));
        } else {
            for (slot, job) in slots.iter_mut().zip(&mut jobs) {
                job.run(slot, &ctx);
            }
        }
        let mut ran = Vec::with_capacity(jobs.len());
        let mut failed = None;
        for job in jobs {
            let (i, worked, ms) = (job.slot, job.worked(), job.ms());
            if let Err(e) = self.apply(job, frame) {
                failed.get_or_insert(e);
            }
            ran.push((i, ms, worked));
        }
        match failed {
            Some(e) => Err(e),
            None => Ok(ran),
        }
    }

    /// A node's result: its value, its version, what it took in, its time.
    fn apply(&mut self, mut job: Job, frame: u32) -> crate::Result<()> {
        let (result, ms, moved) = job.outcome.take().expect("every job ran");
        let slot = &mut self.slots[job.slot];
        // What the node warned about this frame (each kind once per run) goes to the run's
        // warnings, also when the frame failed.
        for w in &slot.report.warnings[job.warned.min(slot.report.warnings.len())..] {
            self.report
                .warnings
                .push(format!("node '{}': {w}", slot.name));
        }
        let before = job.own.as_ref();
        let step = match result.and_then(|step| finite(step, before, &slot.name, frame)) {
            Ok(step) => step,
            Err(e) => {
                // The last good value stays, for a viewer that goes on after the error.
                if let Some(own) = job.own.take() {
                    self.values.set(&slot.name, own);
                }
                return Err(e.into());
            }
        };
        match (step.published, job.own.take()) {
            (Some(v), _) => {
                self.values.set(&slot.name, v);
                *self.versions.entry(slot.name.clone()).or_default() += 1;
            }
            (None, Some(own)) => self.values.set(&slot.name, own),
            (None, None) => {}
        }
        if step.consumed {
            slot.seen = Some(job.inputs);
        }
        if step.worked {
            slot.report.record(frame, ms - step.untimed_ms);
        }
        self.report.files_written += step.files.len();
        if !step.files.is_empty() {
            let mine = self.written.entry(slot.name.clone()).or_default();
            mine.extend(step.files);
        }
        if moved.uploaded_bytes + moved.read_back_bytes > 0 {
            slot.report.transfers.push(FrameTransfers {
                frame,
                uploaded_bytes: moved.uploaded_bytes,
                read_back_bytes: moved.read_back_bytes,
                field_read_backs: moved.field_read_backs,
            });
        }
        Ok(())
    }
}

/// Never silent: a published value that is not finite stops the run, named. What the node's
/// last value (`before`) held was checked when it was published.
fn finite(
    step: Step,
    before: Option<&Value>,
    node: &str,
    frame: u32,
) -> imprint_core::Result<Step> {
    let published = step.published.as_ref();
    match published.and_then(|v| v.first_non_finite_since(before)) {
        None => Ok(step),
        Some(what) => Err(imprint_core::Error::Numerical {
            node: node.to_string(),
            frame,
            message: format!("its output is not finite: {what}"),
            hint: "lower the time step (more substeps) or the stiffness, or check the inputs \
                   for huge coordinates"
                .into(),
        }),
    }
}

/// What every node of a wave shares.
struct Shared<'a> {
    values: &'a Values,
    gpu: Option<&'static GpuContext>,
    frame: u32,
    fps: f32,
    first_frame: u32,
}

/// One node's run within a wave.
struct Job {
    slot: usize,
    /// Its inputs' versions now.
    inputs: Vec<u64>,
    changed: bool,
    /// Its value, lent for the run.
    own: Option<Value>,
    /// How many run warnings its report held before the run (the new ones follow).
    warned: usize,
    /// The run's result, its time (ms) and the bytes it moved.
    outcome: Option<(imprint_core::Result<Step>, f64, transfer::Transfers)>,
}

impl Job {
    fn run(&mut self, slot: &mut Slot, s: &Shared<'_>) {
        let t0 = Instant::now();
        let before = transfer::snapshot();
        let mut ctx = FrameCtx {
            name: &slot.name,
            frame: s.frame,
            time: s.frame as f32 / s.fps,
            fps: s.fps,
            first_frame: s.first_frame,
            first: self.own.is_none(),
            own: self.own.take(),
            key: slot.schedule.is_key(s.frame as i64),
            changed: self.changed,
            values: s.values,
            gpu: s.gpu,
            report: &mut slot.report,
        };
        let result = slot.stage.run(&mut ctx);
        self.own = ctx.own.take();
        let moved = transfer::snapshot().since(&before);
        self.outcome = Some((result, t0.elapsed().as_secs_f64() * 1e3, moved));
    }

    fn worked(&self) -> bool {
        matches!(&self.outcome, Some((Ok(s), ..)) if s.worked)
    }

    fn ms(&self) -> f64 {
        self.outcome.as_ref().map_or(0.0, |o| o.1)
    }
}

/// The slots in waves: a node's wave is one more than its latest input's.
pub(super) fn waves(slots: &[Slot]) -> Vec<Vec<usize>> {
    let mut level: BTreeMap<&str, usize> = BTreeMap::new();
    let mut waves: Vec<Vec<usize>> = Vec::new();
    for (i, s) in slots.iter().enumerate() {
        let l = s
            .inputs
            .iter()
            .filter_map(|n| level.get(n.as_str()).map(|l| l + 1))
            .max()
            .unwrap_or(0);
        level.insert(&s.name, l);
        if waves.len() <= l {
            waves.resize(l + 1, Vec::new());
        }
        waves[l].push(i);
    }
    waves
}
