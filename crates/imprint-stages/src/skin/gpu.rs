//! The GPU blends (`shaders/skin/blend.wgsl`): linear blend (LBS) and dual quaternion (DQS)
//! skinning as one compute dispatch per frame, tested against [`lbs`](super::blend::lbs) and
//! [`dqs`](super::blend::dqs) (`tests/tests/gpu_skin.rs`).
//!
//! What runs where:
//! - **Once per mesh** ([`GpuBlend::new`]): the rest positions and the [`Weights`] (as 4
//!   (bone, weight) slots per vertex, unused slots weight 0) are uploaded, the two pipelines
//!   and their bind groups made.
//! - **Per frame** ([`GpuBlend::dispatch`]): the CPU turns the bones' skin transforms
//!   (`Pose::skin`) into what the shader reads, one 64-byte record per bone: for LBS the
//!   affine's columns; for DQS the unit dual quaternion, built in f64 exactly as
//!   [`dqs`](super::blend::dqs) builds it (rotation of the 3x3 part, normalised; dual
//!   ½ t q) and then rounded to f32. That is written with one `queue.write_buffer`, and
//!   one dispatch of one invocation per vertex blends: LBS Σ w_b M_b p; DQS with the same
//!   hemisphere fix as the CPU (each bone's real part signed by its dot with the vertex's
//!   most-weighted bone's, so the GPU flips past 180° of relative twist where the CPU
//!   does), normalised, applied as a rigid motion, the pivot's transform kept where the
//!   blend's real part vanishes.
//! - **Read-back** ([`GpuBlend::positions`]) only when the CPU needs the positions (normals
//!   are then recomputed on the CPU, `Mesh::compute_normals`); [`GpuBlend::positions_buffer`]
//!   is the result for a GPU consumer.
//!
//! Precision: the shader works in f32 where the CPU works in f64 (both round to f32 at the
//! end). Measured on a unit-length limb (automatic weights; bends to 150°, twists to 270°
//! on both sides of 180°, a pose turning both bones and moving the root): max |GPU − CPU|
//! per vertex 1.0e-7 for LBS and 2.7e-7 for DQS, a few ulps of the coordinates; the tests
//! hold it to 1e-5 of the limb's length. The one place the two can differ by more is a DQS
//! vertex whose bones are within about 1e-5° of 180° apart relative to its pivot: there the
//! sign of q_b · q_pivot is decided by rounding, and f32 and f64 may pick opposite sides of
//! the (legitimate, documented) flip.
//!
//! Cost: per frame, 64 bytes per bone up, one dispatch of ⌈vertices / 64⌉ workgroups (a few
//! dozen flops and 48-112 bytes of reads per vertex), no buffer allocated. On GPU memory: 64 bytes
//! per vertex (rest, influences, posed) and 64 per bone. On Mesa lavapipe (a CPU
//! rasteriser, so not a GPU figure) one dispatch of 10k vertices takes 3-6 ms wall.

use super::weights::{MAX_INFLUENCES, Weights};
use glam::{Affine3A, DQuat, Vec3};
use imprint_core::{Error, Result};
use imprint_gpu::{GpuContext, compute_pass, shader};

/// Which blend [`GpuBlend::dispatch`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BlendMethod {
    /// Linear blend skinning ([`lbs`](super::blend::lbs)).
    Linear,
    /// Dual quaternion skinning ([`dqs`](super::blend::dqs)).
    DualQuaternion,
}

/// The shader's `Params`.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    vertices: u32,
    _pad: [u32; 3],
}

/// The shader's `Influence`: 4 bone indices, then their 4 weights.
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Influence {
    bone: [u32; 4],
    weight: [f32; 4],
}

/// The shader's `Bone`: 4 vec4 (see the shader for what they hold per method).
type BoneRecord = [[f32; 4]; 4];

/// A mesh's rest positions and weights on the GPU, skinned by a pose per dispatch.
#[derive(Debug)]
pub struct GpuBlend {
    vertices: u32,
    bones: usize,
    bone_buffer: wgpu::Buffer,
    posed: wgpu::Buffer,
    lbs: (wgpu::ComputePipeline, wgpu::BindGroup),
    dqs: (wgpu::ComputePipeline, wgpu::BindGroup),
    /// Per-frame staging of the bone records (kept to avoid an allocation a frame).
    records: Vec<BoneRecord>,
}

impl GpuBlend {
    /// Uploads `rest` (one position per vertex) and `weights` (one list per vertex, bone
    /// indices below `bones`, the rig's bone count). Refuses an empty mesh, a rig without
    /// bones, a weight list per vertex that does not match, or a bone index out of range.
    pub fn new(ctx: &GpuContext, rest: &[Vec3], weights: &Weights, bones: usize) -> Result<Self> {
        if rest.is_empty() {
            return Err(Error::Invalid(
                "GPU skinning: the mesh has no vertices".into(),
            ));
        }
        if bones == 0 {
            return Err(Error::Invalid("GPU skinning: the rig has no bones".into()));
        }
        if weights.len() != rest.len() {
            return Err(Error::Invalid(format!(
                "GPU skinning: {} weight lists for {} vertices (one per vertex)",
                weights.len(),
                rest.len()
            )));
        }
        let vertices = u32::try_from(rest.len()).map_err(|_| {
            Error::Invalid(format!(
                "GPU skinning: {} vertices, at most {} (32-bit indices)",
                rest.len(),
                u32::MAX
            ))
        })?;
        let mut influences = Vec::with_capacity(rest.len());
        for v in 0..rest.len() {
            let list = weights.of(v);
            debug_assert!(list.len() <= MAX_INFLUENCES);
            let mut inf = Influence {
                bone: [0; 4],
                weight: [0.0; 4],
            };
            for (k, &(b, w)) in list.iter().enumerate() {
                if b as usize >= bones {
                    return Err(Error::Invalid(format!(
                        "GPU skinning: vertex {v} follows bone {b}, the rig has {bones} bones"
                    )));
                }
                inf.bone[k] = b;
                inf.weight[k] = w;
            }
            // Unused slots point at the pivot with weight 0: they add nothing.
            for k in list.len()..4 {
                inf.bone[k] = inf.bone[0];
            }
            influences.push(inf);
        }
        let rest4: Vec<[f32; 4]> = rest.iter().map(|p| [p.x, p.y, p.z, 1.0]).collect();
        let rest_buffer = ctx.storage_buffer("skin rest positions", &rest4)?;
        let influence_buffer = ctx.storage_buffer("skin influences", &influences)?;
        let bone_buffer = ctx.zeroed_buffer(
            "skin bones",
            (bones * std::mem::size_of::<BoneRecord>()) as u64,
        )?;
        let posed = ctx.zeroed_buffer("skin posed positions", 16 * rest.len() as u64)?;
        let params = ctx.uniform_buffer(
            "skin params",
            &Params {
                vertices,
                _pad: [0; 3],
            },
        );
        let stage = |entry: &str| -> Result<(wgpu::ComputePipeline, wgpu::BindGroup)> {
            let pipeline = ctx.pipeline(
                "skin blend",
                &[shader!("common/dispatch.wgsl"), shader!("skin/blend.wgsl")],
                entry,
            )?;
            let bind = ctx.bind_group(
                entry,
                &pipeline,
                &[
                    (0, &params),
                    (1, &rest_buffer),
                    (2, &influence_buffer),
                    (3, &bone_buffer),
                    (4, &posed),
                ],
            );
            Ok((pipeline, bind))
        };
        Ok(GpuBlend {
            vertices,
            bones,
            lbs: stage("lbs")?,
            dqs: stage("dqs")?,
            bone_buffer,
            posed,
            records: Vec::with_capacity(bones),
        })
    }

    /// The number of vertices.
    pub fn vertices(&self) -> usize {
        self.vertices as usize
    }

    /// The number of bones each pose must have.
    pub fn bones(&self) -> usize {
        self.bones
    }

    /// Uploads the pose's skin transforms (rest space → posed space, one per bone: a rig's
    /// `Pose::skin`) and records and submits the blend. The result stays on the GPU:
    /// [`GpuBlend::positions`] reads it back.
    pub fn dispatch(
        &mut self,
        ctx: &GpuContext,
        method: BlendMethod,
        skin: &[Affine3A],
    ) -> Result<()> {
        if skin.len() != self.bones {
            return Err(Error::Invalid(format!(
                "GPU skinning: the pose has {} bone transforms, the weights were made for {} \
                 bones",
                skin.len(),
                self.bones
            )));
        }
        self.records.clear();
        match method {
            BlendMethod::Linear => self.records.extend(skin.iter().map(|m| {
                let c = |v: glam::Vec3A| [v.x, v.y, v.z, 0.0];
                [
                    c(m.matrix3.x_axis),
                    c(m.matrix3.y_axis),
                    c(m.matrix3.z_axis),
                    c(m.translation),
                ]
            })),
            BlendMethod::DualQuaternion => self.records.extend(skin.iter().map(|m| {
                let (r, d) = super::blend::dual_quat(&m.as_daffine3());
                let q = |q: DQuat| [q.x as f32, q.y as f32, q.z as f32, q.w as f32];
                [q(r), q(d), [0.0; 4], [0.0; 4]]
            })),
        }
        ctx.queue.write_buffer(
            &self.bone_buffer,
            0,
            bytemuck::cast_slice(self.records.as_slice()),
        );
        let (pipeline, bind) = match method {
            BlendMethod::Linear => &self.lbs,
            BlendMethod::DualQuaternion => &self.dqs,
        };
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("skin blend"),
            });
        {
            let mut pass = compute_pass(&mut encoder, "skin blend", None);
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, bind, &[]);
            ctx.dispatch_1d(&mut pass, self.vertices);
        }
        ctx.queue.submit([encoder.finish()]);
        Ok(())
    }

    /// The posed positions of the last [`GpuBlend::dispatch`] (zeros before the first), read
    /// back (waits for the GPU).
    pub fn positions(&self, ctx: &GpuContext) -> Result<Vec<Vec3>> {
        let raw: Vec<[f32; 4]> = ctx.read_buffer(&self.posed)?;
        Ok(raw
            .iter()
            .take(self.vertices as usize)
            .map(|p| Vec3::new(p[0], p[1], p[2]))
            .collect())
    }

    /// [`GpuBlend::dispatch`] then [`GpuBlend::positions`].
    pub fn skin(
        &mut self,
        ctx: &GpuContext,
        method: BlendMethod,
        skin: &[Affine3A],
    ) -> Result<Vec<Vec3>> {
        self.dispatch(ctx, method, skin)?;
        self.positions(ctx)
    }

    /// The posed positions on the GPU (`array<vec4<f32>>`, w = 1), for a GPU consumer.
    pub fn positions_buffer(&self) -> &wgpu::Buffer {
        &self.posed
    }
}
