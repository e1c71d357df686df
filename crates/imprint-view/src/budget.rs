//! `--target-fps N` in the window: measure the frames, let the scheduler choose `every`,
//! `split` and `interpolate` for the expensive nodes (`imprint_graph::budget`), apply the
//! choice as live edits, show it with what it costs, and print it as RON to paste.

use crate::panel::PanelOut;
use crate::session::{Reloaded, Session};
use egui::{RichText, Ui};
use imprint_graph::budget::{Budget, Measured, choose};
use imprint_graph::executor::FrameSummary;

/// Frames measured before choosing (after the first ones, which load and build).
const MEASURE: u32 = 8;
const SKIP: u32 = 2;

pub struct BudgetView {
    target_fps: f64,
    measured: Measured,
    seen: u32,
    chosen: Option<Budget>,
    /// Frames since the choice was applied, their work (step, drawing, UI) in ms, and when
    /// the first of them started: the fps held and the fps the work alone would allow.
    held: (u32, f64, Option<std::time::Instant>),
}

impl BudgetView {
    pub fn new(target_fps: f64) -> BudgetView {
        BudgetView {
            target_fps,
            measured: Measured::new(),
            seen: 0,
            chosen: None,
            held: (0, 0.0, None),
        }
    }

    /// A frame stepped, and what drawing and the UI took around it.
    pub fn observe(&mut self, summary: &FrameSummary, draw_ui_ms: f64) {
        self.seen += 1;
        if self.chosen.is_some() {
            // The first frame after the reload builds its fields whole: not counted.
            if self.held.2.is_none() {
                self.held.2 = Some(std::time::Instant::now());
                return;
            }
            self.held.0 += 1;
            self.held.1 += summary.ms + draw_ui_ms;
            return;
        }
        if self.seen > SKIP {
            self.measured.add_frame(summary);
            self.measured.add_overhead_ms(draw_ui_ms);
        }
    }

    /// Chooses once enough frames were measured, and applies the choice.
    fn decide(&mut self, session: &mut Session, out: &mut PanelOut) {
        if self.chosen.is_some() || self.measured.frames() < MEASURE {
            return;
        }
        let Some(plan) = session.plan() else {
            return;
        };
        let budget = choose(plan, &self.measured, self.target_fps);
        // A target out of reach is not chased: the largest `every` would cost accuracy (on
        // H's twisting bunny, fields 8 frames apart let the cloth explode) and still miss.
        let apply = if budget.met {
            budget.assignments()
        } else {
            Vec::new()
        };
        for a in apply {
            if session.edit(a) == Reloaded::Refused {
                break;
            }
            out.reloaded = true;
        }
        crate::app::say(&self.report_of(&budget));
        self.chosen = Some(budget);
    }

    pub fn show(&mut self, ui: &mut Ui, session: &mut Session, out: &mut PanelOut) {
        self.decide(session, out);
        egui::CollapsingHeader::new(format!("Frame budget: {} fps", self.target_fps))
            .default_open(true)
            .show(ui, |ui| match &self.chosen {
                None => {
                    ui.label(format!(
                        "measuring ({} of {} frames)",
                        self.measured.frames(),
                        MEASURE
                    ));
                }
                Some(b) => {
                    ui.label(self.report_of(b));
                    ui.label(RichText::new(b.ron_snippet()).monospace().small());
                    if ui.button("Copy the RON").clicked() {
                        ui.ctx().copy_text(b.ron_snippet());
                    }
                    if ui.button("Measure and choose again").clicked() {
                        *self = BudgetView::new(self.target_fps);
                    }
                }
            });
    }

    fn report_of(&self, b: &Budget) -> String {
        let mut s = format!(
            "budget: target {:.1} ms ({} fps), predicted {:.1} ms, {}",
            b.target_ms,
            self.target_fps,
            b.predicted_ms,
            if b.met {
                "met, applied"
            } else {
                "not met: not applied"
            }
        );
        for n in &b.notes {
            s += &format!("\n  {n}");
        }
        for c in &b.choices {
            s += &format!(
                "\n  {}: every {}, split {}, interpolate {} ({:.1} ms per build, {:.1} ms per \
                 frame): {}",
                c.node, c.every, c.split, c.interpolate, c.build_ms, c.per_frame_ms, c.cost
            );
        }
        if let (n @ 1.., ms, Some(since)) = self.held {
            let wall = since.elapsed().as_secs_f64();
            s += &format!(
                "\n  held: {:.1} fps over {n} frames ({:.1} ms of work a frame)",
                n as f64 / wall.max(1e-9),
                ms / n as f64
            );
        }
        s
    }

    /// The choice and the fps held, for the end of a headless run.
    pub fn report(&self) -> String {
        match &self.chosen {
            Some(b) => format!("{}\n{}", self.report_of(b), b.ron_snippet()),
            None => "budget: not enough frames measured to choose".into(),
        }
    }
}
