//! `Ground`: a deformable ground (Onoue & Nishita) that keeps the prints objects press into
//! it, optionally taking in a layer that piles up on it (`accumulate`). After every frame the
//! heights are checked against what the frame could make of them ([`GroundBounds`]).

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Track, Trigger,
    load_state, save_state,
};
use crate::schema::defaults;
use crate::value::{HeightsIn, MeshIn, Value, Values};
use imprint_core::{Error, HeightField, Mesh};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_stages::ground::GroundGrid;
use imprint_stages::ground::gpu::GpuGround;
use imprint_stages::ground::{GroundParams, GroundSim, Initial, Relaxation};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
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
        let bounds = GroundBounds::new(sim.heights_units());
        Ok(Box::new(GroundStage {
            objects: self.objects.iter().map(|o| ctx.mesh_in(o)).collect(),
            params: self.params.clone(),
            bounds,
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
    /// What the heights may reach, checked after every frame.
    bounds: GroundBounds,
}

impl Stage for GroundStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        // Fresh snow (or anything piling up) first: the rise since last frame.
        if let Some(a) = &self.accumulate {
            let now = ctx.values.heights(a)?;
            if let Some(before) = &self.last {
                let rise = imprint_stages::ground::rise(now, before);
                self.sim.add_heights(&rise).map_err(|e| ctx.at_node(e))?;
                self.bounds.take_in(&rise, self.sim.grid().unit);
            }
            self.last = Some(now.clone());
        }
        let meshes = ctx.values.meshes(&self.objects)?;
        let refs: Vec<&Mesh> = meshes.iter().map(|m| &**m).collect();
        self.bounds.see_objects(&refs);
        let stepped = match &mut self.path {
            // The contact view stays on the GPU, where the passes read it.
            Path::Gpu(gpu, r, g) => g.step_resident(gpu, r, &refs),
            Path::Raster(gpu, r) => self
                .sim
                .step_with(&refs, |m, cam, w, h, o| r.depth_map(gpu, m, cam, w, h, o)),
            Path::Cpu => self.sim.step(&refs),
        };
        let m = stepped.map_err(|e| ctx.at_node(e))?;
        self.bounds.displaced += m.displaced_units;
        let (units, grid) = match &self.path {
            Path::Gpu(_, _, g) => (g.heights_units(), g.grid()),
            _ => (self.sim.heights_units(), self.sim.grid()),
        };
        let above = self.bounds.check(units, grid, ctx)?;
        let mut frame_metrics = serde_json::to_value(m).expect("plain data");
        frame_metrics["above_bound_cells"] = above.into();
        ctx.push_per_frame(frame_metrics);
        if above > 0 {
            ctx.count("frames_above_bound", 1);
            let top = self.bounds.object_top(grid) as f64 * grid.unit;
            ctx.warn_once("ground above its bound", || {
                format!(
                    "{above} cell(s) stand above the highest start height plus the layer taken \
                     in plus the tallest object ({top:.4} m), within what was pushed out of \
                     prints, so counted per frame (above_bound_cells in report.json), not \
                     stopped: relaxation: Labelled leaves needles and Full does not spill a heap \
                     over the body that holds it; relaxation: Settle (the default) does"
                )
            });
        }
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
        let sim = gpu_sim.as_ref().unwrap_or(&self.sim);
        save_state(&(sim, &self.last, &self.bounds))
    }

    fn load(&mut self, bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        type Saved = (GroundSim, Option<Arc<HeightField>>, GroundBounds);
        let (sim, last, bounds): Saved = load_state(bytes)?;
        if let Path::Gpu(gpu, _, g) = &mut self.path {
            **g = GpuGround::from_sim(gpu, &sim)?;
        }
        *self.sim = sim;
        self.last = last;
        // The start height is the file's (its initial heights), not the checkpoint's.
        self.bounds = GroundBounds {
            start_top: self.bounds.start_top,
            ..bounds
        };
        Ok(())
    }

    fn on_gpu(&self) -> bool {
        !matches!(self.path, Path::Cpu)
    }
}

/// What a ground's heights may reach, checked after every frame (in height units, from the
/// heights the stage keeps: O(cells), as the height field it publishes).
///
/// - **Below the base plane** (height 0): an error. The fixed-point heights are clamped
///   there by every pass, so a negative height is a broken state, never a model's answer.
/// - **Above what the frames could raise** (an error): no pass raises a cell by more than
///   the ground pushed out of a print that frame (`displaced_units`: it goes to the rim) and
///   the layer it took in (the largest rise of `accumulate`), and the slump only moves
///   ground downhill; so no cell stands above the highest start height plus all that, plus
///   one unit for the rounding of a layer to whole units. Beyond it the state is broken (a
///   damaged checkpoint, or a changed initial height image under `--resume`). With α = 0
///   (the snow preset) nothing is pushed out, so this is the start height plus the layer.
/// - **Above the tallest object** (counted and warned once): above the highest start height
///   plus the layer plus the tallest object's vertical extent (its mesh bounds, the largest
///   seen so far) but within the bound above. The default `Relaxation::Settle` keeps below it
///   (what a body pushes above its top spills over the body, `tests/ground_settle.rs`); O's
///   `Labelled` passes leave needles above it and `Full` relaxation does not spill, which are
///   the models' known limits, not failures. Counted per frame (`above_bound_cells`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct GroundBounds {
    /// The highest start height, units (from the file's initial heights at build).
    pub start_top: i64,
    /// Σ over frames of the largest rise taken in from `accumulate`, units.
    pub added: f64,
    /// Σ over frames of the ground pushed out to the rims, units.
    pub displaced: i64,
    /// The largest vertical extent of an object so far, m.
    pub object: f32,
}

impl GroundBounds {
    /// Bounds of a ground that starts with `heights` (units).
    pub fn new(heights: &[i32]) -> Self {
        GroundBounds {
            start_top: heights.iter().copied().max().unwrap_or(0).max(0) as i64,
            ..Default::default()
        }
    }

    /// A layer's rise taken in (metres per cell), `unit` m per height unit.
    pub fn take_in(&mut self, rise: &[f32], unit: f64) {
        let top = rise.iter().copied().fold(0.0f32, f32::max);
        self.added += top as f64 / unit;
    }

    /// The objects pressing this frame.
    pub fn see_objects(&mut self, objects: &[&Mesh]) {
        for m in objects {
            let b = m.bounds();
            if !b.is_empty() {
                self.object = self.object.max(b.size().y);
            }
        }
    }

    /// Start height plus the layer taken in, units (one unit for the layer's rounding).
    fn base_top(&self) -> i64 {
        self.start_top + self.added.ceil() as i64 + 1
    }

    /// The highest the frames could raise a cell, units.
    pub fn hard_top(&self) -> i64 {
        self.base_top() + self.displaced.max(0)
    }

    /// The highest start height plus the layer plus the tallest object, units.
    pub fn object_top(&self, grid: &GroundGrid) -> i64 {
        self.base_top() + (self.object as f64 / grid.unit).ceil() as i64
    }

    /// Checks `heights` (units, x fastest, on `grid`): an [`Error::Numerical`] naming the
    /// node, the frame and the first cell out of bounds, or the number of cells above the
    /// tallest object (within what the frames could raise).
    pub fn check(
        &self,
        heights: &[i32],
        grid: &GroundGrid,
        ctx: &FrameCtx<'_>,
    ) -> imprint_core::Result<usize> {
        let (lo, hi) = heights
            .iter()
            .fold((i32::MAX, i32::MIN), |(lo, hi), &h| (lo.min(h), hi.max(h)));
        if heights.is_empty() {
            return Ok(0);
        }
        let nx = grid.dims.x as usize;
        let unit = grid.unit;
        let cell = |pred: &dyn Fn(i32) -> bool| {
            let j = heights.iter().position(|&h| pred(h)).unwrap_or(0);
            (j % nx, j / nx, heights[j] as f64 * unit)
        };
        let restart = "start the run again from its first frame (without --resume: a damaged \
                       checkpoint, or one taken with another initial height image, gives such \
                       a state); if it happens from the start, it is a bug in the ground \
                       stage: please report it with the pipeline";
        if lo < 0 {
            let (i, k, h) = cell(&|h| h < 0);
            return Err(ctx.numerical(
                format!("ground cell ({i}, {k}) is at {h} m, below the base plane (0 m)"),
                restart,
            ));
        }
        let hard = self.hard_top();
        if hi as i64 > hard {
            let (i, k, h) = cell(&|h| h as i64 > hard);
            return Err(ctx.numerical(
                format!(
                    "ground cell ({i}, {k}) is at {h} m, above anything the frames could raise \
                     ({} m: the highest start height {} m, plus {} m taken in from the layer, \
                     plus {} m pushed out of prints so far)",
                    hard as f64 * unit,
                    self.start_top as f64 * unit,
                    self.added.ceil() * unit,
                    self.displaced as f64 * unit
                ),
                restart,
            ));
        }
        let top = self.object_top(grid);
        if hi as i64 <= top {
            return Ok(0);
        }
        Ok(heights.iter().filter(|&&h| h as i64 > top).count())
    }
}
