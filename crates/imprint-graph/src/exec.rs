//! A whole run: an [`Executor`] stepped frame by frame into an output folder, with
//! checkpoints on request, resumption from them, and a `report.json` that is written whatever
//! happens (after the last frame, or with the frames done and the error when a frame fails or
//! the run is interrupted).

use crate::executor::{Checkpoint, Executor, checkpoint_path};
pub use crate::executor::{Observed, Observer, RunOptions};
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
}

impl Run {
    /// Builds every stage; with `opts.resume`, restores the folder's checkpoint. Nothing is
    /// written yet, so a refused resume leaves the folder as it was.
    pub fn start(plan: &Plan, opts: &RunOptions) -> crate::Result<Run> {
        let mut ex = Executor::new(plan, opts.clone())?;
        if opts.resume {
            let c = Checkpoint::read_dir(&opts.out)?;
            ex.restore(&c)?;
            ex.report.resumed_at = Some(c.next_frame());
        }
        Ok(Run {
            ex,
            opts: opts.clone(),
        })
    }

    /// What the plan and the stages' construction warn about.
    pub fn warnings(&self) -> &[String] {
        &self.ex.report.warnings
    }

    pub fn executor(&self) -> &Executor {
        &self.ex
    }

    /// Runs the remaining frames, then the whole-run writers; writes `report.json`.
    pub fn finish(
        mut self,
        progress: &mut dyn FnMut(u32, u32),
        mut observer: Option<&mut dyn Observer>,
    ) -> crate::Result<Report> {
        let (ex, opts) = (&mut self.ex, &self.opts);
        let total = ex.frames().len() as u32;
        while !ex.done() {
            if opts.stop.as_ref().is_some_and(|s| s.load(Ordering::SeqCst)) {
                let e = Error::Interrupted {
                    frame: ex.next_frame(),
                };
                return Err(stopped(ex, opts, e.into()));
            }
            let obs: Option<&mut dyn Observer> = match observer {
                Some(ref mut o) => Some(&mut **o),
                None => None,
            };
            if let Err(e) = ex.step_observed(obs) {
                return Err(stopped(ex, opts, e));
            }
            progress(ex.next_frame() - ex.frames().start, total);
            let every = opts.checkpoint_every;
            let since = ex.next_frame() - ex.frames().start;
            if every > 0 && since.is_multiple_of(every) && !ex.done() {
                save_checkpoint(ex, &opts.out)?;
            }
        }
        if opts.checkpoint_every > 0 {
            // Before the whole-run writers: a later run may go on from here.
            save_checkpoint(ex, &opts.out)?;
        }
        let report = ex.finish()?;
        write_report(&report, &opts.out)?;
        Ok(report)
    }
}

/// The checkpoint and the report so far, in `out` (a run killed later leaves both).
fn save_checkpoint(ex: &Executor, out: &Path) -> crate::Result<()> {
    ex.checkpoint()?.write(&checkpoint_path(out))?;
    write_report(&ex.report(), out)
}

/// A run that stopped early: its report says how far it got and why; with checkpoints, the
/// state before the failed frame is kept too.
fn stopped(ex: &Executor, opts: &RunOptions, e: crate::Error) -> crate::Error {
    let mut report = ex.report();
    report.error = Some(e.to_string());
    let _ = write_report(&report, &opts.out);
    if opts.checkpoint_every > 0 && matches!(&e, crate::Error::Core(Error::Interrupted { .. })) {
        let _ = ex
            .checkpoint()
            .and_then(|c| Ok(c.write(&checkpoint_path(&opts.out))?));
    }
    e
}

fn write_report(report: &Report, out: &Path) -> crate::Result<()> {
    let json = serde_json::to_string_pretty(report).expect("report is plain data");
    imprint_core::io::atomic_write_bytes(&out.join("report.json"), json.as_bytes())?;
    Ok(())
}
