//! The particle skinning's substeps on the GPU (`shaders/skin/particles.wgsl`), tested
//! against [`ParticleSkin::step_frame`] (`tests/tests/gpu_skin_particles.rs`).
//!
//! What runs where:
//! - **Once** ([`GpuParticleSkin::new`]): the CPU simulator's fixed data (CSR neighbour lists
//!   with rest lengths and signed mass weights, each entry's pair slot, each particle's first
//!   upper entry and first pair slot, rest positions, bones) and its state (positions,
//!   half-step velocities, estimated step velocities, and the tracked rotations and volume
//!   changes) are uploaded, the pipelines made, and one bind group per substep for the
//!   update (each with its own substep-number uniform).
//! - **Per frame** ([`GpuParticleSkin::step_frame`]): the CPU computes the bones' transforms
//!   at every substep boundary (rotation slerped, translation lerped: the same glam code as
//!   the CPU path, so the same f32 transforms) and uploads them in one write of
//!   (substeps + 1) × bones × 64 bytes; then one submission of 2 or 3 dispatches per substep,
//!   the CPU's passes: `rotate` (corotated springs or pressure only: each particle's rotation,
//!   one round of the iteration from its last one, and its volume change det A / det B),
//!   `pairs` / `pairs_corotated` (each pair's force once, from its lower end) and `update`
//!   (gather in list order, bone pull and damping, leap-frog, blow-up check). The blow-up flag (lowest failing
//!   particle, first failing substep) is read back at the frame's end: one 8-byte read.
//! - **Read-back** ([`GpuParticleSkin::read_positions`]) only when asked.
//!
//! - **Vertices** ([`GpuParticleSkin::vertices`]): the CPU's rule on the GPU, one invocation
//!   per vertex (the mean of its 4 particles' proposals, rest offsets turned by the bone's
//!   rotation at the last frame's end, or by the particle's own: a `particle_rotations` pass
//!   first, one round from its tracked rotation with corotated springs, 20 from its bone's
//!   with distance springs), then read back.
//!
//! Supported: every force and vertex rule of the CPU path ([`Spring::Distance`] and
//! [`Spring::Corotated`], with or without pressure; both [`VertexRotation`]s). Not here: the
//! frame metrics. The GPU copy runs on its own from the state it was made from;
//! [`GpuParticleSkin::read_into`] takes its state back into a [`ParticleSkin`] (for a
//! checkpoint: `GpuParticleSkin::new` of that skin steps on to the same bits as the GPU copy
//! that never stopped). The blow-up check reports the lowest failing
//! particle over the frame and the first failing substep (the CPU: the first substep's
//! lowest), without the distance.
//!
//! Precision: f32 on both sides; the same operations per pair and per particle in the same
//! order, so differences come from contraction (fused multiply-adds) and the GPU's `length`
//! and division. Measured on lavapipe (two-bone limb, 378 particles, 90° bend over 6 frames
//! then held): max |GPU − CPU| per particle 6e-8 to 1.2e-7 m per frame with T's set,
//! 1.2e-7 to 1.4e-7 with the defaults (corotated springs, pressure), not growing (the motion
//! is damped); per vertex up to 1.8e-7 m.
//!
//! Cost: per substep two dispatches of ⌈particles / 64⌉ workgroups; per frame one upload of
//! the substeps' bone transforms and an 8-byte read-back. GPU memory: 48 bytes per particle
//! state, 48 per particle of fixed data, 64 per particle rotation, 32 per neighbour entry,
//! 16 per pair, 64 per bone and substep, 80 + 16 per vertex.

use super::particles::{ParticleSkin, Spring, VertexRotation};
use glam::{Affine3A, Mat3A, Quat, Vec3, Vec3A};
use imprint_core::{Error, Result};
use imprint_gpu::{GpuContext, compute_pass, shader};

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    n: u32,
    bones: u32,
    h: f32,
    ks: f32,
    cs: f32,
    kb: f32,
    cb: f32,
    limit: f32,
    kv: f32,
    corotated: u32,
    verts: u32,
    vrot_particle: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Tie {
    p: [u32; 4],
    o: [[f32; 4]; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Step {
    s: u32,
    _pad: [u32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct State {
    x: [f32; 4],
    v: [f32; 4],
    ve: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Part {
    rest: [f32; 4],
    idx: [u32; 4],
    bone: [u32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Edge {
    j: u32,
    pair: u32,
    rest_len: f32,
    weight: f32,
    off: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Rot {
    q: [f32; 4],
    hx: [f32; 4],
    hy: [f32; 4],
    hz: [f32; 4],
}

type TfRecord = [[f32; 4]; 4];

/// A [`ParticleSkin`]'s particles on the GPU, stepped frame by frame.
#[derive(Debug)]
pub struct GpuParticleSkin {
    n: u32,
    bones: usize,
    substeps: u32,
    params: Params,
    params_buffer: wgpu::Buffer,
    state: wgpu::Buffer,
    /// Per particle [`Rot`]: tracked rotation, half its matrix, volume change.
    rots: wgpu::Buffer,
    tfs: wgpu::Buffer,
    bad: wgpu::Buffer,
    pairs: (wgpu::ComputePipeline, wgpu::BindGroup),
    /// Pass 0 (rotations and volume change), with corotated springs or pressure only.
    rotate: Option<(wgpu::ComputePipeline, wgpu::BindGroup)>,
    update: wgpu::ComputePipeline,
    /// Vertices: the bones' rotations at the last frame's end, the posed vertices, the
    /// particle-rotation and vertex passes.
    bone_q: wgpu::Buffer,
    verts: wgpu::Buffer,
    vertex_passes: [(wgpu::ComputePipeline, wgpu::BindGroup); 2],
    /// One per substep (its `Step` uniform differs).
    update_binds: Vec<wgpu::BindGroup>,
    records: Vec<TfRecord>,
}

fn v4(v: Vec3A) -> [f32; 4] {
    [v.x, v.y, v.z, 0.0]
}

impl GpuParticleSkin {
    /// Uploads `skin`'s fixed data and current state (a copy: the GPU then runs on its own).
    pub fn new(ctx: &GpuContext, skin: &ParticleSkin) -> Result<Self> {
        let p = skin.params();
        let corotated = p.spring == Spring::Corotated;
        let pass0 = corotated || p.volume_stiffness > 0.0;
        let (rot, half_rot, jac, rest_det, rest_off) = skin.gpu_rotation_state();
        let [start, nbr, upper, pair_start, pair_of] = skin.gpu_lists();
        let (rest_len, weight) = skin.gpu_edge_values();
        let (xa, v, ve) = skin.gpu_state();
        let rest = skin.rest_positions();
        let bone = skin.particle_bones();
        let n = u32::try_from(xa.len())
            .map_err(|_| Error::Invalid("GPU particle skinning: too many particles".into()))?;
        if n == 0 {
            return Err(Error::Invalid("GPU particle skinning: no particles".into()));
        }
        let bones = skin.gpu_bone_count();
        let states: Vec<State> = (0..xa.len())
            .map(|i| State {
                x: v4(xa[i]),
                v: v4(v[i]),
                ve: v4(ve[i]),
            })
            .collect();
        let parts: Vec<Part> = (0..xa.len())
            .map(|i| Part {
                rest: [rest[i].x, rest[i].y, rest[i].z, 0.0],
                idx: [start[i], start[i + 1], upper[i], pair_start[i]],
                bone: [
                    bone[i],
                    rest_det[i].unwrap_or(1.0).to_bits(),
                    rest_det[i].is_some() as u32,
                    0,
                ],
            })
            .collect();
        let mut edges: Vec<Edge> = (0..nbr.len())
            .map(|e| Edge {
                j: nbr[e],
                pair: pair_of[e],
                rest_len: rest_len[e],
                weight: weight[e],
                off: v4(rest_off[e]),
            })
            .collect();
        if edges.is_empty() {
            edges.push(bytemuck::Zeroable::zeroed());
        }
        let pairs_n = (pair_start[xa.len()] as u64).max(1);
        let substeps = p.substeps;
        let params = Params {
            n,
            bones: bones as u32,
            h: 0.0,
            ks: p.stiffness,
            cs: p.damping,
            kb: p.bone_stiffness,
            cb: p.bone_damping,
            limit: skin.gpu_deviation_limit(),
            kv: p.volume_stiffness,
            corotated: corotated as u32,
            verts: 0,
            vrot_particle: (p.vertex_rotation == VertexRotation::Particle) as u32,
        };
        let rots: Vec<Rot> = (0..xa.len())
            .map(|i| {
                let h = half_rot[i];
                let mut hx = v4(h.x_axis);
                hx[3] = jac[i];
                Rot {
                    q: rot[i].to_array(),
                    hx,
                    hy: v4(h.y_axis),
                    hz: v4(h.z_axis),
                }
            })
            .collect();
        let rot_buffer = ctx.storage_buffer("particles rotations", &rots)?;
        let params_buffer = ctx.uniform_buffer("particles params", &params);
        let state = ctx.storage_buffer("particles state", &states)?;
        let part = ctx.storage_buffer("particles fixed", &parts)?;
        let edge = ctx.storage_buffer("particles edges", &edges)?;
        let pair_f = ctx.zeroed_buffer("particles pair forces", 16 * pairs_n)?;
        let tf_bytes =
            (substeps as u64 + 1) * bones as u64 * std::mem::size_of::<TfRecord>() as u64;
        let tfs = ctx.zeroed_buffer("particles bone transforms", tf_bytes)?;
        let bad = ctx.storage_buffer("particles blow-up", &[u32::MAX, u32::MAX])?;
        let sources = [
            shader!("common/dispatch.wgsl"),
            shader!("skin/particles.wgsl"),
        ];
        let (pairs_pipeline, pairs_bind, rotate) = if pass0 {
            let rp = ctx.pipeline("particles rotate", &sources, "rotate")?;
            let rb = ctx.bind_group(
                "particles rotate",
                &rp,
                &[
                    (0, &params_buffer),
                    (2, &state),
                    (3, &part),
                    (4, &edge),
                    (8, &rot_buffer),
                ],
            );
            let pp = ctx.pipeline("particles pairs", &sources, "pairs_corotated")?;
            let pb = ctx.bind_group(
                "particles pairs",
                &pp,
                &[
                    (0, &params_buffer),
                    (2, &state),
                    (3, &part),
                    (4, &edge),
                    (5, &pair_f),
                    (8, &rot_buffer),
                ],
            );
            (pp, pb, Some((rp, rb)))
        } else {
            let pp = ctx.pipeline("particles pairs", &sources, "pairs")?;
            let pb = ctx.bind_group(
                "particles pairs",
                &pp,
                &[
                    (0, &params_buffer),
                    (2, &state),
                    (3, &part),
                    (4, &edge),
                    (5, &pair_f),
                ],
            );
            (pp, pb, None)
        };
        let update = ctx.pipeline("particles update", &sources, "update")?;
        let update_binds = (0..substeps)
            .map(|s| {
                let step = ctx.uniform_buffer("particles step", &Step { s, _pad: [0; 3] });
                ctx.bind_group(
                    "particles update",
                    &update,
                    &[
                        (0, &params_buffer),
                        (1, &step),
                        (2, &state),
                        (3, &part),
                        (4, &edge),
                        (5, &pair_f),
                        (6, &tfs),
                        (7, &bad),
                    ],
                )
            })
            .collect();
        let (vp, vo) = skin.gpu_vertex_ties();
        let mut ties: Vec<Tie> = vp
            .iter()
            .zip(vo)
            .map(|(ps, os)| Tie {
                p: *ps,
                o: os.map(|o| [o.x, o.y, o.z, 0.0]),
            })
            .collect();
        let verts_n = u32::try_from(ties.len())
            .map_err(|_| Error::Invalid("GPU particle skinning: too many vertices".into()))?;
        if ties.is_empty() {
            ties.push(bytemuck::Zeroable::zeroed());
        }
        let mut params = params;
        params.verts = verts_n;
        ctx.queue
            .write_buffer(&params_buffer, 0, bytemuck::bytes_of(&params));
        let tie_buffer = ctx.storage_buffer("particles vertex ties", &ties)?;
        // The bones' rotations at the last frame's end, as the skin has them (the vertices
        // before the first GPU frame turn offsets by these).
        let bone_rot: Vec<[f32; 4]> = skin.bone_rotations().iter().map(|q| q.to_array()).collect();
        let bone_q = ctx.storage_buffer("particles bone rotations", &bone_rot)?;
        let prot = ctx.zeroed_buffer("particles vertex rotations", 16 * n as u64)?;
        let verts = ctx.zeroed_buffer("particles vertices", 16 * ties.len() as u64)?;
        let vertex_passes = [("particle_rotations", 0), ("vertices", 1)].map(|(entry, k)| {
            let pl = ctx.pipeline("particles vertices", &sources, entry)?;
            let list: Vec<(u32, &wgpu::Buffer)> = if k == 0 {
                vec![
                    (0, &params_buffer),
                    (2, &state),
                    (3, &part),
                    (4, &edge),
                    (8, &rot_buffer),
                    (9, &bone_q),
                    (10, &prot),
                ]
            } else {
                vec![
                    (0, &params_buffer),
                    (2, &state),
                    (3, &part),
                    (9, &bone_q),
                    (10, &prot),
                    (11, &tie_buffer),
                    (12, &verts),
                ]
            };
            let bg = ctx.bind_group(entry, &pl, &list);
            Ok::<_, Error>((pl, bg))
        });
        let [a, b] = vertex_passes;
        let vertex_passes = [a?, b?];
        Ok(GpuParticleSkin {
            bone_q,
            verts,
            vertex_passes,
            n,
            bones,
            substeps,
            params,
            params_buffer,
            state,
            rots: rot_buffer,
            tfs,
            bad,
            pairs: (pairs_pipeline, pairs_bind),
            rotate,
            update,
            update_binds,
            records: Vec::new(),
        })
    }

    /// The number of particles.
    pub fn particles(&self) -> usize {
        self.n as usize
    }

    /// One frame of substeps on the GPU, as [`ParticleSkin::step_frame`] (`start`, `end`: the
    /// bones' skinning transforms at the frame's start and end). Waits for the GPU (the
    /// blow-up flag is read back).
    pub fn step_frame(
        &mut self,
        ctx: &GpuContext,
        start: &[Affine3A],
        end: &[Affine3A],
        frame: u32,
        dt_frame: f32,
    ) -> Result<()> {
        if start.len() != self.bones || end.len() != self.bones {
            return Err(Error::Invalid(format!(
                "GPU particle skinning: {} bones, but {} start and {} end transforms",
                self.bones,
                start.len(),
                end.len()
            )));
        }
        if start.iter().chain(end).any(|m| !m.is_finite()) {
            return Err(Error::Invalid(
                "GPU particle skinning: a bone's skinning transform is not finite".into(),
            ));
        }
        if !(dt_frame.is_finite() && dt_frame > 0.0) {
            return Err(Error::Invalid(format!(
                "GPU particle skinning: frame length {dt_frame} s must be > 0"
            )));
        }
        // The CPU path's substep transforms, bit for bit (same glam calls).
        let split = |m: &Affine3A| {
            let (_, r, t) = m.to_scale_rotation_translation();
            (r.normalize(), t)
        };
        let s0: Vec<(Quat, Vec3)> = start.iter().map(split).collect();
        let s1: Vec<(Quat, Vec3)> = end.iter().map(split).collect();
        let substeps = self.substeps;
        self.records.clear();
        for s in 0..=substeps {
            let u = s as f32 / substeps as f32;
            for (&(q0, t0), &(q1, t1)) in s0.iter().zip(&s1) {
                let q = if q0.dot(q1) < 0.0 { -q1 } else { q1 };
                let m = Affine3A::from_rotation_translation(q0.slerp(q, u), t0.lerp(t1, u));
                self.records.push([
                    v4(m.matrix3.x_axis),
                    v4(m.matrix3.y_axis),
                    v4(m.matrix3.z_axis),
                    v4(m.translation),
                ]);
            }
        }
        ctx.queue
            .write_buffer(&self.tfs, 0, bytemuck::cast_slice(self.records.as_slice()));
        self.params.h = dt_frame / substeps as f32;
        ctx.queue
            .write_buffer(&self.params_buffer, 0, bytemuck::bytes_of(&self.params));
        ctx.queue
            .write_buffer(&self.bad, 0, bytemuck::cast_slice(&[u32::MAX, u32::MAX]));
        let end_q: Vec<[f32; 4]> = s1.iter().map(|&(q, _)| q.to_array()).collect();
        ctx.queue
            .write_buffer(&self.bone_q, 0, bytemuck::cast_slice(end_q.as_slice()));
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("particles frame"),
            });
        for s in 0..substeps as usize {
            if let Some((pipeline, bind)) = &self.rotate {
                let mut pass = compute_pass(&mut encoder, "particles rotate", None);
                pass.set_pipeline(pipeline);
                pass.set_bind_group(0, bind, &[]);
                ctx.dispatch_1d(&mut pass, self.n);
            }
            {
                let mut pass = compute_pass(&mut encoder, "particles pairs", None);
                pass.set_pipeline(&self.pairs.0);
                pass.set_bind_group(0, &self.pairs.1, &[]);
                ctx.dispatch_1d(&mut pass, self.n);
            }
            {
                let mut pass = compute_pass(&mut encoder, "particles update", None);
                pass.set_pipeline(&self.update);
                pass.set_bind_group(0, &self.update_binds[s], &[]);
                ctx.dispatch_1d(&mut pass, self.n);
            }
        }
        ctx.queue.submit([encoder.finish()]);
        let bad: Vec<u32> = ctx.read_buffer(&self.bad)?;
        if bad[0] != u32::MAX {
            return Err(Error::Numerical {
                node: "skin (GPU)".into(),
                frame,
                message: format!(
                    "GPU particle skinning blew up: particle {} is non-finite or past the \
                     deviation limit {} m from its bone's target, first at substep {} of \
                     {substeps}",
                    bad[0],
                    self.params.limit,
                    bad[1] + 1
                ),
                hint: format!(
                    "raise substeps (now {substeps}); the time step is past the stable limit"
                ),
            });
        }
        Ok(())
    }

    /// The posed vertices (the CPU's [`ParticleSkin::vertices`] rule: the mean of the 4
    /// particles' proposals, offsets turned by the particle's or the bone's rotation), in
    /// the rest mesh's order (waits for the GPU).
    pub fn vertices(&self, ctx: &GpuContext) -> Result<Vec<Vec3>> {
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("particles vertices"),
            });
        for (k, (pipeline, bind)) in self.vertex_passes.iter().enumerate() {
            if k == 0 && self.params.vrot_particle == 0 {
                continue;
            }
            let mut pass = compute_pass(&mut encoder, "particles vertices", None);
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            ctx.dispatch_1d(&mut pass, if k == 0 { self.n } else { self.params.verts });
        }
        ctx.queue.submit([encoder.finish()]);
        let raw: Vec<[f32; 4]> = ctx.read_buffer(&self.verts)?;
        Ok(raw
            .iter()
            .take(self.params.verts as usize)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect())
    }

    /// Reads the GPU's particle state back into `skin` (the skin it was made from, or a copy
    /// of it): positions, half-step velocities, estimated step velocities, tracked
    /// rotations (and half their matrices), volume changes, and the bones' rotations at the
    /// last frame's end — everything the GPU carries from one frame to the next. Then
    /// `skin` is where this GPU skin is: [`ParticleSkin::positions`] and
    /// [`ParticleSkin::vertices`] give its state (to the CPU's rounding for the vertices),
    /// a checkpoint of it restores this GPU skin, and `GpuParticleSkin::new(ctx, &skin)`
    /// steps on to the same bits as this one. Waits for the GPU (three read-backs: 48 + 64
    /// bytes per particle, 16 per bone).
    pub fn read_into(&self, ctx: &GpuContext, skin: &mut ParticleSkin) -> Result<()> {
        let n = self.n as usize;
        let verts = skin.gpu_vertex_ties().0.len();
        if skin.gpu_state().0.len() != n
            || skin.gpu_bone_count() != self.bones
            || verts != self.params.verts as usize
        {
            return Err(Error::Invalid(format!(
                "GPU particle skinning: a GPU skin of {n} particles, {} bones and {} vertices \
                 cannot be read into a skin of {} particles, {} bones and {verts} vertices",
                self.bones,
                self.params.verts,
                skin.gpu_state().0.len(),
                skin.gpu_bone_count(),
            )));
        }
        let states: Vec<State> = ctx.read_buffer(&self.state)?;
        let rots: Vec<Rot> = ctx.read_buffer(&self.rots)?;
        let bone_q: Vec<[f32; 4]> = ctx.read_buffer(&self.bone_q)?;
        let a3 = |v: [f32; 4]| Vec3A::new(v[0], v[1], v[2]);
        let (x, xa, v, ve, rot, half_rot, jac, bone_rot) = skin.gpu_state_mut();
        for (i, st) in states.iter().take(n).enumerate() {
            xa[i] = a3(st.x);
            x[i] = xa[i].into();
            v[i] = a3(st.v);
            ve[i] = a3(st.ve);
        }
        for (i, r) in rots.iter().take(n).enumerate() {
            rot[i] = Quat::from_array(r.q);
            half_rot[i] = Mat3A::from_cols(a3(r.hx), a3(r.hy), a3(r.hz));
            jac[i] = r.hx[3];
        }
        for (b, q) in bone_rot.iter_mut().zip(&bone_q) {
            *b = Quat::from_array(*q);
        }
        Ok(())
    }

    /// The particles' positions (waits for the GPU).
    pub fn read_positions(&self, ctx: &GpuContext) -> Result<Vec<Vec3>> {
        let raw: Vec<State> = ctx.read_buffer(&self.state)?;
        Ok(raw
            .iter()
            .take(self.n as usize)
            .map(|s| Vec3::new(s.x[0], s.x[1], s.x[2]))
            .collect())
    }
}
