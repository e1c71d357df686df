//! Whole-sequence writers, for checking a run at a glance: a **contact sheet** (every k-th
//! frame as a labelled thumbnail in one PNG) and an **animated GIF** preview.
//!
//! Both take frames as they are rendered, so a long run never holds its full-size frames:
//! the contact sheet keeps only thumbnails, and the GIF keeps each frame quantised and
//! compressed, in memory. Nothing is written before the end: [`GifWriter::finish`] writes
//! the whole GIF at once, atomically, so a run that fails or is killed half-way leaves no
//! file at all (not even a temporary one).
//!
//! Both are serde values (a run's checkpoint holds them): a writer loaded from a checkpoint
//! and given the remaining frames writes the same bytes as one that never stopped.
//!
//! Thumbnails are area-averaged downscales (`image::imageops::thumbnail`) and the GIF palette
//! is NeuQuant's (the `gif` crate): both deterministic, so the same frames give the same bytes.

use crate::png::write_png;
use crate::text::{draw_text, text_height};
use image::{Rgb, RgbImage, imageops};
use imprint_core::io::atomic_write_bytes;
use imprint_core::{Error, Result};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;
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

/// Serde for an [`RgbImage`] (which has none): `(width, height, raw RGB bytes)`.
mod rgb_image {
    use image::RgbImage;
    use serde::de::Error as _;
    use serde::{Deserialize, Deserializer, Serialize, Serializer};

    pub fn serialize<S: Serializer>(img: &RgbImage, s: S) -> Result<S::Ok, S::Error> {
        (img.width(), img.height(), img.as_raw()).serialize(s)
    }

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<RgbImage, D::Error> {
        let (w, h, raw) = <(u32, u32, Vec<u8>)>::deserialize(d)?;
        let len = raw.len();
        RgbImage::from_raw(w, h, raw).ok_or_else(|| {
            D::Error::custom(format!("an RGB image of {w}x{h} pixels with {len} bytes"))
        })
    }
}

/// One thumbnail of a [`ContactSheet`].
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Tile {
    frame: u32,
    #[serde(with = "rgb_image")]
    image: RgbImage,
}

/// A grid of every k-th frame in one picture, each tile labelled with its frame number.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ContactSheet {
    columns: u32,
    thumb_width: u32,
    tiles: Vec<Tile>,
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
        self.tiles.push(Tile {
            frame,
            image: downscale(img, self.thumb_width),
        });
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
        let tw = self.tiles.iter().map(|t| t.image.width()).max()?;
        let th = self.tiles.iter().map(|t| t.image.height()).max()?;
        let n = self.tiles.len() as u32;
        let cols = self.columns.min(n);
        let rows = n.div_ceil(cols);
        let mut sheet =
            RgbImage::from_pixel(GAP + cols * (tw + GAP), GAP + rows * (th + GAP), SHEET_BG);
        let scale = if tw >= 240 { 2 } else { 1 };
        for (k, Tile { frame, image: tile }) in self.tiles.iter().enumerate() {
            let (c, r) = (k as u32 % cols, k as u32 / cols);
            let (x, y) = (GAP + c * (tw + GAP), GAP + r * (th + GAP));
            imageops::replace(&mut sheet, tile, x as i64, y as i64);
            let label = format!("f {frame}");
            let lw = crate::text::text_width(&label, scale);
            crate::text::fill_rect(
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

/// One GIF frame as the file will hold it: a `gif::Frame` quantised (palette and indices)
/// and its indices LZW-compressed (`Frame::make_lzw_pre_encoded`, the compression
/// `Encoder::write_frame` applies), so the file written at the end has the bytes a streaming
/// encoder would have written.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct EncodedFrame {
    delay: u16,
    /// `gif::DisposalMethod` as its number.
    dispose: u8,
    transparent: Option<u8>,
    needs_user_input: bool,
    top: u16,
    left: u16,
    width: u16,
    height: u16,
    interlaced: bool,
    palette: Option<Vec<u8>>,
    /// Minimum code size, then the LZW data.
    lzw: Vec<u8>,
}

impl EncodedFrame {
    fn new(mut frame: gif::Frame<'_>) -> Self {
        frame.make_lzw_pre_encoded();
        EncodedFrame {
            delay: frame.delay,
            dispose: frame.dispose as u8,
            transparent: frame.transparent,
            needs_user_input: frame.needs_user_input,
            top: frame.top,
            left: frame.left,
            width: frame.width,
            height: frame.height,
            interlaced: frame.interlaced,
            palette: frame.palette,
            lzw: frame.buffer.into_owned(),
        }
    }

    /// The frame, its buffer LZW-encoded (for `Encoder::write_lzw_pre_encoded_frame`).
    fn frame(&self) -> gif::Frame<'_> {
        gif::Frame {
            delay: self.delay,
            dispose: gif::DisposalMethod::from_u8(self.dispose)
                .unwrap_or(gif::DisposalMethod::Keep),
            transparent: self.transparent,
            needs_user_input: self.needs_user_input,
            top: self.top,
            left: self.left,
            width: self.width,
            height: self.height,
            interlaced: self.interlaced,
            palette: self.palette.clone(),
            buffer: Cow::Borrowed(&self.lzw),
        }
    }
}

/// An animated GIF taken frame by frame and written whole by [`GifWriter::finish`]; see the
/// module doc. Memory: each frame's palette and compressed indices (a few KiB to a few tens
/// of KiB per preview frame).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct GifWriter {
    path: std::path::PathBuf,
    width: u32,
    size: Option<(u16, u16)>,
    /// Frame delay in hundredths of a second.
    delay_cs: u16,
    frames: Vec<EncodedFrame>,
}

/// NeuQuant sampling factor (1 = best, 30 = fastest); 10 is `gif`'s own default trade-off.
const GIF_SPEED: i32 = 10;

impl GifWriter {
    /// Starts a GIF for `path` (nothing is written before [`GifWriter::finish`]): frames are
    /// scaled to `width` pixels wide and shown `seconds_per_frame` each (GIF delays are whole
    /// hundredths of a second, at least 0.02 s so that viewers do not slow them down),
    /// looping forever.
    pub fn create(path: &Path, width: u32, seconds_per_frame: f32) -> Result<Self> {
        check_width("gif", width)?;
        if !(seconds_per_frame.is_finite() && seconds_per_frame > 0.0) {
            return Err(Error::Invalid(format!(
                "gif: seconds per frame must be finite and > 0, got {seconds_per_frame}"
            )));
        }
        let delay_cs = (seconds_per_frame * 100.0).round().clamp(2.0, 65535.0) as u16;
        Ok(GifWriter {
            path: path.to_path_buf(),
            width,
            size: None,
            delay_cs,
            frames: Vec::new(),
        })
    }

    fn gif_err(&self, e: gif::EncodingError) -> Error {
        match e {
            gif::EncodingError::Io(e) => Error::io(&self.path, e),
            other => Error::Invalid(format!("{}: {other}", self.path.display())),
        }
    }

    /// Appends one frame (quantised and compressed now, kept in memory). Every frame must
    /// have the first frame's size after scaling.
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
            None => self.size = Some((w16, h16)),
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
        self.frames.push(EncodedFrame::new(frame));
        Ok(())
    }

    /// Frames taken so far.
    pub fn frames(&self) -> u32 {
        self.frames.len() as u32
    }

    /// The whole GIF file, as [`GifWriter::finish`] writes it. Errors when no frame was
    /// pushed (an empty GIF is not a picture).
    pub fn encode(&self) -> Result<Vec<u8>> {
        let Some((w, h)) = self.size.filter(|_| !self.frames.is_empty()) else {
            return Err(Error::Invalid(format!(
                "{}: gif has no frames (is `every` larger than the run?)",
                self.path.display()
            )));
        };
        let mut enc = gif::Encoder::new(Vec::new(), w, h, &[]).map_err(|e| self.gif_err(e))?;
        enc.set_repeat(gif::Repeat::Infinite)
            .map_err(|e| self.gif_err(e))?;
        for f in &self.frames {
            enc.write_lzw_pre_encoded_frame(&f.frame())
                .map_err(|e| self.gif_err(e))?;
        }
        enc.into_inner().map_err(|e| self.gif_err(e))
    }

    /// Writes the GIF to its path, atomically (the first and only write). Errors when no
    /// frame was pushed (an empty GIF is not a picture).
    pub fn finish(self) -> Result<()> {
        atomic_write_bytes(&self.path, &self.encode()?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame whose colour encodes its index, with a white square marking a position.
    fn frame(k: u32, w: u32, h: u32) -> RgbImage {
        let mut img = RgbImage::from_pixel(w, h, Rgb([(40 * k) as u8, 100, 200 - (20 * k) as u8]));
        crate::text::fill_rect(&mut img, (10 * k) as i64, 30, 16, 16, Rgb([255, 255, 255]));
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

    /// Many colours (NeuQuant's palette, not the exact one).
    fn gradient(k: u32, w: u32, h: u32) -> RgbImage {
        RgbImage::from_fn(w, h, |x, y| {
            Rgb([
                (x * 3 + k * 7) as u8,
                (y * 5 + k) as u8,
                ((x ^ y) * 11) as u8,
            ])
        })
    }

    /// The GIF as the writer streamed it before it kept frames in memory: one encoder over
    /// the whole file, `write_frame` per pushed frame.
    fn streamed(frames: &[RgbImage], width: u32, seconds_per_frame: f32) -> Vec<u8> {
        let small: Vec<RgbImage> = frames.iter().map(|f| downscale(f, width)).collect();
        let (w, h) = (small[0].width() as u16, small[0].height() as u16);
        let mut enc = gif::Encoder::new(Vec::new(), w, h, &[]).unwrap();
        enc.set_repeat(gif::Repeat::Infinite).unwrap();
        for s in &small {
            let mut f = gif::Frame::from_rgb_speed(w, h, s.as_raw(), GIF_SPEED);
            f.delay = (seconds_per_frame * 100.0).round().clamp(2.0, 65535.0) as u16;
            enc.write_frame(&f).unwrap();
        }
        enc.into_inner().unwrap()
    }

    #[test]
    fn gif_bytes_match_a_streaming_encoder() {
        let dir = tempfile::tempdir().unwrap();
        let few: Vec<RgbImage> = (0..5).map(|k| frame(k, 128, 96)).collect();
        let many: Vec<RgbImage> = (0..4).map(|k| gradient(k, 200, 120)).collect();
        for (name, frames, width, spf) in [
            ("few.gif", &few, 64, 1.0 / 12.0),
            ("many.gif", &many, 100, 0.05),
        ] {
            let path = dir.path().join(name);
            let mut g = GifWriter::create(&path, width, spf).unwrap();
            for f in frames {
                g.push(f).unwrap();
            }
            g.finish().unwrap();
            let got = std::fs::read(&path).unwrap();
            assert_eq!(got, streamed(frames, width, spf), "{name}");
        }
    }

    #[test]
    fn gif_writes_no_file_before_finish() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let path = out.join("preview.gif");
        let mut g = GifWriter::create(&path, 48, 0.1).unwrap();
        for k in 0..3 {
            g.push(&frame(k, 96, 64)).unwrap();
            assert_eq!(g.frames(), k + 1);
        }
        // Nothing at all: no final file, no temporary sibling, not even the folder.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let kept = g.clone();
        drop(g); // as a killed run
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        kept.finish().unwrap();
        let names: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, ["preview.gif"]);
    }

    #[test]
    fn gif_and_contact_sheet_resume_from_postcard() {
        let dir = tempfile::tempdir().unwrap();
        let frames: Vec<RgbImage> = (0..6)
            .map(|k| {
                if k % 2 == 0 {
                    gradient(k, 160, 96)
                } else {
                    frame(k, 160, 96)
                }
            })
            .collect();
        let (a, b) = (dir.path().join("a.gif"), dir.path().join("b.gif"));
        let mut whole = GifWriter::create(&a, 80, 0.1).unwrap();
        let mut sheet_whole = ContactSheet::new(3, 40).unwrap();
        for (k, f) in frames.iter().enumerate() {
            whole.push(f).unwrap();
            sheet_whole.push(k as u32, f);
        }
        whole.finish().unwrap();

        let mut part = GifWriter::create(&b, 80, 0.1).unwrap();
        let mut sheet_part = ContactSheet::new(3, 40).unwrap();
        for (k, f) in frames.iter().enumerate().take(4) {
            part.push(f).unwrap();
            sheet_part.push(k as u32, f);
        }
        let bytes = postcard::to_allocvec(&(&part, &sheet_part)).unwrap();
        drop((part, sheet_part));
        let (mut part, mut sheet_part): (GifWriter, ContactSheet) =
            postcard::from_bytes(&bytes).unwrap();
        assert_eq!(part.frames(), 4);
        for (k, f) in frames.iter().enumerate().skip(4) {
            part.push(f).unwrap();
            sheet_part.push(k as u32, f);
        }
        part.finish().unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
        assert_eq!(sheet_part.len(), 6);
        assert_eq!(
            sheet_part.compose().unwrap(),
            sheet_whole.compose().unwrap()
        );

        // A loaded writer keeps refusing frames of another size.
        let (mut g, _): (GifWriter, ContactSheet) = postcard::from_bytes(&bytes).unwrap();
        assert!(g.push(&frame(0, 160, 160)).is_err());
        // A tile whose bytes do not match its size is refused on load.
        let bad = Tile {
            frame: 0,
            image: RgbImage::new(2, 2),
        };
        let mut raw = postcard::to_allocvec(&bad).unwrap();
        raw[1] = 3; // width 2 -> 3 (the byte after the frame number's)
        assert!(postcard::from_bytes::<Tile>(&raw).is_err());
    }
}
