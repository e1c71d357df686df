//! A tiny embedded 5x7 bitmap font for labels on pictures (legends, titles, tick values), so
//! writers need no font file or font crate and draw the same pixels everywhere.
//!
//! Each glyph is 7 rows of 5 bits, bit 4 the leftmost column, drawn in a cell 6 columns wide
//! (one blank column between letters) and 9 rows tall: rows 0-6 hold capitals and digits
//! (baseline under row 6), rows 7-8 the descenders of g, j, p, q, y, whose glyphs are drawn
//! lower (see [`drop_rows`]). Every printable ASCII character is present; anything else draws
//! as an empty box so a missing glyph is visible rather than silently skipped.

use image::{Rgb, RgbImage};

/// Glyph width and the horizontal advance per character, in font pixels.
pub const GLYPH_W: u32 = 5;
pub const ADVANCE: u32 = 6;
/// Glyph rows, and the height of a line including descenders, in font pixels.
pub const GLYPH_H: u32 = 7;
pub const LINE_H: u32 = 9;

/// Printable ASCII, in code order (index = code - 32), so lookup is an index.
#[rustfmt::skip]
const GLYPHS: [(char, [u8; 7]); 95] = [
    (' ', [0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000]),
    ('!', [0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00000, 0b00100]),
    ('"', [0b01010, 0b01010, 0b01010, 0b00000, 0b00000, 0b00000, 0b00000]),
    ('#', [0b01010, 0b01010, 0b11111, 0b01010, 0b11111, 0b01010, 0b01010]),
    ('$', [0b00100, 0b01111, 0b10100, 0b01110, 0b00101, 0b11110, 0b00100]),
    ('%', [0b11000, 0b11001, 0b00010, 0b00100, 0b01000, 0b10011, 0b00011]),
    ('&', [0b01100, 0b10010, 0b10100, 0b01000, 0b10101, 0b10010, 0b01101]),
    ('\'', [0b00100, 0b00100, 0b01000, 0b00000, 0b00000, 0b00000, 0b00000]),
    ('(', [0b00010, 0b00100, 0b01000, 0b01000, 0b01000, 0b00100, 0b00010]),
    (')', [0b01000, 0b00100, 0b00010, 0b00010, 0b00010, 0b00100, 0b01000]),
    ('*', [0b00000, 0b00100, 0b10101, 0b01110, 0b10101, 0b00100, 0b00000]),
    ('+', [0b00000, 0b00100, 0b00100, 0b11111, 0b00100, 0b00100, 0b00000]),
    (',', [0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b00100, 0b01000]),
    ('-', [0b00000, 0b00000, 0b00000, 0b11111, 0b00000, 0b00000, 0b00000]),
    ('.', [0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b01100, 0b01100]),
    ('/', [0b00000, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b00000]),
    ('0', [0b01110, 0b10001, 0b10011, 0b10101, 0b11001, 0b10001, 0b01110]),
    ('1', [0b00100, 0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('2', [0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b01000, 0b11111]),
    ('3', [0b11111, 0b00010, 0b00100, 0b00010, 0b00001, 0b10001, 0b01110]),
    ('4', [0b00010, 0b00110, 0b01010, 0b10010, 0b11111, 0b00010, 0b00010]),
    ('5', [0b11111, 0b10000, 0b11110, 0b00001, 0b00001, 0b10001, 0b01110]),
    ('6', [0b00110, 0b01000, 0b10000, 0b11110, 0b10001, 0b10001, 0b01110]),
    ('7', [0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b01000, 0b01000]),
    ('8', [0b01110, 0b10001, 0b10001, 0b01110, 0b10001, 0b10001, 0b01110]),
    ('9', [0b01110, 0b10001, 0b10001, 0b01111, 0b00001, 0b00010, 0b01100]),
    (':', [0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b01100, 0b00000]),
    (';', [0b00000, 0b01100, 0b01100, 0b00000, 0b01100, 0b00100, 0b01000]),
    ('<', [0b00010, 0b00100, 0b01000, 0b10000, 0b01000, 0b00100, 0b00010]),
    ('=', [0b00000, 0b00000, 0b11111, 0b00000, 0b11111, 0b00000, 0b00000]),
    ('>', [0b01000, 0b00100, 0b00010, 0b00001, 0b00010, 0b00100, 0b01000]),
    ('?', [0b01110, 0b10001, 0b00001, 0b00010, 0b00100, 0b00000, 0b00100]),
    ('@', [0b01110, 0b10001, 0b00001, 0b01101, 0b10101, 0b10101, 0b01110]),
    ('A', [0b01110, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001]),
    ('B', [0b11110, 0b10001, 0b10001, 0b11110, 0b10001, 0b10001, 0b11110]),
    ('C', [0b01110, 0b10001, 0b10000, 0b10000, 0b10000, 0b10001, 0b01110]),
    ('D', [0b11100, 0b10010, 0b10001, 0b10001, 0b10001, 0b10010, 0b11100]),
    ('E', [0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b11111]),
    ('F', [0b11111, 0b10000, 0b10000, 0b11110, 0b10000, 0b10000, 0b10000]),
    ('G', [0b01110, 0b10001, 0b10000, 0b10111, 0b10001, 0b10001, 0b01111]),
    ('H', [0b10001, 0b10001, 0b10001, 0b11111, 0b10001, 0b10001, 0b10001]),
    ('I', [0b01110, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('J', [0b00111, 0b00010, 0b00010, 0b00010, 0b00010, 0b10010, 0b01100]),
    ('K', [0b10001, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010, 0b10001]),
    ('L', [0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b10000, 0b11111]),
    ('M', [0b10001, 0b11011, 0b10101, 0b10101, 0b10001, 0b10001, 0b10001]),
    ('N', [0b10001, 0b10001, 0b11001, 0b10101, 0b10011, 0b10001, 0b10001]),
    ('O', [0b01110, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110]),
    ('P', [0b11110, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000, 0b10000]),
    ('Q', [0b01110, 0b10001, 0b10001, 0b10001, 0b10101, 0b10010, 0b01101]),
    ('R', [0b11110, 0b10001, 0b10001, 0b11110, 0b10100, 0b10010, 0b10001]),
    ('S', [0b01111, 0b10000, 0b10000, 0b01110, 0b00001, 0b00001, 0b11110]),
    ('T', [0b11111, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100]),
    ('U', [0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01110]),
    ('V', [0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100]),
    ('W', [0b10001, 0b10001, 0b10001, 0b10101, 0b10101, 0b10101, 0b01010]),
    ('X', [0b10001, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001, 0b10001]),
    ('Y', [0b10001, 0b10001, 0b10001, 0b01010, 0b00100, 0b00100, 0b00100]),
    ('Z', [0b11111, 0b00001, 0b00010, 0b00100, 0b01000, 0b10000, 0b11111]),
    ('[', [0b01110, 0b01000, 0b01000, 0b01000, 0b01000, 0b01000, 0b01110]),
    ('\\', [0b00000, 0b10000, 0b01000, 0b00100, 0b00010, 0b00001, 0b00000]),
    (']', [0b01110, 0b00010, 0b00010, 0b00010, 0b00010, 0b00010, 0b01110]),
    ('^', [0b00100, 0b01010, 0b10001, 0b00000, 0b00000, 0b00000, 0b00000]),
    ('_', [0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b00000, 0b11111]),
    ('`', [0b01000, 0b00100, 0b00010, 0b00000, 0b00000, 0b00000, 0b00000]),
    ('a', [0b00000, 0b00000, 0b01110, 0b00001, 0b01111, 0b10001, 0b01111]),
    ('b', [0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b11110]),
    ('c', [0b00000, 0b00000, 0b01110, 0b10000, 0b10000, 0b10001, 0b01110]),
    ('d', [0b00001, 0b00001, 0b01101, 0b10011, 0b10001, 0b10001, 0b01111]),
    ('e', [0b00000, 0b00000, 0b01110, 0b10001, 0b11111, 0b10000, 0b01110]),
    ('f', [0b00110, 0b01001, 0b01000, 0b11100, 0b01000, 0b01000, 0b01000]),
    // g, j, p, q, y: drawn lower by drop_rows(); the last rows are the descender.
    ('g', [0b01111, 0b10001, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110]),
    ('h', [0b10000, 0b10000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001]),
    ('i', [0b00100, 0b00000, 0b01100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('j', [0b00010, 0b00000, 0b00110, 0b00010, 0b00010, 0b10010, 0b01100]),
    ('k', [0b10000, 0b10000, 0b10010, 0b10100, 0b11000, 0b10100, 0b10010]),
    ('l', [0b01100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b01110]),
    ('m', [0b00000, 0b00000, 0b11010, 0b10101, 0b10101, 0b10001, 0b10001]),
    ('n', [0b00000, 0b00000, 0b10110, 0b11001, 0b10001, 0b10001, 0b10001]),
    ('o', [0b00000, 0b00000, 0b01110, 0b10001, 0b10001, 0b10001, 0b01110]),
    ('p', [0b11110, 0b10001, 0b10001, 0b10001, 0b11110, 0b10000, 0b10000]),
    ('q', [0b01111, 0b10001, 0b10001, 0b10001, 0b01111, 0b00001, 0b00001]),
    ('r', [0b00000, 0b00000, 0b10110, 0b11001, 0b10000, 0b10000, 0b10000]),
    ('s', [0b00000, 0b00000, 0b01110, 0b10000, 0b01110, 0b00001, 0b11110]),
    ('t', [0b01000, 0b01000, 0b11100, 0b01000, 0b01000, 0b01001, 0b00110]),
    ('u', [0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b10011, 0b01101]),
    ('v', [0b00000, 0b00000, 0b10001, 0b10001, 0b10001, 0b01010, 0b00100]),
    ('w', [0b00000, 0b00000, 0b10001, 0b10001, 0b10101, 0b10101, 0b01010]),
    ('x', [0b00000, 0b00000, 0b10001, 0b01010, 0b00100, 0b01010, 0b10001]),
    ('y', [0b10001, 0b10001, 0b10001, 0b10001, 0b01111, 0b00001, 0b01110]),
    ('z', [0b00000, 0b00000, 0b11111, 0b00010, 0b00100, 0b01000, 0b11111]),
    ('{', [0b00010, 0b00100, 0b00100, 0b01000, 0b00100, 0b00100, 0b00010]),
    ('|', [0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100, 0b00100]),
    ('}', [0b01000, 0b00100, 0b00100, 0b00010, 0b00100, 0b00100, 0b01000]),
    ('~', [0b00000, 0b00000, 0b01000, 0b10101, 0b00010, 0b00000, 0b00000]),
];

/// Drawn for characters the font lacks: an empty box.
const MISSING: [u8; 7] = [
    0b11111, 0b10001, 0b10001, 0b10001, 0b10001, 0b10001, 0b11111,
];

/// The 7 rows of `c`'s glyph (bit 4 = leftmost column), or None if the font lacks it.
pub fn glyph(c: char) -> Option<[u8; 7]> {
    let i = (c as u32).checked_sub(32)? as usize;
    GLYPHS.get(i).map(|&(_, rows)| rows)
}

/// How many rows below the line's top a glyph starts: letters with descenders sit lower.
pub fn drop_rows(c: char) -> u32 {
    match c {
        'g' | 'p' | 'q' | 'y' => 2,
        'j' => 1,
        _ => 0,
    }
}

/// Width in image pixels of `text` drawn at `scale` (no trailing gap).
pub fn text_width(text: &str, scale: u32) -> u32 {
    let n = text.chars().count() as u32;
    (n * ADVANCE).saturating_sub(ADVANCE - GLYPH_W) * scale
}

/// Height in image pixels of a line at `scale`, descenders included.
pub fn text_height(scale: u32) -> u32 {
    LINE_H * scale
}

/// Draws `text` with its top-left corner at (x, y), each font pixel a `scale`x`scale` square.
/// Pixels outside the image are clipped, so labels near an edge never panic.
pub fn draw_text(img: &mut RgbImage, x: i64, y: i64, text: &str, scale: u32, color: Rgb<u8>) {
    let s = scale.max(1) as i64;
    for (n, c) in text.chars().enumerate() {
        let rows = glyph(c).unwrap_or(MISSING);
        let gx = x + n as i64 * ADVANCE as i64 * s;
        let gy = y + drop_rows(c) as i64 * s;
        for (r, bits) in rows.iter().enumerate() {
            for col in 0..GLYPH_W as i64 {
                if bits & (0b10000 >> col) != 0 {
                    fill_rect(img, gx + col * s, gy + r as i64 * s, s, s, color);
                }
            }
        }
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

    #[test]
    fn table_is_in_ascii_order() {
        for (i, &(c, _)) in GLYPHS.iter().enumerate() {
            assert_eq!(c as usize, i + 32, "glyph {c:?} out of place");
        }
        assert_eq!(glyph('A'), Some(GLYPHS[33].1));
        assert_eq!(glyph('\u{e9}'), None);
        assert_eq!(glyph('\n'), None);
    }

    #[test]
    fn every_glyph_fits_five_columns_and_is_distinct() {
        for &(c, rows) in &GLYPHS {
            assert!(rows.iter().all(|&r| r < 32), "{c:?} is wider than 5");
        }
        for (i, a) in GLYPHS.iter().enumerate() {
            for b in &GLYPHS[i + 1..] {
                assert!(
                    a.1 != b.1 || a.0 == ' ',
                    "{:?} and {:?} look the same",
                    a.0,
                    b.0
                );
            }
        }
    }

    #[test]
    fn draws_the_glyph_pattern_at_scale() {
        // '7' at scale 2, one pixel in from the corner: its top bar, then the diagonal.
        let mut img = RgbImage::new(16, 20);
        let white = Rgb([255, 255, 255]);
        draw_text(&mut img, 1, 1, "7", 2, white);
        let on = |x: u32, y: u32| img.get_pixel(x, y)[0] == 255;
        let expected = glyph('7').unwrap();
        for (r, bits) in expected.iter().enumerate() {
            for c in 0..5u32 {
                let want = bits & (0b10000 >> c) != 0;
                for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                    let (x, y) = (1 + 2 * c + dx, 1 + 2 * r as u32 + dy);
                    assert_eq!(on(x, y), want, "pixel ({x}, {y})");
                }
            }
        }
        // The top row of '7' is a full bar; its last row has only column 1 lit.
        assert!((0..10).all(|x| on(1 + x, 1)));
        assert!(!on(1, 13) && on(3, 13) && !on(5, 13));
        // Nothing outside the glyph's 10x14 box.
        assert!((0..16).all(|x| !on(x, 0) && !on(x, 15)));
    }

    #[test]
    fn descenders_drop_and_text_clips_at_edges() {
        let mut img = RgbImage::new(12, 12);
        let c = Rgb([9, 9, 9]);
        draw_text(&mut img, 0, 0, "g", 1, c);
        // 'g' starts two rows down: rows 0-1 are empty, its bowl top is row 2.
        assert!((0..5).all(|x| img.get_pixel(x, 0)[0] == 0 && img.get_pixel(x, 1)[0] == 0));
        assert_eq!(img.get_pixel(1, 2)[0], 9);
        // Its descender reaches row 8.
        assert_eq!(img.get_pixel(2, 8)[0], 9);
        // Far outside or half outside: no panic.
        draw_text(&mut img, -7, 9, "distance (cells) far", 3, c);
        draw_text(&mut img, 1000, -1000, "x", 1, c);
        assert_eq!(text_width("far", 2), (3 * 6 - 1) * 2);
        assert_eq!(text_width("", 2), 0);
    }
}
