//! The uniform grid every volumetric stage shares.
//!
//! Convention: `origin` is the *centre* of cell (0, 0, 0); cell (i, j, k) is the cube of side
//! `cell` centred on `origin + (i, j, k) * cell`. Data is laid out x fastest, then y, then z
//! (index = i + nx * (j + ny * k)), so a `[nz, ny, nx]` array in NumPy reads it directly.

use crate::error::check_alloc;
use crate::{Aabb, Error, Result};
use glam::{IVec3, UVec3, Vec3};
use serde::{Deserialize, Serialize};

/// The largest number of cells along one axis we accept (a guard against typos like 100000).
pub const MAX_AXIS_CELLS: u32 = 4096;

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridSpec {
    /// Centre of cell (0, 0, 0), world units.
    pub origin: Vec3,
    /// Edge length of a (cubic) cell, world units.
    pub cell: f32,
    /// Number of cells along x, y, z.
    pub dims: UVec3,
}

impl GridSpec {
    /// An explicit grid, validated.
    pub fn new(origin: Vec3, cell: f32, dims: UVec3) -> Result<Self> {
        if !origin.is_finite() {
            return Err(Error::Invalid(format!(
                "grid origin {origin} is not finite"
            )));
        }
        if !(cell.is_finite() && cell > 0.0) {
            return Err(Error::Invalid(format!(
                "grid cell size {cell} must be a positive finite number"
            )));
        }
        if dims.min_element() == 0 {
            return Err(Error::Invalid(format!(
                "grid resolution {dims} has a zero axis; every axis needs at least 1 cell"
            )));
        }
        if dims.max_element() > MAX_AXIS_CELLS {
            let n = dims.x as u64 * dims.y as u64 * dims.z as u64;
            return Err(Error::TooLarge {
                what: format!("a {}x{}x{} grid", dims.x, dims.y, dims.z),
                needed: n.saturating_mul(8),
                available: crate::error::available_memory(),
            });
        }
        Ok(GridSpec { origin, cell, dims })
    }

    /// A grid of cubic cells around `bounds`: `resolution` cells along the longest side of the
    /// box grown by `padding` (a fraction of that longest side) on every side.
    pub fn fit(bounds: &Aabb, resolution: u32, padding: f32) -> Result<Self> {
        if resolution == 0 {
            return Err(Error::Invalid("grid resolution must be at least 1".into()));
        }
        if !(padding.is_finite() && padding >= 0.0) {
            return Err(Error::Invalid(format!(
                "grid padding {padding} must be a finite number >= 0"
            )));
        }
        if bounds.is_empty() || !bounds.min.is_finite() || !bounds.max.is_finite() {
            return Err(Error::Invalid(
                "cannot fit a grid around an empty box".into(),
            ));
        }
        let size = bounds.size();
        let longest = size.max_element().max(f32::MIN_POSITIVE * 1e6);
        let pad = padding * longest;
        let cell = (longest + 2.0 * pad) / resolution as f32;
        let dims = ((size + Vec3::splat(2.0 * pad)) / cell)
            .ceil()
            .max(Vec3::ONE)
            .as_uvec3()
            .min(UVec3::splat(resolution));
        let extent = dims.as_vec3() * cell;
        let min_corner = bounds.center() - 0.5 * extent;
        Self::new(min_corner + Vec3::splat(0.5 * cell), cell, dims)
    }

    pub fn len(&self) -> usize {
        self.dims.x as usize * self.dims.y as usize * self.dims.z as usize
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    #[inline]
    pub fn index(&self, c: UVec3) -> usize {
        c.x as usize + self.dims.x as usize * (c.y as usize + self.dims.y as usize * c.z as usize)
    }

    #[inline]
    pub fn coords(&self, index: usize) -> UVec3 {
        let nx = self.dims.x as usize;
        let ny = self.dims.y as usize;
        UVec3::new(
            (index % nx) as u32,
            ((index / nx) % ny) as u32,
            (index / (nx * ny)) as u32,
        )
    }

    #[inline]
    pub fn center(&self, c: UVec3) -> Vec3 {
        self.origin + c.as_vec3() * self.cell
    }

    /// Continuous cell coordinates: cell centres are at integers.
    #[inline]
    pub fn to_cell(&self, p: Vec3) -> Vec3 {
        (p - self.origin) / self.cell
    }

    /// The cell containing `p`, or None outside the grid.
    pub fn cell_of(&self, p: Vec3) -> Option<UVec3> {
        let c = self.to_cell(p).round().as_ivec3();
        self.contains(c).then(|| c.as_uvec3())
    }

    #[inline]
    pub fn contains(&self, c: IVec3) -> bool {
        c.cmpge(IVec3::ZERO).all() && c.cmplt(self.dims.as_ivec3()).all()
    }

    /// World box covered by the grid's cells.
    pub fn bounds(&self) -> Aabb {
        let h = Vec3::splat(0.5 * self.cell);
        Aabb {
            min: self.origin - h,
            max: self.origin + (self.dims - UVec3::ONE).as_vec3() * self.cell + h,
        }
    }

    /// Refuses, before allocating, a grid whose arrays of `bytes_per_cell` would not fit.
    pub fn check_memory(&self, what: &str, bytes_per_cell: u64) -> Result<()> {
        let n = self.dims.x as u64 * self.dims.y as u64 * self.dims.z as u64;
        check_alloc(
            &format!(
                "{what} on a {}x{}x{} grid",
                self.dims.x, self.dims.y, self.dims.z
            ),
            n.saturating_mul(bytes_per_cell),
        )
    }

    /// Refuses a grid whose cell indices do not fit 32 bits: surface cells and the field's
    /// refinement keep them as `u32` (half the memory of `usize`).
    pub fn check_cell_indices(&self, what: &str) -> Result<()> {
        if self.dims.x as u64 * self.dims.y as u64 * self.dims.z as u64 > u32::MAX as u64 {
            return Err(Error::Invalid(format!(
                "{what}: a {}x{}x{} grid has more than {} cells, the most it can index; \
                 lower the resolution",
                self.dims.x,
                self.dims.y,
                self.dims.z,
                u32::MAX
            )));
        }
        Ok(())
    }
}

/// A dense 3D array over a [`GridSpec`].
#[derive(Clone, Debug, PartialEq)]
pub struct Grid3<T> {
    pub spec: GridSpec,
    pub data: Vec<T>,
}

impl<T: Clone> Grid3<T> {
    pub fn filled(spec: GridSpec, value: T) -> Self {
        Grid3 {
            data: vec![value; spec.len()],
            spec,
        }
    }

    pub fn get(&self, c: UVec3) -> &T {
        &self.data[self.spec.index(c)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fit_is_cubic_and_covers_the_box() {
        let b = Aabb {
            min: Vec3::new(-1.0, 0.0, 2.0),
            max: Vec3::new(1.0, 0.5, 3.0),
        };
        let g = GridSpec::fit(&b, 64, 0.1).unwrap();
        assert_eq!(g.dims.x, 64);
        assert!((g.cell - 2.4 / 64.0).abs() < 1e-6);
        let gb = g.bounds();
        assert!(gb.min.cmple(b.min).all() && gb.max.cmpge(b.max).all());
        // Index and coords are inverse.
        let c = UVec3::new(3, 5, 7);
        assert_eq!(g.coords(g.index(c)), c);
    }

    #[test]
    fn bad_grids_are_refused() {
        assert!(GridSpec::new(Vec3::ZERO, 0.0, UVec3::ONE).is_err());
        assert!(GridSpec::new(Vec3::ZERO, 1.0, UVec3::new(0, 4, 4)).is_err());
        let e = GridSpec::new(Vec3::ZERO, 1.0, UVec3::splat(100_000)).unwrap_err();
        assert!(matches!(e, Error::TooLarge { .. }), "{e}");
        assert!(e.to_string().contains("100000x100000x100000"));
    }

    /// 2048 × 2048 × 1024 cells is 2^32, one past what a `u32` indexes; one layer fewer fits.
    #[test]
    fn grids_past_32_bit_cell_indices_are_refused() {
        let big = GridSpec::new(Vec3::ZERO, 1.0, UVec3::new(2048, 2048, 1024)).unwrap();
        let e = big.check_cell_indices("voxelisation").unwrap_err();
        assert!(matches!(e, Error::Invalid(_)), "{e}");
        assert!(e.to_string().contains("2048x2048x1024"), "{e}");
        let fits = GridSpec::new(Vec3::ZERO, 1.0, UVec3::new(2048, 2048, 1023)).unwrap();
        assert!(fits.check_cell_indices("voxelisation").is_ok());
    }
}
