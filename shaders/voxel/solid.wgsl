// Solid voxelisation: which cell centres lie inside a closed mesh, the GPU twin of
// imprint_stages::voxel::solid (read its module docs for the method and the tie rules).
// Prepended: common/dispatch.wgsl, common/geom.wgsl.
//
// Three passes, each deterministic whatever order threads run in:
//   mark (per triangle): for each row (y, z) its projection covers, xor 1 into the first cell
//                        past its crossing along x (xor commutes: the order cannot matter);
//   rows (per row):      xor-prefix along the row, in place: the cell's parity;
//   pack (per word):     32 cells' parities into one word of the bitset.
// Every product is rounded on its own (`rnd`), as the CPU rounds it.

struct SolidParams {
    // xyz: grid cells per axis; w: number of triangles.
    dims: vec4<u32>,
    n_rows: u32,
    n_words: u32,
    n_cells: u32,
    // Always 0; see `rnd` in common/geom.wgsl.
    zero: u32,
}

@group(0) @binding(0) var<uniform> params: SolidParams;
// Three per triangle: its vertices in grid coordinates (w unused).
@group(0) @binding(1) var<storage, read> tris: array<vec4<f32>>;
// Per cell: the marks, then (after `rows`) the parity.
@group(0) @binding(2) var<storage, read_write> marks: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> words: array<u32>;

fn orient(p: vec2<f32>, q: vec2<f32>, r: vec2<f32>) -> f32 {
    return rnd((q.x - p.x) * (r.y - p.y)) - rnd((q.y - p.y) * (r.x - p.x));
}

// solid::edge: from the edge's lexicographically smaller end.
fn edge(p: vec2<f32>, q: vec2<f32>, r: vec2<f32>) -> f32 {
    if p.x < q.x || (p.x == q.x && p.y <= q.y) {
        return orient(p, q, r);
    }
    return -orient(q, p, r);
}

// solid::covers.
fn covers(e: f32, d: vec2<f32>) -> bool {
    return e > 0.0 || (e == 0.0 && (d.y > 0.0 || (d.y == 0.0 && d.x > 0.0)));
}

@compute @workgroup_size(64)
fn mark(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = thread_index(gid, nwg);
    if t >= params.dims.w {
        return;
    }
    geom_zero = params.zero;
    let a = tris[3u * t].xyz;
    var b = tris[3u * t + 1u].xyz;
    var c = tris[3u * t + 2u].xyz;
    let area = edge(a.yz, b.yz, c.yz);
    if !(area != 0.0) {
        return;
    }
    if area < 0.0 {
        let s = b;
        b = c;
        c = s;
    }
    let a2 = a.yz;
    let b2 = b.yz;
    let c2 = c.yz;
    let lo = max(ceil(min(min(a2, b2), c2)), vec2<f32>(0.0));
    let hi = min(floor(max(max(a2, b2), c2)), vec2<f32>(f32(params.dims.y), f32(params.dims.z)) - 1.0);
    let nx = f32(params.dims.x);
    for (var z = lo.y; z <= hi.y; z += 1.0) {
        for (var y = lo.x; y <= hi.x; y += 1.0) {
            let r = vec2<f32>(y, z);
            let e0 = edge(b2, c2, r);
            let e1 = edge(c2, a2, r);
            let e2 = edge(a2, b2, r);
            if covers(e0, c2 - b2) && covers(e1, a2 - c2) && covers(e2, b2 - a2) {
                let den = (e0 + e1) + e2;
                let x = div_rn(rnd(e0 * a.x) + rnd(e1 * b.x) + rnd(e2 * c.x), den);
                let first = max(floor(clamp(x, -1.0, nx)) + 1.0, 0.0);
                if den > 0.0 && first < nx {
                    let row = u32(y) + params.dims.y * u32(z);
                    atomicXor(&marks[row * params.dims.x + u32(first)], 1u);
                }
            }
        }
    }
}

@compute @workgroup_size(64)
fn rows(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let row = thread_index(gid, nwg);
    if row >= params.n_rows {
        return;
    }
    let base = row * params.dims.x;
    var parity = 0u;
    for (var x = 0u; x < params.dims.x; x++) {
        parity ^= atomicLoad(&marks[base + x]);
        atomicStore(&marks[base + x], parity);
    }
}

@compute @workgroup_size(64)
fn pack(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let w = thread_index(gid, nwg);
    if w >= params.n_words {
        return;
    }
    var word = 0u;
    for (var k = 0u; k < 32u; k++) {
        let i = 32u * w + k;
        if i < params.n_cells && atomicLoad(&marks[i]) != 0u {
            word |= 1u << k;
        }
    }
    words[w] = word;
}
