//! The resources of H §1-2: a discrete boundary (points on a grid) and the narrow-band
//! distance field built from it.

mod bricks;

pub use bricks::FarBricks;

use crate::GridSpec;
use crate::closest::Batch;
use glam::{UVec3, Vec3, Vec4};
use rayon::prelude::*;
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::sync::{Arc, Mutex, OnceLock};

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
    /// The boundary point of each surface cell, world units. Shared (as are the faces and the
    /// inside bits) with the fields built from it: copying them was a serial pass of 48 bytes
    /// a cell per build.
    pub points: Arc<Vec<Vec3>>,
    /// The triangle (world vertices) that owns each point: the surface triangle closest to the
    /// cell centre, smallest index on ties. The field refines its distances with it.
    pub faces: Arc<Vec<[Vec3; 3]>>,
    /// Which cell centres lie inside the mesh (a bitset over the grid, [`bit`]), when the mesh
    /// is closed; `None` for an open mesh, whose inside is undefined: its field is unsigned.
    #[serde(default)]
    pub inside: Option<Arc<Vec<u32>>>,
}

/// The cells of a row of `nearest` from its first to its last band cell (None: all far).
/// Whole groups of eight cells are tested at once (a fixed-size test that vectorises; inlined,
/// so a caller compiled for AVX2 makes it one compare), the few cells past them one by one.
#[inline(always)]
pub fn band_span(row: &[u32]) -> Option<std::ops::Range<usize>> {
    let near = |n: &u32| *n != DistanceField::FAR;
    let groups = row.len() / 8;
    let group = |j: usize| -> &[u32; 8] { row[j * 8..j * 8 + 8].try_into().unwrap() };
    let far8 = |j: usize| {
        group(j)
            .iter()
            .fold(true, |all, &n| all & (n == DistanceField::FAR))
    };
    let rest = &row[groups * 8..];
    let first = match (0..groups).find(|&j| !far8(j)) {
        Some(j) => j * 8 + group(j).iter().position(near)?,
        None => groups * 8 + rest.iter().position(near)?,
    };
    let last = match rest.iter().rposition(near) {
        Some(i) => groups * 8 + i,
        // A band cell is in a group (the first one found), so some group is not far.
        None => {
            let j = (0..groups).rev().find(|&j| !far8(j))?;
            j * 8 + group(j).iter().rposition(near)?
        }
    };
    Some(first..last + 1)
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

/// The distance [`Sampling::Vector`] reads where the 8 corners are in the band: the blended
/// vector's length `len`, or, where longer, a lower bound from the corners' blended distance
/// `dist` at fraction `t` of a cell of side `cell`. Near the middle of a gap (or any medial
/// surface) the corners' vectors point to different walls and their blend is shorter than
/// either distance: 4.8 mm read where the nearer wall was 24 mm away, a false contact. Since a
/// distance changes by no more than the distance moved, each corner bounds the distance at
/// the point from below, and so does their blend less the mean corner distance, at most
/// `cell * sqrt(Σ t(1 - t))`. Near a surface the vector's length is the larger (the bound is
/// ≤ 0 on it), so a plane still reads exactly. Beyond H.
#[inline(always)]
pub fn vector_distance(len: f32, dist: f32, cell: f32, t: Vec3) -> f32 {
    let spread = t.x * (1.0 - t.x) + t.y * (1.0 - t.y) + t.z * (1.0 - t.z);
    len.max(dist - cell * spread.sqrt())
}

/// How a field is read between cell centres (H Fig. 5).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Sampling {
    /// "A": trilinear blend of the closest-point vectors, distance = its length (exact on a plane),
    /// or [`vector_distance`]'s lower bound where that is longer (near the middle of a gap).
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
pub struct LazyCells {
    cells: OnceLock<(Vec<Vec4>, FarBricks)>,
    /// A buffer of the same grid whose cells are all far, to compute into.
    spare: Mutex<Option<SpareCells>>,
    /// Every far cell's distance is exactly the far value (a built field), so the cells can
    /// go back as a spare once their band cells are reset.
    far_exact: bool,
    /// Per row of the grid (`y + ny z`), its band span `[lo, hi)` (`lo == hi`: all far), when
    /// the builder knew them: computing the cells and resetting them then skip a scan of
    /// `nearest` each (8 MiB, cold, for a 128³ grid), and so does [`DistanceField::band_cells`].
    /// Like the cells, they hold while no cell of the field changes (a clone has none).
    spans: Option<Arc<[[u32; 2]]>>,
}

/// A [`DistanceField::cells`] buffer in which every cell is far, `(0, 0, 0, -far)`: a field
/// of the same grid and band computed into it writes only its band cells. A 128³ buffer is
/// 32 MiB; a fresh one costs page faults on every frame of a moving body.
pub struct SpareCells {
    buf: Vec<Vec4>,
    far: f32,
}

impl LazyCells {
    /// The cache of a field built by the field stage (far cells hold exactly the far value),
    /// computed into `spare` when one is given; `spans` are the rows' band spans, if known
    /// (see [`band_span`]).
    pub fn built(spare: Option<SpareCells>, spans: Option<Arc<[[u32; 2]]>>) -> Self {
        LazyCells {
            cells: OnceLock::new(),
            spare: Mutex::new(spare),
            far_exact: true,
            spans,
        }
    }
}

impl Clone for LazyCells {
    fn clone(&self) -> Self {
        Self::default()
    }
}

impl std::fmt::Debug for LazyCells {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.cells.get() {
            Some((c, _)) => write!(f, "LazyCells({} computed)", c.len()),
            None => f.write_str("LazyCells(not computed)"),
        }
    }
}

impl DistanceField {
    pub const FAR: u32 = u32::MAX;

    /// An exact field from a closest-point function (for references, tests and examples):
    /// every cell whose closest surface point is within the band keeps it as its own boundary
    /// point; the others are far. Its far cells hold exactly the far value and its rows' band
    /// spans are recorded, as the field stage's are, so its [`DistanceField::cells`] are
    /// computed for the band alone (a tenth of a 128³ grid's cells at band 3).
    pub fn from_closest_points(spec: GridSpec, band: f32, closest: impl Fn(Vec3) -> Vec3) -> Self {
        let far = band * spec.cell;
        let mut dist = vec![far; spec.len()];
        let mut nearest = vec![Self::FAR; spec.len()];
        let mut points = Vec::new();
        let nx = spec.dims.x as usize;
        // Per row `[lo, hi)` of its band cells (`lo == hi`: none), as `band_span` gives them.
        let mut spans = vec![[0u32; 2]; spec.len() / nx];
        for i in 0..spec.len() {
            let x = spec.center(spec.coords(i));
            let p = closest(x);
            let d = (p - x).length();
            if d <= far {
                dist[i] = d;
                nearest[i] = points.len() as u32;
                points.push(p);
                let span = &mut spans[i / nx];
                let at = (i % nx) as u32;
                if span[0] == span[1] {
                    span[0] = at;
                }
                span[1] = at + 1;
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
            cells: LazyCells::built(None, Some(spans.into())),
        }
    }

    /// Per cell: xyz the closest-point vector (as [`DistanceField::vector`]), w the distance,
    /// negated for far cells (whose vector is zero). The layout the cloth samples and the GPU
    /// binds: a vector costs one load instead of a closest-point query (on a triangle, for a
    /// `Closest` field). Computed in parallel on first use and kept, so a field read by many
    /// substeps, frames or consumers pays once. Change no cell of a field after calling it.
    ///
    /// The triangles' closest points go a batch at a time ([`Batch`], the scalar function's
    /// bits); given a spare buffer ([`LazyCells::built`]), only the rows' band spans are
    /// written. Either way the cells are the same bits.
    pub fn cells(&self) -> &[Vec4] {
        &self.cached_cells().0
    }

    /// Where the [`DistanceField::cells`] are all plainly far (computed with them).
    pub fn far_bricks(&self) -> &FarBricks {
        &self.cached_cells().1
    }

    fn cached_cells(&self) -> &(Vec<Vec4>, FarBricks) {
        self.cells.cells.get_or_init(|| {
            let spec = &self.spec;
            let far = self.far_value();
            let spare = self
                .cells
                .spare
                .lock()
                .map(|mut s| s.take())
                .unwrap_or(None);
            let spare = spare.filter(|s| s.buf.len() == spec.len() && s.far == far);
            let far_cell = Vec4::new(0.0, 0.0, 0.0, -far);
            // A built field's band spans say where its cells can differ from far, so a fresh
            // buffer of far cells takes them as a spare would.
            let (mut out, fresh) = match spare {
                Some(s) => (s.buf, false),
                None if self.cells.far_exact && self.cells.spans.is_some() => {
                    (crate::pool::grid_vec(spec.len(), far_cell), false)
                }
                None => (bytemuck::zeroed_vec(spec.len()), true),
            };
            let (nx, ny) = (spec.dims.x as usize, spec.dims.y as usize);
            // Written into a spare, only the band cells differ from far; fresh, any may: each
            // plane's rows are scanned for them while the plane is in cache.
            let scanned: Vec<Vec<_>> = out
                .par_chunks_mut(nx * ny)
                .enumerate()
                .map(|(z, plane)| {
                    self.plane_cells(z, plane, fresh);
                    let rows = plane.chunks(nx).filter(|_| fresh);
                    rows.map(|row| bricks::not_far_span(row, far_cell))
                        .collect()
                })
                .collect();
            let spans: Vec<_> = if fresh {
                scanned.into_iter().flatten().collect()
            } else {
                (0..spec.len() / nx)
                    .map(|r| self.row_span(r, &self.nearest[r * nx..(r + 1) * nx]))
                    .collect()
            };
            let bricks = FarBricks::from_rows(spec.dims, spans.into_iter());
            (out, bricks)
        })
    }

    /// The cells of plane `z` ([`DistanceField::cells`]): every row whole when `fresh`, else
    /// only its band span (the rest already far).
    fn plane_cells(&self, z: usize, plane: &mut [Vec4], fresh: bool) {
        let spec = &self.spec;
        let (nx, ny) = (spec.dims.x as usize, spec.dims.y as usize);
        let base = z * nx * ny;
        let centre = |k: usize| spec.center(UVec3::new((k % nx) as u32, (k / nx) as u32, z as u32));
        // A batch's closest points, written as the cells' vectors.
        let put = |plane: &mut [Vec4], k: u32, q: Vec3| {
            let k = k as usize;
            plane[k] = (q - centre(k)).extend(self.dist[base + k]);
        };
        let mut batch = Batch::<u32>::default();
        for y in 0..ny {
            let row = y * nx;
            let near = &self.nearest[base + row..base + row + nx];
            let span = if fresh {
                Some(0..nx)
            } else {
                self.row_span(z * ny + y, near)
            };
            for k in span.into_iter().flatten().map(|x| row + x) {
                let d = self.dist[base + k];
                match (near[k - row], &self.faces) {
                    (Self::FAR, _) => plane[k] = Vec4::new(0.0, 0.0, 0.0, -d),
                    (n, Some(faces)) => {
                        if batch.push(centre(k), faces[n as usize], k as u32) {
                            batch.run(|k, q, _| put(plane, k, q));
                        }
                    }
                    (n, None) => plane[k] = (self.points[n as usize] - centre(k)).extend(d),
                }
            }
        }
        batch.run(|k, q, _| put(plane, k, q));
    }

    /// Takes the computed cells back as a [`SpareCells`] (their band cells reset to far), for
    /// the next field of the same grid and band; None unless computed and built.
    pub fn take_spare_cells(&mut self) -> Option<SpareCells> {
        if !self.cells.far_exact {
            return None;
        }
        let (mut buf, _) = self.cells.cells.take()?;
        let far = self.far_value();
        let (nx, ny) = (self.spec.dims.x as usize, self.spec.dims.y as usize);
        buf.par_chunks_mut(nx * ny)
            .zip(self.nearest.par_chunks(nx * ny))
            .enumerate()
            .for_each(|(z, (plane, near))| {
                let rows = plane.chunks_mut(nx).zip(near.chunks(nx));
                for (y, (cells, near)) in rows.enumerate() {
                    if let Some(span) = self.row_span(z * ny + y, near) {
                        cells[span].fill(Vec4::new(0.0, 0.0, 0.0, -far));
                    }
                }
            });
        Some(SpareCells { buf, far })
    }

    /// Per row of the grid (`y + ny z`), its band span `[lo, hi)` as the builder found it,
    /// if it did: outside its row's span every cell is far (`nearest` [`Self::FAR`], `dist`
    /// the far value), which lets the builder reset the field's buffers for the next field
    /// by writing only the spans. Holds while no cell of this field changes, as the cells do.
    pub fn band_spans(&self) -> Option<Arc<[[u32; 2]]>> {
        self.cells.spans.clone()
    }

    /// [`band_span`] of `row` (its cells' `nearest` in `near`), from the builder's spans
    /// when it gave them.
    fn row_span(&self, row: usize, near: &[u32]) -> Option<std::ops::Range<usize>> {
        match &self.cells.spans {
            Some(spans) => {
                let [lo, hi] = spans[row];
                (lo < hi).then_some(lo as usize..hi as usize)
            }
            None => band_span(near),
        }
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
        let nx = self.spec.dims.x as usize;
        let in_band = |near: &[u32]| near.iter().filter(|&&n| n != Self::FAR).count();
        match &self.cells.spans {
            // Only the rows' spans: a tenth of the grid's cells at a = 3 on 128³.
            Some(spans) => (spans.iter().enumerate())
                .map(|(row, &[lo, hi])| {
                    in_band(&self.nearest[row * nx..][lo as usize..hi as usize])
                })
                .sum(),
            None => in_band(&self.nearest),
        }
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
                distance: vector_distance(vec.length(), dist, self.spec.cell, t),
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The plain scan `band_span` must equal: first and last cell that is not far.
    fn plain_span(row: &[u32]) -> Option<std::ops::Range<usize>> {
        let first = row.iter().position(|&n| n != DistanceField::FAR)?;
        let last = row.iter().rposition(|&n| n != DistanceField::FAR)?;
        Some(first..last + 1)
    }

    #[test]
    fn band_span_is_the_plain_scans_span_for_every_length_and_place() {
        const FAR: u32 = DistanceField::FAR;
        // Rows of every length up to three groups and a few past, each all far, with one band
        // cell at each place, and with two band cells at every pair of places.
        for len in 0..30 {
            let far = vec![FAR; len];
            assert_eq!(band_span(&far), None, "all far, length {len}");
            for i in 0..len {
                for j in i..len {
                    let mut row = far.clone();
                    (row[i], row[j]) = (7, 9);
                    assert_eq!(band_span(&row), plain_span(&row), "length {len}: {i}, {j}");
                    assert_eq!(band_span(&row), Some(i..j + 1));
                }
            }
        }
        // A full grid row with band cells spread in it.
        let row: Vec<u32> = (0..128u32)
            .map(|x| if x % 37 == 5 { x } else { FAR })
            .collect();
        assert_eq!(band_span(&row), Some(5..117));
    }

    /// The rows' spans a field from closest points records are the plain scans' (`lo == hi`
    /// where a row has no band cell), and its cells, computed over those spans alone, are the
    /// bits of the cells computed over every cell (a clone's, which knows no spans), with the
    /// same far bricks and band cells.
    fn spans_and_cells_as_every_cell(field: &DistanceField) {
        let nx = field.spec.dims.x as usize;
        let spans = field.band_spans().expect("recorded");
        assert_eq!(spans.len(), field.spec.len() / nx);
        for (r, &[lo, hi]) in spans.iter().enumerate() {
            let near = &field.nearest[r * nx..(r + 1) * nx];
            let span = (lo < hi).then_some(lo as usize..hi as usize);
            assert_eq!(span, plain_span(near), "row {r}");
            assert!(lo <= hi && hi as usize <= nx, "row {r}: {lo}..{hi}");
        }
        let every = field.clone();
        assert!(every.band_spans().is_none());
        let bits = |c: &[Vec4]| {
            c.iter()
                .map(|v| v.to_array().map(f32::to_bits))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(field.cells()), bits(every.cells()));
        assert_eq!(field.band_cells(), every.band_cells());
        let d = field.spec.dims;
        for c in (0..d.x * d.y * d.z).map(|i| [i % d.x, (i / d.x) % d.y, i / (d.x * d.y)]) {
            let c = c.map(|k| k as usize);
            assert_eq!(
                field.far_bricks().all_far(c),
                every.far_bricks().all_far(c),
                "{c:?}"
            );
        }
    }

    #[test]
    fn closest_points_cells_from_the_band_spans_are_every_cells() {
        // Sides that are not whole bricks; a sphere off centre (rows with one span, rows with
        // none), a plane along whole rows, and a band of every cell (spans from 0 to nx).
        let spec = GridSpec::new(Vec3::splat(-0.5), 0.05, UVec3::new(21, 14, 19)).unwrap();
        let c = Vec3::new(0.07, -0.03, 0.11);
        let sphere = |p: Vec3| c + 0.3 * (p - c).try_normalize().unwrap_or(Vec3::X);
        spans_and_cells_as_every_cell(&DistanceField::from_closest_points(spec, 2.5, sphere));
        let plane = |p: Vec3| p.with_y(0.012);
        spans_and_cells_as_every_cell(&DistanceField::from_closest_points(spec, 3.0, plane));
        let wide = DistanceField::from_closest_points(spec, 40.0, sphere);
        assert!(wide.band_spans().unwrap().iter().all(|s| *s == [0, 21]));
        spans_and_cells_as_every_cell(&wide);
    }
}
