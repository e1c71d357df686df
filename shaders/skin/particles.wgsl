// Particle skinning substeps (crates/imprint-stages/src/skin/gpu_particles.rs), the f32 GPU
// counterpart of `ParticleSkin::step_frame` (skin/particles.rs). Per substep, the CPU's
// passes: `rotate` (pass 0, corotated springs or pressure only, below), then
// - `pairs` (T: distance springs, no pressure) or `pairs_corotated` (any spring, pressure):
//   one invocation per particle i computes each of its pairs with j > i once, into the
//   pair's own slot (spring, pressure, damping along the pair);
// - `update`: one invocation per particle gathers its pairs' terms in list order, each times
//   its signed mass weight (negative where the pair was stored from the other end), adds the
//   bone's pull and damping, and does the leap-frog update and the blow-up check.
// Every invocation writes only its own slots: no atomics but the blow-up flag (lowest failing
// particle, atomicMin), no order dependence.

struct Params {
    n: u32,
    bones: u32,
    h: f32,
    ks: f32,
    cs: f32,
    kb: f32,
    cb: f32,
    limit: f32,
    kv: f32,
    // 1: corotated springs (else distance springs).
    corotated: u32,
    // The mesh's vertex count, and 1 where vertex offsets turn with the particle's rotation
    // (else with its bone's).
    verts: u32,
    vrot_particle: u32,
}

struct Step {
    s: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

// Positions x, half-step velocities v, estimated step velocities ve (w unused).
struct State {
    x: vec4<f32>,
    v: vec4<f32>,
    ve: vec4<f32>,
}

// Rest position (w unused); list range [start, end), first entry with j > i (upper), first
// pair slot (pair_start); bone, then the rest determinant's bits and whether it exists.
struct Part {
    rest: vec4<f32>,
    idx: vec4<u32>,
    bone: vec4<u32>,
}

// A neighbour entry: j, its pair's slot, rest length, signed mass weight m_j / (m_i + m_j).
struct Edge {
    j: u32,
    pair: u32,
    rest_len: f32,
    weight: f32,
    // X_j − X_i (w unused).
    off: vec4<f32>,
}

// Per particle: its tracked rotation (xyzw) and half its rotation matrix's columns, the
// volume change J in hx.w.
struct Rot {
    q: vec4<f32>,
    hx: vec4<f32>,
    hy: vec4<f32>,
    hz: vec4<f32>,
}

// A bone's skinning transform: matrix columns and translation (w unused).
struct Tf {
    x: vec4<f32>,
    y: vec4<f32>,
    z: vec4<f32>,
    t: vec4<f32>,
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<uniform> step: Step;
@group(0) @binding(2) var<storage, read_write> state: array<State>;
@group(0) @binding(3) var<storage, read> part: array<Part>;
@group(0) @binding(4) var<storage, read> edge: array<Edge>;
@group(0) @binding(5) var<storage, read_write> pair_f: array<vec4<f32>>;
// (substeps + 1) × bones transforms: substep s's start at s × bones.
@group(0) @binding(6) var<storage, read> tfs: array<Tf>;
@group(0) @binding(7) var<storage, read_write> bad: array<atomic<u32>>;
@group(0) @binding(8) var<storage, read_write> rot: array<Rot>;
// Vertices: the bones' rotations at the frame's end (xyzw), each particle's rotation for the
// vertices, the vertex ties (4 particles, then their 4 rest offsets), the posed vertices.
@group(0) @binding(9) var<storage, read> bone_q: array<vec4<f32>>;
@group(0) @binding(10) var<storage, read_write> prot: array<vec4<f32>>;
@group(0) @binding(11) var<storage, read> ties: array<Tie>;
@group(0) @binding(12) var<storage, read_write> verts: array<vec4<f32>>;

struct Tie {
    p: vec4<u32>,
    o0: vec4<f32>,
    o1: vec4<f32>,
    o2: vec4<f32>,
    o3: vec4<f32>,
}

// Σ over a particle's neighbours of (x_j − x_i) ⊗ rest offset: the matrix its rotation is
// fitted to and whose determinant gives its volume change (skin/particles.rs, the same sum in
// the same order).
fn neighbourhood(i: u32, pi: Part) -> mat3x3<f32> {
    let xi = state[i].x.xyz;
    var a = mat3x3<f32>(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var e = pi.idx.x; e < pi.idx.y; e++) {
        let ed = edge[e];
        let d = state[ed.j].x.xyz - xi;
        a += mat3x3<f32>(d * ed.off.x, d * ed.off.y, d * ed.off.z);
    }
    return a;
}

// `rounds` rounds of Müller et al.'s iteration from q (skin/particles.rs `extract_rotation`).
fn extract_rotation(a: mat3x3<f32>, q0: vec4<f32>, rounds: u32) -> vec4<f32> {
    var q = q0;
    for (var k = 0u; k < rounds; k++) {
        let r = quat_mat(q);
        let num = cross(r[0], a[0]) + cross(r[1], a[1]) + cross(r[2], a[2]);
        let den = abs(dot(r[0], a[0]) + dot(r[1], a[1]) + dot(r[2], a[2])) + 1e-20;
        let w = num / den;
        if dot(w, w) < 1e-18 {
            break;
        }
        let st = normalize(vec4<f32>(0.5 * w, 1.0));
        q = normalize(quat_mul(st, q));
    }
    return q;
}

fn quat_rotate(q: vec4<f32>, v: vec3<f32>) -> vec3<f32> {
    let t = 2.0 * cross(q.xyz, v);
    return v + q.w * t + cross(q.xyz, t);
}

// Each particle's rotation for the vertices (VertexRotation::Particle): one round from its
// tracked rotation with corotated springs, else 20 rounds from its bone's.
@compute @workgroup_size(64)
fn particle_rotations(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i >= p.n {
        return;
    }
    let pi = part[i];
    let a = neighbourhood(i, pi);
    if p.corotated == 1u {
        prot[i] = extract_rotation(a, rot[i].q, 1u);
    } else {
        prot[i] = extract_rotation(a, bone_q[pi.bone.x], 20u);
    }
}

// Each vertex: the mean of its 4 particles' proposals (position plus the turned rest offset).
@compute @workgroup_size(64)
fn vertices(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let v = thread_index(gid, nwg);
    if v >= p.verts {
        return;
    }
    let t = ties[v];
    let offs = array<vec3<f32>, 4>(t.o0.xyz, t.o1.xyz, t.o2.xyz, t.o3.xyz);
    var sum = vec3<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        let j = t.p[k];
        var q: vec4<f32>;
        if p.vrot_particle == 1u {
            q = prot[j];
        } else {
            q = bone_q[part[j].bone.x];
        }
        sum += state[j].x.xyz + quat_rotate(q, offs[k]);
    }
    verts[v] = vec4<f32>(sum * 0.25, 1.0);
}

fn apply(m: Tf, q: vec3<f32>) -> vec3<f32> {
    return m.x.xyz * q.x + m.y.xyz * q.y + m.z.xyz * q.z + m.t.xyz;
}

// glam's Mat3A::from_quat.
fn quat_mat(q: vec4<f32>) -> mat3x3<f32> {
    let x2 = q.x + q.x;
    let y2 = q.y + q.y;
    let z2 = q.z + q.z;
    let xx = q.x * x2;
    let xy = q.x * y2;
    let xz = q.x * z2;
    let yy = q.y * y2;
    let yz = q.y * z2;
    let zz = q.z * z2;
    let wx = q.w * x2;
    let wy = q.w * y2;
    let wz = q.w * z2;
    return mat3x3<f32>(
        vec3<f32>(1.0 - (yy + zz), xy + wz, xz - wy),
        vec3<f32>(xy - wz, 1.0 - (xx + zz), yz + wx),
        vec3<f32>(xz + wy, yz - wx, 1.0 - (xx + yy)),
    );
}

// Hamilton product a b (xyzw).
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.w * b.x + a.x * b.w + a.y * b.z - a.z * b.y,
        a.w * b.y - a.x * b.z + a.y * b.w + a.z * b.x,
        a.w * b.z + a.x * b.y - a.y * b.x + a.z * b.w,
        a.w * b.w - a.x * b.x - a.y * b.y - a.z * b.z,
    );
}

// Pass 0 (corotated springs or pressure): each particle's rotation, one round of Müller et
// al.'s iteration from its last one (skin/particles.rs `extract_rotation`), and its
// neighbourhood's volume change det A / det B. Each invocation reads only its own rotation.
@compute @workgroup_size(64)
fn rotate(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i >= p.n {
        return;
    }
    let pi = part[i];
    let a = neighbourhood(i, pi);
    var ro = rot[i];
    if p.corotated == 1u {
        var q = ro.q;
        let r = quat_mat(q);
        let num = cross(r[0], a[0]) + cross(r[1], a[1]) + cross(r[2], a[2]);
        let den = abs(dot(r[0], a[0]) + dot(r[1], a[1]) + dot(r[2], a[2])) + 1e-20;
        let w = num / den;
        if dot(w, w) >= 1e-18 {
            let st = normalize(vec4<f32>(0.5 * w, 1.0));
            q = normalize(quat_mul(st, q));
        }
        ro.q = q;
        let h = quat_mat(q) * 0.5;
        ro.hx = vec4<f32>(h[0], ro.hx.w);
        ro.hy = vec4<f32>(h[1], 0.0);
        ro.hz = vec4<f32>(h[2], 0.0);
    }
    var jac = 1.0;
    if pi.bone.z == 1u {
        // Bounded as on the CPU (JAC_RANGE in skin/particles.rs).
        jac = clamp(determinant(a) / bitcast<f32>(pi.bone.y), 0.0, 2.0);
    }
    ro.hx.w = jac;
    rot[i] = ro;
}

@compute @workgroup_size(64)
fn pairs_corotated(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i >= p.n {
        return;
    }
    let pi = part[i];
    let xi = state[i].x.xyz;
    let vi = state[i].ve.xyz;
    let ri = rot[i];
    let hri = mat3x3<f32>(ri.hx.xyz, ri.hy.xyz, ri.hz.xyz);
    let hkv = 0.5 * p.kv;
    let pri = hkv * ri.hx.w;
    var slot = pi.idx.w;
    for (var e = pi.idx.z; e < pi.idx.y; e++) {
        let ed = edge[e];
        let dx = state[ed.j].x.xyz - xi;
        let d2 = dot(dx, dx);
        var f = vec3<f32>(0.0);
        let rj = rot[ed.j];
        let pr = (pri + hkv * rj.hx.w) - p.kv;
        if d2 > 0.0 {
            if p.corotated == 1u {
                let nrm = dx * (1.0 / sqrt(d2));
                let hrj = mat3x3<f32>(rj.hx.xyz, rj.hy.xyz, rj.hz.xyz);
                let off = (hri + hrj) * ed.off.xyz;
                f = p.ks * (dx - off) + pr * dx
                    + (p.cs * dot(state[ed.j].ve.xyz - vi, nrm)) * nrm;
            } else {
                let d = sqrt(d2);
                let nrm = dx / d;
                let s = p.ks * (d - ed.rest_len) + p.cs * dot(state[ed.j].ve.xyz - vi, nrm);
                f = s * nrm + pr * dx;
            }
        }
        pair_f[slot] = vec4<f32>(f, 0.0);
        slot++;
    }
}

@compute @workgroup_size(64)
fn pairs(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i >= p.n {
        return;
    }
    let pi = part[i];
    let xi = state[i].x.xyz;
    let vi = state[i].ve.xyz;
    var slot = pi.idx.w;
    for (var e = pi.idx.z; e < pi.idx.y; e++) {
        let ed = edge[e];
        let dx = state[ed.j].x.xyz - xi;
        let d = length(dx);
        var f = vec3<f32>(0.0);
        if d > 0.0 {
            let nrm = dx / d;
            let s = p.ks * (d - ed.rest_len) + p.cs * dot(state[ed.j].ve.xyz - vi, nrm);
            f = s * nrm;
        }
        pair_f[slot] = vec4<f32>(f, 0.0);
        slot++;
    }
}

@compute @workgroup_size(64)
fn update(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i >= p.n {
        return;
    }
    let pi = part[i];
    var acc = vec3<f32>(0.0);
    for (var e = pi.idx.x; e < pi.idx.y; e++) {
        let ed = edge[e];
        acc += ed.weight * pair_f[ed.pair].xyz;
    }
    let b = pi.bone.x;
    let target_now = apply(tfs[step.s * p.bones + b], pi.rest.xyz);
    var st = state[i];
    let xi = st.x.xyz;
    let an = acc + (p.kb * (target_now - xi) - p.cb * st.ve.xyz);
    let v = st.v.xyz + p.h * an;
    let x = xi + p.h * v;
    st.v = vec4<f32>(v, 0.0);
    st.x = vec4<f32>(x, 0.0);
    st.ve = vec4<f32>(v + (0.5 * p.h) * an, 0.0);
    state[i] = st;
    let target_next = apply(tfs[(step.s + 1u) * p.bones + b], pi.rest.xyz);
    let dev = distance(x, target_next);
    let finite_v = all(abs(v) <= vec3<f32>(3.4e38));
    if !(dev <= p.limit) || !finite_v {
        atomicMin(&bad[0], i);
        atomicMin(&bad[1], step.s);
    }
}
