//! CPU voxelisation: the grid cut into z-slabs, one task each, no atomics; deterministic for
//! any thread count.
//!
//! The triangles are first binned by the slabs their candidate cells reach (a counting sort,
//! so each slab sees its triangles in increasing index). A slab task then takes a clean
//! scratch of keys for its layers from the voxeliser's pool: each (triangle, candidate cell)
//! pair in the slab yields the key (squared distance from the cell centre to the triangle,
//! triangle index), and the cell keeps the smallest, which does not depend on the order the
//! pairs arrive in. A slab's keys (128² cells × 4 layers × 8 bytes = 512 KiB at 128³) stay in
//! cache while it is worked on; one shared grid-sized array updated with atomic minima missed
//! the cache on nearly every proposal. The closest points are computed a batch at a time
//! ([`imprint_core::closest`], the scalar function's bits). The same task then lists its
//! surface cells in increasing index from its occupancy bits and resets what it touched, so a
//! `Voxelizer` kept across frames costs time in proportion to the surface, not the grid, and
//! the slabs' lists concatenate in index order.

use super::solid::ClosedCache;
use glam::{IVec3, UVec3, Vec3};
use imprint_core::buckets::Buckets;
use imprint_core::cache::prefetch;
use imprint_core::closest::{Batch, LANES};
use imprint_core::geom::{ceil_i, floor_i, triangle_box_overlap};
use imprint_core::pool::Pool;
use imprint_core::{Boundary, BoundaryVariant, GridSpec, Mesh, Result};
use rayon::prelude::*;
use std::hint::select_unpredictable;
use std::sync::Arc;

/// Half-size of the closed cell box in the overlap test: a hair over 0.5 so that a triangle
/// lying exactly on a cell face marks both cells even after rounding.
pub const CELL_HALF: f32 = 0.5 + 1e-5;
const EMPTY: u64 = u64::MAX;
/// z-layers per slab task: 4 layers of 128² keys are 512 KiB, about an L2 cache.
const SLAB_LAYERS: usize = 4;

/// Cells, points and owning triangles of one slab's surface cells.
type BoundaryPart = (Vec<u32>, Vec<Vec3>, Vec<[Vec3; 3]>);

/// Voxelises meshes onto one grid, keeping its scratch arrays between calls.
pub struct Voxelizer {
    spec: GridSpec,
    /// Scratch for the slabs being worked on (one per task running at once, made on demand),
    /// given back clean: a one-shot run allocates a few slabs' worth, not the grid's.
    pool: Pool<SlabScratch>,
    /// Mark the cells inside a closed mesh ([`Boundary::inside`]: the field's sign); on by
    /// default, off where nothing reads the sign.
    pub signed: bool,
    closed: ClosedCache,
}

/// One slab's keys, (d² bits << 32 | triangle) per cell, EMPTY where no triangle touches it,
/// and a bit per cell that some triangle touches; clean (all EMPTY, all 0) between uses.
struct SlabScratch {
    best: Vec<u64>,
    occupied: Vec<u64>,
}

impl SlabScratch {
    fn new(nxy: usize) -> Self {
        let cells = nxy * SLAB_LAYERS;
        SlabScratch {
            best: vec![EMPTY; cells],
            occupied: vec![0; cells.div_ceil(64)],
        }
    }
}

/// What a slab task reads: the grid and the mesh in grid units.
struct Scene<'a> {
    spec: GridSpec,
    verts: &'a [Vec3],
    mesh: &'a Mesh,
    variant: BoundaryVariant,
}

impl Voxelizer {
    pub fn new(spec: GridSpec) -> Result<Self> {
        // Grid-sized: only the inside bits (the slab scratch is a few slabs' worth).
        spec.check_memory("voxelisation inside bits", 1)?;
        spec.check_cell_indices("voxelisation")?;
        Ok(Voxelizer {
            spec,
            pool: Pool::default(),
            signed: true,
            closed: ClosedCache::default(),
        })
    }

    pub fn spec(&self) -> &GridSpec {
        &self.spec
    }

    /// The discrete boundary of `mesh` on this grid. Parts of the mesh outside the grid are
    /// clipped away.
    pub fn run(&mut self, mesh: &Mesh, variant: BoundaryVariant) -> Result<Boundary> {
        // Parallel passes: from a worker (see `on_workers`).
        imprint_core::pool::on_workers(|| self.run_here(mesh, variant))
    }

    /// [`Voxelizer::run`] on the calling thread.
    fn run_here(&mut self, mesh: &Mesh, variant: BoundaryVariant) -> Result<Boundary> {
        let spec = self.spec;
        let verts: Vec<Vec3> = mesh
            .positions
            .par_iter()
            .map(|&p| spec.to_cell(p))
            .collect();
        let nxy = spec.dims.x as usize * spec.dims.y as usize;
        let bins = SlabBins::new(&spec, &verts, mesh);
        let scene = Scene {
            spec,
            verts: &verts,
            mesh,
            variant,
        };
        let nz = spec.dims.z as usize;
        let (pool, closed, signed) = (&self.pool, &mut self.closed, self.signed);
        // The sign beside the surface cells: the closedness test is one thread's work (a
        // new mesh's; a kept one's is remembered), which the other thread's slabs overlap.
        let (parts, inside) = rayon::join(
            || {
                let slab = |slab: usize| {
                    let z = slab * SLAB_LAYERS..(slab * SLAB_LAYERS + SLAB_LAYERS).min(nz);
                    let mut scratch = pool.take(|| SlabScratch::new(nxy));
                    let part = slab_task(&scene, bins.of(slab), z, &mut scratch);
                    pool.give(scratch);
                    part
                };
                let slabs = 0..nz.div_ceil(SLAB_LAYERS);
                slabs.into_par_iter().map(slab).collect::<Vec<_>>()
            },
            || {
                (signed && closed.is_closed(mesh))
                    .then(|| Arc::new(super::solid::inside_cells(&spec, &verts, &mesh.triangles)))
            },
        );
        let cells = concat(&parts, |p| &p.0);
        let points = concat(&parts, |p| &p.1);
        let faces = concat(&parts, |p| &p.2);
        Ok(Boundary {
            spec,
            variant,
            cells,
            points: Arc::new(points),
            faces: Arc::new(faces),
            inside,
        })
    }
}

/// The slabs' lists of one kind (`list` of each part), joined in slab order, the parts copied
/// side by side: joined one after another they were a serial pass, the faces (36 bytes a
/// surface cell) most of it, about 1% of a one-thread build's samples.
fn concat<T: Copy + Send + Sync>(
    parts: &[BoundaryPart],
    list: impl Fn(&BoundaryPart) -> &Vec<T> + Sync,
) -> Vec<T> {
    let total = parts.iter().map(|p| list(p).len()).sum();
    let mut out = Vec::with_capacity(total);
    let mut free = &mut out.spare_capacity_mut()[..total];
    let mut dests = Vec::with_capacity(parts.len());
    for p in parts {
        let (dest, rest) = free.split_at_mut(list(p).len());
        dests.push(dest);
        free = rest;
    }
    dests.into_par_iter().zip(parts).for_each(|(dest, p)| {
        dest.write_copy_of_slice(list(p));
    });
    // SAFETY: the parts' lengths sum to `total` and each part was copied into its own range
    // of the first `total` slots, so every one of them is initialised.
    unsafe { out.set_len(total) };
    out
}

/// The triangles of each slab, in increasing index (a counting sort by slab).
pub(crate) struct SlabBins(Buckets);

impl SlabBins {
    /// The voxeliser's bins: a triangle reaches the z-layers of its candidate cells.
    fn new(spec: &GridSpec, verts: &[Vec3], mesh: &Mesh) -> Self {
        let nz = spec.dims.z as i32;
        let layers: Vec<(i32, i32)> = mesh
            .triangles
            .par_iter()
            .map(|t| {
                let z = t.map(|i| verts[i as usize].z);
                let lo = ceil_i(z[0].min(z[1]).min(z[2]) - CELL_HALF).max(0);
                let hi = floor_i(z[0].max(z[1]).max(z[2]) + CELL_HALF).min(nz - 1);
                (lo, hi)
            })
            .collect();
        Self::by_layers::<{ SLAB_LAYERS as u32 }>(spec.dims.z as usize, &layers)
    }

    /// Triangle `t` in every slab of `PER_SLAB` of the `nz` z-layers that `layers[t]` (first,
    /// last, within `0..nz`; first > last: none) reaches.
    ///
    /// Chunks of triangles are binned side by side, then each slab's lists are joined in chunk
    /// order: increasing index whatever the thread count (one pass over the bunny's 69k
    /// triangles on one thread was a tenth of the voxeliser's samples). `PER_SLAB` is a
    /// constant so that finding a layer's slab is a shift, not a division.
    pub(crate) fn by_layers<const PER_SLAB: u32>(nz: usize, layers: &[(i32, i32)]) -> Self {
        const CHUNK: usize = 8192;
        let slabs = nz.div_ceil(PER_SLAB as usize);
        let range = |&(lo, hi): &(i32, i32)| {
            if lo > hi {
                0..0
            } else {
                // Both within `0..nz`, so their u32 values are theirs.
                (lo as u32 / PER_SLAB) as usize..(hi as u32 / PER_SLAB) as usize + 1
            }
        };
        let chunks: Vec<Buckets> = layers
            .par_chunks(CHUNK)
            .enumerate()
            .map(|(c, chunk)| {
                let pairs = || {
                    chunk
                        .iter()
                        .enumerate()
                        .flat_map(move |(t, r)| range(r).map(move |s| (s, (c * CHUNK + t) as u32)))
                };
                Buckets::build(slabs, pairs)
            })
            .collect();
        SlabBins(Buckets::join(slabs, &chunks))
    }

    /// The triangles of slab `slab`, in increasing index.
    pub(crate) fn of(&self, slab: usize) -> &[u32] {
        self.0.of(slab)
    }
}

/// One slab's surface cells ([`propose_slab`], then [`collect_slab`]) with the slab's clean
/// scratch, compiled for AVX2 where the CPU has it (decided once per process): the same
/// operations, so the same bits, with fewer instructions for the scalar bookkeeping around
/// the closest points (VEX's three-operand forms spare the register copies).
fn slab_task(
    scene: &Scene,
    tris: &[u32],
    z: std::ops::Range<usize>,
    scratch: &mut SlabScratch,
) -> BoundaryPart {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (checked just above).
        return unsafe { slab_task_avx2(scene, tris, z, scratch) };
    }
    slab_task_any(scene, tris, z, scratch)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn slab_task_avx2(
    scene: &Scene,
    tris: &[u32],
    z: std::ops::Range<usize>,
    scratch: &mut SlabScratch,
) -> BoundaryPart {
    slab_task_any(scene, tris, z, scratch)
}

#[inline(always)]
fn slab_task_any(
    scene: &Scene,
    tris: &[u32],
    z: std::ops::Range<usize>,
    scratch: &mut SlabScratch,
) -> BoundaryPart {
    let nxy = scene.spec.dims.x as usize * scene.spec.dims.y as usize;
    let best = &mut scratch.best[..z.len() * nxy];
    let base = z.start * nxy;
    propose_slab(scene, tris, z, best, &mut scratch.occupied);
    collect_slab(scene, base, best, &mut scratch.occupied)
}

/// Pass 1 of a slab of layers `z`: every (triangle, candidate cell) pair in it proposes its
/// key; `best` and `occupied` are the slab's.
#[inline(always)]
fn propose_slab(
    scene: &Scene,
    tris: &[u32],
    z: std::ops::Range<usize>,
    best: &mut [u64],
    occupied: &mut [u64],
) {
    let Scene {
        spec, verts, mesh, ..
    } = *scene;
    let nx = spec.dims.x as usize;
    let nxy = nx * spec.dims.y as usize;
    let base = z.start * nxy;
    let lo_bound = Vec3::new(0.0, 0.0, z.start as f32);
    let hi_bound = Vec3::new(
        (spec.dims.x - 1) as f32,
        (spec.dims.y - 1) as f32,
        (z.end - 1) as f32,
    );
    // (cell, triangle) pairs past the plane test, their closest points a batch at a time;
    // the proposals do not depend on the order.
    // Tagged with the cell's coordinates: the box test's centre without three divisions.
    let mut batch = Batch::<(IVec3, u32)>::default();
    let mut keys = Keys {
        best,
        occupied,
        base,
        nx,
        nxy,
        exact: [(0, 0); LANES],
        len: 0,
    };
    let run = |batch: &mut Batch<(IVec3, u32)>, keys: &mut Keys| {
        batch.run(|tag, q, d2| keys.propose(tag, q, d2));
        keys.settle_exact(verts, mesh);
    };
    for (k, &ti) in tris.iter().enumerate() {
        // A triangle's indices sixteen triangles ahead, its corners six ahead (their indices
        // are in cache by then): a slab's triangles are scattered over the mesh.
        if let Some(&t) = tris.get(k + 16) {
            prefetch(&mesh.triangles[t as usize]);
        }
        if let Some(&t) = tris.get(k + 6) {
            for i in mesh.triangles[t as usize] {
                prefetch(&verts[i as usize]);
            }
        }
        let [a, b, c] = mesh.triangles[ti as usize].map(|i| verts[i as usize]);
        let (mn, mx) = (a.min(b).min(c) - CELL_HALF, a.max(b).max(c) + CELL_HALF);
        // Rounded and clamped as floats, then converted: with AVX2 `ceil` and `floor` are an
        // instruction each, and the clamps leave a small integer (one past the slab's cells
        // where the triangle misses them: an empty range, as integer clamps gave), so the
        // cast needs none of the saturating cast's fix-ups (14 instructions a value).
        let cells = |v: Vec3| {
            // SAFETY: `max` gives the bound for a NaN, so each value is a finite integer in
            // -1 ..= the grid's size.
            v.to_array().map(|c| unsafe { c.to_int_unchecked::<i32>() })
        };
        let lo = IVec3::from(cells(mn.ceil().clamp(lo_bound, hi_bound + 1.0)));
        let hi = IVec3::from(cells(mx.floor().clamp(lo_bound - 1.0, hi_bound)));
        // The triangle's plane is a separating axis: one dot product rejects the candidate
        // cells it misses before any closest-point work (exact, like the rest).
        let n = (b - a).cross(c - a);
        // `n.dot(centre - a)` term by term, the y and z terms once per row and layer (the
        // same products and sums in the same order, so the same bits). Exclusive ranges:
        // `..=` keeps an extra flag per step, and these loops run one to three times.
        let reach = CELL_HALF * (n.x.abs() + n.y.abs() + n.z.abs());
        for z in lo.z..hi.z + 1 {
            let tz = n.z * (z as f32 - a.z);
            for y in lo.y..hi.y + 1 {
                let ty = n.y * (y as f32 - a.y);
                for x in lo.x..hi.x + 1 {
                    let at = IVec3::new(x, y, z);
                    let centre = at.as_vec3();
                    if ((n.x * (centre.x - a.x) + ty) + tz).abs() > reach {
                        continue;
                    }
                    if batch.push(centre, [a, b, c], (at, ti)) {
                        run(&mut batch, &mut keys);
                    }
                }
            }
        }
    }
    run(&mut batch, &mut keys);
}

/// A slab's smallest proposed key per cell (`best`, marked in `occupied`), as pass 1 makes
/// them a batch of pairs at a time; the pairs that need the exact box test wait for it until
/// the batch is through.
struct Keys<'a> {
    best: &'a mut [u64],
    occupied: &'a mut [u64],
    /// The slab's first cell, and the grid's cells per row and per layer.
    base: usize,
    nx: usize,
    nxy: usize,
    /// This batch's pairs for the exact test: the cell (in the slab) and the key.
    exact: [(usize, u64); LANES],
    len: usize,
}

impl Keys<'_> {
    /// A pair's proposal: its closest point `q` to the cell's centre (grid units), `d2` the
    /// squared distance. Outside the circumscribed sphere: no contact. Inside the inscribed
    /// sphere, or the closest point inside the box: contact (half the pairs in between, for
    /// the bunny), taken without a branch (which was a coin toss to the predictor); the rest
    /// wait for the exact test. A key no smaller than the cell's holds nothing new (the key is
    /// a minimum and the cell is marked).
    #[inline(always)]
    fn propose(&mut self, (at, ti): (IVec3, u32), q: Vec3, d2: f32) {
        let key = ((d2.to_bits() as u64) << 32) | ti as u64;
        let [x, y, z] = at.to_array().map(|c| c as usize);
        let local = x + self.nx * y + self.nxy * z - self.base;
        let held = self.best[local];
        let in_box = (q - at.as_vec3()).abs().cmple(Vec3::splat(CELL_HALF)).all();
        // As the branches they replace, a NaN is neither outside nor between the spheres.
        let (outside, between) = (d2 > 3.0 * CELL_HALF * CELL_HALF, d2 > 0.25);
        let new = !outside & (key < held);
        let take = new & (!between | in_box);
        self.best[local] = select_unpredictable(take, key, held);
        self.occupied[local / 64] |= (take as u64) << (local % 64);
        self.exact[self.len] = (local, key);
        self.len += (new & !take) as usize;
    }

    /// The waiting pairs' exact tests (their triangle is the key's low half), in the order
    /// proposed; each taken where it beats the cell's key by then.
    #[inline(always)]
    fn settle_exact(&mut self, verts: &[Vec3], mesh: &Mesh) {
        for &(local, key) in &self.exact[..std::mem::take(&mut self.len)] {
            if key >= self.best[local] {
                continue;
            }
            let cell = local + self.base;
            let centre = Vec3::new(
                (cell % self.nx) as f32,
                (cell % self.nxy / self.nx) as f32,
                (cell / self.nxy) as f32,
            );
            let ti = (key & 0xffff_ffff) as usize;
            let [a, b, c] = mesh.triangles[ti].map(|i| verts[i as usize]);
            if triangle_box_overlap(centre, Vec3::splat(CELL_HALF), a, b, c) {
                self.best[local] = key;
                self.occupied[local / 64] |= 1u64 << (local % 64);
            }
        }
    }
}

/// Pass 2 of a slab whose first cell is `base`: its surface cells in increasing index, with
/// their points and triangles; resets what pass 1 touched.
#[inline(always)]
fn collect_slab(
    scene: &Scene,
    base: usize,
    best: &mut [u64],
    occupied: &mut [u64],
) -> BoundaryPart {
    let Scene {
        spec,
        verts,
        mesh,
        variant,
    } = *scene;
    // Sized to the slab's surface cells: grown from empty, the lists were copied at every
    // doubling, as many bytes again as they hold (2 MB a bunny build at 128³, the faces most).
    let count = occupied.iter().map(|w| w.count_ones() as usize).sum();
    let mut cells = Vec::with_capacity(count);
    let mut points = Vec::with_capacity(count);
    let mut faces = Vec::with_capacity(count);
    // `Closest`: the cells' closest points a batch at a time, written in place.
    let mut batch = Batch::<u32>::default();
    let put = |points: &mut Vec<Vec3>, k: u32, q: Vec3| {
        points[k as usize] = spec.origin + q * spec.cell;
    };
    for (w, word) in occupied.iter_mut().enumerate() {
        let mut bits = std::mem::take(word);
        while bits != 0 {
            let local = w * 64 + bits.trailing_zeros() as usize;
            bits &= bits - 1;
            let key = std::mem::replace(&mut best[local], EMPTY);
            let cell = base + local;
            let coords = spec.coords(cell);
            let tri = mesh.triangles[(key & 0xffff_ffff) as usize];
            points.push(spec.center(coords));
            if variant == BoundaryVariant::Closest {
                let k = points.len() as u32 - 1;
                if batch.push(coords.as_vec3(), tri.map(|i| verts[i as usize]), k) {
                    batch.run(|k, q, _| put(&mut points, k, q));
                }
            }
            cells.push(cell as u32);
            faces.push(tri.map(|i| mesh.positions[i as usize]));
        }
    }
    batch.run(|k, q, _| put(&mut points, k, q));
    (cells, points, faces)
}

/// One-shot voxelisation (allocates scratch for the grid; keep a [`Voxelizer`] across frames).
pub fn voxelize_cpu(mesh: &Mesh, spec: &GridSpec, variant: BoundaryVariant) -> Result<Boundary> {
    Voxelizer::new(*spec)?.run(mesh, variant)
}

/// Cell coordinates of a boundary's surface cell.
pub fn cell_coords(spec: &GridSpec, cell: u32) -> UVec3 {
    spec.coords(cell as usize)
}

#[cfg(test)]
mod tests {
    use super::{CELL_HALF, EMPTY, Keys, LANES, SlabBins};
    use glam::{IVec3, Vec3};
    use imprint_core::Mesh;
    use imprint_core::geom::{closest_point_on_triangle, triangle_box_overlap};

    /// The branches [`Keys`] replaced, one proposal at a time (the reference).
    fn propose_branching(best: &mut [u64], mesh: &Mesh, at: IVec3, ti: u32, nx: usize) {
        let [a, b, c] = mesh.triangles[ti as usize].map(|i| mesh.positions[i as usize]);
        let centre = at.as_vec3();
        let q = closest_point_on_triangle(centre, a, b, c);
        let d2 = (q - centre).length_squared();
        if d2 > 3.0 * CELL_HALF * CELL_HALF {
            return;
        }
        let key = ((d2.to_bits() as u64) << 32) | ti as u64;
        let local = at.x as usize + nx * (at.y as usize + nx * at.z as usize);
        if key >= best[local] {
            return;
        }
        if d2 > 0.25 {
            let in_box = (q - centre).abs().cmple(Vec3::splat(CELL_HALF)).all();
            if !in_box && !triangle_box_overlap(centre, Vec3::splat(CELL_HALF), a, b, c) {
                return;
            }
        }
        best[local] = key;
    }

    /// A slab's keys proposed a batch at a time, the exact box tests after each batch, are
    /// the keys proposed one at a time with the branches, whatever the order of the pairs:
    /// triangles crossing a few cells in every way (inside either sphere, between them in and
    /// out of the box, beyond), each cell proposed to by several, batches cut anywhere.
    #[test]
    fn keys_a_batch_at_a_time_are_the_branching_keys_in_any_order() {
        let nx = 4;
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        let mut seed = 777u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) as f32 / (1u32 << 24) as f32
        };
        for t in 0..60u32 {
            let centre = Vec3::new(next(), next(), next()) * 3.0;
            let size = [0.2, 0.6, 1.5][t as usize % 3];
            for _ in 0..3 {
                positions.push(centre + (Vec3::new(next(), next(), next()) - 0.5) * size);
            }
            triangles.push([3 * t, 3 * t + 1, 3 * t + 2]);
        }
        let mesh = Mesh::new(positions, triangles, "keys test").unwrap();
        let cells = (0..nx * nx * nx).map(|i| IVec3::new(i % nx, i / nx % nx, i / (nx * nx)));
        let mut pairs: Vec<(IVec3, u32)> =
            cells.flat_map(|at| (0..60).map(move |t| (at, t))).collect();
        let n = (nx * nx * nx) as usize;
        let mut want = vec![EMPTY; n];
        for &(at, ti) in &pairs {
            propose_branching(&mut want, &mesh, at, ti, nx as usize);
        }
        assert!(want.iter().filter(|&&k| k != EMPTY).count() > n / 2);
        for round in 0..6 {
            // Shuffled pairs; every other round grouped by cell (a cell's pairs then share
            // batches, where a deferred key may be beaten before its test), batches of
            // several sizes up to `LANES`.
            for i in (1..pairs.len()).rev() {
                pairs.swap(i, (next() * (i + 1) as f32) as usize % (i + 1));
            }
            if round % 2 == 1 {
                pairs.sort_by_key(|(at, _)| (at.z, at.y, at.x));
            }
            let (mut best, mut occupied) = (vec![EMPTY; n], vec![0u64; n.div_ceil(64)]);
            let mut keys = Keys {
                best: &mut best,
                occupied: &mut occupied,
                base: 0,
                nx: nx as usize,
                nxy: (nx * nx) as usize,
                exact: [(0, 0); LANES],
                len: 0,
            };
            for batch in pairs.chunks([1, LANES, 7, LANES, 23, 16][round]) {
                for &(at, ti) in batch {
                    let [a, b, c] = mesh.triangles[ti as usize].map(|i| mesh.positions[i as usize]);
                    let q = closest_point_on_triangle(at.as_vec3(), a, b, c);
                    keys.propose((at, ti), q, (q - at.as_vec3()).length_squared());
                }
                keys.settle_exact(&mesh.positions, &mesh);
            }
            assert_eq!(best, want, "round {round}");
            for (i, &k) in want.iter().enumerate() {
                assert_eq!(
                    occupied[i / 64] >> (i % 64) & 1 == 1,
                    k != EMPTY,
                    "cell {i}"
                );
            }
        }
    }

    /// The bins against a plain scan: every slab lists exactly the triangles whose layers
    /// reach it, in increasing index, across several chunks and with empty ranges.
    #[test]
    fn slab_bins_list_each_slabs_triangles_in_order() {
        const PER_SLAB: usize = 4;
        let nz = 37;
        let mut seed = 12345u32;
        let layers: Vec<(i32, i32)> = (0..20_000)
            .map(|_| {
                seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                let lo = (seed >> 8) as i32 % nz as i32;
                let len = (seed >> 20) as i32 % 9 - 2; // some first > last: reaches none
                (lo, (lo + len).min(nz as i32 - 1))
            })
            .collect();
        let bins = SlabBins::by_layers::<{ PER_SLAB as u32 }>(nz, &layers);
        for s in 0..nz.div_ceil(PER_SLAB) {
            let (first, last) = ((s * PER_SLAB) as i32, ((s + 1) * PER_SLAB) as i32 - 1);
            let want: Vec<u32> = (0..layers.len() as u32)
                .filter(|&t| {
                    let (lo, hi) = layers[t as usize];
                    lo <= hi && lo <= last && hi >= first
                })
                .collect();
            assert_eq!(bins.of(s), want.as_slice(), "slab {s}");
        }
    }
}
