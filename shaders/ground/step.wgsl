// The ground's frame passes (crates/imprint-stages/src/ground/gpu.rs), the integer passes of
// ground/cpu.rs and ground/contour.rs one dispatch each. Everything works on the frame's work
// window (w x h cells at (i0, k0) of a field nx wide, x fastest); `heights` is the whole
// field. Every pass reads what earlier dispatches wrote and writes values no other invocation
// of the same dispatch reads, or adds with atomics (integer sums: order-free), so the result
// is the CPU's bit for bit.
//
// 64-bit counters (carries, sums) are pairs of u32 words (lo, hi), added with two atomics:
// the sum mod 2^64 does not depend on the order the halves land in.

struct Params {
    nx: u32,
    i0: u32,
    k0: u32,
    w: u32,
    h: u32,
    // Outer map width in rings (slump_band).
    band: u32,
    // Slump threshold T, units (clamped to i32::MAX: nothing exceeds it then).
    t: u32,
    // Displacement level l, or slump ring k.
    level: u32,
    // Slump pass index (its `moved` counter).
    pass_index: u32,
    // dist_rows: 0 = seeds are the cells outside the contact (inner map), 1 = the contact.
    mode: u32,
    _pad0: u32,
    _pad1: u32,
}

const UNLABELLED: u32 = 0xffffffffu;
const I32_MAX: u32 = 0x7fffffffu;

// Stats words: see gpu.rs (`STAT_*`).
const STAT_MAX_LEVEL: u32 = 0u;
const STAT_LABELLED: u32 = 1u;
const STAT_MAX_DIFF: u32 = 2u;
const STAT_DISPLACED: u32 = 4u;
const STAT_MOVED: u32 = 8u;

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read_write> heights: array<i32>;
@group(0) @binding(2) var<storage, read> bottom: array<i32>;
@group(0) @binding(3) var<storage, read_write> contact: array<u32>;
@group(0) @binding(4) var<storage, read_write> tmp: array<u32>;
@group(0) @binding(5) var<storage, read_write> inner: array<u32>;
@group(0) @binding(6) var<storage, read_write> outer: array<u32>;
@group(0) @binding(7) var<storage, read_write> carry: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> steep: array<u32>;
@group(0) @binding(9) var<storage, read_write> delta: array<i32>;
@group(0) @binding(10) var<storage, read_write> stats: array<atomic<u32>>;

fn global_index(j: u32) -> u32 {
    return (p.k0 + j / p.w) * p.nx + p.i0 + j % p.w;
}

fn sat1(d: u32) -> u32 {
    return select(d + 1u, UNLABELLED, d == UNLABELLED);
}

// Adds the 64-bit value (lo, hi) to the pair of words at `word` of `carry`.
fn carry_add(word: u32, lo: u32, hi: u32) {
    let old = atomicAdd(&carry[word], lo);
    let c = select(0u, 1u, old + lo < old);
    if (hi + c != 0u) {
        atomicAdd(&carry[word + 1u], hi + c);
    }
}

fn stats_add(word: u32, lo: u32, hi: u32) {
    let old = atomicAdd(&stats[word], lo);
    let c = select(0u, 1u, old + lo < old);
    if (hi + c != 0u) {
        atomicAdd(&stats[word + 1u], hi + c);
    }
}

// The 4-neighbours of window cell j in the CPU's order -x, +x, -z, +z; UNLABELLED beyond the
// window.
fn neighbour(j: u32, t: u32) -> u32 {
    let x = j % p.w;
    let y = j / p.w;
    switch t {
        case 0u: { return select(UNLABELLED, j - 1u, x > 0u); }
        case 1u: { return select(UNLABELLED, j + 1u, x + 1u < p.w); }
        case 2u: { return select(UNLABELLED, j - p.w, y > 0u); }
        default: { return select(UNLABELLED, j + p.w, y + 1u < p.h); }
    }
}

// O 2.3, first half: contact = bottom below the ground; contact cells drop to the bottom.
@compute @workgroup_size(64)
fn press(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h) {
        return;
    }
    let g = global_index(j);
    let c = bottom[j] < heights[g];
    contact[j] = select(0u, 1u, c);
    if (c) {
        heights[g] = bottom[j];
    }
}

// L1 distance, first separable pass: per row, the distance along the row to the nearest seed
// (UNLABELLED when the row has none). One invocation per row.
@compute @workgroup_size(64)
fn dist_rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let y = thread_index(gid, nw);
    if (y >= p.h) {
        return;
    }
    let base = y * p.w;
    var d = UNLABELLED;
    for (var x = 0u; x < p.w; x++) {
        // mode 0: the cells outside the contact (contact 0); mode 1: the contact (1).
        let seed = contact[base + x] == p.mode;
        d = select(sat1(d), 0u, seed);
        tmp[base + x] = d;
    }
    d = UNLABELLED;
    for (var x = p.w; x > 0u; x--) {
        let j = base + x - 1u;
        d = min(sat1(d), tmp[j]);
        tmp[j] = d;
    }
}

// Second pass: per column, min over the column of row distance + |dy| (two scans), which is
// the exact L1 distance. mode 0 writes the inner map and its deepest level; mode 1 the outer
// map (contact and beyond the band unlabelled, rim = 0) and its cell count.
@compute @workgroup_size(64)
fn dist_cols(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let x = thread_index(gid, nw);
    if (x >= p.w) {
        return;
    }
    var d = UNLABELLED;
    for (var y = 0u; y < p.h; y++) {
        let j = y * p.w + x;
        d = min(sat1(d), tmp[j]);
        tmp[j] = d;
    }
    d = UNLABELLED;
    var deepest = 0u;
    var labelled = 0u;
    for (var y = p.h; y > 0u; y--) {
        let j = (y - 1u) * p.w + x;
        d = min(sat1(d), tmp[j]);
        if (p.mode == 0u) {
            inner[j] = d;
            if (d != UNLABELLED) {
                deepest = max(deepest, d);
            }
        } else {
            var o = UNLABELLED;
            if (contact[j] == 0u && d <= p.band) {
                o = d - 1u;
                labelled += 1u;
            }
            outer[j] = o;
        }
    }
    if (p.mode == 0u) {
        atomicMax(&stats[STAT_MAX_LEVEL], deepest);
    } else {
        atomicAdd(&stats[STAT_LABELLED], labelled);
    }
}

// (hi, lo) / n and its remainder, n in 1..=4.
fn div64(lo: u32, hi: u32, n: u32) -> vec3<u32> {
    let qh = hi / n;
    let r0 = hi % n;
    let a = (r0 << 16u) | (lo >> 16u);
    let q1 = a / n;
    let r1 = a % n;
    let b = (r1 << 16u) | (lo & 0xffffu);
    let q0 = b / n;
    let r = b % n;
    return vec3<u32>((q1 << 16u) | q0, qh, r);
}

// O 2.3, one level l (deepest first): every cell at level l shares its carry among its
// neighbours at level l - 1, the remainder one unit each from the rotated start.
@compute @workgroup_size(64)
fn displace(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h || inner[j] != p.level) {
        return;
    }
    let lo = atomicLoad(&carry[2u * j]);
    let hi = atomicLoad(&carry[2u * j + 1u]);
    atomicStore(&carry[2u * j], 0u);
    atomicStore(&carry[2u * j + 1u], 0u);
    var lower: array<u32, 4>;
    var n = 0u;
    for (var t = 0u; t < 4u; t++) {
        let nb = neighbour(j, t);
        if (nb != UNLABELLED && inner[nb] == p.level - 1u) {
            lower[n] = nb;
            n += 1u;
        }
    }
    if (n == 0u) {
        return;
    }
    let qr = div64(lo, hi, n);
    let first = (p.i0 + j % p.w + p.k0 + j / p.w) % n;
    for (var t = 0u; t < n; t++) {
        let extra = select(0u, 1u, (t + n - first) % n < qr.z);
        let s_lo = qr.x + extra;
        let s_hi = qr.y + select(0u, 1u, s_lo < qr.x);
        if ((s_lo | s_hi) != 0u) {
            carry_add(2u * lower[t], s_lo, s_hi);
        }
    }
}

// O 2.3, end: the rim cells (outside the contact) take what reached them.
@compute @workgroup_size(64)
fn rim(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h || contact[j] != 0u) {
        return;
    }
    let lo = atomicLoad(&carry[2u * j]);
    let hi = atomicLoad(&carry[2u * j + 1u]);
    if ((lo | hi) == 0u) {
        return;
    }
    let g = global_index(j);
    let h = u32(heights[g]);
    var sum = h + lo;
    if (hi != 0u || sum < h || sum > I32_MAX) {
        sum = I32_MAX;
    }
    heights[g] = i32(sum);
    stats_add(STAT_DISPLACED, lo, hi);
}

// Whether (j, n) is an edge of slump step k (j's level lj, n's ln): ring k to ring k + 1, or
// two ring-k cells.
fn step_edge(lj: u32, ln: u32, k: u32) -> bool {
    return (lj == k && (ln == k || ln == k + 1u)) || (lj == k + 1u && ln == k);
}

fn in_step(j: u32) -> bool {
    let l = outer[j];
    return l == p.level || l == p.level + 1u;
}

fn absdiff(a: i32, b: i32) -> u32 {
    // Heights are >= 0, so the difference fits an i32.
    return u32(abs(a - b));
}

// O 2.5, step k, first dispatch: each cell's count of steep edges in the step.
@compute @workgroup_size(64)
fn slump_steep(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h || !in_step(j)) {
        return;
    }
    let hj = heights[global_index(j)];
    var s = 0u;
    for (var t = 0u; t < 4u; t++) {
        let nb = neighbour(j, t);
        if (nb != UNLABELLED && step_edge(outer[j], outer[nb], p.level)) {
            if (absdiff(hj, heights[global_index(nb)]) > p.t) {
                s += 1u;
            }
        }
    }
    steep[j] = s;
}

// Second dispatch: each cell's net flow from the heights before the step; `moved` counts
// every edge once (from its ring-k end, the CPU's edge list).
@compute @workgroup_size(64)
fn slump_flow(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h || !in_step(j)) {
        return;
    }
    let hj = heights[global_index(j)];
    let lj = outer[j];
    var dj = 0i;
    var moved_lo = 0u;
    var moved_hi = 0u;
    for (var t = 0u; t < 4u; t++) {
        let nb = neighbour(j, t);
        if (nb == UNLABELLED || !step_edge(lj, outer[nb], p.level)) {
            continue;
        }
        let d = hj - heights[global_index(nb)];
        let a = u32(abs(d));
        if (a > p.t) {
            let f = (a - p.t) / (steep[j] + steep[nb]);
            dj -= select(-i32(f), i32(f), d > 0i);
            let counts = lj == p.level && (outer[nb] == p.level + 1u || nb > j);
            if (counts) {
                let s = moved_lo + f;
                moved_hi += select(0u, 1u, s < moved_lo);
                moved_lo = s;
            }
        }
    }
    delta[j] = dj;
    if ((moved_lo | moved_hi) != 0u) {
        stats_add(STAT_MOVED + 2u * p.pass_index, moved_lo, moved_hi);
    }
}

// Third dispatch: the step's flows applied.
@compute @workgroup_size(64)
fn slump_apply(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h || !in_step(j)) {
        return;
    }
    let g = global_index(j);
    heights[g] = heights[g] + delta[j];
}

// max_slope: the largest difference between two labelled 4-neighbours.
@compute @workgroup_size(64)
fn slope(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if (j >= p.w * p.h || outer[j] == UNLABELLED) {
        return;
    }
    let hj = heights[global_index(j)];
    var d = 0u;
    for (var t = 1u; t < 4u; t += 2u) {
        let nb = neighbour(j, t);
        if (nb != UNLABELLED && outer[nb] != UNLABELLED) {
            d = max(d, absdiff(hj, heights[global_index(nb)]));
        }
    }
    atomicMax(&stats[STAT_MAX_DIFF], d);
}
