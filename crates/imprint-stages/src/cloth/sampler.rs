//! Reading a distance field at a particle, fast, with the same numbers as
//! `DistanceField::sample(p, Sampling::Vector)` (unit tests hold it to that).
//!
//! The field stores per cell a distance and the index of its nearest boundary point; the
//! closest-point vector is derived from them (point minus cell centre, or the closest point
//! of the owning triangle, which is costly). The cloth reads 8 cells per particle per field
//! per substep, so it reads [`DistanceField::cells`] instead: one `Vec4` per cell (xyz the
//! vector, w the distance, negated for far cells), computed once per field and kept with it,
//! so a static body's field costs nothing after its first frame and a moving body's field
//! is computed once though the cloth reads it in two frames (as the end, then the start).
//! Reads in the grid's outermost half cell or outside it take the field's own code.

use super::lanes::{LANES, lane_bits, lanes_of, mask};
use glam::{IVec3, UVec3, Vec3, Vec3A, Vec4};
use imprint_core::field::{FarBricks, vector_distance};
use imprint_core::{DistanceField, FieldSample, Sampling};

/// A field and its cells, looked up once per frame.
#[derive(Clone, Copy)]
pub struct FieldView<'a> {
    pub field: &'a DistanceField,
    cells: &'a [Vec4],
    /// Where the cells are all plainly far: reads there load none.
    far_bricks: &'a FarBricks,
    /// The field's inside bits, when it is signed.
    signs: Option<&'a [u32]>,
    dims: IVec3,
}

/// The eight cells around each of [`LANES`] particles as [`FieldView::sample_lanes`] last
/// read them from one field, by component, corner and lane. A particle moves a fraction of a
/// cell in a substep, so most reads find their cells here and load none from the field (a
/// 128³ field's cells are 32 MiB, read at scattered places, and moving them into lanes cost
/// a store per value). Good for one field while it does not change: [`Corners::forget`]
/// before a read of another, or of the same after it changed.
#[derive(Clone, Debug)]
pub struct Corners {
    /// Per axis and lane, the cell the lane's corners start at; [`Corners::NONE`]: none held
    /// (a read's cells are never negative).
    base: [[i32; LANES]; 3],
    cells: [[[f32; LANES]; 8]; 4],
}

impl Default for Corners {
    fn default() -> Self {
        Corners {
            base: [[Self::NONE; LANES]; 3],
            cells: [[[0.0; LANES]; 8]; 4],
        }
    }
}

impl Corners {
    const NONE: i32 = i32::MIN;

    /// Drops what is held: the next read loads every lane's cells.
    pub fn forget(&mut self) {
        self.base = [[Self::NONE; LANES]; 3];
    }
}

/// Where [`LANES`] points (`p[axis][lane]`) fall in one field's grid, worked out once for
/// both [`FieldView::lanes_far`] and [`FieldView::sample_lanes`].
#[derive(Clone, Copy, Debug)]
pub struct CellLanes {
    /// The coordinates' floor (exact below 2^24, as `cell_coords`) clamped to the grid, as
    /// integers (where `inner`, the floor itself).
    i: [[i32; LANES]; 3],
    /// The fraction within the cell.
    t: [[f32; LANES]; 3],
    /// All ones where all eight cells of a read are in the grid, else zero (a lane mask).
    inner: [u32; LANES],
    /// All ones where the floor is off the grid by a cell or more (`read` gives the far
    /// sample), else zero.
    off: [u32; LANES],
}

/// A sample and, for a signed field, the blend of the cells' signed distances
/// ([`DistanceField::side`]): negative inside.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Read {
    pub sample: FieldSample,
    pub side: Option<f32>,
}

impl<'a> FieldView<'a> {
    /// Computes the field's cells if no one has yet.
    pub fn new(field: &'a DistanceField) -> Self {
        FieldView {
            field,
            cells: field.cells(),
            far_bricks: field.far_bricks(),
            signs: field.inside.as_deref().map(|w| w.as_slice()),
            dims: field.spec.dims.as_ivec3(),
        }
    }

    /// Whether the field knows inside from outside (see [`Read::side`]).
    pub fn is_signed(&self) -> bool {
        self.signs.is_some()
    }

    /// [`FieldView::sample`] at [`LANES`] points (`p[axis][lane]`, their cells `c` from
    /// [`FieldView::cell_lanes`]), lane by lane the same bits: the distances, the
    /// closest-point vectors and whether in the band. The lanes' weights and blends are
    /// computed side by side (loops over the lanes, which vectorise); one particle at a time,
    /// each read was a chain of dependent steps (a division, the cell's index, its loads, eight
    /// additions in order, a square root) that left the processor waiting. Lanes whose cells
    /// are not all inside the grid take [`FieldView::sample`]. `corners` holds the lanes'
    /// cells from the last read of this field (see [`Corners`]): a lane still in the same cell
    /// loads nothing, and which lanes load is found for all lanes at once (a branch per lane
    /// missed as often as the cloth jitters across cell faces).
    #[inline(always)]
    // A lane indexes the cells, the held corners and the outputs alike.
    #[allow(clippy::type_complexity, clippy::needless_range_loop)]
    pub fn sample_lanes(
        &self,
        p: &[[f32; LANES]; 3],
        c: &CellLanes,
        corners: &mut Corners,
    ) -> ([f32; LANES], [[f32; LANES]; 3], [bool; LANES]) {
        let t = &c.t;
        // Lane masks (all ones or zero), which vectorise where bools do not.
        let mut held = [u32::MAX; LANES];
        for a in 0..3 {
            for m in 0..LANES {
                held[m] &= mask(corners.base[a][m] == c.i[a][m]);
            }
        }
        let mut need = [0u32; LANES];
        for m in 0..LANES {
            need[m] = c.inner[m] & !held[m];
        }
        let (nx, nxy) = (self.dims.x as usize, (self.dims.x * self.dims.y) as usize);
        let far = -self.field.far_value();
        for m in lanes_of(lane_bits(&need)) {
            let base = [0, 1, 2].map(|a| c.i[a][m] as usize);
            (0..3).for_each(|a| corners.base[a][m] = c.i[a][m]);
            let i0 = base[0] + nx * base[1] + nxy * base[2];
            let cells = &mut corners.cells;
            if self.far_bricks.all_far(base) {
                // The cells are (0, 0, 0, -far): the values, not loaded.
                for (a, comp) in cells.iter_mut().enumerate() {
                    let v = if a == 3 { far } else { 0.0 };
                    comp.iter_mut().for_each(|corner| corner[m] = v);
                }
                continue;
            }
            for k in 0..8 {
                let c = self.cells[i0 + (k & 1) + nx * ((k >> 1) & 1) + nxy * (k >> 2)];
                for (a, comp) in cells.iter_mut().enumerate() {
                    comp[k][m] = c[a];
                }
            }
        }
        // The field's weights in its order, and the blends, corner after corner.
        let (mut v, mut dist) = ([[0.0f32; LANES]; 3], [0.0f32; LANES]);
        let mut far = [0u32; LANES];
        let [cx, cy, cz, cw] = &corners.cells;
        for k in 0..8 {
            for m in 0..LANES {
                let wx = if k & 1 == 1 { t[0][m] } else { 1.0 - t[0][m] };
                let wy = if (k >> 1) & 1 == 1 {
                    t[1][m]
                } else {
                    1.0 - t[1][m]
                };
                let wz = if k >> 2 == 1 { t[2][m] } else { 1.0 - t[2][m] };
                let w = wx * wy * wz;
                v[0][m] += w * cx[k][m];
                v[1][m] += w * cy[k][m];
                v[2][m] += w * cz[k][m];
                dist[m] += w * cw[k][m].abs();
                far[m] |= mask(cw[k][m] < 0.0);
            }
        }
        // In the band: the vector's length or the bound (`finish`); at its edge: the blend of
        // distances. Into a new array: selected in place, it compiled to a masked store, which
        // on AMD processors takes many cycles.
        let cell = self.field.spec.cell;
        let mut distance = [0.0f32; LANES];
        for m in 0..LANES {
            let len = (v[0][m] * v[0][m] + v[1][m] * v[1][m] + v[2][m] * v[2][m]).sqrt();
            let t = Vec3::new(t[0][m], t[1][m], t[2][m]);
            let inside = vector_distance(len, dist[m], cell, t);
            distance[m] = if far[m] != 0 { dist[m] } else { inside };
        }
        let mut dist = distance;
        let mut in_band = [false; LANES];
        for m in 0..LANES {
            in_band[m] = far[m] == 0;
        }
        for m in lanes_of(!lane_bits(&c.inner) & ((1 << LANES) - 1)) {
            let f = self.sample(Vec3::new(p[0][m], p[1][m], p[2][m]));
            (dist[m], in_band[m]) = (f.distance, f.in_band);
            for (a, v) in v.iter_mut().enumerate() {
                v[m] = f.vector[a];
            }
        }
        (dist, v, in_band)
    }

    /// Whether every one of the [`LANES`] points (their cells `c`) reads plainly far: off
    /// the grid by a cell or more, or among cells that are all far ([`FarBricks`]). Such a
    /// read has no vector and is not in the band, so no contact can come of it; this costs
    /// a few operations per lane, where [`FieldView::sample_lanes`] loads eight cells.
    #[inline(always)]
    pub fn lanes_far(&self, c: &CellLanes) -> bool {
        // Lanes off the grid are far; of the others, one at the grid's edge is not
        // (`read_outside` blends real cells), and the rest are far in far bricks (`i` is
        // clamped to the grid, so every lane has one).
        let on = !lane_bits(&c.off) & ((1 << LANES) - 1);
        on & !lane_bits(&c.inner) == 0 && self.far_bricks.all_far_lanes(&c.i, on)
    }

    /// The lanes' cells (`p[axis][lane]`): their coordinates' floor (exact below 2^24, as
    /// `cell_coords`), the fraction, whether all eight cells of a read are in the grid, and
    /// whether the floor is off it by a cell or more.
    #[inline(always)]
    // A lane indexes the positions and every output alike.
    #[allow(clippy::needless_range_loop)]
    pub fn cell_lanes(&self, p: &[[f32; LANES]; 3]) -> CellLanes {
        let spec = &self.field.spec;
        let (origin, cell) = (spec.origin.to_array(), spec.cell);
        let dims = self.dims.to_array().map(|d| d as f32);
        let mut c = CellLanes {
            i: [[0; LANES]; 3],
            t: [[0.0; LANES]; 3],
            inner: [0; LANES],
            off: [0; LANES],
        };
        // Per axis, then combined: `inner &= mask` in the loop below compiled to a masked
        // store, which on AMD processors takes many cycles.
        let (mut inside, mut off) = ([[0u32; LANES]; 3], [[0u32; LANES]; 3]);
        for a in 0..3 {
            for m in 0..LANES {
                let x = (p[a][m] - origin[a]) / cell;
                let b = x.floor();
                c.t[a][m] = x - b;
                inside[a][m] = mask((b >= 0.0) & (b + 1.0 < dims[a]));
                off[a][m] = mask((b < -1.0) | (b >= dims[a]));
                // SAFETY: clamped to [0, dims − 1] (NaN to 0 by `max`), which an i32 holds:
                // the plain conversion, which saturates, is one scalar call per lane.
                c.i[a][m] = unsafe { b.max(0.0).min(dims[a] - 1.0).to_int_unchecked::<i32>() };
            }
        }
        for m in 0..LANES {
            c.inner[m] = inside[0][m] & inside[1][m] & inside[2][m];
            c.off[m] = off[0][m] | off[1][m] | off[2][m];
        }
        c
    }

    /// The field at `p`, as `Sampling::Vector` reads it.
    #[inline(always)]
    pub fn sample(&self, p: Vec3) -> FieldSample {
        self.read(p).sample
    }

    /// The field at `p`, as `Sampling::Vector` reads it, with the side when it is signed.
    #[inline(always)]
    pub fn read(&self, p: Vec3) -> Read {
        let spec = &self.field.spec;
        let (b, t) = cell_coords(spec, p);
        if b.cmplt(IVec3::ZERO).any() || (b + 1).cmpge(self.dims).any() {
            if b.cmplt(IVec3::splat(-1)).any() || b.cmpge(self.dims).any() {
                // A cell or more outside the grid, where most of a cloth larger than the
                // field is: the field's nearest cell is off the grid too, so it reads far.
                return self.far();
            }
            return read_outside(self.field, p);
        }
        let (nx, nxy) = (self.dims.x as usize, (self.dims.x * self.dims.y) as usize);
        let i0 = b.x as usize + nx * b.y as usize + nxy * b.z as usize;
        // The field's weights, multiplied in its order; corners x-pairs at 4 (y, z) rows.
        let (wx, wy, wz) = ([1.0 - t.x, t.x], [1.0 - t.y, t.y], [1.0 - t.z, t.z]);
        let cells = self.cells;
        let mut corners = [Vec4::ZERO; 8];
        let mut weights = [0.0f32; 8];
        for yz in 0..4 {
            let row = i0 + nx * (yz & 1) + nxy * (yz >> 1);
            let pair = &cells[row..row + 2];
            for x in 0..2 {
                corners[2 * yz + x] = pair[x];
                weights[2 * yz + x] = wx[x] * wy[yz & 1] * wz[yz >> 1];
            }
        }
        // xyz: the blended vector, lane by lane as the field adds it; w unused here.
        let mut acc = Vec4::ZERO;
        let (mut far, mut dist) = (false, 0.0);
        for k in 0..8 {
            acc += weights[k] * corners[k];
            far |= corners[k].w < 0.0;
            dist += weights[k] * corners[k].w.abs();
        }
        let vec = acc.truncate();
        // The signed distance in the field's order of corners (as `DistanceField::side`).
        let side = self.signs.map(|words| {
            let mut sd = 0.0;
            for k in 0..8 {
                let i = i0 + (k & 1) + nx * ((k >> 1) & 1) + nxy * (k >> 2);
                let d = corners[k].w.abs();
                sd += weights[k]
                    * if imprint_core::field::bit(words, i) {
                        -d
                    } else {
                        d
                    };
            }
            sd
        });
        Read {
            sample: finish(dist, vec, !far, spec.cell, t),
            side,
        }
    }

    /// What the field reads off its grid (`DistanceField::sample` and `side` there).
    #[inline(always)]
    fn far(&self) -> Read {
        let far = self.field.far_value();
        Read {
            sample: FieldSample {
                distance: far,
                vector: Vec3::ZERO,
                in_band: false,
            },
            side: self.signs.map(|_| far),
        }
    }
}

/// `spec.to_cell(p)`, its floor as integers, and the fraction: the field's arithmetic
/// (`(p - origin) / cell`, lane by lane, so the same bits), but four lanes at a time and
/// without the library call `floorf` is on x86-64 (SSE2 has no rounding instruction).
/// Exact wherever a grid can be indexed (|c| < 2^24).
#[inline(always)]
fn cell_coords(spec: &imprint_core::GridSpec, p: Vec3) -> (IVec3, Vec3) {
    let c = (Vec3A::from(p) - Vec3A::from(spec.origin)) / Vec3A::splat(spec.cell);
    let i = c.as_ivec3();
    let t = i.as_vec3a();
    let floor = Vec3A::select(t.cmpgt(c), t - Vec3A::ONE, t);
    let b = IVec3::new(
        if t.x > c.x {
            i.x.saturating_sub(1)
        } else {
            i.x
        },
        if t.y > c.y {
            i.y.saturating_sub(1)
        } else {
            i.y
        },
        if t.z > c.z {
            i.z.saturating_sub(1)
        } else {
            i.z
        },
    );
    (b, (c - floor).into())
}

/// A sample from its blended distance and vector at fraction `t` of a cell of side `cell`.
#[inline(always)]
fn finish(dist: f32, vec: Vec3, all_in: bool, cell: f32, t: Vec3) -> FieldSample {
    if all_in {
        FieldSample {
            distance: vector_distance(vec.length(), dist, cell, t),
            vector: vec,
            in_band: true,
        }
    } else {
        FieldSample {
            distance: dist,
            vector: vec,
            in_band: false,
        }
    }
}

/// Reads outside the cached box: the slow path, kept out of line so that the cached read
/// stays small enough to inline into the particle loop.
#[cold]
#[inline(never)]
fn read_outside(field: &DistanceField, p: Vec3) -> Read {
    Read {
        sample: sample_vector(field, p),
        side: field.side(p),
    }
}

/// Samples `field` at `p` as [`Sampling::Vector`] does, without the cache: the field's own
/// arithmetic, minus its per-corner integer divisions (cell index → coordinates → centre).
#[inline]
pub fn sample_vector(field: &DistanceField, p: Vec3) -> FieldSample {
    let spec = &field.spec;
    let (b, t) = cell_coords(spec, p);
    let dims = spec.dims.as_ivec3();
    if b.cmplt(IVec3::ZERO).any() || (b + 1).cmpge(dims).any() {
        // Outside the grid or in its outermost half cell: rare, the field's own code.
        return field.sample(p, Sampling::Vector);
    }
    let bu = b.as_uvec3();
    let (nx, nxy) = (
        spec.dims.x as usize,
        spec.dims.x as usize * spec.dims.y as usize,
    );
    let i0 = spec.index(bu);
    let mut all_in = true;
    let mut dist = 0.0;
    let mut vec = Vec3::ZERO;
    for k in 0..8u32 {
        let o = UVec3::new(k & 1, (k >> 1) & 1, (k >> 2) & 1);
        let w = (if o.x == 1 { t.x } else { 1.0 - t.x })
            * (if o.y == 1 { t.y } else { 1.0 - t.y })
            * (if o.z == 1 { t.z } else { 1.0 - t.z });
        let i = i0 + o.x as usize + nx * o.y as usize + nxy * o.z as usize;
        dist += w * field.dist[i];
        match field.nearest[i] {
            DistanceField::FAR => all_in = false,
            n => {
                let centre = spec.center(bu + o);
                vec += w * (field.closest_point(n as usize, centre) - centre);
            }
        }
    }
    finish(dist, vec, all_in, spec.cell, t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::GridSpec;
    use imprint_core::mesh::primitives;

    /// Equal as numbers (a zero's sign may differ: far corners add +0 here, nothing there).
    fn assert_same(a: FieldSample, b: FieldSample, p: Vec3) {
        assert_eq!(a.in_band, b.in_band, "{p}");
        assert!(
            a.distance == b.distance,
            "{p}: {} vs {}",
            a.distance,
            b.distance
        );
        assert!(a.vector == b.vector, "{p}: {} vs {}", a.vector, b.vector);
    }

    fn points() -> impl Iterator<Item = Vec3> {
        (0..4000u64).map(|i| {
            let h = |k: u64| {
                let v = (i * 3 + k + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                (v >> 40) as f32 / (1u64 << 24) as f32
            };
            Vec3::new(h(0), h(1), h(2)) * 1.4 - Vec3::splat(0.7)
        })
    }

    fn check(f: &DistanceField) {
        let view = FieldView::new(f);
        for p in points() {
            let want = f.sample(p, Sampling::Vector);
            assert_same(sample_vector(f, p), want, p);
            assert_same(view.sample(p), want, p);
            assert_eq!(view.read(p).side, f.side(p), "{p}");
        }
        // The cells are the field's vectors and distances.
        for i in (0..f.spec.len()).step_by(7) {
            let c = f.cells()[i];
            assert_eq!(c.truncate(), f.vector(i));
            assert_eq!(c.w.abs(), f.dist[i]);
            assert_eq!(c.w < 0.0, f.is_far(i));
        }
    }

    #[test]
    fn same_numbers_as_the_field_with_points() {
        let spec = GridSpec::new(Vec3::splat(-0.5), 0.05, UVec3::splat(21)).unwrap();
        check(&DistanceField::from_closest_points(spec, 3.0, |p| {
            0.3 * p.normalize_or(Vec3::X)
        }));
    }

    #[test]
    fn same_numbers_as_the_field_with_faces() {
        let mesh = primitives::uv_sphere(0.3, 16, 8);
        let spec = GridSpec::new(Vec3::splat(-0.5), 0.05, UVec3::splat(21)).unwrap();
        let b = crate::voxel::voxelize_cpu(&mesh, &spec, imprint_core::BoundaryVariant::Closest)
            .unwrap();
        let f = crate::sdf::build_field_cpu(&b, 3.0).unwrap();
        assert!(f.faces.is_some());
        check(&f);
    }
}
