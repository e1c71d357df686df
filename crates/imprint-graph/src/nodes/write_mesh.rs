//! `WriteMesh`: a mesh per frame as OBJ or binary PLY, or the whole run as one animated glTF
//! binary (`Glb`), for other tools.
//!
//! **Glb.** The frames the node's schedule picks (`every`, `offset`) are kept in memory and
//! written as `NAME.glb` once, after the last frame ([`Stage::finish`], where the Render
//! node writes its GIF), atomically. Blender and three.js play it at the pipeline's fps:
//! - the same triangles in every frame (any Mesh node, a skin, a cloth): one mesh, frame 0 its
//!   base, one morph target per frame holding the position (and normal) deltas from frame 0,
//!   and an animation of its `weights` with STEP interpolation, one key per frame at
//!   `(frame - first frame) / fps`;
//! - triangles that change between frames: one node per frame under a root node, each shown
//!   only during its frame by a STEP `scale` animation (scale 0 when hidden).
//!
//! Cost: every kept frame's positions and normals (24 bytes per vertex) stay in memory until
//! the end and go into each checkpoint, so a resumed run's file still holds every frame; a
//! run interrupted before its end leaves no `.glb` (its checkpoint has the frames). Use
//! `every: k` to keep fewer frames of a long run.

use crate::node::{
    BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger, load_state,
    save_state,
};
use crate::report::NodeReport;
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::{MeshIn, Values};
use imprint_render::mesh_io::{MeshSequence, write_glb};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::path::PathBuf;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct WriteMeshNode {
    /// The Mesh node to write.
    pub mesh: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
    /// File format: `Obj` or `Ply` (a file per frame), or `Glb` (one animated file per run).
    #[serde(default)]
    pub format: MeshFormat,
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

/// File format of `WriteMesh`: OBJ (positions, normals, UVs where they exist) or binary PLY,
/// a file per frame; or `Glb`, one animated glTF binary of the whole run (see the module).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
pub enum MeshFormat {
    #[default]
    Obj,
    Ply,
    Glb,
}

impl Node for WriteMeshNode {
    fn kind(&self) -> &'static str {
        "WriteMesh"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![Port::new("mesh", &self.mesh, PortType::Mesh)]
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
    fn writes_whole_run(&self) -> bool {
        self.format == MeshFormat::Glb
    }
    fn check(&self, _ctx: &CheckCtx<'_>) -> crate::Result<()> {
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        Ok(Box::new(WriteMeshStage {
            input: ctx.mesh_in(&self.mesh),
            dir: ctx.out.join(self.dir.as_deref().unwrap_or(ctx.name())),
            format: self.format,
            fps: ctx.check.fps,
            sequence: MeshSequence::default(),
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct WriteMeshStage {
    input: MeshIn,
    dir: PathBuf,
    format: MeshFormat,
    fps: f32,
    /// The frames kept for the `.glb` (empty for the per-frame formats).
    sequence: MeshSequence,
}

impl WriteMeshStage {
    /// Where the `.glb` goes: `DIR/NAME.glb`, NAME the mesh node's.
    fn glb_path(&self) -> PathBuf {
        self.dir.join(format!("{}.glb", self.input.node()))
    }
}

impl Stage for WriteMeshStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !ctx.key {
            return Ok(Step::idle());
        }
        let mesh = ctx.values.mesh(&self.input)?;
        let (name, frame) = (self.input.node(), ctx.frame);
        let path = match self.format {
            MeshFormat::Obj => {
                let p = self.dir.join(format!("{name}_{frame:04}.obj"));
                imprint_render::mesh_io::write_obj(&p, mesh, &Default::default())?;
                p
            }
            MeshFormat::Ply => {
                let p = self.dir.join(format!("{name}_{frame:04}.ply"));
                imprint_render::mesh_io::write_ply(&p, mesh)?;
                p
            }
            MeshFormat::Glb => {
                self.sequence
                    .push(frame, mesh)
                    .map_err(|e| ctx.at_node(e))?;
                ctx.metric("glb_frames", self.sequence.len());
                // Kept, not written yet: the file is written by `finish`.
                return Ok(Step::wrote(Vec::new()));
            }
        };
        ctx.metric("last", path.display().to_string());
        ctx.count("files", 1);
        Ok(Step::wrote(vec![path]))
    }

    fn finish(&mut self, report: &mut NodeReport) -> imprint_core::Result<Vec<PathBuf>> {
        // A node that kept no frame in this run's range writes no file.
        if self.format != MeshFormat::Glb || self.sequence.is_empty() {
            return Ok(Vec::new());
        }
        let path = self.glb_path();
        write_glb(&path, &self.sequence, self.fps, self.input.node())?;
        let layout = if self.sequence.shares_topology() {
            "morph targets"
        } else {
            "node per frame"
        };
        let metrics = &mut report.metrics;
        metrics.insert("glb".into(), path.display().to_string().into());
        metrics.insert("glb_layout".into(), layout.into());
        Ok(vec![path])
    }

    fn save(&self, _values: &Values) -> imprint_core::Result<Vec<u8>> {
        match self.format {
            MeshFormat::Glb => save_state(&self.sequence),
            MeshFormat::Obj | MeshFormat::Ply => Ok(Vec::new()),
        }
    }

    fn load(&mut self, bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        if self.format == MeshFormat::Glb {
            self.sequence = load_state(bytes)?;
        }
        Ok(())
    }
}
