//! The snow simulator on the CPU: arrival ([`super::arrival`]), deposit, stabilisation
//! ([`super::relax`]) per step, and the covered scene as output ([`SnowCover`]).
//!
//! **Deposit.** In a step of `dt` seconds a receiver with arrival probability P and unit
//! normal n gains, along its normal,
//!
//! depth += rate · dt · P · max(0, n · (−d)),
//!
//! d the (unjittered) fall direction. Why the cosine: snow is a flux F through planes facing
//! the fall (`rate` is that flux, metres of snow per second). A surface patch of area A whose
//! normal is at φ to the fall presents A cos φ to it, so it catches F A cos φ per second;
//! spread over its area A that is a layer F cos φ thick. A plane at slope φ under vertical fall
//! gets depth ∝ cos φ; its *vertical* thickness, depth / cos φ, is F, the same as flat ground,
//! which is what conserves the snow's volume per unit of horizontal area.
//!
//! **Meshes** keep the depth per vertex (f32, m along the normal), attached to the vertex
//! index: a mesh must keep its vertex count from step to step. They are not stabilised.
//!
//! **The ground** keeps its snow as a vertical column per cell (what a height field adds), in
//! whole quanta ([`QUANTUM`], u32) plus a fractional remainder below one quantum (f32), so
//! that slow snowfall is not rounded away and stabilisation moves whole quanta only. A cell
//! with normal n gains the column rate · dt · P · max(0, n · (−d)) / n_y (the layer above,
//! measured vertically). The ground given to each step is the bare ground (a `Ground` node may
//! have pressed prints into it); snow lies on it, and the surface seen by the depth maps and
//! the output is bare ground + snow.

use super::arrival::{Arrival, Receivers, arrival_with, fall_directions, gather, vertex_normals};
use super::check::Fallen;
use super::params::SnowParams;
use super::relax::{self, MAX_CELL_UNITS, QUANTUM, RelaxReport, Scratch};
use glam::{UVec2, Vec3};
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{Camera, Error, HeightField, Mesh, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// The snow on a ground height field.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundSnow {
    /// The bare ground of the last step (or [`SnowSim::set_ground`]).
    pub base: HeightField,
    /// Snow column per cell in whole quanta of [`QUANTUM`] metres (what stabilisation moves).
    pub units: Vec<u32>,
    /// Snow not yet a whole quantum, per cell, in quanta, in [0, 1).
    pub residual: Vec<f32>,
}

impl GroundSnow {
    fn new(base: &HeightField) -> Self {
        let n = base.heights.len();
        GroundSnow {
            base: base.clone(),
            units: vec![0; n],
            residual: vec![0.0; n],
        }
    }

    /// The vertical snow thickness of each cell, metres (x fastest, as the height field).
    pub fn thickness(&self) -> Vec<f32> {
        self.units
            .iter()
            .zip(&self.residual)
            .map(|(&u, &r)| (u as f32 + r) * QUANTUM)
            .collect()
    }

    /// Bare ground + snow.
    pub fn surface(&self) -> HeightField {
        let mut s = self.base.clone();
        for (h, t) in s.heights.iter_mut().zip(self.thickness()) {
            *h += t;
        }
        s
    }

    /// The whole quanta on the field: what stabilisation conserves exactly.
    pub fn total_units(&self) -> u64 {
        self.units.iter().map(|&u| u as u64).sum()
    }

    /// Snow volume, m³ (whole quanta and remainders), summed in f64.
    pub fn volume(&self) -> f64 {
        self.quanta_volume(self.total_quanta())
    }

    /// The snow on the field in quanta: whole quanta and remainders, summed in f64.
    pub fn total_quanta(&self) -> f64 {
        self.total_units() as f64 + self.residual.iter().map(|&r| r as f64).sum::<f64>()
    }

    /// `quanta` of snow over one cell each, m³.
    pub fn quanta_volume(&self, quanta: f64) -> f64 {
        quanta * QUANTUM as f64 * self.base.cell as f64 * self.base.cell as f64
    }
}

/// What one step did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SnowStep {
    /// Depth maps rendered.
    pub directions: u32,
    /// Receivers (mesh vertices and ground cells) reached from at least one direction.
    pub reached: usize,
    /// The ground's stabilisation (default when there is no ground or it is off).
    pub relax: RelaxReport,
}

/// The covered scene: the stage's output.
#[derive(Clone, Debug, PartialEq)]
pub struct SnowCover {
    /// One per input mesh, in order.
    pub meshes: Vec<MeshSnow>,
    pub ground: Option<GroundCover>,
}

/// Snow on one mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct MeshSnow {
    /// Snow depth per vertex, m, along the vertex normal.
    pub depth: Vec<f32>,
    /// The mesh with each vertex moved along its normal by `displacement × depth` (normals
    /// recomputed; uvs kept).
    pub mesh: Mesh,
}

/// Snow on the ground.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundCover {
    /// Bare ground + snow, m: what a `Ground` node deforms next (objects print into the fresh
    /// snow).
    pub surface: HeightField,
    /// The snow's vertical thickness per cell, m (same cells).
    pub thickness: HeightField,
}

/// Snow accumulating over a scene, step by step. All state is here; a run is reproducible to
/// the bit on any number of threads.
///
/// Serde writes all of it but the relaxation's scratch buffers (a checkpoint: loaded, it steps
/// on to the same bytes as a sim that never stopped).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SnowSim {
    params: SnowParams,
    directions: Vec<Vec3>,
    meshes: Vec<Vec<f32>>,
    ground: Option<GroundSnow>,
    arrival: Option<Arrival>,
    /// Not serialised (empty after loading): [`relax::relax`] sizes it and every pass writes
    /// all of it before reading it, so nothing carries over from one call to the next.
    #[serde(skip)]
    scratch: Scratch,
    time: f64,
    /// What has fallen so far, for [`SnowSim::check`].
    fallen: Fallen,
}

impl SnowSim {
    /// A simulator with no snow yet; checks the parameters.
    pub fn new(params: &SnowParams) -> Result<Self> {
        params.validate()?;
        Ok(SnowSim {
            params: params.clone(),
            directions: fall_directions(params),
            meshes: Vec::new(),
            ground: None,
            arrival: None,
            scratch: Scratch::default(),
            time: 0.0,
            fallen: Fallen::default(),
        })
    }

    pub fn params(&self) -> &SnowParams {
        &self.params
    }

    /// The fall directions rendered each step ([`fall_directions`]).
    pub fn directions(&self) -> &[Vec3] {
        &self.directions
    }

    /// Seconds of snowfall so far.
    pub fn time(&self) -> f64 {
        self.time
    }

    /// What has fallen so far: the bound of [`SnowSim::check`].
    pub fn fallen(&self) -> Fallen {
        self.fallen
    }

    /// The meshes snow is kept on (0 before the first step).
    pub fn mesh_count(&self) -> usize {
        self.meshes.len()
    }

    /// Snow depth per vertex of mesh `m` (empty before its first step).
    pub fn mesh_depth(&self, m: usize) -> &[f32] {
        self.meshes.get(m).map_or(&[], |d| d)
    }

    pub fn ground(&self) -> Option<&GroundSnow> {
        self.ground.as_ref()
    }

    /// The arrival counts of the last step, per receiver (mesh vertices, then ground cells).
    pub fn arrival(&self) -> Option<&Arrival> {
        self.arrival.as_ref()
    }

    /// Sets the bare ground snow lies on: the first call starts with no snow; later calls
    /// replace the ground under the snow (a `Ground` node deformed it) and must keep its
    /// cells.
    pub fn set_ground(&mut self, base: &HeightField) -> Result<()> {
        base.validate()?;
        match &mut self.ground {
            None => self.ground = Some(GroundSnow::new(base)),
            Some(g) => {
                if (g.base.dims, g.base.cell, g.base.origin) != (base.dims, base.cell, base.origin)
                {
                    return Err(Error::Invalid(format!(
                        "snow: the ground changed its cells ({} x {} of {} at {} before, {} x {} \
                         of {} at {} now); snow is kept per cell, so the ground's grid must stay",
                        g.base.dims.x,
                        g.base.dims.y,
                        g.base.cell,
                        g.base.origin,
                        base.dims.x,
                        base.dims.y,
                        base.cell,
                        base.origin
                    )));
                }
                g.base.heights.clone_from(&base.heights);
            }
        }
        Ok(())
    }

    /// One step of `dt` seconds on the CPU: arrival, deposit, stabilisation.
    pub fn step(
        &mut self,
        meshes: &[&Mesh],
        ground: Option<&HeightField>,
        dt: f32,
    ) -> Result<SnowStep> {
        self.step_with(meshes, ground, dt, rasterize_depth_with)
    }

    /// [`Self::step`] with the depth maps from any rasteriser with the signature of
    /// `imprint_core::raster::rasterize_depth_with` (the GPU one is a closure over its
    /// context).
    pub fn step_with(
        &mut self,
        meshes: &[&Mesh],
        ground: Option<&HeightField>,
        dt: f32,
        rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
    ) -> Result<SnowStep> {
        let mut scratch = std::mem::take(&mut self.scratch);
        let step = self.step_with_parts(
            meshes,
            ground,
            dt,
            |occluder, receivers, directions, params| {
                arrival_with(occluder, receivers, directions, params, rasterize)
            },
            |g, tan, units, passes| Ok(relax::relax(g, tan, units, passes, &mut scratch)),
        );
        self.scratch = scratch;
        step
    }

    /// [`Self::step_with`] with the parts given: `arrival` counts the receivers reached (the
    /// contract of [`arrival_with`]; e.g. the GPU's `super::gpu::GpuSnowArrival`), `relax`
    /// stabilises the ground's snow as in [`Self::relax_with`] (e.g. the GPU's
    /// `super::gpu::GpuSnowRelax::relaxer`). The deposit stays here.
    pub fn step_with_parts(
        &mut self,
        meshes: &[&Mesh],
        ground: Option<&HeightField>,
        dt: f32,
        arrival: impl FnOnce(&Mesh, &Receivers, &[Vec3], &SnowParams) -> Result<Arrival>,
        relax: impl FnMut(&HeightField, f32, &mut Vec<u32>, u32) -> Result<RelaxReport>,
    ) -> Result<SnowStep> {
        if !(dt.is_finite() && dt >= 0.0) {
            return Err(Error::Invalid(format!(
                "snow: step duration {dt} must be a finite number >= 0"
            )));
        }
        self.sync_meshes(meshes)?;
        match ground {
            Some(g) => self.set_ground(g)?,
            None if self.ground.is_some() => {
                return Err(Error::Invalid(
                    "snow: the ground was given before and is missing now".into(),
                ));
            }
            None => {}
        }
        let surface = self.ground.as_ref().map(GroundSnow::surface);
        let (occluder, receivers) = gather(meshes, surface.as_ref());
        let arrival = arrival(&occluder, &receivers, &self.directions, &self.params)?;
        if arrival.counts.len() != receivers.points.len() || arrival.directions == 0 {
            return Err(Error::Invalid(format!(
                "snow: the arrival gave {} counts over {} directions for {} receivers",
                arrival.counts.len(),
                arrival.directions,
                receivers.points.len()
            )));
        }

        let fall = self.params.fall();
        let gain = self.params.rate * dt;
        let prob = |i: usize| arrival.probability(i);
        for (m, depth) in self.meshes.iter_mut().enumerate() {
            let range = receivers.mesh(m);
            let normals = &receivers.normals[range.clone()];
            depth
                .par_iter_mut()
                .zip(normals)
                .enumerate()
                .for_each(|(v, (d, n))| {
                    *d += gain * prob(range.start + v) * (-n.dot(fall)).max(0.0);
                });
        }
        if let Some(g) = &mut self.ground {
            let before = g.total_quanta();
            let start = receivers.ground().start;
            let normals = &receivers.normals[start..];
            let overflow = g
                .units
                .par_iter_mut()
                .zip(g.residual.par_iter_mut())
                .zip(normals)
                .enumerate()
                .map(|(c, ((units, residual), n))| {
                    // The layer gain·P·cos φ measured vertically: divided by n_y (> 0 on a
                    // height field's lattice).
                    let column = gain * prob(start + c) * (-n.dot(fall)).max(0.0) / n.y;
                    let q = *residual + column / QUANTUM;
                    let whole = q.floor();
                    let total = *units as f64 + whole as f64;
                    if total > MAX_CELL_UNITS as f64 {
                        return true;
                    }
                    *units = total as u32;
                    *residual = q - whole;
                    false
                })
                .reduce(|| false, |a, b| a || b);
            if overflow {
                return Err(Error::Run(format!(
                    "snow: a ground cell would hold more than {} m of snow; lower rate ({}) or \
                     the number of steps",
                    MAX_CELL_UNITS as f64 * QUANTUM as f64,
                    self.params.rate
                )));
            }
            self.fallen.ground_quanta += g.total_quanta() - before;
        }
        // As the deposit sums a vertex's depth: in f32, the largest gain a step can give.
        self.fallen.depth += gain;
        self.fallen.steps += 1;
        let reached = arrival.counts.iter().filter(|&&c| c > 0).count();
        let directions = arrival.directions;
        self.arrival = Some(arrival);
        self.time += dt as f64;
        let relax = self.relax_with(self.params.relax_passes, relax)?;
        Ok(SnowStep {
            directions,
            reached,
            relax,
        })
    }

    /// Runs up to `passes` stabilisation passes on the ground's snow (none without a ground,
    /// or with `repose_degrees` = 90); stops at the first pass that moves nothing.
    pub fn relax(&mut self, passes: u32) -> RelaxReport {
        match (&mut self.ground, self.params.tan_repose()) {
            (Some(g), Some(tan)) => {
                relax::relax(&g.base, tan, &mut g.units, passes, &mut self.scratch)
            }
            _ => RelaxReport::default(),
        }
    }

    /// [`Self::relax`] done by `relax`, called as `relax(bare ground, tan θ, units, passes)`
    /// with the contract of [`relax::relax`] (e.g. the GPU's
    /// `super::gpu::GpuSnowRelax::relaxer`, which leaves the same quanta to the bit).
    pub fn relax_with(
        &mut self,
        passes: u32,
        mut relax: impl FnMut(&HeightField, f32, &mut Vec<u32>, u32) -> Result<RelaxReport>,
    ) -> Result<RelaxReport> {
        match (&mut self.ground, self.params.tan_repose()) {
            (Some(g), Some(tan)) => relax(&g.base, tan, &mut g.units, passes),
            _ => Ok(RelaxReport::default()),
        }
    }

    /// Pours `volume` m³ of snow onto ground cell `cell` (rounded to whole quanta); returns
    /// the quanta added (counted as fallen). Needs a ground ([`Self::set_ground`] or a step).
    pub fn pour(&mut self, cell: UVec2, volume: f64) -> Result<u32> {
        let g = self
            .ground
            .as_mut()
            .ok_or_else(|| Error::Invalid("snow: pour needs a ground; set one first".into()))?;
        if cell.x >= g.base.dims.x || cell.y >= g.base.dims.y {
            return Err(Error::Invalid(format!(
                "snow: pour cell {cell} is outside the {} x {} ground",
                g.base.dims.x, g.base.dims.y
            )));
        }
        let area = g.base.cell as f64 * g.base.cell as f64;
        let q = (volume / area / QUANTUM as f64).round();
        let c = g.base.index(cell.x, cell.y);
        let total = g.units[c] as f64 + q;
        if !(q >= 0.0 && total <= MAX_CELL_UNITS as f64) {
            return Err(Error::Invalid(format!(
                "snow: pour volume {volume} m³ must be >= 0 and leave at most {} m of snow in \
                 the cell",
                MAX_CELL_UNITS as f64 * QUANTUM as f64
            )));
        }
        g.units[c] = total as u32;
        // Snow put there counts as fallen for [`SnowSim::check`].
        self.fallen.ground_quanta += q;
        Ok(q as u32)
    }

    /// The covered scene: per mesh its depths and displaced mesh (`meshes` are the meshes of
    /// the last step, in order), and the ground with its snow.
    pub fn cover(&self, meshes: &[&Mesh]) -> Result<SnowCover> {
        self.check_meshes(meshes)?;
        let meshes = meshes
            .iter()
            .enumerate()
            .map(|(m, mesh)| MeshSnow {
                depth: self.mesh_depth(m).to_vec(),
                mesh: self.displaced(m, mesh),
            })
            .collect();
        let ground = self.ground.as_ref().map(|g| {
            let mut thickness = g.base.clone();
            thickness.heights = g.thickness();
            GroundCover {
                surface: g.surface(),
                thickness,
            }
        });
        Ok(SnowCover { meshes, ground })
    }

    /// Mesh `m` with its vertices moved along their normals by `displacement × depth`.
    pub fn displaced(&self, m: usize, mesh: &Mesh) -> Mesh {
        let depth = self.mesh_depth(m);
        let normals = vertex_normals(mesh);
        let s = self.params.displacement;
        let mut out = mesh.clone();
        for (v, p) in out.positions.iter_mut().enumerate() {
            *p += normals[v] * (s * depth.get(v).copied().unwrap_or(0.0));
        }
        out.compute_normals();
        out
    }

    /// Allocates the per-vertex depths on the first step; later steps must bring the same
    /// meshes (counts of meshes and vertices).
    fn sync_meshes(&mut self, meshes: &[&Mesh]) -> Result<()> {
        if self.arrival.is_none() {
            self.meshes = meshes
                .iter()
                .map(|m| vec![0.0; m.positions.len()])
                .collect();
            return Ok(());
        }
        self.check_meshes(meshes)
    }

    fn check_meshes(&self, meshes: &[&Mesh]) -> Result<()> {
        if meshes.len() != self.meshes.len() {
            return Err(Error::Invalid(format!(
                "snow: {} meshes given, {} before; snow is kept per vertex, so the scene's \
                 meshes must stay",
                meshes.len(),
                self.meshes.len()
            )));
        }
        for (m, (mesh, depth)) in meshes.iter().zip(&self.meshes).enumerate() {
            if mesh.positions.len() != depth.len() {
                return Err(Error::Invalid(format!(
                    "snow: mesh {m} has {} vertices, {} before; snow is kept per vertex",
                    mesh.positions.len(),
                    depth.len()
                )));
            }
        }
        Ok(())
    }
}
