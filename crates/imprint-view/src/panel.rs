//! The panel (egui) left of the 3D view, and the view's mouse and keys: playback and
//! scrubbing, each node's time, backend and metrics, objects shown or hidden, field slices,
//! the height legend, live edits with write-back, the frame budget's choice, and the problem
//! to fix. Drag to orbit, right- or middle-drag to pan, scroll to zoom; keys: space
//! play/pause, `.` step, `,` back, Home first frame, arrows orbit (with Shift: pan), +/-
//! zoom, R the file's camera.

use crate::PANEL_WIDTH;
use crate::app::Timing;
use crate::budget::BudgetView;
use crate::camera::OrbitCamera;
use crate::edits;
use crate::scene::{Legend, Look, ViewObject};
use crate::session::{Reloaded, Session};
use egui::{Color32, RichText, Ui};
use imprint_graph::Plan;
use imprint_graph::value::Value;
use imprint_render::slice::{Axis, SliceIndex};
use std::collections::HashMap;

/// What the panel asks of the frame loop.
#[derive(Default)]
pub struct PanelOut {
    /// The plan changed (an edit applied): objects and camera follow.
    pub reloaded: bool,
    /// The 3D view must be drawn again.
    pub redraw: bool,
    /// Playback (re)started: pace from now.
    pub restart_pacing: bool,
}

pub struct Panel {
    pub playing: bool,
    pub looping: bool,
    pub step_once: bool,
    /// Size of the 3D view in pixels, as laid out last frame.
    pub view_pixels: Option<[u32; 2]>,
    /// The 3D view's rectangle in the window, pixels: x, y, width, height.
    pub view_rect: Option<[u32; 4]>,
    pub legend: Option<Legend>,
    /// Simulation, drawing and UI of the last frame stepped, ms.
    pub last_times: [f64; 3],
    pub budget: Option<BudgetView>,
    /// Anti-aliasing as the Render node asks (`Some(true)`), off, or the default (`None`):
    /// as the file asks on a hardware GPU, off on a software one, where 4x MSAA doubles the
    /// drawing time.
    pub antialias: Option<bool>,
    /// The file's camera, to return to (R).
    file_camera: Option<OrbitCamera>,
    message: Option<String>,
    /// Numbers being dragged or typed, by assignment path, not applied yet.
    drafts: HashMap<String, f64>,
}

impl Panel {
    pub fn new(target_fps: Option<f64>) -> Panel {
        Panel {
            playing: true,
            looping: true,
            step_once: false,
            view_pixels: None,
            view_rect: None,
            legend: None,
            last_times: [0.0; 3],
            budget: target_fps.map(BudgetView::new),
            antialias: None,
            file_camera: None,
            message: None,
            drafts: HashMap::new(),
        }
    }

    pub fn plan_changed(&mut self, plan: &Plan) {
        self.file_camera = crate::scene::file_camera(plan).map(OrbitCamera::from_spec);
    }

    /// The whole window's UI for one frame.
    pub fn show(
        &mut self,
        ui: &mut Ui,
        session: &mut Session,
        objects: &mut [ViewObject],
        camera: Option<&mut OrbitCamera>,
        view: Option<(egui::TextureId, [u32; 2])>,
        timing: &Timing,
    ) -> PanelOut {
        let mut out = PanelOut::default();
        egui::Panel::left("imprint panel")
            .exact_size(PANEL_WIDTH as f32)
            .resizable(false)
            .show(ui, |ui| {
                egui::ScrollArea::vertical().show(ui, |ui| {
                    self.transport(ui, session, timing, &mut out);
                    self.problem(ui, session);
                    nodes(ui, session);
                    self.objects(ui, session, objects, &mut out);
                    self.edits(ui, session, &mut out);
                    if let Some(b) = &mut self.budget {
                        b.show(ui, session, &mut out);
                    }
                });
            });
        egui::CentralPanel::default()
            // No fill: the 3D view is copied into the window under this panel.
            .frame(egui::Frame::NONE)
            .show(ui, |ui| self.view(ui, session, camera, view, &mut out));
        out
    }

    fn transport(&mut self, ui: &mut Ui, session: &mut Session, t: &Timing, out: &mut PanelOut) {
        ui.heading(session.path().display().to_string());
        let Some(range) = session.frames() else {
            ui.label("waiting for a good save of the file");
            return;
        };
        ui.horizontal(|ui| {
            if ui
                .button("|<")
                .on_hover_text("first frame (Home)")
                .clicked()
            {
                session.show(range.start);
                out.redraw = true;
            }
            if ui.button("<").on_hover_text("back one frame (,)").clicked() {
                back_one(session, out);
            }
            let play = if self.playing { "Pause" } else { "Play" };
            if ui
                .button(play)
                .on_hover_text("play / pause (space)")
                .clicked()
            {
                self.toggle_play(out);
            }
            if ui.button(">").on_hover_text("one frame (.)").clicked() {
                self.step_once = true;
            }
            ui.checkbox(&mut self.looping, "loop");
        });
        let mut frame = session.shown_frame().unwrap_or(range.start);
        let slider = egui::Slider::new(&mut frame, range.start..=range.end - 1).text("frame");
        if ui.add(slider).changed() {
            self.playing = false;
            session.show(frame);
            out.redraw = true;
        }
        let [sim, draw, uit] = self.last_times;
        ui.label(format!(
            "last frame: sim {sim:.1} ms · draw {draw:.1} ms · UI {uit:.1} ms"
        ));
        if t.frames > 0 {
            let n = t.frames as f64;
            let per = (t.sim_ms + t.draw_ms + t.ui_ms) / n;
            ui.label(format!(
                "mean {per:.1} ms per frame over {} frames",
                t.frames
            ));
        }
    }

    fn toggle_play(&mut self, out: &mut PanelOut) {
        self.playing = !self.playing;
        out.restart_pacing = self.playing;
    }

    fn problem(&mut self, ui: &mut Ui, session: &Session) {
        if let Some(m) = &self.message {
            ui.label(m);
        }
        let Some(p) = session.problem() else {
            return;
        };
        ui.separator();
        ui.label(
            RichText::new(format!("Problem ({})", p.when))
                .color(Color32::LIGHT_RED)
                .strong(),
        );
        ui.label(RichText::new(&p.message).color(Color32::LIGHT_RED));
        if !p.detail.is_empty() {
            ui.label(RichText::new(&p.detail).monospace());
        }
        if p.still_running {
            ui.label("the last good pipeline keeps running");
        }
    }

    fn objects(
        &mut self,
        ui: &mut Ui,
        session: &Session,
        objects: &mut [ViewObject],
        out: &mut PanelOut,
    ) {
        egui::CollapsingHeader::new("Objects")
            .default_open(true)
            .show(ui, |ui| {
                for (k, o) in objects.iter_mut().enumerate() {
                    ui.push_id(k, |ui| object_row(ui, session, o, out));
                }
                if let Some(l) = &self.legend {
                    legend(ui, l);
                }
                let mut aa = self.antialias.unwrap_or(!software());
                let label = "anti-aliasing as the file asks (slow on a software GPU)";
                if ui.checkbox(&mut aa, label).changed() {
                    self.antialias = Some(aa);
                    out.redraw = true;
                }
            });
    }

    fn edits(&mut self, ui: &mut Ui, session: &mut Session, out: &mut PanelOut) {
        let Some(plan) = session.plan().cloned() else {
            return;
        };
        egui::CollapsingHeader::new("Edit").show(ui, |ui| {
            for name in &plan.order {
                ui.collapsing(name.as_str(), |ui| {
                    for n in edits::numbers(&plan, name) {
                        self.number(ui, session, &n, out);
                    }
                });
            }
            let pending = session.edits().len();
            if pending > 0 {
                ui.label(session.edits().join("\n"));
                if ui
                    .button(format!("Write {pending} edits into the file"))
                    .clicked()
                {
                    self.message = Some(match session.write_edits() {
                        Ok(()) => "written; comments and layout kept".into(),
                        Err(e) => format!("not written: {e}"),
                    });
                }
            }
        });
    }

    /// One number: dragged or typed into a draft, applied when let go.
    fn number(
        &mut self,
        ui: &mut Ui,
        session: &mut Session,
        n: &edits::Number,
        out: &mut PanelOut,
    ) {
        let mut v = self.drafts.get(&n.path).copied().unwrap_or(n.value);
        let label = n.path.split_once('.').map_or(n.path.as_str(), |p| p.1);
        let mut drag = egui::DragValue::new(&mut v).prefix(format!("{label}: "));
        if n.integer {
            drag = drag.fixed_decimals(0);
        } else {
            drag = drag.speed(n.value.abs().max(1e-3) * 0.01);
        }
        let r = ui.add(drag);
        if v != n.value {
            self.drafts.insert(n.path.clone(), v);
        }
        let settled = !r.dragged() && !r.has_focus();
        if let Some(v) = self.drafts.get(&n.path).copied().filter(|_| settled) {
            self.drafts.remove(&n.path);
            if v != n.value && session.edit(edits::assignment(n, v)) != Reloaded::Refused {
                out.reloaded = true;
                out.redraw = true;
            }
        }
    }

    fn view(
        &mut self,
        ui: &mut Ui,
        session: &mut Session,
        camera: Option<&mut OrbitCamera>,
        view: Option<(egui::TextureId, [u32; 2])>,
        out: &mut PanelOut,
    ) {
        let rect = ui.max_rect();
        let ppp = ui.pixels_per_point();
        let pixels = [
            ((rect.width() * ppp).floor() as u32).max(1),
            ((rect.height() * ppp).floor() as u32).max(1),
        ];
        if self.view_pixels != Some(pixels) {
            self.view_pixels = Some(pixels);
            out.redraw = true;
        }
        self.view_rect = Some([
            (rect.min.x * ppp) as u32,
            (rect.min.y * ppp) as u32,
            pixels[0],
            pixels[1],
        ]);
        if let Some((id, [w, h])) = view {
            let size = egui::vec2(w as f32, h as f32) / ppp;
            let at = egui::Rect::from_min_size(rect.min, size);
            let uv = egui::Rect::from_min_max(egui::pos2(0.0, 0.0), egui::pos2(1.0, 1.0));
            ui.painter().image(id, at, uv, Color32::WHITE);
        }
        let response = ui.interact(
            rect,
            ui.scope_id().with("view"),
            egui::Sense::click_and_drag(),
        );
        let time =
            session.shown_frame().unwrap_or(0) as f32 / session.plan().map_or(24.0, |p| p.file.fps);
        let file = self.file_camera.as_ref();
        if let Some(cam) = camera
            && drive_camera(ui, &response, cam, time, pixels[1] as f32, file)
        {
            out.redraw = true;
        }
        self.keys(ui, session, out);
        if let Some(p) = session.problem() {
            error_overlay(ui, rect, p);
        }
    }

    fn keys(&mut self, ui: &mut Ui, session: &mut Session, out: &mut PanelOut) {
        if ui.memory(|m| m.focused().is_some()) {
            return;
        }
        let pressed = |k| ui.input(|i| i.key_pressed(k));
        if pressed(egui::Key::Space) {
            self.toggle_play(out);
        }
        if pressed(egui::Key::Period) {
            self.step_once = true;
        }
        if pressed(egui::Key::Comma) {
            back_one(session, out);
        }
        if pressed(egui::Key::Home)
            && let Some(r) = session.frames()
        {
            session.show(r.start);
            out.redraw = true;
        }
    }
}

fn software() -> bool {
    imprint_gpu::GpuContext::shared().is_ok_and(|g| g.is_software())
}

fn back_one(session: &mut Session, out: &mut PanelOut) {
    if let Some(f) = session.shown_frame()
        && f > 0
    {
        session.show(f - 1);
        out.redraw = true;
    }
}

/// Mouse and keys on the 3D view; returns whether the camera moved.
fn drive_camera(
    ui: &Ui,
    r: &egui::Response,
    cam: &mut OrbitCamera,
    time: f32,
    height: f32,
    file: Option<&OrbitCamera>,
) -> bool {
    let before = cam.clone();
    let d = r.drag_delta() * ui.pixels_per_point();
    if r.dragged_by(egui::PointerButton::Primary) {
        cam.rotate(time, d.x, d.y);
    } else if r.dragged_by(egui::PointerButton::Secondary)
        || r.dragged_by(egui::PointerButton::Middle)
    {
        cam.pan(time, d.x, d.y, height);
    }
    if r.hovered() {
        let scroll = ui.input(|i| i.smooth_scroll_delta.y);
        if scroll != 0.0 {
            cam.zoom(time, scroll / 50.0);
        }
    }
    if ui.memory(|m| m.focused().is_none()) {
        let key = |k| ui.input(|i| i.key_down(k));
        let step = 3.0 / 0.3;
        let (dx, dy) = (
            f32::from(key(egui::Key::ArrowLeft)) - f32::from(key(egui::Key::ArrowRight)),
            f32::from(key(egui::Key::ArrowUp)) - f32::from(key(egui::Key::ArrowDown)),
        );
        let shift = ui.input(|i| i.modifiers.shift);
        if (dx != 0.0 || dy != 0.0) && shift {
            cam.pan(time, -dx * step, -dy * step, height);
        } else if dx != 0.0 || dy != 0.0 {
            cam.rotate(time, -dx * step, dy * step);
        }
        if ui.input(|i| i.key_pressed(egui::Key::Plus) || i.key_pressed(egui::Key::Equals)) {
            cam.zoom(time, 1.0);
        }
        if ui.input(|i| i.key_pressed(egui::Key::Minus)) {
            cam.zoom(time, -1.0);
        }
        if ui.input(|i| i.key_pressed(egui::Key::R))
            && let Some(f) = file
        {
            *cam = f.clone();
        }
    }
    *cam != before
}

/// A checkbox per object, and its slice or colouring controls.
fn object_row(ui: &mut Ui, session: &Session, o: &mut ViewObject, out: &mut PanelOut) {
    let kind = match o.look {
        Look::Mesh { .. } => "mesh",
        Look::Slice { .. } => "field slice",
        Look::Heights { .. } => "height field",
    };
    out.redraw |= ui
        .checkbox(&mut o.visible, format!("{} ({kind})", o.node))
        .changed();
    if !o.visible {
        return;
    }
    match &mut o.look {
        Look::Slice { axis, index } => {
            let dims = field_dims(session, &o.node);
            ui.horizontal(|ui| {
                for a in [Axis::X, Axis::Y, Axis::Z] {
                    out.redraw |= ui.radio_value(axis, a, a.letter().to_string()).changed();
                }
                if let Some(dims) = dims {
                    let n = dims[axis.dim()];
                    let mut i = index.resolve(*axis, n).unwrap_or(n / 2);
                    if ui
                        .add(egui::Slider::new(&mut i, 0..=n - 1).text("cell"))
                        .changed()
                    {
                        *index = SliceIndex::Cell(i);
                        out.redraw = true;
                    }
                }
            });
        }
        Look::Heights { by_height, .. } => {
            out.redraw |= ui.checkbox(by_height, "colour by height").changed();
        }
        Look::Mesh { .. } => {}
    }
}

fn field_dims(session: &Session, node: &str) -> Option<[u32; 3]> {
    let ex = session.executor()?;
    match ex.value(node)? {
        Value::Field(f) => f.cpu(ex.gpu()).ok().map(|f| f.spec.dims.to_array()),
        _ => None,
    }
}

fn legend(ui: &mut Ui, l: &Legend) {
    ui.label(format!("{}: height, m", l.node));
    let n = l.colors.len();
    for (b, c) in l.colors.iter().enumerate().rev() {
        let lo = l.min + (l.max - l.min) * b as f32 / n as f32;
        let hi = l.min + (l.max - l.min) * (b + 1) as f32 / n as f32;
        ui.horizontal(|ui| {
            let (r, _) = ui.allocate_exact_size(egui::vec2(18.0, 12.0), egui::Sense::hover());
            ui.painter()
                .rect_filled(r, 0.0, Color32::from_rgb(c[0], c[1], c[2]));
            ui.label(
                RichText::new(format!("{lo:+.4} … {hi:+.4}"))
                    .monospace()
                    .small(),
            );
        });
    }
}

/// The problem over the 3D view, where it cannot be missed.
fn error_overlay(ui: &Ui, rect: egui::Rect, p: &crate::session::Problem) {
    egui::Area::new(egui::Id::unique("problem overlay"))
        .fixed_pos(rect.min + egui::vec2(12.0, 12.0))
        .show(ui.ctx(), |ui| {
            egui::Frame::popup(ui.style())
                .fill(Color32::from_rgb(60, 16, 16))
                .show(ui, |ui| {
                    ui.set_max_width(rect.width() - 40.0);
                    ui.label(RichText::new(&p.message).color(Color32::WHITE).strong());
                    if !p.detail.is_empty() {
                        ui.label(RichText::new(&p.detail).monospace().color(Color32::WHITE));
                    }
                    if p.still_running {
                        ui.label(
                            RichText::new("the last good pipeline keeps running")
                                .color(Color32::LIGHT_GRAY),
                        );
                    }
                });
        });
}

/// Every node that ran lately: kind, backend, mean time over the frames it worked, metrics.
fn nodes(ui: &mut Ui, session: &Session) {
    let Some(ex) = session.executor() else {
        return;
    };
    let report = ex.report();
    egui::CollapsingHeader::new("Nodes")
        .default_open(true)
        .show(ui, |ui| {
            egui::Grid::new("node times").striped(true).show(ui, |ui| {
                ui.strong("node");
                ui.strong("kind");
                ui.strong("on");
                ui.strong("ms");
                ui.end_row();
                for (name, r) in &report.nodes {
                    let (sum, n) = session
                        .history()
                        .iter()
                        .flat_map(|f| f.nodes.iter().filter(|(m, _, worked)| m == name && *worked))
                        .fold((0.0, 0u32), |(s, n), (_, ms, _)| (s + ms, n + 1));
                    ui.label(name);
                    ui.label(&r.kind);
                    ui.label(&r.backend);
                    ui.label(if n > 0 {
                        format!("{:.2}", sum / n as f64)
                    } else {
                        "–".into()
                    });
                    ui.end_row();
                }
            });
            for (name, r) in &report.nodes {
                if r.metrics.is_empty() {
                    continue;
                }
                ui.collapsing(format!("{name} metrics"), |ui| {
                    for (k, v) in &r.metrics {
                        ui.label(RichText::new(format!("{k}: {v}")).small());
                    }
                });
            }
        });
}
