// The ground's contact from depth maps left on the device (GpuGround::step_resident): what
// imprint_stages::ground::contact::object_bottoms_with, work_window and the carry loop of
// GpuGround::press do on the CPU with a read-back depth map, here on the map where the
// rasteriser rendered it, with the same integers as results.
// Prepended: common/dispatch.wgsl.
//
// - `bottoms` (one object, one invocation per cell of its window): the depth view's height of
//   the cell (HeightView::Below: eye.y + depth, the map mirrored in x; f32::MAX where the map
//   is uncovered), in height units as GroundGrid::bottom_units takes it, kept as the lowest
//   over the objects (atomicMin) over the union of their windows;
// - `contact_box` (union window): the cells whose bottom is below the ground: their box, count
//   and removed units (Σ ground − bottom), for the host to size the work window as
//   work_window does;
// - `gather` (work window): the window's bottoms (NO_OBJECT outside the union window) and
//   each contact cell's carry round(α · removed).
//
// The CPU does two steps in f64, which WGSL lacks: metres / unit rounded to units, and
// α · removed rounded. Both are done here in integers, exactly: an f32 and an f64 are integers
// times powers of two, so the f64 quotient (product) and its rounding can be decided with
// 64-bit integer arithmetic made of u32 pairs (see `units_of` and `carry_of`).

struct ContactParams {
    // Ground cells along x.
    nx: u32,
    // `bottoms`: the object's window (its map's pixels), and the map's row stride in texels.
    i0: u32,
    k0: u32,
    w: u32,
    h: u32,
    row_texels: u32,
    // The union window of the objects (the `bottoms` buffer).
    bi0: u32,
    bk0: u32,
    bw: u32,
    bh: u32,
    // `gather`: the work window.
    wi0: u32,
    wk0: u32,
    ww: u32,
    wh: u32,
    // The depth view's eye height (`bottoms`).
    eye_y: f32,
    // α, the displaced fraction (`gather`).
    alpha: f32,
    // The height unit (f64, positive, normal): unit_mant * 2^unit_exp, unit_mant the 53-bit
    // significand as (lo, hi) words.
    unit_lo: u32,
    unit_hi: u32,
    unit_exp: i32,
    // Probes: values to convert.
    count: u32,
}

const NO_OBJECT: u32 = 0x7fffffffu;
const MAX_UNITS: u32 = 0x7ffffffeu;
const F32_MAX: f32 = 3.40282347e38;

@group(0) @binding(0) var<uniform> p: ContactParams;
@group(0) @binding(1) var<storage, read> heights: array<i32>;
// The object's depth map where the rasteriser rendered it: (view depth, coverage) per texel.
@group(0) @binding(2) var<storage, read> texels: array<vec2<f32>>;
// Per cell of the union window: the lowest bottom, units (NO_OBJECT: none).
@group(0) @binding(3) var<storage, read_write> bottoms: array<atomic<u32>>;
// 0, 1: u32::MAX − the box's lowest x, z; 2, 3: its highest x, z; 4: contact cells;
// 5, 6: removed units (lo, hi); 7: 1 when a covered texel gave a height that is not finite
// (the CPU's height field refuses it).
@group(0) @binding(4) var<storage, read_write> box_: array<atomic<u32>, 8>;
// The work window's bottoms (ground/step.wgsl's `bottom`).
@group(0) @binding(5) var<storage, read_write> bottom_out: array<i32>;
// The work window's carries (ground/step.wgsl's `carry`: u64 as (lo, hi)).
@group(0) @binding(6) var<storage, read_write> carry_out: array<u32>;
@group(0) @binding(7) var<storage, read> probe_in: array<u32>;
@group(0) @binding(8) var<storage, read_write> probe_out: array<u32>;

// 64-bit unsigned integers as (lo, hi).
fn add64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    let lo = a.x + b.x;
    return vec2<u32>(lo, a.y + b.y + select(0u, 1u, lo < a.x));
}

fn sub64(a: vec2<u32>, b: vec2<u32>) -> vec2<u32> {
    return vec2<u32>(a.x - b.x, a.y - b.y - select(0u, 1u, a.x < b.x));
}

fn ge64(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y > b.y || (a.y == b.y && a.x >= b.x);
}

// a << k and a >> k, k in 0..=63 (WGSL shifts take their amount modulo 32).
fn shl64(a: vec2<u32>, k: u32) -> vec2<u32> {
    if k == 0u {
        return a;
    }
    if k >= 32u {
        return vec2<u32>(0u, a.x << (k - 32u));
    }
    return vec2<u32>(a.x << k, (a.y << k) | (a.x >> (32u - k)));
}

fn shr64(a: vec2<u32>, k: u32) -> vec2<u32> {
    if k == 0u {
        return a;
    }
    if k >= 32u {
        return vec2<u32>(a.y >> (k - 32u), 0u);
    }
    return vec2<u32>((a.x >> k) | (a.y << (32u - k)), a.y >> k);
}

// a * b, exactly.
fn mul32(a: u32, b: u32) -> vec2<u32> {
    let a0 = a & 0xffffu;
    let a1 = a >> 16u;
    let b0 = b & 0xffffu;
    let b1 = b >> 16u;
    let lo = vec2<u32>(a0 * b0, 0u);
    let m1 = shl64(vec2<u32>(a1 * b0, 0u), 16u);
    let m2 = shl64(vec2<u32>(a0 * b1, 0u), 16u);
    let hi = vec2<u32>(0u, a1 * b1);
    return add64(add64(lo, m1), add64(m2, hi));
}

fn bit_length64(a: vec2<u32>) -> u32 {
    if a.y != 0u {
        return 64u - countLeadingZeros(a.y);
    }
    return 32u - countLeadingZeros(a.x);
}

// An f32 > 0 as mant * 2^exp (mant < 2^24).
struct Split {
    mant: u32,
    exp: i32,
}

fn split(x: f32) -> Split {
    let bits = bitcast<u32>(x);
    let e = (bits >> 23u) & 0xffu;
    let m = bits & 0x7fffffu;
    if e == 0u {
        return Split(m, -149);
    }
    return Split(m | 0x800000u, i32(e) - 150);
}

// GroundGrid::bottom_units for a height that is not f32::MAX or more: Rust's
// `((m as f64) / unit).round() as i64` clamped to 0..=i32::MAX − 1.
//
// With m = M 2^a and unit = U 2^b (M < 2^24, U in [2^52, 2^53)), x = m / unit = (M / U)
// 2^(a − b) < 2^(a − b − 28). The long division of M 2^s by U, s = a − b + 64, gives
// floor(x 2^64) = I 2^64 + F: the integer part I and 64 fraction bits F. The f64 quotient
// rounds x to 53 significant bits (to nearest, ties to even), and `round` then goes half
// away from zero, so the result is I + 1 exactly when that rounding of x reaches I + 0.5:
// when x ≥ I + 0.5 − 2^−(p+1), p = 53 − bitlength(I) the fraction bits kept (54 for I = 0,
// where 0.5's predecessor is 0.5 − 2^−54); at that midpoint itself the tie goes to I + 0.5,
// whose last kept bit is 0. With 64 exact fraction bits (p + 1 ≤ 55) the comparison
// F ≥ 2^63 − 2^(63 − p) decides it exactly.
fn units_of(m: f32) -> u32 {
    // NaN, zeros and negatives: Rust's rounding gives 0 or less, clamped to 0.
    if !(m > 0.0) {
        return 0u;
    }
    let sp = split(m);
    let d = sp.exp - p.unit_exp;
    // x < 2^(d − 28): below 0.25 rounds to 0.
    if d < 26 {
        return 0u;
    }
    // x > 2^(d − 30) ≥ 2^31: clamped.
    if d >= 61 {
        return MAX_UNITS;
    }
    let u = vec2<u32>(p.unit_lo, p.unit_hi);
    let s = u32(d + 64);
    var r = vec2<u32>(sp.mant, 0u);
    var q0 = 0u;
    var q1 = 0u;
    var q2 = 0u;
    for (var k = 0u; k < s; k++) {
        r = shl64(r, 1u);
        q2 = (q2 << 1u) | (q1 >> 31u);
        q1 = (q1 << 1u) | (q0 >> 31u);
        q0 = q0 << 1u;
        if ge64(r, u) {
            r = sub64(r, u);
            q0 = q0 | 1u;
        }
    }
    let i = q2;
    if i >= MAX_UNITS {
        return MAX_UNITS;
    }
    let len = 32u - countLeadingZeros(i);
    var kept = 54u;
    if len > 0u {
        kept = 53u - len;
    }
    // T = 2^63 − 2^t, t = 63 − kept in 9..=42.
    let t = 63u - kept;
    var thr: vec2<u32>;
    if t >= 32u {
        thr = vec2<u32>(0u, 0x80000000u - (1u << (t - 32u)));
    } else {
        thr = vec2<u32>(0u - (1u << t), 0x7fffffffu);
    }
    let up = ge64(vec2<u32>(q0, q1), thr);
    return min(i + select(0u, 1u, up), MAX_UNITS);
}

// Rust's `(alpha as f64 * removed as f64).round() as u64` for alpha in [0, 1] and
// removed > 0: alpha = A 2^c (A < 2^24), so the product is Z 2^c with the integer Z = A ·
// removed < 2^55; the f64 product keeps Z's top 53 bits (to nearest, ties to even), and
// rounding half away from zero is floor(· + 0.5), a shift of Z.
fn carry_of(alpha: f32, removed: u32) -> vec2<u32> {
    if !(alpha > 0.0) || removed == 0u {
        return vec2<u32>(0u);
    }
    let sp = split(alpha);
    var z = mul32(sp.mant, removed);
    let len = bit_length64(z);
    if len > 53u {
        let sh = len - 53u;
        let half = 1u << (sh - 1u);
        let rem = z.x & ((1u << sh) - 1u);
        var q = shr64(z, sh);
        if rem > half || (rem == half && (q.x & 1u) == 1u) {
            q = add64(q, vec2<u32>(1u, 0u));
        }
        z = shl64(q, sh);
    }
    // alpha ≤ 1: c ≤ −23. Below 2^−57 · 2^56 the product is under 0.5.
    let k = u32(-sp.exp);
    if k >= 57u {
        return vec2<u32>(0u);
    }
    return shr64(add64(z, shl64(vec2<u32>(1u, 0u), k - 1u)), k);
}

// One object's bottoms: cell (x, y) of its window is pixel (w − 1 − x, y) of its map.
@compute @workgroup_size(64)
fn bottoms_pass(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if j >= p.w * p.h {
        return;
    }
    let x = j % p.w;
    let y = j / p.w;
    let t = texels[y * p.row_texels + (p.w - 1u - x)];
    // heights_from_depth: eye.y + 1 · depth where covered, the region's empty (f32::MAX)
    // elsewhere; then bottom_units.
    var b = NO_OBJECT;
    if t.y > 0.5 {
        let metres = p.eye_y + t.x;
        if !(abs(metres) <= F32_MAX) {
            atomicMax(&box_[7], 1u);
        }
        if !(metres >= F32_MAX) {
            b = units_of(metres);
        }
    }
    let at = (p.k0 - p.bk0 + y) * p.bw + (p.i0 - p.bi0 + x);
    atomicMin(&bottoms[at], b);
}

// The contact over the union window: box, count and removed units.
@compute @workgroup_size(64)
fn contact_box(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if j >= p.bw * p.bh {
        return;
    }
    let i = p.bi0 + j % p.bw;
    let k = p.bk0 + j / p.bw;
    let h = heights[k * p.nx + i];
    let bot = i32(atomicLoad(&bottoms[j]));
    if bot >= h {
        return;
    }
    atomicMax(&box_[0], 0xffffffffu - i);
    atomicMax(&box_[1], 0xffffffffu - k);
    atomicMax(&box_[2], i);
    atomicMax(&box_[3], k);
    atomicAdd(&box_[4], 1u);
    // h − bot > 0 fits a u32 (h ≤ i32::MAX, bot ≥ 0).
    let removed = u32(h - bot);
    let old = atomicAdd(&box_[5], removed);
    if old + removed < old {
        atomicAdd(&box_[6], 1u);
    }
}

// The work window's bottoms and carries.
@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if j >= p.ww * p.wh {
        return;
    }
    let i = p.wi0 + j % p.ww;
    let k = p.wk0 + j / p.ww;
    var bot = NO_OBJECT;
    if i >= p.bi0 && i < p.bi0 + p.bw && k >= p.bk0 && k < p.bk0 + p.bh {
        bot = atomicLoad(&bottoms[(k - p.bk0) * p.bw + (i - p.bi0)]);
    }
    bottom_out[j] = i32(bot);
    let h = heights[k * p.nx + i];
    var c = vec2<u32>(0u);
    if i32(bot) < h {
        c = carry_of(p.alpha, u32(h - i32(bot)));
    }
    carry_out[2u * j] = c.x;
    carry_out[2u * j + 1u] = c.y;
}

// Probes of the two conversions, for tests: `units_of` of probe_in as f32 bits, and
// `carry_of(alpha, probe_in)`.
@compute @workgroup_size(64)
fn probe_units(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if j >= p.count {
        return;
    }
    probe_out[j] = units_of(bitcast<f32>(probe_in[j]));
}

@compute @workgroup_size(64)
fn probe_carry(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nw: vec3<u32>) {
    let j = thread_index(gid, nw);
    if j >= p.count {
        return;
    }
    let c = carry_of(p.alpha, probe_in[j]);
    probe_out[2u * j] = c.x;
    probe_out[2u * j + 1u] = c.y;
}
