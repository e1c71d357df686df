//! O §2.1, contact from below: each object is rendered looking up, orthographically, one
//! pixel per cell ([`crate::depth`], `HeightView::Below`), which gives its lowest surface
//! over every cell; a cell is in contact where that bottom is below the ground's surface.
//!
//! O does this with one depth buffer (ground first, objects with the depth test, a stencil
//! bit where an object wins). We rasterise each object on its own, only over the cells under
//! its bounds (a window), and keep the lowest bottom per cell: the same answer, without
//! touching the cells no object is over. Bottoms are rounded to the nearest height unit and
//! never below the base plane (height 0), which O's ground does not go under.

use crate::depth::{HeightRegion, HeightView, height_field_with};
use glam::{UVec2, Vec2};
use imprint_core::geom::Aabb;
use imprint_core::raster::{DepthMap, RasterOptions, rasterize_depth_with};
use imprint_core::{Camera, Mesh, Result};
use serde::{Deserialize, Serialize};

/// The ground's cells in the world (the conventions of `imprint_core::HeightField`: square
/// cells, `origin` the centre of cell (0, 0), x fastest) and its fixed-point height unit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GroundGrid {
    /// World (x, z) of the centre of cell (0, 0).
    pub origin: Vec2,
    /// Edge length of a cell, m.
    pub cell: f32,
    /// Cells along x and z.
    pub dims: UVec2,
    /// Metres per height unit.
    pub unit: f64,
}

/// A rectangle of cells: columns `i0..i0 + w`, rows `k0..k0 + h`. The per-frame work of the
/// stage runs over windows, so its cost follows the contact, not the field.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Window {
    pub i0: u32,
    pub k0: u32,
    pub w: u32,
    pub h: u32,
}

/// The bottom of a cell no object is over.
pub const NO_OBJECT: i32 = i32::MAX;

/// The objects' lowest surface over a window of cells, in height units, row-major (x
/// fastest); [`NO_OBJECT`] where no object is over the cell.
#[derive(Clone, Debug, PartialEq)]
pub struct Bottoms {
    pub window: Window,
    pub bottom: Vec<i32>,
}

impl GroundGrid {
    /// Heights in units (x fastest) as a height field in metres, for writers and renderers.
    pub fn height_field(&self, units: &[i32]) -> imprint_core::HeightField {
        use rayon::prelude::*;
        imprint_core::HeightField {
            origin: self.origin,
            cell: self.cell,
            dims: self.dims,
            heights: units
                .par_iter()
                .map(|&h| (h as f64 * self.unit) as f32)
                .collect(),
        }
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.dims.x as usize * self.dims.y as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// World (x, z) of the centre of cell (i, k).
    pub fn centre(&self, i: u32, k: u32) -> Vec2 {
        self.origin + Vec2::new(i as f32, k as f32) * self.cell
    }

    /// `metres` in height units, rounded to the nearest (so a height stated in metres that
    /// is a whole number of units is exact).
    pub fn to_units(&self, metres: f64) -> i64 {
        (metres / self.unit).round() as i64
    }

    /// Units in metres.
    pub fn to_metres(&self, units: i64) -> f64 {
        units as f64 * self.unit
    }

    /// Cubic metres per unit of summed height (one unit over one cell).
    pub fn unit_volume(&self) -> f64 {
        self.unit * self.cell as f64 * self.cell as f64
    }

    /// The cells whose centres may lie under the x-z extent of `b` (one cell of margin
    /// against rounding), clipped to the grid; `None` when none do.
    pub fn window_under(&self, b: &Aabb) -> Option<Window> {
        let lo = (Vec2::new(b.min.x, b.min.z) - self.origin) / self.cell;
        let hi = (Vec2::new(b.max.x, b.max.z) - self.origin) / self.cell;
        let range = |lo: f32, hi: f32, n: u32| -> Option<(u32, u32)> {
            let a = (lo.floor() as i64 - 1).max(0);
            let z = (hi.ceil() as i64 + 1).min(n as i64 - 1);
            (lo.is_finite() && hi.is_finite() && a <= z).then_some((a as u32, (z - a + 1) as u32))
        };
        let (i0, w) = range(lo.x, hi.x, self.dims.x)?;
        let (k0, h) = range(lo.y, hi.y, self.dims.y)?;
        Some(Window { i0, k0, w, h })
    }

    /// The depth-view region of a window: its cells, with "empty" far above everything.
    pub fn region(&self, w: &Window) -> Result<HeightRegion> {
        HeightRegion::new(
            self.origin + Vec2::new(w.i0 as f32, w.k0 as f32) * self.cell,
            self.cell,
            UVec2::new(w.w, w.h),
            f32::MAX,
        )
    }

    /// A height from the depth view in units: rounded, at least 0 (the base plane), and
    /// [`NO_OBJECT`] for cells the view left empty.
    fn bottom_units(&self, metres: f32) -> i32 {
        if metres >= f32::MAX {
            NO_OBJECT
        } else {
            self.to_units(metres as f64).clamp(0, NO_OBJECT as i64 - 1) as i32
        }
    }
}

impl Window {
    /// The whole grid.
    pub fn full(dims: UVec2) -> Self {
        Window {
            i0: 0,
            k0: 0,
            w: dims.x,
            h: dims.y,
        }
    }

    pub fn len(&self) -> usize {
        self.w as usize * self.h as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Grown by `by` cells on every side, clipped to a grid of `dims`.
    pub fn grow(&self, by: u32, dims: UVec2) -> Window {
        let i0 = self.i0.saturating_sub(by);
        let k0 = self.k0.saturating_sub(by);
        let i1 = (self.i0 as u64 + self.w as u64 + by as u64).min(dims.x as u64) as u32;
        let k1 = (self.k0 as u64 + self.h as u64 + by as u64).min(dims.y as u64) as u32;
        Window {
            i0,
            k0,
            w: i1 - i0,
            h: k1 - k0,
        }
    }

    /// The smallest window holding both.
    pub fn union(&self, o: &Window) -> Window {
        let i0 = self.i0.min(o.i0);
        let k0 = self.k0.min(o.k0);
        let i1 = (self.i0 + self.w).max(o.i0 + o.w);
        let k1 = (self.k0 + self.h).max(o.k0 + o.h);
        Window {
            i0,
            k0,
            w: i1 - i0,
            h: k1 - k0,
        }
    }

    /// Index, in a grid `nx` cells wide, of the window's cell (x, y).
    #[inline]
    pub fn global(&self, x: u32, y: u32, nx: u32) -> usize {
        (self.k0 + y) as usize * nx as usize + (self.i0 + x) as usize
    }
}

/// The objects' bottoms over the cells under them, on the CPU rasteriser; `None` when no
/// object reaches below the highest ground under it (then nothing can be in contact).
pub fn object_bottoms(
    objects: &[&Mesh],
    grid: &GroundGrid,
    heights: &[i32],
) -> Result<Option<Bottoms>> {
    object_bottoms_with(objects, grid, heights, rasterize_depth_with)
}

/// [`object_bottoms`] through any rasteriser with the signature of
/// `imprint_core::raster::rasterize_depth_with` (the GPU one is a closure over its context).
/// Several objects: each is rasterised over its own window and the lowest bottom kept.
pub fn object_bottoms_with(
    objects: &[&Mesh],
    grid: &GroundGrid,
    heights: &[i32],
    mut rasterize: impl FnMut(&Mesh, &Camera, u32, u32, &RasterOptions) -> Result<DepthMap>,
) -> Result<Option<Bottoms>> {
    let nx = grid.dims.x;
    let mut parts = Vec::new();
    for mesh in objects {
        let b = mesh.bounds();
        if b.is_empty() {
            continue;
        }
        let Some(w) = grid.window_under(&b) else {
            continue;
        };
        // Skip an object that stays above every cell under it: no contact, no rasterising.
        let top = (0..w.h)
            .flat_map(|y| (0..w.w).map(move |x| heights[w.global(x, y, nx)]))
            .max()
            .unwrap_or(0);
        if grid.to_units(b.min.y as f64) >= top as i64 {
            continue;
        }
        let hf = height_field_with(mesh, &grid.region(&w)?, HeightView::Below, &mut rasterize)?;
        parts.push((w, hf));
    }
    let Some(window) = parts.iter().map(|p| p.0).reduce(|a, b| a.union(&b)) else {
        return Ok(None);
    };
    let mut bottom = vec![NO_OBJECT; window.len()];
    for (w, hf) in &parts {
        for y in 0..w.h {
            for x in 0..w.w {
                let j = (w.k0 - window.k0 + y) as usize * window.w as usize
                    + (w.i0 - window.i0 + x) as usize;
                let b = grid.bottom_units(hf.get(x, y));
                bottom[j] = bottom[j].min(b);
            }
        }
    }
    Ok(Some(Bottoms { window, bottom }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{Mat4, Vec3};
    use imprint_core::mesh::primitives::cuboid;

    fn grid() -> GroundGrid {
        GroundGrid {
            origin: Vec2::new(-0.95, -0.95),
            cell: 0.1,
            dims: UVec2::new(20, 20),
            unit: 1e-5,
        }
    }

    /// Two boxes: the window holds both, each cell under a box gets its bottom (rounded to
    /// the unit, clamped at the base plane), and the lower box wins where both are.
    #[test]
    fn several_objects_keep_the_lowest_bottom() {
        let g = grid();
        let heights = vec![g.to_units(0.5) as i32; g.len()];
        let mut a = cuboid(Vec3::new(0.3, 0.2, 0.3), 1);
        a.transform(Mat4::from_translation(Vec3::new(-0.3, 0.6, 0.0)));
        let mut b = cuboid(Vec3::new(0.2, 0.2, 0.2), 1);
        b.transform(Mat4::from_translation(Vec3::new(0.0, 0.1, 0.0)));
        let bt = object_bottoms(&[&a, &b], &g, &heights).unwrap().unwrap();
        let at = |x: f32, z: f32| {
            let i = ((x - g.origin.x) / g.cell).round() as u32 - bt.window.i0;
            let k = ((z - g.origin.y) / g.cell).round() as u32 - bt.window.k0;
            bt.bottom[(k * bt.window.w + i) as usize]
        };
        assert_eq!(at(-0.45, 0.05), 40_000); // box a only: bottom 0.4
        assert_eq!(at(0.05, 0.05), 0); // box b reaches -0.1: clamped to the base plane
        assert_eq!(at(0.15, 0.25), NO_OBJECT); // in the window, under neither box
        // An object above all the ground under it is not rasterised at all.
        let mut high = cuboid(Vec3::splat(0.1), 1);
        high.transform(Mat4::from_translation(Vec3::new(0.0, 0.7, 0.0)));
        assert!(object_bottoms(&[&high], &g, &heights).unwrap().is_none());
    }

    #[test]
    fn windows_clip_to_the_grid() {
        let g = grid();
        let far = Aabb {
            min: Vec3::new(5.0, 0.0, 5.0),
            max: Vec3::new(6.0, 1.0, 6.0),
        };
        assert!(g.window_under(&far).is_none());
        let edge = Aabb {
            min: Vec3::new(-2.0, 0.0, 0.0),
            max: Vec3::new(-0.9, 1.0, 0.1),
        };
        let w = g.window_under(&edge).unwrap();
        assert_eq!((w.i0, w.w), (0, 3));
        let grown = w.grow(5, g.dims);
        assert_eq!((grown.i0, grown.w, grown.k0), (0, 8, w.k0 - 5));
        assert_eq!(Window::full(g.dims).grow(3, g.dims), Window::full(g.dims));
    }
}
