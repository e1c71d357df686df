// One stabilisation pass on the ground's snow, the GPU twin of
// imprint_stages::snow::relax (read its module doc): a Jacobi pass over whole quanta (u32)
// with a 16-neighbour stencil, in two dispatches. `shed` reads the snapshot `units` and
// writes each cell's shares per stencil slot into `flows` (and adds what it sheds to this
// pass's `moved` counter); `gather` writes each cell's new snow into `next`. The host swaps
// `units` and `next` between passes.
// Prepended: common/dispatch.wgsl.
//
// Bit-identical to the CPU: the integer work is exact, and every f32 operation is one that
// Vulkan rounds correctly (add, subtract, multiply, int-to-float, floor, min, max) in the
// CPU's order. `/ QUANTUM` is `* 65536.0` (exact both ways, so a fused multiply-add cannot
// change it), and the one division, excess / sum, is done in integers (`div_rn`) because a
// shader's f32 division may be off by 2.5 ulp.

struct RelaxParams {
    nx: u32,
    nz: u32,
    // This pass's slot in the batch: its counter is moved[2 slot] (low), moved[2 slot + 1]
    // (carries).
    slot: u32,
    _pad: u32,
    // tan θ · |step| · cell / QUANTUM per stencil slot, computed on the host as the CPU does.
    crit: array<vec4<f32>, 4>,
}

@group(0) @binding(0) var<uniform> p: RelaxParams;
@group(0) @binding(1) var<storage, read> ground: array<f32>;
@group(0) @binding(2) var<storage, read> units: array<u32>;
@group(0) @binding(3) var<storage, read_write> flows: array<u32>;
@group(0) @binding(4) var<storage, read_write> next: array<u32>;
@group(0) @binding(5) var<storage, read_write> moved: array<atomic<u32>>;

// imprint_stages::snow::relax::STENCIL: sides, diagonals, knight moves.
var<private> STENCIL: array<vec2<i32>, 16> = array<vec2<i32>, 16>(
    vec2<i32>(1, 0), vec2<i32>(-1, 0), vec2<i32>(0, 1), vec2<i32>(0, -1),
    vec2<i32>(1, 1), vec2<i32>(1, -1), vec2<i32>(-1, 1), vec2<i32>(-1, -1),
    vec2<i32>(2, 1), vec2<i32>(2, -1), vec2<i32>(-2, 1), vec2<i32>(-2, -1),
    vec2<i32>(1, 2), vec2<i32>(1, -2), vec2<i32>(-1, 2), vec2<i32>(-1, -2),
);

fn inside(i: i32, k: i32) -> bool {
    return i >= 0 && k >= 0 && i < i32(p.nx) && k < i32(p.nz);
}

// a / b rounded to nearest even, as IEEE division, for positive normal a <= b (the quotient
// is then a normal number in (0, 1] for the magnitudes a pass meets): long division of the
// 24-bit significands, 24 quotient bits plus a round bit, the remainder as sticky bit.
fn div_rn(a: f32, b: f32) -> f32 {
    let ba = bitcast<u32>(a);
    let bb = bitcast<u32>(b);
    var e = i32(ba >> 23u) - i32(bb >> 23u) + 127;
    var r = (ba & 0x7fffffu) | 0x800000u;
    let mb = (bb & 0x7fffffu) | 0x800000u;
    if r < mb {
        r = r << 1u;
        e -= 1;
    }
    // r in [mb, 2 mb): the quotient is in [1, 2); 25 bits of it.
    var q = 0u;
    for (var i = 0u; i < 25u; i++) {
        let bit = r >= mb;
        if bit {
            r -= mb;
        }
        q = (q << 1u) | select(0u, 1u, bit);
        r = r << 1u;
    }
    let round = (q & 1u) != 0u;
    q = q >> 1u;
    if round && (r != 0u || (q & 1u) != 0u) {
        q += 1u;
        if q == 0x1000000u {
            q = q >> 1u;
            e += 1;
        }
    }
    if e <= 0 {
        return 0.0;
    }
    return bitcast<f32>((u32(e) << 23u) | (q & 0x7fffffu));
}

// The cell (i, k) of index c.
fn cell_of(c: u32) -> vec2<i32> {
    return vec2<i32>(i32(c % p.nx), i32(c / p.nx));
}

fn crit(t: u32) -> f32 {
    return p.crit[t / 4u][t % 4u];
}

// relax::outflows for one cell: its shares to each stencil neighbour, into flows[16 c ..].
@compute @workgroup_size(64)
fn shed(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let c = thread_index(gid, nwg);
    if c >= p.nx * p.nz { return; }
    let ik = cell_of(c);
    var out: array<u32, 16>;
    let s = units[c];
    if s != 0u {
        var excess: array<f32, 16>;
        var largest = 0.0;
        var sum = 0.0;
        for (var t = 0u; t < 16u; t++) {
            let ni = ik.x + STENCIL[t].x;
            let nk = ik.y + STENCIL[t].y;
            if !inside(ni, nk) {
                continue;
            }
            let j = u32(nk) * p.nx + u32(ni);
            let e = (ground[c] - ground[j]) * 65536.0 + f32(i32(s) - i32(units[j])) - crit(t);
            if e > 0.0 {
                excess[t] = e;
                sum += e;
                largest = max(largest, e);
            }
        }
        let total = min(f32(s), floor(0.5 * largest));
        if total >= 1.0 {
            var left = u32(total);
            var steepest = 0u;
            for (var t = 0u; t < 16u; t++) {
                let e = excess[t];
                if e > 0.0 {
                    let share = min(u32(floor(total * div_rn(e, sum))), left);
                    out[t] = share;
                    left -= share;
                    if e > excess[steepest] {
                        steepest = t;
                    }
                }
            }
            out[steepest] += left;
        }
    }
    var shed_total = 0u;
    for (var t = 0u; t < 16u; t++) {
        flows[16u * c + t] = out[t];
        shed_total += out[t];
    }
    if shed_total != 0u {
        let old = atomicAdd(&moved[2u * p.slot], shed_total);
        if old + shed_total < old {
            atomicAdd(&moved[2u * p.slot + 1u], 1u);
        }
    }
}

// The gather: a cell's snow less its shares plus its neighbours' shares to it.
@compute @workgroup_size(64)
fn gather(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let c = thread_index(gid, nwg);
    if c >= p.nx * p.nz { return; }
    let ik = cell_of(c);
    var v = units[c];
    for (var t = 0u; t < 16u; t++) {
        v -= flows[16u * c + t];
    }
    for (var t = 0u; t < 16u; t++) {
        let si = ik.x - STENCIL[t].x;
        let sk = ik.y - STENCIL[t].y;
        if inside(si, sk) {
            v += flows[16u * (u32(sk) * p.nx + u32(si)) + t];
        }
    }
    next[c] = v;
}
