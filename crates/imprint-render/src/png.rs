//! PNG output through [`atomic_write`]: a picture is either complete under its name or absent.

use image::codecs::png::PngEncoder;
use image::{ExtendedColorType, ImageEncoder, RgbImage};
use imprint_core::Result;
use imprint_core::io::atomic_write;
use std::path::Path;

/// Writes an 8-bit RGB PNG.
pub fn write_png(path: &Path, img: &RgbImage) -> Result<()> {
    atomic_write(path, |w| {
        PngEncoder::new(w)
            .write_image(
                img.as_raw(),
                img.width(),
                img.height(),
                ExtendedColorType::Rgb8,
            )
            .map_err(std::io::Error::other)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.png");
        let mut img = RgbImage::new(3, 2);
        img.put_pixel(2, 1, image::Rgb([10, 200, 30]));
        write_png(&path, &img).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        assert_eq!(back, img);
    }
}
