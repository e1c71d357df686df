//! A picture of one grid plane of a distance field, like H Fig. 1 and Fig. 4: the distance in
//! cells through a colour map (0 at the surface, `band` at the band's edge), far cells grey,
//! boundary points marked in white, thin dark iso-lines at every whole cell, and a legend
//! (colour bar with ticks in cells, a "far" swatch, a title, the cell index range of both
//! in-plane axes).
//!
//! Orientation: the in-plane axes are, as (image right, image up),
//! X-slice → (y, z), Y-slice → (x, z), Z-slice → (x, y); cell index 0 of the "up" axis is the
//! bottom row of the picture (the image is flipped from row order so that +up is up).
//! Each cell is a `pixels_per_cell` square of one colour: the picture shows the data as
//! stored, with no interpolation that would hide the grid.
//!
//! In a pipeline file a slice is written `(axis: Z, index: Middle)`; every other field of
//! [`SliceOptions`] has a default, and unknown fields are refused so a typo is reported.

use crate::colormap::Colormap;
use crate::field_io::check_field;
use crate::png::write_png;
use crate::text::{cap_height, draw_text, fill_rect, text_height, text_width};
use image::{Rgb, RgbImage};
use imprint_core::glam::UVec3;
use imprint_core::{DistanceField, Error, GridSpec, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Far cells (outside the band): a neutral grey that viridis never produces.
pub const FAR_GREY: Rgb<u8> = Rgb([150, 150, 150]);
/// Boundary points are marked in white.
pub const BOUNDARY_MARK: Rgb<u8> = Rgb([255, 255, 255]);
/// Page and text colours of the legend.
pub const BACKGROUND: Rgb<u8> = Rgb([255, 255, 255]);
pub const INK: Rgb<u8> = Rgb([25, 25, 25]);
/// Long side of the slice, in pixels, when `pixels_per_cell` is left to choose.
pub const AUTO_LONG_SIDE: u32 = 512;
/// The largest picture side we draw (a guard against a typo like `pixels_per_cell: 4000`).
pub const MAX_SIDE: u32 = 16384;
/// Iso-lines are drawn only when cells are at least this many pixels wide (else they hide the cells).
pub const ISO_MIN_PIXELS: u32 = 3;

/// A grid axis; a slice is the plane normal to it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
#[schemars(rename = "SliceAxis")]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    /// 0, 1, 2 for x, y, z.
    pub fn dim(self) -> usize {
        self as usize
    }

    pub fn letter(self) -> char {
        ['x', 'y', 'z'][self.dim()]
    }

    /// The in-plane axes of a slice normal to `self`: (image right, image up).
    pub fn plane_axes(self) -> (Axis, Axis) {
        match self {
            Axis::X => (Axis::Y, Axis::Z),
            Axis::Y => (Axis::X, Axis::Z),
            Axis::Z => (Axis::X, Axis::Y),
        }
    }
}

/// Which plane along the axis: resolved against the grid when the field is known.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
pub enum SliceIndex {
    /// Cell `size / 2`.
    #[default]
    Middle,
    /// A cell index, 0-based; must be below the axis size.
    Cell(u32),
    /// A fraction of the axis in [0, 1]: 0 is the first cell, 1 the last.
    Fraction(f32),
}

impl SliceIndex {
    /// The cell index along `axis` of `size` cells, or `Error::Invalid` naming the axis, the
    /// index and the size.
    pub fn resolve(self, axis: Axis, size: u32) -> Result<u32> {
        match self {
            SliceIndex::Middle => Ok(size / 2),
            SliceIndex::Cell(i) if i < size => Ok(i),
            SliceIndex::Cell(i) => Err(Error::Invalid(format!(
                "slice index {i} is out of range on axis {axis:?}, which has {size} cells \
                 (valid: 0 to {})",
                size.saturating_sub(1)
            ))),
            SliceIndex::Fraction(f) if f.is_finite() && (0.0..=1.0).contains(&f) => {
                Ok(((f * size.saturating_sub(1) as f32).round() as u32).min(size - 1))
            }
            SliceIndex::Fraction(f) => Err(Error::Invalid(format!(
                "slice fraction {f} on axis {axis:?} ({size} cells) must be between 0 and 1"
            ))),
        }
    }
}

/// What to draw and how (serde: every field has a default, unknown fields are errors).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SliceOptions {
    /// The axis the slice is normal to.
    pub axis: Axis,
    /// Which plane along `axis`: `Middle`, `Cell(i)` or `Fraction(f)`.
    pub index: SliceIndex,
    /// Pixels per cell side; `None` picks the largest that keeps the slice's long side
    /// within [`AUTO_LONG_SIDE`] (at least 1).
    pub pixels_per_cell: Option<u32>,
    /// Colour map of the distance: 0 at the surface, 1 at the band's edge.
    pub colormap: Colormap,
    /// Thin dark lines where the whole number of cells of distance changes.
    pub iso_lines: bool,
    /// White dots at the boundary points that lie in the slice's cells.
    pub mark_boundary: bool,
    /// Title, colour bar and axis labels; without it the picture is the bare slice.
    pub legend: bool,
    /// Start of the title line (e.g. "bunny  frame 0012"); the plane and unit are appended.
    pub title: Option<String>,
}

impl Default for SliceOptions {
    fn default() -> Self {
        SliceOptions {
            axis: Axis::Z,
            index: SliceIndex::Middle,
            pixels_per_cell: None,
            colormap: Colormap::Viridis,
            iso_lines: true,
            mark_boundary: true,
            legend: true,
            title: None,
        }
    }
}

impl SliceOptions {
    pub fn new(axis: Axis, index: SliceIndex) -> Self {
        SliceOptions {
            axis,
            index,
            ..Default::default()
        }
    }

    /// The cell index of the plane along `axis` for this grid.
    pub fn resolve_index(&self, spec: &GridSpec) -> Result<u32> {
        self.index.resolve(self.axis, spec.dims[self.axis.dim()])
    }

    /// Pixels per cell for this grid: the given value, or the automatic one.
    pub fn resolve_pixels_per_cell(&self, spec: &GridSpec) -> Result<u32> {
        let (u, v) = self.axis.plane_axes();
        let long = spec.dims[u.dim()].max(spec.dims[v.dim()]).max(1);
        let ppc = match self.pixels_per_cell {
            None => (AUTO_LONG_SIDE / long).max(1),
            Some(0) => {
                return Err(Error::Invalid(
                    "slice pixels_per_cell must be at least 1".into(),
                ));
            }
            Some(p) => p,
        };
        if long as u64 * ppc as u64 > MAX_SIDE as u64 {
            return Err(Error::Invalid(format!(
                "a slice of {long} cells at {ppc} pixels per cell would be wider than \
                 {MAX_SIDE} pixels; lower pixels_per_cell"
            )));
        }
        Ok(ppc)
    }
}

/// Draws the slice `opts` describes and writes it as a PNG at `path`.
pub fn write_field_slice(path: &Path, field: &DistanceField, opts: &SliceOptions) -> Result<()> {
    let img = render_field_slice(field, opts)?;
    write_png(path, &img)
}

/// Draws the slice `opts` describes, with its legend unless `opts.legend` is false.
pub fn render_field_slice(field: &DistanceField, opts: &SliceOptions) -> Result<RgbImage> {
    check_field(field)?;
    let index = opts.resolve_index(&field.spec)?;
    let ppc = opts.resolve_pixels_per_cell(&field.spec)?;
    let plane = Plane::new(&field.spec, opts.axis, index);
    let slice = draw_cells(field, &plane, ppc, opts);
    if !opts.legend {
        return Ok(slice);
    }
    Ok(add_legend(field, &plane, ppc, opts, &slice))
}

/// One plane of the grid: maps in-plane cell coordinates (a right, b up) to grid indices.
struct Plane {
    axis: Axis,
    index: u32,
    u: Axis,
    v: Axis,
    nu: u32,
    nv: u32,
    spec: GridSpec,
}

impl Plane {
    fn new(spec: &GridSpec, axis: Axis, index: u32) -> Self {
        let (u, v) = axis.plane_axes();
        Plane {
            axis,
            index,
            u,
            v,
            nu: spec.dims[u.dim()],
            nv: spec.dims[v.dim()],
            spec: *spec,
        }
    }

    fn cell(&self, a: u32, b: u32) -> usize {
        let mut c = UVec3::ZERO;
        c[self.axis.dim()] = self.index;
        c[self.u.dim()] = a;
        c[self.v.dim()] = b;
        self.spec.index(c)
    }

    /// Top image row of in-plane row `b` (row 0 is at the bottom).
    fn top_row(&self, b: u32, ppc: u32) -> u32 {
        (self.nv - 1 - b) * ppc
    }
}

/// The slice alone: `nu * ppc` by `nv * ppc` pixels.
fn draw_cells(field: &DistanceField, plane: &Plane, ppc: u32, opts: &SliceOptions) -> RgbImage {
    let cell = field.spec.cell;
    let mut img = RgbImage::new(plane.nu * ppc, plane.nv * ppc);
    let p = ppc as i64;
    // Whole cells of distance, None when far: iso-lines separate different levels.
    let level = |i: usize| (!field.is_far(i)).then(|| (field.dist[i] / cell).floor() as i64);

    for b in 0..plane.nv {
        let y = plane.top_row(b, ppc) as i64;
        for a in 0..plane.nu {
            let i = plane.cell(a, b);
            let color = if field.is_far(i) {
                FAR_GREY
            } else {
                Rgb(opts.colormap.sample(field.dist[i] / cell / field.band))
            };
            fill_rect(&mut img, a as i64 * p, y, p, p, color);
        }
    }

    if opts.iso_lines && ppc >= ISO_MIN_PIXELS {
        for b in 0..plane.nv {
            let y = plane.top_row(b, ppc);
            for a in 0..plane.nu {
                let here = level(plane.cell(a, b));
                if here.is_none() {
                    continue;
                }
                // Right neighbour: the last pixel column of this cell.
                if a + 1 < plane.nu {
                    let right = level(plane.cell(a + 1, b));
                    if right.is_some() && right != here {
                        let x = (a + 1) * ppc - 1;
                        (y..y + ppc).for_each(|py| darken(&mut img, x, py));
                    }
                }
                // Neighbour above: the top pixel row of this cell.
                if b + 1 < plane.nv {
                    let up = level(plane.cell(a, b + 1));
                    if up.is_some() && up != here {
                        (a * ppc..(a + 1) * ppc).for_each(|px| darken(&mut img, px, y));
                    }
                }
            }
        }
    }

    if opts.mark_boundary {
        // A cell is a boundary cell when its nearest point lies inside it; the mark sits at
        // the point's position projected onto the plane (sub-cell for the Closest variant).
        let dot = ppc.div_ceil(3).max(1) as i64;
        for b in 0..plane.nv {
            for a in 0..plane.nu {
                let i = plane.cell(a, b);
                if field.is_far(i) {
                    continue;
                }
                let q = field.vector(i) / cell;
                if q.abs().max_element() > 0.5 + 1e-4 {
                    continue;
                }
                let qu = q[plane.u.dim()].clamp(-0.5, 0.5);
                let qv = q[plane.v.dim()].clamp(-0.5, 0.5);
                let cx = ((a as f32 + 0.5 + qu) * ppc as f32) as i64;
                let cy = (((plane.nv - 1 - b) as f32 + 0.5 - qv) * ppc as f32) as i64;
                // Keep the dot inside its cell.
                let x0 = (cx - dot / 2).clamp(a as i64 * p, (a as i64 + 1) * p - dot);
                let y0 = (cy - dot / 2).clamp(
                    plane.top_row(b, ppc) as i64,
                    plane.top_row(b, ppc) as i64 + p - dot,
                );
                fill_rect(&mut img, x0, y0, dot, dot, BOUNDARY_MARK);
            }
        }
    }
    img
}

fn darken(img: &mut RgbImage, x: u32, y: u32) {
    let px = img.get_pixel_mut(x, y);
    px.0 = px.0.map(|c| (c as f32 * 0.35) as u8);
}

/// A number as a tick label: "3", "2.5".
fn tick_label(v: f32) -> String {
    if (v - v.round()).abs() < 1e-4 {
        format!("{}", v.round() as i64)
    } else {
        let s = format!("{v:.2}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// Tick values in cells from 0 to `band`: a step of 1, 2, 5, 10, ... cells, the smallest whose
/// labels do not overlap on a bar of `bar_h` pixels; plus `band` itself when not on the step.
fn ticks(band: f32, bar_h: u32, label_h: u32) -> Vec<f32> {
    let px_per_cell = (bar_h.saturating_sub(1)) as f32 / band;
    let mut step = 1.0f32;
    for k in 0.. {
        step = [1.0, 2.0, 5.0][k % 3] * 10f32.powi(k as i32 / 3);
        if step * px_per_cell >= label_h as f32 || step >= band {
            break;
        }
    }
    let mut out: Vec<f32> = (0..)
        .map(|k| k as f32 * step)
        .take_while(|&v| v <= band + 1e-4)
        .collect();
    let last = *out.last().unwrap_or(&0.0);
    if band - last > 1e-4 && (band - last) * px_per_cell >= label_h as f32 {
        out.push(band);
    }
    out
}

/// Puts the slice on a page with a title, axis labels and a colour bar on the right.
fn add_legend(
    field: &DistanceField,
    plane: &Plane,
    ppc: u32,
    opts: &SliceOptions,
    slice: &RgbImage,
) -> RgbImage {
    let (sw, sh) = (slice.width() as i64, slice.height() as i64);
    // Text at 2x on slices of a usual size, 1x on small ones.
    let ts = if sw.max(sh) >= 256 { 2 } else { 1 };
    let tsi = ts as i64;
    let lh = text_height(ts) as i64;
    let cap = cap_height(ts) as i64;
    let gap = 4 * tsi;
    let margin = 8 * tsi;

    let plane_text = format!("{} = {}", plane.axis.letter(), plane.index);
    let title = match opts.title.as_deref() {
        Some(t) if !t.is_empty() => format!("{t}  {plane_text}  distance (cells)"),
        _ => format!("{plane_text}  distance (cells)"),
    };

    // Left column: the up axis' index range and letter.
    let v_top = (plane.nv - 1).to_string();
    let v_name = plane.v.letter().to_string();
    let left_w = [&v_top, &v_name, "0"]
        .iter()
        .map(|s| text_width(s, ts) as i64)
        .max()
        .unwrap_or(0);
    let x0 = margin + left_w + gap;
    let y0 = margin + lh + 2 * gap;

    // Colour bar: a "far" swatch on top, the bar below it down to the slice's bottom (or
    // lower, for slices too short to hold a readable bar).
    let bar_w = 8 * tsi;
    let tick_len = 3 * tsi;
    let bar_x = x0 + sw + 6 * gap;
    let swatch_y = y0;
    let bar_top = swatch_y + bar_w + 3 * gap;
    let bar_bottom = (y0 + sh).max(bar_top + 4 * lh);
    let bar_h = (bar_bottom - bar_top) as u32;
    let tick_values = ticks(field.band, bar_h, (lh + tsi) as u32);
    let labels: Vec<String> = tick_values.iter().map(|&v| tick_label(v)).collect();
    let label_x = bar_x + bar_w + tick_len + gap / 2;
    let label_w = labels
        .iter()
        .map(|s| text_width(s, ts))
        .chain([text_width("far", ts)])
        .max()
        .unwrap_or(0) as i64;

    let width = (label_x + label_w + margin).max(margin + text_width(&title, ts) as i64 + margin);
    let height = (y0 + sh + gap + lh).max(bar_bottom + cap / 2 + 1) + margin;
    let mut img = RgbImage::from_pixel(width as u32, height as u32, BACKGROUND);

    draw_text(&mut img, margin, margin, &title, ts, INK);

    // The slice, framed by a one-pixel line just outside it.
    frame(&mut img, x0, y0, sw, sh);
    image::imageops::replace(&mut img, slice, x0, y0);

    // Axis labels: index 0 at the bottom-left, the last index at the ends, the letter mid-way.
    let right_align = |s: &str, x: i64| x - text_width(s, ts) as i64;
    draw_text(&mut img, right_align(&v_top, x0 - gap), y0, &v_top, ts, INK);
    draw_text(
        &mut img,
        right_align(&v_name, x0 - gap),
        y0 + sh / 2 - cap / 2,
        &v_name,
        ts,
        INK,
    );
    draw_text(
        &mut img,
        right_align("0", x0 - gap),
        y0 + sh - cap,
        "0",
        ts,
        INK,
    );
    let below = y0 + sh + gap;
    let u_last = (plane.nu - 1).to_string();
    let u_name = plane.u.letter().to_string();
    draw_text(&mut img, x0, below, "0", ts, INK);
    draw_text(
        &mut img,
        x0 + sw / 2 - text_width(&u_name, ts) as i64 / 2,
        below,
        &u_name,
        ts,
        INK,
    );
    draw_text(
        &mut img,
        right_align(&u_last, x0 + sw),
        below,
        &u_last,
        ts,
        INK,
    );

    // The far swatch.
    fill_rect(&mut img, bar_x, swatch_y, bar_w, bar_w, FAR_GREY);
    frame(&mut img, bar_x, swatch_y, bar_w, bar_w);
    draw_text(
        &mut img,
        label_x,
        swatch_y + (bar_w - cap) / 2,
        "far",
        ts,
        INK,
    );

    // The bar: 0 cells at the bottom, band at the top.
    let value_y = |v: f32| bar_bottom - 1 - (v / field.band * (bar_h - 1) as f32).round() as i64;
    for y in bar_top..bar_bottom {
        let t = (bar_bottom - 1 - y) as f32 / (bar_h - 1) as f32;
        fill_rect(&mut img, bar_x, y, bar_w, 1, Rgb(opts.colormap.sample(t)));
    }
    if opts.iso_lines && ppc >= ISO_MIN_PIXELS {
        // The slice's iso-lines sit at whole cells: mark the same levels across the bar.
        for k in 1..field.band.ceil() as i64 {
            let y = value_y(k as f32);
            for x in bar_x..bar_x + bar_w {
                darken(&mut img, x as u32, y as u32);
            }
        }
    }
    frame(&mut img, bar_x, bar_top, bar_w, bar_h as i64);
    for (&v, label) in tick_values.iter().zip(&labels) {
        let y = value_y(v);
        fill_rect(&mut img, bar_x + bar_w, y - tsi / 2, tick_len, tsi, INK);
        draw_text(&mut img, label_x, y - cap / 2, label, ts, INK);
    }
    img
}

/// A one-pixel INK rectangle just outside the box (x, y, w, h).
fn frame(img: &mut RgbImage, x: i64, y: i64, w: i64, h: i64) {
    fill_rect(img, x - 1, y - 1, w + 2, 1, INK);
    fill_rect(img, x - 1, y + h, w + 2, 1, INK);
    fill_rect(img, x - 1, y - 1, 1, h + 2, INK);
    fill_rect(img, x + w, y - 1, 1, h + 2, INK);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::colormap::viridis;
    use imprint_core::glam::Vec3;

    /// Distance to the plane y = y0 on an 8x6x4 grid of unit cells at the origin, band 2:
    /// rows j with |j - y0| <= 2 are in band. Each in-band cell has its own boundary point
    /// (the foot of the perpendicular), as an exact field would.
    fn plane_field(y0: f32) -> DistanceField {
        let spec = GridSpec::new(Vec3::ZERO, 1.0, UVec3::new(8, 6, 4)).unwrap();
        DistanceField::from_closest_points(spec, 2.0, |c| Vec3::new(c.x, y0, c.z))
    }

    fn bare(axis: Axis, index: SliceIndex, ppc: u32) -> SliceOptions {
        SliceOptions {
            pixels_per_cell: Some(ppc),
            legend: false,
            iso_lines: false,
            mark_boundary: false,
            ..SliceOptions::new(axis, index)
        }
    }

    /// Colour of cell (a right, b up) in a bare slice at `ppc` pixels per cell.
    fn cell_px(img: &RgbImage, a: u32, b: u32, ppc: u32) -> [u8; 3] {
        let rows = img.height() / ppc;
        img.get_pixel(a * ppc + ppc / 2, (rows - 1 - b) * ppc + ppc / 2)
            .0
    }

    #[test]
    fn z_slice_is_x_right_y_up() {
        // Plane y = 1: row j = 1 is at distance 0, rows 4-5 are far.
        let field = plane_field(1.0);
        let img = render_field_slice(&field, &bare(Axis::Z, SliceIndex::Cell(2), 4)).unwrap();
        assert_eq!((img.width(), img.height()), (8 * 4, 6 * 4));
        // y = 1 is the second row from the BOTTOM of the picture.
        assert_eq!(img.get_pixel(5 * 4 + 1, 4 * 4 + 2).0, viridis(0.0));
        // y = 5 (the top row of the picture) is far.
        assert_eq!(img.get_pixel(3, 1).0, FAR_GREY.0);
        // y = 3, two cells away: the top of the colour map.
        assert_eq!(cell_px(&img, 0, 3, 4), viridis(1.0));
        // y = 2, one cell: its middle.
        assert_eq!(cell_px(&img, 7, 2, 4), viridis(0.5));
    }

    #[test]
    fn x_slice_is_y_right_z_up() {
        let field = plane_field(1.0);
        let img = render_field_slice(&field, &bare(Axis::X, SliceIndex::Middle, 3)).unwrap();
        // Right is y (6 cells), up is z (4 cells).
        assert_eq!((img.width(), img.height()), (6 * 3, 4 * 3));
        for b in 0..4 {
            assert_eq!(cell_px(&img, 1, b, 3), viridis(0.0));
            assert_eq!(cell_px(&img, 5, b, 3), FAR_GREY.0);
        }
        // Y-slice: right is x, up is z; the plane y = 1 cuts it at distance 0 everywhere.
        let img = render_field_slice(&field, &bare(Axis::Y, SliceIndex::Cell(1), 2)).unwrap();
        assert_eq!((img.width(), img.height()), (8 * 2, 4 * 2));
        assert!(img.pixels().all(|p| p.0 == viridis(0.0)));
    }

    #[test]
    fn boundary_marks_and_iso_lines_are_drawn() {
        let field = plane_field(1.0);
        let opts = SliceOptions {
            pixels_per_cell: Some(9),
            legend: false,
            ..SliceOptions::new(Axis::Z, SliceIndex::Cell(0))
        };
        let img = render_field_slice(&field, &opts).unwrap();
        // Row y = 1 holds the boundary points, at the cells' centres: a white dot there.
        let (cx, cy) = (3 * 9 + 4, 4 * 9 + 4);
        assert_eq!(img.get_pixel(cx, cy).0, BOUNDARY_MARK.0);
        // Its corner keeps the colour of distance 0.
        assert_eq!(img.get_pixel(3 * 9 + 1, 4 * 9 + 7).0, viridis(0.0));
        // Rows y = 1 (level 0) and y = 2 (level 1) differ: a dark line on y = 1's top row.
        let line = img.get_pixel(3 * 9 + 4, 4 * 9).0;
        assert_eq!(line, viridis(0.0).map(|c| (c as f32 * 0.35) as u8));
        // Between y = 3 (level 2, in band) and y = 4 (far) no line: y = 3's top row keeps
        // the colour of 2 cells.
        assert_eq!(img.get_pixel(2 * 9 + 4, 2 * 9).0, viridis(1.0));
        // Only cells holding their nearest point are marked: none in row y = 2.
        assert!((0..8 * 9).all(|x| img.get_pixel(x, 3 * 9 + 4).0 != BOUNDARY_MARK.0));
    }

    #[test]
    fn out_of_range_index_names_axis_index_and_size() {
        let field = plane_field(1.0);
        let e = render_field_slice(&field, &bare(Axis::Y, SliceIndex::Cell(6), 1)).unwrap_err();
        let msg = e.to_string();
        assert!(matches!(e, Error::Invalid(_)));
        assert!(
            msg.contains("6") && msg.contains("Y") && msg.contains("6 cells"),
            "{msg}"
        );
        assert!(render_field_slice(&field, &bare(Axis::Z, SliceIndex::Fraction(1.5), 1)).is_err());
        assert!(
            render_field_slice(&field, &bare(Axis::Z, SliceIndex::Fraction(f32::NAN), 1)).is_err()
        );
        assert!(render_field_slice(&field, &bare(Axis::Z, SliceIndex::Cell(3), 0)).is_err());
        // The ends resolve inside the axis.
        assert_eq!(SliceIndex::Fraction(1.0).resolve(Axis::X, 8).unwrap(), 7);
        assert_eq!(SliceIndex::Fraction(0.0).resolve(Axis::X, 8).unwrap(), 0);
        assert_eq!(SliceIndex::Middle.resolve(Axis::X, 8).unwrap(), 4);
    }

    #[test]
    fn options_deserialize_with_defaults_and_refuse_typos() {
        // The shape a pipeline file uses.
        let o: SliceOptions = ron::from_str("(axis: X, index: Fraction(0.25))").unwrap();
        assert_eq!(o.axis, Axis::X);
        assert_eq!(o.index, SliceIndex::Fraction(0.25));
        assert!(o.legend && o.iso_lines && o.mark_boundary && o.pixels_per_cell.is_none());
        let v: Vec<SliceOptions> =
            ron::from_str("[(axis: Z, index: Middle), (index: Cell(3), iso_lines: false)]")
                .unwrap();
        assert_eq!(v[1].axis, Axis::Z);
        assert_eq!(v[1].index, SliceIndex::Cell(3));
        assert!(!v[1].iso_lines);
        assert!(ron::from_str::<SliceOptions>("(axis: Z, indx: Middle)").is_err());
    }

    #[test]
    fn auto_scale_targets_the_long_side() {
        let spec = GridSpec::new(Vec3::ZERO, 1.0, UVec3::new(96, 40, 128)).unwrap();
        let z = SliceOptions::new(Axis::Z, SliceIndex::Middle);
        assert_eq!(z.resolve_pixels_per_cell(&spec).unwrap(), 5); // 96 long -> 480 px
        let x = SliceOptions::new(Axis::X, SliceIndex::Middle);
        assert_eq!(x.resolve_pixels_per_cell(&spec).unwrap(), 4); // 128 long -> 512 px
        let huge = SliceOptions {
            pixels_per_cell: Some(1000),
            ..x
        };
        assert!(huge.resolve_pixels_per_cell(&spec).is_err());
    }

    #[test]
    fn legend_page_holds_the_slice_and_the_bar() {
        let field = plane_field(1.0);
        let opts = SliceOptions {
            pixels_per_cell: Some(40),
            title: Some("plane  frame 0007".into()),
            ..SliceOptions::new(Axis::Z, SliceIndex::Cell(1))
        };
        let img = render_field_slice(&field, &opts).unwrap();
        let bare_img = render_field_slice(
            &field,
            &SliceOptions {
                legend: false,
                ..opts.clone()
            },
        )
        .unwrap();
        assert!(img.width() > bare_img.width() + 40 && img.height() > bare_img.height());
        // The bare slice appears unchanged somewhere on the page: find its top-left pixel
        // run (the far row) and compare the whole block.
        let found = (0..=img.height() - bare_img.height()).any(|y| {
            (0..=img.width() - bare_img.width()).any(|x| {
                img.get_pixel(x, y) == bare_img.get_pixel(0, 0)
                    && bare_img
                        .enumerate_pixels()
                        .step_by(7)
                        .all(|(bx, by, p)| img.get_pixel(x + bx, y + by) == p)
            })
        });
        assert!(found, "slice not found on the legend page");
        // The bar's ends are the map's ends, and the page holds the far grey swatch.
        let has = |c: [u8; 3]| img.pixels().any(|p| p.0 == c);
        assert!(has(viridis(0.0)) && has(viridis(1.0)) && has(FAR_GREY.0));
    }

    #[test]
    fn ticks_cover_the_band_without_overlap() {
        assert_eq!(ticks(3.0, 300, 20), vec![0.0, 1.0, 2.0, 3.0]);
        assert_eq!(ticks(2.5, 300, 20), vec![0.0, 1.0, 2.0, 2.5]);
        // A wide band on a short bar takes larger steps.
        let t = ticks(40.0, 200, 20);
        assert!(
            t.windows(2).all(|w| (w[1] - w[0]) * 199.0 / 40.0 >= 20.0),
            "{t:?}"
        );
        assert_eq!(t.first(), Some(&0.0));
        assert_eq!(tick_label(2.5), "2.5");
        assert_eq!(tick_label(3.0), "3");
    }
}
