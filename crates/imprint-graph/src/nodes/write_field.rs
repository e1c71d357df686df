//! `WriteField`: a field per frame as `.npy` + JSON, and PNG slices.

use crate::node::{BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger};
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::FieldIn;
use imprint_core::DistanceField;
use imprint_render::slice::SliceOptions;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WriteFieldNode {
    /// The DistanceField node to write.
    pub field: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
    /// Write `<name>_<frame>_dist.npy`, `_vec.npy` and `_field.json`.
    #[serde(default = "defaults::yes")]
    pub npy: bool,
    /// PNG slices per frame.
    #[serde(default)]
    pub slices: Vec<SliceOptions>,
    /// Write every k-th frame (1 = every frame).
    #[serde(default = "defaults::one")]
    pub every: u32,
    /// Frames written are those where (frame - offset) mod every = 0.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

impl Node for WriteFieldNode {
    fn kind(&self) -> &'static str {
        "WriteField"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![Port::new("field", &self.field, PortType::DistanceField)]
    }
    fn output(&self) -> Option<PortType> {
        None
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::Writes
    }
    fn schedule(&self) -> Schedule {
        Schedule::every(self.every, self.offset)
    }
    fn check(&self, _ctx: &CheckCtx<'_>) -> crate::Result<()> {
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        Ok(Box::new(WriteFieldStage {
            input: ctx.field_in(&self.field),
            dir: ctx.out.join(self.dir.as_deref().unwrap_or(ctx.name())),
            npy: self.npy,
            slices: self.slices.clone(),
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct WriteFieldStage {
    input: FieldIn,
    dir: PathBuf,
    npy: bool,
    slices: Vec<SliceOptions>,
}

impl Stage for WriteFieldStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !ctx.key {
            return Ok(Step::idle());
        }
        let field = ctx.values.field(&self.input)?.cpu(ctx.gpu)?;
        let (name, frame) = (self.input.node(), ctx.frame);
        let mut files = Vec::new();
        if self.npy {
            files = imprint_render::field_io::write_field(&self.dir, name, frame, &field)?;
        }
        for s in &self.slices {
            files.push(write_slice(&self.dir, name, frame, &field, s)?);
        }
        ctx.metric("dir", self.dir.display().to_string());
        ctx.count("files", files.len() as u64);
        Ok(Step::wrote(files))
    }
}

/// Writes `DIR/<field>_<frame:04>_<axis><index>.png`, titled with the field and frame;
/// returns its path.
fn write_slice(
    dir: &Path,
    field_name: &str,
    frame: u32,
    field: &DistanceField,
    opts: &SliceOptions,
) -> imprint_core::Result<PathBuf> {
    let index = opts.resolve_index(&field.spec)?;
    let mut opts = opts.clone();
    if opts.title.is_none() {
        opts.title = Some(format!("{field_name}  frame {frame:04}"));
    }
    let path = dir.join(format!(
        "{field_name}_{frame:04}_{}{index}.png",
        opts.axis.letter()
    ));
    imprint_render::slice::write_field_slice(&path, field, &opts)?;
    Ok(path)
}
