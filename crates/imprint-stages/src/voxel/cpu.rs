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
use imprint_core::closest::Batch;
use imprint_core::geom::{ceil_i, floor_i, triangle_box_overlap};
use imprint_core::pool::Pool;
use imprint_core::{Boundary, BoundaryVariant, GridSpec, Mesh, Result};
use rayon::prelude::*;
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
    let mut propose = |(at, ti): (IVec3, u32), q: Vec3, d2: f32| {
        // Outside the circumscribed sphere: no contact. A cell that already holds a smaller
        // key: nothing to change (the key is a minimum and the cell is marked). Inside the
        // inscribed sphere, or the closest point inside the box: contact (half the pairs in
        // between, for the bunny). Otherwise: the exact test.
        if d2 > 3.0 * CELL_HALF * CELL_HALF {
            return;
        }
        let key = ((d2.to_bits() as u64) << 32) | ti as u64;
        let [x, y, z] = at.to_array().map(|c| c as usize);
        let local = x + nx * y + nxy * z - base;
        if key >= best[local] {
            return;
        }
        if d2 > 0.25 {
            let centre = at.as_vec3();
            let in_box = (q - centre).abs().cmple(Vec3::splat(CELL_HALF)).all();
            let [a, b, c] = mesh.triangles[ti as usize].map(|i| verts[i as usize]);
            if !in_box && !triangle_box_overlap(centre, Vec3::splat(CELL_HALF), a, b, c) {
                return;
            }
        }
        best[local] = key;
        occupied[local / 64] |= 1u64 << (local % 64);
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
                        batch.run(&mut propose);
                    }
                }
            }
        }
    }
    batch.run(&mut propose);
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
    let mut cells = Vec::new();
    let mut points = Vec::new();
    let mut faces = Vec::new();
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
    use super::SlabBins;

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
