//! A whole run: an [`Executor`] stepped frame by frame into an output folder, with
//! checkpoints on request, resumption from them, and a `report.json` that is written whatever
//! happens (after the last frame, or with the frames done and the error when a frame fails or
//! the run is interrupted). Beside it, `manifest.json` lists what the run wrote; what the
//! folder's previous run wrote and this one did not is removed when this one completes
//! ([`crate::manifest`]).

use crate::executor::{Checkpoint, Executor, checkpoint_path};
pub use crate::executor::{Observed, Observer, RunOptions};
use crate::manifest::{Manifest, RUN_KEY};
use crate::plan::Plan;
use crate::report::Report;
use imprint_core::Error;
use std::path::Path;
use std::sync::atomic::Ordering;

/// Runs `plan`; `progress(done, total)` is called after every frame.
pub fn run(
    plan: &Plan,
    opts: &RunOptions,
    progress: &mut dyn FnMut(u32, u32),
) -> crate::Result<Report> {
    Run::start(plan, opts)?.finish(progress, None)
}

/// [`run`], showing every frame's resources to `observer`.
pub fn run_observed(
    plan: &Plan,
    opts: &RunOptions,
    progress: &mut dyn FnMut(u32, u32),
    observer: Option<&mut dyn Observer>,
) -> crate::Result<Report> {
    Run::start(plan, opts)?.finish(progress, observer)
}

/// A run into a folder, built (and restored from its checkpoint with `resume`) but not run
/// yet: what it warns about can be shown first.
pub struct Run {
    ex: Executor,
    opts: RunOptions,
    /// The folder's manifest before this run (empty when it had none).
    previous: Manifest,
    /// What the run's observer had gathered, when resumed from a checkpoint.
    observed: Option<Vec<u8>>,
}

impl Run {
    /// Builds every stage; with `opts.resume`, restores the folder's checkpoint. Nothing is
    /// written yet, so a refused resume leaves the folder as it was.
    pub fn start(plan: &Plan, opts: &RunOptions) -> crate::Result<Run> {
        let previous = Manifest::read(&opts.out)?.unwrap_or_default();
        let mut ex = Executor::new(plan, opts.clone())?;
        let mut observed = None;
        if opts.resume {
            let c = Checkpoint::read_dir(&opts.out)?;
            ex.restore(&c)?;
            ex.report.resumed_at = Some(c.next_frame());
            observed = Some(c.observer().to_vec());
        }
        Ok(Run {
            ex,
            opts: opts.clone(),
            previous,
            observed,
        })
    }

    /// What the plan and the stages' construction warn about.
    pub fn warnings(&self) -> &[String] {
        &self.ex.report.warnings
    }

    pub fn executor(&self) -> &Executor {
        &self.ex
    }

    /// Runs the remaining frames, then the whole-run writers; writes `report.json`. Resumed,
    /// `observer` first takes back what it had gathered before the checkpoint.
    pub fn finish(
        mut self,
        progress: &mut dyn FnMut(u32, u32),
        mut observer: Option<&mut dyn Observer>,
    ) -> crate::Result<Report> {
        if let (Some(o), Some(bytes)) = (observer.as_mut(), &self.observed) {
            o.load(bytes).map_err(|why| {
                Error::Invalid(format!(
                    "--resume: the checkpoint in {} cannot be continued by this command ({why}); \
                     run without --resume",
                    self.opts.out.display()
                ))
            })?;
        }
        let total = self.ex.frames().len() as u32;
        while !self.ex.done() {
            let stop = self.opts.stop.as_ref();
            if stop.is_some_and(|s| s.load(Ordering::SeqCst)) {
                let e = Error::Interrupted {
                    frame: self.ex.next_frame(),
                };
                return Err(self.stopped(e.into(), observed_state(&observer)));
            }
            let obs: Option<&mut dyn Observer> = match observer {
                Some(ref mut o) => Some(&mut **o),
                None => None,
            };
            if let Err(e) = self.ex.step_observed(obs) {
                return Err(self.stopped(e, observed_state(&observer)));
            }
            let ex = &self.ex;
            progress(ex.next_frame() - ex.frames().start, total);
            let every = self.opts.checkpoint_every;
            let since = ex.next_frame() - ex.frames().start;
            if every > 0 && since.is_multiple_of(every) && !ex.done() {
                self.save_checkpoint(observed_state(&observer))?;
            }
        }
        if self.opts.checkpoint_every > 0 {
            // Before the whole-run writers: a later run may go on from here.
            self.save_checkpoint(observed_state(&observer))?;
        }
        let mut report = self.ex.finish()?;
        report.complete = true;
        let mut manifest = self.manifest();
        report.stale_removed = manifest.remove_stale(&self.opts.out)?;
        manifest.write(&self.opts.out)?;
        write_report(&report, &self.opts.out)?;
        Ok(report)
    }

    /// What this run wrote so far (and, resumed, what the run it continues wrote), with what
    /// the folder's earlier runs wrote besides as stale.
    fn manifest(&self) -> Manifest {
        let out = &self.opts.out;
        let mut m = Manifest {
            pipeline: self.ex.plan.source.name.clone(),
            ..Default::default()
        };
        if self.opts.resume {
            m.files = self.previous.files.clone();
        }
        for (node, files) in self.ex.written() {
            m.add(out, node, files.iter().cloned());
        }
        if self.opts.checkpoint_every > 0 || self.opts.resume {
            m.add(out, RUN_KEY, [checkpoint_path(out)]);
        }
        m.inherit_stale(&self.previous);
        m
    }

    /// The checkpoint (with what the observer gathered), the manifest and the report so
    /// far, in `out` (a run killed later leaves all three).
    fn save_checkpoint(&self, observed: Vec<u8>) -> crate::Result<()> {
        let out = &self.opts.out;
        let c = self.ex.checkpoint()?.with_observer(observed);
        c.write(&checkpoint_path(out))?;
        self.manifest().write(out)?;
        write_report(&self.ex.report(), out)
    }

    /// A run that stopped early: its report says how far it got and why; with checkpoints,
    /// the state before the failed frame is kept too. Nothing is removed: the manifest lists
    /// the earlier run's files as stale, for the next complete run.
    fn stopped(&self, e: crate::Error, observed: Vec<u8>) -> crate::Error {
        let (ex, opts) = (&self.ex, &self.opts);
        let mut report = ex.report();
        report.error = Some(e.to_string());
        let _ = self.manifest().write(&opts.out);
        let _ = write_report(&report, &opts.out);
        let interrupted = matches!(&e, crate::Error::Core(Error::Interrupted { .. }));
        if opts.checkpoint_every > 0 && interrupted {
            let _ = ex.checkpoint().and_then(|c| {
                let c = c.with_observer(observed);
                Ok(c.write(&checkpoint_path(&opts.out))?)
            });
        }
        e
    }
}

/// What `observer` gathered so far (empty without one).
fn observed_state(observer: &Option<&mut dyn Observer>) -> Vec<u8> {
    observer.as_ref().map_or_else(Vec::new, |o| o.save())
}

fn write_report(report: &Report, out: &Path) -> crate::Result<()> {
    let json = serde_json::to_string_pretty(report).expect("report is plain data");
    imprint_core::io::atomic_write_bytes(&out.join("report.json"), json.as_bytes())?;
    Ok(())
}
