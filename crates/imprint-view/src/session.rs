//! The pipeline side of the viewer, without a window: the last good plan, its executor stepped
//! frame by frame, reloads that keep the state of unchanged nodes, and the problem to show
//! (a broken file, a failed frame). The window only asks this object to step, seek and
//! reload, and draws what it holds.

use imprint_graph::Executor;
use imprint_graph::exec::RunOptions;
use imprint_graph::executor::FrameSummary;
use imprint_graph::schema::Backend;
use imprint_graph::{Error, Plan};
use std::collections::{BTreeSet, VecDeque};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// How many frames of timings the panel averages over.
const HISTORY: usize = 24;
/// A checkpoint kept in memory every this many frames at first, for scrubbing back; then as
/// often as costs a tenth of the stepping ([`Session::pace_checkpoints`]), from
/// `KEEP_EVERY` to `KEEP_MAX` frames.
const KEEP_EVERY: u32 = 8;
const KEEP_MAX: u32 = 64;

/// What is wrong, as the window shows it.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    /// "pipeline file" or "frame 12".
    pub when: String,
    /// `file:line:column: message` for a file error, the stage's message otherwise.
    pub message: String,
    /// The offending line of the file with a caret under the column, and the help.
    pub detail: String,
    /// Whether the last good pipeline still runs.
    pub still_running: bool,
}

/// What a reload did.
#[derive(Clone, Debug, PartialEq)]
pub enum Reloaded {
    /// The nodes built anew (the others kept their state).
    Applied { rebuilt: Vec<String> },
    /// The text is the same as the running plan's: nothing to do.
    Unchanged,
    /// The file is broken (see [`Session::problem`]); the last good plan keeps running.
    Refused,
}

/// The viewer's pipeline: see the module doc.
pub struct Session {
    path: PathBuf,
    sets: Vec<String>,
    frames: Option<Range<u32>>,
    backend: Option<Backend>,
    /// The file as last read and the plan made from it, when it was good.
    plan: Option<Plan>,
    ex: Option<Executor>,
    problem: Option<Problem>,
    history: VecDeque<FrameSummary>,
    /// Live edits (`NODE.FIELD=VALUE`, after the `--set`s) not yet written to the file.
    edits: Vec<String>,
}

impl Session {
    /// Opens `path`; a broken file is not an error here: it becomes the [`Problem`] shown,
    /// and the session waits for a good save.
    pub fn open(
        path: &Path,
        sets: &[String],
        frames: Option<Range<u32>>,
        backend: Option<Backend>,
    ) -> Session {
        let mut s = Session {
            path: path.to_path_buf(),
            sets: sets.to_vec(),
            frames,
            backend,
            plan: None,
            ex: None,
            problem: None,
            history: VecDeque::new(),
            edits: Vec::new(),
        };
        s.reload();
        s
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The running plan, with its writers (the viewer draws what its Render node draws).
    pub fn plan(&self) -> Option<&Plan> {
        self.plan.as_ref()
    }

    pub fn executor(&self) -> Option<&Executor> {
        self.ex.as_ref()
    }

    pub fn problem(&self) -> Option<&Problem> {
        self.problem.as_ref()
    }

    /// The frame whose values are shown: the last one stepped.
    pub fn shown_frame(&self) -> Option<u32> {
        let ex = self.ex.as_ref()?;
        (ex.next_frame() > ex.frames().start).then(|| ex.next_frame() - 1)
    }

    pub fn frames(&self) -> Option<Range<u32>> {
        self.ex.as_ref().map(Executor::frames)
    }

    /// Whether the last frame has run.
    pub fn at_end(&self) -> bool {
        self.ex.as_ref().is_none_or(Executor::done)
    }

    /// The timings of the last frames stepped, oldest first.
    pub fn history(&self) -> &VecDeque<FrameSummary> {
        &self.history
    }

    /// Reads the file again and runs it from the next frame, keeping every node whose spec
    /// and inputs did not change. A broken file leaves the running plan as it was.
    pub fn reload(&mut self) -> Reloaded {
        self.reload_with(&BTreeSet::new())
    }

    /// [`Session::reload`] after the assets of the nodes in `stale` changed on disk: those
    /// are built anew whatever their spec.
    pub fn reload_with(&mut self, stale: &BTreeSet<String>) -> Reloaded {
        let sets: Vec<String> = self.sets.iter().chain(&self.edits).cloned().collect();
        let plan = match imprint_graph::load(&self.path, &sets) {
            Ok(p) => p,
            Err(e) => return self.refuse(&e),
        };
        if let Some(old) = &self.plan
            && old.source.text == plan.source.text
            && self.ex.is_some()
            && stale.is_empty()
        {
            // A save that changed nothing (or only touched the file).
            if self
                .problem
                .as_ref()
                .is_some_and(|p| p.when == "pipeline file")
            {
                self.problem = None;
            }
            return Reloaded::Unchanged;
        }
        self.apply(plan, stale)
    }

    /// Runs `plan` (already checked) in place of the current one.
    fn apply(&mut self, plan: Plan, stale: &BTreeSet<String>) -> Reloaded {
        let live = live_plan(&plan);
        let result = match self.ex.as_mut() {
            Some(ex) => ex.reload_stale(&live, stale).map(Some),
            None => self.fresh(&live).map(|()| None),
        };
        match result {
            Ok(rebuilt) => {
                if let Some(ex) = self.ex.as_mut() {
                    ex.keep_every(KEEP_EVERY);
                }
                self.plan = Some(plan);
                self.problem = None;
                let all = || self.plan.iter().flat_map(|p| p.order.clone()).collect();
                Reloaded::Applied {
                    rebuilt: rebuilt.unwrap_or_else(all),
                }
            }
            Err(e) => self.refuse(&e),
        }
    }

    fn fresh(&mut self, live: &Plan) -> imprint_graph::Result<()> {
        let opts = RunOptions {
            frames: self.frames.clone(),
            backend: self.backend,
            ..Default::default()
        };
        self.ex = Some(Executor::new(live, opts)?);
        Ok(())
    }

    fn refuse(&mut self, e: &Error) -> Reloaded {
        self.problem = Some(Problem {
            when: "pipeline file".into(),
            message: e.to_string(),
            detail: detail(e),
            still_running: self.ex.is_some(),
        });
        Reloaded::Refused
    }

    /// The live edits not yet in the file.
    pub fn edits(&self) -> &[String] {
        &self.edits
    }

    /// Applies `assignment` (`NODE.FIELD=VALUE`) at once, through a reload; a value the
    /// file's checks refuse is dropped and shown as the problem.
    pub fn edit(&mut self, assignment: String) -> Reloaded {
        let before = self.edits.clone();
        crate::edits::record(&mut self.edits, assignment);
        let r = self.reload();
        if r == Reloaded::Refused {
            self.edits = before;
        }
        r
    }

    /// Writes the live edits into the file (keeping its comments and layout).
    pub fn write_edits(&mut self) -> imprint_core::Result<()> {
        crate::edits::write_back(&self.path, &self.edits)?;
        self.edits.clear();
        Ok(())
    }

    /// Runs the next frame; at the end, with `looping`, starts again from the first. A
    /// failed frame becomes the problem shown (the frames before it stay). Returns whether a
    /// frame ran.
    pub fn step(&mut self, looping: bool) -> bool {
        let Some(ex) = self.ex.as_mut() else {
            return false;
        };
        if ex.done() {
            if !looping {
                return false;
            }
            let first = ex.frames().start;
            if let Err(e) = ex.seek(first) {
                self.fail(e);
                return false;
            }
        }
        let ex = self.ex.as_mut().expect("checked above");
        let frame = ex.next_frame();
        let t = std::time::Instant::now();
        match ex.step() {
            Ok(summary) => {
                let kept_ms = t.elapsed().as_secs_f64() * 1e3 - summary.ms;
                self.pace_checkpoints(kept_ms);
                self.history.push_back(summary);
                while self.history.len() > HISTORY {
                    self.history.pop_front();
                }
                if self
                    .problem
                    .as_ref()
                    .is_some_and(|p| p.when != "pipeline file")
                {
                    self.problem = None;
                }
                true
            }
            Err(e) => {
                self.fail_at(frame, e);
                false
            }
        }
    }

    /// A checkpoint of a big state (fields of 96³ cells) takes as long as several frames;
    /// keeping one every 8 frames made a live view of `amortised_cloth.ron` 11 ms a frame
    /// slower. After each checkpoint (`kept_ms` over the step itself), the interval becomes
    /// the one that spends a tenth of the stepping time on them.
    fn pace_checkpoints(&mut self, kept_ms: f64) {
        if kept_ms < 1.0 || self.history.is_empty() {
            return;
        }
        let step_ms = self.history.iter().map(|f| f.ms).sum::<f64>() / self.history.len() as f64;
        let every = (10.0 * kept_ms / step_ms.max(1e-3)).ceil() as u32;
        if let Some(ex) = self.ex.as_mut() {
            ex.keep_every(every.clamp(KEEP_EVERY, KEEP_MAX));
        }
    }

    /// Shows `frame`'s values: back through the checkpoints kept in memory, or forward.
    pub fn show(&mut self, frame: u32) {
        let Some(ex) = self.ex.as_mut() else {
            return;
        };
        let range = ex.frames();
        let next = (frame + 1).clamp(range.start + 1, range.end);
        if let Err(e) = ex.seek(next) {
            self.fail(e);
        }
    }

    fn fail(&mut self, e: Error) {
        let frame = self.ex.as_ref().map_or(0, Executor::next_frame);
        self.fail_at(frame, e);
    }

    fn fail_at(&mut self, frame: u32, e: Error) {
        self.problem = Some(Problem {
            when: format!("frame {frame}"),
            message: e.to_string(),
            detail: String::new(),
            still_running: false,
        });
    }
}

/// The plan as the viewer runs it: no writers (nothing is written while watching), and every
/// node that feeds one, switched on or not ([`Plan::producers`]).
pub fn live_plan(plan: &Plan) -> Plan {
    let mut live = plan.clone();
    live.order = plan.producers.clone();
    live.order.retain(|n| !plan.file.nodes[n].is_writer());
    live
}

/// The offending line with a caret under the column, then the help, for a file error.
fn detail(e: &Error) -> String {
    let Error::Pipeline(p) = e else {
        return String::new();
    };
    let text = p.src.inner();
    let line = text.lines().nth(p.line.saturating_sub(1)).unwrap_or("");
    let mut s = format!(
        "{:>4} | {line}\n     | {}^ {}",
        p.line,
        " ".repeat(p.column.saturating_sub(1)),
        p.label
    );
    if let Some(help) = &p.help {
        s += &format!("\nhelp: {help}");
    }
    s
}
