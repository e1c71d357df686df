// The arrival look-ups of one fall direction, the GPU twin of
// imprint_stages::snow::arrival::reaches: one invocation per receiver (mesh vertices, then
// ground cells) compares its view depth with the depth map's texel its projection falls in,
// with the bias texel × (bias_texels + min(tan β, 8)), and adds 1 to its own count when
// reached (no atomics: each invocation owns its count). The host dispatches once per
// direction, with that direction's map and `LookupParams`.
// Prepended: common/dispatch.wgsl.
//
// f32 as on the CPU, but dot products and the projection may be fused by the shader
// compiler, and the slope's division may be less exact than the CPU's, so a receiver exactly
// at a texel edge or on the bias threshold can flip (see snow::gpu).

struct LookupParams {
    // The map camera's frame (xyz; w unused).
    eye: vec4<f32>,
    right: vec4<f32>,
    up: vec4<f32>,
    forward: vec4<f32>,
    // The fall direction (xyz).
    dir: vec4<f32>,
    // Pixels per world unit, half the image side in pixels, texel size, bias_texels.
    k: f32,
    centre: f32,
    texel: f32,
    bias_texels: f32,
    res: u32,
    receivers: u32,
    // `lookup_resident`: elements from one row of `texels` to the next.
    row_texels: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> lp: LookupParams;
// Per receiver: xyz position (w unused), then xyz normal (w unused).
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> normals: array<vec4<f32>>;
// View depth per texel, row-major from the top row; UNCOVERED where no triangle covers it.
@group(0) @binding(3) var<storage, read> depth_map: array<f32>;
@group(0) @binding(4) var<storage, read_write> counts: array<u32>;
// `lookup_resident`: the rasteriser's texels where it rendered them (imprint_gpu::raster::
// GpuDepthMap): per texel (view depth, coverage), rows `row_texels` apart, top row first.
@group(0) @binding(5) var<storage, read> texels: array<vec2<f32>>;

const MAX_BIAS_SLOPE: f32 = 8.0;
// f32::MAX (not +inf, which a compiler may assume away).
const UNCOVERED: f32 = 3.40282347e38;

// Where receiver `r` falls in the view: its texel and its depth along the view, or `ok`
// false when it faces away from the fall (or its normal is NaN).
struct Look {
    ok: bool,
    i: u32,
    j: u32,
    depth: f32,
    c: f32,
}

fn look(r: u32) -> Look {
    var l: Look;
    let n = normals[r].xyz;
    l.c = -dot(n, lp.dir.xyz);
    // `!(c > 0)` also refuses NaN.
    l.ok = l.c > 0.0;
    let q = points[r].xyz - lp.eye.xyz;
    let v = vec3<f32>(dot(q, lp.right.xyz), dot(q, lp.up.xyz), dot(q, lp.forward.xyz));
    let px = lp.centre + v.x * lp.k;
    let py = lp.centre - v.y * lp.k;
    let last = f32(lp.res) - 1.0;
    l.i = u32(clamp(floor(px), 0.0, last));
    l.j = u32(clamp(floor(py), 0.0, last));
    l.depth = v.z;
    return l;
}

// Counts receiver `r` when nothing nearer than its biased depth was `seen` at its texel.
fn count_if_reached(r: u32, l: Look, seen: f32) {
    var reached = true;
    if seen != UNCOVERED {
        let tan = min(sqrt(max(1.0 - l.c * l.c, 0.0)) / l.c, MAX_BIAS_SLOPE);
        reached = l.depth <= seen + lp.texel * (lp.bias_texels + tan);
    }
    if reached {
        counts[r] += 1u;
    }
}

@compute @workgroup_size(64)
fn lookup(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let r = thread_index(gid, nwg);
    if r >= lp.receivers {
        return;
    }
    let l = look(r);
    if l.ok {
        count_if_reached(r, l, depth_map[l.j * lp.res + l.i]);
    }
}

// `lookup` on a depth map left where the rasteriser rendered it: the same test, the texel
// read from `texels` (nothing uploaded): the depth where covered, UNCOVERED elsewhere.
@compute @workgroup_size(64)
fn lookup_resident(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let r = thread_index(gid, nwg);
    if r >= lp.receivers {
        return;
    }
    let l = look(r);
    if l.ok {
        let t = texels[l.j * lp.row_texels + l.i];
        count_if_reached(r, l, select(UNCOVERED, t.x, t.y > 0.5));
    }
}
