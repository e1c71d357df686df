//! An exact inside test for a closed mesh: the parity of the surface crossings of a ray.
//!
//! One ray per axis (+x, +y, +z) and a majority vote of the three, so that a ray grazing an
//! edge or lying in a face plane is outvoted by the other two. Each ray is answered in the
//! mesh's projection along its axis: the triangles are binned in a 2D grid of that
//! projection, and a triangle is crossed when its projection covers the point (a half-open
//! rule on edges, so a point on an edge shared by two triangles is counted by exactly one) and
//! its plane lies beyond the point along the axis. The cells are about square, the size of an
//! average triangle's projected box; a cell's list carries each triangle's projected box, which
//! rejects most of the list (by comparisons, without branches) before the exact test, which
//! takes the survivors four at a time (one in three is crossed: a branch per triangle would be
//! a coin toss to the predictor).
//!
//! Meaningful for closed (watertight) bodies, as is "inside". Pieces that touch along shared
//! faces (boxes stacked into a U) are fine: each shared face is crossed twice, which keeps the
//! parity. Pieces that overlap are not (a point inside two of them counts as outside).
//!
//! A coarse voxel grid over the body answers most points without a ray (same answers): a
//! cell no triangle's bounding box comes near (a margin around the cell) lies in one
//! surface-free region with its face-adjacent far cells, and for a mesh whose edges each
//! border an even number of triangles (a closed surface, or several) the ray parity is the
//! same at every point of such a region. Each region is decided by the exact test at a few of
//! its cell centres (and left to the exact test when they disagree); points in near cells,
//! beyond the grid, or of a mesh that is not closed take the exact test.

use glam::{DVec2, DVec3, Vec2, Vec3};
use imprint_core::{Aabb, Mesh};
use std::mem::MaybeUninit;

/// The inside test of one closed mesh.
pub struct InsideTest {
    axes: [AxisGrid; 3],
    cells: Option<CellGrid>,
}

/// Voxel states: near the surface (ask the rays), inside, outside.
const NEAR: u8 = 0;
const INSIDE: u8 = 1;
const OUTSIDE: u8 = 2;

/// The voxel grid of far cells with their answers.
struct CellGrid {
    min: DVec3,
    inv: f64,
    n: [usize; 3],
    state: Vec<u8>,
}

impl CellGrid {
    fn index(&self, p: Vec3) -> Option<usize> {
        let f = (p.as_dvec3() - self.min) * self.inv;
        let n = self.n.map(|k| k as f64);
        if !(f.x >= 0.0 && f.y >= 0.0 && f.z >= 0.0 && f.x < n[0] && f.y < n[1] && f.z < n[2]) {
            return None;
        }
        let (i, j, k) = (f.x as usize, f.y as usize, f.z as usize);
        Some((k * self.n[1] + j) * self.n[0] + i)
    }

    /// The grid of `tris` (all finite) within `bounds` with its far cells (not yet decided) and
    /// their regions: face-adjacent far cells, in scan order.
    fn far_regions(tris: &[[Vec3; 3]], bounds: &Aabb) -> Option<(Self, Vec<Vec<u32>>)> {
        let ext = (bounds.max - bounds.min).as_dvec3();
        let longest = ext.max_element();
        if !(longest > 0.0 && longest.is_finite()) {
            return None;
        }
        let res = ((tris.len() as f64).cbrt() * 3.0).clamp(16.0, 128.0);
        let cell = longest / res;
        // One padding cell on each side, so that points just outside the body hit far cells.
        let min = bounds.min.as_dvec3() - DVec3::splat(cell);
        let n = [0, 1, 2].map(|a| ((ext[a] / cell).ceil() as usize).max(1) + 2);
        let inv = 1.0 / cell;
        let margin = 0.05 * cell;
        let total = n[0] * n[1] * n[2];
        let mut state = vec![OUTSIDE; total];
        let clampi = |x: f64, a: usize| (x.floor().max(0.0) as usize).min(n[a] - 1);
        for t in tris {
            let lo = t[0].min(t[1]).min(t[2]).as_dvec3() - DVec3::splat(margin);
            let hi = t[0].max(t[1]).max(t[2]).as_dvec3() + DVec3::splat(margin);
            let l = [0, 1, 2].map(|a| clampi((lo[a] - min[a]) * inv, a));
            let h = [0, 1, 2].map(|a| clampi((hi[a] - min[a]) * inv, a));
            for k in l[2]..=h[2] {
                for j in l[1]..=h[1] {
                    for i in l[0]..=h[0] {
                        state[(k * n[1] + j) * n[0] + i] = NEAR;
                    }
                }
            }
        }
        // Regions of face-adjacent far cells, in scan order.
        let mut label = vec![u32::MAX; total];
        let mut regions: Vec<Vec<u32>> = Vec::new();
        let mut stack = Vec::new();
        for start in 0..total {
            if state[start] == NEAR || label[start] != u32::MAX {
                continue;
            }
            let r = regions.len() as u32;
            let mut cells = Vec::new();
            label[start] = r;
            stack.push(start);
            while let Some(c) = stack.pop() {
                cells.push(c as u32);
                let i = c % n[0];
                let j = (c / n[0]) % n[1];
                let k = c / (n[0] * n[1]);
                let mut visit = |d: usize| {
                    if state[d] != NEAR && label[d] == u32::MAX {
                        label[d] = r;
                        stack.push(d);
                    }
                };
                if i > 0 {
                    visit(c - 1);
                }
                if i + 1 < n[0] {
                    visit(c + 1);
                }
                if j > 0 {
                    visit(c - n[0]);
                }
                if j + 1 < n[1] {
                    visit(c + n[0]);
                }
                if k > 0 {
                    visit(c - n[0] * n[1]);
                }
                if k + 1 < n[2] {
                    visit(c + n[0] * n[1]);
                }
            }
            regions.push(cells);
        }
        Some((CellGrid { min, inv, n, state }, regions))
    }

    /// Decides each far region by `exact` at up to three of its cell centres (first, middle,
    /// last found), which must agree; a region where they do not is left to the exact test.
    fn decide(&mut self, regions: &[Vec<u32>], exact: impl Fn(Vec3) -> bool) {
        let n = self.n;
        let centre = |c: usize| {
            let ijk = DVec3::new(
                (c % n[0]) as f64,
                ((c / n[0]) % n[1]) as f64,
                (c / (n[0] * n[1])) as f64,
            );
            (self.min + (ijk + 0.5) / self.inv).as_vec3()
        };
        for cells in regions {
            let picks = [0, cells.len() / 2, cells.len() - 1];
            let answers = picks.map(|k| exact(centre(cells[k] as usize)));
            let s = if answers.iter().all(|&a| a == answers[0]) {
                if answers[0] { INSIDE } else { OUTSIDE }
            } else {
                NEAR
            };
            for &c in cells {
                self.state[c as usize] = s;
            }
        }
    }
}

impl InsideTest {
    /// The test with its voxel grid of far cells: worth it for many queries spread through
    /// and around the body.
    pub fn new(mesh: &Mesh) -> Self {
        let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        let bounds = mesh.bounds();
        // The three axes' bins and the grid's far regions are independent: built side by side.
        let (axes, far) = rayon::join(
            || AxisGrid::all(&tris, &bounds),
            || {
                let finite = tris.iter().flatten().all(|v| v.is_finite());
                if finite && !tris.is_empty() && !bounds.is_empty() && mesh.is_closed() {
                    CellGrid::far_regions(&tris, &bounds)
                } else {
                    None
                }
            },
        );
        let mut test = InsideTest { axes, cells: None };
        if let Some((mut grid, regions)) = far {
            grid.decide(&regions, |p| test.exact(p));
            test.cells = Some(grid);
        }
        test
    }

    /// The test by the rays alone (same answers as [`InsideTest::new`]'s): for queries near
    /// the surface (a garment on a body), which the grid would leave to the rays anyway, at
    /// about half the set-up cost.
    pub fn rays_only(mesh: &Mesh) -> Self {
        let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle(t))
            .collect();
        InsideTest {
            axes: AxisGrid::all(&tris, &mesh.bounds()),
            cells: None,
        }
    }

    /// An order of `points` in which queries near each other follow each other: by the
    /// cell of the y-axis grid they fall in, x fastest (points beyond it last). Consecutive
    /// points then read the same cells of the y grid, and of the x grid (same y and z rows),
    /// and neighbouring cells of the z grid, from the cache; in a garment's own order most
    /// walks read cells the cache had dropped since the last time (2.6× slower).
    pub fn locality_order(&self, points: &[Vec3]) -> Vec<u32> {
        let g = &self.axes[1];
        let cells = g.n[0] * g.n[1];
        let key = |p: &Vec3| g.cell_of(*p).unwrap_or(cells);
        let mut next = vec![0u32; cells + 2];
        for p in points {
            next[key(p) + 1] += 1;
        }
        for c in 1..next.len() {
            next[c] += next[c - 1];
        }
        let mut order = vec![0u32; points.len()];
        for (i, p) in points.iter().enumerate() {
            let at = &mut next[key(p)];
            order[*at as usize] = i as u32;
            *at += 1;
        }
        order
    }

    /// Whether `p` is inside the body (two of the three rays cross its surface an odd number
    /// of times).
    /// A point exactly on the surface (a ray meets a triangle at the point itself) is outside.
    pub fn inside(&self, p: Vec3) -> bool {
        if let Some(g) = &self.cells
            && let Some(c) = g.index(p)
        {
            match g.state[c] {
                INSIDE => return true,
                OUTSIDE => return false,
                _ => {}
            }
        }
        self.exact(p)
    }

    /// The parity of the surface crossings of the one ray from `p` along +x (T's fill test,
    /// which projects the triangles on the y-z plane and counts them along x): `Some(true)`
    /// when odd (inside a closed mesh), `None` when `p` lies on a triangle the ray meets.
    /// Edges are owned half-open, so a ray through an edge shared by two triangles, or
    /// through a vertex, counts one crossing there.
    pub fn odd_along_x(&self, p: Vec3) -> Option<bool> {
        self.axes[0].odd_crossings(p)
    }

    /// The surface crossings of the ray from `p` along axis `axis` (0, 1, 2 for x, y, z),
    /// towards + when `positive`: the distances of those within `reach` of `p` go to `out`
    /// (cleared first; unsorted); returns the parity of all of them (odd: inside by this one
    /// ray), `None` when `p` lies on a triangle the ray meets. One walk of the triangle list of
    /// the cell `p` projects into (what [`InsideTest::exact`] reads for that axis).
    pub fn ray_crossings(
        &self,
        p: Vec3,
        axis: usize,
        positive: bool,
        reach: f64,
        out: &mut Vec<f64>,
    ) -> Option<bool> {
        out.clear();
        let mut ray = Ray::new(p[axis] as f64, positive, reach);
        match self.axes[axis].each_hit(p, &mut EachCrossing(|w| ray.add(w, out))) {
            Some(false) => None,
            _ => Some(ray.odd),
        }
    }

    /// [`InsideTest::ray_crossings`] at the point `lines` were kept for, read from them.
    pub fn ray_crossings_kept(
        &self,
        lines: &Lines,
        axis: usize,
        positive: bool,
        reach: f64,
        out: &mut Vec<f64>,
    ) -> Option<bool> {
        out.clear();
        let mut ray = Ray::new(lines.at[axis] as f64, positive, reach);
        lines.w[axis]
            .iter()
            .all(|&w| ray.add(w, out))
            .then_some(ray.odd)
    }

    /// [`InsideTest::exact`] at each of `points` into `inside`, keeping the crossings of the
    /// three axis lines through each point in its `lines` (complete where it is inside) for
    /// [`InsideTest::exact_on_lines`] and [`InsideTest::ray_crossings_kept`]. Ray by ray:
    /// every point's ray along x, then along y, then along z, so that points near each other
    /// (see [`InsideTest::locality_order`]) walk the same cells one after the other, from the
    /// cache (point by point, three grids' cells took turns in it).
    pub fn exact_keeping(&self, points: &[Vec3], lines: &mut [Lines], inside: &mut [bool]) {
        let mut votes = vec![Vote::default(); points.len()];
        for g in &self.axes {
            for ((&p, lines), vote) in points.iter().zip(lines.iter_mut()).zip(&mut votes) {
                if vote.answer.is_some() {
                    continue;
                }
                lines.at = p;
                let kept = &mut lines.w[g.axis];
                kept.clear();
                vote.add(g.parity(p, kept));
            }
        }
        for (inside, vote) in inside.iter_mut().zip(&votes) {
            *inside = vote.answer == Some(true);
        }
    }

    /// [`InsideTest::exact`] at `q`, reading the ray along an axis from `lines` where `q` lies
    /// on that axis's line through the point they were kept for (its other two coordinates
    /// the same): a point pushed along an axis needs one or two walks, not three.
    pub fn exact_on_lines(&self, q: Vec3, lines: &Lines) -> bool {
        let on_line = |g: &AxisGrid| {
            g.uv.iter()
                .all(|&a| q[a].to_bits() == lines.at[a].to_bits())
        };
        // From the first axis q is on the line of, in turn (`leaves_cleanly` asks the next
        // axis at a point on the same line just before: its cell is still in the cache).
        let first = (0..3).find(|&a| on_line(&self.axes[a])).unwrap_or(0);
        vote((0..3).map(|k| (first + k) % 3).map(|a| {
            let g = &self.axes[a];
            if !on_line(g) {
                return g.odd_crossings(q);
            }
            let qw = q[a] as f64;
            let w = &lines.w[a];
            (!w.contains(&qw)).then(|| w.iter().filter(|&&w| w > qw).count() % 2 == 1)
        }))
    }

    /// [`InsideTest::inside`] by the three rays, without the voxel grid.
    pub fn exact(&self, p: Vec3) -> bool {
        vote(self.axes.iter().map(|g| g.odd_crossings(p)))
    }

    /// [`InsideTest::exact`] at a point where the ray along `axis` is known to cross the
    /// surface an even number of times: inside only when both other rays cross it an odd
    /// number of times (neither lying on the surface). One or two rays instead of three.
    pub fn exact_even_along(&self, p: Vec3, axis: usize) -> bool {
        [1, 2]
            .into_iter()
            .all(|k| self.axes[(axis + k) % 3].odd_crossings(p) == Some(true))
    }
}

/// The majority of the rays' parities (`Some(true)`: odd), drawn one ray at a time: a ray
/// on the surface (`None`) makes the point outside, and so do two even rays, whatever the
/// third says, which is then not asked (a walk saved for most points outside).
fn vote(rays: impl IntoIterator<Item = Option<bool>>) -> bool {
    let mut vote = Vote::default();
    for ray in rays {
        if let Some(answer) = vote.add(ray) {
            return answer;
        }
    }
    unreachable!("three rays decide")
}

/// The count of [`vote`], ray by ray.
#[derive(Clone, Copy, Default)]
struct Vote {
    odd: u8,
    even: u8,
    /// Inside or not, once decided.
    answer: Option<bool>,
}

impl Vote {
    /// Counts one more ray; the answer once it is decided.
    fn add(&mut self, ray: Option<bool>) -> Option<bool> {
        match ray {
            None => self.answer = Some(false),
            Some(false) if self.even == 1 => self.answer = Some(false),
            Some(false) => self.even += 1,
            Some(true) => self.odd += 1,
        }
        if self.odd + self.even == 3 {
            self.answer = Some(self.odd >= 2);
        }
        self.answer
    }
}

/// The crossings of the three axis lines through one point (axis coordinates, both ways from
/// it, in list order), kept by [`InsideTest::exact_keeping`].
#[derive(Clone, Default)]
pub struct Lines {
    at: Vec3,
    w: [Vec<f64>; 3],
}

/// The crossings of one ray as [`InsideTest::ray_crossings`] gathers them.
struct Ray {
    from: f64,
    positive: bool,
    reach: f64,
    odd: bool,
}

impl Ray {
    fn new(from: f64, positive: bool, reach: f64) -> Self {
        Ray {
            from,
            positive,
            reach,
            odd: false,
        }
    }

    /// Takes the crossing of the line at `w`; false when it is the ray's origin.
    #[inline]
    fn add(&mut self, w: f64, out: &mut Vec<f64>) -> bool {
        let s = if self.positive {
            w - self.from
        } else {
            self.from - w
        };
        if s > 0.0 {
            self.odd = !self.odd;
            if s <= self.reach {
                out.push(s);
            }
        }
        s != 0.0
    }
}

/// The triangles projected along one axis, binned in a 2D grid of about square cells.
struct AxisGrid {
    axis: usize,
    /// The two other axes (u, v).
    uv: [usize; 2],
    min: DVec2,
    cell: DVec2,
    n: [usize; 2],
    /// Triangle lists per cell, as ranges of `blocks`.
    starts: Vec<u32>,
    /// The lists, [`BLOCK`] entries at a time, each list padded to whole blocks.
    blocks: Vec<Block>,
    tris: Vec<Tri2>,
}

/// Entries of a list tested at once: one comparison instruction per bound with AVX.
const BLOCK: usize = 8;

/// [`BLOCK`] entries of a cell's list: their triangles' projected boxes by bound, read before
/// the triangles themselves (most of a list is rejected from this one contiguous stream), and
/// the triangles. A padding entry's box is empty (`lo` = +∞), so no point lies in it.
#[derive(Clone, Copy)]
#[repr(C, align(32))]
struct Block {
    lo_u: [f32; BLOCK],
    lo_v: [f32; BLOCK],
    hi_u: [f32; BLOCK],
    hi_v: [f32; BLOCK],
    items: [u32; BLOCK],
}

impl Block {
    /// The box of a padding entry: no point lies in it.
    const EMPTY_BOX: (Vec2, Vec2) = (Vec2::INFINITY, Vec2::NEG_INFINITY);

    const EMPTY: Block = Block {
        lo_u: [f32::INFINITY; BLOCK],
        lo_v: [f32::INFINITY; BLOCK],
        hi_u: [f32::NEG_INFINITY; BLOCK],
        hi_v: [f32::NEG_INFINITY; BLOCK],
        items: [0; BLOCK],
    };

    /// A bit per entry whose box holds `r` (no branch per entry: whether a box holds the
    /// point is a coin toss the branch predictor loses).
    #[inline(always)]
    fn holds(&self, r: Vec2) -> u32 {
        let mut mask = 0;
        for k in 0..BLOCK {
            let inside = (self.lo_u[k] <= r.x)
                & (self.lo_v[k] <= r.y)
                & (self.hi_u[k] >= r.x)
                & (self.hi_v[k] >= r.y);
            mask |= (inside as u32) << k;
        }
        mask
    }
}

/// The items of `blocks`' entries whose box holds `r`, in list order, written to the front of
/// `queue` (which has room for all the entries and a block more); their count. Each block's
/// mask packs its items without a branch per entry: in AVX2 instructions where the CPU has
/// them (decided once per process), the mask's bits picked by a table of lane orders, else one
/// entry at a time, each written and counted where its bit is set.
#[inline]
fn candidates(blocks: &[Block], r: Vec2, queue: &mut [MaybeUninit<u32>]) -> usize {
    assert!(queue.len() >= (blocks.len() + 1) * BLOCK);
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("popcnt") {
        // SAFETY: the CPU has AVX2 and POPCNT (checked just above); `queue` holds a block's
        // entries past all of `blocks`' (asserted above).
        return unsafe { candidates_avx2(blocks, r, queue) };
    }
    candidates_plain(blocks, r, queue)
}

/// [`candidates`] in plain Rust: each entry written and counted where its bit is set.
#[inline]
fn candidates_plain(blocks: &[Block], r: Vec2, queue: &mut [MaybeUninit<u32>]) -> usize {
    let mut len = 0;
    for b in blocks {
        let mask = b.holds(r);
        for (k, &item) in b.items.iter().enumerate() {
            queue[len].write(item);
            len += (mask >> k & 1) as usize;
        }
    }
    len
}

/// [`candidates`] in AVX2 instructions: the same comparisons, a block's per instruction.
///
/// # Safety
/// The CPU has AVX2 and POPCNT, and `queue` has room for a block's entries past all of
/// `blocks`'.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn candidates_avx2(blocks: &[Block], r: Vec2, queue: &mut [MaybeUninit<u32>]) -> usize {
    use std::arch::x86_64::*;
    let (u, v) = (_mm256_set1_ps(r.x), _mm256_set1_ps(r.y));
    let mut len = 0;
    for b in blocks {
        // SAFETY: each bound and the items are eight 4-byte values, 32-byte aligned (`Block`
        // is, and each field's offset is a multiple of 32); the store's eight lanes are within
        // `queue` (the caller's room), unaligned.
        unsafe {
            let lo = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_load_ps(b.lo_u.as_ptr()), u),
                _mm256_cmp_ps::<_CMP_LE_OQ>(_mm256_load_ps(b.lo_v.as_ptr()), v),
            );
            let hi = _mm256_and_ps(
                _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_load_ps(b.hi_u.as_ptr()), u),
                _mm256_cmp_ps::<_CMP_GE_OQ>(_mm256_load_ps(b.hi_v.as_ptr()), v),
            );
            let mask = _mm256_movemask_ps(_mm256_and_ps(lo, hi)) as usize;
            let order = _mm256_cvtepu8_epi32(_mm_cvtsi64_si128(PACK[mask] as i64));
            let items = _mm256_load_si256(b.items.as_ptr().cast());
            let packed = _mm256_permutevar8x32_epi32(items, order);
            _mm256_storeu_si256(queue.as_mut_ptr().add(len).cast(), packed);
            len += mask.count_ones() as usize;
        }
    }
    len
}

/// Per 8-bit mask, the lanes of its set bits in increasing order, a byte each from the
/// lowest (the rest 0): the permutation that packs a block's candidates.
const PACK: [u64; 256] = {
    let mut table = [0u64; 256];
    let mut mask = 0;
    while mask < 256 {
        let (mut lane, mut at) = (0, 0);
        while lane < 8 {
            if mask >> lane & 1 == 1 {
                table[mask] |= (lane as u64) << (8 * at);
                at += 1;
            }
            lane += 1;
        }
        mask += 1;
    }
    table
};

/// A cell's side in average projected triangle boxes: finer cells mean shorter lists (fewer
/// triangles to reject per query) but more entries to build, as each triangle is listed in
/// every cell its box meets.
const CELL_PER_EXTENT: f64 = 1.0;
/// Most cells per triangle kept (a few large triangles among many small ones).
const MAX_CELLS_PER_TRIANGLE: f64 = 4.0;
/// Most cells along one side of an axis grid.
const MAX_SIDE: usize = 4096;

/// A triangle as its ray sees it: counter-clockwise projection and the axis coordinate of
/// its corners. Kept in f32, as the mesh gives them (half the memory the queries read; the
/// arithmetic is in f64, from the same values).
#[derive(Clone, Copy)]
#[repr(C)]
struct Tri2 {
    p: [Vec2; 3],
    w: [f32; 3],
}

impl Tri2 {
    const ZERO: Self = Tri2 {
        p: [Vec2::ZERO; 3],
        w: [0.0; 3],
    };

    /// `t` as the ray along `AXIS` sees it (projected on the next two axes); `None` when it
    /// is parallel to the ray (never crossed). Arrays written out: `array::map` was a call
    /// per corner here, a tenth of the inside test's build.
    #[inline(always)]
    fn facing<const AXIS: usize>(t: &[Vec3; 3]) -> Option<Self> {
        let (u, v) = ((AXIS + 1) % 3, (AXIS + 2) % 3);
        let at = |p: Vec3| Vec2::new(p[u], p[v]);
        let mut p = [at(t[0]), at(t[1]), at(t[2])];
        let mut w = [t[0][AXIS], t[1][AXIS], t[2][AXIS]];
        let d = [p[0].as_dvec2(), p[1].as_dvec2(), p[2].as_dvec2()];
        let area = (d[1] - d[0]).perp_dot(d[2] - d[0]);
        if area == 0.0 || !area.is_finite() {
            return None;
        }
        if area < 0.0 {
            p.swap(1, 2);
            w.swap(1, 2);
        }
        Some(Tri2 { p, w })
    }

    #[inline]
    fn p(&self, k: usize) -> DVec2 {
        self.p[k].as_dvec2()
    }

    /// The projected box (lo, hi).
    #[inline]
    fn bounds(&self) -> (Vec2, Vec2) {
        let [a, b, c] = self.p;
        (a.min(b).min(c), a.max(b).max(c))
    }
}

impl AxisGrid {
    /// The grids of the three axes, built side by side.
    fn all(tris: &[[Vec3; 3]], bounds: &Aabb) -> [Self; 3] {
        let (x, (y, z)) = rayon::join(
            || AxisGrid::new(tris, bounds, 0),
            || {
                rayon::join(
                    || AxisGrid::new(tris, bounds, 1),
                    || AxisGrid::new(tris, bounds, 2),
                )
            },
        );
        [x, y, z]
    }

    /// Compiled for AVX2 too, where the CPU has it (the same operations, so the same grid).
    fn new(tris: &[[Vec3; 3]], bounds: &Aabb, axis: usize) -> Self {
        #[cfg(target_arch = "x86_64")]
        if std::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (checked just above).
            return unsafe { Self::new_avx2(tris, bounds, axis) };
        }
        Self::new_any(tris, bounds, axis)
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn new_avx2(tris: &[[Vec3; 3]], bounds: &Aabb, axis: usize) -> Self {
        Self::new_any(tris, bounds, axis)
    }

    #[inline(always)]
    fn new_any(tris: &[[Vec3; 3]], bounds: &Aabb, axis: usize) -> Self {
        match axis {
            0 => Self::along::<0>(tris, bounds),
            1 => Self::along::<1>(tris, bounds),
            _ => Self::along::<2>(tris, bounds),
        }
    }

    /// [`AxisGrid::new`] with the axis fixed when compiling: a corner's projected
    /// coordinates are then plain loads, not a `Vec3` indexed through the stack.
    #[inline(always)]
    fn along<const AXIS: usize>(tris: &[[Vec3; 3]], bounds: &Aabb) -> Self {
        let uv = [(AXIS + 1) % 3, (AXIS + 2) % 3];
        let proj = |v: Vec3| DVec2::new(v[uv[0]] as f64, v[uv[1]] as f64);
        // Sized up front: collected, the filter's unknown length grew it by copies.
        let mut kept: Vec<Tri2> = Vec::with_capacity(tris.len());
        kept.extend(tris.iter().filter_map(Tri2::facing::<AXIS>));
        let boxes: Vec<(Vec2, Vec2)> = kept.iter().map(Tri2::bounds).collect();
        let min = if bounds.is_empty() {
            DVec2::ZERO
        } else {
            proj(bounds.min)
        };
        let size = if bounds.is_empty() {
            DVec2::ONE
        } else {
            (proj(bounds.max) - min).max(DVec2::splat(1e-9))
        };
        // About square cells the size of an average triangle's projected box: a triangle is
        // listed in a few cells whatever the projection's aspect (a torus seen edge-on is a
        // long thin band), and a cell's list holds a few layers' worth of triangles.
        let extent: f64 = boxes
            .iter()
            .map(|(lo, hi)| (*hi - *lo).max_element() as f64)
            .sum::<f64>()
            / kept.len().max(1) as f64;
        let fine = (size.x * size.y / (kept.len() as f64 * MAX_CELLS_PER_TRIANGLE).max(1.0)).sqrt();
        let side = (CELL_PER_EXTENT * extent).max(fine);
        let n = [0, 1].map(|a| ((size[a] / side).ceil() as usize).clamp(1, MAX_SIDE));
        let cell = size / DVec2::new(n[0] as f64, n[1] as f64);
        // Clamped to the grid, then truncated, which is the floor for c >= 0 (`max` takes NaN
        // to 0).
        let last = [(n[0] - 1) as f64, (n[1] - 1) as f64];
        let cell_of = |g: DVec2| {
            // SAFETY: in [0, n − 1], which an i64 holds: the plain conversion, which
            // saturates, was ten instructions a coordinate, and one to an unsigned integer
            // seven (x86-64 converts to signed ones in one).
            unsafe {
                [
                    g.x.max(0.0).min(last[0]).to_int_unchecked::<i64>() as usize,
                    g.y.max(0.0).min(last[1]).to_int_unchecked::<i64>() as usize,
                ]
            }
        };
        // Per triangle, the first and last cell its box meets.
        let spans: Vec<[[usize; 2]; 2]> = boxes
            .iter()
            .map(|&(lo, hi)| [cell_of(grid(min, cell, lo)), cell_of(grid(min, cell, hi))])
            .collect();
        let cells = n[0] * n[1];
        let mut counts = vec![0u32; cells];
        for [l, h] in &spans {
            for j in l[1]..=h[1] {
                for c in &mut counts[j * n[0] + l[0]..=j * n[0] + h[0]] {
                    *c += 1;
                }
            }
        }
        let mut starts = vec![0u32; cells + 1];
        for c in 0..cells {
            starts[c + 1] = starts[c] + counts[c].div_ceil(BLOCK as u32);
        }
        // The triangles, their boxes and spans in the sorted order, moved there in mesh order
        // (scattered writes, which do not hold up the loop as scattered reads would).
        let rank = by_first_cell(&spans, n);
        let mut sorted = vec![(Block::EMPTY_BOX, [[0; 2]; 2]); kept.len()];
        // Zeroed, not a clone of `kept`: every entry is written below.
        let mut tris2 = vec![Tri2::ZERO; kept.len()];
        for (t, &r) in rank.iter().enumerate() {
            sorted[r as usize] = (boxes[t], spans[t]);
            tris2[r as usize] = kept[t];
        }
        let blocks = fill_blocks(&sorted, &starts, n);
        AxisGrid {
            axis: AXIS,
            uv,
            min,
            cell,
            n,
            starts,
            blocks,
            tris: tris2,
        }
    }

    /// `p` projected along the axis (an array read: indexing a `Vec3` by a run-time axis is
    /// a branch per coordinate).
    #[inline]
    fn project(&self, p: Vec3) -> Vec2 {
        let a = p.to_array();
        Vec2::new(a[self.uv[0]], a[self.uv[1]])
    }

    /// The cell whose list holds the triangles the line through `p` can cross; `None`
    /// beyond the box (no triangle there).
    #[inline]
    fn cell_of(&self, p: Vec3) -> Option<usize> {
        self.cell_at(self.project(p))
    }

    /// [`AxisGrid::cell_of`] for the projection `r` of the point.
    #[inline]
    fn cell_at(&self, r: Vec2) -> Option<usize> {
        let c = grid(self.min, self.cell, r);
        // On the box's far side (the cell's floor is n): the last cell, as the binning clamps.
        // (The conversion below truncates, the floor for c >= 0; `floor` itself is a library
        // call on x86-64 without SSE4.1.)
        let n = DVec2::new(self.n[0] as f64, self.n[1] as f64) + 1.0;
        if !(c.x >= 0.0 && c.y >= 0.0 && c.x < n.x && c.y < n.y) {
            return None;
        }
        // SAFETY: in [0, n + 1) (tested just above), which an i64 holds: the plain
        // conversion, which saturates, was ten instructions a coordinate, and one to an
        // unsigned integer seven (see `along`).
        let (x, y) = unsafe {
            (
                c.x.to_int_unchecked::<i64>() as usize,
                c.y.to_int_unchecked::<i64>() as usize,
            )
        };
        Some(y.min(self.n[1] - 1) * self.n[0] + x.min(self.n[0] - 1))
    }

    /// Gives `visit` the axis coordinate of each place where the line through `p` along the
    /// axis crosses a triangle (both ways from `p`, in list order), four candidates at a time,
    /// until it says stop; `None` beyond the box (no triangle there), else whether all were
    /// visited. A triangle whose projected box does not hold `p`'s projection is not crossed
    /// (the premise of the binning, taken down from cells to single boxes).
    ///
    /// Without a branch on any one candidate: a block's boxes that hold the point are packed
    /// into a queue by their mask, and the queue goes four at a time through [`crossings`].
    /// Taken one set bit at a time, then queued four at a time and visited one crossing at a
    /// time, the candidates' loops were branches whose counts the predictor could not know:
    /// 60% of the drape's mispredictions (cachegrind's branch simulation).
    #[inline]
    fn each_hit(&self, p: Vec3, visit: &mut impl Visit) -> Option<bool> {
        let r = self.project(p);
        let q = r.as_dvec2();
        let cell = self.cell_at(r)?;
        let list = &self.blocks[self.starts[cell] as usize..self.starts[cell + 1] as usize];
        // A chunk's candidates, and room for a block's eight past them (not zeroed first: a
        // walk reads only what `candidates` wrote).
        let mut queue = [MaybeUninit::<u32>::uninit(); WALK_BLOCKS * BLOCK + BLOCK];
        for chunk in list.chunks(WALK_BLOCKS) {
            let len = candidates(chunk, r, &mut queue);
            // SAFETY: `candidates` wrote the first `len`.
            let found = unsafe { std::slice::from_raw_parts(queue.as_ptr().cast::<u32>(), len) };
            for four in found.chunks(CROSS_LANES) {
                let (w, hits) = crossings(&self.tris, four, q);
                if !visit.four(&w, hits) {
                    return Some(false);
                }
            }
        }
        Some(true)
    }

    /// Whether the ray from `p` along the axis crosses the surface an odd number of times;
    /// `None` when `p` lies on a triangle the ray meets.
    fn odd_crossings(&self, p: Vec3) -> Option<bool> {
        self.parity(p, ())
    }

    /// [`AxisGrid::odd_crossings`], giving `keep` the line's crossings.
    #[inline]
    fn parity(&self, p: Vec3, keep: impl Keep) -> Option<bool> {
        let mut parity = Parity {
            pw: p[self.axis] as f64,
            odd: false,
            on: false,
            keep,
        };
        // Beyond the box (no walk): no crossing, even.
        self.each_hit(p, &mut parity);
        (!parity.on).then_some(parity.odd)
    }
}

/// Blocks of a list a walk tests at once ([`AxisGrid::each_hit`]).
const WALK_BLOCKS: usize = 16;

/// What a walk does with the crossings it finds ([`AxisGrid::each_hit`]).
trait Visit {
    /// The crossings at `w` of the candidates whose bit is set in `hits`, in list order;
    /// false to stop the walk.
    fn four(&mut self, w: &[f64; CROSS_LANES], hits: u32) -> bool;
}

/// A visitor of one crossing at a time, until it returns false.
struct EachCrossing<F>(F);

impl<F: FnMut(f64) -> bool> Visit for EachCrossing<F> {
    #[inline]
    fn four(&mut self, w: &[f64; CROSS_LANES], mut hits: u32) -> bool {
        while hits != 0 {
            let l = hits.trailing_zeros() as usize;
            hits &= hits - 1;
            if !(self.0)(w[l]) {
                return false;
            }
        }
        true
    }
}

/// The parity of a line's crossings beyond `pw` (its point's axis coordinate), and whether
/// one is at `pw` itself (the point lies on a triangle the line meets: then the walk stops),
/// lane by lane with no branch (where a candidate is crossed is a coin toss to the
/// predictor); `keep` takes the crossings.
struct Parity<K> {
    pw: f64,
    odd: bool,
    on: bool,
    keep: K,
}

impl<K: Keep> Visit for Parity<K> {
    #[inline]
    fn four(&mut self, w: &[f64; CROSS_LANES], hits: u32) -> bool {
        for (l, &w) in w.iter().enumerate() {
            let hit = hits >> l & 1 == 1;
            self.odd ^= hit & (w > self.pw);
            self.on |= hit & (w == self.pw);
        }
        self.keep.four(w, hits);
        !self.on
    }
}

/// Where [`Parity`] keeps the crossings: nowhere, or appended to a list.
trait Keep {
    fn four(&mut self, w: &[f64; CROSS_LANES], hits: u32);
}

impl Keep for () {
    #[inline]
    fn four(&mut self, _: &[f64; CROSS_LANES], _: u32) {}
}

impl Keep for &mut Vec<f64> {
    /// Appends the crossings of the set lanes, in order, without a branch per lane.
    #[inline]
    fn four(&mut self, w: &[f64; CROSS_LANES], hits: u32) {
        let mut len = self.len();
        self.extend_from_slice(w);
        for (l, &w) in w.iter().enumerate() {
            self[len] = w;
            len += (hits >> l & 1) as usize;
        }
        self.truncate(len);
    }
}

/// Crossings computed together: four f64 lanes of one AVX register.
const CROSS_LANES: usize = 4;

/// [`crossing`] of each of the triangles `four` names in `tris` (one to [`CROSS_LANES`]): the
/// crossings' axis coordinates and a bit per triangle crossed. AVX where the CPU has it
/// (decided once per process): the same operations in the same order, so the same bits, and
/// no branch per triangle (whether a candidate is crossed is a coin toss to the predictor).
#[inline]
fn crossings(tris: &[Tri2], four: &[u32], q: DVec2) -> ([f64; CROSS_LANES], u32) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx") {
        // SAFETY: the CPU has AVX (checked just above).
        return unsafe { crossings_avx(tris, four, q) };
    }
    let mut out = ([0.0; CROSS_LANES], 0);
    for (l, &t) in four.iter().enumerate() {
        if let Some(w) = crossing(&tris[t as usize], q) {
            out.0[l] = w;
            out.1 |= 1 << l;
        }
    }
    out
}

/// [`crossings`] in AVX instructions, lane `l` the operations of [`crossing`] on its `l`th
/// triangle (lanes past the end repeat the last triangle and are masked off).
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx")]
fn crossings_avx(tris: &[Tri2], four: &[u32], q: DVec2) -> ([f64; CROSS_LANES], u32) {
    use std::arch::x86_64::*;
    let last = four.len() - 1;
    let t: [&Tri2; CROSS_LANES] = std::array::from_fn(|l| &tris[four[l.min(last)] as usize]);
    // The four triangles' first eight floats (p0, p1, p2, w0, w1) transposed in registers:
    // after the unpacks and shuffles, row k holds float k of the four in its low half and
    // float k + 4 in its high half. (Gathered float by float, the rows cost 36 loads.)
    // SAFETY: a `Tri2` is nine f32s in order (`repr(C)`): eight are read, unaligned.
    let load = |t: &Tri2| unsafe { _mm256_loadu_ps((t as *const Tri2).cast::<f32>()) };
    let (a, b, c, d) = (load(t[0]), load(t[1]), load(t[2]), load(t[3]));
    let (ab_lo, ab_hi) = (_mm256_unpacklo_ps(a, b), _mm256_unpackhi_ps(a, b));
    let (cd_lo, cd_hi) = (_mm256_unpacklo_ps(c, d), _mm256_unpackhi_ps(c, d));
    let rows = [
        _mm256_shuffle_ps::<0x44>(ab_lo, cd_lo),
        _mm256_shuffle_ps::<0xEE>(ab_lo, cd_lo),
        _mm256_shuffle_ps::<0x44>(ab_hi, cd_hi),
        _mm256_shuffle_ps::<0xEE>(ab_hi, cd_hi),
    ];
    // Float k of the four, widened exactly to f64.
    let float = |k: usize| {
        let r = rows[k % 4];
        let half = if k < 4 {
            _mm256_castps256_ps128(r)
        } else {
            _mm256_extractf128_ps::<1>(r)
        };
        _mm256_cvtps_pd(half)
    };
    let pu = [float(0), float(2), float(4)];
    let pv = [float(1), float(3), float(5)];
    let w2 = _mm_set_ps(t[3].w[2], t[2].w[2], t[1].w[2], t[0].w[2]);
    let pw = [float(6), float(7), _mm256_cvtps_pd(w2)];
    let (qu, qv) = (_mm256_set1_pd(q.x), _mm256_set1_pd(q.y));
    let zero = _mm256_setzero_pd();
    // Edge k (corner k+1 to corner k+2): its function at q, and whether q counts on it.
    let edge = |k: usize| {
        let (a, c) = ((k + 1) % 3, (k + 2) % 3);
        let (du, dv) = (_mm256_sub_pd(pu[c], pu[a]), _mm256_sub_pd(pv[c], pv[a]));
        // d.perp_dot(q - a) = d.x (q - a).y - d.y (q - a).x
        let e = _mm256_sub_pd(
            _mm256_mul_pd(du, _mm256_sub_pd(qv, pv[a])),
            _mm256_mul_pd(dv, _mm256_sub_pd(qu, pu[a])),
        );
        let owns = _mm256_or_pd(
            _mm256_cmp_pd::<_CMP_GT_OQ>(dv, zero),
            _mm256_and_pd(
                _mm256_cmp_pd::<_CMP_EQ_OQ>(dv, zero),
                _mm256_cmp_pd::<_CMP_LT_OQ>(du, zero),
            ),
        );
        let counts = _mm256_or_pd(
            _mm256_cmp_pd::<_CMP_GT_OQ>(e, zero),
            _mm256_and_pd(_mm256_cmp_pd::<_CMP_EQ_OQ>(e, zero), owns),
        );
        (e, counts)
    };
    let ((e0, k0), (e1, k1), (e2, k2)) = (edge(0), edge(1), edge(2));
    let sum = _mm256_add_pd(_mm256_add_pd(e0, e1), e2);
    let hit = _mm256_and_pd(
        _mm256_and_pd(k0, k1),
        _mm256_and_pd(k2, _mm256_cmp_pd::<_CMP_GT_OQ>(sum, zero)),
    );
    let num = _mm256_add_pd(
        _mm256_add_pd(_mm256_mul_pd(e0, pw[0]), _mm256_mul_pd(e1, pw[1])),
        _mm256_mul_pd(e2, pw[2]),
    );
    let mut w = [0.0; CROSS_LANES];
    // SAFETY: `w` is four f64s (an unaligned store).
    unsafe { _mm256_storeu_pd(w.as_mut_ptr(), _mm256_div_pd(num, sum)) };
    let live = (1u32 << four.len()) - 1;
    (w, _mm256_movemask_pd(hit) as u32 & live)
}

/// A projected point in a grid's coordinates (cells from `min`; the cell's index is the floor).
#[inline]
fn grid(min: DVec2, cell: DVec2, x: Vec2) -> DVec2 {
    (x.as_dvec2() - min) / cell
}

/// The cells' lists (`starts`: each cell's first block), filled with the triangles' boxes in
/// the sorted order (`sorted`: each triangle's box and the first and last cell it meets, in
/// a grid of `n` cells); a list's last block is padded with empty boxes.
#[allow(clippy::type_complexity)]
#[inline(always)]
fn fill_blocks(
    sorted: &[((Vec2, Vec2), [[usize; 2]; 2])],
    starts: &[u32],
    n: [usize; 2],
) -> Vec<Block> {
    let cells = n[0] * n[1];
    let mut blocks = vec![Block::EMPTY; starts[cells] as usize];
    // The next free entry of each cell's list.
    let mut fill: Vec<u32> = starts[..cells].iter().map(|&s| s * BLOCK as u32).collect();
    for (t, &((lo, hi), [l, h])) in sorted.iter().enumerate() {
        for j in l[1]..=h[1] {
            for f in &mut fill[j * n[0] + l[0]..=j * n[0] + h[0]] {
                let (b, k) = (*f as usize / BLOCK, *f as usize % BLOCK);
                let b = &mut blocks[b];
                (b.lo_u[k], b.lo_v[k], b.hi_u[k], b.hi_v[k]) = (lo.x, lo.y, hi.x, hi.y);
                b.items[k] = t as u32;
                *f += 1;
            }
        }
    }
    blocks
}

/// Each triangle's place in the order by the cell its box starts in (a counting sort:
/// stable, in the mesh's order within a cell). A query reads the triangles of a few
/// neighbouring cells, then close together in memory, not spread over the mesh's order; the
/// answers do not depend on the order of a list.
fn by_first_cell(spans: &[[[usize; 2]; 2]], n: [usize; 2]) -> Vec<u32> {
    let key = |s: &[[usize; 2]; 2]| s[0][1] * n[0] + s[0][0];
    let mut next = vec![0u32; n[0] * n[1] + 1];
    for s in spans {
        next[key(s) + 1] += 1;
    }
    for c in 1..next.len() {
        next[c] += next[c - 1];
    }
    spans
        .iter()
        .map(|s| {
            let at = &mut next[key(s)];
            *at += 1;
            *at - 1
        })
        .collect()
}

/// Where the ray through `q` crosses the triangle (its axis coordinate), if it does. An edge
/// owns the points on it when it runs "up" (dv > 0, or dv = 0 and du < 0): of two triangles
/// sharing an edge (traversed in opposite directions), exactly one owns it.
#[inline]
fn crossing(t: &Tri2, q: DVec2) -> Option<f64> {
    // All three edges, then one branch: which edge rejects a point is unpredictable, and a
    // mispredicted branch costs more than the arithmetic it skips.
    let edge = |k: usize| {
        let a = t.p((k + 1) % 3);
        let c = t.p((k + 2) % 3);
        let d = c - a;
        let e = d.perp_dot(q - a);
        // `|` and `&`, not `||` and `&&`: no branches.
        let owns = (d.y > 0.0) | ((d.y == 0.0) & (d.x < 0.0));
        (e, (e > 0.0) | ((e == 0.0) & owns))
    };
    let ((e0, k0), (e1, k1), (e2, k2)) = (edge(0), edge(1), edge(2));
    let sum = e0 + e1 + e2;
    if !(k0 & k1 & k2 & (sum > 0.0)) {
        return None;
    }
    let w = t.w.map(f64::from);
    Some((e0 * w[0] + e1 * w[1] + e2 * w[2]) / sum)
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::mesh::primitives::{cuboid, torus, uv_sphere};

    /// A deterministic generator of uniform numbers in [0, 1).
    struct Rng(u64);
    impl Rng {
        fn next(&mut self) -> f32 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            (self.0 >> 40) as f32 / (1u64 << 24) as f32
        }
        fn vec(&mut self) -> Vec3 {
            Vec3::new(self.next(), self.next(), self.next())
        }
    }

    /// A uniform point on a random triangle of `mesh`.
    fn point_on(mesh: &Mesh, rng: &mut Rng) -> Vec3 {
        let tri = mesh.triangle((rng.next() * mesh.triangles.len() as f32) as usize);
        let (u, v) = (rng.next(), rng.next());
        let (u, v) = if u + v > 1.0 {
            (1.0 - u, 1.0 - v)
        } else {
            (u, v)
        };
        tri[0] + u * (tri[1] - tri[0]) + v * (tri[2] - tri[0])
    }

    fn boxed(min: Vec3, max: Vec3) -> Mesh {
        let mut m = cuboid(0.5 * (max - min), 2);
        let c = 0.5 * (min + max);
        for p in &mut m.positions {
            *p += c;
        }
        m
    }

    /// Checks the grid's answers against the rays on random points in and around the bounds,
    /// on the triangles, near them (several scales) and at the vertices; returns the share of
    /// the points the grid answered.
    fn same_as_exact(mesh: &Mesh, seed: u64) -> f64 {
        let t = InsideTest::new(mesh);
        let grid = t.cells.as_ref().expect("closed mesh: grid built");
        let b = mesh.bounds();
        let (lo, size) = (b.min - 0.2 * (b.max - b.min), 1.4 * (b.max - b.min));
        let mut rng = Rng(seed);
        let mut points: Vec<Vec3> = mesh.positions.clone();
        for _ in 0..100_000 {
            points.push(lo + rng.vec() * size);
        }
        for _ in 0..100_000 {
            let on = point_on(mesh, &mut rng);
            points.push(on);
            let scale = [1e-1, 1e-2, 1e-3, 1e-5, 1e-7][(rng.next() * 5.0) as usize];
            points.push(on + (rng.vec() - 0.5) * scale);
        }
        // Points on a lattice (grazing rays through edges and face planes of boxes).
        for i in 0..=24 {
            for j in 0..=24 {
                for k in 0..=24 {
                    points.push(lo + Vec3::new(i as f32, j as f32, k as f32) / 24.0 * size);
                }
            }
        }
        let mut fast = 0usize;
        for &p in &points {
            assert_eq!(t.inside(p), t.exact(p), "{p:?}");
            if grid.index(p).is_some_and(|c| grid.state[c] != NEAR) {
                fast += 1;
            }
        }
        fast as f64 / points.len() as f64
    }

    #[test]
    fn grid_answers_equal_exact() {
        let tor = same_as_exact(&torus(0.5, 0.2, 250, 100), 1);
        let cube = same_as_exact(&cuboid(Vec3::new(0.5, 0.3, 0.2), 4), 2);
        let mut u = boxed(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.3, 0.8));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.0), Vec3::new(0.5, 1.0, 0.6)));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.7), Vec3::new(0.5, 1.0, 0.8)));
        let ub = same_as_exact(&u, 3);
        // The grid does answer a good share (not only the rays).
        for share in [tor, cube, ub] {
            assert!(share > 0.05, "{tor} {cube} {ub}");
        }
    }

    /// The bins and the boxes drop only triangles the ray cannot cross: each axis's answer
    /// equals that of a walk over all its triangles, at random points, on and near the
    /// triangles (several scales) and at the vertices.
    #[test]
    fn bins_answer_as_all_triangles() {
        let mut u = boxed(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.3, 0.8));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.0), Vec3::new(0.5, 1.0, 0.6)));
        // A sphere of thin wedges: its poles' cells list hundreds of triangles (more than one
        // chunk of blocks per walk).
        let wedges = uv_sphere(1.0, 300, 8);
        for (mesh, seed) in [(torus(0.5, 0.2, 60, 24), 5), (u, 6), (wedges, 7)] {
            let t = InsideTest::rays_only(&mesh);
            let longest = |g: &AxisGrid| g.starts.windows(2).map(|w| w[1] - w[0]).max();
            if seed == 7 {
                assert!(t.axes.iter().any(|g| longest(g) > Some(32)));
            }
            let b = mesh.bounds();
            let (lo, size) = (b.min - 0.1 * (b.max - b.min), 1.2 * (b.max - b.min));
            let mut rng = Rng(seed);
            let mut points: Vec<Vec3> = mesh.positions.clone();
            for _ in 0..4_000 {
                points.push(lo + rng.vec() * size);
                let on = point_on(&mesh, &mut rng);
                points.push(on);
                let scale = [1e-2, 1e-4, 1e-6, 1e-7][(rng.next() * 4.0) as usize];
                points.push(on + (rng.vec() - 0.5) * scale);
            }
            for g in &t.axes {
                for &p in &points {
                    let q = DVec2::new(p[g.uv[0]] as f64, p[g.uv[1]] as f64);
                    let pw = p[g.axis] as f64;
                    let mut all = Some(false);
                    for tri in &g.tris {
                        match crossing(tri, q) {
                            Some(w) if w == pw => {
                                all = None;
                                break;
                            }
                            Some(w) if w > pw => all = all.map(|o| !o),
                            _ => {}
                        }
                    }
                    assert_eq!(g.odd_crossings(p), all, "axis {} at {p:?}", g.axis);
                }
            }
        }
    }

    /// A chunk's candidates (packed by the AVX2 build where the CPU has it, and by the plain
    /// one) are the items of the entries whose box holds the point by plain Rust's masks, in
    /// list order, at random
    /// points and at the boxes' own corners (the bounds are inclusive), padding included.
    #[test]
    fn candidates_are_the_boxes_holding_the_point_in_order() {
        let t = InsideTest::rays_only(&torus(0.5, 0.2, 60, 24));
        let mut rng = Rng(9);
        let mut queue = [MaybeUninit::<u32>::uninit(); 33 * BLOCK];
        let (mut found, mut most) = (0, 0);
        for g in &t.axes {
            let b = &g.blocks;
            let mut points: Vec<Vec2> = (0..2000)
                .map(|_| {
                    let f = Vec2::new(rng.next(), rng.next()) * 1.2 - 0.1;
                    (g.min + f.as_dvec2() * g.cell * DVec2::new(g.n[0] as f64, g.n[1] as f64))
                        .as_vec2()
                })
                .collect();
            points.extend(b.iter().take(200).flat_map(|b| {
                (0..BLOCK).flat_map(move |k| {
                    [
                        Vec2::new(b.lo_u[k], b.lo_v[k]),
                        Vec2::new(b.hi_u[k], b.hi_v[k]),
                    ]
                })
            }));
            for &r in &points {
                for chunk in b.chunks(32) {
                    let want: Vec<u32> = (chunk.iter())
                        .flat_map(|blk| {
                            (0..BLOCK)
                                .filter(|&k| blk.holds(r) >> k & 1 == 1)
                                .map(|k| blk.items[k])
                        })
                        .collect();
                    // The build this CPU takes, and the plain one (the fallback elsewhere).
                    for build in [candidates, candidates_plain] {
                        let len = build(chunk, r, &mut queue);
                        // SAFETY: `build` wrote the first `len`.
                        let got: Vec<u32> = queue[..len]
                            .iter()
                            .map(|c| unsafe { c.assume_init() })
                            .collect();
                        assert_eq!(got, want, "axis {} at {r:?}", g.axis);
                    }
                    (found, most) = (found + want.len(), most.max(want.len()));
                }
            }
            assert!(
                b.iter()
                    .any(|blk| blk.holds(Vec2::new(blk.lo_u[0], blk.lo_v[0])) & 1 == 1)
            );
        }
        // Blocks with several candidates, and with more than one block's worth in a chunk.
        assert!(
            found > 10_000 && most > BLOCK,
            "{found} candidates, at most {most}"
        );
    }

    /// The grids are the same bits from the AVX2 build of their construction as from the
    /// plain one: the cells, the lists' blocks (padding included) and the triangles.
    #[test]
    fn grids_same_in_both_builds() {
        let mut u = boxed(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.3, 0.8));
        u.append(&boxed(Vec3::new(-0.5, 0.3, 0.0), Vec3::new(0.5, 1.0, 0.6)));
        for mesh in [torus(0.5, 0.2, 60, 24), u, uv_sphere(1.0, 300, 8)] {
            let tris: Vec<[Vec3; 3]> = (0..mesh.triangles.len())
                .map(|t| mesh.triangle(t))
                .collect();
            for axis in 0..3 {
                let a = AxisGrid::new(&tris, &mesh.bounds(), axis);
                let b = AxisGrid::new_any(&tris, &mesh.bounds(), axis);
                assert_eq!(
                    (a.min, a.cell, a.n, &a.starts),
                    (b.min, b.cell, b.n, &b.starts)
                );
                let bits = |g: &AxisGrid| -> Vec<u32> {
                    let blocks = g.blocks.iter().flat_map(|k| {
                        let bounds = [k.lo_u, k.lo_v, k.hi_u, k.hi_v];
                        let floats = bounds.into_iter().flatten().map(f32::to_bits);
                        floats.chain(k.items).collect::<Vec<_>>()
                    });
                    let corners = g.tris.iter().flat_map(|t| {
                        let p = t.p.iter().flat_map(|p| p.to_array());
                        p.chain(t.w).map(f32::to_bits).collect::<Vec<_>>()
                    });
                    blocks.chain(corners).collect()
                };
                assert_eq!(bits(&a), bits(&b), "axis {axis}");
                assert!(!a.blocks.is_empty() && !a.tris.is_empty());
            }
        }
    }

    /// The crossings four at a time (AVX here) are [`crossing`]'s, bit for bit, lane by lane:
    /// random points against a torus's projected triangles, and points on their corners and
    /// edge midpoints, where the half-open edge rule decides; any count of candidates.
    #[test]
    fn crossings_together_are_crossing_each() {
        let t = InsideTest::rays_only(&torus(0.5, 0.2, 60, 24));
        let mut rng = Rng(5);
        let (mut hits, mut on_corners) = (0, 0);
        for g in &t.axes {
            for (i, four) in g.tris.chunks(CROSS_LANES).enumerate().take(800) {
                // One to four of them, by index, not in order.
                let at = (i * CROSS_LANES) as u32;
                let picks: Vec<u32> = [2, 0, 3, 1]
                    .into_iter()
                    .filter(|&o| o < four.len() as u32)
                    .map(|o| at + o)
                    .take(1 + i % 4)
                    .collect();
                let t0 = &g.tris[picks[0] as usize];
                let corner = t0.p(i % 3);
                let points = [
                    DVec2::new(rng.next() as f64, rng.next() as f64) * 1.4 - 0.7,
                    corner,
                    (corner + t0.p((i + 1) % 3)) * 0.5,
                    (t0.p(0) + t0.p(1) + t0.p(2)) / 3.0,
                ];
                for q in points {
                    let (w, mask) = crossings(&g.tris, &picks, q);
                    for (l, &tri) in picks.iter().enumerate() {
                        let want = crossing(&g.tris[tri as usize], q);
                        assert_eq!(mask >> l & 1 == 1, want.is_some(), "axis {} {q:?}", g.axis);
                        if let Some(want) = want {
                            assert_eq!(w[l].to_bits(), want.to_bits());
                            hits += 1;
                            on_corners += (q == corner) as usize;
                        }
                    }
                    assert_eq!(mask >> picks.len(), 0);
                }
            }
        }
        assert!(
            hits > 2000 && on_corners > 100,
            "{hits} hits, {on_corners} on corners"
        );
    }

    /// The vote that stops at two even rays answers as all three rays asked: `exact`,
    /// `exact_keeping` and `exact_on_lines` (at points moved along an axis, on the surface
    /// and off it) against the plain majority, where a ray on the surface makes it outside.
    #[test]
    fn the_short_vote_is_the_majority_of_three() {
        let all = [None, Some(false), Some(true)];
        for a in all {
            for b in all {
                for c in all {
                    let plain = [a, b, c].iter().all(Option::is_some)
                        && [a, b, c].iter().filter(|&&r| r == Some(true)).count() >= 2;
                    assert_eq!(vote([a, b, c]), plain, "{a:?} {b:?} {c:?}");
                }
            }
        }
        let mesh = torus(0.5, 0.2, 60, 24);
        let t = InsideTest::rays_only(&mesh);
        let majority = |p: Vec3| {
            let rays = t.axes.each_ref().map(|g| g.odd_crossings(p));
            rays.iter().all(Option::is_some) && rays.iter().flatten().filter(|&&o| o).count() >= 2
        };
        let mut rng = Rng(11);
        let points: Vec<Vec3> = (0..6_000)
            .map(|k| match k % 3 {
                0 => (rng.vec() - 0.5) * 1.6,
                1 => point_on(&mesh, &mut rng),
                _ => mesh.positions[k % mesh.positions.len()],
            })
            .collect();
        // All points in one batch: the points decided after two rays sit among those that
        // need the third.
        let mut lines = vec![Lines::default(); points.len()];
        let mut kept = vec![false; points.len()];
        t.exact_keeping(&points, &mut lines, &mut kept);
        let (mut inside, mut moved_in) = (0, 0);
        for (k, (&p, lines)) in points.iter().zip(&lines).enumerate() {
            assert_eq!(t.exact(p), majority(p), "{p:?}");
            assert_eq!(kept[k], majority(p), "{p:?}");
            inside += majority(p) as usize;
            if majority(p) {
                let mut q = p;
                q[k % 3] += (rng.next() - 0.5) * 0.2;
                assert_eq!(t.exact_on_lines(q, lines), majority(q), "{p:?} to {q:?}");
                moved_in += majority(q) as usize;
            }
        }
        // Both answers are met often enough for the comparisons to mean something.
        assert!(inside > 500 && moved_in > 200, "{inside} {moved_in}");
    }

    /// The locality order visits every point once (those beyond the grid too), cell by
    /// cell of the y grid in increasing order.
    #[test]
    fn locality_order_is_a_permutation_by_cell() {
        let t = InsideTest::rays_only(&torus(0.5, 0.2, 60, 24));
        let mut rng = Rng(12);
        let points: Vec<Vec3> = (0..5_000).map(|_| (rng.vec() - 0.5) * 2.5).collect();
        let order = t.locality_order(&points);
        let mut seen = vec![false; points.len()];
        for &i in &order {
            assert!(!std::mem::replace(&mut seen[i as usize], true));
        }
        assert!(seen.iter().all(|&s| s));
        let cell = |i: &u32| t.axes[1].cell_of(points[*i as usize]).unwrap_or(usize::MAX);
        assert!(order.windows(2).all(|w| cell(&w[0]) <= cell(&w[1])));
        assert!(order.iter().any(|i| cell(i) == usize::MAX));
    }

    #[test]
    fn open_mesh_has_no_grid() {
        let mut m = cuboid(Vec3::splat(0.5), 2);
        m.triangles.pop();
        assert!(InsideTest::new(&m).cells.is_none());
    }

    #[test]
    fn sphere_and_touching_boxes() {
        let s = InsideTest::new(&uv_sphere(1.0, 32, 16));
        assert!(s.inside(Vec3::ZERO));
        assert!(s.inside(Vec3::new(0.3, -0.5, 0.6)));
        assert!(!s.inside(Vec3::new(0.8, 0.8, 0.0)));
        assert!(!s.inside(Vec3::new(3.0, 0.0, 0.0)));
        // Two unit boxes sharing the face x = 0: the shared face is crossed twice.
        let mut m = cuboid(Vec3::splat(0.5), 3);
        let mut right = m.clone();
        for p in &mut m.positions {
            p.x -= 0.5;
        }
        for p in &mut right.positions {
            p.x += 0.5;
        }
        m.append(&right);
        let t = InsideTest::new(&m);
        for x in [-0.9, -0.5 + 1e-3, 0.1, 0.7] {
            assert!(t.inside(Vec3::new(x, 0.1, -0.2)), "{x}");
        }
        assert!(!t.inside(Vec3::new(1.2, 0.0, 0.0)));
        // Exactly on the surface: outside.
        assert!(!t.inside(Vec3::new(1.0, 0.0, 0.0)));
    }
}
