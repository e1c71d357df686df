//! `WriteHeightmap`: a height field per frame as 16-bit PNG (+ JSON sidecar), EXR, `.npy`
//! and a coloured preview.

use crate::node::{BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger};
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::HeightsIn;
use imprint_render::heightmap as hm;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::path::PathBuf;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WriteHeightmapNode {
    /// The HeightField node to write.
    pub heights: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
    /// Files per frame, each `<heights>_<frame:04>.<ext>` (the preview `_preview.png`).
    #[serde(default = "default_heightmap_formats")]
    pub formats: Vec<HeightmapFormat>,
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

/// File formats of `WriteHeightmap`.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Deserialize, Serialize, JsonSchema,
)]
pub enum HeightmapFormat {
    /// 16-bit grayscale PNG, heights mapped to the full range; the range is in a JSON
    /// sidecar so the file reads back to within one quantisation step.
    Png16,
    /// Single-channel 32-bit float OpenEXR (channel "Y"): exact heights.
    Exr,
    /// NumPy `.npy`, f32, shape (nz, nx), north up as the PNG: exact heights, with the same
    /// JSON sidecar.
    Npy,
    /// 8-bit colour-mapped picture with a legend, for people.
    Preview,
}

fn default_heightmap_formats() -> Vec<HeightmapFormat> {
    vec![HeightmapFormat::Png16, HeightmapFormat::Preview]
}

impl Node for WriteHeightmapNode {
    fn kind(&self) -> &'static str {
        "WriteHeightmap"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![Port::new("heights", &self.heights, PortType::HeightField)]
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
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        if self.formats.is_empty() {
            return Err(ctx.fail("formats", "list at least one of Png16, Exr, Npy, Preview"));
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let mut formats = self.formats.clone();
        formats.sort();
        formats.dedup();
        Ok(Box::new(WriteHeightmapStage {
            input: ctx.heights_in(&self.heights),
            dir: ctx.out.join(self.dir.as_deref().unwrap_or(ctx.name())),
            formats,
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct WriteHeightmapStage {
    input: HeightsIn,
    dir: PathBuf,
    formats: Vec<HeightmapFormat>,
}

impl Stage for WriteHeightmapStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !ctx.key {
            return Ok(Step::idle());
        }
        let hf = ctx.values.heights(&self.input)?;
        let stem = format!("{}_{:04}", self.input.node(), ctx.frame);
        let mut files = Vec::new();
        for f in &self.formats {
            type Write =
                fn(&std::path::Path, &imprint_core::HeightField) -> imprint_core::Result<()>;
            let (ext, write): (&str, Write) = match f {
                HeightmapFormat::Png16 => (".png", hm::write_heightmap_png16),
                HeightmapFormat::Exr => (".exr", hm::write_heightmap_exr),
                HeightmapFormat::Npy => (".npy", hm::write_heightmap_npy),
                HeightmapFormat::Preview => ("_preview.png", hm::write_heightmap_preview),
            };
            let path = self.dir.join(format!("{stem}{ext}"));
            write(&path, hf)?;
            if matches!(f, HeightmapFormat::Png16 | HeightmapFormat::Npy) {
                files.push(hm::sidecar_path(&path));
            }
            files.push(path);
        }
        ctx.metric("dir", self.dir.display().to_string());
        Ok(Step::wrote(files))
    }
}
