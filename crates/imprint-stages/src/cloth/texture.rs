//! The anisotropy texture of T eq. 5: per texel four spring multipliers (warp, weft and the
//! two bias diagonals), read at a spring's midpoint UV.
//!
//! It is read from a PNG through the `image` crate (any bit depth and colour type, converted
//! to 8-bit RGBA; missing channels are 255).

use glam::{Vec2, Vec4};
use imprint_core::{Error, Result};
use std::path::Path;

/// RGBA multipliers per texel, row 0 at v = 0 (the bottom of the image: PNG rows run top to
/// bottom, UVs bottom to top, as in OBJ).
#[derive(Clone, Debug, PartialEq)]
pub struct AnisotropyMap {
    pub width: u32,
    pub height: u32,
    /// `scale * channel / 255` per texel, rows from v = 0 up.
    pub texels: Vec<Vec4>,
}

impl AnisotropyMap {
    /// One texel everywhere: (Ka, Kb, Kc, Kd).
    pub fn uniform(k: Vec4) -> Self {
        AnisotropyMap {
            width: 1,
            height: 1,
            texels: vec![k],
        }
    }

    /// From 8-bit RGBA rows as stored in an image (top row first).
    pub fn from_rgba8(width: u32, height: u32, rgba: &[u8], scale: f32) -> Result<Self> {
        if width == 0 || height == 0 || rgba.len() != 4 * width as usize * height as usize {
            return Err(Error::Invalid(format!(
                "anisotropy texture: {} bytes for {width}x{height} RGBA texels",
                rgba.len()
            )));
        }
        let row = 4 * width as usize;
        let texels = (0..height as usize)
            .rev()
            .flat_map(|r| rgba[r * row..(r + 1) * row].chunks_exact(4))
            .map(|t| {
                Vec4::new(t[0] as f32, t[1] as f32, t[2] as f32, t[3] as f32) * (scale / 255.0)
            })
            .collect();
        Ok(AnisotropyMap {
            width,
            height,
            texels,
        })
    }

    /// Reads a PNG (grey, grey+alpha, RGB or RGBA; channels missing are 255).
    pub fn load(path: &Path, scale: f32) -> Result<Self> {
        let img = image::open(path)
            .map_err(|e| Error::Invalid(format!("anisotropy texture {}: {e}", path.display())))?
            .to_rgba8();
        Self::from_rgba8(img.width(), img.height(), img.as_raw(), scale)
    }

    /// Bilinear lookup at `uv` (clamped to the edge; texel centres at (i + 0.5) / width).
    pub fn sample(&self, uv: Vec2) -> Vec4 {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = (uv.x * w as f32 - 0.5).clamp(0.0, (w - 1) as f32);
        let y = (uv.y * h as f32 - 0.5).clamp(0.0, (h - 1) as f32);
        let (x0, y0) = (x.floor() as i64, y.floor() as i64);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (tx, ty) = (x - x0 as f32, y - y0 as f32);
        let t = |i: i64, j: i64| self.texels[(j * w + i) as usize];
        let bottom = t(x0, y0).lerp(t(x1, y0), tx);
        let top = t(x0, y1).lerp(t(x1, y1), tx);
        bottom.lerp(top, ty)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unreadable_files_name_the_file() {
        let dir = std::env::temp_dir().join(format!("imprint-aniso-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("bad.png");
        std::fs::write(&p, b"GIF89a not a png").unwrap();
        let e = AnisotropyMap::load(&p, 1.0).unwrap_err().to_string();
        assert!(e.contains("bad.png"), "{e}");
        let e = AnisotropyMap::load(&dir.join("missing.png"), 1.0)
            .unwrap_err()
            .to_string();
        assert!(e.contains("missing.png"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn bilinear_lookup_flips_rows_and_clamps() {
        // Top row red-ish (Ka = 255), bottom row Ka = 0.
        let rgba = [255, 0, 0, 0, 255, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0];
        let m = AnisotropyMap::from_rgba8(2, 2, &rgba, 2.0).unwrap();
        assert_eq!(m.sample(Vec2::new(0.5, 0.0)).x, 0.0);
        assert_eq!(m.sample(Vec2::new(0.5, 1.0)).x, 2.0);
        assert!((m.sample(Vec2::new(0.3, 0.5)).x - 1.0).abs() < 1e-6);
        assert_eq!(
            AnisotropyMap::uniform(Vec4::ONE).sample(Vec2::new(7.0, -3.0)),
            Vec4::ONE
        );
    }
}
