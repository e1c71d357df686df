//! Moving an executor in time and changing its plan while it runs: `seek` back through the
//! checkpoints it keeps in memory (or from the start), and `reload` a new plan keeping the
//! state of every node whose spec and inputs did not change.

use super::Executor;
use super::wave::waves;
use crate::plan::Plan;
use imprint_core::Error;
use std::collections::{BTreeMap, BTreeSet};

impl Executor {
    /// Keeps a checkpoint in memory every `n` frames (0: none), for [`Executor::seek`].
    pub fn keep_every(&mut self, n: u32) {
        self.keep_every = n;
    }

    /// Keeps the state between two frames when it is due (see [`Executor::keep_every`]).
    pub(crate) fn keep_if_due(&mut self) -> crate::Result<()> {
        let n = self.keep_every;
        if n > 0 && (self.next - self.frames.start).is_multiple_of(n) {
            let bytes = self.checkpoint()?.to_bytes()?;
            self.kept.insert(self.next, bytes);
        }
        Ok(())
    }

    /// Makes `frame` the next frame to run: back from the nearest kept checkpoint at or
    /// before it (or from the run's first frame), then forward step by step. Writers write
    /// again the frames they step through.
    pub fn seek(&mut self, frame: u32) -> crate::Result<()> {
        if frame < self.frames.start || frame > self.frames.end {
            return Err(Error::Invalid(format!(
                "seek to frame {frame}: outside the run's frames {}..{}",
                self.frames.start, self.frames.end
            ))
            .into());
        }
        if frame < self.next {
            match self.kept.range(..=frame).next_back() {
                Some((_, bytes)) => {
                    let c = super::Checkpoint::from_bytes(bytes, "memory".as_ref())?;
                    self.restore(&c)?;
                }
                None => self.reset()?,
            }
        }
        while self.next < frame {
            self.step()?;
        }
        Ok(())
    }

    /// Back to before the first frame: every stage built again, no values.
    fn reset(&mut self) -> crate::Result<()> {
        let fresh = Executor::new(&self.plan, self.opts.clone())?;
        let kept = std::mem::take(&mut self.kept);
        let (every, concurrent) = (self.keep_every, self.concurrent);
        *self = fresh;
        self.kept = kept;
        self.keep_every = every;
        self.concurrent = concurrent;
        Ok(())
    }

    /// Runs `plan` from the next frame on, keeping the stage, value and report of every node
    /// whose spec is unchanged and whose inputs are all kept (a render colour changed: the
    /// cloth keeps falling; its stiffness changed: it starts again from rest). Returns the
    /// nodes built anew. On an error the executor keeps its old plan.
    pub fn reload(&mut self, plan: &Plan) -> crate::Result<Vec<String>> {
        self.reload_stale(plan, &BTreeSet::new())
    }

    /// [`Executor::reload`], building the nodes named in `stale` anew even where their spec
    /// did not change (a mesh file they read was saved), and everything downstream of them.
    pub fn reload_stale(
        &mut self,
        plan: &Plan,
        stale: &BTreeSet<String>,
    ) -> crate::Result<Vec<String>> {
        let mut same = self.unchanged_nodes(plan);
        for name in &plan.topo {
            let reads_stale = plan.file.nodes[name]
                .inputs()
                .iter()
                .any(|p| !same.contains(p.node));
            if stale.contains(name) || reads_stale {
                same.remove(name);
            }
        }
        let old_plan = std::mem::replace(&mut self.plan, plan.clone());
        for (name, _) in old_plan
            .file
            .nodes
            .iter()
            .filter(|(n, _)| !same.contains(*n))
        {
            self.swept.remove(name);
        }
        let mut fresh = BTreeMap::new();
        let to_build: Vec<&String> = plan
            .order
            .iter()
            .filter(|n| !self.has_slot(n, &same))
            .collect();
        for name in to_build {
            match self.build_slot(name) {
                Ok(slot) => fresh.insert(name.clone(), slot),
                Err(e) => {
                    self.plan = old_plan;
                    return Err(e);
                }
            };
        }
        let mut old: BTreeMap<String, super::Slot> =
            self.slots.drain(..).map(|s| (s.name.clone(), s)).collect();
        for name in old.keys().filter(|n| !same.contains(*n)) {
            self.values.remove(name);
            *self.versions.entry(name.clone()).or_default() += 1;
        }
        for name in &plan.order {
            let slot = match fresh.remove(name) {
                Some(s) => s,
                None => old.remove(name).expect("kept nodes have a slot"),
            };
            self.slots.push(slot);
        }
        self.waves = waves(&self.slots);
        self.frames.end = self.frames.end.min(plan.file.frames);
        self.report.pruned = plan.pruned.clone();
        self.report.warnings = plan.warnings.clone();
        // What kept nodes warned about while running stays said (they do not say it again).
        for s in &self.slots {
            let said = s.report.warnings.iter();
            let named = said.map(|w| format!("node '{}': {w}", s.name));
            self.report.warnings.extend(named);
        }
        self.kept.clear();
        Ok(fresh_names(plan, &same))
    }

    fn has_slot(&self, name: &str, same: &BTreeSet<String>) -> bool {
        same.contains(name) && self.slots.iter().any(|s| s.name == name)
    }

    /// The nodes of `plan` whose spec equals this executor's and whose inputs are all such.
    fn unchanged_nodes(&self, plan: &Plan) -> BTreeSet<String> {
        let (a, b) = (&self.plan, plan);
        let mut same = BTreeSet::new();
        let run_wide = a.file.fps == b.file.fps
            && a.file.backend == b.file.backend
            && a.file.frames == b.file.frames
            && a.base_dir == b.base_dir;
        if !run_wide {
            return same;
        }
        let json = |p: &Plan, n: &str| p.file.nodes.get(n).map(|s| serde_json::to_value(s).ok());
        for name in &b.topo {
            let spec_same = json(a, name).is_some() && json(a, name) == json(b, name);
            let inputs_same = b.file.nodes[name]
                .inputs()
                .iter()
                .all(|p| same.contains(p.node));
            if spec_same && inputs_same {
                same.insert(name.clone());
            }
        }
        same
    }
}

fn fresh_names(plan: &Plan, same: &BTreeSet<String>) -> Vec<String> {
    plan.order
        .iter()
        .filter(|n| !same.contains(*n))
        .cloned()
        .collect()
}
