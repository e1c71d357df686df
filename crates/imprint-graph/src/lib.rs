//! imprint-graph: the pipeline file (RON), the node graph built and checked from it, pruning,
//! and the executor that runs it frame by frame with per-node timing.
//!
//! Flow: [`plan::load`] parses and validates a file into a [`plan::Plan`] (every edge typed
//! and checked, every value range checked, assets found, memory estimated) before anything
//! runs; an [`Executor`] runs it frame by frame ([`exec::run`]: a whole run into a folder)
//! and returns a [`report::Report`]. Each node kind is a module of [`nodes`] implementing the
//! traits of [`node`]; `docs/architecture.md` says how a frame runs.

pub mod budget;
pub mod diagnostics;
pub mod exec;
pub mod executor;
pub mod json_schema;
pub mod manifest;
pub mod node;
pub mod nodes;
pub mod overrides;
pub mod plan;
pub mod report;
pub mod rig;
pub mod schedule;
pub mod schema;
mod table;
pub mod value;

pub use diagnostics::PipelineError;
pub use executor::Executor;
pub use plan::{Plan, load, parse};

/// What can go wrong with a pipeline: an invalid file (exit 2) or a stage's error.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    #[error(transparent)]
    Pipeline(Box<PipelineError>),
    #[error(transparent)]
    Core(#[from] imprint_core::Error),
}

impl From<PipelineError> for Error {
    fn from(e: PipelineError) -> Self {
        Error::Pipeline(Box::new(e))
    }
}

impl Error {
    /// 2: the input must be fixed; 1: a failure while running.
    pub fn exit_code(&self) -> i32 {
        match self {
            Error::Pipeline(_) => 2,
            Error::Core(e) => e.exit_code(),
        }
    }
}

pub type Result<T, E = Error> = std::result::Result<T, E>;
