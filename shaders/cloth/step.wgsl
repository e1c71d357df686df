// One cloth substep (H eq. 9-12, docs/methods.md §3), the GPU twin of imprint_stages::cloth::cpu:
// one invocation per particle gathers its spring forces from `pos` (CSR over LinkQuads, four
// springs per 64-byte struct) and its hinges' bending forces (T eq. 2, CSR over hinge refs),
// integrates damped position Verlet from `pos` and `prev` into `next` (pins: their target,
// moving linearly over the frame), then pushes its own new position out of each collider in
// order and off the ground. Nothing reads another particle's `next`, so forces, integration
// and contact are one dispatch per substep; the host rotates the three position buffers
// between substeps. No atomics: every particle writes only its own `next`, `side` and
// `stats` slots.
// Prepended: common/dispatch.wgsl.
//
// Fields are sampled as imprint_stages::cloth::sampler does (trilinear, the field's weight
// order; out of the grid or in its outermost half cell the nearest cell, as
// DistanceField::sample), from one `vec4` per cell: xyz the closest-point vector, w the
// distance, negated for far cells (the sampler's cache layout).

struct StepParams {
    // xyz gravity; w unused.
    gravity: vec4<f32>,
    // xyz wind velocity, w drag (used when has_wind = 1).
    wind: vec4<f32>,
    n: u32,
    // Colliders (each has a start slot 2k and an end slot 2k + 1 in `headers`).
    nf: u32,
    // 1: T eq. 1's quadratic spring law; 0: H eq. 9's linear one.
    quad: u32,
    has_ground: u32,
    // Fraction of the frame at this substep's end (H §5.3's j/n).
    s: f32,
    dt: f32,
    // dt / (previous substep's dt).
    ratio: f32,
    damping: f32,
    eps: f32,
    friction: f32,
    ground: f32,
    max_stretch: f32,
    has_wind: u32,
    // This substep's number within the frame, from 0.
    substep: u32,
    // Where the face and pin-slot lists start in `topo`.
    face_base: u32,
    pin_base: u32,
    // Where the hinge offsets (n + 1) and the hinge refs (hinge * 4 + role) start in `topo`.
    hinge_base: u32,
    href_base: u32,
    // 0: no hinges (`hinges` is a dummy), skip them.
    has_hinges: u32,
    _pad: u32,
}

// imprint_stages::cloth::springs::Hinge: the edge (v0, v1) shared by the triangles (v0, v1, v2)
// and (v1, v0, v3).
struct Hinge {
    v: vec4<u32>,
    rest_angle: f32,
    c: f32,
    _pad0: f32,
    _pad1: f32,
}

struct LinkQuad {
    other: vec4<u32>,
    rest: vec4<f32>,
    k_stretch: vec4<f32>,
    k_compress: vec4<f32>,
}

struct FieldHeader {
    // xyz: world position of cell (0, 0, 0)'s centre; w: cell edge.
    origin: vec4<f32>,
    // xyz: cells per axis; w: offset of cell 0 in `cells`.
    dims: vec4<u32>,
    far_value: f32,
    // 0: no field in this slot (a start slot when the fields are not blended).
    present: u32,
    // Offset of the slot's inside bits in `signs` (words).
    sign_offset: u32,
    // 1: the field is signed (its inside bits are in `signs`).
    signed: u32,
}

// Per particle, accumulated over a frame's substeps (zeroed at the frame's start).
struct Stats {
    // Contacts (collider and ground hits) in the latest substep.
    contacts: u32,
    // Most hits from inside a body in one substep.
    inside: u32,
    max_depth: f32,
    band_misses: u32,
    // 1 + the first substep where the position was not finite; 0 = never.
    nonfinite: u32,
    // 1 + the first substep where a spring exceeded max_stretch; 0 = never.
    overstretched: u32,
    // |x_next - x| ^ 2 of the latest substep (free particles).
    step2: f32,
    // Largest |x_next - 2 x + x_prev| ^ 2 (times nothing: the host divides by dt^4).
    accel2: f32,
    // Written by `residual` after the frame: ε - signed distance at the frame's end, the
    // largest over the colliders and the ground, when positive (closer than ε); else 0.
    close_depth: f32,
}

const NONE: u32 = 0xffffffffu;
const TINY: f32 = 1e-20;
const F32_MAX: f32 = 3.40282347e38;

@group(0) @binding(0) var<uniform> params: StepParams;
// Link offsets (n + 1), face offsets (n + 1), pin slots (n; NONE when free), hinge offsets
// (n + 1), hinge refs.
@group(0) @binding(1) var<storage, read> topo: array<u32>;
@group(0) @binding(2) var<storage, read> quads: array<LinkQuad>;
// Per pinned particle: its position at the frame's start, then its target at the end.
@group(0) @binding(3) var<storage, read> pins: array<vec4<f32>>;
// Per particle's faces: the two other corners, in winding order.
@group(0) @binding(4) var<storage, read> face_others: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read> prev: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read> pos: array<vec4<f32>>;
@group(0) @binding(7) var<storage, read_write> next: array<vec4<f32>>;
// Per particle and collider: the outward direction at the last sample, w = 1 when known.
@group(0) @binding(8) var<storage, read_write> side: array<vec4<f32>>;
@group(0) @binding(9) var<storage, read_write> stats: array<Stats>;
@group(0) @binding(10) var<storage, read> headers: array<FieldHeader>;
@group(0) @binding(11) var<storage, read> cells: array<vec4<f32>>;
@group(0) @binding(12) var<storage, read> hinges: array<Hinge>;
// The signed slots' inside bits (DistanceField::inside), one bitset per slot at its offset.
@group(0) @binding(13) var<storage, read> signs: array<u32>;

fn finite3(v: vec3<f32>) -> bool {
    return all(abs(v) <= vec3<f32>(F32_MAX));
}

// glam's Vec4::element_sum: ((x + y) + z) + w.
fn esum(v: vec4<f32>) -> f32 {
    return ((v.x + v.y) + v.z) + v.w;
}

// glam's normalize: v times the reciprocal of its length.
fn unit(v: vec3<f32>) -> vec3<f32> {
    return v * (1.0 / length(v));
}

// Rust's f32::round: half away from zero (WGSL's round goes to even).
fn round_away(c: vec3<f32>) -> vec3<f32> {
    let r = floor(abs(c) + vec3<f32>(0.5));
    return select(r, -r, c < vec3<f32>(0.0));
}

struct Sample {
    distance: f32,
    vector: vec3<f32>,
    in_band: bool,
    // For a signed field: the blend of the cells' signed distances (DistanceField::side).
    signed: bool,
    side: f32,
}

// The signed distance of cell `c` of slot h, given its stored distance w (negated when far).
fn signed_cell(h: FieldHeader, c: vec3<i32>, w: f32) -> f32 {
    let i = cell_index(h, c) - h.dims.w;
    let word = signs[h.sign_offset + i / 32u];
    return select(abs(w), -abs(w), ((word >> (i % 32u)) & 1u) == 1u);
}

fn cell_index(h: FieldHeader, c: vec3<i32>) -> u32 {
    let d = h.dims;
    return h.dims.w + u32(c.x) + d.x * (u32(c.y) + d.y * u32(c.z));
}

// The field in slot `slot` at `p`, as DistanceField::sample(p, Sampling::Vector).
fn sample_field(slot: u32, p: vec3<f32>) -> Sample {
    let h = headers[slot];
    let c = (p - h.origin.xyz) / h.origin.w;
    let fl = floor(c);
    let t = c - fl;
    let dims = vec3<i32>(h.dims.xyz);
    let signed = h.signed == 1u;
    if !finite3(c) {
        return Sample(h.far_value, vec3<f32>(0.0), false, signed, h.far_value);
    }
    let b = vec3<i32>(fl);
    if any(b < vec3<i32>(0)) || any(b + vec3<i32>(1) >= dims) {
        // Outside the grid or in its outermost half cell: the nearest cell (beyond the grid,
        // outside the body).
        let cl = vec3<i32>(round_away(c));
        if any(cl < vec3<i32>(0)) || any(cl >= dims) {
            return Sample(h.far_value, vec3<f32>(0.0), false, signed, h.far_value);
        }
        let v = cells[cell_index(h, cl)];
        var sd = 0.0;
        if signed {
            sd = signed_cell(h, cl, v.w);
        }
        return Sample(abs(v.w), v.xyz, v.w >= 0.0, signed, sd);
    }
    let wx = vec2<f32>(1.0 - t.x, t.x);
    let wy = vec2<f32>(1.0 - t.y, t.y);
    let wz = vec2<f32>(1.0 - t.z, t.z);
    var acc = vec4<f32>(0.0);
    var dist = 0.0;
    var far = false;
    var sd = 0.0;
    for (var k = 0u; k < 8u; k++) {
        let o = vec3<u32>(k & 1u, (k >> 1u) & 1u, (k >> 2u) & 1u);
        let w = wx[o.x] * wy[o.y] * wz[o.z];
        let cc = b + vec3<i32>(o);
        let v = cells[cell_index(h, cc)];
        acc += w * v;
        dist += w * abs(v.w);
        far = far || v.w < 0.0;
        if signed {
            sd += w * signed_cell(h, cc, v.w);
        }
    }
    if !far {
        // DistanceField::vector_distance: the vector's length, or the bound from the blended
        // distances where longer (near the middle of a gap).
        let spread = t.x * (1.0 - t.x) + t.y * (1.0 - t.y) + t.z * (1.0 - t.z);
        let bound = dist - h.origin.w * sqrt(spread);
        return Sample(max(length(acc.xyz), bound), acc.xyz, true, signed, sd);
    }
    return Sample(dist, acc.xyz, false, signed, sd);
}

struct Signed {
    ok: bool,
    distance: f32,
    outward: vec3<f32>,
    band_miss: bool,
}

// contact::classify: a sample read as signed, by the field's sign or else by the particle's
// side memory.
fn classify(f: Sample, side_k: vec4<f32>, reach: f32, band_miss: bool) -> Signed {
    let d = f.distance;
    let v = f.vector;
    let known = abs(d) <= F32_MAX && any(v != vec3<f32>(0.0));
    if f.signed {
        if f.side < 0.0 {
            if known {
                return Signed(true, -d, v, band_miss);
            }
            // Deeper than the band: inside, no direction.
            return Signed(abs(f.side) <= F32_MAX, f.side, vec3<f32>(0.0), band_miss);
        }
        if known {
            return Signed(true, d, -v, band_miss);
        }
        return Signed(false, 0.0, vec3<f32>(0.0), false);
    }
    if !known {
        return Signed(false, 0.0, vec3<f32>(0.0), false);
    }
    if side_k.w > 0.0 && dot(v, side_k.xyz) > 0.0 && d < reach {
        return Signed(true, -d, v, band_miss);
    }
    return Signed(true, d, -v, band_miss);
}

// Whether classify reads an unsigned sample's reach: its vector runs along the memory.
fn turned(f: Sample, side_k: vec4<f32>) -> bool {
    return !f.signed && side_k.w > 0.0 && dot(f.vector, side_k.xyz) > 0.0;
}

// contact::moved: the field in `slot` at the other field's closest point `q`, no more than
// `jump`.
fn moved(slot: u32, q: vec3<f32>, jump: f32) -> f32 {
    return min(sample_field(slot, q).distance, jump);
}

// contact::sweep of the other field's reading: how much less the reach of a crossing is.
fn outside(r: Signed, agree: bool) -> f32 {
    if !r.ok || r.distance < 0.0 {
        return 0.0;
    }
    if agree {
        return r.distance;
    }
    return F32_MAX;
}

// contact::signed_sample for collider k.
fn signed_sample(k: u32, x: vec3<f32>, x_from: vec3<f32>, side_k: vec4<f32>) -> Signed {
    let s = params.s;
    let eps = params.eps;
    let reach0 = 2.0 * eps + length(x - x_from);
    let b = sample_field(2u * k + 1u, x);
    if headers[2u * k].present == 0u || s >= 1.0 {
        return classify(b, side_k, reach0, false);
    }
    let a = sample_field(2u * k, x);
    let far_end = headers[2u * k + 1u].far_value;
    if a.in_band && b.in_band {
        // A crossing only as deep as the body moved here, and a sweep the surface could
        // make where the other field finds the particle outside (contact.rs).
        let jump = length(b.vector - a.vector);
        var reach_a = reach0;
        var reach_b = reach0;
        if turned(a, side_k) {
            reach_a = reach0 + moved(2u * k + 1u, x + a.vector, jump);
        }
        if turned(b, side_k) {
            reach_b = reach0 + moved(2u * k, x + b.vector, jump);
        }
        let p0 = classify(a, side_k, reach_a, false);
        let q0 = classify(b, side_k, reach_b, false);
        let agree = dot(a.vector, b.vector) < 0.0;
        let p = classify(a, side_k, reach_a - outside(q0, agree), false);
        let q = classify(b, side_k, reach_b - outside(p0, agree), false);
        if p.ok && q.ok {
            let distance = p.distance + (q.distance - p.distance) * s;
            var np = p.outward;
            var nq = q.outward;
            if distance < eps {
                np = unit(np);
                nq = unit(nq);
            }
            return Signed(true, distance, np + (nq - np) * s, false);
        }
        if q.ok {
            return q;
        }
        return p;
    }
    // One field far: the body moved here by up to the band, or more.
    if !a.in_band && b.in_band {
        var reach = reach0;
        if turned(b, side_k) {
            reach = reach0 + moved(2u * k, x + b.vector, far_end);
        }
        return classify(b, side_k, reach, true);
    }
    if a.in_band && !b.in_band {
        var reach = reach0;
        if turned(a, side_k) {
            reach = reach0 + moved(2u * k + 1u, x + a.vector, far_end);
        }
        return classify(a, side_k, reach, true);
    }
    let f = Sample(
        a.distance + (b.distance - a.distance) * s,
        a.vector + (b.vector - a.vector) * s,
        false,
        a.signed && b.signed,
        a.side + (b.side - a.side) * s,
    );
    return classify(f, side_k, reach0, false);
}

// Rust's f32::signum (1 for +0, -1 for -0; WGSL's sign gives 0 at zero).
fn signum(x: f32) -> f32 {
    return select(1.0, -1.0, bitcast<u32>(x) >= 0x80000000u);
}

// atan2(y, x) to within a few ulps of Rust's f32::atan2 (Cephes' atanf polynomial after
// reduction to [0, tan(pi/8)]). WGSL leaves the builtin's precision to the device (Vulkan
// allows 4096 ulps; Mesa lavapipe's is off by up to ~350 ulps), and the hinge angle feeds
// every bending force. Signs of zero as Rust: y = -0 gives -0 (x > 0) or -pi (x < 0).
fn atan2_f32(y: f32, x: f32) -> f32 {
    let ax = abs(x);
    let ay = abs(y);
    let hi = max(ax, ay);
    var a = 0.0;
    if hi > 0.0 {
        var t = min(ax, ay) / hi;
        var base = 0.0;
        if t > 0.41421356 {
            base = 0.78539816;
            t = (t - 1.0) / (t + 1.0);
        }
        let z = t * t;
        a = base + ((((0.0805374449538 * z - 0.138776856032) * z + 0.199777106478) * z
            - 0.333329491539) * z * t + t);
        if ay > ax {
            a = 1.5707963 - a;
        }
    }
    if bitcast<u32>(x) >= 0x80000000u {
        a = 3.1415927 - a;
    }
    return select(a, -a, bitcast<u32>(y) >= 0x80000000u);
}

// springs::hinge_slope: c (1 - cos φ) sign(φ).
fn hinge_slope(c: f32, phi: f32) -> f32 {
    return c * (1.0 - cos(phi)) * signum(phi);
}

// springs::hinge_angle_gradient for the hinge at x0..x3, its angle θ and dθ/dx of the vertex
// in slot `role`; ok = false (no force) when a triangle is degenerate.
struct HingeGrad {
    ok: bool,
    theta: f32,
    g: vec3<f32>,
}

fn hinge_angle_gradient(
    x0: vec3<f32>,
    x1: vec3<f32>,
    x2: vec3<f32>,
    x3: vec3<f32>,
    role: u32,
) -> HingeGrad {
    let e = x1 - x0;
    let n1 = cross(e, x2 - x0);
    let n2 = cross(x0 - x1, x3 - x1);
    let l1 = dot(n1, n1);
    let l2 = dot(n2, n2);
    let le2 = dot(e, e);
    if !(l1 > 1e-12 * le2 * le2 && l2 > 1e-12 * le2 * le2 && le2 > 0.0) {
        return HingeGrad(false, 0.0, vec3<f32>(0.0));
    }
    let le = sqrt(le2);
    let eh = e / le;
    let m1 = n1 / l1;
    let m2 = n2 / l2;
    let sin_t = dot(cross(n1, n2), eh) / sqrt(l1 * l2);
    let cos_t = dot(n1, n2) / sqrt(l1 * l2);
    let theta = atan2_f32(sin_t, cos_t);
    // Bridson et al. 2003's bending modes, as on the CPU; only this vertex's.
    var g: vec3<f32>;
    switch role {
        case 0u: {
            g = -(dot(x2 - x1, eh) * m1 + dot(x3 - x1, eh) * m2);
        }
        case 1u: {
            g = dot(x2 - x0, eh) * m1 + dot(x3 - x0, eh) * m2;
        }
        case 2u: {
            g = -le * m1;
        }
        default: {
            g = -le * m2;
        }
    }
    return HingeGrad(true, theta, g);
}

// cpu::hinge_force: the sum over particle i's hinges of -U'(θ - θ_rest) dθ/dx_i.
fn hinge_force(i: u32) -> vec3<f32> {
    var f = vec3<f32>(0.0);
    let base = params.hinge_base;
    for (var r = topo[base + i]; r < topo[base + i + 1u]; r++) {
        let ref_ = topo[params.href_base + r];
        let h = hinges[ref_ / 4u];
        let hg = hinge_angle_gradient(
            pos[h.v.x].xyz,
            pos[h.v.y].xyz,
            pos[h.v.z].xyz,
            pos[h.v.w].xyz,
            ref_ % 4u,
        );
        if hg.ok {
            f -= hinge_slope(h.c, hg.theta - h.rest_angle) * hg.g;
        }
    }
    return f;
}

// Faces::area_normal at `pos`.
fn area_normal(i: u32) -> vec3<f32> {
    let xi = pos[i].xyz;
    var n = vec3<f32>(0.0);
    for (var r = topo[params.face_base + i]; r < topo[params.face_base + i + 1u]; r++) {
        let o = face_others[r];
        n += cross(pos[o.x].xyz - xi, pos[o.y].xyz - xi);
    }
    return n * (1.0 / 6.0);
}

@compute @workgroup_size(64)
fn substep(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let i = thread_index(gid, nwg);
    if i >= params.n {
        return;
    }
    let xi4 = pos[i];
    let px = vec4<f32>(xi4.x);
    let py = vec4<f32>(xi4.y);
    let pz = vec4<f32>(xi4.z);
    var fx = vec4<f32>(0.0);
    var fy = vec4<f32>(0.0);
    var fz = vec4<f32>(0.0);
    var over = false;
    let limit = vec4<f32>(params.max_stretch);
    for (var r = topo[i]; r < topo[i + 1u]; r++) {
        let q = quads[r];
        let o0 = pos[q.other.x];
        let o1 = pos[q.other.y];
        let o2 = pos[q.other.z];
        let o3 = pos[q.other.w];
        let dx = vec4<f32>(o0.x, o1.x, o2.x, o3.x) - px;
        let dy = vec4<f32>(o0.y, o1.y, o2.y, o3.y) - py;
        let dz = vec4<f32>(o0.z, o1.z, o2.z, o3.z) - pz;
        let len = sqrt(dx * dx + dy * dy + dz * dz);
        let e = len - q.rest;
        let k = select(q.k_compress, q.k_stretch, e >= vec4<f32>(0.0));
        var c = k * e / max(len, vec4<f32>(TINY));
        if params.quad == 1u {
            c *= abs(e);
        }
        fx += c * dx;
        fy += c * dy;
        fz += c * dz;
        over = over || any(len > q.rest * limit);
    }
    var f = vec3<f32>(esum(fx), esum(fy), esum(fz));
    var st = stats[i];
    if over && st.overstretched == 0u {
        st.overstretched = params.substep + 1u;
    }
    let slot = topo[params.pin_base + i];
    if slot != NONE {
        let a = pins[2u * slot].xyz;
        let b = pins[2u * slot + 1u].xyz;
        var p = b;
        if params.s < 1.0 {
            p = a + (b - a) * params.s;
        }
        next[i] = vec4<f32>(p, 0.0);
        st.contacts = 0u;
        stats[i] = st;
        return;
    }
    if params.has_hinges == 1u {
        f += hinge_force(i);
    }
    // H eq. 10.
    let dt = params.dt;
    let inv_m = xi4.w;
    let moved = (xi4.xyz - prev[i].xyz) * params.ratio;
    if params.has_wind == 1u {
        let n = area_normal(i);
        let rel = params.wind.xyz - moved / dt;
        let ln = length(n);
        var nn = vec3<f32>(0.0);
        if ln > 0.0 && ln <= F32_MAX {
            nn = n * (1.0 / ln);
        }
        f += params.wind.w * dot(nn, rel) * n;
    }
    var x = xi4.xyz + params.damping * moved + (f * inv_m + params.gravity.xyz) * (dt * dt);
    let x0 = xi4.xyz;
    let eps = params.eps;
    let friction = params.friction;
    var hits = 0u;
    var inside = 0u;
    let nf = max(params.nf, 1u);
    for (var k = 0u; k < params.nf; k++) {
        let si = i * nf + k;
        let sd = signed_sample(k, x, x0, side[si]);
        if !sd.ok {
            continue;
        }
        // contact::respond.
        if sd.distance < 0.0 && all(sd.outward == vec3<f32>(0.0)) {
            // Inside a signed field, deeper than its band: undo the step.
            x = x0;
            hits += 1u;
            inside += 1u;
            st.max_depth = max(st.max_depth, eps - sd.distance);
            st.band_misses += u32(sd.band_miss);
            continue;
        }
        side[si] = vec4<f32>(sd.outward, 1.0);
        if sd.distance >= eps {
            continue;
        }
        let l = length(sd.outward);
        let rcp = 1.0 / l;
        if !(rcp > 0.0 && rcp <= F32_MAX) {
            continue;
        }
        let nrm = sd.outward * rcp;
        x += (eps - sd.distance) * nrm;
        if friction > 0.0 {
            let stp = x - x0;
            x -= friction * (stp - dot(stp, nrm) * nrm);
        }
        let depth = eps - sd.distance;
        hits += 1u;
        inside += u32(sd.distance < 0.0);
        st.max_depth = max(st.max_depth, depth);
        st.band_misses += u32(sd.band_miss);
    }
    if params.has_ground == 1u {
        let target_y = params.ground + eps;
        if x.y < target_y {
            let depth = target_y - x.y;
            x.y = target_y;
            if friction > 0.0 {
                x.x -= friction * (x.x - x0.x);
                x.z -= friction * (x.z - x0.z);
            }
            hits += 1u;
            inside += u32(depth > eps);
            st.max_depth = max(st.max_depth, depth);
        }
    }
    if !finite3(x) && st.nonfinite == 0u {
        st.nonfinite = params.substep + 1u;
    }
    let stp = x - x0;
    let d2 = stp - moved;
    st.contacts = hits;
    st.inside = max(st.inside, inside);
    st.step2 = dot(stp, stp);
    st.accel2 = max(st.accel2, dot(d2, d2));
    stats[i] = st;
    next[i] = vec4<f32>(x, inv_m);
}

// After a frame's last substep, with `pos` the frame's end positions and the last substep's
// parameters (s = 1: only the end slots are read): each free particle's residual contact, as
// imprint_stages::cloth::ClothSim's frame pass measures it against the end fields (its own
// position as where it came from, so the reach is 2ε) and the ground. Nothing else changes.
@compute @workgroup_size(64)
fn residual(
    @builtin(global_invocation_id) gid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let i = thread_index(gid, nwg);
    if i >= params.n {
        return;
    }
    let x4 = pos[i];
    var worst = 0.0;
    if x4.w != 0.0 {
        let x = x4.xyz;
        let eps = params.eps;
        let nf = max(params.nf, 1u);
        for (var k = 0u; k < params.nf; k++) {
            let sd = signed_sample(k, x, x, side[i * nf + k]);
            if sd.ok {
                worst = max(worst, eps - sd.distance);
            }
        }
        if params.has_ground == 1u {
            worst = max(worst, params.ground + eps - x.y);
        }
    }
    stats[i].close_depth = worst;
}
