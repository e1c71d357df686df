//! GPU rasterisation: depth maps ([`GpuRasterizer`], the twin of
//! `imprint_core::raster::rasterize_depth_with`, read back as a `DepthMap` or left on the
//! device for a consumer there as a [`GpuDepthMap`]), and what every raster pass shares: the camera
//! uniform ([`GpuView`], one projection convention for all of them), render shader modules
//! ([`shader_module`]), error-checked creation ([`checked`]), vertex and index buffers that
//! grow and are reused ([`GrowingBuffer`]), and texture readback ([`TextureReadback`]).
//!
//! # Depth maps, and where their depth comes from
//!
//! One render pass draws the mesh into a Depth32Float buffer (the nearest-surface test) and an
//! Rg32Float colour target that receives, per covered pixel, (view depth, 1); the colour target
//! is cleared to 0, so its second channel is the coverage and its first the depth map.
//!
//! The view depth is neither read from the depth buffer (whose non-linear encoding, with the
//! default 1e-3 near plane, resolves depth d only to about `6e-8 * d² / near`) nor the
//! hardware's interpolated varying: a GPU interpolates over its snapped vertices (NVIDIA's
//! does; lavapipe's interpolates over the unsnapped ones), and on a steep triangle the snap
//! times the slope moved heights by 2.6 mm on an H100 where the CPU's plane (fitted through
//! the unsnapped vertices) did not move. So the vertex stage pulls the whole triangle from
//! storage buffers, computes the CPU's pixel coordinates and depth plane (`shaders/render/
//! depth.wgsl`), and each fragment evaluates that plane at its pixel centre and writes the
//! result to the depth buffer as well, so the nearest-surface decision follows it too. The
//! depth buffer uses reversed depth for perspective cameras (near → 1, far → 0), which keeps
//! ~24 bits of relative precision at every distance; orthographic cameras keep the
//! conventional mapping, which is linear and precise there (`shaders/render/camera.wgsl`).
//!
//! Coverage follows the hardware rules that the CPU rasteriser copies: pixel centres at +0.5,
//! the top-left fill rule, 1/256-pixel vertex snapping, clipping at the near and far planes,
//! earlier triangles winning exact ties (strict depth test, draws in order). On lavapipe and
//! on an H100 the coverage is identical to the CPU's on every test scene, and on lavapipe the
//! depth agrees to 1e-6 world units or better (99th percentile ≤ 4.8e-7); other hardware may
//! differ on a few silhouette pixels, where a pixel centre lies within rounding of an edge
//! (`tests/tests/gpu_raster.rs`). The plane is not clamped to the triangle's depths: where
//! snapping covers a pixel centre just outside the triangle, the CPU extrapolates it too.

use crate::{GpuContext, shader};
use imprint_core::camera::Camera;
use imprint_core::error::human_bytes;
use imprint_core::raster::{DepthMap, RasterOptions};
use imprint_core::{Error, Mesh, Result};

/// Format of every depth buffer of the raster passes.
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Depth32Float;
/// Format of the depth-map colour target: (view depth, coverage).
const DEPTH_MAP_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rg32Float;

/// The camera uniform of the raster shaders, mirroring `View` in `shaders/render/camera.wgsl`:
/// world → view coordinates exactly as `Frame::to_view`, then clip space with the depth
/// mapping described there (reversed for perspective cameras).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuView {
    /// xyz: the eye; w: 1 for perspective, 0 for orthographic.
    pub eye: [f32; 4],
    /// xyz: camera right; w: clip x per view x (per unit of view depth for perspective).
    pub right: [f32; 4],
    /// xyz: camera up; w: clip y per view y.
    pub up: [f32; 4],
    /// xyz: the unit viewing direction; w: unused.
    pub forward: [f32; 4],
    /// x, y: `z_clip = x * d + y`; z: relative and w: absolute depth bias of lines.
    pub depth: [f32; 4],
}

impl GpuView {
    /// The uniform for `camera` on an image of `aspect = width / height`, without line bias.
    pub fn new(camera: &Camera, aspect: f32) -> Self {
        let f = camera.frame();
        let (n, far) = (camera.near as f64, camera.far as f64);
        let hh = camera.half_height_scale();
        let persp = camera.is_perspective();
        // Reversed for perspective: z_ndc = n (far - d) / (d (far - n)), so z_clip (w = d) is
        // linear in d. Conventional for orthographic: z_ndc = (d - n) / (far - n), w = 1.
        let (a, b) = if persp {
            (-n / (far - n), n * far / (far - n))
        } else {
            (1.0 / (far - n), -n / (far - n))
        };
        GpuView {
            eye: f.eye.extend(if persp { 1.0 } else { 0.0 }).to_array(),
            right: f.right.extend(1.0 / (hh * aspect)).to_array(),
            up: f.up.extend(1.0 / hh).to_array(),
            forward: f.forward.extend(0.0).to_array(),
            depth: [a as f32, b as f32, 0.0, 0.0],
        }
    }

    /// The same view with the depth bias lines are tested with (see `shaders/render/line.wgsl`).
    pub fn with_line_bias(mut self, relative: f32, absolute: f32) -> Self {
        self.depth[2] = relative;
        self.depth[3] = absolute;
        self
    }

    /// Whether depth is reversed (perspective cameras): the nearer surface has the greater
    /// depth value.
    pub fn reversed(&self) -> bool {
        self.eye[3] != 0.0
    }

    /// The depth test that keeps the nearer surface (`or_equal` for passes drawn over the
    /// surfaces without writing depth, such as lines).
    pub fn depth_compare(reversed: bool, or_equal: bool) -> wgpu::CompareFunction {
        use wgpu::CompareFunction::*;
        match (reversed, or_equal) {
            (true, false) => Greater,
            (true, true) => GreaterEqual,
            (false, false) => Less,
            (false, true) => LessEqual,
        }
    }

    /// The depth buffer's clear value: the far plane.
    pub fn depth_clear(&self) -> f32 {
        if self.reversed() { 0.0 } else { 1.0 }
    }
}

/// Runs `make` (resource or pipeline creation) inside validation and out-of-memory error
/// scopes, so that a mistake or a failed allocation is an [`Error::Gpu`] naming `what`
/// instead of a wgpu panic.
pub fn checked<T>(ctx: &GpuContext, what: &str, make: impl FnOnce() -> T) -> Result<T> {
    let oom = ctx.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let invalid = ctx.device.push_error_scope(wgpu::ErrorFilter::Validation);
    let value = make();
    let e1 = pollster::block_on(invalid.pop());
    let e2 = pollster::block_on(oom.pop());
    match e1.or(e2) {
        None => Ok(value),
        Some(e) => Err(Error::Gpu(format!("{what} on {}: {e}", ctx.adapter_name()))),
    }
}

/// A shader module from WGSL sources concatenated in order (shared helpers first, as for
/// compute pipelines); errors come back as [`Error::Gpu`] with naga's message.
pub fn shader_module(
    ctx: &GpuContext,
    label: &str,
    sources: &[&str],
) -> Result<wgpu::ShaderModule> {
    let source = sources.join("\n");
    checked(ctx, &format!("shader '{label}'"), || {
        ctx.device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(label),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
    })
}

/// Refuses an image larger than the device's textures can be, naming the limit.
pub fn check_image_size(ctx: &GpuContext, what: &str, width: u32, height: u32) -> Result<()> {
    let max = ctx.limits.max_texture_dimension_2d;
    for (name, v) in [("width", width), ("height", height)] {
        if v == 0 {
            return Err(Error::Invalid(format!(
                "{what}: {name} must be at least 1, got 0"
            )));
        }
        if v > max {
            return Err(Error::Invalid(format!(
                "{what}: {name} {v} exceeds the largest texture of {} (max_texture_dimension_2d \
                 = {max}); lower the {name} or use the CPU path",
                ctx.adapter_name()
            )));
        }
    }
    Ok(())
}

/// A GPU buffer rewritten from the CPU on every use, replaced by a larger one (the next power
/// of two) only when the data outgrows it: per-frame vertex and index data without
/// per-frame allocation.
#[derive(Debug)]
pub struct GrowingBuffer {
    label: &'static str,
    usage: wgpu::BufferUsages,
    buffer: Option<wgpu::Buffer>,
}

impl GrowingBuffer {
    /// An empty buffer for `usage` (`COPY_DST` is added).
    pub fn new(label: &'static str, usage: wgpu::BufferUsages) -> Self {
        GrowingBuffer {
            label,
            usage: usage | wgpu::BufferUsages::COPY_DST,
            buffer: None,
        }
    }

    /// Writes `data` at the start of the buffer (queued: it lands before the next submission),
    /// growing it first if needed; returns the buffer, which may be longer than `data`.
    pub fn write<T: bytemuck::Pod>(
        &mut self,
        ctx: &GpuContext,
        data: &[T],
    ) -> Result<&wgpu::Buffer> {
        let bytes: &[u8] = bytemuck::cast_slice(data);
        let len = (bytes.len() as u64).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        if self.buffer.as_ref().is_none_or(|b| b.size() < len) {
            let limit = ctx.limits.max_buffer_size;
            if len > limit {
                return Err(Error::TooLarge {
                    what: format!(
                        "{} (one GPU buffer; {} allows at most {})",
                        self.label,
                        ctx.adapter_name(),
                        human_bytes(limit)
                    ),
                    needed: len,
                    available: limit,
                });
            }
            let size = len
                .max(256)
                .checked_next_power_of_two()
                .unwrap_or(len)
                .min(limit);
            self.buffer = None;
            self.buffer = Some(checked(ctx, self.label, || {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(self.label),
                    size,
                    usage: self.usage,
                    mapped_at_creation: false,
                })
            })?);
        }
        let buffer = self.buffer.as_ref().expect("allocated above");
        if bytes
            .len()
            .is_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT as usize)
        {
            ctx.queue.write_buffer(buffer, 0, bytes);
        } else {
            let mut padded = bytes.to_vec();
            padded.resize(len as usize, 0);
            ctx.queue.write_buffer(buffer, 0, &padded);
        }
        Ok(buffer)
    }
}

/// Copies a 2D texture into a buffer and back to the CPU: rows padded to 256 bytes on the GPU
/// (`COPY_BYTES_PER_ROW_ALIGNMENT`), tightly packed, top row first, on the CPU. Made once per
/// image size and reused.
#[derive(Debug)]
pub struct TextureReadback {
    width: u32,
    height: u32,
    bytes_per_pixel: u32,
    padded_row: u32,
    buffer: wgpu::Buffer,
}

impl TextureReadback {
    pub fn new(ctx: &GpuContext, width: u32, height: u32, bytes_per_pixel: u32) -> Result<Self> {
        let row = width as u64 * bytes_per_pixel as u64;
        let padded_row = row.next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT as u64);
        let size = padded_row * height as u64;
        let limit = ctx.limits.max_buffer_size;
        if size > limit || padded_row > u32::MAX as u64 {
            return Err(Error::TooLarge {
                what: format!(
                    "readback of a {width}x{height} image (one GPU buffer; {} allows at most {})",
                    ctx.adapter_name(),
                    human_bytes(limit)
                ),
                needed: size,
                available: limit,
            });
        }
        // STORAGE too: a consumer on the device may read the copied pixels where they are
        // (`GpuRasterizer::depth_map_resident`).
        let buffer = checked(ctx, "readback buffer", || {
            ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("imprint texture readback"),
                size,
                usage: wgpu::BufferUsages::COPY_DST
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::STORAGE,
                mapped_at_creation: false,
            })
        })?;
        Ok(TextureReadback {
            width,
            height,
            bytes_per_pixel,
            padded_row: padded_row as u32,
            buffer,
        })
    }

    /// Records the copy of mip 0 of `texture` (of this readback's size) into the buffer.
    pub fn copy(&self, encoder: &mut wgpu::CommandEncoder, texture: &wgpu::Texture) {
        encoder.copy_texture_to_buffer(
            texture.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &self.buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(self.padded_row),
                    rows_per_image: Some(self.height),
                },
            },
            wgpu::Extent3d {
                width: self.width,
                height: self.height,
                depth_or_array_layers: 1,
            },
        );
    }

    /// The buffer the pixels are copied into: rows of [`TextureReadback::padded_row_bytes`],
    /// top row first (usable as a storage binding).
    pub fn buffer(&self) -> &wgpu::Buffer {
        &self.buffer
    }

    /// Bytes from one row of the copy to the next (a multiple of 256).
    pub fn padded_row_bytes(&self) -> u32 {
        self.padded_row
    }

    /// Waits for the GPU and returns the copied pixels, tightly packed, top row first (through
    /// [`GpuContext::read_buffer`], which maps a staging copy and counts it).
    pub fn read(&self, ctx: &GpuContext) -> Result<Vec<u8>> {
        let padded: Vec<u8> = ctx.read_buffer(&self.buffer)?;
        let row = (self.width * self.bytes_per_pixel) as usize;
        if row == self.padded_row as usize {
            return Ok(padded);
        }
        let mut out = Vec::with_capacity(row * self.height as usize);
        for r in padded.chunks_exact(self.padded_row as usize) {
            out.extend_from_slice(&r[..row]);
        }
        Ok(out)
    }
}

/// A 2D render attachment of `format` (`sample_count` 1 or 4).
pub fn render_texture(
    ctx: &GpuContext,
    label: &str,
    width: u32,
    height: u32,
    format: wgpu::TextureFormat,
    sample_count: u32,
    usage: wgpu::TextureUsages,
) -> Result<wgpu::Texture> {
    let plain = [format.remove_srgb_suffix()];
    let view_formats: &[wgpu::TextureFormat] = if plain[0] != format { &plain } else { &[] };
    checked(ctx, &format!("{label} ({width}x{height})"), || {
        ctx.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: usage | wgpu::TextureUsages::RENDER_ATTACHMENT,
            // An sRGB image can also be viewed as its plain bytes (a UI library showing it).
            view_formats,
        })
    })
}

/// The attachments and readback of one image size.
#[derive(Debug)]
struct Target {
    width: u32,
    height: u32,
    color: wgpu::TextureView,
    color_texture: wgpu::Texture,
    depth: wgpu::TextureView,
    readback: TextureReadback,
}

/// Depth maps on the GPU, the twin of `imprint_core::raster::rasterize_depth_with` (see the
/// module doc for the method and where the two may differ). Long-lived: the shader and
/// pipelines are built once, the vertex and index buffers grow and are reused, the render
/// targets are kept while the image size stays the same. Use it with the context it was made
/// with.
#[derive(Debug)]
pub struct GpuRasterizer {
    device: wgpu::Device,
    module: wgpu::ShaderModule,
    layout: wgpu::PipelineLayout,
    /// By `reversed as usize * 2 + cull_back as usize`, built on first use.
    pipelines: [Option<wgpu::RenderPipeline>; 4],
    group: wgpu::BindGroupLayout,
    view: wgpu::Buffer,
    /// The image's size, centre and scale (`Image` in depth.wgsl).
    image: wgpu::Buffer,
    vertices: GrowingBuffer,
    indices: GrowingBuffer,
    target: Option<Target>,
}

impl GpuRasterizer {
    pub fn new(ctx: &GpuContext) -> Result<Self> {
        let module = shader_module(
            ctx,
            "render/depth.wgsl",
            &[
                shader!("render/camera.wgsl"),
                shader!("common/geom.wgsl"),
                shader!("render/depth.wgsl"),
            ],
        )?;
        let entry = |binding, visibility, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let storage = wgpu::BufferBindingType::Storage { read_only: true };
        let uniform = wgpu::BufferBindingType::Uniform;
        let (vertex, fragment) = (wgpu::ShaderStages::VERTEX, wgpu::ShaderStages::FRAGMENT);
        // The view, the image size, and the mesh pulled by the vertex stage (depth.wgsl).
        let group = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("depth map"),
                entries: &[
                    entry(0, vertex | fragment, uniform),
                    entry(1, vertex | fragment, uniform),
                    entry(2, vertex, storage),
                    entry(3, vertex, storage),
                ],
            });
        let layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("depth map"),
                bind_group_layouts: &[Some(&group)],
                immediate_size: 0,
            });
        let view = ctx.uniform_buffer("depth map view", &<GpuView as bytemuck::Zeroable>::zeroed());
        let image = ctx.uniform_buffer("depth map image", &[0.0f32; 8]);
        let storage = wgpu::BufferUsages::STORAGE;
        Ok(GpuRasterizer {
            device: ctx.device.clone(),
            module,
            layout,
            group,
            pipelines: Default::default(),
            view,
            image,
            vertices: GrowingBuffer::new("depth map vertices", storage),
            indices: GrowingBuffer::new("depth map indices", storage),
            target: None,
        })
    }

    /// The pass's bind group: made per map, as the mesh buffers may have grown.
    fn bind_group(
        &self,
        ctx: &GpuContext,
        vertices: &wgpu::Buffer,
        indices: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        let buffers = [&self.view, &self.image, vertices, indices];
        let entries: Vec<wgpu::BindGroupEntry> = (0u32..)
            .zip(buffers)
            .map(|(binding, buffer)| wgpu::BindGroupEntry {
                binding,
                resource: buffer.as_entire_binding(),
            })
            .collect();
        ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("depth map"),
            layout: &self.group,
            entries: &entries,
        })
    }

    fn pipeline(
        &mut self,
        ctx: &GpuContext,
        reversed: bool,
        cull_back: bool,
    ) -> Result<wgpu::RenderPipeline> {
        let key = reversed as usize * 2 + cull_back as usize;
        if let Some(p) = &self.pipelines[key] {
            return Ok(p.clone());
        }
        let p = checked(ctx, "depth map pipeline", || {
            ctx.device
                .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                    label: Some("depth map"),
                    layout: Some(&self.layout),
                    vertex: wgpu::VertexState {
                        module: &self.module,
                        entry_point: Some("vs_depth"),
                        compilation_options: Default::default(),
                        // Pulled from storage buffers (depth.wgsl).
                        buffers: &[],
                    },
                    primitive: wgpu::PrimitiveState {
                        topology: wgpu::PrimitiveTopology::TriangleList,
                        // Counter-clockwise as seen by the camera is the front, as on the CPU.
                        front_face: wgpu::FrontFace::Ccw,
                        cull_mode: cull_back.then_some(wgpu::Face::Back),
                        ..Default::default()
                    },
                    depth_stencil: Some(wgpu::DepthStencilState {
                        format: DEPTH_FORMAT,
                        depth_write_enabled: Some(true),
                        depth_compare: Some(GpuView::depth_compare(reversed, false)),
                        stencil: Default::default(),
                        bias: Default::default(),
                    }),
                    multisample: Default::default(),
                    fragment: Some(wgpu::FragmentState {
                        module: &self.module,
                        entry_point: Some("fs_depth"),
                        compilation_options: Default::default(),
                        targets: &[Some(DEPTH_MAP_FORMAT.into())],
                    }),
                    multiview_mask: None,
                    cache: None,
                })
        })?;
        self.pipelines[key] = Some(p.clone());
        Ok(p)
    }

    fn target(&mut self, ctx: &GpuContext, width: u32, height: u32) -> Result<&Target> {
        let stale = self
            .target
            .as_ref()
            .is_none_or(|t| (t.width, t.height) != (width, height));
        if stale {
            self.target = None;
            let color_texture = render_texture(
                ctx,
                "depth map",
                width,
                height,
                DEPTH_MAP_FORMAT,
                1,
                wgpu::TextureUsages::COPY_SRC,
            )?;
            let depth = render_texture(
                ctx,
                "depth buffer",
                width,
                height,
                DEPTH_FORMAT,
                1,
                wgpu::TextureUsages::empty(),
            )?;
            self.target = Some(Target {
                width,
                height,
                color: color_texture.create_view(&Default::default()),
                color_texture,
                depth: depth.create_view(&Default::default()),
                readback: TextureReadback::new(ctx, width, height, 8)?,
            });
        }
        Ok(self.target.as_ref().expect("made above"))
    }

    /// The depth map of `mesh` seen by `camera` on a `width` × `height` image: view depth
    /// (`f32::INFINITY` where uncovered) and coverage, row 0 on top, as
    /// `imprint_core::raster::rasterize_depth_with` makes it. Errors: an invalid camera or
    /// mesh (the CPU's messages), a size of 0 or beyond the device's largest texture (naming
    /// the limit), a context other than the one this rasteriser was made with.
    ///
    /// The map is read back (its padded rows, 8 bytes a pixel): for CPU consumers. A consumer
    /// on the device takes [`GpuRasterizer::depth_map_resident`] instead.
    pub fn depth_map(
        &mut self,
        ctx: &GpuContext,
        mesh: &Mesh,
        camera: &Camera,
        width: u32,
        height: u32,
        opts: &RasterOptions,
    ) -> Result<DepthMap> {
        self.depth_map_resident(ctx, mesh, camera, width, height, opts)?
            .to_cpu(ctx)
    }

    /// [`GpuRasterizer::depth_map`] left on the device: the same render and the same copy of
    /// its texels into a buffer, which a consumer's passes read where it is (nothing is read
    /// back). The map lives in this rasteriser's buffer: it borrows the rasteriser, so the
    /// next map cannot be rendered over it while it is in use; a consumer submits its passes
    /// before asking for the next map (the queue runs them in order).
    pub fn depth_map_resident(
        &mut self,
        ctx: &GpuContext,
        mesh: &Mesh,
        camera: &Camera,
        width: u32,
        height: u32,
        opts: &RasterOptions,
    ) -> Result<GpuDepthMap<'_>> {
        if ctx.device != self.device {
            return Err(Error::Invalid(
                "GpuRasterizer used with another GPU context than it was made with".into(),
            ));
        }
        camera.validate()?;
        check_image_size(ctx, "GPU rasteriser", width, height)?;
        mesh.validate("rasterised mesh")?;
        let view = GpuView::new(camera, width as f32 / height as f32);
        let pipeline = self.pipeline(ctx, view.reversed(), opts.cull_back)?;
        ctx.queue
            .write_buffer(&self.view, 0, bytemuck::bytes_of(&view));
        // `Image` in depth.wgsl: the CPU's Projector numbers, bit for bit.
        let k = height as f32 / (2.0 * camera.half_height_scale());
        let (w, h) = (width as f32, height as f32);
        let image = [w, h, 0.5 * w, 0.5 * h, k, 0.0, 0.0, 0.0];
        ctx.queue
            .write_buffer(&self.image, 0, bytemuck::bytes_of(&image));
        let index_count = u32::try_from(mesh.triangles.len() * 3).map_err(|_| {
            Error::Invalid(format!(
                "GPU rasteriser: {} triangles do not fit 32-bit draw counts",
                mesh.triangles.len()
            ))
        })?;
        let positions: &[[f32; 3]] = bytemuck::cast_slice(&mesh.positions);
        let vertices = self.vertices.write(ctx, positions)?.clone();
        let indices = self.indices.write(ctx, &mesh.triangles)?.clone();
        let bind = self.bind_group(ctx, &vertices, &indices);
        let target = self.target(ctx, width, height)?;
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("depth map"),
            });
        {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("depth map"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &target.color,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &target.depth,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(view.depth_clear()),
                        store: wgpu::StoreOp::Discard,
                    }),
                    stencil_ops: None,
                }),
                ..Default::default()
            });
            if index_count > 0 {
                pass.set_pipeline(&pipeline);
                pass.set_bind_group(0, &bind, &[]);
                pass.draw(0..index_count, 0..1);
            }
        }
        target.readback.copy(&mut encoder, &target.color_texture);
        ctx.queue.submit([encoder.finish()]);
        Ok(GpuDepthMap {
            camera: *camera,
            width,
            height,
            row_texels: target.readback.padded_row_bytes() / 8,
            readback: &target.readback,
        })
    }
}

/// A depth map on the device ([`GpuRasterizer::depth_map_resident`]): per texel
/// `vec2<f32>` (view depth, coverage), exactly the render target's values; a texel is
/// covered when its coverage is above 0.5, and its depth is then the map's depth (what
/// [`GpuRasterizer::depth_map`] reads back and decodes: consumers on the device copy the same
/// floats). Row 0 is the top row; texel (x, y) is element `y * row_texels + x` of
/// [`GpuDepthMap::texels`].
#[derive(Debug)]
pub struct GpuDepthMap<'a> {
    pub camera: Camera,
    pub width: u32,
    pub height: u32,
    /// Elements from one row to the next (rows are padded to 256 bytes).
    pub row_texels: u32,
    readback: &'a TextureReadback,
}

impl GpuDepthMap<'_> {
    /// The texels (`array<vec2<f32>>`, bindable as storage).
    pub fn texels(&self) -> &wgpu::Buffer {
        self.readback.buffer()
    }

    /// Read back and decoded as the CPU's [`DepthMap`] (for CPU consumers, writers and tests;
    /// counted as a read-back of the padded rows).
    pub fn to_cpu(&self, ctx: &GpuContext) -> Result<DepthMap> {
        let texels: Vec<[f32; 2]> = bytemuck::pod_collect_to_vec(&self.readback.read(ctx)?);
        let mut map = DepthMap::empty(self.camera, self.width, self.height);
        for ((d, c), t) in map.depth.iter_mut().zip(&mut map.coverage).zip(&texels) {
            if t[1] > 0.5 {
                *d = t[0];
                *c = true;
            }
        }
        Ok(map)
    }
}

/// The bind group layout of the raster passes' group 0: binding 0 the [`GpuView`] uniform
/// (vertex and fragment stages), then `extra` uniform bindings 1, 2, … with the given
/// visibilities.
pub fn view_layout(ctx: &GpuContext, extra: &[wgpu::ShaderStages]) -> wgpu::BindGroupLayout {
    let uniform = |binding: u32, visibility| wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    };
    let mut entries = vec![uniform(
        0,
        wgpu::ShaderStages::VERTEX | wgpu::ShaderStages::FRAGMENT,
    )];
    for (k, v) in extra.iter().enumerate() {
        entries.push(uniform(k as u32 + 1, *v));
    }
    ctx.device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("raster view"),
            entries: &entries,
        })
}
