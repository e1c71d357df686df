//! Labels on pictures (legends, titles, tick values, contact-sheet frame numbers): text drawn
//! by `ab_glyph` in DejaVu Sans, the font shipped in `assets/fonts/` that the plots use too,
//! anti-aliased by coverage blending into an [`RgbImage`].
//!
//! Sizes are integer `scale`s, as the call sites lay pictures out in whole pixels: at scale
//! `s` capitals are `7 s` pixels tall ([`cap_height`]) and a line, descenders included, is
//! [`text_height`] pixels. Text is placed by the top-left corner of its capitals: `y` is where
//! capitals start, the baseline is `cap_height` below it.

use ab_glyph::{Font, FontRef, Glyph, PxScale, ScaleFont, point};
use image::{Rgb, RgbImage};
use std::sync::OnceLock;

/// DejaVu Sans (see `assets/fonts/LICENSE-DejaVu.txt`).
const FONT_DATA: &[u8] = include_bytes!("../../../assets/fonts/DejaVuSans.ttf");

/// Capital height per unit of `scale`, in pixels.
const CAP_PER_SCALE: f32 = 7.0;

/// Coverage is multiplied by this (and capped at 1) before blending: at scale 1 a stem is
/// under a pixel wide, so without it no pixel of small text reaches the ink colour and labels
/// read as grey (FreeType's "stem darkening" does the same for small sizes).
const DARKEN: f32 = 1.5;

struct Face {
    font: FontRef<'static>,
    /// Height of a capital H over the font's ascent-to-descent height (what `PxScale` sets).
    cap_ratio: f32,
    /// Depth of the descent below the baseline over the same height.
    descent_ratio: f32,
}

/// The font, parsed once.
fn face() -> &'static Face {
    static FACE: OnceLock<Face> = OnceLock::new();
    FACE.get_or_init(|| {
        let font = FontRef::try_from_slice(FONT_DATA).expect("the shipped DejaVu Sans parses");
        let height = font.height_unscaled();
        let cap = font
            .outline(font.glyph_id('H'))
            // Outline bounds come y-down (min.y is the top), hence the absolute value.
            .map_or(0.7 * height, |o| (o.bounds.max.y - o.bounds.min.y).abs());
        Face {
            cap_ratio: cap / height,
            descent_ratio: -font.descent_unscaled() / height,
            font,
        }
    })
}

/// The `PxScale` that makes capitals `CAP_PER_SCALE * scale` pixels tall.
fn px_scale(scale: u32) -> PxScale {
    PxScale::from(CAP_PER_SCALE * scale.max(1) as f32 / face().cap_ratio)
}

/// Height in image pixels of a capital letter at `scale`.
pub fn cap_height(scale: u32) -> u32 {
    (CAP_PER_SCALE * scale.max(1) as f32).round() as u32
}

/// Height in image pixels of a line at `scale`: capitals plus the font's descent.
pub fn text_height(scale: u32) -> u32 {
    let descent = px_scale(scale).y * face().descent_ratio;
    (CAP_PER_SCALE * scale.max(1) as f32 + descent).ceil() as u32
}

/// Lays `text` out on a baseline at y = 0 from x = 0: the glyphs and the caret's end.
fn layout(text: &str, scale: u32) -> (Vec<Glyph>, f32) {
    let font = face().font.as_scaled(px_scale(scale));
    let mut glyphs = Vec::with_capacity(text.len());
    let mut caret = 0.0f32;
    let mut prev = None;
    for c in text.chars() {
        let id = font.glyph_id(c);
        if let Some(p) = prev {
            caret += font.kern(p, id);
        }
        glyphs.push(id.with_scale_and_position(font.scale(), point(caret, 0.0)));
        caret += font.h_advance(id);
        prev = Some(id);
    }
    (glyphs, caret)
}

/// Width in image pixels of `text` drawn at `scale` (advances and kerning, rounded up).
pub fn text_width(text: &str, scale: u32) -> u32 {
    layout(text, scale).1.ceil() as u32
}

/// Draws `text` with the top of its capitals at `y`, starting at `x`, anti-aliased: each pixel
/// moves towards `color` by the glyph's coverage of it (darkened, see `DARKEN`). Pixels outside the image are clipped,
/// so labels near an edge never panic.
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, scale: u32, color: Rgb<u8>) {
    let (w, h) = (img.width() as i64, img.height() as i64);
    let baseline = y as f32 + cap_height(scale) as f32;
    let font = &face().font;
    for mut glyph in layout(text, scale).0 {
        glyph.position.x += x as f32;
        glyph.position.y += baseline;
        let Some(outlined) = font.outline_glyph(glyph) else {
            continue; // a space
        };
        let bounds = outlined.px_bounds();
        let (ox, oy) = (bounds.min.x as i64, bounds.min.y as i64);
        outlined.draw(|gx, gy, coverage| {
            let (px, py) = (ox + gx as i64, oy + gy as i64);
            if coverage <= 0.0 || px < 0 || py < 0 || px >= w || py >= h {
                return;
            }
            let a = (coverage * DARKEN).min(1.0);
            let dst = img.get_pixel_mut(px as u32, py as u32);
            for (d, &c) in dst.0.iter_mut().zip(&color.0) {
                *d = (*d as f32 + (c as f32 - *d as f32) * a).round() as u8;
            }
        });
    }
}

/// Fills a rectangle, clipped to the image.
pub fn fill_rect(img: &mut RgbImage, x: i64, y: i64, w: i64, h: i64, color: Rgb<u8>) {
    let x0 = x.clamp(0, img.width() as i64);
    let y0 = y.clamp(0, img.height() as i64);
    let x1 = (x + w).clamp(0, img.width() as i64);
    let y1 = (y + h).clamp(0, img.height() as i64);
    for py in y0..y1 {
        for px in x0..x1 {
            img.put_pixel(px as u32, py as u32, color);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The box that holds every pixel `draw_text` changed on a black image, if any.
    fn inked_box(img: &RgbImage) -> Option<(u32, u32, u32, u32)> {
        let mut b: Option<(u32, u32, u32, u32)> = None;
        for (x, y, p) in img.enumerate_pixels() {
            if p.0 != [0, 0, 0] {
                b = Some(b.map_or((x, y, x, y), |(x0, y0, x1, y1)| {
                    (x0.min(x), y0.min(y), x1.max(x), y1.max(y))
                }));
            }
        }
        b
    }

    #[test]
    fn label_ink_lies_in_its_box_and_nowhere_else() {
        for scale in [1, 2, 3] {
            let mut img = RgbImage::new(400, 80);
            let ink = Rgb([250, 200, 40]);
            let (x, y) = (20i64, 15i64);
            let label = "Frame 12: 3.5 mm";
            draw_text(&mut img, x, y, label, scale, ink);
            let (w, h) = (text_width(label, scale), text_height(scale));
            // Full-coverage pixels of exactly the label colour exist (stems of the glyphs).
            let solid = img.pixels().filter(|p| **p == ink).count();
            assert!(
                solid > 10 * scale as usize,
                "scale {scale}: {solid} solid pixels"
            );
            // Every changed pixel lies in the label's box (one pixel of anti-aliasing spill).
            let (x0, y0, x1, y1) = inked_box(&img).unwrap();
            assert!(
                x0 as i64 >= x - 1 && x1 as i64 <= x + w as i64,
                "scale {scale}: x {x0}..{x1}, w {w}"
            );
            assert!(
                y0 as i64 >= y - 1 && y1 as i64 <= y + h as i64,
                "scale {scale}: y {y0}..{y1}, h {h}"
            );
            // ... and fills most of it: capitals reach the top, the text reaches its width.
            assert!(
                y0 as i64 <= y + 1 && x1 as i64 >= x + w as i64 - 2 * scale as i64,
                "scale {scale}: {x0} {y0} {x1} {y1} w {w} h {h}"
            );
            // Blended pixels lie between background and ink, channel by channel.
            for p in img.pixels() {
                for c in 0..3 {
                    assert!(p[c] <= ink[c]);
                }
            }
        }
    }

    #[test]
    fn capitals_span_the_cap_height_and_descenders_go_below() {
        let mut img = RgbImage::new(40, 40);
        let white = Rgb([255, 255, 255]);
        draw_text(&mut img, 5, 10, "H", 2, white);
        let (_, y0, _, y1) = inked_box(&img).unwrap();
        assert_eq!(y0, 10);
        assert_eq!(y1 + 1, 10 + cap_height(2), "H ends on the baseline");
        let mut img = RgbImage::new(40, 40);
        draw_text(&mut img, 5, 10, "g", 2, white);
        let (_, y0, _, y1) = inked_box(&img).unwrap();
        assert!(y0 > 10, "lower case starts below the capitals' top");
        assert!(y1 >= 10 + cap_height(2) && y1 < 10 + text_height(2));
    }

    #[test]
    fn text_clips_at_edges_and_sizes_grow_with_scale() {
        let mut img = RgbImage::new(12, 12);
        let c = Rgb([9, 9, 9]);
        draw_text(&mut img, -7, 9, "distance (cells) far", 3, c);
        draw_text(&mut img, 1000, -1000, "x", 1, c);
        draw_text(&mut img, 0, 0, "\u{e9}\u{263a}\n", 1, c);
        assert_eq!(text_width("", 2), 0);
        assert!(text_width("far", 2) > text_width("far", 1));
        assert!(text_width("far far", 1) > text_width("far", 1));
        assert_eq!(cap_height(2), 14);
        assert!(text_height(1) >= 8 && text_height(1) <= 11);
        // A space advances but draws nothing.
        let mut img = RgbImage::new(30, 30);
        draw_text(&mut img, 2, 2, "   ", 2, c);
        assert!(inked_box(&img).is_none());
        assert!(text_width("   ", 2) > 0);
    }
}
