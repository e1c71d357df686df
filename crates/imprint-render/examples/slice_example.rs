//! Writes a field-slice picture of a synthetic field: the exact unsigned distance to two
//! sphere shells (a large one in the middle, a small one up and to the right, so the picture
//! shows which way is up) on a 96^3 grid, band 3 cells.
//!
//! `cargo run -p imprint-render --example slice_example -- [OUT.png [AXIS [PIXELS_PER_CELL]]]`
//! (default `/tmp/slice_example.png`, a Z slice through the middle, automatic scale).

use imprint_core::glam::{UVec3, Vec3};
use imprint_core::{DistanceField, GridSpec};
use imprint_render::slice::{Axis, SliceIndex, SliceOptions, write_field_slice};

fn main() -> imprint_core::Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = args
        .first()
        .cloned()
        .unwrap_or("/tmp/slice_example.png".into());
    let axis = match args.get(1).map(String::as_str) {
        None | Some("z" | "Z") => Axis::Z,
        Some("y" | "Y") => Axis::Y,
        Some("x" | "X") => Axis::X,
        Some(other) => {
            return Err(imprint_core::Error::Invalid(format!(
                "axis {other:?}: expected x, y or z"
            )));
        }
    };
    let pixels_per_cell = match args.get(2) {
        Some(p) => Some(p.parse().map_err(|_| {
            imprint_core::Error::Invalid(format!("pixels per cell {p:?}: expected a number"))
        })?),
        None => None,
    };
    let n = 96;
    let spec = GridSpec::new(Vec3::splat(0.5 / n as f32), 1.0 / n as f32, UVec3::splat(n))?;
    let band = 3.0;
    // (centre, radius) in world units; the grid spans [0, 1]^3.
    let spheres = [
        (Vec3::new(0.46, 0.42, 0.5), 0.30),
        (Vec3::new(0.76, 0.82, 0.5), 0.09),
    ];

    // The closest point on the union is the closest of the closest points.
    let field = DistanceField::from_closest_points(spec, band, |x| {
        spheres
            .iter()
            .map(|&(c, r)| c + r * (x - c).try_normalize().unwrap_or(Vec3::X))
            .min_by(|p, q| (*p - x).length().total_cmp(&(*q - x).length()))
            .unwrap()
    });

    let opts = SliceOptions {
        title: Some("spheres  frame 0000".into()),
        pixels_per_cell,
        ..SliceOptions::new(axis, SliceIndex::Middle)
    };
    write_field_slice(out.as_ref(), &field, &opts)?;
    println!("wrote {out}");
    Ok(())
}
