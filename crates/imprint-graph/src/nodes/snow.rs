//! `Snow`: snow falling on meshes and, optionally, a flat ground (Tokoi): arrival by depth
//! maps from jittered directions, accumulation, slides steeper than the repose angle. After
//! every step no receiver may hold more snow than fell (`SnowSim::check`, `warn_rounding`).

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
    load_state, save_state,
};
use crate::schema::defaults;
use crate::value::{MeshIn, Value, Values};
use imprint_core::{Error, HeightField, Mesh};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::snow::gpu::{GpuSnowArrival, GpuSnowRelax};
use imprint_stages::snow::{SnowParams, SnowSim, flat_ground};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SnowNode {
    /// Mesh nodes the snow falls on; each also shades the others (and the ground).
    pub meshes: Vec<String>,
    /// A flat ground under the meshes that collects snow too; the node then outputs the
    /// ground's snow surface instead of the first mesh.
    #[serde(default)]
    pub ground: Option<SnowGround>,
    /// Direction, jitter, rate, repose angle, …: `imprint_stages::snow::SnowParams`.
    #[serde(default)]
    pub params: SnowParams,
    /// Where the K depth maps are rendered; deposit and slides run on the CPU.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

/// The flat ground a `Snow` node collects snow on (cells as a `Ground` node's, so a Ground
/// with the same grid can take the snow in with `accumulate`).
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct SnowGround {
    /// Extent along x and z, m.
    pub size: (f32, f32),
    /// Cells along x and z (square cells).
    pub resolution: (u32, u32),
    /// World (x, z) of the centre of cell (0, 0); default: centred on the origin.
    #[serde(default)]
    pub origin: Option<(f32, f32)>,
    /// Height of the bare ground, m.
    #[serde(default)]
    pub height: f32,
}

impl SnowGround {
    pub fn height_field(&self) -> imprint_core::Result<HeightField> {
        flat_ground(self.size, self.resolution, self.origin, self.height)
    }
}

impl Node for SnowNode {
    fn kind(&self) -> &'static str {
        "Snow"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        self.meshes
            .iter()
            .map(|m| Port::new("meshes", m, PortType::Mesh))
            .collect()
    }
    fn output(&self) -> Option<PortType> {
        Some(match self.ground {
            Some(_) => PortType::HeightField,
            None => PortType::Mesh,
        })
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::EveryFrame
    }
    fn backend(&self) -> Option<Backend> {
        self.backend
    }
    fn has_gpu_path(&self) -> bool {
        true
    }
    fn track(&self) -> Option<Track> {
        Some(match self.ground {
            Some(_) => Track::Heights,
            None => Track::Vertices,
        })
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        self.params.validate().map_err(|e| ctx.fail("params", e))?;
        if self.meshes.is_empty() {
            return Err(ctx.fail("meshes", "a Snow node needs at least one mesh"));
        }
        if let Some(g) = &self.ground {
            g.height_field().map_err(|e| ctx.fail("ground", e))?;
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let sim = SnowSim::new(&self.params)
            .map_err(|e| Error::Invalid(format!("node '{}': {e}", ctx.name())))?;
        let gpu = match ctx.choose_gpu()? {
            Some(g) => Some((g, Box::new(GpuRasterizer::new(g)?))),
            None => None,
        };
        Ok(Box::new(SnowStage {
            meshes: self.meshes.iter().map(|m| ctx.mesh_in(m)).collect(),
            sim: Box::new(sim),
            ground: self.ground.as_ref().map(|g| g.height_field()).transpose()?,
            gpu,
            gpu_relax: Box::new(GpuSnowRelax::new()),
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct SnowStage {
    meshes: Vec<MeshIn>,
    sim: Box<SnowSim>,
    ground: Option<HeightField>,
    /// The GPU rasteriser for the depth maps, when the node runs on the GPU, and the
    /// look-ups and slides there too.
    gpu: Option<(&'static GpuContext, Box<GpuRasterizer>)>,
    gpu_relax: Box<GpuSnowRelax>,
}

impl Stage for SnowStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        let ms = ctx.values.meshes(&self.meshes)?;
        let refs: Vec<&Mesh> = ms.iter().map(|m| &**m).collect();
        let dt = 1.0 / ctx.fps;
        let step = match &mut self.gpu {
            // Depth maps (never read back), look-ups and slides on the GPU; the deposit on
            // the CPU.
            Some((gpu, r)) => {
                let gpu: &GpuContext = gpu;
                let mut look_ups = GpuSnowArrival::new();
                self.sim.step_with_parts(
                    &refs,
                    self.ground.as_ref(),
                    dt,
                    look_ups.resident(gpu, r),
                    self.gpu_relax.relaxer(gpu),
                )
            }
            None => self.sim.step(&refs, self.ground.as_ref(), dt),
        }
        .map_err(|e| ctx.at_node(e))?;
        let checked = self.sim.check().map_err(|e| ctx.at_node(e))?;
        let m = self.sim.frame_metrics(ctx.frame, &step);
        let mut frame_metrics = serde_json::to_value(m).expect("plain data");
        frame_metrics["vertices_over_fallen"] = checked.vertices_over.into();
        ctx.push_per_frame(frame_metrics);
        if checked.any() {
            warn_rounding(&checked, ctx);
        }
        // Only what the node outputs: the ground's surface, or the first mesh.
        let v = match self.sim.ground() {
            Some(g) => Value::Heights(Arc::new(g.surface())),
            None => Value::Mesh(Arc::new(self.sim.displaced(0, refs[0]))),
        };
        Ok(Step::computed(v))
    }

    fn save(&self, _values: &Values) -> imprint_core::Result<Vec<u8>> {
        save_state(&*self.sim)
    }

    fn load(&mut self, bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        *self.sim = load_state(bytes)?;
        Ok(())
    }

    fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }
}

/// The snow's self-check (`SnowSim::check`, after every step): no mesh vertex deeper than
/// the snow that fell (rate × time: the open-sky depth facing the fall), no more snow on the
/// ground than the deposit put there (the stabilisation moves snow, never makes it).
///
/// Beyond rounding it is a broken state and stops the run (`Error::Numerical`): no
/// parameter makes more snow than fell. Within f32 rounding (a vertex under open sky facing
/// the fall, whose unit normal is a few ulps long) it is counted per frame
/// (`vertices_over_fallen`) and warned about once.
fn warn_rounding(checked: &imprint_stages::snow::SnowCheck, ctx: &mut FrameCtx<'_>) {
    ctx.count("frames_over_fallen", 1);
    let (v, g) = (checked.vertices_over, checked.ground_over_quanta);
    ctx.warn_once("snow over what fell", || {
        format!(
            "{v} mesh vertices (and {g:.3e} quanta on the ground) hold more snow than fell, by \
             no more than f32 rounding (a unit normal a few ulps long); counted per frame \
             (vertices_over_fallen in report.json), harmless"
        )
    });
}
