//! `Drape`: Tokoi's depth-buffer draping, a garment fitted out of a body every frame the
//! body or garment changes. The vertices it leaves inside the body are counted and warned
//! about once (`check_inside`).

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
};
use crate::schema::defaults;
use crate::value::{MeshIn, Value};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::drape::DrapeParams;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
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
            cache: Default::default(),
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
    /// The last body's maps and inside test, for a body that did not change (CPU path).
    cache: imprint_stages::drape::BodyCache,
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
            None => imprint_stages::drape::drape_cached(
                &mut self.cache,
                body,
                &mut fitted.positions,
                &self.params,
            ),
        }
        .map_err(|e| ctx.at_node(e))?;
        fitted.compute_normals();
        let mut m = serde_json::to_value(&r).expect("plain data");
        m["frame"] = ctx.frame.into();
        ctx.push_per_frame(m);
        check_inside(&r, &self.params, ctx);
        Ok(Step::computed(Value::Mesh(Arc::new(fitted))))
    }
    fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }
}

/// The drape's self-check: garment vertices left inside the body (the exact inside test,
/// `DrapeReport::inside_after`, found by the fit at no extra queries) are counted per frame
/// (`inside_after` in `per_frame`, the run's sum in `inside_after`) and warned about once.
///
/// Never a hard error: leaving them is the method's documented outcome, not a failure. T's
/// views cannot resolve a vertex that no view sees inside or whose shortest push tunnels
/// through another part of the body (T's own chest), and the fit leaves it where it was and
/// counts it (`unresolved`); the distance-field fallback leaves those deeper than its band. A
/// pushed vertex is checked to leave the body by half a texel past where it lands, so it may
/// end inside by less than that.
fn check_inside(
    r: &imprint_stages::drape::DrapeReport,
    params: &DrapeParams,
    ctx: &mut FrameCtx<'_>,
) {
    if r.inside_after == 0 {
        return;
    }
    ctx.count("inside_after", r.inside_after as u64);
    let (n, unresolved, short) = (r.inside_after, r.unresolved, r.inside_after - r.unresolved);
    let texel = r.texel;
    let fallback = match params.fallback {
        imprint_stages::drape::Fallback::None => "fallback: DistanceField(resolution: 64, band: 8)",
        imprint_stages::drape::Fallback::DistanceField { .. } => {
            "a wider fallback band, or more views (e.g. (1, 0, 0))"
        }
    };
    ctx.warn_once("garment inside the body", || {
        format!(
            "{n} of {} garment vertices are left inside the body ({unresolved} no view or \
             fallback resolved, {short} pushed to within half a texel ({:.2e} m) short of the \
             surface); counted per frame (inside_after in report.json). For fewer: {fallback}; \
             a finer resolution; an offset of at least half a texel",
            r.vertices,
            0.5 * texel
        )
    });
}
