//! The window's frame loop (winit): each frame reloads what was saved, steps the pipeline
//! when playback is due, draws the 3D view, runs the panel and presents; headless runs stop
//! after `exit_after` frames with a screenshot. Times are taken per part: simulation (the
//! executor's step), drawing (the 3D view, waited for) and UI (panel layout, its drawing and
//! the present).

use crate::camera::OrbitCamera;
use crate::display::{Display, UiFrame};
use crate::panel::{Panel, PanelOut};
use crate::scene::{self, ViewObject};
use crate::session::{Reloaded, Session};
use crate::watch::Watch;
use crate::{PANEL_WIDTH, ViewError, ViewOptions};
use imprint_gpu::GpuContext;
use imprint_render::frame::RenderOptions;
use std::sync::Arc;
use std::time::{Duration, Instant};
use winit::application::ApplicationHandler;
use winit::event::WindowEvent;
use winit::event_loop::{ActiveEventLoop, ControlFlow, EventLoop};
use winit::window::{Window, WindowId};

/// Redraws at least this often when paused (a save, the panel's hover).
const IDLE_REDRAW: Duration = Duration::from_millis(100);
/// While playing with no input, the panel is laid out and drawn this often; the frames in
/// between copy the panel drawn last (on a software GPU its pass costs as much as a third of
/// the view's).
const PANEL_PERIOD: Duration = Duration::from_millis(100);
const DEFAULT_SIZE: [u32; 2] = [960, 540];

pub fn run(opts: ViewOptions) -> Result<(), ViewError> {
    // The display connection first: Vulkan drivers open and close display connections of
    // their own while the adapters are listed, and an X server with no client left resets,
    // refusing a connection made during the reset. Held open, winit's keeps it from resetting.
    let event_loop = EventLoop::new().map_err(|e| {
        ViewError::display(format!(
            "imprint view cannot open a window: {e}; on a machine without a display, run it \
             under Xvfb: xvfb-run -a imprint view FILE"
        ))
    })?;
    let gpu = GpuContext::shared()
        .map_err(|e| ViewError::display(format!("imprint view draws with the GPU (wgpu): {e}")))?;
    let mut app = App::new(opts, gpu);
    event_loop
        .run_app(&mut app)
        .map_err(|e| ViewError::failed(format!("the window's event loop failed: {e}")))?;
    app.exit.unwrap_or(Ok(()))
}

/// Seconds taken by each part of the frames shown, summed.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timing {
    pub frames: u32,
    pub sim_ms: f64,
    pub draw_ms: f64,
    pub ui_ms: f64,
}

struct App {
    opts: ViewOptions,
    gpu: &'static GpuContext,
    session: Session,
    watch: Option<Watch>,
    objects: Vec<ViewObject>,
    camera: Option<OrbitCamera>,
    panel: Panel,
    display: Option<Display>,
    egui: egui::Context,
    egui_state: Option<egui_winit::State>,
    /// Frames stepped since the start (what `exit_after` counts).
    stepped: u32,
    next_step: Instant,
    started: Option<Instant>,
    /// When the second frame began: the fps after the first (loading, first builds).
    second: Option<Instant>,
    timing: Timing,
    /// The 3D view must be drawn again (a new frame, camera or object list).
    dirty: bool,
    /// Input arrived for the UI since it last ran (it runs on the next frame).
    ui_input: bool,
    /// When the UI last ran.
    last_ui: Option<Instant>,
    exit: Option<Result<(), ViewError>>,
}

impl App {
    fn new(opts: ViewOptions, gpu: &'static GpuContext) -> App {
        let session = Session::open(&opts.file, &opts.sets, opts.frames.clone(), opts.backend);
        let mut app = App {
            watch: Watch::new(&opts.file)
                .inspect_err(|e| {
                    tracing::warn!(
                        "cannot watch {} for saves ({e}): saves will not reload it; \
                         restart imprint view after editing",
                        opts.file.display()
                    )
                })
                .ok(),
            objects: Vec::new(),
            camera: None,
            panel: Panel::new(opts.target_fps),
            display: None,
            egui: egui::Context::default(),
            egui_state: None,
            stepped: 0,
            next_step: Instant::now(),
            started: None,
            second: None,
            timing: Timing::default(),
            dirty: true,
            ui_input: true,
            last_ui: None,
            exit: None,
            opts,
            gpu,
            session,
        };
        match app.session.problem() {
            Some(p) => say(&format!("error: {}", p.message)),
            None => app.adopt_plan(),
        }
        app
    }

    /// After a good (re)load: the objects, the camera (first time only), the watched assets.
    fn adopt_plan(&mut self) {
        let Some(plan) = self.session.plan() else {
            return;
        };
        self.objects = scene::objects(plan, &self.objects);
        if self.camera.is_none() {
            self.camera = scene::file_camera(plan).map(OrbitCamera::from_spec);
        }
        if let Some(w) = &mut self.watch {
            w.track_assets(plan);
        }
        self.panel.plan_changed(plan);
        self.dirty = true;
    }

    /// The file's playback rate, or the target the user asked to hold.
    fn fps(&self) -> f64 {
        let file = self.session.plan().map_or(24.0, |p| p.file.fps as f64);
        self.opts.target_fps.unwrap_or(file)
    }

    fn view_size(&self) -> [u32; 2] {
        let render = self.session.plan().and_then(scene::render_node);
        self.opts
            .size
            .or(render.map(|r| [r.width, r.height]))
            .unwrap_or(DEFAULT_SIZE)
    }

    fn reload_if_saved(&mut self) {
        let Some(changed) = self.watch.as_mut().and_then(Watch::poll) else {
            return;
        };
        let t = Instant::now();
        let outcome = self.session.reload_with(&changed.nodes);
        match &outcome {
            Reloaded::Applied { rebuilt } => {
                self.adopt_plan();
                say(&format!(
                    "reloaded {} in {:.0} ms: rebuilt [{}]",
                    self.opts.file.display(),
                    t.elapsed().as_secs_f64() * 1e3,
                    rebuilt.join(", ")
                ));
            }
            Reloaded::Refused => {
                let p = self.session.problem().expect("a refused reload says why");
                say(&format!(
                    "error: {} (the last good pipeline keeps running)",
                    p.message
                ));
            }
            Reloaded::Unchanged => {}
        }
        self.dirty = true;
    }

    /// Steps one frame when playing and due; the step's ms when a frame ran.
    fn step_if_due(&mut self) -> Option<f64> {
        let due = self.panel.playing && Instant::now() >= self.next_step;
        if !(due || self.panel.step_once) || self.session.executor().is_none() {
            return None;
        }
        self.panel.step_once = false;
        let t = Instant::now();
        if self.session.step(self.panel.looping) {
            self.stepped += 1;
            self.started.get_or_insert(t);
            if self.stepped == 2 {
                self.second = Some(t);
            }
            self.dirty = true;
            let period = Duration::from_secs_f64(1.0 / self.fps());
            self.next_step = (self.next_step + period).max(Instant::now() - period);
            return Some(t.elapsed().as_secs_f64() * 1e3);
        }
        self.panel.playing = false;
        if let Some(p) = self.session.problem() {
            say(&format!("error: {}", p.message));
        }
        None
    }

    /// The whole frame; returns whether the headless run is over.
    fn frame(&mut self) -> bool {
        self.reload_if_saved();
        let sim_ms = self.step_if_due();
        let t = Instant::now();
        let drew = self.draw_scene();
        let draw_ms = t.elapsed().as_secs_f64() * 1e3;
        let t = Instant::now();
        let last = self.headless_done();
        let shot = self.run_panel(last && self.opts.screenshot.is_some());
        let ui_ms = t.elapsed().as_secs_f64() * 1e3;
        if let Some(sim_ms) = sim_ms {
            self.count(sim_ms, if drew { draw_ms } else { 0.0 }, ui_ms);
        }
        if let Some(img) = shot {
            self.save_screenshot(&img);
        }
        last
    }

    fn count(&mut self, sim: f64, draw: f64, ui: f64) {
        let t = &mut self.timing;
        t.frames += 1;
        (t.sim_ms, t.draw_ms, t.ui_ms) = (t.sim_ms + sim, t.draw_ms + draw, t.ui_ms + ui);
        self.panel.last_times = [sim, draw, ui];
        if let (Some(b), Some(summary)) = (&mut self.panel.budget, self.session.history().back()) {
            b.observe(summary, draw + ui);
        }
        if self.opts.exit_after.is_some() {
            let frame = self.session.shown_frame().unwrap_or(0);
            say(&format!(
                "frame {frame}: sim {sim:.2} ms, draw {draw:.2} ms, ui {ui:.2} ms"
            ));
        }
    }

    /// Draws the 3D view when something changed; returns whether it drew.
    fn draw_scene(&mut self) -> bool {
        if !self.dirty {
            return false;
        }
        let size = self.panel.view_pixels.unwrap_or(self.view_size());
        let (Some(ex), Some(display)) = (self.session.executor(), self.display.as_mut()) else {
            return false;
        };
        if self.camera.is_none() {
            self.camera = scene::bounds(ex, &self.objects).map(OrbitCamera::framing);
        }
        let Some(camera) = &self.camera else {
            return false;
        };
        let fps = ex.plan().file.fps;
        let time = self.session.shown_frame().unwrap_or(0) as f32 / fps;
        let plan = self.session.plan().expect("an executor has a plan");
        let render = scene::render_node(plan);
        let grid = render.is_none_or(|r| r.ground_grid);
        let file_samples = render.map_or(1, |r| r.samples);
        let samples = if self.panel.antialias.unwrap_or(!self.gpu.is_software()) {
            file_samples
        } else {
            1
        };
        let [w, h] = size;
        let drawn = scene::scene(ex, &self.objects, grid).and_then(|(scene, legend)| {
            self.panel.legend = legend;
            let opts = RenderOptions {
                width: w,
                height: h,
                samples,
                camera: camera.camera(time)?,
            };
            display.draw_scene(&scene, &opts)
        });
        if let Err(e) = drawn {
            say(&format!("error: drawing the view: {e}"));
        }
        self.dirty = false;
        true
    }

    /// Runs the panel when it is due, and presents; the window's image when `capture`.
    fn run_panel(&mut self, capture: bool) -> Option<image::RgbImage> {
        let at = self.panel.view_rect;
        let display = self.display.as_mut()?;
        let due = capture
            || self.ui_input
            || !self.panel.playing
            || self.session.problem().is_some()
            || self.last_ui.is_none_or(|t| t.elapsed() >= PANEL_PERIOD)
            || !display.can_reuse_panel(at);
        if !due {
            if let Err(e) = display.present(None, at, false) {
                self.exit = Some(Err(e));
            }
            return None;
        }
        let state = self.egui_state.as_mut()?;
        let input = state.take_egui_input(&display.window);
        let view = display.view_texture().map(|v| (v.id, v.size));
        let mut out = PanelOut::default();
        let full = self.egui.run_ui(input, |ui| {
            out = self.panel.show(
                ui,
                &mut self.session,
                &mut self.objects,
                self.camera.as_mut(),
                view,
                &self.timing,
            );
        });
        state.handle_platform_output(&display.window, full.platform_output);
        let jobs = self.egui.tessellate(full.shapes, full.pixels_per_point);
        let ui = UiFrame {
            jobs: &jobs,
            textures: &full.textures_delta,
            pixels_per_point: full.pixels_per_point,
            over_view: self.session.problem().is_some(),
        };
        let shot = display.present(Some(ui), at, capture).unwrap_or_else(|e| {
            self.exit = Some(Err(e));
            None
        });
        (self.ui_input, self.last_ui) = (false, Some(Instant::now()));
        self.after_panel(out);
        shot
    }

    /// What the user did in the panel.
    fn after_panel(&mut self, out: PanelOut) {
        if out.reloaded {
            self.adopt_plan();
        }
        if out.redraw {
            self.dirty = true;
        }
        if out.restart_pacing {
            self.next_step = Instant::now();
        }
    }

    /// Whether a headless run has done its frames (or cannot run any).
    fn headless_done(&self) -> bool {
        let Some(n) = self.opts.exit_after else {
            return false;
        };
        self.stepped >= n || self.session.executor().is_none() || self.failed_at_end()
    }

    fn failed_at_end(&self) -> bool {
        self.session.problem().is_some_and(|p| !p.still_running) && !self.panel.playing
    }

    fn save_screenshot(&mut self, img: &image::RgbImage) {
        let Some(path) = &self.opts.screenshot else {
            return;
        };
        match imprint_render::png::write_png(path, img) {
            Ok(()) => {
                if let Some(v) = self.panel.view_rect {
                    say(&format!(
                        "screenshot {}: {}x{}, view at {} {} {}x{}",
                        path.display(),
                        img.width(),
                        img.height(),
                        v[0],
                        v[1],
                        v[2],
                        v[3]
                    ));
                }
            }
            Err(e) => self.exit = Some(Err(ViewError::failed(format!("screenshot: {e}")))),
        }
    }

    /// The exit of a headless run: 2 when the file never ran, 1 when a frame failed.
    fn finish_headless(&mut self) {
        let t = self.timing;
        if t.frames > 0 {
            let wall = self.started.map_or(0.0, |s| s.elapsed().as_secs_f64());
            let n = t.frames as f64;
            let steady = self.second.map_or(0.0, |s| {
                (t.frames - 1) as f64 / s.elapsed().as_secs_f64().max(1e-9)
            });
            say(&format!(
                "view: {} frames in {wall:.2} s ({:.1} fps; {steady:.1} fps after the first); \
                 per frame: sim {:.2} ms, draw {:.2} ms, ui {:.2} ms",
                t.frames,
                n / wall.max(1e-9),
                t.sim_ms / n,
                t.draw_ms / n,
                t.ui_ms / n
            ));
        }
        if let Some(b) = &self.panel.budget {
            say(&b.report());
        }
        if self.exit.is_some() {
            return;
        }
        self.exit = Some(match self.session.problem() {
            Some(p) if self.session.executor().is_none() => {
                Err(ViewError::display(format!("{}\n{}", p.message, p.detail)))
            }
            Some(p) if !p.still_running => Err(ViewError::failed(p.message.clone())),
            _ => Ok(()),
        });
    }
}

impl ApplicationHandler for App {
    fn resumed(&mut self, event_loop: &ActiveEventLoop) {
        if self.display.is_some() {
            return;
        }
        let [w, h] = self.view_size();
        let attrs = Window::default_attributes()
            .with_title(format!("imprint view {}", self.opts.file.display()))
            .with_inner_size(winit::dpi::PhysicalSize::new(w + PANEL_WIDTH, h));
        let made = event_loop
            .create_window(attrs)
            .map_err(|e| ViewError::display(format!("cannot open a window: {e}")))
            .map(Arc::new)
            .and_then(|window| Display::new(self.gpu, window));
        match made {
            Ok(display) => {
                let max = self.gpu.limits.max_texture_dimension_2d as usize;
                self.egui_state = Some(egui_winit::State::new(
                    self.egui.clone(),
                    egui::ViewportId::ROOT,
                    &display.window,
                    Some(display.window.scale_factor() as f32),
                    None,
                    Some(max),
                ));
                display.window.request_redraw();
                self.display = Some(display);
            }
            Err(e) => {
                self.exit = Some(Err(e));
                event_loop.exit();
            }
        }
    }

    fn window_event(&mut self, event_loop: &ActiveEventLoop, _id: WindowId, event: WindowEvent) {
        if let (Some(d), Some(s)) = (&self.display, &mut self.egui_state)
            && s.on_window_event(&d.window, &event).repaint
        {
            self.ui_input |= !matches!(event, WindowEvent::RedrawRequested);
            d.window.request_redraw();
        }
        match event {
            WindowEvent::CloseRequested => event_loop.exit(),
            WindowEvent::Resized(size) => {
                if let Some(d) = &mut self.display {
                    d.resize(size.width, size.height);
                }
                self.dirty = true;
            }
            WindowEvent::RedrawRequested => {
                let over = self.frame();
                if over || self.exit.is_some() {
                    if self.opts.exit_after.is_some() {
                        self.finish_headless();
                    }
                    event_loop.exit();
                }
            }
            _ => {}
        }
    }

    fn new_events(&mut self, _: &ActiveEventLoop, cause: winit::event::StartCause) {
        if let winit::event::StartCause::ResumeTimeReached { .. } = cause
            && let Some(d) = &self.display
        {
            d.window.request_redraw();
        }
    }

    fn about_to_wait(&mut self, event_loop: &ActiveEventLoop) {
        let idle = Instant::now() + IDLE_REDRAW;
        let wake = if self.panel.playing || self.panel.step_once {
            self.next_step.min(idle)
        } else {
            idle
        };
        event_loop.set_control_flow(ControlFlow::WaitUntil(wake));
    }
}

/// One line about what happened, on standard output (tests and scripts read it).
pub(crate) fn say(line: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
    let _ = out.flush();
}
