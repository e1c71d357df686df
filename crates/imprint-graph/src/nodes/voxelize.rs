//! `Voxelize`: a mesh's surface cells and their boundary points on a fixed grid.

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger,
};
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::{BoundaryValue, MeshIn, Value};
use imprint_core::{BoundaryVariant, Error, GridSpec};
use imprint_gpu::GpuContext;
use imprint_stages::voxel::cpu::Voxelizer;
use imprint_stages::voxel::solid::ClosedCache;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::sync::Arc;

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct VoxelizeNode {
    /// The Mesh node to voxelise.
    pub mesh: String,
    /// The cells: fitted to the box the mesh sweeps over the run, or explicit.
    pub grid: GridChoice,
    /// `Closest` (sub-voxel, default) or `Centre` (H's voxel centres).
    #[serde(default)]
    pub variant: BoundaryVariant,
    /// Mark the cells inside the mesh, so that its distance field is signed (the cloth then
    /// knows a particle that got inside and takes it out the nearest way). Only a closed mesh
    /// has an inside: an open one gives an unsigned field, and the report says so.
    #[serde(default = "defaults::yes")]
    pub signed: bool,
    /// Where the voxelisation runs: `Auto`, `Cpu` or `Gpu`; null: the pipeline's `backend`.
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

/// The grid a Voxelize node works on.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
pub enum GridChoice {
    /// Cubic cells, `resolution` along the longest side of the box the mesh sweeps over the run,
    /// grown by `padding` (a fraction of that side) on every side. The grid stays fixed.
    Fit {
        /// Number of cells along the longest side of the padded box (at least 1).
        resolution: u32,
        /// Margin added on every side, as a fraction of the box's longest side (0.1 = 10 %).
        #[serde(default = "defaults::padding")]
        padding: f32,
    },
    /// An explicit grid: `origin` is the centre of cell (0, 0, 0).
    Explicit {
        /// Centre of cell (0, 0, 0), m.
        origin: (f32, f32, f32),
        /// Side of a cubic cell, m.
        cell: f32,
        /// Number of cells along x, y and z.
        dims: (u32, u32, u32),
    },
}

impl VoxelizeNode {
    /// The grid, for node `name` (a fitted grid takes its mesh's swept box).
    pub fn grid_spec(&self, name: &str, ctx: &mut BuildCtx<'_>) -> crate::Result<GridSpec> {
        Ok(match self.grid {
            GridChoice::Fit {
                resolution,
                padding,
            } => {
                let b = ctx.swept_bounds(&self.mesh)?.ok_or_else(|| {
                    Error::Invalid(format!(
                        "node '{name}': Fit needs the swept box of a Mesh node, and '{}' is \
                         computed while running; give an Explicit grid",
                        self.mesh
                    ))
                })?;
                GridSpec::fit(&b, resolution, padding)?
            }
            GridChoice::Explicit { origin, cell, dims } => GridSpec::new(
                glam::Vec3::new(origin.0, origin.1, origin.2),
                cell,
                glam::UVec3::new(dims.0, dims.1, dims.2),
            )?,
        })
    }
}

/// The `Explicit` grid as a file writes it, for messages.
const VOXEL_EXPLICIT: &str = "Explicit(origin: (x, y, z), cell: size, dims: (nx, ny, nz))";
const VOXEL_ORIGIN: &str = "origin is the centre of cell (0, 0, 0)";

impl Node for VoxelizeNode {
    fn kind(&self) -> &'static str {
        "Voxelize"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        vec![Port::new("mesh", &self.mesh, PortType::Mesh)]
    }
    fn output(&self) -> Option<PortType> {
        Some(PortType::Boundary)
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
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        match &self.grid {
            GridChoice::Fit {
                resolution,
                padding,
            } => {
                if *resolution == 0 {
                    return Err(ctx.fail("grid", "grid resolution must be at least 1, got 0"));
                }
                if *resolution > imprint_core::grid::MAX_AXIS_CELLS {
                    let r = *resolution as u64;
                    return Err(ctx.fail(
                        "grid",
                        format!(
                            "a {r}^3 grid would need {} (resolution at most {})",
                            imprint_core::error::human_bytes(r * r * r * 17),
                            imprint_core::grid::MAX_AXIS_CELLS
                        ),
                    ));
                }
                if !(padding.is_finite() && *padding >= 0.0) {
                    return Err(ctx.fail(
                        "grid",
                        format!("grid padding must be finite and >= 0, got {padding}"),
                    ));
                }
                ctx.fit_needs_swept_box("grid", &self.mesh, VOXEL_EXPLICIT, VOXEL_ORIGIN)?;
            }
            GridChoice::Explicit { origin, cell, dims } => {
                let o = glam::Vec3::new(origin.0, origin.1, origin.2);
                let d = glam::UVec3::new(dims.0, dims.1, dims.2);
                GridSpec::new(o, *cell, d).map_err(|e| ctx.fail("grid", e))?;
            }
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let name = ctx.name().to_string();
        let spec = self.grid_spec(&name, ctx)?;
        // Scratch, field and the writers' copies: refuse now rather than fail later.
        spec.check_memory(
            &format!("node '{name}': voxelisation and distance field"),
            9 + 8 + 16,
        )?;
        let gpu = ctx.choose_gpu()?;
        Ok(Box::new(VoxelizeStage {
            input: ctx.mesh_in(&self.mesh),
            spec,
            variant: self.variant,
            signed: self.signed,
            path: match gpu {
                Some(gpu) => VoxelPath::Gpu(gpu, ClosedCache::default()),
                None => {
                    let mut vox = Voxelizer::new(spec)?;
                    vox.signed = self.signed;
                    VoxelPath::Cpu(Box::new(vox))
                }
            },
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

struct VoxelizeStage {
    input: MeshIn,
    spec: GridSpec,
    variant: BoundaryVariant,
    signed: bool,
    path: VoxelPath,
}

enum VoxelPath {
    /// With whether the mesh is closed, checked again only when its triangles change.
    Gpu(&'static GpuContext, ClosedCache),
    /// The CPU voxeliser keeps its scratch (and knows whether the mesh is closed) between
    /// frames.
    Cpu(Box<Voxelizer>),
}

impl Stage for VoxelizeStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !(ctx.first || (ctx.key && ctx.changed)) {
            return Ok(Step::idle());
        }
        let mesh = ctx.values.mesh(&self.input)?;
        let (b, signed) = match &mut self.path {
            VoxelPath::Gpu(gpu, closed) => {
                let signed = self.signed && closed.is_closed(mesh);
                let b = imprint_stages::voxel::gpu::voxelize_gpu_timed(
                    gpu,
                    mesh,
                    &self.spec,
                    self.variant,
                    signed,
                    None,
                )?;
                gpu.wait()?;
                (BoundaryValue::Gpu(Arc::new(b)), signed)
            }
            VoxelPath::Cpu(vox) => {
                let b = vox.run(mesh, self.variant)?;
                ctx.metric("boundary_points", b.len());
                let signed = b.inside.is_some();
                (BoundaryValue::Cpu(Arc::new(b)), signed)
            }
        };
        // In the report, not on stderr: a field that no cloth reads needs no sign.
        if self.signed && ctx.first {
            ctx.metric("signed", signed);
            if !signed {
                ctx.metric(
                    "unsigned_because",
                    format!(
                        "mesh '{}' is open (some edge borders an odd number of triangles): its \
                         distance field is unsigned, so the cloth guesses which side a particle \
                         is on; `close_holes: true` on the Mesh node fills its holes",
                        self.input.node()
                    ),
                );
            }
        }
        Ok(Step::computed(Value::Boundary(b)))
    }
    fn on_gpu(&self) -> bool {
        matches!(self.path, VoxelPath::Gpu(..))
    }
}
