//! Whole-sequence writers, for checking a run at a glance: a **contact sheet** (every k-th
//! frame as a labelled thumbnail in one PNG) and an **animated GIF** preview.
//!
//! Both take frames as they are rendered, so a long run never holds its full-size frames:
//! the contact sheet keeps only thumbnails, and the GIF is encoded frame by frame into an
//! [`AtomicFile`] that appears under its final name only when [`GifWriter::finish`] succeeds
//! (a run that fails half-way leaves no truncated GIF behind).
//!
//! Thumbnails are area-averaged downscales (`image::imageops::thumbnail`) and the GIF palette
//! is NeuQuant's (the `gif` crate): both deterministic, so the same frames give the same bytes.

use crate::font::{draw_text, text_height};
use crate::png::write_png;
use image::{Rgb, RgbImage, imageops};
use imprint_core::io::AtomicFile;
use imprint_core::{Error, Result};
use std::path::Path;

/// Largest thumbnail or GIF width accepted, in pixels.
const MAX_WIDTH: u32 = 4096;

/// Size of `img` scaled to `width` pixels wide (never upscaled), keeping the aspect ratio.
fn scaled_size(img: &RgbImage, width: u32) -> (u32, u32) {
    let w = width.min(img.width()).max(1);
    let h = ((img.height() as u64 * w as u64 + img.width() as u64 / 2) / img.width() as u64).max(1)
        as u32;
    (w, h)
}

/// `img` scaled down to `width` pixels wide (a copy if it is already that narrow).
fn downscale(img: &RgbImage, width: u32) -> RgbImage {
    let (w, h) = scaled_size(img, width);
    if (w, h) == img.dimensions() {
        img.clone()
    } else {
        imageops::thumbnail(img, w, h)
    }
}

fn check_width(what: &str, width: u32) -> Result<()> {
    if width == 0 || width > MAX_WIDTH {
        return Err(Error::Invalid(format!(
            "{what}: width must be in 1..={MAX_WIDTH}, got {width}"
        )));
    }
    Ok(())
}

/// A grid of every k-th frame in one picture, each tile labelled with its frame number.
#[derive(Clone, Debug)]
pub struct ContactSheet {
    columns: u32,
    thumb_width: u32,
    tiles: Vec<(u32, RgbImage)>,
}

/// Gap between tiles and around the sheet, in pixels.
const GAP: u32 = 4;
const SHEET_BG: Rgb<u8> = Rgb([40, 40, 44]);
const LABEL_FG: Rgb<u8> = Rgb([255, 255, 255]);
const LABEL_BG: Rgb<u8> = Rgb([0, 0, 0]);

impl ContactSheet {
    /// An empty sheet of `columns` tiles per row, each `thumb_width` pixels wide.
    pub fn new(columns: u32, thumb_width: u32) -> Result<Self> {
        if columns == 0 || columns > 64 {
            return Err(Error::Invalid(format!(
                "contact sheet: columns must be in 1..=64, got {columns}"
            )));
        }
        check_width("contact sheet", thumb_width)?;
        Ok(ContactSheet {
            columns,
            thumb_width,
            tiles: Vec::new(),
        })
    }

    /// Adds frame `frame` (kept as a thumbnail only).
    pub fn push(&mut self, frame: u32, img: &RgbImage) {
        self.tiles.push((frame, downscale(img, self.thumb_width)));
    }

    pub fn len(&self) -> usize {
        self.tiles.len()
    }

    pub fn is_empty(&self) -> bool {
        self.tiles.is_empty()
    }

    /// The sheet: tiles left to right, top to bottom in the order pushed, each labelled
    /// `f <frame>` in its top-left corner. Tiles of differing sizes are placed at the largest
    /// size's pitch. `None` when no frame was pushed.
    pub fn compose(&self) -> Option<RgbImage> {
        let tw = self.tiles.iter().map(|(_, t)| t.width()).max()?;
        let th = self.tiles.iter().map(|(_, t)| t.height()).max()?;
        let n = self.tiles.len() as u32;
        let cols = self.columns.min(n);
        let rows = n.div_ceil(cols);
        let mut sheet =
            RgbImage::from_pixel(GAP + cols * (tw + GAP), GAP + rows * (th + GAP), SHEET_BG);
        let scale = if tw >= 240 { 2 } else { 1 };
        for (k, (frame, tile)) in self.tiles.iter().enumerate() {
            let (c, r) = (k as u32 % cols, k as u32 / cols);
            let (x, y) = (GAP + c * (tw + GAP), GAP + r * (th + GAP));
            imageops::replace(&mut sheet, tile, x as i64, y as i64);
            let label = format!("f {frame}");
            let lw = crate::font::text_width(&label, scale);
            crate::font::fill_rect(
                &mut sheet,
                x as i64,
                y as i64,
                (lw + 2 * scale) as i64,
                (text_height(scale) + scale) as i64,
                LABEL_BG,
            );
            draw_text(
                &mut sheet,
                (x + scale) as i64,
                (y + scale) as i64,
                &label,
                scale,
                LABEL_FG,
            );
        }
        Some(sheet)
    }

    /// Writes the sheet as a PNG (atomically). Errors when no frame was pushed.
    pub fn write(&self, path: &Path) -> Result<()> {
        let sheet = self.compose().ok_or_else(|| {
            Error::Invalid(format!(
                "{}: contact sheet has no frames (is `every` larger than the run?)",
                path.display()
            ))
        })?;
        write_png(path, &sheet)
    }
}

/// An animated GIF written frame by frame; see the module doc.
pub struct GifWriter {
    encoder: Option<gif::Encoder<AtomicFile>>,
    path: std::path::PathBuf,
    width: u32,
    size: Option<(u16, u16)>,
    /// Frame delay in hundredths of a second.
    delay_cs: u16,
    frames: u32,
}

/// NeuQuant sampling factor (1 = best, 30 = fastest); 10 is `gif`'s own default trade-off.
const GIF_SPEED: i32 = 10;

impl GifWriter {
    /// Starts `path`: frames are scaled to `width` pixels wide and shown `seconds_per_frame`
    /// each (GIF delays are whole hundredths of a second, at least 0.02 s so that viewers
    /// do not slow them down), looping forever.
    pub fn create(path: &Path, width: u32, seconds_per_frame: f32) -> Result<Self> {
        check_width("gif", width)?;
        if !(seconds_per_frame.is_finite() && seconds_per_frame > 0.0) {
            return Err(Error::Invalid(format!(
                "gif: seconds per frame must be finite and > 0, got {seconds_per_frame}"
            )));
        }
        let delay_cs = (seconds_per_frame * 100.0).round().clamp(2.0, 65535.0) as u16;
        Ok(GifWriter {
            encoder: None,
            path: path.to_path_buf(),
            width,
            size: None,
            delay_cs,
            frames: 0,
        })
    }

    fn gif_err(&self, e: gif::EncodingError) -> Error {
        match e {
            gif::EncodingError::Io(e) => Error::io(&self.path, e),
            other => Error::Invalid(format!("{}: {other}", self.path.display())),
        }
    }

    /// Appends one frame. Every frame must have the first frame's size after scaling.
    pub fn push(&mut self, img: &RgbImage) -> Result<()> {
        let small = downscale(img, self.width);
        let (w, h) = small.dimensions();
        let (w16, h16) = (w as u16, h as u16); // ≤ MAX_WIDTH wide; height checked below
        if h > u16::MAX as u32 {
            return Err(Error::Invalid(format!(
                "{}: gif frame {w}x{h} is too tall",
                self.path.display()
            )));
        }
        match self.size {
            None => {
                let file = AtomicFile::create(&self.path)?;
                let mut enc =
                    gif::Encoder::new(file, w16, h16, &[]).map_err(|e| self.gif_err(e))?;
                enc.set_repeat(gif::Repeat::Infinite)
                    .map_err(|e| self.gif_err(e))?;
                self.encoder = Some(enc);
                self.size = Some((w16, h16));
            }
            Some(size) if size != (w16, h16) => {
                return Err(Error::Invalid(format!(
                    "{}: gif frame is {w}x{h} after scaling, the first was {}x{}",
                    self.path.display(),
                    size.0,
                    size.1
                )));
            }
            Some(_) => {}
        }
        let mut frame = gif::Frame::from_rgb_speed(w16, h16, small.as_raw(), GIF_SPEED);
        frame.delay = self.delay_cs;
        let enc = self.encoder.as_mut().expect("created above");
        let r = enc.write_frame(&frame);
        r.map_err(|e| self.gif_err(e))?;
        self.frames += 1;
        Ok(())
    }

    /// Frames written so far.
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// Writes the trailer and moves the GIF to its final name. Errors when no frame was
    /// pushed (an empty GIF is not a picture).
    pub fn finish(mut self) -> Result<()> {
        let Some(enc) = self.encoder.take() else {
            return Err(Error::Invalid(format!(
                "{}: gif has no frames (is `every` larger than the run?)",
                self.path.display()
            )));
        };
        let file = enc.into_inner().map_err(|e| self.gif_err(e))?;
        file.commit()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame whose colour encodes its index, with a white square marking a position.
    fn frame(k: u32, w: u32, h: u32) -> RgbImage {
        let mut img = RgbImage::from_pixel(w, h, Rgb([(40 * k) as u8, 100, 200 - (20 * k) as u8]));
        crate::font::fill_rect(&mut img, (10 * k) as i64, 30, 16, 16, Rgb([255, 255, 255]));
        img
    }

    #[test]
    fn contact_sheet_places_labelled_tiles_in_order() {
        let mut sheet = ContactSheet::new(2, 80).unwrap();
        for k in 0..3 {
            sheet.push(k * 4, &frame(k, 160, 120));
        }
        let img = sheet.compose().unwrap();
        // 2 columns, 2 rows of 80x60 tiles with 4-pixel gaps.
        assert_eq!(img.dimensions(), (4 + 2 * 84, 4 + 2 * 64));
        // Each tile's interior (away from the label and the square) has its frame's colour.
        for k in 0..3u32 {
            let (x, y) = (4 + (k % 2) * 84 + 70, 4 + (k / 2) * 64 + 50);
            let want = frame(k, 1, 1).get_pixel(0, 0).0;
            let got = img.get_pixel(x, y).0;
            for c in 0..3 {
                assert!(
                    (got[c] as i32 - want[c] as i32).abs() <= 1,
                    "tile {k}: {got:?} vs {want:?}"
                );
            }
            // The label box (black with white text) is in the tile's corner.
            assert_eq!(
                img.get_pixel(4 + (k % 2) * 84, 4 + (k / 2) * 64).0,
                [0, 0, 0]
            );
        }
        // The empty fourth slot is background.
        assert_eq!(img.get_pixel(4 + 84 + 40, 4 + 64 + 30).0, SHEET_BG.0);
        assert!(ContactSheet::new(2, 80).unwrap().compose().is_none());
        assert!(ContactSheet::new(0, 80).is_err());
    }

    #[test]
    fn gif_round_trips_frames_and_delay() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run.gif");
        let mut gif = GifWriter::create(&path, 64, 1.0 / 12.0).unwrap();
        for k in 0..4 {
            gif.push(&frame(k, 128, 96)).unwrap();
        }
        assert!(!path.exists(), "nothing under the final name before finish");
        gif.finish().unwrap();

        let mut opts = gif::DecodeOptions::new();
        opts.set_color_output(gif::ColorOutput::RGBA);
        let mut dec = opts.read_info(std::fs::File::open(&path).unwrap()).unwrap();
        assert_eq!((dec.width(), dec.height()), (64, 48));
        let mut n = 0;
        while let Some(f) = dec.read_next_frame().unwrap() {
            assert_eq!(f.delay, 8, "1/12 s rounds to 8 cs");
            // Quantised colour of the tile interior stays close to the source.
            let want = frame(n, 1, 1).get_pixel(0, 0).0;
            let px = &f.buffer[(40 * 64 + 60) * 4..][..3];
            for c in 0..3 {
                assert!(
                    (px[c] as i32 - want[c] as i32).abs() <= 8,
                    "frame {n}: {px:?} vs {want:?}"
                );
            }
            n += 1;
        }
        assert_eq!(n, 4);
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn gif_is_deterministic_and_failed_runs_leave_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let write = |name: &str| {
            let p = dir.path().join(name);
            let mut g = GifWriter::create(&p, 48, 0.1).unwrap();
            for k in 0..3 {
                g.push(&frame(k, 96, 64)).unwrap();
            }
            g.finish().unwrap();
            std::fs::read(p).unwrap()
        };
        assert_eq!(write("a.gif"), write("b.gif"));

        // A frame of another size is refused, and dropping the writer leaves no file.
        let p = dir.path().join("c.gif");
        let mut g = GifWriter::create(&p, 48, 0.1).unwrap();
        g.push(&frame(0, 96, 64)).unwrap();
        assert!(g.push(&frame(1, 96, 96)).is_err());
        drop(g);
        assert!(!p.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
        // No frames: finish is an error, not an empty file.
        let e = GifWriter::create(&p, 48, 0.1).unwrap().finish();
        assert!(e.is_err() && !p.exists());
    }
}
