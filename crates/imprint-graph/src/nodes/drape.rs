//! `Drape`: Tokoi's depth-buffer draping, a garment fitted out of a body every frame the
//! body or garment changes.

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
};
use crate::schema::defaults;
use crate::value::{MeshIn, Value};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::drape::DrapeParams;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct DrapeNode {
    /// The Mesh node the garment must not enter (closed; it may deform).
    pub body: String,
    /// The Mesh node to fit (a garment mesh, or a Cloth node's output).
    pub garment: String,
    /// Views, resolution, offset, fallback: `imprint_stages::drape::DrapeParams`.
    #[serde(default)]
    pub params: DrapeParams,
    /// Where the views' depth maps are rendered; the pushes run on the CPU.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

impl Node for DrapeNode {
    fn kind(&self) -> &'static str {
        "Drape"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![
            Port::new("body", &self.body, PortType::Mesh),
            Port::new("garment", &self.garment, PortType::Mesh),
        ]
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::Mesh)
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::Inputs
    }
    fn backend(&self) -> Option<Backend> {
        self.backend
    }
    fn has_gpu_path(&self) -> bool {
        true
    }
    fn track(&self) -> Option<Track> {
        Some(Track::Vertices)
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        self.params.validate().map_err(|e| ctx.fail("params", e))?;
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let gpu = match ctx.choose_gpu()? {
            Some(g) => Some((g, Box::new(GpuRasterizer::new(g)?))),
            None => None,
        };
        Ok(Box::new(DrapeStage {
            body: ctx.mesh_in(&self.body),
            garment: ctx.mesh_in(&self.garment),
            params: self.params.clone(),
            gpu,
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct DrapeStage {
    body: MeshIn,
    garment: MeshIn,
    params: DrapeParams,
    /// The GPU rasteriser for the views, when the node runs on the GPU.
    gpu: Option<(&'static GpuContext, Box<GpuRasterizer>)>,
}

impl Stage for DrapeStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !(ctx.first || ctx.changed) {
            return Ok(Step::idle());
        }
        let body = ctx.values.mesh(&self.body)?;
        let mut fitted = (**ctx.values.mesh(&self.garment)?).clone();
        let r = match &mut self.gpu {
            Some((gpu, r)) => imprint_stages::drape::drape_with(
                body,
                &mut fitted.positions,
                &self.params,
                |m, cam, w, h, o| r.depth_map(gpu, m, cam, w, h, o),
            ),
            None => imprint_stages::drape::drape_cpu(body, &mut fitted.positions, &self.params),
        }
        .map_err(|e| ctx.at_node(e))?;
        fitted.compute_normals();
        let mut m = serde_json::to_value(&r).expect("plain data");
        m["frame"] = ctx.frame.into();
        ctx.push_per_frame(m);
        Ok(Step::computed(Value::Mesh(Arc::new(fitted))))
    }
    fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }
}
