//! Writes a field-slice picture of a synthetic field: the exact unsigned distance to two
//! sphere shells (a large one in the middle, a small one up and to the right, so the picture
//! shows which way is up) on a 96^3 grid, band 3 cells.
//!
//! `cargo run -p imprint-render --example slice_example -- [OUT.png]` (default
//! `/tmp/slice_example.png`).

use imprint_core::glam::{UVec3, Vec3};
use imprint_core::{DistanceField, GridSpec};
use imprint_render::slice::{Axis, SliceIndex, SliceOptions, write_field_slice};
use std::sync::Arc;

fn main() -> imprint_core::Result<()> {
    let out = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "/tmp/slice_example.png".into());
    let n = 96;
    let spec = GridSpec::new(Vec3::splat(0.5 / n as f32), 1.0 / n as f32, UVec3::splat(n))?;
    let band = 3.0;
    // (centre, radius) in world units; the grid spans [0, 1]^3.
    let spheres = [
        (Vec3::new(0.46, 0.42, 0.5), 0.30),
        (Vec3::new(0.76, 0.82, 0.5), 0.09),
    ];

    let mut dist = vec![band * spec.cell; spec.len()];
    let mut nearest = vec![DistanceField::FAR; spec.len()];
    let mut points = Vec::new();
    for i in 0..spec.len() {
        let x = spec.center(spec.coords(i));
        // The closest point on the union is the closest of the closest points.
        let (d, p) = spheres
            .iter()
            .map(|&(c, r)| {
                let dir = (x - c).try_normalize().unwrap_or(Vec3::X);
                let p = c + r * dir;
                ((x - p).length(), p)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .unwrap();
        if d <= band * spec.cell {
            dist[i] = d;
            nearest[i] = points.len() as u32;
            points.push(p);
        }
    }
    let field = DistanceField {
        spec,
        band,
        dist,
        nearest,
        points: Arc::new(points),
    };

    let opts = SliceOptions {
        title: Some("spheres  frame 0000".into()),
        ..SliceOptions::new(Axis::Z, SliceIndex::Middle)
    };
    write_field_slice(out.as_ref(), &field, &opts)?;
    println!("wrote {out}");
    Ok(())
}
