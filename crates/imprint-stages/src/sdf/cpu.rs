//! CPU distance field: each boundary point writes the ball of radius `a` around it (H §2).
//!
//! The grid is cut into slabs of a few z-layers, one task each. A slab visits, in increasing
//! index, every point that can reach it, and keeps per cell the strictly nearest point, so
//! ties go to the smaller index whatever the slab size or thread count: the result is the
//! same bytes on every machine. Working slab by slab keeps the written cells in cache.
//!
//! For a `Closest` boundary a second pass refines each band cell to the exact distance to the
//! best of a few triangles: the owner of its nearest point and the owners of its six
//! neighbours' nearest points (a one-step closest-feature propagation). One point per cell
//! misses ridges and tight curves by up to half a cell; its own triangle misses where the foot
//! point lies on the next facet; the neighbours' triangles catch most of that. The pass reads
//! only the finished first pass, so it is as deterministic as the first. H's `Centre` boundary
//! keeps point distances, as published.
//!
//! Speed: the splat's rows are written eight cells at a time (AVX2 where the CPU has it), and
//! the refinement takes band cells a batch at a time, each lane one cell against its seven
//! candidates in turn ([`imprint_core::closest`]): no per-cell removal of repeated
//! candidates (five in seven differ, and the branches cost more than the repeats), no
//! scatter of results. Both give the scalar code's bits, so the field is the same.

use glam::Vec3;
use imprint_core::cache::prefetch;
use imprint_core::closest::{Closest, LANES, Pairs};
use imprint_core::field::{LazyCells, SpareCells, band_span};
use imprint_core::geom::{ceil_i, floor_i};
use imprint_core::pool::{Pool, grid_vec};
use imprint_core::{Boundary, BoundaryVariant, DistanceField, Error, Result};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::sync::Arc;

/// z-layers per slab task: a point within reach of a slab's faces is splatted by each slab it
/// reaches (its set-up repeated), so fewer, thicker slabs do less: 8 layers against 4, the
/// bunny's 128³ field 9.2 -> 9.0 ms; 16 slabs still share two threads evenly.
const SLAB_LAYERS: usize = 8;

type Lanes = [f32; LANES];

/// The narrow-band field of half-width `band` cells around `boundary` (one-shot; keep a
/// [`FieldBuilder`] across frames to reuse the grid-sized buffers).
pub fn build_field_cpu(boundary: &Boundary, band: f32) -> Result<DistanceField> {
    FieldBuilder::default().build(boundary, band)
}

/// Per row (`y + ny z`) of a grid, a build's band span `[lo, hi)` (`lo == hi`: none).
type Spans = Arc<[[u32; 2]]>;

/// Builds fields frame after frame, reusing the buffers of fields given back with
/// [`FieldBuilder::recycle`]: fresh grid-sized allocations cost page faults every frame.
#[derive(Default)]
pub struct FieldBuilder {
    spare: Vec<Recycled<u32>>,
    spare_dist: Option<Recycled<f32>>,
    /// The last recycled field's per-cell vectors, reset to far: the next field computes
    /// its own into them.
    spare_cells: Option<SpareCells>,
    /// The splat's per-slab squared distances, shared by the builds.
    scratch: Arc<Pool<Vec<f32>>>,
    /// The refinement's per-slab owners, shared by the builds.
    owners: Arc<Pool<Vec<Owned>>>,
}

/// A grid-sized buffer given back, and what is known of it: outside the rows' `spans` every
/// cell holds `clean`. A build cleans such a buffer by writing only the spans (a fifth of the
/// bunny's 128³ cells), where writing every cell of the four buffers was 32 MiB a build.
struct Recycled<T> {
    buf: Vec<T>,
    clean: T,
    spans: Option<Spans>,
}

impl<T: Copy + PartialEq + Send + Sync> Recycled<T> {
    /// A buffer of `n` cells, `rows` rows, to be cleaned to `clean`, and the spans to clean
    /// when they are known for that value and grid (else every cell is cleaned). A fresh
    /// buffer is made clean ([`grid_vec`], filled in parallel), so no span needs cleaning.
    fn take(this: Option<Self>, clean: T, n: usize, rows: usize) -> (Vec<T>, Option<Spans>) {
        let Some(Recycled {
            mut buf,
            clean: was,
            spans,
        }) = this
        else {
            return (grid_vec(n, clean), Some(vec![[0, 0]; rows].into()));
        };
        let spans = spans.filter(|s| buf.len() == n && was == clean && s.len() == rows);
        buf.resize(n, clean);
        (buf, spans)
    }
}

impl FieldBuilder {
    /// Takes back a field nobody else holds, for its buffers. Its cells must not have been
    /// changed since it was built (its band spans say where they can differ from far).
    pub fn recycle(&mut self, mut field: DistanceField) {
        self.spare_cells = field.take_spare_cells().or(self.spare_cells.take());
        let spans = field.band_spans();
        self.spare_dist = Some(Recycled {
            clean: field.far_value(),
            buf: field.dist,
            spans: spans.clone(),
        });
        self.spare.push(Recycled {
            buf: field.nearest,
            clean: DistanceField::FAR,
            spans,
        });
    }

    pub fn build(&mut self, boundary: &Boundary, band: f32) -> Result<DistanceField> {
        // Parallel passes: from a worker (see `on_workers`).
        imprint_core::pool::on_workers(|| {
            let mut build = self.start(boundary, band)?;
            build.run_part_here(0, 1);
            Ok(build.finish(self))
        })
    }

    /// A build to run in parts (`FieldBuild::run_part`), e.g. one per frame: the same field
    /// as [`FieldBuilder::build`], bit for bit, whatever the number of parts.
    pub fn start(&mut self, boundary: &Boundary, band: f32) -> Result<FieldBuild> {
        validate_band(band)?;
        let spec = boundary.spec;
        spec.check_cell_indices("distance field")?;
        spec.check_memory("distance field", 8)?;
        let nxy = spec.dims.x as usize * spec.dims.y as usize;
        let pts: Vec<Vec3> = boundary
            .points
            .par_iter()
            .map(|&p| spec.to_cell(p))
            .collect();
        // Points are in increasing cell index, so their cell z is non-decreasing.
        let cell_z: Vec<usize> = boundary.cells.iter().map(|&c| c as usize / nxy).collect();
        let refine = boundary.variant == BoundaryVariant::Closest;
        // Owning triangles in grid units, for the refinement.
        let faces: Vec<[Vec3; 3]> = if refine {
            boundary
                .faces
                .par_iter()
                .map(|f| f.map(|v| spec.to_cell(v)))
                .collect()
        } else {
            Vec::new()
        };
        let (n, rows) = (spec.len(), spec.len() / spec.dims.x as usize);
        let far = band * spec.cell;
        let (dist, dist_dirt) = Recycled::take(self.spare_dist.take(), far, n, rows);
        let (nearest, near_dirt) = Recycled::take(self.spare.pop(), DistanceField::FAR, n, rows);
        Ok(FieldBuild {
            spec,
            band,
            pts,
            cell_z,
            faces,
            dist,
            nearest,
            refine,
            pending: Vec::new(),
            dirt: Dirt {
                nearest: near_dirt,
                dist: dist_dirt,
            },
            scratch: self.scratch.clone(),
            owners: self.owners.clone(),
            points: boundary.points.clone(),
            world_faces: refine.then(|| boundary.faces.clone()),
            inside: boundary.inside.clone(),
            spans: if refine {
                vec![[0, 0]; spec.len() / spec.dims.x as usize]
            } else {
                Vec::new()
            },
        })
    }
}

/// A field being built in parts: each part splats the boundary points into its z-layers
/// (and one layer more, which the next part splats again to the same values) and refines its
/// layers, whose six neighbours are then all splatted. The refined owners replace the splat's
/// nearest points in place (a second grid-sized buffer was a third of a fresh build's first
/// touches), once no layer left to refine reads them: a part's last layer waits in
/// `pending` until the next part has refined its first. Cells do not depend on how the grid
/// is cut, so any number of parts gives the same field.
///
/// Serde writes all of it, so a build can be checkpointed between parts and finished after
/// loading (with any [`FieldBuilder`]: the builder only lends buffers).
#[derive(Serialize, Deserialize)]
pub struct FieldBuild {
    spec: imprint_core::GridSpec,
    band: f32,
    /// Boundary points in grid units, and their cells' z.
    pts: Vec<Vec3>,
    cell_z: Vec<usize>,
    /// Owning triangles in grid units (refinement only).
    faces: Vec<[Vec3; 3]>,
    dist: Vec<f32>,
    /// The splat's nearest points, and the refined owners over them in the refined layers.
    nearest: Vec<u32>,
    /// Whether the cells are refined to their triangles (a `Closest` boundary).
    refine: bool,
    /// The last refined layer's owners, not yet written over the nearest points the next
    /// part's first layer reads.
    pending: Vec<Owned>,
    /// Where the buffers may still hold a recycled field's values in layers not yet built.
    dirt: Dirt,
    /// The splat's per-slab squared distances (contents do not matter between slabs).
    #[serde(skip)]
    scratch: Arc<Pool<Vec<f32>>>,
    /// The refinement's per-slab owners (contents do not matter between slabs).
    #[serde(skip)]
    owners: Arc<Pool<Vec<Owned>>>,
    points: Arc<Vec<Vec3>>,
    world_faces: Option<Arc<Vec<[Vec3; 3]>>>,
    /// The boundary's inside cells: the field's sign.
    #[serde(default)]
    inside: Option<Arc<Vec<u32>>>,
    /// Per row (`y + ny z`), the band span the refinement found (refinement only): the
    /// field's cells use them.
    spans: Vec<[u32; 2]>,
}

/// A band cell's grid index (below 2^32, as [`Boundary::cells`]) and its refined owner.
type Owned = [u32; 2];

/// Per buffer of a [`FieldBuild`], the spans outside which it is clean (`nearest`
/// [`DistanceField::FAR`], `dist` the far value), or None: every cell may hold anything. A
/// part cleans its layers before writing them (the splat again the layer it shares with the
/// next part, whose values it then writes again: the same values).
#[derive(Default, Serialize, Deserialize)]
struct Dirt {
    nearest: Option<Spans>,
    dist: Option<Spans>,
}

/// Cleans `buf`, whole rows of `nx` cells from row `first_row` on, to `value`: only each
/// row's span where `spans` are known, every cell otherwise.
fn clean<T: Copy>(
    buf: &mut [T],
    value: T,
    spans: Option<&[[u32; 2]]>,
    first_row: usize,
    nx: usize,
) {
    let Some(spans) = spans else {
        return buf.fill(value);
    };
    for (row, &[lo, hi]) in buf.chunks_mut(nx).zip(&spans[first_row..]) {
        row[lo as usize..hi as usize].fill(value);
    }
}

impl FieldBuild {
    /// The z-layers of part `part` of `parts`.
    pub fn layers(&self, part: u32, parts: u32) -> std::ops::Range<usize> {
        let nz = self.spec.dims.z as usize;
        let (p, n) = (part as usize, parts.max(1) as usize);
        p * nz / n..(p + 1) * nz / n
    }

    /// Runs part `part` of `parts` (parts run in order, each once).
    pub fn run_part(&mut self, part: u32, parts: u32) {
        imprint_core::pool::on_workers(|| self.run_part_here(part, parts))
    }

    /// [`FieldBuild::run_part`] on the calling thread.
    fn run_part_here(&mut self, part: u32, parts: u32) {
        let nz = self.spec.dims.z as usize;
        let z = self.layers(part, parts);
        if z.is_empty() {
            return;
        }
        if self.refine {
            self.splat(z.start..(z.end + 1).min(nz));
            self.refine(z);
        } else {
            self.splat(z);
        }
    }

    /// Phase 1 over layers `z`: per cell the strictly nearest point within the band (squared
    /// grid distances in a slab's scratch; world distances in `dist` straight away when
    /// nothing refines them).
    fn splat(&mut self, z: std::ops::Range<usize>) {
        let spec = self.spec;
        let (nx, ny) = (spec.dims.x as usize, spec.dims.y as usize);
        let nxy = nx * ny;
        let band = self.band;
        let reach = (band + 0.8661).floor() as usize;
        let a2 = band * band;
        // d² <= a² exactly when d² < next_up(a²): the band includes its edge.
        let unset = f32::from_bits(a2.to_bits() + 1);
        let far = band * spec.cell;
        // Bands up to WINDOW/2 - 1 cells take the fixed-window splat.
        let fast = band <= (WINDOW / 2 - 1) as f32;
        let refine = self.refine;
        let (pts, cell_z) = (&self.pts, &self.cell_z);
        let (dirt, scratch) = (self.dirt.nearest.as_deref(), &*self.scratch);
        let range = z.start * nxy..z.end * nxy;
        self.dist[range.clone()]
            .par_chunks_mut(nxy * SLAB_LAYERS)
            .zip(self.nearest[range].par_chunks_mut(nxy * SLAB_LAYERS))
            .enumerate()
            .for_each(|(slab, (dist, near))| {
                let z0 = z.start + slab * SLAB_LAYERS;
                let z1 = (z0 + SLAB_LAYERS).min(z.end);
                clean(near, DistanceField::FAR, dirt, z0 * ny, nx);
                let mut d2s = scratch.take(Vec::new);
                d2s.clear();
                d2s.resize(near.len(), unset);
                let first = cell_z.partition_point(|&z| z + reach < z0);
                let last = cell_z.partition_point(|&z| z <= z1 - 1 + reach);
                let slab = Slab {
                    band,
                    a2,
                    z0,
                    z1,
                    nx,
                    ny,
                    fast,
                };
                splat_slab(&slab, &pts[first..last.max(first)], first, &mut d2s, near);
                // Refined builds write their own distances; point distances are final.
                if !refine {
                    for ((d, &d2), &n) in dist.iter_mut().zip(&d2s).zip(near.iter()) {
                        *d = if n == DistanceField::FAR {
                            far
                        } else {
                            d2.sqrt() * spec.cell
                        };
                    }
                }
                scratch.give(d2s);
            });
    }

    /// Phase 2 over layers `z` (their neighbours splatted): see [`refine_to_faces`]. The
    /// owners then go over the nearest points of every layer no refinement still reads: the
    /// previous part's last layer, and all of `z` but its last when a part follows (whose
    /// first layer reads it as splatted), which waits in `pending`.
    fn refine(&mut self, z: std::ops::Range<usize>) {
        let spec = self.spec;
        let dims = (
            spec.dims.x as usize,
            spec.dims.y as usize,
            spec.dims.z as usize,
        );
        let (ny, nxy) = (dims.1, dims.0 * dims.1);
        let mut owned = refine_to_faces(
            &mut self.dist[z.start * nxy..z.end * nxy],
            &self.nearest,
            &mut self.spans[z.start * ny..z.end * ny],
            self.dirt.dist.as_deref(),
            z.start * nxy,
            &self.faces,
            dims,
            (spec.cell, self.band * spec.cell),
            &self.owners,
        );
        write_owners(&mut self.nearest, 0, &std::mem::take(&mut self.pending));
        if z.end < dims.2 {
            let last = owned.last_mut().expect("a part has layers");
            let held = last.partition_point(|&[i, _]| (i as usize) < (z.end - 1) * nxy);
            self.pending = last.split_off(held);
        }
        let pool = &*self.owners;
        self.nearest[z.start * nxy..z.end * nxy]
            .par_chunks_mut(nxy * SLAB_LAYERS)
            .zip(owned)
            .enumerate()
            .for_each(|(slab, (near, owned))| {
                write_owners(near, (z.start + slab * SLAB_LAYERS) * nxy, &owned);
                pool.give(owned);
            });
    }

    /// The field (after every part ran); `builder` lends it a spare buffer for its cells.
    pub fn finish(self, builder: &mut FieldBuilder) -> DistanceField {
        // Refined builds found every row's span (point-distance builds keep none).
        let spans: Option<Spans> = self.refine.then(|| self.spans.into());
        DistanceField {
            spec: self.spec,
            band: self.band,
            dist: self.dist,
            nearest: self.nearest,
            points: self.points,
            faces: self.world_faces,
            inside: self.inside,
            cells: LazyCells::built(builder.spare_cells.take(), spans),
        }
    }
}

/// The refinement pass: per band cell, the exact distance to the best owning triangle among
/// its nearest point's and its six neighbours' nearest points'. Writes world distances into
/// `dist` (the layers starting at cell `offset`, cleaned first to `far` where `dist_dirt`
/// says old values may be) and the rows' band `spans`, and gives per slab of
/// [`SLAB_LAYERS`] its band cells in index order with their owners (the point whose
/// triangle won; ties to the smaller index).
#[allow(clippy::too_many_arguments)]
fn refine_to_faces(
    dist: &mut [f32],
    nearest: &[u32],
    spans: &mut [[u32; 2]],
    dist_dirt: Option<&[[u32; 2]]>,
    offset: usize,
    faces: &[[Vec3; 3]],
    (nx, ny, nz): (usize, usize, usize),
    (cell, far): (f32, f32),
    pool: &Pool<Vec<Owned>>,
) -> Vec<Vec<Owned>> {
    let nxy = nx * ny;
    let grid = Neighbours::new(nearest, (nx, ny, nz));
    dist.par_chunks_mut(nxy * SLAB_LAYERS)
        .zip(spans.par_chunks_mut(ny * SLAB_LAYERS))
        .enumerate()
        .map(|(slab, (dist, row_spans))| {
            let base = offset + slab * nxy * SLAB_LAYERS;
            clean(dist, far, dist_dirt, base / nx, nx);
            let mut owners = pool.take(Vec::new);
            owners.clear();
            let slab = RefineSlab {
                grid: &grid,
                faces,
                base,
                cell,
            };
            slab.run(dist, &mut owners, row_spans);
            owners
        })
        .collect()
}

/// Writes the `owned` cells' owners over their nearest points in `near` (the grid's cells
/// from index `base` on).
fn write_owners(near: &mut [u32], base: usize, owned: &[Owned]) {
    for &[i, owner] in owned {
        near[i as usize - base] = owner;
    }
}

/// One slab's refinement: its layers' cells from grid index `base` on.
struct RefineSlab<'a> {
    grid: &'a Neighbours<'a>,
    faces: &'a [[Vec3; 3]],
    base: usize,
    cell: f32,
}

impl RefineSlab<'_> {
    /// Refines the slab's band cells into `dist` (its layers) and `owners` (in index order)
    /// and writes its rows' band spans, compiled for AVX2 where the CPU has it (decided once
    /// per process): the same operations, so the same bits, with the rows' scans and the
    /// candidates' selects eight lanes to an instruction.
    fn run(&self, dist: &mut [f32], owners: &mut Vec<Owned>, row_spans: &mut [[u32; 2]]) {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { self.run_avx2(dist, owners, row_spans) };
        }
        self.run_lanes(dist, owners, row_spans)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn run_avx2(
        &self,
        dist: &mut [f32],
        owners: &mut Vec<Owned>,
        row_spans: &mut [[u32; 2]],
    ) {
        self.run_lanes(dist, owners, row_spans)
    }

    #[inline(always)]
    fn run_lanes(&self, dist: &mut [f32], owners: &mut Vec<Owned>, row_spans: &mut [[u32; 2]]) {
        let (grid, base) = (self.grid, self.base);
        let (nx, ny, _) = grid.dims;
        let nxy = nx * ny;
        let nearest = grid.nearest;
        let mut group = Group::default();
        // Each row's band cells, between its first and its last (the far ones, nine cells
        // in ten of a 128³ grid, are clean already).
        for (r, span) in row_spans.iter_mut().enumerate() {
            let row = r * nx;
            let (y, z) = (r % ny, base / nxy + r / ny);
            // The row above in z, a layer ahead of the rows read so far: its cells are the
            // +z neighbours' reads, which missed the cache on most rows.
            if let Some(above) = nearest.get(base + row + nxy..base + row + nxy + nx) {
                above.iter().step_by(16).for_each(prefetch);
            }
            let Some(xs) = band_span(&nearest[base + row..base + row + nx]) else {
                *span = [0, 0];
                continue;
            };
            *span = [xs.start as u32, xs.end as u32];
            for x in xs {
                let k = row + x;
                let n = nearest[base + k];
                if n != DistanceField::FAR && grid.add(&mut group, base + k, [x, y, z], n) {
                    self.flush(&mut group, dist, owners);
                }
            }
        }
        if group.len > 0 {
            self.flush(&mut group, dist, owners);
        }
    }

    /// A group's best squared distances to world distances, in place, and its owners.
    #[inline(always)]
    fn flush(&self, group: &mut Group, dist: &mut [f32], owners: &mut Vec<Owned>) {
        let (d2, n) = self.grid.best_faces(group, self.faces);
        let cells = &group.cells.index[..group.len];
        for (&i, d2) in cells.iter().zip(d2) {
            dist[i - self.base] = d2.sqrt() * self.cell;
        }
        owners.extend(cells.iter().zip(n).map(|(&i, n)| [i as u32, n]));
        group.len = 0;
    }
}

/// Up to [`LANES`] band cells waiting for their best triangles: one cell per lane.
#[derive(Default)]
struct Group {
    /// The cells' points (grid units), against a triangle per lane, and their closest points.
    pairs: Pairs,
    out: Closest,
    cells: Cells,
    len: usize,
}

/// Per lane: the cell's grid index, its nearest point, and its six neighbours' nearest points
/// (`cands[s]`: `Neighbours::steps[s]` away; the cell's own where that one is far or off the
/// grid).
#[derive(Default)]
struct Cells {
    index: [usize; LANES],
    own: [u32; LANES],
    cands: [[u32; LANES]; 6],
}

/// The splatted nearest points of the whole grid, read around a cell.
struct Neighbours<'a> {
    nearest: &'a [u32],
    dims: (usize, usize, usize),
    /// The six neighbours' index offsets: -x, +x, -y, +y, -z, +z.
    steps: [isize; 6],
}

impl<'a> Neighbours<'a> {
    fn new(nearest: &'a [u32], (nx, ny, nz): (usize, usize, usize)) -> Self {
        let (x, xy) = (nx as isize, (nx * ny) as isize);
        Neighbours {
            nearest,
            dims: (nx, ny, nz),
            steps: [-1, 1, -x, x, -xy, xy],
        }
    }

    /// Queues band cell `i` at `[x, y, z]` (nearest point `n`) and its neighbours'
    /// candidates, read while the cell's rows are in cache; true when the group is full.
    #[inline(always)]
    fn add(&self, group: &mut Group, i: usize, [x, y, z]: [usize; 3], n: u32) -> bool {
        let (nx, ny, nz) = self.dims;
        let l = group.len;
        group
            .pairs
            .set_point(l, Vec3::new(x as f32, y as f32, z as f32));
        group.cells.index[l] = i;
        group.cells.own[l] = n;
        let inside = [x > 0, x + 1 < nx, y > 0, y + 1 < ny, z > 0, z + 1 < nz];
        // A neighbour off the grid reads the cell itself (its own point, as a far one gives);
        // whether a neighbour is far is a coin toss at the band's edge. Both by arithmetic:
        // as branches (a conditional load, and an `if` the compiler kept as one), they were
        // 9% of the field's mispredictions.
        for (s, (&step, inside)) in self.steps.iter().zip(inside).enumerate() {
            let m = self.nearest[i.wrapping_add_signed(step * inside as isize)];
            let far = ((m == DistanceField::FAR) as u32).wrapping_neg();
            group.cells.cands[s][l] = (n & far) | (m & !far);
        }
        group.len += 1;
        group.len == LANES
    }

    /// Per lane of `group`: the squared grid distance to the best triangle of its cell's
    /// nearest point and its six neighbours', and that point (ties to the smaller index).
    /// Every lane tries all seven (a neighbour that is far or off the grid stands for the
    /// cell's own), so no lane waits on another's candidates; a minimum, so repeats and
    /// order do not change it. Lanes past the group's length take its first cell's
    /// candidates (their results are not used).
    #[inline(always)]
    fn best_faces(&self, group: &mut Group, faces: &[[Vec3; 3]]) -> (Lanes, [u32; LANES]) {
        let c = &mut group.cells;
        for l in group.len..LANES {
            (c.index[l], c.own[l]) = (c.index[0], c.own[0]);
            c.cands.iter_mut().for_each(|cands| cands[l] = cands[0]);
        }
        let mut best = ([f32::INFINITY; LANES], [u32::MAX; LANES]);
        let (pairs, out) = (&mut group.pairs, &mut group.out);
        best = keep_better(best, pairs, out, faces, &c.own);
        for cands in &c.cands {
            best = keep_better(best, pairs, out, faces, cands);
        }
        best
    }
}

/// Per lane, the nearer of `best`'s triangle and the lane's triangle of `cands` (ties to
/// the smaller index), by selects, not branches: which candidate wins is a coin toss to the
/// predictor. Into fresh arrays: selected into `best` in place, the lanes compiled to
/// masked stores, which on AMD processors take many cycles each.
#[inline(always)]
fn keep_better(
    best: (Lanes, [u32; LANES]),
    pairs: &mut Pairs,
    out: &mut Closest,
    faces: &[[Vec3; 3]],
    cands: &[u32; LANES],
) -> (Lanes, [u32; LANES]) {
    pairs.set_triangles(faces, cands);
    pairs.closest(out);
    let d2 = &out.d2;
    let mut kept = ([0.0f32; LANES], [0u32; LANES]);
    for l in 0..LANES {
        let (d, o, n) = (best.0[l], best.1[l], cands[l]);
        let better = (d2[l] < d) | ((d2[l] == d) & (n < o));
        kept.0[l] = if better { d2[l] } else { d };
        kept.1[l] = if better { n } else { o };
    }
    kept
}

/// What [`splat_slab`] needs of a slab of layers `z0..z1` and the band.
struct Slab {
    band: f32,
    a2: f32,
    z0: usize,
    z1: usize,
    nx: usize,
    ny: usize,
    /// The band fits [`splat_point_window`].
    fast: bool,
}

/// Splats `pts` (indices from `first`) into a slab's cells, compiled for AVX2 where the CPU
/// has it (decided once per process): a window row is then one instruction per operation,
/// the same operations, so the same bits.
#[inline]
fn splat_slab(s: &Slab, pts: &[Vec3], first: usize, d2s: &mut [f32], near: &mut [u32]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { splat_slab_avx2(s, pts, first, d2s, near) };
    }
    splat_slab_lanes::<false>(s, pts, first, d2s, near)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn splat_slab_avx2(s: &Slab, pts: &[Vec3], first: usize, d2s: &mut [f32], near: &mut [u32]) {
    splat_slab_lanes::<true>(s, pts, first, d2s, near)
}

/// `AVX2`: the caller runs with AVX2, so the window rows take [`keep_row_avx2`].
#[inline(always)]
fn splat_slab_lanes<const AVX2: bool>(
    s: &Slab,
    pts: &[Vec3],
    first: usize,
    d2s: &mut [f32],
    near: &mut [u32],
) {
    let Slab {
        band,
        a2,
        z0,
        z1,
        nx,
        ny,
        fast,
    } = *s;
    for (k, &p) in pts.iter().enumerate() {
        let pi = (first + k) as u32;
        if !(fast && splat_point_window::<AVX2>(p, pi, band, z0, z1, nx, ny, d2s, near)) {
            splat_point(p, pi, band, a2, z0, z1, nx, ny, d2s, near);
        }
    }
}

/// Cells per row in [`splat_point_window`]: a point's ball of radius <= 3 fits in the 8 cells
/// floor(x) - 3 ..= floor(x) + 4.
const WINDOW: usize = 8;

/// The same writes as [`splat_point`] for bands <= 3, faster: every row is the fixed window of
/// `WINDOW` cells around the point, so there are no square roots or range computations per row
/// and the row vectorises. Cells outside the ball fail the `d² < best` test as they do in
/// `splat_point` (whose best starts just above a²), and d² is the same expression, so the
/// result is identical, rows outside the ball included. Returns false, writing nothing, when
/// the window would leave the grid (points near its x faces take `splat_point`).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn splat_point_window<const AVX2: bool>(
    p: Vec3,
    pi: u32,
    band: f32,
    z0: usize,
    z1: usize,
    nx: usize,
    ny: usize,
    d2s: &mut [f32],
    near: &mut [u32],
) -> bool {
    const SLACK: f32 = 1e-3;
    let x0 = floor_i(p.x) - (WINDOW as i32 / 2 - 1);
    if x0 < 0 || x0 as usize + WINDOW > nx {
        return false;
    }
    let x0 = x0 as usize;
    let dx2: [f32; WINDOW] = std::array::from_fn(|k| {
        let dx = (x0 + k) as f32 - p.x;
        dx * dx
    });
    let zlo = ceil_i(p.z - band - SLACK).max(z0 as i32);
    let zhi = floor_i(p.z + band + SLACK).min(z1 as i32 - 1);
    let ylo = ceil_i(p.y - band - SLACK).max(0);
    let yhi = floor_i(p.y + band + SLACK).min(ny as i32 - 1);
    if ylo > yhi {
        return true;
    }
    let (ylo, yhi) = (ylo as usize, yhi as usize);
    for z in zlo..zhi + 1 {
        let dz = z as f32 - p.z;
        // The same value as `dz * dz` in each row's sum.
        let dz2 = dz * dz;
        let layer = (z as usize - z0) * nx * ny + x0;
        // Every window row of the layer is in both buffers (one test per layer, not per row).
        let end = layer + yhi * nx + WINDOW;
        assert!(end <= d2s.len() && end <= near.len());
        // Every row of the window's square, those outside the ball too (a fifth of them):
        // their cells fail the `d² < best` test (d² >= dyz2 > a², so d² >= next_up(a²), where
        // a best starts), so they write what they read. Skipped, which rows they are depends
        // on the point's fractions: a branch the predictor missed about a dozen times a point,
        // two fifths of the field's mispredictions (cachegrind's branch simulation).
        for y in ylo..yhi + 1 {
            let dy = y as f32 - p.y;
            let dyz2 = dy * dy + dz2;
            let row = layer + y * nx;
            // SAFETY: row + WINDOW <= end (tested above), and the buffers do not alias.
            let (d_row, n_row) = unsafe {
                (
                    &mut *d2s.as_mut_ptr().add(row).cast::<[f32; WINDOW]>(),
                    &mut *near.as_mut_ptr().add(row).cast::<[u32; WINDOW]>(),
                )
            };
            #[cfg(target_arch = "x86_64")]
            if AVX2 {
                // SAFETY: AVX2 is only set by `splat_slab_avx2`, which runs with AVX2.
                unsafe { keep_row_avx2(d_row, n_row, &dx2, dyz2, pi) };
                continue;
            }
            keep_row(d_row, n_row, &dx2, dyz2, pi);
        }
    }
    true
}

/// Per cell of a window row: `dx2 + dyz2` and `pi` where that is strictly below the cell's
/// squared distance. Whole rows in, whole rows out, the select as bit masks: this vectorises
/// (a select per cell compiles to a branch per cell).
#[inline(always)]
fn keep_row(
    d_row: &mut [f32; WINDOW],
    n_row: &mut [u32; WINDOW],
    dx2: &[f32; WINDOW],
    dyz2: f32,
    pi: u32,
) {
    let (d_old, n_old) = (*d_row, *n_row);
    for k in 0..WINDOW {
        let d2 = dx2[k] + dyz2;
        let closer = ((d2 < d_old[k]) as u32).wrapping_neg();
        d_row[k] = f32::from_bits(d2.to_bits() & closer | d_old[k].to_bits() & !closer);
        n_row[k] = pi & closer | n_old[k] & !closer;
    }
}

/// [`keep_row`] in AVX2 instructions, the same operations: written out because LLVM turns
/// the portable select (and a blend of the loaded row) into masked stores (`vmaskmovps`),
/// which cost AMD processors tens of cycles each and took two thirds of the splat's time.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
#[inline]
unsafe fn keep_row_avx2(
    d_row: &mut [f32; WINDOW],
    n_row: &mut [u32; WINDOW],
    dx2: &[f32; WINDOW],
    dyz2: f32,
    pi: u32,
) {
    use std::arch::x86_64::*;
    // SAFETY: each pointer is to 8 lanes of a live array (unaligned loads and stores).
    unsafe {
        let d_old = _mm256_loadu_ps(d_row.as_ptr());
        let n_old = _mm256_loadu_si256(n_row.as_ptr().cast());
        let d2 = _mm256_add_ps(_mm256_loadu_ps(dx2.as_ptr()), _mm256_set1_ps(dyz2));
        let closer = _mm256_cmp_ps::<_CMP_LT_OQ>(d2, d_old);
        // minps is `d2 < d_old ? d2 : d_old`, the select, and unlike a blend LLVM keeps it.
        _mm256_storeu_ps(d_row.as_mut_ptr(), _mm256_min_ps(d2, d_old));
        let n_new = _mm256_blendv_ps(
            _mm256_castsi256_ps(n_old),
            _mm256_castsi256_ps(_mm256_set1_epi32(pi as i32)),
            closer,
        );
        _mm256_storeu_si256(n_row.as_mut_ptr().cast(), _mm256_castps_si256(n_new));
    }
}

/// Writes point `p` (grid units, index `pi`) into the cells of slab [z0, z1) within `band`.
#[allow(clippy::too_many_arguments)]
#[inline]
fn splat_point(
    p: Vec3,
    pi: u32,
    band: f32,
    a2: f32,
    z0: usize,
    z1: usize,
    nx: usize,
    ny: usize,
    d2s: &mut [f32],
    near: &mut [u32],
) {
    const SLACK: f32 = 1e-3;
    let zlo = ceil_i(p.z - band - SLACK).max(z0 as i32);
    let zhi = floor_i(p.z + band + SLACK).min(z1 as i32 - 1);
    for z in zlo..=zhi {
        let dz = z as f32 - p.z;
        let rz2 = a2 - dz * dz;
        if rz2 < -SLACK {
            continue;
        }
        let ry = rz2.max(0.0).sqrt();
        let ylo = ceil_i(p.y - ry - SLACK).max(0);
        let yhi = floor_i(p.y + ry + SLACK).min(ny as i32 - 1);
        for y in ylo..=yhi {
            let dy = y as f32 - p.y;
            let dyz2 = dy * dy + dz * dz;
            let rx = (a2 - dyz2).max(0.0).sqrt();
            let xlo = ceil_i(p.x - rx - SLACK).max(0);
            let xhi = floor_i(p.x + rx + SLACK).min(nx as i32 - 1);
            if xhi < xlo {
                continue;
            }
            let (z, y, xlo, xhi) = (z as usize, y as usize, xlo as usize, xhi as usize);
            let row = (z - z0) * nx * ny + y * nx;
            let d_row = &mut d2s[row + xlo..=row + xhi];
            let n_row = &mut near[row + xlo..=row + xhi];
            for (k, (d, n)) in d_row.iter_mut().zip(n_row.iter_mut()).enumerate() {
                let dx = (xlo + k) as f32 - p.x;
                keep_nearer(d, n, dx * dx + dyz2, pi);
            }
        }
    }
}

/// Keeps point `pi` at squared distance `d2` if it is strictly nearer than the cell's current
/// point: a branch-free select (the many near-equal candidates of neighbouring points cost no
/// mispredictions, and fixed-width rows vectorise); strict, so ties keep the smaller index.
#[inline(always)]
fn keep_nearer(d: &mut f32, n: &mut u32, d2: f32, pi: u32) {
    let closer = d2 < *d;
    *d = if closer { d2 } else { *d };
    *n = if closer { pi } else { *n };
}

/// The band half-width must be a finite number of cells > 0.
pub fn validate_band(band: f32) -> Result<()> {
    if !(band.is_finite() && band > 0.0) {
        return Err(Error::Invalid(format!(
            "band must be a finite number of cells > 0, got {band}"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::geom::closest_point_on_triangle;
    use imprint_core::mesh::primitives::torus;
    use imprint_core::{BoundaryVariant, GridSpec};

    /// Each band cell's refined distance and owner are, bit for bit, the best (smallest
    /// squared distance, then smallest point) of its splatted nearest point's triangle and
    /// its six in-grid neighbours' (a lane that read another lane's candidates, a wrong step
    /// or a padding lane written back would break it). The grid hugs the torus, so the band
    /// reaches every face of the grid; groups run across rows, and each slab's last is
    /// partial.
    #[test]
    fn refinement_is_the_best_of_seven_candidates() {
        let mesh = torus(0.5, 0.2, 64, 24);
        let spec = GridSpec::fit(&mesh.bounds(), 44, 0.01).unwrap();
        let boundary = crate::voxel::voxelize_cpu(&mesh, &spec, BoundaryVariant::Closest).unwrap();
        let mut build = FieldBuilder::default().start(&boundary, 3.0).unwrap();
        let [nx, ny, nz] = spec.dims.to_array().map(|n| n as usize);
        build.splat(0..nz);
        let splatted = build.nearest.clone();
        build.refine(0..nz);
        let owner = &build.nearest;
        let far = 3.0 * spec.cell;
        let (mut band, mut on_faces) = (0, [0; 3]);
        for (i, &n0) in splatted.iter().enumerate() {
            let c = [i % nx, i / nx % ny, i / (nx * ny)];
            if n0 == DistanceField::FAR {
                assert_eq!(
                    (build.dist[i], owner[i]),
                    (far, DistanceField::FAR),
                    "cell {c:?}"
                );
                continue;
            }
            band += 1;
            let dims = [nx, ny, nz];
            for a in 0..3 {
                on_faces[a] += (c[a] == 0 || c[a] + 1 == dims[a]) as usize;
            }
            let p = Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32);
            let mut cands = vec![n0];
            for (a, stride) in [1, nx, nx * ny].into_iter().enumerate() {
                if c[a] > 0 {
                    cands.push(splatted[i - stride]);
                }
                if c[a] + 1 < dims[a] {
                    cands.push(splatted[i + stride]);
                }
            }
            let best = cands
                .into_iter()
                .filter(|&n| n != DistanceField::FAR)
                .map(|n| {
                    let [a, b, c] = build.faces[n as usize];
                    (
                        (closest_point_on_triangle(p, a, b, c) - p).length_squared(),
                        n,
                    )
                })
                .min_by(|x, y| x.0.total_cmp(&y.0).then(x.1.cmp(&y.1)))
                .unwrap();
            assert_eq!(owner[i], best.1, "cell {c:?}");
            let want = best.0.sqrt() * spec.cell;
            assert_eq!(build.dist[i].to_bits(), want.to_bits(), "cell {c:?}");
        }
        assert!(band > 10_000, "{band} band cells");
        assert!(
            on_faces.iter().all(|&k| k > 0),
            "band cells on the grid's faces: {on_faces:?}"
        );
    }

    /// A build in any number of parts is the build in one, also where parts are thinner than
    /// a slab or empty: each part's first layer reads the layer before it as splatted, not
    /// refined (the refined owners of a part's last layer wait for the next part).
    #[test]
    fn any_number_of_parts_builds_the_same_field() {
        let mesh = torus(0.5, 0.2, 48, 16);
        let spec = GridSpec::fit(&mesh.bounds(), 37, 0.05).unwrap();
        let boundary = crate::voxel::voxelize_cpu(&mesh, &spec, BoundaryVariant::Closest).unwrap();
        let whole = build_field_cpu(&boundary, 3.0).unwrap();
        let nz = spec.dims.z;
        for parts in [2, 3, 5, 9, nz - 1, nz, nz + 4] {
            let mut builder = FieldBuilder::default();
            builder.recycle(build_field_cpu(&boundary, 2.0).unwrap());
            let mut build = builder.start(&boundary, 3.0).unwrap();
            (0..parts).for_each(|p| build.run_part(p, parts));
            let f = build.finish(&mut builder);
            assert!(f.nearest == whole.nearest, "{parts} parts");
            assert!(f.dist == whole.dist, "{parts} parts");
        }
    }

    /// A grid whose cell indices overflow 32 bits is refused with the grid named, before
    /// anything grid-sized is allocated, by the voxeliser and by the field.
    #[test]
    fn grids_past_32_bit_indices_are_refused() {
        let spec = GridSpec::new(Vec3::ZERO, 0.01, glam::UVec3::new(2048, 2048, 1024)).unwrap();
        let e = crate::voxel::cpu::Voxelizer::new(spec)
            .err()
            .expect("refused");
        assert!(
            e.to_string()
                .contains("voxelisation: a 2048x2048x1024 grid"),
            "{e}"
        );
        let boundary = Boundary {
            spec,
            variant: BoundaryVariant::Closest,
            cells: Vec::new(),
            points: Default::default(),
            faces: Default::default(),
            inside: None,
        };
        let e = FieldBuilder::default()
            .start(&boundary, 3.0)
            .err()
            .expect("refused");
        assert!(
            e.to_string()
                .contains("distance field: a 2048x2048x1024 grid"),
            "{e}"
        );
    }
}
