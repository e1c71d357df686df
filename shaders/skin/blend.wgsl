// Linear blend and dual quaternion skinning (crates/imprint-stages/src/skin/gpu.rs), one
// invocation per vertex, the f32 counterparts of skin/blend.rs (`lbs`, `dqs`, which work in
// f64). Each vertex reads its rest position, its influences and its bones, and writes only its
// own posed position: no atomics, no order dependence.
//
// Influences: up to 4 (bone, weight) per vertex, most-weighted first (the DQS pivot is slot
// 0); unused slots have weight 0 and add exactly nothing.
//
// Bones, per frame, 4 vec4 each, depending on the entry point:
// - `lbs`: the skin transform's columns x_axis, y_axis, z_axis, translation (w unused);
// - `dqs`: the unit dual quaternion (real xyzw, dual xyzw) built on the CPU in f64 from the
//   same transform, then rounded to f32; the last two vec4 unused.

struct Params {
    vertices: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

struct Influence {
    bone: vec4<u32>,
    weight: vec4<f32>,
}

struct Bone {
    a: vec4<f32>,
    b: vec4<f32>,
    c: vec4<f32>,
    d: vec4<f32>,
}

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var<storage, read> rest: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> influence: array<Influence>;
@group(0) @binding(3) var<storage, read> bones: array<Bone>;
@group(0) @binding(4) var<storage, read_write> posed: array<vec4<f32>>;

// Real parts whose blend is shorter than this keep the pivot's transform (as the CPU).
const DEGENERATE: f32 = 1e-12;

@compute @workgroup_size(64)
fn lbs(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let v = thread_index(gid, nwg);
    if v >= p.vertices {
        return;
    }
    let x = rest[v].xyz;
    let inf = influence[v];
    var acc = vec3<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        let w = inf.weight[k];
        if w == 0.0 {
            continue;
        }
        let m = bones[inf.bone[k]];
        let q = m.a.xyz * x.x + m.b.xyz * x.y + m.c.xyz * x.z + m.d.xyz;
        acc += w * q;
    }
    posed[v] = vec4<f32>(acc, 1.0);
}

@compute @workgroup_size(64)
fn dqs(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let v = thread_index(gid, nwg);
    if v >= p.vertices {
        return;
    }
    let x = rest[v].xyz;
    let inf = influence[v];
    let pivot = bones[inf.bone[0]];
    var r = vec4<f32>(0.0);
    var d = vec4<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        var w = inf.weight[k];
        if w == 0.0 {
            continue;
        }
        let b = bones[inf.bone[k]];
        // The antipodality fix: every rotation in the pivot's hemisphere.
        if dot(b.a, pivot.a) < 0.0 {
            w = -w;
        }
        r += w * b.a;
        d += w * b.b;
    }
    let len = length(r);
    if len > DEGENERATE {
        r = r / len;
        d = d / len;
    } else {
        r = pivot.a;
        d = pivot.b;
    }
    // Rotation by r: x + 2 r.w (u × x) + 2 u × (u × x), with u = r.xyz.
    let u = r.xyz;
    let uv = cross(u, x);
    let turned = x + 2.0 * (r.w * uv + cross(u, uv));
    // Translation: the vector part of 2 d r*.
    let t = 2.0 * (r.w * d.xyz - d.w * u + cross(u, d.xyz));
    posed[v] = vec4<f32>(turned + t, 1.0);
}
