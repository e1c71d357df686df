//! Checkpoints: everything an executor carries between frames (every node's value and stage
//! state, the versions and what each node last took in, the report so far), so that a run
//! restored from one ends with the same bytes as a run that never stopped. Written with
//! postcard behind a magic line; the pipeline is identified by its parsed file and backend.

use super::Executor;
use crate::report::Report;
use crate::value::{Values, ValuesSnapshot};

use imprint_core::Error;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The file name of the checkpoint a run keeps in its output folder.
pub const CHECKPOINT_FILE: &str = "checkpoint.bin";

/// First bytes of a checkpoint file (its format version is the last number).
const MAGIC: &[u8] = b"imprint checkpoint 6\n";

/// An executor's state between two frames.
#[derive(Serialize, Deserialize)]
pub struct Checkpoint {
    /// The pipeline as parsed (JSON) and the backend override: what must match to restore.
    identity: String,
    /// The run's first frame, and the next frame to run.
    first: u32,
    next: u32,
    versions: BTreeMap<String, u64>,
    seen: BTreeMap<String, Option<Vec<u64>>>,
    values: ValuesSnapshot,
    /// Each node's stage state (postcard bytes, see `Stage::save`).
    stages: BTreeMap<String, Vec<u8>>,
    /// The report so far (JSON: its metrics are free-form).
    report: String,
    /// What the run's observer gathered so far ([`super::Observer::save`]; empty: none).
    observer: Vec<u8>,
}

impl Checkpoint {
    /// The frame a run restored from it runs next.
    pub fn next_frame(&self) -> u32 {
        self.next
    }

    /// The first frame of the run that wrote it.
    pub fn first_frame(&self) -> u32 {
        self.first
    }

    /// What the run's observer had gathered ([`super::Observer::save`]).
    pub fn observer(&self) -> &[u8] {
        &self.observer
    }

    /// Keeps what the run's observer has gathered with the executor's state.
    pub fn with_observer(mut self, bytes: Vec<u8>) -> Self {
        self.observer = bytes;
        self
    }

    pub fn to_bytes(&self) -> imprint_core::Result<Vec<u8>> {
        let mut bytes = MAGIC.to_vec();
        bytes.extend(crate::node::save_state(self)?);
        Ok(bytes)
    }

    pub fn from_bytes(bytes: &[u8], name: &Path) -> imprint_core::Result<Self> {
        let body = bytes.strip_prefix(MAGIC).ok_or_else(|| {
            Error::Invalid(format!(
                "{}: not an imprint checkpoint (or one from another version of imprint)",
                name.display()
            ))
        })?;
        crate::node::load_state(body)
            .map_err(|e| Error::Invalid(format!("{}: {e}", name.display())))
    }

    /// Writes it atomically (a checkpoint is never half-written under its name).
    pub fn write(&self, path: &Path) -> imprint_core::Result<()> {
        imprint_core::io::atomic_write_bytes(path, &self.to_bytes()?)
    }

    /// The checkpoint in `dir`, or a clear error when there is none.
    pub fn read_dir(dir: &Path) -> imprint_core::Result<Self> {
        let path = checkpoint_path(dir);
        let bytes = std::fs::read(&path).map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => Error::Invalid(format!(
                "--resume: no checkpoint in {} (run with --checkpoint-every N first)",
                dir.display()
            )),
            _ => Error::io(&path, e),
        })?;
        Self::from_bytes(&bytes, &path)
    }
}

/// Where a run keeps its checkpoint.
pub fn checkpoint_path(dir: &Path) -> PathBuf {
    dir.join(CHECKPOINT_FILE)
}

impl Executor {
    /// What identifies the run's pipeline: the parsed file and the backend override.
    fn identity(&self) -> String {
        serde_json::to_string(&(&self.plan.file, &self.opts.backend)).expect("plain data")
    }

    /// The executor's state now, between two frames.
    pub fn checkpoint(&self) -> crate::Result<Checkpoint> {
        let mut stages = BTreeMap::new();
        let mut seen = BTreeMap::new();
        for s in &self.slots {
            stages.insert(s.name.clone(), s.stage.save(&self.values)?);
            seen.insert(s.name.clone(), s.seen.clone());
        }
        Ok(Checkpoint {
            identity: self.identity(),
            first: self.frames.start,
            next: self.next,
            versions: self.versions.clone(),
            seen,
            values: self.values.snapshot(self.gpu)?,
            stages,
            report: serde_json::to_string(&self.report()).expect("plain data"),
            observer: Vec::new(),
        })
    }

    /// Takes the state of `c` (a checkpoint of this pipeline and first frame); the next
    /// [`Executor::step`] runs `c`'s next frame. Nothing changes when it does not fit.
    pub fn restore(&mut self, c: &Checkpoint) -> crate::Result<()> {
        self.check_fits(c)?;
        let report: Report = serde_json::from_str(&c.report)
            .map_err(|e| Error::Invalid(format!("checkpoint: its report does not read: {e}")))?;
        self.values = Values::from_snapshot(c.values.clone());
        for s in &mut self.slots {
            let state = c.stages.get(&s.name).ok_or_else(|| missing(&s.name))?;
            s.stage.load(state, &self.values)?;
            s.seen = c.seen.get(&s.name).cloned().flatten();
            s.report = report.nodes.get(&s.name).cloned().unwrap_or_default();
        }
        self.versions = c.versions.clone();
        self.next = c.next;
        // What this program, machine and invocation state, not the checkpoint's writer.
        let now = std::mem::take(&mut self.report);
        self.report = Report {
            nodes: BTreeMap::new(),
            adapter: now.adapter,
            threads: now.threads,
            schema_version: now.schema_version,
            imprint_version: now.imprint_version,
            overrides: now.overrides,
            units: now.units,
            axes: now.axes,
            ..report
        };
        Ok(())
    }

    /// Refuses a checkpoint of another pipeline, another first frame, or past the end.
    fn check_fits(&self, c: &Checkpoint) -> crate::Result<()> {
        if c.identity != self.identity() {
            return Err(Error::Invalid(format!(
                "the checkpoint is of a different pipeline ({}); run without --resume, or \
                 into another --out folder",
                differences(&c.identity, &self.identity())
            ))
            .into());
        }
        if c.first != self.frames.start {
            return Err(Error::Invalid(format!(
                "the checkpoint is of a run that began at frame {}, not {}: give --frames {}..{}",
                c.first, self.frames.start, c.first, self.frames.end
            ))
            .into());
        }
        if c.next > self.frames.end || c.next < self.frames.start {
            return Err(Error::Invalid(format!(
                "the checkpoint is at frame {}, outside --frames {}..{}",
                c.next, self.frames.start, self.frames.end
            ))
            .into());
        }
        for s in &self.slots {
            if !c.stages.contains_key(&s.name) {
                return Err(missing(&s.name).into());
            }
        }
        Ok(())
    }
}

fn missing(node: &str) -> Error {
    Error::Invalid(format!("the checkpoint has no state for node '{node}'"))
}

/// Which nodes (or file settings) differ between two identities, for the message.
fn differences(a: &str, b: &str) -> String {
    let parse = |s: &str| serde_json::from_str::<serde_json::Value>(s).unwrap_or_default();
    let (a, b) = (parse(a), parse(b));
    let mut what = Vec::new();
    let (fa, fb) = (&a[0], &b[0]);
    for key in ["frames", "fps", "backend", "seed"] {
        if fa[key] != fb[key] {
            what.push(key.to_string());
        }
    }
    if a[1] != b[1] {
        what.push("--backend".into());
    }
    let empty = serde_json::Map::new();
    let na = fa["nodes"].as_object().unwrap_or(&empty);
    let nb = fb["nodes"].as_object().unwrap_or(&empty);
    for name in na.keys().chain(nb.keys().filter(|k| !na.contains_key(*k))) {
        if na.get(name) != nb.get(name) {
            what.push(format!("node '{name}'"));
        }
    }
    match what.is_empty() {
        true => "the files differ".into(),
        false => format!("differs in {}", what.join(", ")),
    }
}
