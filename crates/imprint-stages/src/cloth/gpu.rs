//! The GPU cloth (`shaders/cloth/step.wgsl`): the same model as [`super::cpu`], one compute
//! dispatch per substep.
//!
//! [`GpuCloth::new`] takes a [`ClothSim`] and uploads its CSR links, hinges, faces, pins and
//! state. Each substep is one invocation per particle that gathers its springs and Tokoi's
//! bending hinges from the current positions, integrates damped Verlet into the next buffer,
//! then projects its own new position out of each collider in order and off the ground
//! (contact reads no other particle's new position, so it needs no second dispatch). The
//! three position buffers rotate between substeps; nothing is read back between substeps, and
//! nothing uses atomics.
//!
//! Colliders are [`GpuCollider`]s: a [`DistanceField`]'s cells uploaded in the sampler's cache
//! layout (`vec4`: closest-point vector, distance negated for far cells), sampled with the
//! formulas of [`super::sampler`] and [`super::contact`], start and end fields blended per
//! substep as on the CPU. The colliders of a frame are copied on the GPU into one buffer
//! (one binding, any number of colliders); a collider passed again in the same slot is not
//! copied again. A field built on the GPU becomes a collider there
//! ([`GpuCollider::from_gpu_field`], `shaders/cloth/collider.wgsl`): the same cells, bit for
//! bit, as uploading the field read back, without reading it back.
//!
//! Blow-up detection is per frame: every particle keeps, over the frame's substeps, the first
//! substep where its position went non-finite or one of its springs passed
//! `limits.max_stretch`, and the host reads those flags back once per frame (with the
//! contact counts, and each particle's residual contact, which a last small pass measures
//! against the end-of-frame colliders and the ground) and checks the kinetic energy of the
//! last substep. A failed frame puts the
//! cloth back where it was at the frame's start and returns `Error::Numerical` naming the
//! node, the frame, the substep and what to change.
//!
//! Every parameter of the CPU cloth is supported: Harada and Tokoi springs (anisotropy is
//! baked into the spring constants), Tokoi's bending hinges (`bend_c > 0`: the hinges are
//! uploaded as built by [`super::springs::Hinges`], and the shader ports
//! [`super::springs::hinge_angle_gradient`] and [`super::springs::hinge_slope`]), gravity,
//! damping, pins with moving targets, wind, ground, colliders with friction and time blending.
//!
//! f32 arithmetic is the CPU's in the same order, but a shader compiler may fuse multiply-adds
//! or divide less exactly, and the hinges' `atan2` is a polynomial in the shader (within a few
//! ulps of Rust's) and their `cos` the device's (WGSL leaves its precision to the device;
//! within an ulp of Rust's on lavapipe), so positions agree to rounding at first and drift
//! apart slowly; `tests/tests/gpu_cloth.rs` states the measured differences.

use super::cpu::{ClothSim, ClothState};
use super::params::ClothParams;
use super::shape::ClothShape;
use super::springs::{Faces, Hinge, LinkQuad, SpringLaw};
use super::stability::{BandMisses, StabilityEstimate};
use crate::sdf::gpu::GpuField;
use bytemuck::Zeroable;
use glam::{Vec3, Vec4};
use imprint_core::{BoundaryVariant, DistanceField, Error, GridSpec, Mesh, Result};
use imprint_gpu::{Dispatch, GpuContext, GpuTimer, record_pass, shader, submit};
use std::sync::atomic::{AtomicU64, Ordering};

const NONE: u32 = u32::MAX;

/// A body's distance field on the GPU, as the cloth samples it.
#[derive(Debug)]
pub struct GpuCollider {
    id: u64,
    pub spec: GridSpec,
    /// Half-width of the band, cells.
    pub band: f32,
    /// Per cell `vec4<f32>`: xyz the closest-point vector, w the distance (negated when far).
    pub cells: wgpu::Buffer,
    /// The field's inside bits when it is signed ([`DistanceField::inside`], `u32` words).
    pub signs: Option<wgpu::Buffer>,
}

impl GpuCollider {
    /// Uploads `field`'s [`DistanceField::cells`] (each cell's vector and distance).
    pub fn from_field(ctx: &GpuContext, field: &DistanceField) -> Result<Self> {
        let spec = field.spec;
        ctx.check_grid("cloth collider field", spec.dims.to_array(), 16)?;
        Ok(GpuCollider {
            id: next_collider_id(),
            spec,
            band: field.band,
            cells: ctx.storage_buffer("cloth collider field", field.cells())?,
            signs: match &field.inside {
                Some(words) => Some(ctx.storage_buffer("cloth collider signs", words)?),
                None => None,
            },
        })
    }

    /// The collider of a field built on the GPU ([`crate::sdf::gpu::build_field_gpu`]), made
    /// on the device (`shaders/cloth/collider.wgsl`): the cells, bit for bit, that
    /// `GpuCollider::from_field(ctx, &field.to_cpu(ctx)?)` would upload
    /// ([`DistanceField::cells`] of the field read back), with nothing read back. A Closest
    /// boundary's owning triangles go up in world units (48 bytes a triangle), as the CPU
    /// field has them; nothing else but a uniform is uploaded. Submitted, not waited for.
    ///
    /// The closest points use WGSL's division, which the WGSL spec lets a device round less
    /// exactly than the CPU; on Mesa lavapipe the cells are the CPU's to the bit
    /// (`tests/tests/gpu_resident.rs`).
    pub fn from_gpu_field(ctx: &GpuContext, field: &GpuField) -> Result<Self> {
        let spec = field.spec;
        ctx.check_grid("cloth collider field", spec.dims.to_array(), 16)?;
        let b = &field.boundary;
        if b.spec != spec {
            return Err(Error::Invalid(format!(
                "GPU field on {:?} but its boundary on {:?}",
                spec, b.spec
            )));
        }
        let closest = b.variant == BoundaryVariant::Closest;
        if closest && b.faces_world.is_empty() {
            return Err(Error::Invalid(
                "a Closest boundary needs the owning face of each point".into(),
            ));
        }
        let faces: Vec<[f32; 4]> = if closest {
            b.faces_world
                .iter()
                .flat_map(|f| f.map(|v| v.extend(0.0).to_array()))
                .collect()
        } else {
            Vec::new()
        };
        let faces = ctx.storage_buffer("cloth collider faces", &faces)?;
        let cells = ctx.zeroed_buffer("cloth collider field", spec.len() as u64 * 16)?;
        let pipeline = ctx.pipeline(
            "cloth collider",
            &[
                shader!("common/dispatch.wgsl"),
                shader!("common/geom.wgsl"),
                shader!("cloth/collider.wgsl"),
            ],
            "collider_cells",
        )?;
        let n_cells = spec.len() as u32;
        let params = ctx.uniform_buffer(
            "cloth collider params",
            &ColliderParams {
                dims: [spec.dims.x, spec.dims.y, spec.dims.z, n_cells],
                origin: spec.origin.extend(spec.cell).to_array(),
                closest: closest as u32,
                zero: 0,
                _pad: [0; 2],
            },
        );
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("cloth collider"),
            });
        record_pass(
            ctx,
            &mut encoder,
            "cloth collider cells",
            &pipeline,
            &[
                (0, &params),
                (1, &field.field),
                (2, &field.nearest_cell),
                (3, &b.points),
                (4, &b.owner),
                (5, &faces),
                (6, &cells),
            ],
            Dispatch::Threads(n_cells),
            None,
        );
        submit(ctx, encoder, None);
        Ok(GpuCollider {
            id: next_collider_id(),
            spec,
            band: field.band,
            cells,
            // The boundary's bits, shared: the field's sign is its boundary's.
            signs: b.inside.clone(),
        })
    }

    /// Far value, world units (as [`DistanceField::far_value`]).
    pub fn far_value(&self) -> f32 {
        self.band * self.spec.cell
    }
}

/// A fresh collider id (slots whose collider did not change are not copied again).
fn next_collider_id() -> u64 {
    static NEXT: AtomicU64 = AtomicU64::new(1);
    NEXT.fetch_add(1, Ordering::Relaxed)
}

/// Mirrors `ColliderParams` in `shaders/cloth/collider.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ColliderParams {
    dims: [u32; 4],
    origin: [f32; 4],
    closest: u32,
    zero: u32,
    _pad: [u32; 2],
}

pub use super::metrics::GpuClothFrameMetrics;

/// Mirrors `StepParams` in the shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct StepParams {
    gravity: [f32; 4],
    wind: [f32; 4],
    n: u32,
    nf: u32,
    quad: u32,
    has_ground: u32,
    s: f32,
    dt: f32,
    ratio: f32,
    damping: f32,
    eps: f32,
    friction: f32,
    ground: f32,
    max_stretch: f32,
    has_wind: u32,
    substep: u32,
    face_base: u32,
    pin_base: u32,
    hinge_base: u32,
    href_base: u32,
    has_hinges: u32,
    _pad: u32,
}

// `Hinge` is bound as it is: `struct Hinge { v: vec4<u32>, rest_angle: f32, c: f32, ... }`.
const _: () = assert!(std::mem::size_of::<Hinge>() == 32 && std::mem::align_of::<Hinge>() == 4);

/// Mirrors `FieldHeader`.
#[repr(C)]
#[derive(Clone, Copy, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct FieldHeader {
    origin: [f32; 4],
    dims: [u32; 4],
    far_value: f32,
    present: u32,
    /// Offset of the slot's inside bits in `FieldSet::signs`, words.
    sign_offset: u32,
    /// 1 when the slot's field is signed.
    signed: u32,
}

/// Mirrors `Stats`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, bytemuck::Pod, bytemuck::Zeroable)]
struct Stats {
    contacts: u32,
    inside: u32,
    max_depth: f32,
    band_misses: u32,
    nonfinite: u32,
    overstretched: u32,
    step2: f32,
    accel2: f32,
    close_depth: f32,
}

/// The colliders bound for the current frame.
struct FieldSet {
    /// Collider id per slot (start 2k, end 2k + 1; 0 = empty).
    ids: Vec<u64>,
    headers: wgpu::Buffer,
    cells: wgpu::Buffer,
    /// The signed slots' inside bits, one bitset per slot.
    signs: wgpu::Buffer,
}

/// A cloth simulated on the GPU; the state stays there between frames.
pub struct GpuCloth {
    params: ClothParams,
    node: String,
    shape: ClothShape,
    faces: Faces,
    stability: StabilityEstimate,
    pinned: Vec<u32>,
    pin_from: Vec<Vec3>,
    pin_to: Vec<Vec3>,
    law: SpringLaw,
    n: u32,
    face_base: u32,
    pin_base: u32,
    hinge_base: u32,
    href_base: u32,
    has_hinges: bool,
    topo: wgpu::Buffer,
    quads: wgpu::Buffer,
    /// [`Hinge`]s (one zeroed hinge when there are none; the shader then skips them).
    hinges: wgpu::Buffer,
    face_others: wgpu::Buffer,
    /// Positions: `bufs[cur]` is current, `bufs[(cur + 2) % 3]` previous.
    bufs: [wgpu::Buffer; 3],
    cur: usize,
    backup: [wgpu::Buffer; 2],
    side: wgpu::Buffer,
    side_backup: wgpu::Buffer,
    side_fields: usize,
    stats: wgpu::Buffer,
    fields: Option<FieldSet>,
    /// One uniform buffer per substep (rewritten every frame).
    step_params: Vec<wgpu::Buffer>,
    dt_prev: Option<f32>,
    /// Kinetic energy at the end of the last frame (for the growth limit).
    ke_last: f64,
}

impl GpuCloth {
    /// Uploads `sim`'s cloth (links, faces, pins) and everything it carries between frames:
    /// its state, the contacts' side memory, the pins' start and end targets (move the end
    /// with [`GpuCloth::set_pin_targets`]), the last substep's dt and kinetic energy
    /// ([`ClothSim::last_substep_kinetic`], the energy-growth limit's base) and its name. A
    /// sim that mirrored a GPU cloth (`ClothSim::adopt_gpu_frame*` after each frame), or was
    /// loaded from a checkpoint of one, gives a GPU cloth that steps on to the same bits as
    /// that one.
    pub fn new(ctx: &GpuContext, sim: &ClothSim) -> Result<Self> {
        let params = sim.params().clone();
        let n = sim.len();
        let shape = sim.shape().clone();
        let faces = Faces::build(n, &shape.triangles);
        let links = sim.links();
        let pinned = sim.pinned().to_vec();
        let mut pin_slot = vec![NONE; n];
        for (k, &p) in pinned.iter().enumerate() {
            pin_slot[p as usize] = k as u32;
        }
        // Link offsets, face offsets, pin slots, hinge offsets, hinge refs.
        let hinges = sim.hinges();
        let mut topo = links.offsets.clone();
        let face_base = topo.len() as u32;
        topo.extend_from_slice(&faces.offsets);
        let pin_base = topo.len() as u32;
        topo.extend_from_slice(&pin_slot);
        let hinge_base = topo.len() as u32;
        if hinges.is_empty() {
            // Zero hinges per particle (the shader skips the loop anyway).
            topo.resize(topo.len() + n + 1, 0);
        } else {
            topo.extend_from_slice(&hinges.offsets);
        }
        let href_base = topo.len() as u32;
        topo.extend_from_slice(&hinges.refs);
        let state = sim.state();
        let (pin_from, pin_to) = sim.pin_endpoints();
        let (side, side_fields) = sim.side_memory();
        if side.len() != n * side_fields.max(1) {
            return Err(Error::Invalid(format!(
                "cloth: {} side entries for {n} particles and {side_fields} colliders",
                side.len()
            )));
        }
        let quads: &[LinkQuad] = &links.quads;
        let face_others: Vec<[u32; 2]> = faces.others.clone();
        let bytes = n as u64 * 16;
        let bufs = [
            ctx.storage_buffer("cloth prev", &state.prev)?,
            ctx.storage_buffer("cloth pos", &state.pos)?,
            ctx.storage_buffer("cloth next", &state.pos)?,
        ];
        Ok(GpuCloth {
            node: sim.name().to_string(),
            stability: *sim.stability(),
            law: links.law,
            n: n as u32,
            face_base,
            pin_base,
            hinge_base,
            href_base,
            has_hinges: !hinges.is_empty(),
            topo: ctx.storage_buffer("cloth topology", &topo)?,
            quads: ctx.storage_buffer("cloth links", quads)?,
            // A binding holds at least one whole struct: one zeroed hinge stands in for none.
            hinges: if hinges.is_empty() {
                ctx.storage_buffer("cloth hinges", &[Hinge::zeroed()])?
            } else {
                ctx.storage_buffer("cloth hinges", &hinges.hinges)?
            },
            face_others: ctx.storage_buffer("cloth faces", &face_others)?,
            bufs,
            cur: 1,
            backup: [
                ctx.zeroed_buffer("cloth backup pos", bytes)?,
                ctx.zeroed_buffer("cloth backup prev", bytes)?,
            ],
            side: ctx.storage_buffer("cloth side", &side)?,
            side_backup: ctx.zeroed_buffer("cloth side backup", side.len() as u64 * 16)?,
            side_fields,
            stats: ctx.zeroed_buffer(
                "cloth stats",
                n as u64 * std::mem::size_of::<Stats>() as u64,
            )?,
            fields: None,
            step_params: Vec::new(),
            dt_prev: sim.dt_prev(),
            ke_last: sim.last_substep_kinetic(),
            pin_from: pin_from.to_vec(),
            pin_to: pin_to.to_vec(),
            pinned,
            faces,
            shape,
            params,
        })
    }

    /// The node name used in errors (default "cloth").
    pub fn with_name(mut self, node: impl Into<String>) -> Self {
        self.node = node.into();
        self
    }

    pub fn len(&self) -> usize {
        self.n as usize
    }

    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    pub fn pinned(&self) -> &[u32] {
        &self.pinned
    }

    /// As [`ClothSim::set_pin_targets`].
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

    /// The state (current and previous positions, w = inverse mass), read back.
    pub fn read_state(&self, ctx: &GpuContext) -> Result<ClothState> {
        let pos: Vec<Vec4> = ctx.read_buffer(&self.bufs[self.cur])?;
        let prev: Vec<Vec4> = ctx.read_buffer(&self.bufs[(self.cur + 2) % 3])?;
        let n = self.len();
        Ok(ClothState {
            pos: pos[..n].to_vec(),
            prev: prev[..n].to_vec(),
        })
    }

    /// The contacts' side memory (per particle and collider, as [`ClothSim`] keeps it), read
    /// back.
    pub fn read_side(&self, ctx: &GpuContext) -> Result<Vec<Vec4>> {
        let side: Vec<Vec4> = ctx.read_buffer(&self.side)?;
        let n = self.len() * self.side_fields.max(1);
        Ok(side[..n.min(side.len())].to_vec())
    }

    /// Current particle positions, read back.
    pub fn read_positions(&self, ctx: &GpuContext) -> Result<Vec<Vec3>> {
        let pos: Vec<Vec4> = ctx.read_buffer(&self.bufs[self.cur])?;
        Ok(pos[..self.len()].iter().map(|p| p.truncate()).collect())
    }

    /// The cloth as a mesh, as [`ClothSim::to_mesh`] (read back).
    pub fn to_mesh(&self, ctx: &GpuContext) -> Result<Mesh> {
        let pos: Vec<Vec4> = ctx.read_buffer(&self.bufs[self.cur])?;
        let normals: Vec<Vec3> = (0..self.len())
            .map(|i| self.faces.area_normal(i, &pos).normalize_or_zero())
            .collect();
        let out = &self.shape.out_particle;
        Ok(Mesh {
            positions: out.iter().map(|&p| pos[p as usize].truncate()).collect(),
            triangles: self.shape.out_triangles.clone(),
            normals: out.iter().map(|&p| normals[p as usize]).collect(),
            uvs: self.shape.out_uvs.clone(),
        })
    }

    /// Binds this frame's colliders, copying only slots whose collider changed.
    fn bind_fields(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        start: &[&GpuCollider],
        end: &[&GpuCollider],
        blend: bool,
    ) -> Result<()> {
        let nf = end.len();
        let mut slots: Vec<Option<&GpuCollider>> = Vec::with_capacity(2 * nf);
        for (k, &e) in end.iter().enumerate() {
            // A body that did not change (the same field at both ends) needs no blend.
            slots.push((blend && start[k].id != e.id).then(|| start[k]));
            slots.push(Some(e));
        }
        let ids: Vec<u64> = slots.iter().map(|s| s.map_or(0, |c| c.id)).collect();
        if self.fields.as_ref().is_some_and(|f| f.ids == ids) {
            return Ok(());
        }
        let mut headers = Vec::with_capacity(slots.len().max(1));
        let mut offset = 0u64;
        let mut sign_words = 0u64;
        for s in &slots {
            let mut h = FieldHeader::default();
            if let Some(c) = s {
                h.origin = c.spec.origin.extend(c.spec.cell).to_array();
                h.dims = [c.spec.dims.x, c.spec.dims.y, c.spec.dims.z, offset as u32];
                h.far_value = c.far_value();
                h.present = 1;
                if c.signs.is_some() {
                    h.signed = 1;
                    h.sign_offset = sign_words as u32;
                    sign_words += c.spec.len().div_ceil(32) as u64;
                }
                offset += c.spec.len() as u64;
                if offset >= u32::MAX as u64 {
                    return Err(Error::TooLarge {
                        what: "cloth colliders' cells (GPU cell indices are 32-bit)".into(),
                        needed: offset * 16,
                        available: (u32::MAX as u64 - 1) * 16,
                    });
                }
            }
            headers.push(h);
        }
        if headers.is_empty() {
            headers.push(FieldHeader::default());
        }
        let old = self.fields.take();
        let (cells, signs) = match old {
            Some(f) if f.cells.size() >= offset * 16 && f.signs.size() >= sign_words * 4 => {
                (f.cells, f.signs)
            }
            _ => (
                ctx.zeroed_buffer("cloth colliders", offset * 16)?,
                ctx.zeroed_buffer("cloth collider signs", sign_words * 4)?,
            ),
        };
        for (s, h) in slots.iter().zip(&headers) {
            if let Some(c) = s {
                let bytes = c.spec.len() as u64 * 16;
                encoder.copy_buffer_to_buffer(&c.cells, 0, &cells, h.dims[3] as u64 * 16, bytes);
                if let Some(b) = &c.signs {
                    let words = c.spec.len().div_ceil(32) as u64 * 4;
                    encoder.copy_buffer_to_buffer(b, 0, &signs, h.sign_offset as u64 * 4, words);
                }
            }
        }
        self.fields = Some(FieldSet {
            ids,
            headers: ctx.storage_buffer("cloth collider headers", &headers)?,
            cells,
            signs,
        });
        Ok(())
    }

    /// Advances one body frame of `dt_frame` seconds in `params.substeps` substeps, as
    /// [`ClothSim::step_frame`]: `fields_end` are the colliders at the frame's end, applied in
    /// order; `fields_start` the same at its start (blended when `blend_fields` is on; `&[]`
    /// to use the end fields throughout). Submits the frame and waits for it (one small
    /// readback of per-particle flags).
    pub fn step_frame(
        &mut self,
        ctx: &GpuContext,
        fields_start: &[&GpuCollider],
        fields_end: &[&GpuCollider],
        frame: u32,
        dt_frame: f32,
    ) -> Result<GpuClothFrameMetrics> {
        self.step_frame_timed(ctx, fields_start, fields_end, frame, dt_frame, None)
    }

    /// [`GpuCloth::step_frame`] with its substeps timed by `timer` (the first
    /// [`GpuTimer::MAX_PASSES`]); the timer is waited on inside, its timings returned too.
    pub fn step_frame_timed(
        &mut self,
        ctx: &GpuContext,
        fields_start: &[&GpuCollider],
        fields_end: &[&GpuCollider],
        frame: u32,
        dt_frame: f32,
        mut timer: Option<&mut GpuTimer>,
    ) -> Result<GpuClothFrameMetrics> {
        let blend = self
            .params
            .frame_blend(dt_frame, fields_start.len(), fields_end.len())?;
        for f in fields_end
            .iter()
            .chain(if blend { fields_start } else { &[] })
        {
            self.params.check_band(f.far_value(), f.band)?;
        }
        let eps = self.params.collision.epsilon;
        let nf = fields_end.len();
        let n = self.len();
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("cloth frame"),
            });
        if nf != self.side_fields {
            let bytes = (n * nf.max(1) * 16) as u64;
            self.side = ctx.zeroed_buffer("cloth side", bytes)?;
            self.side_backup = ctx.zeroed_buffer("cloth side backup", bytes)?;
            self.side_fields = nf;
        }
        self.bind_fields(ctx, &mut encoder, fields_start, fields_end, blend)?;
        let n_sub = self.params.substeps;
        let dt = dt_frame / n_sub as f32;

        // Backups of the frame's start, for a failed frame; stats cleared.
        let (pos_i, prev_i) = (self.cur, (self.cur + 2) % 3);
        let bytes = n as u64 * 16;
        encoder.copy_buffer_to_buffer(&self.bufs[pos_i], 0, &self.backup[0], 0, bytes);
        encoder.copy_buffer_to_buffer(&self.bufs[prev_i], 0, &self.backup[1], 0, bytes);
        encoder.copy_buffer_to_buffer(&self.side, 0, &self.side_backup, 0, self.side.size());
        encoder.clear_buffer(&self.stats, 0, None);

        let pins: Vec<Vec4> = self
            .pin_from
            .iter()
            .zip(&self.pin_to)
            .flat_map(|(a, b)| [a.extend(0.0), b.extend(0.0)])
            .collect();
        let pins = ctx.storage_buffer("cloth pins", &pins)?;
        let pipeline = ctx.pipeline(
            "cloth step",
            &[shader!("common/dispatch.wgsl"), shader!("cloth/step.wgsl")],
            "substep",
        )?;
        while self.step_params.len() < n_sub as usize {
            self.step_params
                .push(ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("cloth step params"),
                    size: std::mem::size_of::<StepParams>() as u64,
                    usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                }));
        }
        let p = &self.params;
        let fields = self.fields.as_ref().expect("bound above");
        let mut cur = self.cur;
        let mut dt_prev = self.dt_prev;
        for j in 0..n_sub {
            let s = if j + 1 == n_sub {
                1.0
            } else {
                (j + 1) as f32 / n_sub as f32
            };
            let ratio = match dt_prev {
                Some(q) if q != dt => dt / q,
                _ => 1.0,
            };
            let sp = StepParams {
                gravity: p.gravity.extend(0.0).to_array(),
                wind: p
                    .wind
                    .map_or([0.0; 4], |w| w.velocity.extend(w.drag).to_array()),
                n: self.n,
                nf: nf as u32,
                quad: (self.law == SpringLaw::Quadratic) as u32,
                has_ground: p.collision.ground.is_some() as u32,
                s,
                dt,
                ratio,
                damping: p.damping,
                eps,
                friction: p.collision.friction,
                ground: p.collision.ground.unwrap_or(0.0),
                max_stretch: p.limits.max_stretch,
                has_wind: p.wind.is_some() as u32,
                substep: j,
                face_base: self.face_base,
                pin_base: self.pin_base,
                hinge_base: self.hinge_base,
                href_base: self.href_base,
                has_hinges: self.has_hinges as u32,
                _pad: 0,
            };
            let ub = &self.step_params[j as usize];
            ctx.queue.write_buffer(ub, 0, bytemuck::bytes_of(&sp));
            let (prev, pos, next) = (
                &self.bufs[(cur + 2) % 3],
                &self.bufs[cur],
                &self.bufs[(cur + 1) % 3],
            );
            record_pass(
                ctx,
                &mut encoder,
                "cloth substep",
                &pipeline,
                &[
                    (0, ub),
                    (1, &self.topo),
                    (2, &self.quads),
                    (3, &pins),
                    (4, &self.face_others),
                    (5, prev),
                    (6, pos),
                    (7, next),
                    (8, &self.side),
                    (9, &self.stats),
                    (10, &fields.headers),
                    (11, &fields.cells),
                    (12, &self.hinges),
                    (13, &fields.signs),
                ],
                Dispatch::Threads(self.n),
                timer.as_deref_mut(),
            );
            cur = (cur + 1) % 3;
            dt_prev = Some(dt);
        }
        // The residual contacts at the frame's end, against the end fields: the last
        // substep's parameters have s = 1, which reads the end slots only.
        let residual = ctx.pipeline(
            "cloth step",
            &[shader!("common/dispatch.wgsl"), shader!("cloth/step.wgsl")],
            "residual",
        )?;
        record_pass(
            ctx,
            &mut encoder,
            "cloth residual",
            &residual,
            &[
                (0, &self.step_params[n_sub as usize - 1]),
                (6, &self.bufs[cur]),
                (8, &self.side),
                (9, &self.stats),
                (10, &fields.headers),
                (11, &fields.cells),
                (13, &fields.signs),
            ],
            Dispatch::Threads(self.n),
            timer.as_deref_mut(),
        );
        submit(ctx, encoder, timer.as_deref_mut());
        if let Some(t) = timer {
            t.wait(ctx)?;
        }
        let stats: Vec<Stats> = ctx.read_buffer(&self.stats)?;
        let stats = &stats[..n];

        // Blow-up checks, in the CPU's order: the earliest substep that went non-finite or
        // overstretched, then the last substep's kinetic energy.
        let first = |get: fn(&Stats) -> u32| {
            stats
                .iter()
                .enumerate()
                .filter(|(_, s)| get(s) != 0)
                .min_by_key(|(i, s)| (get(s), *i))
                .map(|(i, s)| (i, get(s) - 1))
        };
        let nonfinite = first(|s| s.nonfinite);
        let over = first(|s| s.overstretched);
        let mass = p.mass as f64;
        let mut step2 = 0.0f64;
        let (mut contacts, mut inside, mut band_misses) = (0u32, 0u32, 0u32);
        let (mut max_depth, mut accel2) = (0.0f32, 0.0f32);
        let (mut close, mut close_max_depth) = (0u32, 0.0f32);
        for s in stats {
            // Pinned particles leave step2 and the counts at 0.
            if s.close_depth > 0.0 {
                close += 1;
                close_max_depth = close_max_depth.max(s.close_depth);
            }
            contacts += s.contacts;
            inside += s.inside;
            band_misses += s.band_misses;
            max_depth = max_depth.max(s.max_depth);
            accel2 = accel2.max(s.accel2);
            step2 += s.step2 as f64;
        }
        let ke = step2 * 0.5 * mass / (dt as f64 * dt as f64);
        let failure = match (nonfinite, over) {
            (Some((i, j)), o) if o.is_none_or(|(_, jo)| j <= jo) => {
                Some((j, format!("particle {i} reached a non-finite position")))
            }
            (_, Some((i, j))) => Some((
                j,
                format!(
                    "a spring of particle {i} stretched beyond {} times its rest length",
                    p.limits.max_stretch
                ),
            )),
            _ => {
                let limit = self.ke_limit(dt_frame);
                (ke.is_nan() || ke > limit).then(|| {
                    (
                        n_sub - 1,
                        format!("kinetic energy {ke:.3e} J grew beyond the limit {limit:.3e} J"),
                    )
                })
            }
        };
        if let Some((j, what)) = failure {
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&self.backup[0], 0, &self.bufs[pos_i], 0, bytes);
            encoder.copy_buffer_to_buffer(&self.backup[1], 0, &self.bufs[prev_i], 0, bytes);
            encoder.copy_buffer_to_buffer(&self.side_backup, 0, &self.side, 0, self.side.size());
            ctx.queue.submit([encoder.finish()]);
            ctx.wait()?;
            let bands = fields_end.iter().map(|f| (f.band, f.spec.cell));
            return Err(self.stability.blow_up(
                &self.node,
                "cloth (GPU)",
                frame,
                j,
                n_sub,
                dt,
                dt_frame,
                &what,
                BandMisses::of(band_misses, bands),
            ));
        }
        self.cur = cur;
        self.dt_prev = dt_prev;
        self.ke_last = ke;
        self.pin_from.clone_from(&self.pin_to);
        Ok(GpuClothFrameMetrics {
            frame,
            substeps: n_sub,
            dt_substep: dt,
            contacts,
            inside,
            max_depth,
            max_accel: accel2.sqrt() / (dt * dt),
            band_misses,
            kinetic: ke,
            colliders: nf as u32,
            close,
            close_max_depth,
        })
    }

    /// The CPU's kinetic-energy limit for a frame (see `ClothSim::run_frame`).
    fn ke_limit(&self, dt_frame: f32) -> f64 {
        let p = &self.params;
        let total_mass = p.mass as f64 * (self.len() - self.pinned.len()) as f64;
        let wind2 = p.wind.map_or(0.0, |w| w.velocity.length_squared());
        let (lo, hi) = self.shape.rest.iter().fold(
            (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
            |(lo, hi), p| (lo.min(*p), hi.max(*p)),
        );
        let scale = (hi - lo).length() as f64;
        let energy_scale = total_mass
            * (p.gravity.length() as f64 * scale
                + wind2 as f64
                + (scale / dt_frame as f64).powi(2));
        p.limits.energy_growth as f64 * self.ke_last.max(energy_scale)
    }
}
