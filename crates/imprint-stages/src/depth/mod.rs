//! Height fields seen through a depth buffer: a mesh rendered orthographically straight down
//! ([`HeightView::Above`]: its top surface, what snow settles on) or straight up
//! ([`HeightView::Below`]: its underside, what presses into the ground), one pixel per
//! height-field cell. This is the depth-buffer trick of Tokoi's and Onoue's methods
//! (docs/methods.md §4, §5, §7): one rasterisation answers "how high is the body over each cell".
//!
//! The camera is placed so that pixel centres fall exactly on cell centres: pixel (i, j)
//! of an `Above` view is cell (i, j); a `Below` view sees the world mirrored in x, so its
//! pixel (i, j) is cell (nx − 1 − i, j). Heights are `eye.y − depth` (Above) or
//! `eye.y + depth` (Below); cells the mesh does not cover take [`HeightRegion::empty`].
//!
//! The CPU path is `imprint_core::raster`; a GPU path rasterises the same camera through
//! `imprint_gpu::raster` and converts the same way ([`heights_from_depth`]).

use glam::{UVec2, Vec2, Vec3};
use imprint_core::geom::Aabb;
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{Camera, Error, GridSpec, HeightField, Mesh, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Which side of the mesh the height field records.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
pub enum HeightView {
    /// Looking down: the highest surface over each cell.
    #[default]
    Above,
    /// Looking up: the lowest surface over each cell.
    Below,
}

/// The x-z cells a height field covers, and the height of cells the mesh leaves uncovered.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HeightRegion {
    /// World (x, z) of the centre of cell (0, 0).
    pub origin: Vec2,
    pub cell: f32,
    pub dims: UVec2,
    /// Height of cells no triangle covers (e.g. the ground level, 0).
    pub empty: f32,
}

impl HeightRegion {
    /// Square cells, `resolution` along the longer of the box's x and z sides grown by
    /// `padding` (a fraction of that side) on every side — the rule of `GridSpec::fit`.
    pub fn fit(bounds: &Aabb, resolution: u32, padding: f32, empty: f32) -> Result<Self> {
        let flat = Aabb {
            min: Vec3::new(bounds.min.x, 0.0, bounds.min.z),
            max: Vec3::new(bounds.max.x, 0.0, bounds.max.z),
        };
        let spec = GridSpec::fit(&flat, resolution, padding)?;
        Self::new(
            Vec2::new(spec.origin.x, spec.origin.z),
            spec.cell,
            UVec2::new(spec.dims.x, spec.dims.z),
            empty,
        )
    }

    /// Checks the region; errors name the field.
    pub fn new(origin: Vec2, cell: f32, dims: UVec2, empty: f32) -> Result<Self> {
        if !origin.is_finite() || !empty.is_finite() {
            return Err(Error::Invalid(format!(
                "height region: origin {origin} and empty {empty} must be finite"
            )));
        }
        if !(cell.is_finite() && cell > 0.0) {
            return Err(Error::Invalid(format!(
                "height region: cell must be finite and > 0, got {cell}"
            )));
        }
        let max = imprint_core::raster::MAX_SIZE;
        if dims.x == 0 || dims.y == 0 || dims.x > max || dims.y > max {
            return Err(Error::Invalid(format!(
                "height region: dims must be in 1..={max} per axis, got {} x {}",
                dims.x, dims.y
            )));
        }
        Ok(HeightRegion {
            origin,
            cell,
            dims,
            empty,
        })
    }

    /// World (x, z) of the region's centre.
    fn centre(&self) -> Vec2 {
        self.origin + 0.5 * (self.dims.as_vec2() - Vec2::ONE) * self.cell
    }

    /// The orthographic camera whose pixel centres are the cell centres, looking along −y
    /// (Above) or +y (Below) from just beyond `y_range` (the mesh's lowest and highest y),
    /// with a depth range that holds the whole range. Image up is −z, so image rows run
    /// along +z.
    pub fn camera(&self, view: HeightView, y_range: (f32, f32)) -> Result<Camera> {
        let (lo, hi) = y_range;
        let margin = self.cell.max((hi - lo).abs() * 1e-3);
        let c = self.centre();
        let (eye_y, dir) = match view {
            HeightView::Above => (hi + margin, -1.0),
            HeightView::Below => (lo - margin, 1.0),
        };
        let eye = Vec3::new(c.x, eye_y, c.y);
        let half_height = 0.5 * self.dims.y as f32 * self.cell;
        Camera::orthographic(
            eye,
            eye + Vec3::new(0.0, dir, 0.0),
            Vec3::NEG_Z,
            half_height,
        )?
        .with_depth_range(0.0, (hi - lo) + 2.0 * margin)
    }
}

/// Converts a depth map taken with [`HeightRegion::camera`] into the height field.
pub fn heights_from_depth(
    map: &DepthMap,
    region: &HeightRegion,
    view: HeightView,
) -> Result<HeightField> {
    let (nx, nz) = (region.dims.x, region.dims.y);
    if (map.width, map.height) != (nx, nz) {
        return Err(Error::Invalid(format!(
            "depth map is {} x {}, the height region {nx} x {nz}",
            map.width, map.height
        )));
    }
    let eye_y = map.camera.eye.y;
    HeightField::from_fn(region.origin, region.cell, region.dims, |i, k| {
        let (px, sign) = match view {
            HeightView::Above => (i, -1.0),
            HeightView::Below => (nx - 1 - i, 1.0),
        };
        match map.get(px, k) {
            Some(d) => eye_y + sign * d,
            None => region.empty,
        }
    })
}

/// The mesh's height field over `region` on the CPU (`imprint_core::raster`).
pub fn height_field_cpu(
    mesh: &Mesh,
    region: &HeightRegion,
    view: HeightView,
) -> Result<HeightField> {
    height_field_with(mesh, region, view, rasterize_depth_with)
}

/// The mesh's height field over `region`, through any rasteriser with the signature of
/// `imprint_core::raster::rasterize_depth_with` (the GPU one is a closure over its context).
pub fn height_field_with(
    mesh: &Mesh,
    region: &HeightRegion,
    view: HeightView,
    mut rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
) -> Result<HeightField> {
    let b = mesh.bounds();
    if b.is_empty() {
        return HeightField::constant(region.origin, region.cell, region.dims, region.empty);
    }
    let cam = region.camera(view, (b.min.y, b.max.y))?;
    let map = rasterize(
        mesh,
        &cam,
        region.dims.x,
        region.dims.y,
        &RasterOptions::default(),
    )?;
    heights_from_depth(&map, region, view)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::uv_sphere;

    /// A unit sphere at (0.3, 0.5, -0.2): every covered cell's height is the analytic cap
    /// height (top for Above, bottom for Below) to within the faceting of the sphere, and a
    /// cell is covered exactly when its centre lies inside the sphere's outline (away from
    /// the rim, where facets cut the circle).
    #[test]
    fn sphere_heights_match_the_analytic_caps() {
        let (c, r) = (Vec3::new(0.3, 0.5, -0.2), 1.0f32);
        let mut mesh = uv_sphere(r, 96, 48);
        mesh.transform(glam::Mat4::from_translation(c));
        let region = HeightRegion::fit(&mesh.bounds(), 64, 0.1, -7.0).unwrap();
        for view in [HeightView::Above, HeightView::Below] {
            let hf = height_field_cpu(&mesh, &region, view).unwrap();
            let (mut checked, mut empty) = (0, 0);
            for k in 0..hf.dims.y {
                for i in 0..hf.dims.x {
                    let p = hf.position(i, k);
                    let rho2 = (p.x - c.x).powi(2) + (p.z - c.z).powi(2);
                    let h = hf.get(i, k);
                    if rho2 < (0.97 * r).powi(2) {
                        let cap = (r * r - rho2).sqrt();
                        let want = match view {
                            HeightView::Above => c.y + cap,
                            HeightView::Below => c.y - cap,
                        };
                        // Facets lie inside the sphere: at most the chord sag below it.
                        assert!(
                            (h - want).abs() < 0.02 && (h - c.y).abs() <= cap + 1e-4,
                            "{view:?} cell ({i},{k}): {h} vs {want}"
                        );
                        checked += 1;
                    } else if rho2 > (1.01 * r).powi(2) {
                        assert_eq!(h, -7.0, "{view:?} cell ({i},{k}) outside is empty");
                        empty += 1;
                    }
                }
            }
            assert!(checked > 2000 && empty > 500, "{checked} {empty}");
        }
    }

    /// A tilted plane that is not symmetric in x: Below must mirror the image back, so both
    /// views of a single-sided sheet give the same heights.
    #[test]
    fn below_is_mirrored_back_onto_the_cells() {
        let mut m = Mesh::new(
            vec![
                Vec3::new(-1.0, 0.0, -1.0),
                Vec3::new(1.0, 0.6, -1.0),
                Vec3::new(1.0, 0.6, 1.0),
                Vec3::new(-1.0, 0.0, 1.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
            "ramp",
        )
        .unwrap();
        m.compute_normals();
        let region =
            HeightRegion::new(Vec2::new(-0.95, -0.95), 0.1, UVec2::new(20, 20), 0.0).unwrap();
        let up = height_field_cpu(&m, &region, HeightView::Above).unwrap();
        let down = height_field_cpu(&m, &region, HeightView::Below).unwrap();
        for k in 0..20 {
            for i in 0..20 {
                let x = -0.95 + 0.1 * i as f32;
                let want = 0.3 * (x + 1.0);
                assert!((up.get(i, k) - want).abs() < 1e-5, "above ({i},{k})");
                assert!((down.get(i, k) - want).abs() < 1e-5, "below ({i},{k})");
            }
        }
    }

    #[test]
    fn bad_regions_name_the_field() {
        let e = HeightRegion::new(Vec2::ZERO, 0.0, UVec2::ONE, 0.0).unwrap_err();
        assert!(e.to_string().contains("cell"), "{e}");
        let e = HeightRegion::new(Vec2::ZERO, 1.0, UVec2::new(0, 3), 0.0).unwrap_err();
        assert!(e.to_string().contains("dims"), "{e}");
        let e = HeightRegion::new(Vec2::ZERO, 1.0, UVec2::ONE, f32::NAN).unwrap_err();
        assert!(e.to_string().contains("empty"), "{e}");
    }
}
