//! The GPU frame renderer: [`GpuRenderer::render`] draws the same [`Scene`] as
//! [`render_cpu`](crate::frame::render_cpu) with wgpu render passes
//! (`shaders/render/shade.wgsl`, `shaders/render/line.wgsl`, both after
//! `shaders/render/camera.wgsl`): the same picture to rounding on surfaces, with small
//! differences on anti-aliased edges and on lines (measured and bounded in
//! `tests/gpu_frame.rs`).
//!
//! How each step of the CPU pipeline is done here:
//! 1. objects are drawn in scene order into one depth buffer (reversed depth for perspective
//!    cameras, see `imprint_gpu::raster`); the nearer surface wins, an exact tie goes to the
//!    earlier object, as on the CPU;
//! 2. meshes are shaded per pixel with the CPU's formula, `color * (ambient + sun * max(0,
//!    n·l))` clamped to 1, on the perspective-correct interpolated vertex normal flipped
//!    towards the camera, in linear space; the Rgba8UnormSrgb target does the sRGB encoding;
//! 3. field slices are quads textured with one texel per cell, the texel colours computed on
//!    the CPU by the CPU path's own function, looked up with the CPU's rounding (no filtering);
//! 4. the ground grid and wireframes are line lists drawn after the surfaces, depth-tested
//!    without writing depth, with the CPU's relative bias applied in the vertex shader (depth
//!    bias state does not apply to lines). Hardware lines are one pixel wide; the CPU stamps
//!    squares of one output pixel along its lines, which come out a little heavier on slopes
//!    (at 45°, ~1.5 px of ink per column against ~1.2 with MSAA on lavapipe): lines are where
//!    the two renderers differ most;
//! 5. anti-aliasing: `samples > 1` renders with 4× MSAA (whatever the factor: 4 coverage
//!    samples, one shading per pixel) into a resolve target, `samples == 1` without; the
//!    background is the clear colour. The CPU supersamples `samples²` shaded samples instead,
//!    so anti-aliased edges differ a little, interiors by rounding (both resolve in linear
//!    space). Without anti-aliasing, surfaces agree to one level.
//!
//! The renderer is long-lived: shaders and pipelines are built once (pipelines per depth
//! convention and sample count, on first use), vertex buffers grow and are reused, the render
//! targets are kept while the image size and sampling stay the same. Field-slice textures are
//! made per frame (they are small).

use crate::field_io::check_field;
use crate::frame::{
    LINE_BIAS_REL, Object, RenderOptions, Scene, WIRE_COLOR, cell_color, grid_segments, slice_quad,
    srgb3_to_linear, sun_direction, vertex_normals,
};
use glam::UVec3;
use image::RgbImage;
use imprint_core::{Error, Result};
use imprint_gpu::raster::{
    DEPTH_FORMAT, GpuView, GrowingBuffer, TextureReadback, check_image_size, checked,
    render_texture, shader_module, view_layout,
};
use imprint_gpu::{GpuContext, shader};
use std::collections::HashMap;
use std::ops::Range;

/// Format of the colour target: linear shading in, sRGB bytes out (a window may ask for its
/// BGRA twin, [`GpuRenderer::with_format`]).
const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
/// MSAA sample count used when `RenderOptions::samples > 1`.
pub const MSAA_SAMPLES: u32 = 4;
/// Absolute depth bias of lines for orthographic cameras (world units), as on the CPU.
const LINE_BIAS_ABS: f32 = 1e-5;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct MeshVertex {
    position: [f32; 3],
    normal: [f32; 3],
    /// Linear RGB of the object.
    color: [f32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SliceVertex {
    position: [f32; 3],
    /// In-plane grid coordinates (cell centres at integers).
    cell: [f32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LineVertex {
    position: [f32; 3],
    color: [f32; 3],
}

/// Mirrors `Shading` in `shaders/render/shade.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Shading {
    sun: [f32; 4],
    ambient: [f32; 4],
}

/// One draw of the surface pass, in scene order.
enum Draw {
    /// A range of the mesh index buffer (consecutive mesh objects share one draw).
    Meshes(Range<u32>),
    /// Six vertices of the slice vertex buffer from `first`, with the bind group `texture`.
    Slice { first: u32, texture: usize },
}

#[derive(Clone, Debug)]
struct Pipelines {
    mesh: wgpu::RenderPipeline,
    slice: wgpu::RenderPipeline,
    line: wgpu::RenderPipeline,
}

/// The attachments and readback of one image size and sample count.
#[derive(Debug)]
struct Target {
    width: u32,
    height: u32,
    sample_count: u32,
    /// The multisampled colour attachment (MSAA only).
    msaa: Option<wgpu::TextureView>,
    /// The single-sample image: the resolve target with MSAA, the attachment without.
    resolved: wgpu::Texture,
    resolved_view: wgpu::TextureView,
    depth: wgpu::TextureView,
    readback: TextureReadback,
}

/// Renders [`Scene`]s on the GPU; see the module doc. Use it with the context it was made
/// with.
#[derive(Debug)]
pub struct GpuRenderer {
    device: wgpu::Device,
    /// The image's format: sRGB RGBA, or BGRA to be copied into a window's surface.
    format: wgpu::TextureFormat,
    shade: wgpu::ShaderModule,
    line: wgpu::ShaderModule,
    /// Group 0 only (meshes, lines).
    layout: wgpu::PipelineLayout,
    /// Group 0 and the slice texture (group 1).
    slice_layout: wgpu::PipelineLayout,
    slice_group: wgpu::BindGroupLayout,
    /// By (reversed depth, sample count).
    pipelines: HashMap<(bool, u32), Pipelines>,
    view: wgpu::Buffer,
    shading: wgpu::Buffer,
    bind: wgpu::BindGroup,
    mesh_vertices: GrowingBuffer,
    mesh_indices: GrowingBuffer,
    slice_vertices: GrowingBuffer,
    line_vertices: GrowingBuffer,
    target: Option<Target>,
}

impl GpuRenderer {
    pub fn new(ctx: &GpuContext) -> Result<Self> {
        Self::with_format(ctx, COLOR_FORMAT)
    }

    /// A renderer whose image is `Rgba8UnormSrgb` or `Bgra8UnormSrgb` (the format of most
    /// window surfaces, so a live view copies the image into the window as it is).
    pub fn with_format(ctx: &GpuContext, format: wgpu::TextureFormat) -> Result<Self> {
        use wgpu::TextureFormat::{Bgra8UnormSrgb, Rgba8UnormSrgb};
        if !matches!(format, Rgba8UnormSrgb | Bgra8UnormSrgb) {
            return Err(Error::Invalid(format!(
                "GpuRenderer: images are Rgba8UnormSrgb or Bgra8UnormSrgb, not {format:?}"
            )));
        }
        let camera = shader!("render/camera.wgsl");
        let shade = shader_module(
            ctx,
            "render/shade.wgsl",
            &[camera, shader!("render/shade.wgsl")],
        )?;
        let line = shader_module(
            ctx,
            "render/line.wgsl",
            &[camera, shader!("render/line.wgsl")],
        )?;
        let group0 = view_layout(ctx, &[wgpu::ShaderStages::FRAGMENT]);
        let slice_group = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("field slice colours"),
                entries: &[wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: false },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                }],
            });
        let layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("frame"),
                bind_group_layouts: &[Some(&group0)],
                immediate_size: 0,
            });
        let slice_layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("frame slices"),
                bind_group_layouts: &[Some(&group0), Some(&slice_group)],
                immediate_size: 0,
            });
        let view = ctx.uniform_buffer("frame view", &<GpuView as bytemuck::Zeroable>::zeroed());
        let shading =
            ctx.uniform_buffer("frame shading", &<Shading as bytemuck::Zeroable>::zeroed());
        let bind = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("frame"),
            layout: &group0,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: view.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: shading.as_entire_binding(),
                },
            ],
        });
        let vertex = wgpu::BufferUsages::VERTEX;
        Ok(GpuRenderer {
            device: ctx.device.clone(),
            format,
            shade,
            line,
            layout,
            slice_layout,
            slice_group,
            pipelines: HashMap::new(),
            view,
            shading,
            bind,
            mesh_vertices: GrowingBuffer::new("frame mesh vertices", vertex),
            mesh_indices: GrowingBuffer::new("frame mesh indices", wgpu::BufferUsages::INDEX),
            slice_vertices: GrowingBuffer::new("frame slice vertices", vertex),
            line_vertices: GrowingBuffer::new("frame line vertices", vertex),
            target: None,
        })
    }

    fn pipelines(&mut self, ctx: &GpuContext, reversed: bool, samples: u32) -> Result<Pipelines> {
        if let Some(p) = self.pipelines.get(&(reversed, samples)) {
            return Ok(p.clone());
        }
        let make = |label: &str,
                    layout: &wgpu::PipelineLayout,
                    module: &wgpu::ShaderModule,
                    entry: (&str, &str),
                    buffer: wgpu::VertexBufferLayout<'_>,
                    topology: wgpu::PrimitiveTopology,
                    surface: bool| {
            checked(ctx, &format!("{label} pipeline"), || {
                ctx.device
                    .create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                        label: Some(label),
                        layout: Some(layout),
                        vertex: wgpu::VertexState {
                            module,
                            entry_point: Some(entry.0),
                            compilation_options: Default::default(),
                            buffers: &[Some(buffer)],
                        },
                        primitive: wgpu::PrimitiveState {
                            topology,
                            cull_mode: None,
                            ..Default::default()
                        },
                        depth_stencil: Some(wgpu::DepthStencilState {
                            format: DEPTH_FORMAT,
                            depth_write_enabled: Some(surface),
                            depth_compare: Some(GpuView::depth_compare(reversed, !surface)),
                            stencil: Default::default(),
                            bias: Default::default(),
                        }),
                        multisample: wgpu::MultisampleState {
                            count: samples,
                            ..Default::default()
                        },
                        fragment: Some(wgpu::FragmentState {
                            module,
                            entry_point: Some(entry.1),
                            compilation_options: Default::default(),
                            targets: &[Some(self.format.into())],
                        }),
                        multiview_mask: None,
                        cache: None,
                    })
            })
        };
        let triangles = wgpu::PrimitiveTopology::TriangleList;
        let p = Pipelines {
            mesh: make(
                "frame meshes",
                &self.layout,
                &self.shade,
                ("vs_mesh", "fs_mesh"),
                wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<MeshVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3],
                },
                triangles,
                true,
            )?,
            slice: make(
                "frame slices",
                &self.slice_layout,
                &self.shade,
                ("vs_slice", "fs_slice"),
                wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<SliceVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x2],
                },
                triangles,
                true,
            )?,
            line: make(
                "frame lines",
                &self.layout,
                &self.line,
                ("vs_line", "fs_line"),
                wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<LineVertex>() as u64,
                    step_mode: wgpu::VertexStepMode::Vertex,
                    attributes: &wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3],
                },
                wgpu::PrimitiveTopology::LineList,
                false,
            )?,
        };
        self.pipelines.insert((reversed, samples), p.clone());
        Ok(p)
    }

    fn target(
        &mut self,
        ctx: &GpuContext,
        width: u32,
        height: u32,
        samples: u32,
    ) -> Result<&Target> {
        let stale = self
            .target
            .as_ref()
            .is_none_or(|t| (t.width, t.height, t.sample_count) != (width, height, samples));
        if stale {
            self.target = None;
            let msaa = if samples > 1 {
                let t = render_texture(
                    ctx,
                    "frame (multisampled)",
                    width,
                    height,
                    self.format,
                    samples,
                    wgpu::TextureUsages::empty(),
                )?;
                Some(t.create_view(&Default::default()))
            } else {
                None
            };
            let resolved = render_texture(
                ctx,
                "frame",
                width,
                height,
                self.format,
                1,
                wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::TEXTURE_BINDING,
            )?;
            let depth = render_texture(
                ctx,
                "frame depth",
                width,
                height,
                DEPTH_FORMAT,
                samples,
                wgpu::TextureUsages::empty(),
            )?;
            self.target = Some(Target {
                width,
                height,
                sample_count: samples,
                msaa,
                resolved_view: resolved.create_view(&Default::default()),
                resolved,
                depth: depth.create_view(&Default::default()),
                readback: TextureReadback::new(ctx, width, height, 4)?,
            });
        }
        Ok(self.target.as_ref().expect("made above"))
    }

    /// A texture of the slice's cell colours (linear RGB) and its bind group.
    fn slice_texture(
        &self,
        ctx: &GpuContext,
        texels: &[[f32; 4]],
        width: u32,
        height: u32,
    ) -> Result<wgpu::BindGroup> {
        check_image_size(ctx, "GPU renderer: field slice", width, height)?;
        let size = wgpu::Extent3d {
            width,
            height,
            depth_or_array_layers: 1,
        };
        let texture = checked(ctx, "field slice texture", || {
            ctx.device.create_texture(&wgpu::TextureDescriptor {
                label: Some("field slice colours"),
                size,
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format: wgpu::TextureFormat::Rgba32Float,
                usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
                view_formats: &[],
            })
        })?;
        ctx.queue.write_texture(
            texture.as_image_copy(),
            bytemuck::cast_slice(texels),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * 16),
                rows_per_image: Some(height),
            },
            size,
        );
        let view = texture.create_view(&Default::default());
        Ok(ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("field slice colours"),
            layout: &self.slice_group,
            entries: &[wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(&view),
            }],
        }))
    }

    /// Renders `scene` as [`render_cpu`](crate::frame::render_cpu) does (see the module doc
    /// for the differences). Errors: the CPU renderer's for the options, the lights, the
    /// ground grid and field slices; an invalid mesh (naming the object); an image beyond the
    /// device's largest texture; a context other than the one this renderer was made with.
    pub fn render(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        opts: &RenderOptions,
    ) -> Result<RgbImage> {
        let mut encoder = self.draw(ctx, scene, opts)?;
        let target = self.target.as_ref().expect("draw made the target");
        target.readback.copy(&mut encoder, &target.resolved);
        ctx.queue.submit([encoder.finish()]);
        let rgba = target.readback.read(ctx)?;
        rgb_image(&rgba, self.format, opts.width, opts.height)
    }

    /// [`GpuRenderer::render`] without the read-back, for a live view that shows the image
    /// where it is: the image (its bytes are the sRGB-encoded ones `render` returns, alpha
    /// 255), valid until the next call.
    pub fn render_to_texture(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        opts: &RenderOptions,
    ) -> Result<wgpu::Texture> {
        let encoder = self.draw(ctx, scene, opts)?;
        ctx.queue.submit([encoder.finish()]);
        Ok(self
            .target
            .as_ref()
            .expect("draw made the target")
            .resolved
            .clone())
    }

    /// Records the frame's passes into this renderer's target; the caller submits.
    fn draw(
        &mut self,
        ctx: &GpuContext,
        scene: &Scene,
        opts: &RenderOptions,
    ) -> Result<wgpu::CommandEncoder> {
        if ctx.device != self.device {
            return Err(Error::Invalid(
                "GpuRenderer used with another GPU context than it was made with".into(),
            ));
        }
        opts.validate()?;
        let light = sun_direction(&scene.lights)?;
        check_image_size(ctx, "GPU renderer", opts.width, opts.height)?;
        let samples = if opts.samples > 1 { MSAA_SAMPLES } else { 1 };

        // Geometry, in scene order.
        let mut mesh_vertices: Vec<MeshVertex> = Vec::new();
        let mut mesh_indices: Vec<u32> = Vec::new();
        let mut slice_vertices: Vec<SliceVertex> = Vec::new();
        let mut textures: Vec<wgpu::BindGroup> = Vec::new();
        let mut draws: Vec<Draw> = Vec::new();
        let mut wires: Vec<LineVertex> = Vec::new();
        let wire_color = WIRE_COLOR.to_array();
        for (k, obj) in scene.objects.iter().enumerate() {
            match obj {
                Object::Mesh {
                    mesh,
                    color,
                    wireframe,
                } => {
                    if mesh.triangles.is_empty() {
                        continue;
                    }
                    mesh.validate(&format!("render: object {k}"))?;
                    let base = u32::try_from(mesh_vertices.len())
                        .ok()
                        .filter(|b| b.checked_add(mesh.positions.len() as u32).is_some())
                        .ok_or_else(|| {
                            Error::Invalid("render: more than 2^32 vertices in the scene".into())
                        })?;
                    let normals = vertex_normals(mesh);
                    mesh_vertices.extend(mesh.positions.iter().zip(normals.iter()).map(
                        |(p, n)| MeshVertex {
                            position: p.to_array(),
                            normal: n.to_array(),
                            color: *color,
                        },
                    ));
                    let first = mesh_indices.len() as u32;
                    mesh_indices.extend(mesh.triangles.iter().flatten().map(|v| v + base));
                    let end = mesh_indices.len() as u32;
                    match draws.last_mut() {
                        Some(Draw::Meshes(r)) => r.end = end,
                        _ => draws.push(Draw::Meshes(first..end)),
                    }
                    if *wireframe {
                        for t in &mesh.triangles {
                            for e in 0..3 {
                                for v in [t[e], t[(e + 1) % 3]] {
                                    wires.push(LineVertex {
                                        position: mesh.positions[v as usize].to_array(),
                                        color: wire_color,
                                    });
                                }
                            }
                        }
                    }
                }
                Object::FieldSlice {
                    field,
                    axis,
                    index,
                    colormap,
                } => {
                    check_field(field)?;
                    let index = index.resolve(*axis, field.spec.dims[axis.dim()])?;
                    let (u, v) = axis.plane_axes();
                    let (du, dv) = (u.dim(), v.dim());
                    let (nu, nv) = (field.spec.dims[du], field.spec.dims[dv]);
                    let mut texels = Vec::with_capacity(nu as usize * nv as usize);
                    for b in 0..nv {
                        for a in 0..nu {
                            let mut cell = UVec3::ZERO;
                            cell[du] = a;
                            cell[dv] = b;
                            cell[axis.dim()] = index;
                            texels.push(cell_color(field, cell, *colormap).extend(1.0).to_array());
                        }
                    }
                    textures.push(self.slice_texture(ctx, &texels, nu, nv)?);
                    let quad = slice_quad(field, *axis, index);
                    let first = slice_vertices.len() as u32;
                    for t in &quad.triangles {
                        for &i in t {
                            let p = quad.positions[i as usize];
                            let c = field.spec.to_cell(p);
                            slice_vertices.push(SliceVertex {
                                position: p.to_array(),
                                cell: [c[du], c[dv]],
                            });
                        }
                    }
                    draws.push(Draw::Slice {
                        first,
                        texture: textures.len() - 1,
                    });
                }
            }
        }
        // Lines: the grid first, then the wireframes over it (later lines win, as on the CPU).
        let mut lines: Vec<LineVertex> = Vec::new();
        if let Some(g) = &scene.ground_grid {
            let (color, segments) = grid_segments(g)?;
            let color = color.to_array();
            lines.extend(segments.iter().flatten().map(|p| LineVertex {
                position: p.to_array(),
                color,
            }));
        }
        lines.append(&mut wires);
        let line_count = u32::try_from(lines.len())
            .map_err(|_| Error::Invalid("render: more than 2^32 line vertices".into()))?;

        // Uniforms and buffers.
        let view = GpuView::new(&opts.camera, opts.width as f32 / opts.height as f32)
            .with_line_bias(LINE_BIAS_REL, LINE_BIAS_ABS);
        let lights = &scene.lights;
        let shading = Shading {
            sun: light.extend(lights.sun).to_array(),
            ambient: [lights.ambient, 0.0, 0.0, 0.0],
        };
        ctx.queue
            .write_buffer(&self.view, 0, bytemuck::bytes_of(&view));
        ctx.queue
            .write_buffer(&self.shading, 0, bytemuck::bytes_of(&shading));
        let pipes = self.pipelines(ctx, view.reversed(), samples)?;
        let mesh_vb = self.mesh_vertices.write(ctx, &mesh_vertices)?.clone();
        let mesh_ib = self.mesh_indices.write(ctx, &mesh_indices)?.clone();
        let slice_vb = self.slice_vertices.write(ctx, &slice_vertices)?.clone();
        let line_vb = self.line_vertices.write(ctx, &lines)?.clone();
        let bind = self.bind.clone();
        let target = self.target(ctx, opts.width, opts.height, samples)?;

        let bg = srgb3_to_linear(scene.background).as_dvec3();
        let mut encoder = ctx
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("frame"),
            });
        {
            let (view_tex, resolve, store) = match &target.msaa {
                Some(m) => (m, Some(&target.resolved_view), wgpu::StoreOp::Discard),
                None => (&target.resolved_view, None, wgpu::StoreOp::Store),
            };
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("frame"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: view_tex,
                    depth_slice: None,
                    resolve_target: resolve,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color {
                            r: bg.x,
                            g: bg.y,
                            b: bg.z,
                            a: 1.0,
                        }),
                        store,
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
            pass.set_bind_group(0, &bind, &[]);
            for draw in &draws {
                match draw {
                    Draw::Meshes(range) => {
                        pass.set_pipeline(&pipes.mesh);
                        pass.set_vertex_buffer(0, mesh_vb.slice(..));
                        pass.set_index_buffer(mesh_ib.slice(..), wgpu::IndexFormat::Uint32);
                        pass.draw_indexed(range.clone(), 0, 0..1);
                    }
                    Draw::Slice { first, texture } => {
                        pass.set_pipeline(&pipes.slice);
                        pass.set_bind_group(1, &textures[*texture], &[]);
                        pass.set_vertex_buffer(0, slice_vb.slice(..));
                        pass.draw(*first..*first + 6, 0..1);
                    }
                }
            }
            if line_count > 0 {
                pass.set_pipeline(&pipes.line);
                pass.set_vertex_buffer(0, line_vb.slice(..));
                pass.draw(0..line_count, 0..1);
            }
        }
        Ok(encoder)
    }
}

/// An image read back from a texture of `format` (8-bit RGBA or BGRA, tightly packed), as
/// RGB.
pub fn rgb_image(
    bytes: &[u8],
    format: wgpu::TextureFormat,
    width: u32,
    height: u32,
) -> Result<RgbImage> {
    use wgpu::TextureFormat::{Bgra8Unorm, Bgra8UnormSrgb};
    let bgra = matches!(format, Bgra8Unorm | Bgra8UnormSrgb);
    let rgb: Vec<u8> = bytes
        .chunks_exact(4)
        .flat_map(|p| {
            if bgra {
                [p[2], p[1], p[0]]
            } else {
                [p[0], p[1], p[2]]
            }
        })
        .collect();
    RgbImage::from_raw(width, height, rgb).ok_or_else(|| {
        Error::Gpu(format!(
            "a read-back of {} bytes is not a {width}x{height} image",
            bytes.len()
        ))
    })
}
