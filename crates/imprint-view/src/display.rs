//! The window's GPU side: its surface on the device the stages use, the scene renderer
//! (the same `GpuRenderer` as the `Render` node, so the view is the offline frame), the UI
//! renderer, and screenshots of what the window shows.

use crate::ViewError;
use egui_wgpu::{Renderer, RendererOptions, ScreenDescriptor};
use image::RgbImage;
use imprint_gpu::GpuContext;
use imprint_gpu::raster::{TextureReadback, render_texture};
use imprint_render::frame::{RenderOptions, Scene};
use imprint_render::gpu_frame::GpuRenderer;
use std::sync::Arc;
use winit::window::Window;

/// The 3D view as a texture the panel's UI shows, and its size.
pub struct ViewTexture {
    pub id: egui::TextureId,
    pub size: [u32; 2],
}

/// How the 3D view reaches the window: copied into the surface where the view is (cheap:
/// no second pass over its pixels, which costs as much as drawing it on a software
/// rasteriser), or, where the surface cannot be copied to, drawn by the UI as a texture.
enum Route {
    Copy { image: Option<wgpu::Texture> },
    Texture(Option<ViewTexture>),
}

pub struct Display {
    pub window: Arc<Window>,
    gpu: &'static GpuContext,
    surface: wgpu::Surface<'static>,
    config: wgpu::SurfaceConfiguration,
    ui: Renderer,
    scene: GpuRenderer,
    route: Route,
}

impl Display {
    pub fn new(gpu: &'static GpuContext, window: Arc<Window>) -> Result<Display, ViewError> {
        let surface = gpu
            .instance
            .create_surface(window.clone())
            .map_err(|e| ViewError::display(format!("cannot draw into the window: {e}")))?;
        let caps = surface.get_capabilities(&gpu.adapter);
        // Plain (not sRGB) bytes: the UI library blends in gamma space, and the 3D view's
        // bytes then reach the screen unchanged.
        let format = caps
            .formats
            .iter()
            .copied()
            .find(|f| !f.is_srgb())
            .or_else(|| caps.formats.first().copied())
            .ok_or_else(|| {
                ViewError::display(format!(
                    "the GPU adapter '{}' cannot present to this window",
                    gpu.adapter_name()
                ))
            })?;
        let size = window.inner_size();
        let srgb = match format {
            wgpu::TextureFormat::Bgra8Unorm => Some(wgpu::TextureFormat::Bgra8UnormSrgb),
            wgpu::TextureFormat::Rgba8Unorm => Some(wgpu::TextureFormat::Rgba8UnormSrgb),
            _ => None,
        };
        let copy = caps.usages.contains(wgpu::TextureUsages::COPY_DST) && srgb.is_some();
        let mut usage = wgpu::TextureUsages::RENDER_ATTACHMENT;
        if copy {
            usage |= wgpu::TextureUsages::COPY_DST;
        }
        let config = wgpu::SurfaceConfiguration {
            usage,
            format,
            width: size.width.max(1),
            height: size.height.max(1),
            // Frames are paced by the viewer itself (the pipeline's fps or --target-fps).
            present_mode: wgpu::PresentMode::AutoNoVsync,
            desired_maximum_frame_latency: 2,
            alpha_mode: caps.alpha_modes[0],
            view_formats: vec![],
            color_space: wgpu::SurfaceColorSpace::Auto,
        };
        surface.configure(&gpu.device, &config);
        let options = RendererOptions {
            dithering: false,
            ..RendererOptions::default()
        };
        let (scene_format, route) = match srgb.filter(|_| copy) {
            Some(f) => (f, Route::Copy { image: None }),
            None => (wgpu::TextureFormat::Rgba8UnormSrgb, Route::Texture(None)),
        };
        let scene = GpuRenderer::with_format(gpu, scene_format)
            .map_err(|e| ViewError::display(e.to_string()))?;
        Ok(Display {
            window,
            gpu,
            surface,
            config,
            ui: Renderer::new(&gpu.device, format, options),
            scene,
            route,
        })
    }

    pub fn resize(&mut self, width: u32, height: u32) {
        if width > 0 && height > 0 {
            self.config.width = width;
            self.config.height = height;
            self.surface.configure(&self.gpu.device, &self.config);
        }
    }

    pub fn size(&self) -> [u32; 2] {
        [self.config.width, self.config.height]
    }

    /// Draws the 3D view and waits for it (so its time is the drawing's, not the UI's).
    pub fn draw_scene(&mut self, scene: &Scene, opts: &RenderOptions) -> imprint_core::Result<()> {
        let image = self.scene.render_to_texture(self.gpu, scene, opts)?;
        let _ = self.gpu.device.poll(wgpu::PollType::wait_indefinitely());
        match &mut self.route {
            Route::Copy { image: kept } => *kept = Some(image),
            Route::Texture(view) => {
                let plain = image.create_view(&wgpu::TextureViewDescriptor {
                    format: Some(wgpu::TextureFormat::Rgba8Unorm),
                    ..Default::default()
                });
                let (device, filter) = (&self.gpu.device, wgpu::FilterMode::Nearest);
                let size = [opts.width, opts.height];
                match view {
                    Some(v) => {
                        self.ui
                            .update_egui_texture_from_wgpu_texture(device, &plain, filter, v.id);
                        v.size = size;
                    }
                    None => {
                        let id = self.ui.register_native_texture(device, &plain, filter);
                        *view = Some(ViewTexture { id, size });
                    }
                }
            }
        }
        Ok(())
    }

    /// The 3D view for the UI to draw, when it is not copied into the window.
    pub fn view_texture(&self) -> Option<&ViewTexture> {
        match &self.route {
            Route::Texture(v) => v.as_ref(),
            Route::Copy { .. } => None,
        }
    }

    /// Uploads the UI's textures and draws `jobs` to the window; with `capture`, also into an
    /// image of the window read back.
    /// The view is copied to `view_at` (pixels) first, when it is copied.
    pub fn present(
        &mut self,
        jobs: &[egui::ClippedPrimitive],
        textures: &egui::TexturesDelta,
        pixels_per_point: f32,
        view_at: Option<[u32; 4]>,
        capture: bool,
    ) -> Result<Option<RgbImage>, ViewError> {
        let (device, queue) = (&self.gpu.device, self.gpu.queue.uncounted());
        for (id, deltas) in &textures.set {
            for delta in deltas {
                self.ui.update_texture(device, queue, *id, delta);
            }
        }
        let screen = ScreenDescriptor {
            size_in_pixels: self.size(),
            pixels_per_point,
        };
        let frame = match self.surface.get_current_texture() {
            wgpu::CurrentSurfaceTexture::Success(f)
            | wgpu::CurrentSurfaceTexture::Suboptimal(f) => f,
            other => {
                // Lost or outdated (a resize under way): configure again, draw next time.
                let _ = other;
                self.surface.configure(device, &self.config);
                return Ok(None);
            }
        };
        let target = frame.texture.create_view(&Default::default());
        let mut encoder = device.create_command_encoder(&Default::default());
        let mut commands = self
            .ui
            .update_buffers(device, queue, &mut encoder, jobs, &screen);
        let covered = self.copy_view(&mut encoder, &frame.texture, view_at);
        self.ui_pass(&mut encoder, &target, jobs, &screen, covered);
        let shot = if capture {
            Some(self.capture(&mut encoder, jobs, &screen, view_at)?)
        } else {
            None
        };
        commands.push(encoder.finish());
        self.gpu.queue.submit(commands);
        queue.present(frame);
        for id in &textures.free {
            self.ui.free_texture(id);
        }
        match shot {
            Some((texture, readback)) => Ok(Some(self.read(&texture, readback)?)),
            None => Ok(None),
        }
    }

    fn ui_pass(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        target: &wgpu::TextureView,
        jobs: &[egui::ClippedPrimitive],
        screen: &ScreenDescriptor,
        keep: bool,
    ) {
        // What the copy put there stays; otherwise the window starts from black.
        let load = if keep {
            wgpu::LoadOp::Load
        } else {
            wgpu::LoadOp::Clear(wgpu::Color::BLACK)
        };
        let mut pass = encoder
            .begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("viewer UI"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: target,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                ..Default::default()
            })
            .forget_lifetime();
        self.ui.render(&mut pass, jobs, screen);
    }

    /// Copies the 3D view into `window` at `view_at`; returns whether the view and the panel
    /// then cover the window (the view fills its rectangle, which reaches the window's
    /// right and bottom edges).
    fn copy_view(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        window: &wgpu::Texture,
        view_at: Option<[u32; 4]>,
    ) -> bool {
        let (Route::Copy { image: Some(image) }, Some([x, y, w, h])) = (&self.route, view_at)
        else {
            return false;
        };
        let [ww, wh] = self.size();
        let fits = image.width() == w && image.height() == h && x + w == ww && y + h == wh;
        if !fits {
            return false;
        }
        encoder.copy_texture_to_texture(
            image.as_image_copy(),
            wgpu::TexelCopyTextureInfo {
                origin: wgpu::Origin3d { x, y, z: 0 },
                ..window.as_image_copy()
            },
            image.size(),
        );
        true
    }

    /// The same passes into an image of the window's size and format, for a screenshot.
    fn capture(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        jobs: &[egui::ClippedPrimitive],
        screen: &ScreenDescriptor,
        view_at: Option<[u32; 4]>,
    ) -> Result<(wgpu::Texture, TextureReadback), ViewError> {
        let [w, h] = self.size();
        let fail = |e: imprint_core::Error| ViewError::failed(format!("screenshot: {e}"));
        let texture = render_texture(
            self.gpu,
            "viewer screenshot",
            w,
            h,
            self.config.format,
            1,
            wgpu::TextureUsages::COPY_SRC | wgpu::TextureUsages::COPY_DST,
        )
        .map_err(fail)?;
        let view = texture.create_view(&Default::default());
        let covered = self.copy_view(encoder, &texture, view_at);
        self.ui_pass(encoder, &view, jobs, screen, covered);
        let readback = TextureReadback::new(self.gpu, w, h, 4).map_err(fail)?;
        readback.copy(encoder, &texture);
        Ok((texture, readback))
    }

    fn read(
        &self,
        _texture: &wgpu::Texture,
        readback: TextureReadback,
    ) -> Result<RgbImage, ViewError> {
        let fail = |e: imprint_core::Error| ViewError::failed(format!("screenshot: {e}"));
        let rgba = readback.read(self.gpu).map_err(fail)?;
        let bgr = matches!(
            self.config.format,
            wgpu::TextureFormat::Bgra8Unorm | wgpu::TextureFormat::Bgra8UnormSrgb
        );
        let rgb: Vec<u8> = rgba
            .chunks_exact(4)
            .flat_map(|p| {
                if bgr {
                    [p[2], p[1], p[0]]
                } else {
                    [p[0], p[1], p[2]]
                }
            })
            .collect();
        let [w, h] = self.size();
        RgbImage::from_raw(w, h, rgb)
            .ok_or_else(|| ViewError::failed("screenshot: read-back of the wrong size"))
    }
}
