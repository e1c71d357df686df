//! The CPU cloth simulator: H's mass-spring cloth (or Tokoi's material) integrated by damped
//! position Verlet (H eq. 10) in substeps, pushed by the bodies' distance fields.
//!
//! Each substep computes every particle's next position from the current and previous
//! positions only (a gather over its own springs, hinges and faces), in parallel chunks, and
//! then rotates the three position buffers. Nothing a particle computes depends on which
//! thread runs it or how the work is split, and every sum (energies, counts) is taken per
//! fixed-size chunk and then over chunks in order, so a run gives the same bytes on 1 or
//! 16 threads. Between frames the particles are flat `Vec4`s (w the inverse mass) and the
//! springs CSR lists, the layout the GPU path binds; within a frame the positions are kept by
//! axis and stepped eight particles at a time ([`super::lanes`], [`super::contact_lanes`]),
//! the same bits as one particle at a time.

use super::contact::{self, Collider, Hit};
use super::contact_lanes::{self, Fields, Touch};
use super::lanes::{
    Blocks, ForcesFn, LANES, Lane, Lanes, bool_bits, lane_bits, lane_vec, lanes_of, mask, select,
};
use super::metrics::{ClothFrameMetrics, Energy, GpuClothFrameMetrics};
use super::params::{ClothParams, Material, Shape};
use super::sampler::{Corners, FieldView};
use super::shape::ClothShape;
use super::side::{SideLanes, SideMemory};
use super::springs::{
    Faces, Hinges, LinkQuad, Links, SpringLaw, enumerate_springs, hinge_angle_gradient,
    hinge_energy, hinge_slope, spring_constants,
};
use super::stability::{self, BandMisses, StabilityEstimate};
use super::texture::AnisotropyMap;
use crate::drape::DepthCollider;
use glam::{Mat4, Vec3, Vec4};
use imprint_core::{DistanceField, Error, Mesh, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
use std::path::Path;

/// Particles per parallel task (and per partial sum). Fixed, so sums do not depend on the
/// number of threads; whole blocks of [`LANES`].
const CHUNK: usize = 256;
const _: () = assert!(CHUNK.is_multiple_of(LANES));

/// Lengths below this count as zero when normalising a spring (coincident particles).
const TINY: f32 = 1e-20;

/// Positions of the current and previous substep; `w` is the inverse mass (0 = pinned).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClothState {
    pub pos: Vec<Vec4>,
    pub prev: Vec<Vec4>,
}

/// A body the cloth collides with over one frame (see [`ClothSim::step_frame_between`]).
#[derive(Clone, Copy, Debug)]
pub struct Body<'a> {
    pub start: Option<&'a DistanceField>,
    pub end: &'a DistanceField,
    /// The weight of `end` at the frame's start and at its end.
    pub span: (f32, f32),
}

/// Files a cloth reads: the garment mesh and the anisotropy texture (load them with
/// [`ClothAssets::load`], or build them in memory).
#[derive(Clone, Debug, Default)]
pub struct ClothAssets {
    pub mesh: Option<Mesh>,
    pub anisotropy: Option<AnisotropyMap>,
}

impl ClothAssets {
    /// Reads what `params` names, paths relative to `base_dir`.
    pub fn load(params: &ClothParams, base_dir: &Path) -> Result<Self> {
        let mesh = match &params.shape {
            Shape::Mesh { path } => Some(imprint_core::load_mesh(&base_dir.join(path))?),
            Shape::Grid { .. } => None,
        };
        let anisotropy = match &params.material {
            Material::Tokoi {
                anisotropy: Some(a),
                ..
            } => Some(AnisotropyMap::load(&base_dir.join(&a.texture), a.scale)?),
            _ => None,
        };
        Ok(ClothAssets { mesh, anisotropy })
    }
}

/// Per-chunk results of one substep, reduced in chunk order.
#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
struct SubstepStats {
    kinetic: f64,
    contacts: u32,
    inside: u32,
    max_depth: f32,
    max_accel: f32,
    band_misses: u32,
    /// First particle with a non-finite position, or u32::MAX.
    nonfinite: u32,
    /// First particle with a spring beyond `limits.max_stretch`, or u32::MAX.
    overstretched: u32,
}

impl SubstepStats {
    fn new() -> Self {
        SubstepStats {
            nonfinite: u32::MAX,
            overstretched: u32::MAX,
            ..Default::default()
        }
    }

    fn merge(&mut self, o: &SubstepStats) {
        self.kinetic += o.kinetic;
        self.contacts += o.contacts;
        self.inside += o.inside;
        self.max_depth = self.max_depth.max(o.max_depth);
        self.max_accel = self.max_accel.max(o.max_accel);
        self.band_misses += o.band_misses;
        self.nonfinite = self.nonfinite.min(o.nonfinite);
        self.overstretched = self.overstretched.min(o.overstretched);
    }
}

/// The springs as the frame pass reads them: by blocks, at the positions of the frame's end
/// and of the substep before, in lanes.
#[derive(Clone, Copy)]
struct SpringsAt<'a> {
    blocks: &'a Blocks,
    pos: &'a Lanes,
    prev: &'a Lanes,
}

/// What the pass after a frame sums (see `ClothSim::frame_pass`).
#[derive(Clone, Copy, Debug, Default)]
struct FramePass {
    energy: Energy,
    close: u32,
    close_depth: f32,
    strain: f32,
}

/// Everything a particle's update reads, for one substep.
struct Substep<'a> {
    /// The springs by blocks of eight particles, and the build of their forces this
    /// processor runs ([`Blocks::forces_fn`]).
    blocks: &'a Blocks,
    forces: ForcesFn,
    /// The positions at the substep's start and the substep before, and the inverse masses
    /// (padded to whole blocks).
    at: &'a Lanes,
    prev: &'a Lanes,
    inv_mass: &'a [f32],
    /// Per particle, whether it moves freely (not pinned), padded with `false` to whole
    /// blocks: a block's lanes are then one load.
    free: &'a [bool],
    /// The particles (the rest of the last block is padding).
    n: usize,
    hinges: &'a Hinges,
    faces: &'a Faces,
    pin_slot: &'a [u32],
    pin_from: &'a [Vec3],
    pin_to: &'a [Vec3],
    colliders: &'a [Collider<'a>],
    /// Bodies read through depth maps, applied after the fields.
    depth: &'a [DepthCollider<'a>],
    /// Fraction of the frame at this substep's end (H §5.3's j/n).
    s: f32,
    dt: f32,
    /// dt / (previous substep's dt): scales the Verlet velocity term when dt changes.
    ratio: f32,
    damping: f32,
    gravity: Vec3,
    wind: Option<(Vec3, f32)>,
    eps: f32,
    friction: f32,
    ground: Option<f32>,
    max_stretch: f32,
}

/// A cloth and its state between frames. Serde writes all of it (a checkpoint: loaded, it
/// steps on to the same bytes as a sim that never stopped).
#[derive(Serialize, Deserialize)]
pub struct ClothSim {
    /// In RON text inside binary checkpoints (its optional fields need a self-describing
    /// format, see [`crate::checkpoint`]).
    #[serde(with = "crate::checkpoint::ron_text")]
    params: ClothParams,
    node: String,
    shape: ClothShape,
    links: Links,
    /// `links` by blocks of eight particles, rebuilt from them after loading.
    #[serde(skip)]
    blocks: Blocks,
    /// Within a frame, the positions, previous and next positions by axis (structure of
    /// arrays), and the inverse masses: the substeps work on these, and `state` takes them
    /// back when the frame succeeds.
    #[serde(skip)]
    lanes: Lanes,
    #[serde(skip)]
    lanes_prev: Lanes,
    #[serde(skip)]
    lanes_next: Lanes,
    #[serde(skip)]
    inv_mass: Vec<f32>,
    #[serde(skip)]
    free: Vec<bool>,
    hinges: Hinges,
    faces: Faces,
    pinned: Vec<u32>,
    /// Per particle: its index in `pinned`, or u32::MAX.
    pin_slot: Vec<u32>,
    pin_from: Vec<Vec3>,
    pin_to: Vec<Vec3>,
    /// The state at the start of the frame being stepped until it succeeds (the substeps
    /// work on the lanes).
    state: ClothState,
    /// The side memory at the frame's start, restored when the frame fails.
    backup_side: SideMemory,
    /// Per particle and collider: outward direction at the last sample (see `contact`).
    side: SideMemory,
    /// Per block of [`LANES`] particles and collider, the cells its end fields (`[0]`) and
    /// start fields (`[1]`) were last read at (kept through a frame's substeps, whose fields
    /// do not change, and read again by the frame pass after them). Apart, not in pairs: a
    /// body that does not move reads only the end fields, which then stream through the
    /// caches without the start's unread half between them.
    #[serde(skip)]
    corners: [Vec<Corners>; 2],
    stats: Vec<SubstepStats>,
    dt_prev: Option<f32>,
    first_energy: Option<f64>,
    /// The kinetic energy of the last substep as a GPU cloth measured it, when the last
    /// frame was a GPU frame taken in by `adopt_gpu_frame*` (None after a CPU frame or
    /// [`ClothSim::set_positions`]): what a [`GpuCloth`] made from this sim limits its next
    /// frame's energy growth by.
    ///
    /// [`GpuCloth`]: super::gpu::GpuCloth
    gpu_kinetic: Option<f64>,
    stability: StabilityEstimate,
    /// Diagonal of the rest shape's bounding box (for the energy scale).
    extent: f32,
}

impl ClothSim {
    /// Validates `params`, reads its files (relative to `base_dir`) and builds the cloth at rest.
    pub fn new(params: &ClothParams, base_dir: &Path) -> Result<Self> {
        params.validate()?;
        Self::from_assets(params, &ClothAssets::load(params, base_dir)?)
    }

    /// Builds the cloth from assets already in memory.
    pub fn from_assets(params: &ClothParams, assets: &ClothAssets) -> Result<Self> {
        params.validate()?;
        let shape = ClothShape::build(&params.shape, assets.mesh.as_ref())?;
        let n = shape.len();
        if let Material::Tokoi {
            anisotropy: Some(_),
            ..
        } = &params.material
        {
            if assets.anisotropy.is_none() {
                return Err(Error::Invalid(
                    "cloth: material.anisotropy names a texture that was not loaded".into(),
                ));
            }
            if shape.corner_uvs.is_none() {
                return Err(Error::Invalid(
                    "cloth: material.anisotropy needs UVs, and the garment mesh has none".into(),
                ));
            }
        }
        let with_bend = matches!(
            params.material,
            Material::Harada {
                k_bend: Some(_),
                ..
            }
        );
        let springs = enumerate_springs(&shape, with_bend);
        let (law, k) = spring_constants(
            &springs,
            &shape.rest,
            &params.material,
            params.stiffness_mode,
            assets.anisotropy.as_ref(),
        );
        let links = Links::build(n, &springs, &k, law, &shape.rest);
        let hinges = match params.material {
            Material::Tokoi { bend_c, .. } if bend_c > 0.0 => {
                Hinges::build(n, &shape.triangles, &shape.rest, bend_c)
            }
            _ => Hinges::build(n, &[], &[], 0.0),
        };
        let faces = Faces::build(n, &shape.triangles);
        let pinned = shape.resolve_pins(&params.pins)?;
        let mut pin_slot = vec![u32::MAX; n];
        for (k, &p) in pinned.iter().enumerate() {
            pin_slot[p as usize] = k as u32;
        }
        let inv_mass = 1.0 / params.mass;
        let pos: Vec<Vec4> = shape
            .rest
            .iter()
            .zip(&pin_slot)
            .map(|(p, &slot)| p.extend(if slot == u32::MAX { inv_mass } else { 0.0 }))
            .collect();
        let targets: Vec<Vec3> = pinned.iter().map(|&p| shape.rest[p as usize]).collect();
        let is_pinned: Vec<bool> = pin_slot.iter().map(|&s| s != u32::MAX).collect();
        let stability = stability::estimate(
            &links,
            &hinges,
            &shape.rest,
            &is_pinned,
            params.mass,
            params.damping,
        );
        let (lo, hi) = shape.rest.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        Ok(ClothSim {
            params: params.clone(),
            node: "cloth".into(),
            blocks: Blocks::build(&links, n),
            lanes: Lanes::default(),
            lanes_prev: Lanes::default(),
            lanes_next: Lanes::default(),
            inv_mass: Vec::new(),
            free: Vec::new(),
            links,
            hinges,
            faces,
            pinned,
            pin_slot,
            pin_from: targets.clone(),
            pin_to: targets,
            state: ClothState {
                prev: pos.clone(),
                pos,
            },
            side: SideMemory::new(n, 0),
            backup_side: SideMemory::default(),
            corners: Default::default(),
            stats: vec![SubstepStats::new(); n.div_ceil(CHUNK)],
            dt_prev: None,
            first_energy: None,
            gpu_kinetic: None,
            stability,
            extent: (hi - lo).length(),
            shape,
        })
    }

    /// The node name used in errors (default "cloth").
    pub fn with_name(mut self, node: impl Into<String>) -> Self {
        self.node = node.into();
        self
    }

    pub fn params(&self) -> &ClothParams {
        &self.params
    }

    pub fn shape(&self) -> &ClothShape {
        &self.shape
    }

    pub fn links(&self) -> &Links {
        &self.links
    }

    pub fn hinges(&self) -> &Hinges {
        &self.hinges
    }

    pub fn state(&self) -> &ClothState {
        &self.state
    }

    pub fn len(&self) -> usize {
        self.shape.len()
    }

    pub fn is_empty(&self) -> bool {
        self.shape.is_empty()
    }

    /// Current particle positions.
    pub fn positions(&self) -> Vec<Vec3> {
        self.state.pos.iter().map(|p| p.truncate()).collect()
    }

    /// The pinned particles, in the order [`ClothSim::set_pin_targets`] takes targets.
    pub fn pinned(&self) -> &[u32] {
        &self.pinned
    }

    /// The stability estimate made at construction ([`StabilityEstimate::substeps_for`] says
    /// how many substeps a frame needs).
    pub fn stability(&self) -> &StabilityEstimate {
        &self.stability
    }

    /// The node name used in errors (see [`ClothSim::with_name`]).
    pub fn name(&self) -> &str {
        &self.node
    }

    /// The pins' targets at the start and at the end of the next frame (one per
    /// [`ClothSim::pinned`] particle): after a frame both are where it left the pins, until
    /// [`ClothSim::set_pin_targets`] moves the end.
    pub fn pin_endpoints(&self) -> (&[Vec3], &[Vec3]) {
        (&self.pin_from, &self.pin_to)
    }

    /// The contacts' side memory (per particle, one entry per collider of the last frame,
    /// at least one, particle-major) and the number of colliders it is laid out for (0
    /// before any frame).
    pub fn side_memory(&self) -> (Vec<Vec4>, usize) {
        (self.side.to_vec4s(self.len()), self.side.colliders())
    }

    /// The last substep's length, s (None before the first frame): the next substep scales
    /// the Verlet velocity term by dt / this when its own dt differs.
    pub fn dt_prev(&self) -> Option<f32> {
        self.dt_prev
    }

    /// The kinetic energy of the last substep as the GPU cloth measures it, J: ½ m Σ |x −
    /// x_prev|² / dt² over the free particles, each square in f32 and the sum in f64. After
    /// a GPU frame taken in by [`ClothSim::adopt_gpu_frame`] or
    /// [`ClothSim::adopt_gpu_frame_resident`] it is the GPU's own figure (to the bit);
    /// otherwise it is computed here from the state (0 before the first frame).
    pub fn last_substep_kinetic(&self) -> f64 {
        if let Some(ke) = self.gpu_kinetic {
            return ke;
        }
        let Some(dt) = self.dt_prev else { return 0.0 };
        let mut step2 = 0.0f64;
        for (p, q) in self.state.pos.iter().zip(&self.state.prev) {
            if p.w > 0.0 {
                step2 += (*p - *q).truncate().length_squared() as f64;
            }
        }
        step2 * 0.5 * self.params.mass as f64 / (dt as f64 * dt as f64)
    }

    /// Places the cloth at `positions`, at rest (previous = current), and makes the pinned
    /// particles' targets their new positions.
    pub fn set_positions(&mut self, positions: &[Vec3]) -> Result<()> {
        if positions.len() != self.len() {
            return Err(Error::Invalid(format!(
                "cloth: {} positions for {} particles",
                positions.len(),
                self.len()
            )));
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::Invalid(format!(
                "cloth: position of particle {i} is not finite"
            )));
        }
        for (s, p) in self.state.pos.iter_mut().zip(positions) {
            *s = p.extend(s.w);
        }
        self.state.prev.clone_from(&self.state.pos);
        for (k, &p) in self.pinned.iter().enumerate() {
            self.pin_from[k] = positions[p as usize];
            self.pin_to[k] = positions[p as usize];
        }
        self.side.clear();
        self.first_energy = None;
        self.gpu_kinetic = None;
        Ok(())
    }

    /// Where the pinned particles must be at the end of the next frame (one per
    /// [`ClothSim::pinned`] particle, e.g. the skinned positions of the body they hang on);
    /// they move there linearly over the frame's substeps, and are exactly there at its end.
    pub fn set_pin_targets(&mut self, targets: &[Vec3]) -> Result<()> {
        if targets.len() != self.pinned.len() {
            return Err(Error::Invalid(format!(
                "cloth: {} pin targets for {} pinned particles",
                targets.len(),
                self.pinned.len()
            )));
        }
        if let Some(i) = targets.iter().position(|p| !p.is_finite()) {
            return Err(Error::Invalid(format!(
                "cloth: pin target {i} is not finite"
            )));
        }
        self.pin_to.copy_from_slice(targets);
        Ok(())
    }

    /// Advances one body frame of `dt_frame` seconds in `params.substeps` substeps.
    ///
    /// `fields_end` are the colliders at the frame's end, applied in order; `fields_start`
    /// the same colliders at its start (used when `blend_fields` is on; pass `&[]` on the
    /// first frame or to use the end fields throughout). On a numerical failure the cloth is
    /// put back where it was at the frame's start and `Error::Numerical` names the frame, the
    /// substep and what to change.
    pub fn step_frame(
        &mut self,
        fields_start: &[&DistanceField],
        fields_end: &[&DistanceField],
        frame: u32,
        dt_frame: f32,
    ) -> Result<ClothFrameMetrics> {
        let blend = self
            .params
            .frame_blend(dt_frame, fields_start.len(), fields_end.len())?;
        let bodies: Vec<Body> = fields_end
            .iter()
            .enumerate()
            .map(|(k, &end)| Body {
                start: blend.then(|| fields_start[k]),
                end,
                span: (0.0, 1.0),
            })
            .collect();
        self.step_frame_between(&bodies, &[], frame, dt_frame)
    }

    /// [`ClothSim::step_frame`] with each body given as two fields and the part of the time
    /// between them that this frame covers (a field node that builds every k frames and
    /// interpolates gives its two builds around the frame, and the frame's span of the
    /// blend). `start: None` reads `end` throughout; so does `blend_fields: false`.
    ///
    /// `depth` are bodies read through depth maps ([`crate::drape::collider`]), applied after
    /// the fields each substep; their maps must be dilated by this cloth's ε.
    pub fn step_frame_between(
        &mut self,
        bodies: &[Body],
        depth: &[DepthCollider],
        frame: u32,
        dt_frame: f32,
    ) -> Result<ClothFrameMetrics> {
        self.params.frame_blend(dt_frame, 0, bodies.len())?;
        for b in bodies {
            self.params.check_band(b.end.far_value(), b.end.band)?;
            if let Some(f) = b.start.filter(|_| self.params.blend_fields) {
                self.params.check_band(f.far_value(), f.band)?;
            }
            let (s0, s1) = b.span;
            if !(s0.is_finite()
                && s1.is_finite()
                && (0.0..=1.0).contains(&s0)
                && s0 <= s1
                && s1 <= 1.0)
            {
                return Err(Error::Invalid(format!(
                    "cloth: a body's span ({s0}, {s1}) must satisfy 0 <= start <= end <= 1"
                )));
            }
        }
        let eps = self.params.collision.epsilon;
        if let Some(d) = depth.iter().find(|d| d.eps() != eps) {
            return Err(Error::Invalid(format!(
                "cloth: a depth collider dilated by {} for a cloth with epsilon {eps}; build its \
                 camera with the cloth's epsilon",
                d.eps()
            )));
        }
        let nf = bodies.len();
        if nf != self.side.colliders() {
            self.side = SideMemory::new(self.len(), nf);
        }
        let colliders: Vec<Collider> = bodies
            .iter()
            .map(|b| Collider {
                // A body that did not change (the same field at both ends) needs no blend.
                start: b
                    .start
                    .filter(|&f| self.params.blend_fields && !std::ptr::eq(f, b.end))
                    .map(FieldView::new),
                end: FieldView::new(b.end),
                span: b.span,
            })
            .collect();
        // A parallel pass per substep: from a worker (see `on_workers`).
        imprint_core::pool::on_workers(|| self.run_frame(&colliders, depth, frame, dt_frame))
    }

    /// The substeps of one frame, against colliders ready to sample.
    fn run_frame(
        &mut self,
        colliders: &[Collider],
        depth: &[DepthCollider],
        frame: u32,
        dt_frame: f32,
    ) -> Result<ClothFrameMetrics> {
        let n_sub = self.params.substeps;
        let dt = dt_frame / n_sub as f32;
        self.backup_side.clone_from(&self.side);
        let backup_dt = self.dt_prev;
        let ke_start = self.kinetic_energy(self.dt_prev.unwrap_or(dt));
        let total_mass = self.params.mass as f64 * (self.len() - self.pinned.len()) as f64;
        let wind2 = self
            .params
            .wind
            .map_or(0.0, |w| w.velocity.length_squared());
        let scale = self.extent as f64;
        let energy_scale = total_mass
            * (self.params.gravity.length() as f64 * scale
                + wind2 as f64
                + (scale / dt_frame as f64).powi(2));
        let ke_limit = self.params.limits.energy_growth as f64 * ke_start.max(energy_scale);
        let n = self.len();
        self.sync_lanes();
        self.lanes_next.resize(n);
        self.forget_corners(colliders.len());
        self.inv_mass.clear();
        self.inv_mass.resize(n.div_ceil(LANES) * LANES, 0.0);
        for (w, p) in self.inv_mass.iter_mut().zip(&self.state.pos) {
            *w = p.w;
        }
        self.free.clear();
        self.free
            .extend(self.pin_slot.iter().map(|&s| s == u32::MAX));
        self.free.resize(n.div_ceil(LANES) * LANES, false);

        let mut frame_stats = SubstepStats::new();
        let mut last = SubstepStats::new();
        for j in 0..n_sub {
            let s = if j + 1 == n_sub {
                1.0
            } else {
                (j + 1) as f32 / n_sub as f32
            };
            let sub = self.substep(colliders, depth, s, dt);
            if let Err(what) = self.check(&sub, ke_limit) {
                // `state` still holds the frame's start; the side memory changed in place.
                self.side.clone_from(&self.backup_side);
                self.dt_prev = backup_dt;
                let bands = colliders
                    .iter()
                    .map(|c| (c.end.field.band, c.end.field.spec.cell));
                let misses = BandMisses::of(frame_stats.band_misses + sub.band_misses, bands);
                return Err(self.stability.blow_up(
                    &self.node, "cloth", frame, j, n_sub, dt, dt_frame, &what, misses,
                ));
            }
            // Counts add up over a substep's chunks; over the frame's substeps, `inside` is
            // the largest (particles, not particle-substeps).
            let inside = frame_stats.inside.max(sub.inside);
            frame_stats.merge(&sub);
            frame_stats.inside = inside;
            last = sub;
        }
        for i in 0..n {
            let w = self.inv_mass[i];
            self.state.pos[i] = self.lanes.get(i).extend(w);
            self.state.prev[i] = self.lanes_prev.get(i).extend(w);
        }
        for (k, to) in self.pin_to.iter().enumerate() {
            self.pin_from[k] = *to;
        }
        self.gpu_kinetic = None;
        Ok(self.metrics(frame, dt, colliders, depth, &frame_stats, &last))
    }

    /// The substeps' and the frame pass's views of the state: the springs' blocks built for
    /// this cloth, and the positions and those of the substep before in lanes. A frame
    /// keeps them as it steps; anything else that sets the state calls this before they are
    /// read.
    fn sync_lanes(&mut self) {
        if let Cow::Owned(blocks) = self.current_blocks() {
            self.blocks = blocks;
        }
        self.lanes.set_from(&self.state.pos);
        self.lanes_prev.set_from(&self.state.prev);
    }

    /// The springs' blocks for this cloth: the kept ones, or built anew where they do not
    /// fit it (a checkpoint leaves them empty).
    fn current_blocks(&self) -> Cow<'_, Blocks> {
        match self.blocks.fits(self.len()) {
            true => Cow::Borrowed(&self.blocks),
            false => Cow::Owned(Blocks::build(&self.links, self.len())),
        }
    }

    /// The springs at the lanes' positions (which [`ClothSim::sync_lanes`] or a frame
    /// keeps as the state's).
    fn springs_at(&self) -> SpringsAt<'_> {
        SpringsAt {
            blocks: &self.blocks,
            pos: &self.lanes,
            prev: &self.lanes_prev,
        }
    }

    /// Sizes the held corners for `colliders` (whole chunks of blocks per collider) and drops
    /// what they hold: nothing held from the last frame's fields.
    fn forget_corners(&mut self, colliders: usize) {
        let corners = self.len().div_ceil(CHUNK) * (CHUNK / LANES) * colliders.max(1);
        for held in &mut self.corners {
            held.resize_with(corners, Default::default);
            held.iter_mut().for_each(Corners::forget);
        }
    }

    fn check(&self, sub: &SubstepStats, ke_limit: f64) -> std::result::Result<(), String> {
        if sub.nonfinite != u32::MAX {
            return Err(format!(
                "particle {} reached a non-finite position",
                sub.nonfinite
            ));
        }
        if sub.overstretched != u32::MAX {
            return Err(format!(
                "a spring of particle {} stretched beyond {} times its rest length",
                sub.overstretched, self.params.limits.max_stretch
            ));
        }
        if sub.kinetic.is_nan() || sub.kinetic > ke_limit {
            return Err(format!(
                "kinetic energy {:.3e} J grew beyond the limit {:.3e} J",
                sub.kinetic, ke_limit
            ));
        }
        Ok(())
    }

    /// One substep: every particle's next position, then the buffers rotate.
    fn substep(
        &mut self,
        colliders: &[Collider],
        depth: &[DepthCollider],
        s: f32,
        dt: f32,
    ) -> SubstepStats {
        let ratio = match self.dt_prev {
            Some(p) if p != dt => dt / p,
            _ => 1.0,
        };
        let ctx = Substep {
            blocks: &self.blocks,
            forces: Blocks::forces_fn(),
            at: &self.lanes,
            prev: &self.lanes_prev,
            inv_mass: &self.inv_mass,
            free: &self.free,
            n: self.shape.len(),
            hinges: &self.hinges,
            faces: &self.faces,
            pin_slot: &self.pin_slot,
            pin_from: &self.pin_from,
            pin_to: &self.pin_to,
            colliders,
            depth,
            s,
            dt,
            ratio,
            damping: self.params.damping,
            gravity: self.params.gravity,
            wind: self.params.wind.map(|w| (w.velocity, w.drag)),
            eps: self.params.collision.epsilon,
            friction: self.params.collision.friction,
            ground: self.params.collision.ground,
            max_stretch: self.params.limits.max_stretch,
        };
        let nf = colliders.len().max(1);
        let out = &mut self.lanes_next;
        let [end_corners, start_corners] = &mut self.corners;
        out.x
            .par_chunks_mut(CHUNK)
            .zip(out.y.par_chunks_mut(CHUNK))
            .zip(out.z.par_chunks_mut(CHUNK))
            .zip(self.side.runs_mut(CHUNK / LANES))
            .zip(end_corners.par_chunks_mut(CHUNK / LANES * nf))
            .zip(start_corners.par_chunks_mut(CHUNK / LANES * nf))
            .zip(self.stats.par_iter_mut())
            .enumerate()
            .for_each(|(c, ((((((x, y), z), side), end), start), stats))| {
                let mut st = SubstepStats::new();
                let memory = Memory {
                    side,
                    corners: [end, start],
                };
                update_chunk(c * CHUNK, &ctx, [x, y, z], memory, &mut st);
                *stats = st;
            });
        let mut total = SubstepStats::new();
        for st in &self.stats {
            total.merge(st);
        }
        total.kinetic *= 0.5 * self.params.mass as f64 / (dt as f64 * dt as f64);
        total.max_accel = total.max_accel.sqrt() / (dt * dt);
        std::mem::swap(&mut self.lanes_prev, &mut self.lanes);
        std::mem::swap(&mut self.lanes, &mut self.lanes_next);
        self.dt_prev = Some(dt);
        total
    }

    /// Kinetic energy from the last substep's displacement.
    fn kinetic_energy(&self, dt: f32) -> f64 {
        let m = self.params.mass as f64;
        let mut sum = 0.0;
        for (p, q) in self.state.pos.iter().zip(&self.state.prev) {
            if p.w > 0.0 {
                sum += 0.5 * m * ((*p - *q).truncate() / dt).length_squared() as f64;
            }
        }
        sum
    }

    /// Kinetic and potential energy of the current state. Kinetic from (x - x_prev)/dt, and
    /// the potentials averaged over x and x_prev: the half-step pairing under which Verlet's
    /// energy error is second order, not first.
    pub fn energy(&self) -> Energy {
        let (mut pos, mut prev) = (Lanes::default(), Lanes::default());
        pos.set_from(&self.state.pos);
        prev.set_from(&self.state.prev);
        let blocks = self.current_blocks();
        let springs = SpringsAt {
            blocks: &blocks,
            pos: &pos,
            prev: &prev,
        };
        self.frame_pass(springs, &[], &[], [&mut [], &mut []])
            .energy
    }

    /// One pass over the particles after a frame: energies, the largest strain, and the
    /// particles still closer than ε to a collider (or the ground). Partial sums per fixed
    /// chunk, then over chunks in order, so the result does not depend on the threads.
    /// `end` and `start` are laid out as the substeps' (whole chunks of blocks per collider;
    /// none without colliders) and hold the colliders' cells or nothing ([`Corners`]): after a
    /// frame, the cells its last substep read, which the particles have mostly not left.
    fn frame_pass(
        &self,
        springs: SpringsAt,
        colliders: &[Collider],
        depth: &[DepthCollider],
        [end, start]: [&mut [Corners]; 2],
    ) -> FramePass {
        let chunks = self.len().div_ceil(CHUNK);
        let parts: Vec<FramePass> = if colliders.is_empty() {
            (0..chunks)
                .into_par_iter()
                .map(|c| self.chunk_pass(c, springs, colliders, depth, [&mut [], &mut []]))
                .collect()
        } else {
            let per_chunk = CHUNK / LANES * colliders.len();
            let starts = start[..chunks * per_chunk].par_chunks_mut(per_chunk);
            end[..chunks * per_chunk]
                .par_chunks_mut(per_chunk)
                .zip(starts)
                .enumerate()
                .map(|(c, (end, start))| {
                    self.chunk_pass(c, springs, colliders, depth, [end, start])
                })
                .collect()
        };
        let mut total = FramePass::default();
        for p in &parts {
            total.energy.add(&p.energy);
            total.close += p.close;
            total.close_depth = total.close_depth.max(p.close_depth);
            total.strain = total.strain.max(p.strain);
        }
        total
    }

    /// Chunk `c`'s part of [`ClothSim::frame_pass`], with the chunk's `corners`.
    fn chunk_pass(
        &self,
        c: usize,
        springs: SpringsAt,
        colliders: &[Collider],
        depth: &[DepthCollider],
        corners: [&mut [Corners]; 2],
    ) -> FramePass {
        let mut part = FramePass::default();
        let range = c * CHUNK..((c + 1) * CHUNK).min(self.len());
        let residual = self.residual_contact(range.clone(), colliders, corners);
        for (block, worst) in range.step_by(LANES).zip(residual.chunks(LANES)) {
            let b = block / LANES;
            let (u_pos, strain) = springs.blocks.energy(b, springs.pos, true);
            let (u_prev, _) = springs.blocks.energy(b, springs.prev, false);
            for (m, &worst) in worst.iter().enumerate() {
                let energy = (u_pos[m], u_prev[m], strain[m]);
                self.particle_pass(block + m, energy, worst, depth, &mut part);
            }
        }
        part
    }

    /// Per particle of `range` (one chunk), how far it is inside ε of the colliders (ε minus
    /// the signed distance, the largest over the colliders; −∞ for none), against the
    /// end-of-frame fields: eight particles at a time where the fields are unsigned
    /// ([`contact_lanes`], with the chunk's `corners`), one at a time where not.
    fn residual_contact(
        &self,
        range: std::ops::Range<usize>,
        colliders: &[Collider],
        [end, start]: [&mut [Corners]; 2],
    ) -> Vec<f32> {
        let (pos, eps) = (&self.state.pos, self.params.collision.epsilon);
        let mut worst = vec![f32::NEG_INFINITY; range.len()];
        for (k, c) in colliders.iter().enumerate() {
            if c.end.is_signed() || c.start.is_some_and(|f| f.is_signed()) {
                for (i, worst) in range.clone().zip(&mut worst) {
                    let (x, side) = (pos[i].truncate(), self.side.get(i, k));
                    if let Some(s) = contact::signed_sample(c, x, x, 1.0, side, eps) {
                        *worst = worst.max(eps - s.distance);
                    }
                }
                continue;
            }
            let w = c.weight(1.0);
            let nf = colliders.len();
            let fields = Fields {
                end: &c.end,
                start: c.start.as_ref().filter(|_| w < 1.0).map(|f| (f, w)),
            };
            for (b, worst) in range.clone().step_by(LANES).zip(worst.chunks_mut(LANES)) {
                // Lanes past the range repeat its first particle (their answers unused).
                let mut x = [[0.0f32; LANES]; 3];
                // A lane indexes the positions by axis and picks the particle.
                #[allow(clippy::needless_range_loop)]
                for m in 0..LANES {
                    let i = if m < worst.len() { b + m } else { b };
                    (0..3).for_each(|a| x[a][m] = pos[i][a]);
                }
                let side = self.side.block(b / LANES, k);
                let i = (b - range.start) / LANES * nf + k;
                let corners = [&mut end[i], &mut start[i]];
                let found = contact_lanes::resting(fields, &x, side, eps, corners);
                for (worst, d) in worst.iter_mut().zip(found) {
                    if let Some(d) = d {
                        *worst = worst.max(eps - d);
                    }
                }
            }
        }
        worst
    }

    /// One particle's part of [`ClothSim::frame_pass`]: `(u_pos, u_prev, strain)` its
    /// springs' half energy at the frame's end and a substep before, and their largest
    /// strain ([`Blocks::energy`]); `worst` its [`ClothSim::residual_contact`].
    fn particle_pass(
        &self,
        i: usize,
        (u_pos, u_prev, strain): (f32, f32, f32),
        mut worst: f32,
        depth: &[DepthCollider],
        part: &mut FramePass,
    ) {
        let (pos, prev) = (&self.state.pos, &self.state.prev);
        part.energy.springs += 0.5 * (u_pos + u_prev) as f64;
        part.strain = part.strain.max(strain);
        let h = &self.hinges;
        for &r in &h.refs[h.offsets[i] as usize..h.offsets[i + 1] as usize] {
            let hinge = &h.hinges[(r / 4) as usize];
            for x in [pos, prev] {
                if let Some((theta, _)) =
                    hinge_angle_gradient(hinge.v.map(|v| x[v as usize].truncate()))
                {
                    // A quarter per role, half per time level.
                    part.energy.bending +=
                        0.125 * hinge_energy(hinge.c, theta - hinge.rest_angle) as f64;
                }
            }
        }
        if pos[i].w == 0.0 {
            return;
        }
        let m = self.params.mass as f64;
        let dt = self.dt_prev.unwrap_or(1.0);
        let x = pos[i].truncate();
        part.energy.kinetic += 0.5 * m * ((x - prev[i].truncate()) / dt).length_squared() as f64;
        let mid = 0.5 * (x + prev[i].truncate());
        part.energy.gravity -= m * self.params.gravity.dot(mid) as f64;
        // Residual contact, against the end-of-frame fields (the colliders' part in `worst`).
        let eps = self.params.collision.epsilon;
        for d in depth {
            if let Some(s) = d.sample(x, 2.0 * eps, 1.0) {
                worst = worst.max(eps - s.distance);
            }
        }
        if let Some(h) = self.params.collision.ground {
            worst = worst.max(h + eps - x.y);
        }
        if worst > 0.0 {
            part.close += 1;
            part.close_depth = part.close_depth.max(worst);
        }
    }

    /// Internal forces (springs and bending) on each particle at the current positions: zero
    /// at rest, whatever rigid motion the cloth has made.
    pub fn forces(&self) -> Vec<Vec3> {
        let pos = &self.state.pos;
        (0..self.len())
            .map(|i| {
                let (f, _) = match self.links.law {
                    SpringLaw::Linear => spring_force::<false>(i, &self.links, pos, f32::INFINITY),
                    SpringLaw::Quadratic => {
                        spring_force::<true>(i, &self.links, pos, f32::INFINITY)
                    }
                };
                f + hinge_force(i, &self.hinges, |j| pos[j].truncate())
            })
            .collect()
    }

    /// The frame's metrics; the frame pass reads the colliders through `self.corners`, which
    /// must hold their cells or nothing.
    fn metrics(
        &mut self,
        frame: u32,
        dt: f32,
        colliders: &[Collider],
        depth: &[DepthCollider],
        frame_stats: &SubstepStats,
        last: &SubstepStats,
    ) -> ClothFrameMetrics {
        let mut corners = std::mem::take(&mut self.corners);
        let held = corners.each_mut().map(|c| c.as_mut_slice());
        let pass = self.frame_pass(self.springs_at(), colliders, depth, held);
        self.corners = corners;
        let total = pass.energy.total();
        let first = *self.first_energy.get_or_insert(total);
        ClothFrameMetrics {
            frame,
            substeps: self.params.substeps,
            dt_substep: dt,
            max_strain: pass.strain,
            contacts: last.contacts,
            inside: frame_stats.inside,
            max_depth: frame_stats.max_depth,
            close: pass.close,
            close_max_depth: pass.close_depth,
            max_accel: frame_stats.max_accel,
            band_misses: frame_stats.band_misses,
            kinetic: pass.energy.kinetic,
            energy: pass.energy,
            energy_drift: total - first,
            energy_drift_rel: if first != 0.0 {
                (total - first) / first.abs()
            } else {
                0.0
            },
        }
    }

    /// Completes a GPU cloth's frame: takes the state it reached and its contacts' side
    /// memory (read back once per frame) as this simulator's own, and adds to the GPU's
    /// counts what the CPU measures after a frame (strain, particles left closer than ε to
    /// `fields_end`, energies and their drift), so that both paths report the same
    /// [`ClothFrameMetrics`]. The simulator then holds the GPU's state ([`ClothSim::to_mesh`]
    /// gives the GPU cloth's mesh) and all else the GPU cloth carries into its next frame:
    /// the side memory, the last substep's dt and kinetic energy (`gpu.kinetic`), and the
    /// pins' start (their targets, as the GPU cloth moves them; a caller that moves pins
    /// sets the same targets on this sim as on the GPU cloth). So a checkpoint of this sim
    /// restores the GPU cloth exactly: `GpuCloth::new(ctx, &sim)` steps on to the same
    /// bits as the GPU cloth that never stopped.
    pub fn adopt_gpu_frame(
        &mut self,
        state: ClothState,
        side: Vec<Vec4>,
        fields_end: &[&DistanceField],
        gpu: &GpuClothFrameMetrics,
    ) -> Result<ClothFrameMetrics> {
        let stats = self.adopt(state, side, fields_end.len(), gpu)?;
        self.forget_corners(fields_end.len());
        let colliders = end_colliders(fields_end);
        Ok(self.metrics(gpu.frame, gpu.dt_substep, &colliders, &[], &stats, &stats))
    }

    /// [`ClothSim::adopt_gpu_frame`] for a GPU cloth whose colliders stay on the GPU: no
    /// field is needed on the CPU. The residual contacts (`close`, `close_max_depth`) are
    /// the ones the GPU measured against its end-of-frame colliders and the ground after the
    /// frame's last substep (`gpu.close`, `gpu.close_max_depth`); strain, energies and their
    /// drift come from `state` as in [`ClothSim::adopt_gpu_frame`]. `side` holds
    /// `gpu.colliders` entries per particle (at least one), as [`GpuCloth::read_side`] gives
    /// it.
    ///
    /// [`GpuCloth::read_side`]: super::gpu::GpuCloth::read_side
    pub fn adopt_gpu_frame_resident(
        &mut self,
        state: ClothState,
        side: Vec<Vec4>,
        gpu: &GpuClothFrameMetrics,
    ) -> Result<ClothFrameMetrics> {
        let stats = self.adopt(state, side, gpu.colliders as usize, gpu)?;
        // No colliders here: the frame pass measures strain and energies (and a ground
        // residual, which the GPU's replaces).
        let mut m = self.metrics(gpu.frame, gpu.dt_substep, &[], &[], &stats, &stats);
        m.close = gpu.close;
        m.close_max_depth = gpu.close_max_depth;
        Ok(m)
    }

    /// Takes the GPU cloth's state after a frame with `nf` colliders (see
    /// [`ClothSim::adopt_gpu_frame`]); returns the frame's stats as the GPU counted them.
    fn adopt(
        &mut self,
        state: ClothState,
        side: Vec<Vec4>,
        nf: usize,
        gpu: &GpuClothFrameMetrics,
    ) -> Result<SubstepStats> {
        let n = self.len();
        let blocks = SideMemory::from_vec4s(&side, n, nf)
            .filter(|_| state.pos.len() == n && state.prev.len() == n)
            .ok_or_else(|| {
                Error::Invalid(format!(
                    "cloth: a GPU state of {} particles and {} side entries for {n} particles \
                     and {nf} colliders",
                    state.pos.len(),
                    side.len()
                ))
            })?;
        self.state = state;
        self.sync_lanes();
        self.side = blocks;
        self.dt_prev = Some(gpu.dt_substep);
        // What else the GPU cloth carries into its next frame: the pins start from their
        // targets, and the energy limit rests on the last substep's kinetic energy.
        self.pin_from.clone_from(&self.pin_to);
        self.gpu_kinetic = Some(gpu.kinetic);
        Ok(SubstepStats {
            contacts: gpu.contacts,
            inside: gpu.inside,
            max_depth: gpu.max_depth,
            max_accel: gpu.max_accel,
            band_misses: gpu.band_misses,
            ..SubstepStats::new()
        })
    }

    /// The cloth as a mesh (the garment's own vertex layout and UVs, or the grid's), with
    /// area-weighted normals.
    pub fn to_mesh(&self) -> Mesh {
        let pos = &self.state.pos;
        let normals: Vec<Vec3> = (0..self.len())
            .map(|i| self.faces.area_normal(i, pos).normalize_or_zero())
            .collect();
        let out = &self.shape.out_particle;
        Mesh {
            positions: out.iter().map(|&p| pos[p as usize].truncate()).collect(),
            triangles: self.shape.out_triangles.clone(),
            normals: out.iter().map(|&p| normals[p as usize]).collect(),
            uvs: self.shape.out_uvs.clone(),
        }
    }
}

/// What a chunk of particles keeps between substeps: per block and collider its side
/// memory ([`SideMemory`]) and the cells last read from its end and start fields
/// ([`Corners`]).
struct Memory<'a> {
    side: &'a mut [SideLanes],
    corners: [&'a mut [Corners]; 2],
}

/// Colliders read at their end-of-frame `fields` alone: what a frame's residual contact reads
/// after the frame.
fn end_colliders<'a>(fields: &[&'a DistanceField]) -> Vec<Collider<'a>> {
    fields
        .iter()
        .map(|&f| Collider {
            start: None,
            end: FieldView::new(f),
            span: (1.0, 1.0),
        })
        .collect()
}

/// One chunk of particles (`base..`, whole blocks of [`LANES`]) through one substep, their
/// next positions written into `out` (the chunk's part of the next positions, by axis). In
/// the AVX2 build where the processor has it (decided once per process, as in
/// `imprint_core::closest`): the loops over a block's lanes then take eight particles per
/// instruction, with the same operations in the same order, so the same bits.
fn update_chunk(
    base: usize,
    ctx: &Substep,
    out: [&mut [f32]; 3],
    memory: Memory,
    st: &mut SubstepStats,
) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { update_chunk_avx2(base, ctx, out, memory, st) };
    }
    update_blocks(base, ctx, out, memory, st)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn update_chunk_avx2(
    base: usize,
    ctx: &Substep,
    out: [&mut [f32]; 3],
    memory: Memory,
    st: &mut SubstepStats,
) {
    update_blocks(base, ctx, out, memory, st)
}

#[inline(always)]
fn update_blocks(
    base: usize,
    ctx: &Substep,
    [ox, oy, oz]: [&mut [f32]; 3],
    mut memory: Memory,
    st: &mut SubstepStats,
) {
    let blocks = ox.chunks_exact_mut(LANES).zip(oy.chunks_exact_mut(LANES));
    for (b, ((ox, oy), oz)) in blocks.zip(oz.chunks_exact_mut(LANES)).enumerate() {
        let x = step_block(base + b * LANES, ctx, &mut memory, st);
        ox.copy_from_slice(&x[0]);
        oy.copy_from_slice(&x[1]);
        oz.copy_from_slice(&x[2]);
    }
}

/// The next positions of particles `first..first + LANES` (lanes past the last particle:
/// zero), in the order one particle's update takes: springs (and hinges), H eq. 10 (pins
/// to their targets), the colliders in order, the depth maps, the ground; then the stats.
/// `memory` is the chunk's.
#[inline(always)]
fn step_block(
    first: usize,
    ctx: &Substep,
    memory: &mut Memory,
    st: &mut SubstepStats,
) -> [Lane; 3] {
    let count = ctx.n.saturating_sub(first).min(LANES);
    // Lanes that move freely: not pinned, not padding.
    let live: [bool; LANES] = ctx.free[first..first + LANES].try_into().expect("a block");
    let live_bits = bool_bits(&live);
    let block = |a: &[f32]| -> Lane { a[first..first + LANES].try_into().expect("a block") };
    let x = [block(&ctx.at.x), block(&ctx.at.y), block(&ctx.at.z)];
    let xp = [block(&ctx.prev.x), block(&ctx.prev.y), block(&ctx.prev.z)];
    // SAFETY: `forces_fn` picked a build this processor runs.
    let (mut f, over) = unsafe { (ctx.forces)(ctx.blocks, first / LANES, ctx.at, ctx.max_stretch) };
    if over != 0 {
        st.overstretched = st
            .overstretched
            .min((first + over.trailing_zeros() as usize) as u32);
    }
    if !ctx.hinges.hinges.is_empty() {
        for (m, i) in (first..first + count).enumerate() {
            let h = hinge_force(i, ctx.hinges, |j| ctx.at.get(j));
            (0..3).for_each(|a| f[a][m] += h[a]);
        }
    }
    // H eq. 10, as `Vec4` arithmetic does it axis by axis.
    let mut moved = [[0.0f32; LANES]; 3];
    for a in 0..3 {
        for m in 0..LANES {
            moved[a][m] = (x[a][m] - xp[a][m]) * ctx.ratio;
        }
    }
    if let Some((wind, drag)) = ctx.wind {
        for m in lanes_of(live_bits) {
            let n = ctx.faces.area_normal_by(first + m, |j| ctx.at.get(j));
            let rel = wind - Vec3::new(moved[0][m], moved[1][m], moved[2][m]) / ctx.dt;
            let push = drag * n.normalize_or_zero().dot(rel) * n;
            (0..3).for_each(|a| f[a][m] += push[a]);
        }
    }
    let (dt2, g, w) = (ctx.dt * ctx.dt, ctx.gravity.to_array(), block(ctx.inv_mass));
    let mut xn = [[0.0f32; LANES]; 3];
    for a in 0..3 {
        for m in 0..LANES {
            xn[a][m] = x[a][m] + ctx.damping * moved[a][m] + (f[a][m] * w[m] + g[a]) * dt2;
        }
    }
    // Padding lanes stay at zero (the last block only: a branch per block, not per lane).
    if count < LANES {
        xn.iter_mut().for_each(|xn| xn[count..].fill(0.0));
    }
    // The pinned particles (neither live nor padding).
    for m in lanes_of(!live_bits & ((1u32 << count) - 1)) {
        let slot = ctx.pin_slot[first + m] as usize;
        let (a, b) = (ctx.pin_from[slot], ctx.pin_to[slot]);
        let p = if ctx.s >= 1.0 { b } else { a + (b - a) * ctx.s };
        (0..3).for_each(|k| xn[k][m] = p[k]);
    }
    let k0 = first % CHUNK;
    for (c, collider) in ctx.colliders.iter().enumerate() {
        if !collider.end.is_signed() && collider.start.is_none_or(|f| !f.is_signed()) {
            touch_block(ctx, collider, &x, &mut xn, &live, memory, k0, c, st);
        } else {
            let side = &mut memory.side[k0 / LANES * ctx.nf() + c];
            for m in lanes_of(live_bits) {
                let mut mem = Vec4::from_array(side.map(|a| a[m]));
                let (mut p, from) = (lane_vec(&xn, m), lane_vec(&x, m));
                if let Some(sample) = contact::signed_sample(collider, p, from, ctx.s, mem, ctx.eps)
                    && let Some(hit) =
                        contact::respond(&mut p, from, &sample, &mut mem, ctx.eps, ctx.friction)
                {
                    record(st, hit);
                    st.band_misses += sample.band_miss as u32;
                }
                (0..4).for_each(|a| side[a][m] = mem[a]);
                (0..3).for_each(|k| xn[k][m] = p[k]);
            }
        }
    }
    for collider in ctx.depth {
        for m in lanes_of(live_bits) {
            let (mut p, from) = (lane_vec(&xn, m), lane_vec(&x, m));
            let reach = 2.0 * ctx.eps + (p - from).length();
            let Some(sample) = collider.sample(p, reach, ctx.s) else {
                continue;
            };
            // Depth maps carry the side themselves: no memory to keep.
            let mut mem = Vec4::ZERO;
            if let Some(hit) =
                contact::respond(&mut p, from, &sample, &mut mem, ctx.eps, ctx.friction)
            {
                record(st, hit);
            }
            (0..3).for_each(|k| xn[k][m] = p[k]);
        }
    }
    if let Some(h) = ctx.ground {
        ground_block(h, ctx, &x, &mut xn, &live, st);
    }
    block_stats(first, &x, &moved, &xn, &live, st);
    xn
}

/// [`contact::ground`] for a block's live lanes, computed for all and selected.
#[inline(always)]
fn ground_block(
    h: f32,
    ctx: &Substep,
    from: &[Lane; 3],
    x: &mut [Lane; 3],
    live: &[bool; LANES],
    st: &mut SubstepStats,
) {
    let target = h + ctx.eps;
    let mut hits = [false; LANES];
    let mut depth = [0.0f32; LANES];
    for m in 0..LANES {
        // A NaN height counts as below, as in `contact::ground`.
        let above = x[1][m] >= target;
        let hit = live[m] & !above;
        depth[m] = target - x[1][m];
        x[1][m] = if hit { target } else { x[1][m] };
        if ctx.friction > 0.0 {
            for a in [0, 2] {
                let moved = x[a][m] - ctx.friction * (x[a][m] - from[a][m]);
                x[a][m] = if hit { moved } else { x[a][m] };
            }
        }
        hits[m] = hit;
    }
    for m in lanes_of(bool_bits(&hits)) {
        record(
            st,
            Hit {
                depth: depth[m],
                inside: depth[m] > ctx.eps,
            },
        );
    }
}

/// A block's part of the substep's stats: the first non-finite particle, and for the live
/// lanes in order the squared step (kinetic energy) and squared change of step
/// (acceleration), scaled once per substep, not per particle.
#[inline(always)]
fn block_stats(
    first: usize,
    from: &[Lane; 3],
    moved: &[Lane; 3],
    x: &[Lane; 3],
    live: &[bool; LANES],
    st: &mut SubstepStats,
) {
    // The squares of the live lanes, zero for the others: a sum from +0 never reaches −0, so
    // adding +0 leaves it as it is, and the largest squared change is never below 0. So the
    // lanes go without a branch each.
    let mut step2 = [0.0f32; LANES];
    let mut accel2 = [0.0f32; LANES];
    // Lane masks, not `bool`s: the lane loop then vectorises whole.
    let mut bad = [0u32; LANES];
    for m in 0..LANES {
        let s = [
            x[0][m] - from[0][m],
            x[1][m] - from[1][m],
            x[2][m] - from[2][m],
        ];
        let d = [s[0] - moved[0][m], s[1] - moved[1][m], s[2] - moved[2][m]];
        let (s2, a2) = (
            s[0] * s[0] + s[1] * s[1] + s[2] * s[2],
            d[0] * d[0] + d[1] * d[1] + d[2] * d[2],
        );
        let live = mask(live[m]);
        step2[m] = select(live, s2, 0.0);
        accel2[m] = select(live, a2, 0.0);
        let finite = [0, 1, 2].map(|a| mask(x[a][m].is_finite()));
        bad[m] = live & !(finite[0] & finite[1] & finite[2]);
    }
    // The kinetic energy's sum in the lanes' order (its bits depend on it); the largest in
    // halves (`max` drops NaNs, so any order gives the same).
    for s in step2 {
        st.kinetic += s as f64;
    }
    let mut half = LANES / 2;
    while half > 0 {
        for m in 0..half {
            accel2[m] = accel2[m].max(accel2[m + half]);
        }
        half /= 2;
    }
    st.max_accel = st.max_accel.max(accel2[0]);
    let bad = lane_bits(&bad);
    if bad != 0 {
        st.nonfinite = st.nonfinite.min(first as u32 + bad.trailing_zeros());
    }
}

/// The contact of a block's live lanes (new positions `x`, from `from`) with collider `c`,
/// read from unsigned fields ([`contact_lanes`]); `memory` is the chunk's, lane 0 its
/// particle `k0`.
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn touch_block(
    ctx: &Substep,
    collider: &Collider,
    from: &[Lane; 3],
    x: &mut [Lane; 3],
    live: &[bool; LANES],
    memory: &mut Memory,
    k0: usize,
    c: usize,
    st: &mut SubstepStats,
) {
    let nf = ctx.nf();
    let side = &mut memory.side[k0 / LANES * nf + c];
    let t = Touch {
        x,
        from,
        side,
        live,
    };
    let w = collider.weight(ctx.s);
    let fields = Fields {
        end: &collider.end,
        start: collider.start.as_ref().filter(|_| w < 1.0).map(|f| (f, w)),
    };
    let i = k0 / LANES * nf + c;
    let [end, start] = &mut memory.corners;
    let corners = [&mut end[i], &mut start[i]];
    let Some(r) = contact_lanes::touch_lanes(fields, &t, ctx.eps, ctx.friction, corners) else {
        return;
    };
    // The positions are the old where there was no hit.
    *x = r.x;
    *side = r.side;
    for m in lanes_of(bool_bits(&r.hit)) {
        let hit = Hit {
            depth: r.depth[m],
            inside: r.inside[m],
        };
        record(st, hit);
        st.band_misses += r.band_miss[m] as u32;
    }
}

impl Substep<'_> {
    /// Side memories per particle.
    #[inline(always)]
    fn nf(&self) -> usize {
        self.colliders.len().max(1)
    }
}

#[inline(always)]
fn record(st: &mut SubstepStats, hit: Hit) {
    st.contacts += 1;
    st.inside += hit.inside as u32;
    st.max_depth = st.max_depth.max(hit.depth);
}

/// Sum of the spring forces on particle `i`, four springs per step, and whether one of them
/// is longer than `max_stretch` times its rest length. `QUAD` picks T eq. 1's law.
#[inline(always)]
fn spring_force<const QUAD: bool>(
    i: usize,
    links: &Links,
    pos: &[Vec4],
    max_stretch: f32,
) -> (Vec3, bool) {
    let xi = pos[i];
    let (px, py, pz) = (Vec4::splat(xi.x), Vec4::splat(xi.y), Vec4::splat(xi.z));
    let (mut fx, mut fy, mut fz) = (Vec4::ZERO, Vec4::ZERO, Vec4::ZERO);
    let mut over = false;
    let limit = Vec4::splat(max_stretch);
    for q in links.of(i) {
        let LinkQuad {
            other,
            rest,
            k_stretch,
            k_compress,
        } = *q;
        // Rows of the transposed 4x4: x, y, z (and w) of the four other ends.
        let t = Mat4::from_cols(
            pos[other[0] as usize],
            pos[other[1] as usize],
            pos[other[2] as usize],
            pos[other[3] as usize],
        )
        .transpose();
        let dx = t.x_axis - px;
        let dy = t.y_axis - py;
        let dz = t.z_axis - pz;
        let len = (dx * dx + dy * dy + dz * dz).sqrt();
        let rest = Vec4::from_array(rest);
        let e = len - rest;
        let k = Vec4::select(
            e.cmpge(Vec4::ZERO),
            Vec4::from_array(k_stretch),
            Vec4::from_array(k_compress),
        );
        let mut c = k * e / len.max(Vec4::splat(TINY));
        if QUAD {
            c *= e.abs();
        }
        fx += c * dx;
        fy += c * dy;
        fz += c * dz;
        over |= len.cmpgt(rest * limit).any();
    }
    (
        Vec3::new(fx.element_sum(), fy.element_sum(), fz.element_sum()),
        over,
    )
}

/// Half the potential energy of particle `i`'s springs (each is listed at both ends) and the
/// largest |length / rest - 1| among them, four springs per step: what [`Blocks::energy`]
/// gives eight particles at a time, to the bit.
#[cfg(test)]
pub(super) fn spring_energy(i: usize, links: &Links, pos: &[Vec4]) -> (f32, f32) {
    let xi = pos[i];
    let (px, py, pz) = (Vec4::splat(xi.x), Vec4::splat(xi.y), Vec4::splat(xi.z));
    let quad = links.law == SpringLaw::Quadratic;
    let (mut u, mut strain) = (Vec4::ZERO, Vec4::ZERO);
    for q in links.of(i) {
        let t = Mat4::from_cols(
            pos[q.other[0] as usize],
            pos[q.other[1] as usize],
            pos[q.other[2] as usize],
            pos[q.other[3] as usize],
        )
        .transpose();
        let (dx, dy, dz) = (t.x_axis - px, t.y_axis - py, t.z_axis - pz);
        let rest = Vec4::from_array(q.rest);
        let e = (dx * dx + dy * dy + dz * dz).sqrt() - rest;
        let k = Vec4::select(
            e.cmpge(Vec4::ZERO),
            Vec4::from_array(q.k_stretch),
            Vec4::from_array(q.k_compress),
        );
        u += if quad {
            k * e.abs() * e * e * (0.5 / 3.0)
        } else {
            k * e * e * 0.25
        };
        strain = strain.max(e.abs() / rest.max(Vec4::splat(TINY)));
    }
    (u.element_sum(), strain.max_element())
}

/// Sum of the hinge bending forces on particle `i`: -U'(θ - θ_rest) dθ/dx_i per hinge.
#[inline]
fn hinge_force(i: usize, hinges: &Hinges, at: impl Fn(usize) -> Vec3) -> Vec3 {
    let mut f = Vec3::ZERO;
    for &r in &hinges.refs[hinges.offsets[i] as usize..hinges.offsets[i + 1] as usize] {
        let h = &hinges.hinges[(r / 4) as usize];
        if let Some((theta, g)) = hinge_angle_gradient(h.v.map(|v| at(v as usize))) {
            f -= hinge_slope(h.c, theta - h.rest_angle) * g[(r % 4) as usize];
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The frame pass reads the colliders through the cells the frame's last substep held
    /// ([`Corners`]); its residual contact must be what fresh reads give. Two spheres on one
    /// grid, overlapping under a 20×20 cloth (two chunks): a held corner read for the wrong
    /// collider or block would give the other sphere's distances there.
    #[test]
    fn the_frame_pass_reads_the_same_through_the_held_cells_as_afresh() {
        use crate::cloth::params::StiffnessMode;
        use glam::UVec3;
        use imprint_core::GridSpec;
        let mut p = ClothParams::new(
            Shape::Grid {
                size: [0.8, 0.8],
                resolution: [20, 20],
                center: Vec3::new(0.013, 0.34, 0.021),
                normal: Vec3::Y,
            },
            Material::Harada {
                k_structural: 1e4,
                k_shear: 1e4,
                k_bend: None,
            },
        );
        (p.stiffness_mode, p.mass, p.substeps) = (StiffnessMode::Strain, 1.0, 16);
        (p.collision.epsilon, p.collision.ground) = (0.01, None);
        let spec = GridSpec::new(Vec3::splat(-0.395), 0.01, UVec3::splat(80)).unwrap();
        let sphere = |c: Vec3| {
            DistanceField::from_closest_points(spec, 3.0, move |q| {
                c + 0.25 * (q - c).try_normalize().unwrap_or(Vec3::X)
            })
        };
        let fields = [
            sphere(Vec3::new(-0.08, 0.0, 0.0)),
            sphere(Vec3::new(0.08, 0.0, 0.0)),
        ];
        let fields: Vec<&DistanceField> = fields.iter().collect();
        let mut sim = ClothSim::from_assets(&p, &Default::default()).unwrap();
        let mut close_frames = 0;
        for f in 0..40 {
            let m = sim.step_frame(&fields, &fields, f, 1.0 / 60.0).unwrap();
            let colliders = end_colliders(&fields);
            let mut fresh = sim.corners.clone();
            fresh.iter_mut().flatten().for_each(Corners::forget);
            let held = fresh.each_mut().map(|c| c.as_mut_slice());
            let afresh = sim.frame_pass(sim.springs_at(), &colliders, &[], held);
            assert_eq!(m.close, afresh.close, "frame {f}");
            assert_eq!(
                m.close_max_depth.to_bits(),
                afresh.close_depth.to_bits(),
                "frame {f}"
            );
            close_frames += (m.close > 0) as u32;
        }
        assert!(
            close_frames > 10,
            "the cloth must rest within ε of the spheres"
        );
    }

    /// `block_stats` without a branch per lane against the plain loop over the live lanes it
    /// replaced: the same kinetic sum and largest change to the bit, and the same first
    /// non-finite particle, with pinned or padding lanes (never counted, even when not finite)
    /// and NaN and infinite positions among the live ones.
    #[test]
    fn block_stats_match_a_loop_over_the_live_lanes() {
        let mut seed = 2024u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1 << 24) as f32
        };
        let (mut nonfinite_seen, mut pinned_bad_seen) = (0, 0);
        for round in 0..2000 {
            let mut lane = |scale: f32| -> [Lane; 3] {
                [(); 3].map(|_| [(); LANES].map(|_| (next() - 0.5) * scale))
            };
            let (from, moved, mut x) = (lane(1.0), lane(0.01), lane(1.0));
            let mut live = [false; LANES];
            for (m, live) in live.iter_mut().enumerate() {
                *live = next() < 0.8;
                if next() < 0.05 {
                    x[m % 3][m] = [f32::NAN, f32::INFINITY, f32::NEG_INFINITY][m % 3];
                }
            }
            let first = round * LANES;
            let mut st = SubstepStats::new();
            (st.kinetic, st.max_accel) = (next() as f64, next());
            let mut want = st;
            for m in (0..LANES).filter(|&m| live[m]) {
                let s = [0, 1, 2].map(|a| x[a][m] - from[a][m]);
                let d = [0, 1, 2].map(|a| s[a] - moved[a][m]);
                if !(x[0][m].is_finite() && x[1][m].is_finite() && x[2][m].is_finite()) {
                    want.nonfinite = want.nonfinite.min((first + m) as u32);
                }
                want.kinetic += (s[0] * s[0] + s[1] * s[1] + s[2] * s[2]) as f64;
                want.max_accel = want.max_accel.max(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            }
            block_stats(first, &from, &moved, &x, &live, &mut st);
            assert_eq!(
                st.kinetic.to_bits(),
                want.kinetic.to_bits(),
                "round {round}"
            );
            assert_eq!(
                st.max_accel.to_bits(),
                want.max_accel.to_bits(),
                "round {round}"
            );
            assert_eq!(st.nonfinite, want.nonfinite, "round {round}");
            nonfinite_seen += (want.nonfinite != u32::MAX) as u32;
            pinned_bad_seen +=
                (0..LANES).any(|m| !live[m] && !x.iter().all(|a| a[m].is_finite())) as u32;
        }
        assert!(nonfinite_seen > 100 && pinned_bad_seen > 50);
    }
}
