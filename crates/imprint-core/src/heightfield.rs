//! Height fields: a square-cell grid of heights (world y) over the x-z plane.
//!
//! Sample (i, k) sits at the centre of cell (i, k): world x = `origin.x + i * cell`,
//! z = `origin.y + k * cell`, y = `get(i, k)`. Heights are stored x fastest
//! (`heights[k * nx + i]`), so a row of the array is a line of constant z.

use crate::error::check_alloc;
use crate::{Error, Mesh, Result};
use glam::{UVec2, Vec2, Vec3};
use serde::{Deserialize, Serialize};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeightField {
    /// World (x, z) of the centre of cell (0, 0).
    pub origin: Vec2,
    /// Edge length of a (square) cell, in world units; > 0.
    pub cell: f32,
    /// Number of cells along x and z, both > 0.
    pub dims: UVec2,
    /// `dims.x * dims.y` heights, x fastest; all finite.
    pub heights: Vec<f32>,
}

impl HeightField {
    /// Builds a height field, checking that everything is finite, `cell > 0`, `dims > 0` and
    /// `heights.len() == nx * nz`.
    pub fn new(origin: Vec2, cell: f32, dims: UVec2, heights: Vec<f32>) -> Result<Self> {
        let hf = HeightField {
            origin,
            cell,
            dims,
            heights,
        };
        hf.validate()?;
        Ok(hf)
    }

    /// A field of `dims` cells, every height `f(i, k)`; refuses sizes that would not fit in
    /// memory (`Error::TooLarge`) before allocating.
    pub fn from_fn(
        origin: Vec2,
        cell: f32,
        dims: UVec2,
        mut f: impl FnMut(u32, u32) -> f32,
    ) -> Result<Self> {
        let n = Self::checked_len(dims)?;
        let mut heights = Vec::with_capacity(n);
        for k in 0..dims.y {
            for i in 0..dims.x {
                heights.push(f(i, k));
            }
        }
        Self::new(origin, cell, dims, heights)
    }

    /// A flat field at height `h`.
    pub fn constant(origin: Vec2, cell: f32, dims: UVec2, h: f32) -> Result<Self> {
        Self::from_fn(origin, cell, dims, |_, _| h)
    }

    /// `nx * nz`, refusing empty grids and sizes that would not fit in memory.
    fn checked_len(dims: UVec2) -> Result<usize> {
        if dims.x == 0 || dims.y == 0 {
            return Err(Error::Invalid(format!(
                "height field: dims must be > 0 along x and z (got {} x {})",
                dims.x, dims.y
            )));
        }
        let n = dims.x as u64 * dims.y as u64;
        let bytes = n.saturating_mul(4);
        check_alloc(&format!("a {} x {} height field", dims.x, dims.y), bytes)?;
        usize::try_from(n).map_err(|_| Error::TooLarge {
            what: format!("a {} x {} height field", dims.x, dims.y),
            needed: bytes,
            available: crate::error::available_memory(),
        })
    }

    /// Checks the invariants `new` establishes (the fields are public, so a caller may break
    /// them; writers call this before writing).
    pub fn validate(&self) -> Result<()> {
        let n = Self::checked_len(self.dims)?;
        if !(self.cell.is_finite() && self.cell > 0.0) {
            return Err(Error::Invalid(format!(
                "height field: cell size must be finite and > 0 (got {})",
                self.cell
            )));
        }
        if !self.origin.is_finite() {
            return Err(Error::Invalid(format!(
                "height field: origin must be finite (got {})",
                self.origin
            )));
        }
        if self.heights.len() != n {
            return Err(Error::Invalid(format!(
                "height field: {} x {} cells need {n} heights, got {}",
                self.dims.x,
                self.dims.y,
                self.heights.len()
            )));
        }
        if let Some(j) = self.heights.iter().position(|h| !h.is_finite()) {
            let nx = self.dims.x as usize;
            return Err(Error::Invalid(format!(
                "height field: height at cell ({}, {}) is not finite ({})",
                j % nx,
                j / nx,
                self.heights[j]
            )));
        }
        Ok(())
    }

    /// Index of cell (i, k) in `heights`.
    #[inline]
    pub fn index(&self, i: u32, k: u32) -> usize {
        debug_assert!(i < self.dims.x && k < self.dims.y);
        k as usize * self.dims.x as usize + i as usize
    }

    /// Height of cell (i, k). Panics when out of range.
    #[inline]
    pub fn get(&self, i: u32, k: u32) -> f32 {
        assert!(
            i < self.dims.x && k < self.dims.y,
            "cell ({i}, {k}) outside a {} x {} height field",
            self.dims.x,
            self.dims.y
        );
        self.heights[self.index(i, k)]
    }

    /// World position of the sample at the centre of cell (i, k).
    #[inline]
    pub fn position(&self, i: u32, k: u32) -> Vec3 {
        Vec3::new(
            self.origin.x + i as f32 * self.cell,
            self.get(i, k),
            self.origin.y + k as f32 * self.cell,
        )
    }

    /// (lowest, highest) height. Equal for a constant field.
    pub fn height_range(&self) -> (f32, f32) {
        self.heights
            .iter()
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }

    /// Volume between the field and y = 0: the sum of heights times the cell area (negative
    /// heights count negatively). Summed in f64.
    pub fn volume(&self) -> f64 {
        let area = self.cell as f64 * self.cell as f64;
        self.heights.iter().map(|&h| h as f64).sum::<f64>() * area
    }

    /// The surface through the cell centres: one vertex per cell, two triangles per quad of
    /// four neighbouring centres (wound so that faces point +y), normals from central
    /// differences of the heights (one-sided at the border; +y along a 1-cell-wide side),
    /// and uvs (u along x, v along z, 0..1 over the lattice).
    ///
    /// A field one cell wide along x or z has vertices but no triangles.
    pub fn to_mesh(&self) -> Mesh {
        let (nx, nz) = (self.dims.x, self.dims.y);
        let n = nx as usize * nz as usize;
        let mut positions = Vec::with_capacity(n);
        let mut normals = Vec::with_capacity(n);
        let mut uvs = Vec::with_capacity(n);
        let su = if nx > 1 { 1.0 / (nx - 1) as f32 } else { 0.0 };
        let sv = if nz > 1 { 1.0 / (nz - 1) as f32 } else { 0.0 };
        for k in 0..nz {
            for i in 0..nx {
                positions.push(self.position(i, k));
                uvs.push(Vec2::new(i as f32 * su, k as f32 * sv));
                let slope = |lo: u32, hi: u32, h: &dyn Fn(u32) -> f32| {
                    if hi > lo {
                        (h(hi) - h(lo)) / ((hi - lo) as f32 * self.cell)
                    } else {
                        0.0
                    }
                };
                let dx = slope(i.saturating_sub(1), (i + 1).min(nx - 1), &|ii| {
                    self.heights[self.index(ii, k)]
                });
                let dz = slope(k.saturating_sub(1), (k + 1).min(nz - 1), &|kk| {
                    self.heights[self.index(i, kk)]
                });
                normals.push(Vec3::new(-dx, 1.0, -dz).normalize_or(Vec3::Y));
            }
        }
        let quads = (nx.saturating_sub(1) as usize) * (nz.saturating_sub(1) as usize);
        let mut triangles = Vec::with_capacity(2 * quads);
        for k in 0..nz.saturating_sub(1) {
            for i in 0..nx.saturating_sub(1) {
                let a = k * nx + i;
                let b = a + 1;
                let c = a + nx;
                let d = c + 1;
                // (c - a) x (b - a) = z x x = +y.
                triangles.push([a, c, b]);
                triangles.push([b, c, d]);
            }
        }
        Mesh {
            positions,
            triangles,
            normals,
            uvs: Some(uvs),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp() -> HeightField {
        HeightField::from_fn(Vec2::new(-1.0, 2.0), 0.5, UVec2::new(4, 3), |i, k| {
            i as f32 * 0.25 + k as f32
        })
        .unwrap()
    }

    #[test]
    fn construction_validates() {
        let ok = |c: f32, d: UVec2, h: Vec<f32>| HeightField::new(Vec2::ZERO, c, d, h);
        assert!(ok(1.0, UVec2::new(2, 1), vec![0.0, 1.0]).is_ok());
        assert!(ok(0.0, UVec2::new(2, 1), vec![0.0, 1.0]).is_err());
        assert!(ok(-1.0, UVec2::new(2, 1), vec![0.0, 1.0]).is_err());
        assert!(ok(f32::NAN, UVec2::new(2, 1), vec![0.0, 1.0]).is_err());
        assert!(ok(1.0, UVec2::new(0, 1), vec![]).is_err());
        assert!(ok(1.0, UVec2::new(2, 1), vec![0.0]).is_err());
        assert!(ok(1.0, UVec2::new(2, 1), vec![0.0, f32::INFINITY]).is_err());
        assert!(HeightField::new(Vec2::new(f32::NAN, 0.0), 1.0, UVec2::ONE, vec![0.0]).is_err());
    }

    #[test]
    fn huge_sizes_are_refused_before_allocating() {
        let err = HeightField::constant(Vec2::ZERO, 1.0, UVec2::new(u32::MAX, u32::MAX), 0.0)
            .unwrap_err();
        assert!(matches!(err, Error::TooLarge { .. }), "{err}");
        assert_eq!(err.exit_code(), 2);
    }

    #[test]
    fn get_position_range_and_volume() {
        let hf = ramp();
        assert_eq!(hf.get(3, 2), 0.75 + 2.0);
        assert_eq!(hf.heights[hf.index(1, 2)], hf.get(1, 2));
        assert_eq!(hf.position(2, 1), Vec3::new(0.0, 1.5, 2.5));
        assert_eq!(hf.height_range(), (0.0, 2.75));
        // sum over i of 0.25 i = 1.5 per row, 3 rows; plus 4 * (0 + 1 + 2) = 12.
        let expected = (1.5 * 3.0 + 12.0) * 0.25;
        assert!((hf.volume() - expected).abs() < 1e-12);
        let flat = HeightField::constant(Vec2::ZERO, 2.0, UVec2::new(3, 3), -1.5).unwrap();
        assert_eq!(flat.height_range(), (-1.5, -1.5));
        assert_eq!(flat.volume(), -1.5 * 4.0 * 9.0);
    }

    #[test]
    #[should_panic]
    fn get_out_of_range_panics() {
        ramp().get(4, 0);
    }

    #[test]
    fn mesh_is_the_cell_centre_lattice_facing_up() {
        let hf = ramp();
        let m = hf.to_mesh();
        assert_eq!(m.positions.len(), 12);
        assert_eq!(m.triangles.len(), 2 * 3 * 2);
        m.validate("ramp").unwrap();
        for t in 0..m.triangles.len() {
            let [a, b, c] = m.triangle(t);
            let n = (b - a).cross(c - a);
            assert!(n.y > 0.0, "triangle {t} faces down");
        }
        // The ramp is a plane: every normal is the plane's normal.
        let plane_n = Vec3::new(-0.25 / 0.5, 1.0, -1.0 / 0.5).normalize();
        for n in &m.normals {
            assert!((*n - plane_n).length() < 1e-6, "{n} vs {plane_n}");
        }
        let uvs = m.uvs.as_ref().unwrap();
        assert_eq!(uvs[0], Vec2::ZERO);
        assert_eq!(uvs[11], Vec2::ONE);
        // Total area of the mesh matches the tilted plane over the lattice.
        let projected = (3.0 * 0.5) * (2.0 * 0.5);
        let area = projected / plane_n.y as f64;
        assert!((m.surface_area() - area).abs() < 1e-5);
    }

    #[test]
    fn thin_fields_mesh_without_triangles() {
        let hf = HeightField::constant(Vec2::ZERO, 1.0, UVec2::new(5, 1), 2.0).unwrap();
        let m = hf.to_mesh();
        assert_eq!(m.positions.len(), 5);
        assert!(m.triangles.is_empty());
        assert!(m.normals.iter().all(|&n| n == Vec3::Y));
    }
}
