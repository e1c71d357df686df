// Particle skinning substeps (crates/imprint-stages/src/skin/gpu_particles.rs), the f32 GPU
// counterpart of `ParticleSkin::step_frame` (skin/particles.rs) for T's distance springs
// without pressure. Two dispatches per substep, the CPU's passes 1 and 2:
// - `pairs`: one invocation per particle i computes each of its pairs with j > i once, into
//   the pair's own slot (spring toward the rest length plus damping along the pair);
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
// pair slot (pair_start); bone.
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

fn apply(m: Tf, q: vec3<f32>) -> vec3<f32> {
    return m.x.xyz * q.x + m.y.xyz * q.y + m.z.xyz * q.z + m.t.xyz;
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
