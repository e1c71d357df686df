//! The resources of H §1-2: a discrete boundary (points on a grid) and the narrow-band
//! distance field built from it.

use crate::GridSpec;
use glam::{UVec3, Vec3, Vec4};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, OnceLock};

/// Which point stands for a surface cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, JsonSchema)]
pub enum BoundaryVariant {
    /// H's discrete boundary: the cell centre (accurate only to a cell).
    Centre,
    /// Ours: the point of the surface closest to the cell centre (sub-voxel accurate).
    #[default]
    Closest,
}

/// One point per surface cell, cells in increasing linear index (so the order, and every
/// tie-break that depends on it, is the same on every backend and thread count).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Boundary {
    pub spec: GridSpec,
    pub variant: BoundaryVariant,
    /// Linear indices of the surface cells, strictly increasing.
    pub cells: Vec<u32>,
    /// The boundary point of each surface cell, world units.
    pub points: Vec<Vec3>,
    /// The triangle (world vertices) that owns each point: the surface triangle closest to the
    /// cell centre, smallest index on ties. The field refines its distances with it.
    pub faces: Vec<[Vec3; 3]>,
    /// Which cell centres lie inside the mesh (a bitset over the grid, [`bit`]), when the mesh
    /// is closed; `None` for an open mesh, whose inside is undefined: its field is unsigned.
    #[serde(default)]
    pub inside: Option<Vec<u32>>,
}

/// Bit `i` of a bitset stored as 32-bit words (bit `i % 32` of word `i / 32`).
#[inline(always)]
pub fn bit(words: &[u32], i: usize) -> bool {
    words[i / 32] >> (i % 32) & 1 == 1
}

impl Boundary {
    pub fn len(&self) -> usize {
        self.cells.len()
    }
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }
}

/// How a field is read between cell centres (H Fig. 5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Sampling {
    /// "A": trilinear blend of the closest-point vectors, distance = its length (exact on a plane).
    #[default]
    Vector,
    /// "B": trilinear blend of the distances (not exact: distance is not linear between cells).
    Distance,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldSample {
    pub distance: f32,
    /// Toward the closest boundary point (p - x); zero when unknown.
    pub vector: Vec3,
    /// False when any of the 8 cells around the point is far (outside the band or the grid).
    pub in_band: bool,
}

/// A narrow-band unsigned distance field: per cell, which boundary point is nearest within
/// `band` cells, and the distance. Cells farther than the band are "far": their distance is
/// clamped to `far_value()` and their `nearest` is [`DistanceField::FAR`].
///
/// With `faces` (built from a `Closest` boundary) the distance and vector of a cell go to the
/// closest point of the triangle that owns its nearest boundary point, not to the point itself:
/// one point per cell misses ridges and tight curves by up to half a cell, the triangle does not.
///
/// Serde writes everything but the lazily computed [`DistanceField::cells`], which a loaded
/// field computes again on first use (the same values: they depend on the other fields only).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct DistanceField {
    pub spec: GridSpec,
    /// Half-width of the band, in cells (H's `a`).
    pub band: f32,
    /// Distance per cell, world units.
    pub dist: Vec<f32>,
    /// Index into `points` of the nearest boundary point, or `FAR`.
    pub nearest: Vec<u32>,
    /// The boundary points the field was built from.
    pub points: Arc<Vec<Vec3>>,
    /// The owning triangle of each point, when distances are refined to the triangles.
    pub faces: Option<Arc<Vec<[Vec3; 3]>>>,
    /// Which cell centres lie inside the body (a bitset, [`bit`]): the field is *signed*. `None`
    /// for an open mesh: unsigned, and a consumer must guess the side (see the cloth's contact).
    #[serde(default)]
    pub inside: Option<Arc<Vec<u32>>>,
    /// [`DistanceField::cells`], once asked for (write `Default::default()` when building).
    /// Not serialised: a cache of the fields above, empty after loading.
    #[serde(skip)]
    pub cells: LazyCells,
}

/// The per-cell vectors of a [`DistanceField`], computed on first use (see
/// [`DistanceField::cells`]). A clone starts empty again: the clone may be changed.
#[derive(Default)]
pub struct LazyCells(OnceLock<Vec<Vec4>>);

impl Clone for LazyCells {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for LazyCells {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.0.get() {
            Some(c) => write!(f, "LazyCells({} computed)", c.len()),
            None => f.write_str("LazyCells(not computed)"),
        }
    }
}

impl DistanceField {
    pub const FAR: u32 = u32::MAX;

    /// An exact field from a closest-point function (for references, tests and examples):
    /// every cell whose closest surface point is within the band keeps it as its own boundary
    /// point; the others are far.
    pub fn from_closest_points(spec: GridSpec, band: f32, closest: impl Fn(Vec3) -> Vec3) -> Self {
        let far = band * spec.cell;
        let mut dist = vec![far; spec.len()];
        let mut nearest = vec![Self::FAR; spec.len()];
        let mut points = Vec::new();
        for i in 0..spec.len() {
            let x = spec.center(spec.coords(i));
            let p = closest(x);
            let d = (p - x).length();
            if d <= far {
                dist[i] = d;
                nearest[i] = points.len() as u32;
                points.push(p);
            }
        }
        DistanceField {
            spec,
            band,
            dist,
            nearest,
            points: Arc::new(points),
            faces: None,
            inside: None,
            cells: Default::default(),
        }
    }

    /// Per cell: xyz the closest-point vector (as [`DistanceField::vector`]), w the distance,
    /// negated for far cells (whose vector is zero). The layout the cloth samples and the GPU
    /// binds: a vector costs one load instead of a closest-point query (on a triangle, for a
    /// `Closest` field). Computed in parallel on first use and kept, so a field read by many
    /// substeps, frames or consumers pays once. Change no cell of a field after calling it.
    pub fn cells(&self) -> &[Vec4] {
        self.cells.0.get_or_init(|| {
            let spec = &self.spec;
            let (nx, ny) = (spec.dims.x as usize, spec.dims.y as usize);
            let mut out = vec![Vec4::ZERO; spec.len()];
            out.par_chunks_mut(nx * ny)
                .enumerate()
                .for_each(|(z, plane)| {
                    for y in 0..ny {
                        for x in 0..nx {
                            let c = UVec3::new(x as u32, y as u32, z as u32);
                            let i = spec.index(c);
                            plane[y * nx + x] = match self.nearest[i] {
                                Self::FAR => Vec4::new(0.0, 0.0, 0.0, -self.dist[i]),
                                n => {
                                    let centre = spec.center(c);
                                    (self.closest_point(n as usize, centre) - centre)
                                        .extend(self.dist[i])
                                }
                            };
                        }
                    }
                });
            out
        })
    }

    /// The linear blend of two fields of the same grid and band at weight `s` (0: `a`, 1:
    /// `b`): what a body between two builds looks like (H eq. 13-14). Per cell, the distance
    /// is `a + (b - a) s` exactly and the closest-point vector is blended the same way (the
    /// cell's blended closest point becomes its own boundary point); cells far in both stay
    /// far. When both fields are signed, the *signed* distances are blended (a cell the surface
    /// passed between the builds is inside where the blend is negative, and its distance is
    /// the blend's size, which is what the blended vector measures too).
    pub fn blend(a: &DistanceField, b: &DistanceField, s: f32) -> crate::Result<DistanceField> {
        if a.spec != b.spec || a.band != b.band {
            return Err(crate::Error::Invalid(format!(
                "cannot blend fields of different grids or bands ({:?}, band {} vs {:?}, band {})",
                a.spec, a.band, b.spec, b.band
            )));
        }
        let spec = a.spec;
        let (ca, cb) = (a.cells(), b.cells());
        let signed = a.inside.is_some() && b.inside.is_some();
        let blended: Vec<(f32, Option<Vec3>)> = (0..spec.len())
            .into_par_iter()
            .map(|i| {
                let d = if signed {
                    let (sa, sb) = (a.signed_distance(i), b.signed_distance(i));
                    sa + (sb - sa) * s
                } else {
                    a.dist[i] + (b.dist[i] - a.dist[i]) * s
                };
                if a.is_far(i) && b.is_far(i) {
                    return (d, None);
                }
                let (va, vb) = (ca[i].truncate(), cb[i].truncate());
                (d, Some(spec.center(spec.coords(i)) + va + (vb - va) * s))
            })
            .collect();
        let mut points = Vec::new();
        let mut nearest = Vec::with_capacity(spec.len());
        let mut dist = Vec::with_capacity(spec.len());
        let mut inside = signed.then(|| vec![0u32; spec.len().div_ceil(32)]);
        for (i, (d, p)) in blended.into_iter().enumerate() {
            if let Some(words) = &mut inside
                && d < 0.0
            {
                words[i / 32] |= 1 << (i % 32);
            }
            dist.push(d.abs());
            nearest.push(match p {
                Some(p) => {
                    points.push(p);
                    (points.len() - 1) as u32
                }
                None => Self::FAR,
            });
        }
        Ok(DistanceField {
            spec,
            band: a.band,
            dist,
            nearest,
            points: Arc::new(points),
            faces: None,
            inside: inside.map(Arc::new),
            cells: Default::default(),
        })
    }

    /// Whether cell `index`'s centre is inside the body: `None` for an unsigned field.
    #[inline]
    pub fn is_inside(&self, index: usize) -> Option<bool> {
        self.inside.as_deref().map(|w| bit(w, index))
    }

    /// The distance of cell `index`, negative inside (the distance itself when unsigned).
    #[inline]
    pub fn signed_distance(&self, index: usize) -> f32 {
        match self.is_inside(index) {
            Some(true) => -self.dist[index],
            _ => self.dist[index],
        }
    }

    /// The trilinear blend of the cells' signed distances at `p` (far cells count as the band's
    /// edge, with their sign): negative inside, to within the curvature of the surface over a
    /// cell (exact for a plane). In the grid's outermost half cell, the nearest cell's; beyond
    /// the grid, outside (the grid holds the body). `None` for an unsigned field.
    pub fn side(&self, p: Vec3) -> Option<f32> {
        self.inside.as_ref()?;
        let c = self.spec.to_cell(p);
        let b = c.floor().as_ivec3();
        let t = c - c.floor();
        if b.cmplt(glam::IVec3::ZERO).any() || (b + 1).cmpge(self.spec.dims.as_ivec3()).any() {
            let cl = c.round().as_ivec3();
            return Some(if self.spec.contains(cl) {
                self.signed_distance(self.spec.index(cl.as_uvec3()))
            } else {
                self.far_value()
            });
        }
        let mut sd = 0.0;
        for k in 0..8u32 {
            let o = UVec3::new(k & 1, (k >> 1) & 1, (k >> 2) & 1);
            let w = (if o.x == 1 { t.x } else { 1.0 - t.x })
                * (if o.y == 1 { t.y } else { 1.0 - t.y })
                * (if o.z == 1 { t.z } else { 1.0 - t.z });
            sd += w * self.signed_distance(self.spec.index(b.as_uvec3() + o));
        }
        Some(sd)
    }

    /// The distance stored in far cells: the band's half-width in world units.
    pub fn far_value(&self) -> f32 {
        self.band * self.spec.cell
    }

    #[inline]
    pub fn is_far(&self, index: usize) -> bool {
        self.nearest[index] == Self::FAR
    }

    /// Closest-point vector of a cell (toward the surface), zero for far cells.
    #[inline]
    pub fn vector(&self, index: usize) -> Vec3 {
        match self.nearest[index] {
            Self::FAR => Vec3::ZERO,
            n => {
                self.closest_point(n as usize, self.spec.center(self.spec.coords(index)))
                    - self.spec.center(self.spec.coords(index))
            }
        }
    }

    /// The point boundary point `n` stands for as seen from `x`: itself, or with faces the
    /// closest point of its triangle to `x`.
    #[inline]
    pub fn closest_point(&self, n: usize, x: Vec3) -> Vec3 {
        match &self.faces {
            Some(f) => {
                let [a, b, c] = f[n];
                crate::geom::closest_point_on_triangle(x, a, b, c)
            }
            None => self.points[n],
        }
    }

    /// Number of cells inside the band.
    pub fn band_cells(&self) -> usize {
        self.nearest.iter().filter(|&&n| n != Self::FAR).count()
    }

    /// The field at any point, by trilinear interpolation of the 8 surrounding cells.
    pub fn sample(&self, p: Vec3, mode: Sampling) -> FieldSample {
        let far = FieldSample {
            distance: self.far_value(),
            vector: Vec3::ZERO,
            in_band: false,
        };
        let c = self.spec.to_cell(p);
        let base = c.floor();
        let t = c - base;
        let b = base.as_ivec3();
        let dims = self.spec.dims.as_ivec3();
        if b.cmplt(glam::IVec3::ZERO).any() || (b + 1).cmpge(dims).any() {
            // Outside the grid, or in its outermost half cell: clamp to the nearest cell.
            let cl = c.round().as_ivec3();
            if !self.spec.contains(cl) {
                return far;
            }
            let i = self.spec.index(cl.as_uvec3());
            return FieldSample {
                distance: self.dist[i],
                vector: self.vector(i),
                in_band: !self.is_far(i),
            };
        }
        let mut dist = 0.0;
        let mut vec = Vec3::ZERO;
        let mut all_in = true;
        for k in 0..8u32 {
            let o = UVec3::new(k & 1, (k >> 1) & 1, (k >> 2) & 1);
            let w = (if o.x == 1 { t.x } else { 1.0 - t.x })
                * (if o.y == 1 { t.y } else { 1.0 - t.y })
                * (if o.z == 1 { t.z } else { 1.0 - t.z });
            let i = self.spec.index(b.as_uvec3() + o);
            all_in &= !self.is_far(i);
            dist += w * self.dist[i];
            vec += w * self.vector(i);
        }
        match mode {
            Sampling::Vector if all_in => FieldSample {
                distance: vec.length(),
                vector: vec,
                in_band: true,
            },
            _ => FieldSample {
                distance: dist,
                vector: vec,
                in_band: all_in,
            },
        }
    }
}
