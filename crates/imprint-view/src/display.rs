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
    /// The panel drawn last, copied into the frames that do not run the UI again.
    panel: Option<wgpu::Texture>,
}

/// One run of the UI, to draw.
pub struct UiFrame<'a> {
    pub jobs: &'a [egui::ClippedPrimitive],
    pub textures: &'a egui::TexturesDelta,
    pub pixels_per_point: f32,
    /// Something is drawn over the 3D view (the problem box): the UI is drawn onto the
    /// window after the view, not kept.
    pub over_view: bool,
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
            panel: None,
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
    /// Presents a frame: the panel drawn anew from `ui`, or, with `None`, the panel drawn
    /// last copied again ([`Display::can_reuse_panel`]); the 3D view copied to `view_at`
    /// (pixels) where it is copied. With `capture`, also the window's image read back.
    pub fn present(
        &mut self,
        ui: Option<UiFrame<'_>>,
        view_at: Option<[u32; 4]>,
        capture: bool,
    ) -> Result<Option<RgbImage>, ViewError> {
        let device = &self.gpu.device;
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
        let mut encoder = device.create_command_encoder(&Default::default());
        let mut commands = Vec::new();
        let mut shot = None;
        match ui {
            Some(ui) => {
                commands = self.prepare_ui(&mut encoder, &ui);
                let screen = self.screen(ui.pixels_per_point);
                let keep_panel = !ui.over_view && !capture && self.copied(view_at);
                if keep_panel {
                    let panel = self.panel_image()?;
                    let view = panel.create_view(&Default::default());
                    self.ui_pass(&mut encoder, &view, ui.jobs, &screen, false);
                    self.compose(&mut encoder, &frame.texture, view_at);
                } else {
                    self.panel = None;
                    let target = frame.texture.create_view(&Default::default());
                    let covered = self.copy_view(&mut encoder, &frame.texture, view_at);
                    self.ui_pass(&mut encoder, &target, ui.jobs, &screen, covered);
                    if capture {
                        shot = Some(self.capture(&mut encoder, ui.jobs, &screen, view_at)?);
                    }
                }
                for id in &ui.textures.free {
                    self.ui.free_texture(id);
                }
            }
            None => {
                self.compose(&mut encoder, &frame.texture, view_at);
            }
        }
        commands.push(encoder.finish());
        self.gpu.queue.submit(commands);
        self.gpu.queue.uncounted().present(frame);
        match shot {
            Some((texture, readback)) => Ok(Some(self.read(&texture, readback)?)),
            None => Ok(None),
        }
    }

    /// Whether a frame can be presented without running the UI: the panel drawn last is kept
    /// and the view, copied, fills the rest of the window.
    pub fn can_reuse_panel(&self, view_at: Option<[u32; 4]>) -> bool {
        self.panel.is_some() && self.copied(view_at)
    }

    fn screen(&self, pixels_per_point: f32) -> ScreenDescriptor {
        ScreenDescriptor {
            size_in_pixels: self.size(),
            pixels_per_point,
        }
    }

    /// Uploads the UI's textures and buffers; the commands its callbacks made.
    fn prepare_ui(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        ui: &UiFrame<'_>,
    ) -> Vec<wgpu::CommandBuffer> {
        let (device, queue) = (&self.gpu.device, self.gpu.queue.uncounted());
        for (id, deltas) in &ui.textures.set {
            for delta in deltas {
                self.ui.update_texture(device, queue, *id, delta);
            }
        }
        let screen = self.screen(ui.pixels_per_point);
        self.ui
            .update_buffers(device, queue, encoder, ui.jobs, &screen)
    }

    /// The image the panel is drawn into when it is kept, made at the window's size.
    fn panel_image(&mut self) -> Result<wgpu::Texture, ViewError> {
        let [w, h] = self.size();
        if let Some(p) = self
            .panel
            .as_ref()
            .filter(|p| p.width() == w && p.height() == h)
        {
            return Ok(p.clone());
        }
        let usage = wgpu::TextureUsages::COPY_SRC;
        let made = render_texture(self.gpu, "viewer panel", w, h, self.config.format, 1, usage)
            .map_err(|e| ViewError::failed(format!("the panel's image: {e}")))?;
        self.panel = Some(made.clone());
        Ok(made)
    }

    /// The kept panel (left of the view) and the 3D view, copied into `window`.
    fn compose(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        window: &wgpu::Texture,
        view_at: Option<[u32; 4]>,
    ) {
        let (Some(panel), Some([x, _, _, _])) = (&self.panel, view_at) else {
            return;
        };
        if x > 0 {
            let size = wgpu::Extent3d {
                width: x,
                height: panel.height(),
                depth_or_array_layers: 1,
            };
            encoder.copy_texture_to_texture(panel.as_image_copy(), window.as_image_copy(), size);
        }
        self.copy_view(encoder, window, view_at);
    }

    /// Whether the view is copied into the window and fills it right of the panel.
    fn copied(&self, view_at: Option<[u32; 4]>) -> bool {
        let (Route::Copy { image: Some(image) }, Some([x, y, w, h])) = (&self.route, view_at)
        else {
            return false;
        };
        let [ww, wh] = self.size();
        image.width() == w && image.height() == h && x + w == ww && y == 0 && h == wh
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
        let (Route::Copy { image: Some(image) }, Some([x, y, ..])) = (&self.route, view_at) else {
            return false;
        };
        if !self.copied(view_at) {
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
        let [w, h] = self.size();
        imprint_render::gpu_frame::rgb_image(&rgba, self.config.format, w, h).map_err(fail)
    }
}
