//! What an executor is asked to do: its options, and the observer that sees every value.

use crate::node::Backend;
use imprint_core::{DistanceField, HeightField, Mesh};
use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::AtomicBool;

/// How to run a plan.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Output folder for writers, `report.json` and the checkpoint.
    pub out: PathBuf,
    /// Frames to run (default: all the file declares).
    pub frames: Option<Range<u32>>,
    /// Overrides the backend of the file and of every node.
    pub backend: Option<Backend>,
    /// Keep `checkpoint.bin` in the output folder, written every this many frames and at the
    /// end (0: never).
    pub checkpoint_every: u32,
    /// Continue from the output folder's checkpoint.
    pub resume: bool,
    /// Set from elsewhere (a signal handler) to stop before the next frame.
    pub stop: Option<Arc<AtomicBool>>,
}

/// A resource as consumers saw it on one frame (see [`Observer`]).
pub enum Observed<'a> {
    Mesh(&'a Mesh),
    Field(&'a DistanceField),
    Heights(&'a HeightField),
}

/// Sees every resource a run produces, frame by frame: what `imprint sweep` compares between
/// runs. Boundaries are not shown (they have no error metric of their own).
pub trait Observer {
    /// Called after `node` ran (or reused its result) on `frame`, with the value its consumers
    /// see on that frame. The time it takes (and a field's read-back or blend for it) is left
    /// out of the report's frame times.
    fn observe(&mut self, node: &str, frame: u32, value: Observed<'_>);

    /// Whether to show `node` at all (a field may need a read-back or a blend to be shown).
    fn wants(&self, _node: &str) -> bool {
        true
    }

    /// What it gathered so far, kept in the run's checkpoint so that a resumed run's observer
    /// goes on where the interrupted one stopped (empty: nothing to keep).
    fn save(&self) -> Vec<u8> {
        Vec::new()
    }

    /// Takes back what [`Observer::save`] gave, before a resumed run's first frame; `Err`
    /// says why it cannot (the resume is refused with it).
    fn load(&mut self, _bytes: &[u8]) -> Result<(), String> {
        Ok(())
    }
}
