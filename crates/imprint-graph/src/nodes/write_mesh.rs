//! `WriteMesh`: a mesh per frame as OBJ or binary PLY, for other tools.

use crate::node::{BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger};
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::MeshIn;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::path::PathBuf;

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct WriteMeshNode {
    /// The Mesh node to write.
    pub mesh: String,
    /// Folder under the run's output folder (default: the node's name).
    #[serde(default)]
    pub dir: Option<String>,
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

/// File format of `WriteMesh`: OBJ (positions, normals, UVs where they exist) or binary PLY.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize)]
pub enum MeshFormat {
    #[default]
    Obj,
    Ply,
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
    fn check(&self, _ctx: &CheckCtx<'_>) -> crate::Result<()> {
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        Ok(Box::new(WriteMeshStage {
            input: ctx.mesh_in(&self.mesh),
            dir: ctx.out.join(self.dir.as_deref().unwrap_or(ctx.name())),
            format: self.format,
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
        };
        ctx.metric("last", path.display().to_string());
        ctx.count("files", 1);
        Ok(Step::wrote(1))
    }
}
