//! `sweep.png`: run time against error, one point per setting, the Pareto front drawn and
//! marked, the reference marked. Drawn with plotters into an RGB buffer, text in the DejaVu
//! Sans shipped in `assets/fonts/` (no system font needed), written through `write_png`.

use imprint_core::{Error, Result};
use plotters::prelude::*;
use plotters::style::FontStyle;
use std::path::Path;

/// The picture's size in pixels.
pub const WIDTH: u32 = 1200;
pub const HEIGHT: u32 = 800;

const FONT: &[u8] = include_bytes!("../../../../assets/fonts/DejaVuSans.ttf");
const FAMILY: &str = "imprint-sans";

/// One setting on the plot.
pub struct Point {
    pub time_ms: f64,
    pub error: f64,
    pub label: String,
    pub reference: bool,
    pub pareto: bool,
}

/// Which points are on the Pareto front: no other point is at least as fast and at least as
/// accurate, and better in one of the two.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<bool> {
    points
        .iter()
        .map(|&(t, e)| {
            !points
                .iter()
                .any(|&(t2, e2)| t2 <= t && e2 <= e && (t2 < t || e2 < e))
        })
        .collect()
}

/// The y axis: linear, or log10 of the error when the errors span two decades or more (a zero
/// error then sits on the axis' bottom edge).
struct YAxis {
    log: bool,
    floor: f64,
}

impl YAxis {
    fn new(errors: &[f64]) -> Self {
        let positive: Vec<f64> = errors.iter().copied().filter(|e| *e > 0.0).collect();
        let lo = positive.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = positive.iter().copied().fold(0.0, f64::max);
        let log = !positive.is_empty() && hi / lo >= 100.0;
        YAxis {
            log,
            floor: lo / 2.0,
        }
    }

    fn map(&self, e: f64) -> f64 {
        if self.log {
            e.max(self.floor).log10()
        } else {
            e
        }
    }

    fn range(&self, errors: &[f64]) -> std::ops::Range<f64> {
        let hi = errors.iter().copied().fold(0.0, f64::max);
        if self.log {
            self.floor.log10()..(hi.log10() + 0.15 * (hi.log10() - self.floor.log10()))
        } else if hi > 0.0 {
            -0.04 * hi..1.15 * hi
        } else {
            -0.1..1.0
        }
    }

    fn label(&self, v: f64) -> String {
        let e = if self.log { 10f64.powf(v) } else { v };
        if e != 0.0 && (e.abs() < 1e-3 || e.abs() >= 1e4) {
            format!("{e:.1e}")
        } else {
            format!("{:.4}", e)
                .trim_end_matches('0')
                .trim_end_matches('.')
                .to_string()
        }
    }
}

/// Pixel rectangle: x0, y0, x1, y1.
type Rect = (i32, i32, i32, i32);

fn overlap(a: &Rect, b: &Rect) -> bool {
    a.0 < b.2 && b.0 < a.2 && a.1 < b.3 && b.1 < a.3
}

/// The x axis: the times with a margin, more on the right for the labels; never below 0.
fn x_range(times: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = times.fold((f64::INFINITY, 0.0f64), |(lo, hi), t| {
        (lo.min(t), hi.max(t))
    });
    if !lo.is_finite() || hi <= 0.0 {
        return 0.0..1.0;
    }
    let span = (hi - lo).max(0.1 * hi);
    (lo - 0.15 * span).max(0.0)..hi + 0.35 * span
}

fn register_font() -> Result<()> {
    static ONCE: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ok = *ONCE
        .get_or_init(|| plotters::style::register_font(FAMILY, FontStyle::Normal, FONT).is_ok());
    if ok {
        Ok(())
    } else {
        Err(Error::Run(
            "the plot font (DejaVu Sans) did not load".into(),
        ))
    }
}

/// Draws the plot and writes it to `path` (atomically).
pub fn write_plot(path: &Path, title: &str, y_desc: &str, points: &[Point]) -> Result<()> {
    register_font()?;
    let mut buf = vec![255u8; (WIDTH * HEIGHT * 3) as usize];
    draw(&mut buf, title, y_desc, points)
        .map_err(|e| Error::Run(format!("drawing {}: {e}", path.display())))?;
    let img = image::RgbImage::from_raw(WIDTH, HEIGHT, buf).expect("buffer is WIDTH x HEIGHT");
    imprint_render::png::write_png(path, &img)
}

fn draw(
    buf: &mut [u8],
    title: &str,
    y_desc: &str,
    points: &[Point],
) -> std::result::Result<(), Box<dyn std::error::Error>> {
    let root = BitMapBackend::with_buffer(buf, (WIDTH, HEIGHT)).into_drawing_area();
    root.fill(&WHITE)?;
    let errors: Vec<f64> = points.iter().map(|p| p.error).collect();
    let y = YAxis::new(&errors);
    let x_range = x_range(points.iter().map(|p| p.time_ms));
    let y_desc = if y.log {
        format!("{y_desc} (log scale)")
    } else {
        y_desc.to_string()
    };
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FAMILY, 22))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(90)
        .build_cartesian_2d(x_range, y.range(&errors))?;
    let y_fmt = |v: &f64| y.label(*v);
    chart
        .configure_mesh()
        .x_desc("mean frame time (ms)")
        .y_desc(y_desc)
        .y_label_formatter(&y_fmt)
        .label_style((FAMILY, 14))
        .axis_desc_style((FAMILY, 16))
        .light_line_style(RGBColor(235, 235, 235))
        .draw()?;

    let front_color = RGBColor(230, 120, 20);
    let point_color = RGBColor(40, 90, 170);
    let reference_color = RGBColor(200, 30, 40);
    let mut front: Vec<(f64, f64)> = points
        .iter()
        .filter(|p| p.pareto)
        .map(|p| (p.time_ms, y.map(p.error)))
        .collect();
    front.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.total_cmp(&a.1)));
    chart
        .draw_series(LineSeries::new(front.clone(), front_color.stroke_width(2)))?
        .label("Pareto front")
        .legend(move |(x, y)| PathElement::new([(x, y), (x + 20, y)], front_color.stroke_width(2)));
    chart.draw_series(
        front
            .iter()
            .map(|&p| Circle::new(p, 8, front_color.stroke_width(2))),
    )?;
    chart
        .draw_series(
            points
                .iter()
                .filter(|p| !p.reference)
                .map(|p| Circle::new((p.time_ms, y.map(p.error)), 4, point_color.filled())),
        )?
        .label("setting")
        .legend(move |(x, y)| Circle::new((x + 10, y), 4, point_color.filled()));
    chart
        .draw_series(points.iter().filter(|p| p.reference).map(|p| {
            TriangleMarker::new((p.time_ms, y.map(p.error)), 8, reference_color.filled())
        }))?
        .label("reference")
        .legend(move |(x, y)| TriangleMarker::new((x + 10, y), 6, reference_color.filled()));
    // Labels where they overlap no other label, marker or the legend (upper right).
    let (px, py) = chart.plotting_area().get_pixel_range();
    let mut taken: Vec<Rect> = vec![(px.end - 170, py.start, px.end, py.start + 90)];
    let centres: Vec<(i32, i32)> = points
        .iter()
        .map(|p| chart.backend_coord(&(p.time_ms, y.map(p.error))))
        .collect();
    taken.extend(centres.iter().map(|&(x, y)| (x - 9, y - 9, x + 9, y + 9)));
    let style = TextStyle::from((FAMILY, 14).into_font()).color(&BLACK);
    for (p, &(cx, cy)) in points.iter().zip(&centres) {
        let (w, h) = root.estimate_text_size(&p.label, &style)?;
        let (w, h) = (w as i32, h as i32);
        let candidates = [(10, -h - 6), (10, 6), (-10 - w, -h - 6), (-10 - w, 6)]
            .into_iter()
            .chain((1..6).flat_map(|k| [(10, -h - 6 - k * (h + 2)), (10, 6 + k * (h + 2))]));
        let fits = |r: &Rect| {
            r.0 >= 0
                && r.2 <= WIDTH as i32
                && r.1 >= py.start
                && r.3 <= py.end
                && !taken.iter().any(|t| overlap(t, r))
        };
        let rect = |(dx, dy): (i32, i32)| (cx + dx, cy + dy, cx + dx + w, cy + dy + h);
        let (far, at) = candidates
            .map(rect)
            .enumerate()
            .find(|(_, r)| fits(r))
            .map_or((false, rect((10, -h - 6))), |(i, r)| (i >= 4, r));
        if far {
            // Moved away from its point: a thin line says whose label it is.
            let x = if at.0 > cx { at.0 - 2 } else { at.2 + 2 };
            root.draw(&PathElement::new(
                [(cx, cy), (x, (at.1 + at.3) / 2)],
                RGBColor(150, 150, 150),
            ))?;
        }
        root.draw_text(&p.label, &style, (at.0, at.1))?;
        taken.push(at);
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .label_font((FAMILY, 14))
        .draw()?;
    root.present()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pareto_keeps_the_undominated() {
        let pts = [(1.0, 5.0), (2.0, 2.0), (3.0, 3.0), (4.0, 0.0), (2.0, 2.0)];
        assert_eq!(pareto_front(&pts), [true, true, false, true, true]);
    }

    #[test]
    fn log_axis_only_when_errors_span_decades() {
        assert!(!YAxis::new(&[0.0, 1.0, 50.0]).log);
        let y = YAxis::new(&[0.0, 0.01, 5.0]);
        assert!(y.log);
        assert_eq!(y.map(0.0), y.map(0.005));
        assert_eq!(y.label(2.0), "100");
    }

    #[test]
    fn plot_writes_a_png_of_the_stated_size() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("p.png");
        let points = [
            Point {
                time_ms: 10.0,
                error: 0.0,
                label: "reference".into(),
                reference: true,
                pareto: true,
            },
            Point {
                time_ms: 4.0,
                error: 0.3,
                label: "every=4".into(),
                reference: false,
                pareto: true,
            },
        ];
        write_plot(&path, "t", "err", &points).unwrap();
        let img = image::open(&path).unwrap();
        assert_eq!((img.width(), img.height()), (WIDTH, HEIGHT));
    }
}
