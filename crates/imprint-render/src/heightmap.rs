//! Height fields as files: a 16-bit grayscale PNG with a JSON sidecar, a single-channel f32
//! OpenEXR, a NumPy `.npy`, and an 8-bit colour-mapped preview PNG with a legend.
//!
//! Orientation of every file (PNG, EXR, `.npy`, preview): **north up**. Row 0 is the highest
//! z index (`k = nz - 1`), the last row is `k = 0`; column `c` is `i = c` (x grows to the
//! right). Looking down the -y axis with x to the right, z then points up the page. The
//! `.npy` array, shape `[nz, nx]`, is laid out as the pictures are (`a[r, c] = get(c, nz - 1
//! - r)`), so `imshow(a)` shows what the PNG shows; `a[::-1]` indexes it by `[k, i]`. The
//! PNG's and the `.npy`'s sidecars say so ([`ROWS`], [`COLUMNS`]).
//!
//! Every file goes through [`atomic_write`]. The PNG's sidecar is written before the PNG, so a
//! PNG under its final name always has its sidecar next to it.

use crate::colormap::Colormap;
use crate::npy::write_npy_f32;
use crate::png::write_png;
use crate::text::{draw_text, fill_rect, text_height, text_width};
use image::codecs::png::PngEncoder;
use image::{ImageBuffer, Luma, Rgb, RgbImage};
use imprint_core::glam::{UVec2, Vec2};
use imprint_core::io::{atomic_write, atomic_write_bytes};
use imprint_core::{Error, HeightField, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The orientation every heightmap file uses, as recorded in the sidecar.
pub const ORIENTATION: &str =
    "row 0 = highest z index (north up); column 0 = lowest x index; x right, z up the page";

/// What a row of every heightmap file is, in world terms (sidecars and `report.json` say it).
pub const ROWS: &str = "constant z; row 0 is the largest z (north up), the last row the smallest";

/// What a column of every heightmap file is, in world terms.
pub const COLUMNS: &str = "constant x; column 0 is the smallest x, x grows to the right";

/// Largest 16-bit level: `min` maps to 0, `max` to this.
const LEVELS: f64 = 65535.0;

/// The JSON sidecar of a 16-bit heightmap PNG or a `.npy` (`<path>.json`): everything needed
/// to put the cells at their world positions, and for the PNG to turn the levels back into
/// heights: `height = min + level * (max - min) / 65535`; level 0 is exactly `min`, 65535
/// exactly `max`. The `.npy` holds the heights themselves.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeightmapMeta {
    /// Always "imprint-heightmap".
    pub format: String,
    pub version: u32,
    /// The lowest height (level 0), world units.
    pub min: f32,
    /// The highest height (level 65535), world units; equal to `min` for a constant field.
    pub max: f32,
    /// World (x, z) of the centre of cell (0, 0).
    pub origin: [f32; 2],
    /// Cell edge length, world units.
    pub cell: f32,
    /// [nx, nz]: image width and height.
    pub dims: [u32; 2],
    /// Height per level, `(max - min) / 65535` (0 for a constant field, and for the exact
    /// `.npy`): the worst round-trip error is half of it.
    pub quantisation_step: f64,
    /// See [`ORIENTATION`].
    pub orientation: String,
    /// What a row is in the world ([`ROWS`]; sidecars before it: the same order).
    #[serde(default)]
    pub rows: String,
    /// What a column is in the world ([`COLUMNS`]).
    #[serde(default)]
    pub columns: String,
}

impl HeightmapMeta {
    /// The sidecar of `hf` written as levels of `quantisation_step` (0: exact heights).
    fn of(hf: &HeightField, quantisation_step: f64) -> Self {
        let (min, max) = hf.height_range();
        HeightmapMeta {
            format: "imprint-heightmap".into(),
            version: 1,
            min,
            max,
            origin: hf.origin.to_array(),
            cell: hf.cell,
            dims: [hf.dims.x, hf.dims.y],
            quantisation_step,
            orientation: ORIENTATION.into(),
            rows: ROWS.into(),
            columns: COLUMNS.into(),
        }
    }

    /// Writes it beside the file at `path` (before that file, so the file under its final
    /// name always has its sidecar).
    fn write_beside(&self, path: &Path) -> Result<()> {
        let json = serde_json::to_vec_pretty(self).map_err(|e| Error::Run(e.to_string()))?;
        atomic_write_bytes(&sidecar_path(path), &json)
    }
}

/// The sidecar path of a heightmap PNG: `<path>.json` (`a.png` -> `a.png.json`).
pub fn sidecar_path(path: &Path) -> PathBuf {
    let mut s = path.as_os_str().to_owned();
    s.push(".json");
    PathBuf::from(s)
}

/// Image row of cell row `k` (north up).
fn row_of(hf: &HeightField, k: u32) -> u32 {
    hf.dims.y - 1 - k
}

fn io_err(path: &Path, e: impl std::fmt::Display) -> Error {
    Error::Invalid(format!("{}: {e}", path.display()))
}

/// Writes a 16-bit grayscale PNG (`[min, max]` mapped linearly onto `[0, 65535]`, rounded to
/// the nearest level; a constant field is all 0) and its sidecar `<path>.json`
/// ([`HeightmapMeta`]).
pub fn write_heightmap_png16(path: &Path, hf: &HeightField) -> Result<()> {
    hf.validate()?;
    let (min, max) = hf.height_range();
    let range = max as f64 - min as f64;
    let (nx, nz) = (hf.dims.x, hf.dims.y);
    let img: ImageBuffer<Luma<u16>, Vec<u16>> = ImageBuffer::from_fn(nx, nz, |c, r| {
        let h = hf.get(c, nz - 1 - r) as f64;
        let level = if range > 0.0 {
            ((h - min as f64) / range * LEVELS)
                .round()
                .clamp(0.0, LEVELS) as u16
        } else {
            0
        };
        Luma([level])
    });
    HeightmapMeta::of(hf, range / LEVELS).write_beside(path)?;
    atomic_write(path, |w| {
        img.write_with_encoder(PngEncoder::new(w))
            .map_err(std::io::Error::other)
    })
}

/// Reads a heightmap written by [`write_heightmap_png16`], using its sidecar for the range,
/// origin and cell size. Heights come back within half a quantisation step (exactly at the
/// minimum and maximum).
pub fn read_heightmap_png16(path: &Path) -> Result<HeightField> {
    let side = sidecar_path(path);
    let text = std::fs::read_to_string(&side).map_err(|e| Error::io(&side, e))?;
    let meta: HeightmapMeta = serde_json::from_str(&text)
        .map_err(|e| io_err(&side, format!("not a heightmap sidecar ({e})")))?;
    let img = image::ImageReader::open(path)
        .map_err(|e| Error::io(path, e))?
        .decode()
        .map_err(|e| io_err(path, e))?;
    let image::DynamicImage::ImageLuma16(img) = img else {
        return Err(io_err(path, "not a 16-bit grayscale PNG"));
    };
    let [nx, nz] = meta.dims;
    if img.dimensions() != (nx, nz) {
        return Err(io_err(
            path,
            format!(
                "image is {} x {} but the sidecar says {nx} x {nz}",
                img.width(),
                img.height()
            ),
        ));
    }
    let (min, max) = (meta.min, meta.max);
    let range = max as f64 - min as f64;
    HeightField::from_fn(
        Vec2::from_array(meta.origin),
        meta.cell,
        UVec2::new(nx, nz),
        |i, k| match img.get_pixel(i, nz - 1 - k).0[0] {
            0 => min,
            65535 => max,
            q => (min as f64 + range * (q as f64 / LEVELS)) as f32,
        },
    )
}

/// One custom attribute, v3f (origin x, origin z, cell): the exr crate keeps custom
/// attributes in a hash map and writes them in its order, which changes from run to run, so
/// more than one would make the same heights give different bytes.
const EXR_GRID: &str = "imprintGrid";
/// Earlier files' attributes, still read.
const EXR_ORIGIN: &str = "imprintOrigin";
const EXR_CELL: &str = "imprintCell";
/// The channel name of a heightmap EXR: "Y", so viewers show it as a grayscale image.
pub const EXR_CHANNEL: &str = "Y";

/// Writes a single-channel f32 OpenEXR (channel [`EXR_CHANNEL`] = "Y", ZIP-compressed, so the
/// heights are stored bit-exactly), north up. The origin and cell size go into the header as
/// the custom attribute `imprintGrid` (v3f: origin x, origin z, cell), the orientation into
/// its standard `comments`. The same heights give the same bytes.
pub fn write_heightmap_exr(path: &Path, hf: &HeightField) -> Result<()> {
    use exr::prelude::*;
    hf.validate()?;
    let (nx, nz) = (hf.dims.x as usize, hf.dims.y as usize);
    let mut samples = Vec::with_capacity(nx * nz);
    for r in 0..hf.dims.y {
        let k = row_of(hf, r);
        samples.extend((0..hf.dims.x).map(|i| hf.get(i, k)));
    }
    let mut attrs = LayerAttributes::named("height");
    attrs.other.insert(
        Text::from(EXR_GRID),
        AttributeValue::FloatVec3((hf.origin.x, hf.origin.y, hf.cell)),
    );
    attrs.comments = Some(Text::from(ORIENTATION));
    let channel = AnyChannel::new(EXR_CHANNEL, FlatSamples::F32(samples));
    let layer = Layer::new(
        (nx, nz),
        attrs,
        Encoding::SMALL_LOSSLESS,
        AnyChannels::sort(SmallVec::from_elem(channel, 1)),
    );
    let image = Image::from_layer(layer);
    let mut buf = std::io::Cursor::new(Vec::new());
    image
        .write()
        .non_parallel()
        .to_buffered(&mut buf)
        .map_err(|e| io_err(path, e))?;
    atomic_write_bytes(path, buf.get_ref())
}

/// Reads a heightmap EXR: the channel "Y" (or "H", or the only channel), f32 or f16, north up.
/// The origin and cell come from the `imprintGrid` attribute (or the `imprintOrigin` /
/// `imprintCell` of earlier files); files without them (written by other tools) read with
/// origin (0, 0) and cell 1.
pub fn read_heightmap_exr(path: &Path) -> Result<HeightField> {
    use exr::prelude::*;
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .non_parallel()
        .from_file(path)
        .map_err(|e| io_err(path, e))?;
    let layer = &image.layer_data;
    let list = &layer.channel_data.list;
    let channel = list
        .iter()
        .find(|c| c.name.eq(EXR_CHANNEL))
        .or_else(|| list.iter().find(|c| c.name.eq("H")))
        .or_else(|| (list.len() == 1).then(|| &list[0]))
        .ok_or_else(|| io_err(path, "no channel named Y or H"))?;
    let (nx, nz) = (layer.size.0, layer.size.1);
    let values: Vec<f32> = channel.sample_data.values_as_f32().collect();
    let other = &layer.attributes.other;
    let (origin, cell) = match other.get(&Text::from(EXR_GRID)) {
        Some(AttributeValue::FloatVec3((x, z, c))) => (imprint_core::glam::Vec2::new(*x, *z), *c),
        _ => (
            match other.get(&Text::from(EXR_ORIGIN)) {
                Some(AttributeValue::FloatVec2(v)) => imprint_core::glam::Vec2::new(v.0, v.1),
                _ => imprint_core::glam::Vec2::ZERO,
            },
            match other.get(&Text::from(EXR_CELL)) {
                Some(AttributeValue::F32(c)) => *c,
                _ => 1.0,
            },
        ),
    };
    let dims = UVec2::new(
        u32::try_from(nx).map_err(|e| io_err(path, e))?,
        u32::try_from(nz).map_err(|e| io_err(path, e))?,
    );
    if values.len() != nx * nz {
        return Err(io_err(path, "channel size does not match the image size"));
    }
    HeightField::from_fn(origin, cell, dims, |i, k| {
        values[(nz - 1 - k as usize) * nx + i as usize]
    })
}

/// Writes the heights as a NumPy f32 array of shape `[nz, nx]`, north up as the pictures
/// (`a[r, c] = get(c, nz - 1 - r)`), and its sidecar `<path>.json` ([`HeightmapMeta`]).
pub fn write_heightmap_npy(path: &Path, hf: &HeightField) -> Result<()> {
    hf.validate()?;
    let nx = hf.dims.x as usize;
    let north_up: Vec<f32> = hf
        .heights
        .chunks_exact(nx)
        .rev()
        .flatten()
        .copied()
        .collect();
    HeightmapMeta::of(hf, 0.0).write_beside(path)?;
    write_npy_f32(path, &[hf.dims.y as usize, nx], &north_up)
}

/// Page and text colours of the preview.
const PAPER: Rgb<u8> = Rgb([255, 255, 255]);
const INK: Rgb<u8> = Rgb([20, 20, 20]);
const MARGIN: u32 = 8;
const BAR_W: u32 = 16;
const TEXT_SCALE: u32 = 1;

/// Where the map sits in a preview: cell (i, k) covers the `scale` x `scale` square whose
/// top-left pixel is `(x + i * scale, y + (nz - 1 - k) * scale)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PreviewLayout {
    pub x: u32,
    pub y: u32,
    /// Pixels per cell: enough for the longer side to reach about 256 pixels, 1 to 16.
    pub scale: u32,
}

impl PreviewLayout {
    pub fn of(hf: &HeightField) -> Self {
        let longest = hf.dims.x.max(hf.dims.y).max(1);
        PreviewLayout {
            x: MARGIN,
            y: MARGIN,
            scale: (256 / longest).clamp(1, 16),
        }
    }

    /// The centre pixel of cell (i, k).
    pub fn cell_centre(&self, hf: &HeightField, i: u32, k: u32) -> (u32, u32) {
        (
            self.x + i * self.scale + self.scale / 2,
            self.y + row_of(hf, k) * self.scale + self.scale / 2,
        )
    }
}

/// A height as a short label: up to 4 decimals (trailing zeros dropped), or scientific
/// notation for very large or small magnitudes.
fn label(v: f32) -> String {
    let a = v.abs();
    if a == 0.0 || (1e-3..1e5).contains(&a) {
        let s = format!("{v:.4}");
        let s = s.trim_end_matches('0').trim_end_matches('.');
        if s == "-0" { "0".into() } else { s.into() }
    } else {
        format!("{v:.3e}")
    }
}

/// The preview picture: each cell coloured by `colormap` at `(h - min) / (max - min)` (0.5 for
/// a constant field), north up, with a vertical colour bar on the right labelled with the
/// highest height at its top and the lowest at its bottom (world units), and a caption with
/// the grid size and cell size.
pub fn render_heightmap_preview(hf: &HeightField, colormap: Colormap) -> Result<RgbImage> {
    hf.validate()?;
    let layout = PreviewLayout::of(hf);
    let s = layout.scale;
    let (nx, nz) = (hf.dims.x, hf.dims.y);
    let (map_w, map_h) = (nx * s, nz * s);
    let (min, max) = hf.height_range();
    let range = max as f64 - min as f64;
    let t_of = |h: f32| -> f32 {
        if range > 0.0 {
            ((h as f64 - min as f64) / range) as f32
        } else {
            0.5
        }
    };
    let (top, bottom) = (label(max), label(min));
    let title = "height";
    let caption = format!("{nx} x {nz} cells of {}", label(hf.cell));
    let th = text_height(TEXT_SCALE);
    let bar_h = map_h.max(4 * th + 40);
    let bar_x = layout.x + map_w + 12;
    let label_x = bar_x + BAR_W + 6;
    let label_w = [&top, &bottom, title]
        .iter()
        .map(|t| text_width(t, TEXT_SCALE))
        .max()
        .unwrap_or(0);
    let width =
        (label_x + label_w + MARGIN).max(layout.x + text_width(&caption, TEXT_SCALE) + MARGIN);
    let height = layout.y + bar_h + 6 + th + MARGIN;
    imprint_core::error::check_alloc("the heightmap preview", width as u64 * height as u64 * 3)?;
    let mut img = RgbImage::from_pixel(width, height, PAPER);
    for r in 0..nz {
        let k = nz - 1 - r;
        for i in 0..nx {
            let c = Rgb(colormap.sample(t_of(hf.get(i, k))));
            fill_rect(
                &mut img,
                (layout.x + i * s) as i64,
                (layout.y + r * s) as i64,
                s as i64,
                s as i64,
                c,
            );
        }
    }
    // Colour bar: max at the top row, min at the bottom row.
    let by = layout.y;
    for y in 0..bar_h {
        let t = if bar_h > 1 {
            1.0 - y as f32 / (bar_h - 1) as f32
        } else {
            0.5
        };
        let t = if range > 0.0 { t } else { 0.5 };
        let c = Rgb(colormap.sample(t));
        fill_rect(&mut img, bar_x as i64, (by + y) as i64, BAR_W as i64, 1, c);
    }
    let lx = label_x as i64;
    draw_text(&mut img, lx, by as i64, &top, TEXT_SCALE, INK);
    draw_text(
        &mut img,
        lx,
        (by + bar_h / 2) as i64 - th as i64 / 2,
        title,
        TEXT_SCALE,
        INK,
    );
    draw_text(
        &mut img,
        lx,
        (by + bar_h) as i64 - th as i64,
        &bottom,
        TEXT_SCALE,
        INK,
    );
    draw_text(
        &mut img,
        layout.x as i64,
        (layout.y + bar_h + 6) as i64,
        &caption,
        TEXT_SCALE,
        INK,
    );
    Ok(img)
}

/// Writes [`render_heightmap_preview`] with viridis as an 8-bit RGB PNG.
pub fn write_heightmap_preview(path: &Path, hf: &HeightField) -> Result<()> {
    let img = render_heightmap_preview(hf, Colormap::Viridis)?;
    write_png(path, &img)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::npy::read_npy_f32;

    /// A bumpy field with awkward values, its minimum at (1, 2) and maximum at (5, 0).
    fn bumpy() -> HeightField {
        let mut hf =
            HeightField::from_fn(Vec2::new(-3.25, 7.5), 0.125, UVec2::new(7, 4), |i, k| {
                ((i as f32 * 0.37).sin() + (k as f32 * 1.3).cos()) * 0.731 + 2.0
            })
            .unwrap();
        let a = hf.index(1, 2);
        let b = hf.index(5, 0);
        hf.heights[a] = -1.0 / 3.0;
        hf.heights[b] = 4.0 + f32::EPSILON * 7.0;
        hf
    }

    fn only_names(dir: &Path) -> Vec<String> {
        let mut v: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        v.sort();
        v
    }

    #[test]
    fn png16_round_trips_within_one_step() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.png");
        let hf = bumpy();
        write_heightmap_png16(&path, &hf).unwrap();
        assert_eq!(only_names(dir.path()), ["h.png", "h.png.json"]);
        let meta: HeightmapMeta =
            serde_json::from_str(&std::fs::read_to_string(sidecar_path(&path)).unwrap()).unwrap();
        let (min, max) = hf.height_range();
        assert_eq!((meta.min, meta.max), (min, max));
        assert_eq!(meta.dims, [7, 4]);
        assert_eq!(meta.orientation, ORIENTATION);
        let step = (max as f64 - min as f64) / 65535.0;
        assert_eq!(meta.quantisation_step, step);

        // North up: image row 0 is k = nz - 1; the maximum (k = 0) is on the last row.
        let img = image::open(&path).unwrap().into_luma16();
        assert_eq!(img.get_pixel(5, 3).0[0], 65535);
        assert_eq!(img.get_pixel(1, 1).0[0], 0);

        let back = read_heightmap_png16(&path).unwrap();
        assert_eq!(back.dims, hf.dims);
        assert_eq!(back.origin, hf.origin);
        assert_eq!(back.cell, hf.cell);
        for (a, b) in back.heights.iter().zip(&hf.heights) {
            assert!(((a - b).abs() as f64) <= step, "{a} vs {b}, step {step}");
        }
        assert_eq!(back.get(1, 2).to_bits(), min.to_bits());
        assert_eq!(back.get(5, 0).to_bits(), max.to_bits());
        assert_eq!(back.height_range(), (min, max));
    }

    #[test]
    fn constant_fields_write_and_read_everywhere() {
        let dir = tempfile::tempdir().unwrap();
        let hf = HeightField::constant(Vec2::new(1.0, 2.0), 0.5, UVec2::new(3, 2), 1.75).unwrap();
        let png = dir.path().join("c.png");
        write_heightmap_png16(&png, &hf).unwrap();
        assert_eq!(read_heightmap_png16(&png).unwrap(), hf);
        let exr = dir.path().join("c.exr");
        write_heightmap_exr(&exr, &hf).unwrap();
        assert_eq!(read_heightmap_exr(&exr).unwrap(), hf);
        let img = render_heightmap_preview(&hf, Colormap::Viridis).unwrap();
        let (x, y) = PreviewLayout::of(&hf).cell_centre(&hf, 0, 0);
        assert_eq!(img.get_pixel(x, y).0, Colormap::Viridis.sample(0.5));
        write_heightmap_preview(&dir.path().join("c_preview.png"), &hf).unwrap();
        // A single cell too.
        let one = HeightField::constant(Vec2::ZERO, 1.0, UVec2::ONE, -2.0).unwrap();
        write_heightmap_png16(&png, &one).unwrap();
        assert_eq!(read_heightmap_png16(&png).unwrap(), one);
    }

    #[test]
    fn exr_round_trips_bit_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.exr");
        let hf = bumpy();
        write_heightmap_exr(&path, &hf).unwrap();
        let back = read_heightmap_exr(&path).unwrap();
        assert_eq!(back.dims, hf.dims);
        assert_eq!(back.origin, hf.origin);
        assert_eq!(back.cell.to_bits(), hf.cell.to_bits());
        let a: Vec<u32> = back.heights.iter().map(|h| h.to_bits()).collect();
        let b: Vec<u32> = hf.heights.iter().map(|h| h.to_bits()).collect();
        assert_eq!(a, b);

        // One channel named Y, north up: pixel row 0 holds k = nz - 1.
        let img = exr::prelude::read_first_flat_layer_from_file(&path).unwrap();
        let list = &img.layer_data.channel_data.list;
        assert_eq!(list.len(), 1);
        assert_eq!(list[0].name, exr::prelude::Text::from("Y"));
        let first = list[0].sample_data.value_by_flat_index(0).to_f32();
        assert_eq!(first, hf.get(0, 3));

        // The same heights give the same bytes, however the header's maps are ordered (with
        // several custom attributes they came out in a different order from run to run).
        let bytes = std::fs::read(&path).unwrap();
        for k in 0..8 {
            let again = dir.path().join(format!("again{k}.exr"));
            write_heightmap_exr(&again, &hf).unwrap();
            assert_eq!(std::fs::read(&again).unwrap(), bytes, "write {k}");
        }
    }

    #[test]
    fn npy_round_trips_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.npy");
        let hf = bumpy();
        write_heightmap_npy(&path, &hf).unwrap();
        assert_eq!(only_names(dir.path()), ["h.npy", "h.npy.json"]);
        let (shape, data) = read_npy_f32(&path).unwrap();
        assert_eq!(shape, [4, 7]);
        // North up, as the PNG: row r holds k = nz - 1 - r.
        for k in 0..4 {
            for i in 0..7 {
                assert_eq!(data[(3 - k as usize) * 7 + i as usize], hf.get(i, k));
            }
        }
        let meta: HeightmapMeta =
            serde_json::from_str(&std::fs::read_to_string(sidecar_path(&path)).unwrap()).unwrap();
        assert_eq!((meta.rows.as_str(), meta.columns.as_str()), (ROWS, COLUMNS));
        assert_eq!(meta.quantisation_step, 0.0);
    }

    #[test]
    fn preview_colours_min_and_max_cells_and_has_a_legend() {
        let hf = bumpy();
        let img = render_heightmap_preview(&hf, Colormap::Viridis).unwrap();
        let layout = PreviewLayout::of(&hf);
        assert_eq!(layout.scale, 16);
        let (x, y) = layout.cell_centre(&hf, 1, 2);
        assert_eq!(img.get_pixel(x, y).0, Colormap::Viridis.sample(0.0));
        let (x, y) = layout.cell_centre(&hf, 5, 0);
        assert_eq!(img.get_pixel(x, y).0, Colormap::Viridis.sample(1.0));
        // North up: k = 0 is in the bottom row of the map.
        assert_eq!(y, layout.y + 3 * 16 + 8);
        // The colour bar's top is the maximum colour, its bottom the minimum.
        let bar_x = layout.x + 7 * 16 + 12 + BAR_W / 2;
        let bar_h = (4 * 16).max(4 * text_height(TEXT_SCALE) + 40);
        assert_eq!(
            img.get_pixel(bar_x, layout.y).0,
            Colormap::Viridis.sample(1.0)
        );
        assert_eq!(
            img.get_pixel(bar_x, layout.y + bar_h - 1).0,
            Colormap::Viridis.sample(0.0)
        );
        // Some ink right of the bar (the labels).
        let inked = img
            .enumerate_pixels()
            .filter(|(x, _, p)| *x > bar_x + BAR_W && **p == INK)
            .count();
        assert!(inked > 20);
        assert_eq!(label(max_of(&hf)), "4");
        assert_eq!(label(-1.0 / 3.0), "-0.3333");
        assert_eq!(label(1.5e-6), "1.500e-6");
    }

    fn max_of(hf: &HeightField) -> f32 {
        hf.height_range().1
    }

    #[test]
    fn failed_writes_leave_no_final_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut bad = bumpy();
        bad.heights[3] = f32::NAN;
        let names = ["b.png", "b.exr", "b.npy", "b_preview.png"];
        assert!(write_heightmap_png16(&dir.path().join(names[0]), &bad).is_err());
        assert!(write_heightmap_exr(&dir.path().join(names[1]), &bad).is_err());
        assert!(write_heightmap_npy(&dir.path().join(names[2]), &bad).is_err());
        assert!(write_heightmap_preview(&dir.path().join(names[3]), &bad).is_err());
        assert!(only_names(dir.path()).is_empty());

        // A failure part-way (the final name is a directory, so the rename fails): nothing
        // under the final name and no temporary left behind.
        let hf = bumpy();
        let target = dir.path().join("d.exr");
        std::fs::create_dir_all(target.join("x")).unwrap();
        assert!(write_heightmap_exr(&target, &hf).is_err());
        assert!(target.is_dir());
        assert_eq!(only_names(dir.path()), ["d.exr"]);

        // A failed rewrite keeps the previous complete heightmap and sidecar.
        let png = dir.path().join("h.png");
        write_heightmap_png16(&png, &hf).unwrap();
        let before = (
            std::fs::read(&png).unwrap(),
            std::fs::read(sidecar_path(&png)).unwrap(),
        );
        assert!(write_heightmap_png16(&png, &bad).is_err());
        let after = (
            std::fs::read(&png).unwrap(),
            std::fs::read(sidecar_path(&png)).unwrap(),
        );
        assert_eq!(before, after);
    }
}
