//! `Ground`: a deformable ground (Onoue & Nishita) that keeps the prints objects press into
//! it, optionally taking in a layer that piles up on it (`accumulate`).

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
    load_state, save_state,
};
use crate::schema::defaults;
use crate::value::{HeightsIn, MeshIn, Value, Values};
use imprint_core::{Error, HeightField, Mesh};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::ground::gpu::GpuGround;
use imprint_stages::ground::{GroundParams, GroundSim, Initial, Relaxation};
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct GroundNode {
    /// Mesh nodes pressed into the ground every frame (seen from below; the ground does not
    /// push back).
    #[serde(default)]
    pub objects: Vec<String>,
    /// Grid, initial height, material (`Preset(Sand | Snow)` or custom), relaxation:
    /// `imprint_stages::ground::GroundParams`.
    pub params: GroundParams,
    /// A HeightField node (a `Snow` node's ground, on the same cells) whose rise from one
    /// frame to the next is added to this ground before the objects press into it: fresh
    /// snow that then takes prints.
    #[serde(default)]
    pub accumulate: Option<String>,
    /// Where the contact view (the depth map from below) is rendered; the passes run on the
    /// CPU.
    #[serde(default)]
    pub backend: Option<Backend>,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
}

impl Node for GroundNode {
    fn kind(&self) -> &'static str {
        "Ground"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        let objects = self
            .objects
            .iter()
            .map(|o| Port::new("objects", o, PortType::Mesh));
        let layer = self
            .accumulate
            .iter()
            .map(|a| Port::new("accumulate", a, PortType::HeightField));
        objects.chain(layer).collect()
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::HeightField)
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
        Some(Track::Heights)
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        self.params.validate().map_err(|e| ctx.fail("params", e))?;
        if let Initial::Image { path, .. } = &self.params.initial {
            let full = ctx.base_dir.join(path);
            if !full.is_file() {
                return Err(ctx.fail(
                    "params",
                    format!("initial height image not found: {}", full.display()),
                ));
            }
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let sim = GroundSim::new(&self.params, ctx.check.base_dir)
            .map_err(|e| Error::Invalid(format!("node '{}': {e}", ctx.name())))?;
        let gpu = ctx.choose_gpu()?;
        // The passes go to the GPU too (settling reads back and settles on the CPU), except
        // what has no port yet: full relaxation, and taking a layer in (`accumulate`).
        let passes_on_gpu = self.accumulate.is_none() && self.params.relaxation != Relaxation::Full;
        let path = match gpu {
            Some(g) if passes_on_gpu => Path::Gpu(
                g,
                Box::new(GpuRasterizer::new(g)?),
                Box::new(GpuGround::from_sim(g, &sim)?),
            ),
            Some(g) => {
                ctx.warn(
                    "contact view on the GPU, passes on the CPU (full relaxation and \
                     accumulate have no GPU port yet)"
                        .into(),
                );
                Path::Raster(g, Box::new(GpuRasterizer::new(g)?))
            }
            None => Path::Cpu,
        };
        Ok(Box::new(GroundStage {
            objects: self.objects.iter().map(|o| ctx.mesh_in(o)).collect(),
            params: self.params.clone(),
            sim: Box::new(sim),
            accumulate: self.accumulate.as_ref().map(|a| ctx.heights_in(a)),
            last: None,
            path,
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

/// Where the ground's work runs.
enum Path {
    Cpu,
    /// The contact view rendered on the GPU, the passes on the CPU.
    Raster(&'static GpuContext, Box<GpuRasterizer>),
    /// Both on the GPU (heights kept there).
    Gpu(&'static GpuContext, Box<GpuRasterizer>, Box<GpuGround>),
}

struct GroundStage {
    objects: Vec<MeshIn>,
    params: GroundParams,
    /// The CPU ground (on the GPU path, rebuilt from the GPU's for a checkpoint).
    sim: Box<GroundSim>,
    /// The `accumulate` input and its heights last frame (their rise is added).
    accumulate: Option<HeightsIn>,
    last: Option<Arc<HeightField>>,
    path: Path,
}

impl Stage for GroundStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        // Fresh snow (or anything piling up) first: the rise since last frame.
        if let Some(a) = &self.accumulate {
            let now = ctx.values.heights(a)?;
            if let Some(before) = &self.last {
                let rise = imprint_stages::ground::rise(now, before);
                self.sim.add_heights(&rise).map_err(|e| ctx.at_node(e))?;
            }
            self.last = Some(now.clone());
        }
        let meshes = ctx.values.meshes(&self.objects)?;
        let refs: Vec<&Mesh> = meshes.iter().map(|m| &**m).collect();
        let stepped = match &mut self.path {
            // The contact view stays on the GPU, where the passes read it.
            Path::Gpu(gpu, r, g) => g.step_resident(gpu, r, &refs),
            Path::Raster(gpu, r) => self
                .sim
                .step_with(&refs, |m, cam, w, h, o| r.depth_map(gpu, m, cam, w, h, o)),
            Path::Cpu => self.sim.step(&refs),
        };
        let m = stepped.map_err(|e| ctx.at_node(e))?;
        ctx.push_per_frame(serde_json::to_value(m).expect("plain data"));
        let heights = match &self.path {
            Path::Gpu(_, _, g) => g.to_height_field(),
            _ => self.sim.to_height_field(),
        };
        Ok(Step::computed(Value::Heights(Arc::new(heights))))
    }

    fn save(&self, _values: &Values) -> imprint_core::Result<Vec<u8>> {
        let gpu_sim = match &self.path {
            Path::Gpu(_, _, g) => Some(g.to_sim(&self.params)?),
            _ => None,
        };
        save_state(&(gpu_sim.as_ref().unwrap_or(&self.sim), &self.last))
    }

    fn load(&mut self, bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        let (sim, last): (GroundSim, Option<Arc<HeightField>>) = load_state(bytes)?;
        if let Path::Gpu(gpu, _, g) = &mut self.path {
            **g = GpuGround::from_sim(gpu, &sim)?;
        }
        *self.sim = sim;
        self.last = last;
        Ok(())
    }

    fn on_gpu(&self) -> bool {
        !matches!(self.path, Path::Cpu)
    }
}
