//! `Mesh`: a mesh from a file or a primitive, fitted and moved; a function of time.
//!
//! `path` may name an OBJ, PLY (ASCII, binary little- or big-endian), STL (ASCII or binary)
//! or glTF 2.0 file (`.gltf` with its buffers, or `.glb`). The format is told from the file's
//! content, the extension only where the content cannot decide
//! ([`imprint_core::mesh_formats::MeshFormat::detect`]); any other file is refused with a
//! message saying what it looks like (an image, an archive) and what is read. A glTF's
//! meshes come at their bind pose, or posed by one of its clips at each frame's time
//! (`clip: "Walk"`, with `speed`, `loop`, `clip_offset` as on the Skin node: linear blend
//! with the file's weights); a character that should deform by particles or dual
//! quaternions goes through a Skin node instead.

use crate::node::{BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger};
use crate::value::Value;
use imprint_core::{Aabb, Error};
use imprint_stages::mesh::{MeshParams, MeshSource};
use std::any::Any;
use std::sync::Arc;

impl Node for MeshParams {
    fn kind(&self) -> &'static str {
        "Mesh"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        Vec::new()
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::Mesh)
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::Time {
            moves: !self.motion.iter().all(|m| m.is_time_invariant()),
        }
    }
    fn swept_bounds(&self, ctx: &CheckCtx<'_>) -> imprint_core::Result<Option<Aabb>> {
        let src = MeshSource::new(self, ctx.base_dir)?;
        Ok(Some(swept(&src, ctx.frames, ctx.fps)))
    }
    fn swept_bounds_known(&self) -> bool {
        true
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        self.validate().map_err(|e| ctx.fail("motion", e))?;
        if let Some(p) = &self.path {
            ctx.existing_file("path", "mesh file", p)?;
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let source = MeshSource::new(self, ctx.check.base_dir)?;
        let bounds = swept(&source, ctx.check.frames, ctx.check.fps);
        ctx.swept.insert(ctx.name().to_string(), bounds);
        Ok(Box::new(MeshStage { source }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// The box a mesh sweeps over the whole run (every frame up to 64 samples), so a fitted grid
/// holds the motion and partial runs get the same grid.
pub fn swept(src: &MeshSource, frames: u32, fps: f32) -> Aabb {
    let step = frames.div_ceil(64).max(1) as usize;
    let times = (0..frames)
        .step_by(step)
        .chain([frames - 1])
        .map(|f| f as f32 / fps);
    src.sampled_bounds(times)
}

struct MeshStage {
    source: MeshSource,
}

impl Stage for MeshStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !ctx.first && self.source.is_static() {
            return Ok(Step::idle());
        }
        let mesh = self.source.at(ctx.time);
        if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::Numerical {
                node: ctx.name.to_string(),
                frame: ctx.frame,
                message: format!("vertex {i} is not finite after the motion"),
                hint: "lower the motion's amplitude or degrees".into(),
            });
        }
        ctx.metric("triangles", mesh.triangles.len());
        Ok(Step::computed(Value::Mesh(Arc::new(mesh))))
    }
}
