//! `Heightmap`: the heights of a mesh seen straight down (or up) through a depth buffer.

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
};
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::{MeshIn, Value};
use imprint_core::Error;
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::depth::{HeightRegion, HeightView};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct HeightmapNode {
    /// The Mesh node to look at.
    pub mesh: String,
    /// `Above` (the top surface, default) or `Below` (the underside).
    #[serde(default)]
    pub view: HeightView,
    /// The x-z cells: fitted to the box the mesh sweeps over the run, or explicit.
    pub grid: HeightGrid,
    /// Height of cells the mesh does not cover.
    #[serde(default)]
    pub empty: f32,
    /// Where the depth map is rasterised: `Auto`, `Cpu` or `Gpu`; null: the pipeline's
    /// `backend`.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// Compute on frames where (frame - offset) mod every = 0 (and on the run's first
    /// frame); consumers reuse the last result in between.
    #[serde(default = "defaults::one")]
    pub every: u32,
    /// Shifts the `every` cycle: frames where (frame - offset) mod every = 0 are computed.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

/// The x-z cells of a Heightmap node.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
pub enum HeightGrid {
    /// Square cells, `resolution` along the longer x/z side of the box the mesh sweeps over
    /// the run, grown by `padding` (a fraction of that side) on every side.
    Fit {
        /// Number of cells along the longer x/z side of the padded box (at least 1).
        resolution: u32,
        /// Margin added on every side, as a fraction of the box's longer side (0.1 = 10 %).
        #[serde(default = "defaults::padding")]
        padding: f32,
    },
    /// `origin` is the (x, z) centre of cell (0, 0).
    Explicit {
        /// (x, z) centre of cell (0, 0), m.
        origin: (f32, f32),
        /// Side of a square cell, m.
        cell: f32,
        /// Number of cells along x and z.
        dims: (u32, u32),
    },
}

/// The `Explicit` grid as a file writes it, for messages.
const HEIGHT_EXPLICIT: &str = "Explicit(origin: (x, z), cell: size, dims: (nx, nz))";
const HEIGHT_ORIGIN: &str = "origin is the (x, z) centre of cell (0, 0)";

impl Node for HeightmapNode {
    fn kind(&self) -> &'static str {
        "Heightmap"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![Port::new("mesh", &self.mesh, PortType::Mesh)]
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::HeightField)
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::Inputs
    }
    fn schedule(&self) -> Schedule {
        Schedule::every(self.every, self.offset)
    }
    fn backend(&self) -> Option<Backend> {
        self.backend
    }
    fn has_gpu_path(&self) -> bool {
        true
    }
    fn track(&self) -> Option<Track> {
        Some(Track::Heights)
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        match self.grid {
            HeightGrid::Fit {
                resolution,
                padding,
            } => {
                let max = imprint_core::raster::MAX_SIZE;
                if resolution == 0 || resolution > max {
                    return Err(ctx.fail(
                        "grid",
                        format!("resolution must be in 1..={max}, got {resolution}"),
                    ));
                }
                if !(padding.is_finite() && padding >= 0.0) {
                    return Err(ctx.fail(
                        "grid",
                        format!("grid padding must be finite and >= 0, got {padding}"),
                    ));
                }
                if !self.empty.is_finite() {
                    return Err(
                        ctx.fail("empty", format!("empty must be finite, got {}", self.empty))
                    );
                }
                ctx.fit_needs_swept_box("grid", &self.mesh, HEIGHT_EXPLICIT, HEIGHT_ORIGIN)?;
            }
            HeightGrid::Explicit { .. } => {
                self.region(None).map_err(|e| ctx.fail("grid", e))?;
            }
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let swept = match self.grid {
            HeightGrid::Fit { .. } => Some(ctx.swept_bounds(&self.mesh)?.ok_or_else(|| {
                Error::Invalid(format!(
                    "node '{}': Fit needs the swept box of a Mesh node; give an Explicit grid",
                    ctx.name()
                ))
            })?),
            HeightGrid::Explicit { .. } => None,
        };
        let gpu = ctx.choose_gpu()?;
        Ok(Box::new(HeightmapStage {
            input: ctx.mesh_in(&self.mesh),
            region: self.region(swept.as_ref())?,
            view: self.view,
            raster: match gpu {
                Some(g) => Some((g, Box::new(GpuRasterizer::new(g)?))),
                None => None,
            },
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

impl HeightmapNode {
    /// The cells: explicit, or fitted to `swept` (the mesh's swept box).
    fn region(&self, swept: Option<&imprint_core::Aabb>) -> imprint_core::Result<HeightRegion> {
        match (&self.grid, swept) {
            (
                HeightGrid::Fit {
                    resolution,
                    padding,
                },
                Some(b),
            ) => HeightRegion::fit(b, *resolution, *padding, self.empty),
            (HeightGrid::Fit { .. }, None) => Err(Error::Invalid(
                "Fit needs the swept box of a Mesh node; give an Explicit grid".into(),
            )),
            (HeightGrid::Explicit { origin, cell, dims }, _) => HeightRegion::new(
                glam::Vec2::new(origin.0, origin.1),
                *cell,
                glam::UVec2::new(dims.0, dims.1),
                self.empty,
            ),
        }
    }
}

struct HeightmapStage {
    input: MeshIn,
    region: HeightRegion,
    view: HeightView,
    /// The GPU rasteriser when the node runs on the GPU.
    raster: Option<(&'static GpuContext, Box<GpuRasterizer>)>,
}

impl Stage for HeightmapStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !(ctx.first || (ctx.key && ctx.changed)) {
            return Ok(Step::idle());
        }
        let mesh = ctx.values.mesh(&self.input)?;
        let hf = match &mut self.raster {
            Some((gpu, r)) => imprint_stages::depth::height_field_with(
                mesh,
                &self.region,
                self.view,
                |m, cam, w, h, o| r.depth_map(gpu, m, cam, w, h, o),
            )?,
            None => imprint_stages::depth::height_field_cpu(mesh, &self.region, self.view)?,
        };
        let (lo, hi) = hf.height_range();
        ctx.metric("height_min", lo);
        ctx.metric("height_max", hi);
        Ok(Step::computed(Value::Heights(Arc::new(hf))))
    }
    fn on_gpu(&self) -> bool {
        self.raster.is_some()
    }
}
