// Surface voxelisation into a discrete boundary (docs/methods.md §1), the GPU twin of
// imprint_stages::voxel::cpu. Prepended: common/dispatch.wgsl, common/geom.wgsl.
//
// Everything is in grid coordinates (cell (i, j, k)'s centre is the point (i, j, k)).
// Deterministic in three passes, whatever order the threads run in:
//   touch, mode 0  (per triangle): for every cell the triangle touches, atomicMin of the bits
//                  of the squared distance from the cell centre to the triangle (non-negative
//                  floats order like their bits as u32).
//   touch, mode 1  (per triangle): where its distance bits equal the stored minimum,
//                  atomicMin of the triangle index (ties go to the smaller index).
//   finish         (per cell): the boundary point of each surface cell.
// Modes 0 and 1 are one entry point so both compute the distance with the same code.

struct VoxelParams {
    // xyz: grid cells per axis; w: number of triangles.
    dims: vec4<u32>,
    // Half-size of the touching box (CELL_HALF = 0.5 + 1e-5: closed, a hair over the cell).
    half: f32,
    // Squared radius of the sphere around that box (3 * half * half, computed on the CPU).
    outer2: f32,
    // touch: 0 = minimum distance, 1 = minimum triangle at that distance.
    mode: u32,
    // 0 = Centre, 1 = Closest.
    variant: u32,
    n_cells: u32,
    // Always 0; see `rnd` in common/geom.wgsl.
    zero: u32,
    _pad1: u32,
    _pad2: u32,
}

const NONE: u32 = 0xffffffffu;
const VARIANT_CLOSEST: u32 = 1u;

@group(0) @binding(0) var<uniform> params: VoxelParams;
// Three per triangle: its vertices in grid coordinates (w unused).
@group(0) @binding(1) var<storage, read> tris: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> best_d2: array<atomic<u32>>;
@group(0) @binding(3) var<storage, read_write> best_tri: array<atomic<u32>>;
// Per cell: xyz the boundary point (grid coordinates), w = 1 for surface cells, 0 otherwise.
@group(0) @binding(4) var<storage, read_write> points: array<vec4<f32>>;

fn cell_index(c: vec3<u32>) -> u32 {
    return c.x + params.dims.x * (c.y + params.dims.y * c.z);
}

@compute @workgroup_size(64)
fn touch(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = thread_index(gid, nwg);
    if t >= params.dims.w {
        return;
    }
    geom_zero = params.zero;
    let a = tris[3u * t].xyz;
    let b = tris[3u * t + 1u].xyz;
    let c = tris[3u * t + 2u].xyz;
    let half = vec3<f32>(params.half);
    // Candidate cells: the triangle's box grown by the touching half-size, clipped to the grid
    // (the CPU's range, computed the same way).
    let top = vec3<f32>(params.dims.xyz) - 1.0;
    let lo_f = clamp(ceil(min(min(a, b), c) - params.half), vec3<f32>(0.0), top + 1.0);
    let hi_f = clamp(floor(max(max(a, b), c) + params.half), vec3<f32>(-1.0), top);
    if any(lo_f > hi_f) {
        return;
    }
    let lo = vec3<u32>(lo_f);
    let hi = vec3<u32>(hi_f);
    for (var k = lo.z; k <= hi.z; k++) {
        for (var j = lo.y; j <= hi.y; j++) {
            for (var i = lo.x; i <= hi.x; i++) {
                let centre = vec3<f32>(f32(i), f32(j), f32(k));
                let d = closest_point_on_triangle(centre, a, b, c) - centre;
                let d2 = dot3(d, d);
                // Beyond the circumscribed sphere: no contact. Inside the inscribed one, or
                // the closest point inside the box: contact. Otherwise: the exact test. (The
                // CPU's order of decisions.)
                if d2 > params.outer2 {
                    continue;
                }
                if d2 > 0.25 && !all(abs(d) <= half) && !triangle_box_overlap(centre, half, a, b, c) {
                    continue;
                }
                let bits = bitcast<u32>(d2);
                let idx = cell_index(vec3<u32>(i, j, k));
                if params.mode == 0u {
                    atomicMin(&best_d2[idx], bits);
                } else if atomicLoad(&best_d2[idx]) == bits {
                    atomicMin(&best_tri[idx], t);
                }
            }
        }
    }
}

@compute @workgroup_size(64)
fn finish(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = thread_index(gid, nwg);
    if idx >= params.n_cells {
        return;
    }
    geom_zero = params.zero;
    if atomicLoad(&best_d2[idx]) == NONE {
        points[idx] = vec4<f32>(0.0);
        return;
    }
    let nx = params.dims.x;
    let ny = params.dims.y;
    let centre = vec3<f32>(f32(idx % nx), f32((idx / nx) % ny), f32(idx / (nx * ny)));
    if params.variant != VARIANT_CLOSEST {
        points[idx] = vec4<f32>(centre, 1.0);
        return;
    }
    let t = atomicLoad(&best_tri[idx]);
    let q = closest_point_on_triangle(centre, tris[3u * t].xyz, tris[3u * t + 1u].xyz, tris[3u * t + 2u].xyz);
    points[idx] = vec4<f32>(q, 1.0);
}
