// Narrow-band distance field from a discrete boundary (docs/methods.md §2), the GPU twin of
// imprint_stages::sdf::cpu.
//
// In grid coordinates (cell centres at integers). Each boundary point writes into the cells
// within `band` of it (H's splat), deterministically in three passes:
//   scatter, mode 0 (per surface cell s): atomicMin of the bits of |x - p_s|^2 in every cell x
//                   with |x - p_s|^2 <= band^2 (non-negative floats order like their bits);
//   scatter, mode 1 (per surface cell s): where the bits equal the stored minimum, atomicMin
//                   of s, so ties go to the smaller surface-cell index = smaller point index;
//   finish          (per cell): distance and closest-point vector in world units. For a
//                   Closest boundary, refined as on the CPU: among the owning triangles of
//                   the cell's nearest point and of its six neighbours' nearest points, the
//                   one closest to the cell (ties to the smaller point index) gives the exact
//                   distance and vector, and its point becomes the cell's nearest.
// Modes 0 and 1 are one entry point so both compute the distance with the same code.
// Prepended: common/dispatch.wgsl, common/geom.wgsl.
// Splatting costs (surface cells) x (2a+1)^3 distance tests instead of (all cells) x (2a+2)^3
// reads for a gather, and the boundary is a thin shell, so it is the cheaper side. The splat
// runs one thread per surface cell from a compacted list (`compact`, then an indirect dispatch
// sized on the GPU by `size_dispatch`), so nothing waits for the CPU.

struct FieldParams {
    // xyz: grid cells per axis; w: number of cells.
    dims: vec4<u32>,
    // xyz: world position of cell (0, 0, 0)'s centre; w: cell edge (world units).
    origin: vec4<f32>,
    // Half-width of the band in cells (a), a*a as the CPU computes it, the distance of far
    // cells (a * cell).
    band: f32,
    band2: f32,
    far_value: f32,
    _pad3: u32,
    // scatter: 0 = minimum distance, 1 = minimum point at that distance.
    mode: u32,
    // 1 when the boundary is the Centre variant (points at cell centres).
    centre: u32,
    // Always 0; see `rnd` in common/geom.wgsl.
    zero: u32,
    // The device's max_compute_workgroups_per_dimension (for the indirect dispatch).
    max_groups: u32,
    // 1: refine distances to the owning triangles (Closest boundaries).
    refine: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

const FAR: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> params: FieldParams;
// Per cell: xyz the boundary point (grid coordinates), w = 1 for surface cells (GpuBoundary).
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> best_d2: array<atomic<u32>>;
// Per cell: linear index of the surface cell whose point is nearest, or FAR (the splat's
// result; `finish` writes the refined one to `nearest_out`).
@group(0) @binding(3) var<storage, read_write> nearest: array<atomic<u32>>;
// Per cell: xyz = p - x (world units, 0 when far), w = distance (world units, far_value when far).
@group(0) @binding(4) var<storage, read_write> field: array<vec4<f32>>;
// to_cell(center(i)) along x (nx values), then y, then z, computed on the CPU.
@group(0) @binding(5) var<storage, read> axis_coords: array<f32>;
// The surface cells, in no particular order (the minima do not depend on it), and their count.
@group(0) @binding(6) var<storage, read_write> surface: array<u32>;
@group(0) @binding(7) var<storage, read_write> surface_count: atomic<u32>;
// Indirect dispatch arguments (x, y, z workgroups) for one thread per surface cell.
@group(0) @binding(8) var<storage, read_write> dispatch_args: array<u32, 3>;
// Per cell: index into `faces` of the owning triangle of its point (GpuBoundary::owner).
@group(0) @binding(9) var<storage, read> owner: array<u32>;
// Per face: three vertices in grid coordinates (GpuBoundary::faces).
@group(0) @binding(10) var<storage, read> faces: array<vec4<f32>>;
// Per cell: the final nearest surface cell, or FAR.
@group(0) @binding(11) var<storage, read_write> nearest_out: array<u32>;

fn coords(idx: u32) -> vec3<u32> {
    let nx = params.dims.x;
    let ny = params.dims.y;
    return vec3<u32>(idx % nx, (idx / nx) % ny, idx / (nx * ny));
}

// x / cell correctly rounded, as the CPU's division is (WGSL's `/` may be ulps off).
fn div_cell(x: f32) -> f32 {
    return div_rn(x, params.origin.w);
}

// The grid coordinates the CPU field works with for the boundary point of surface cell s:
// to_cell(origin + q * cell), a round trip through world units with its roundings.
fn boundary_point(s: u32, q: vec3<f32>) -> vec3<f32> {
    if params.centre == 1u {
        let c = coords(s);
        let nx = params.dims.x;
        let ny = params.dims.y;
        return vec3<f32>(axis_coords[c.x], axis_coords[nx + c.y], axis_coords[nx + ny + c.z]);
    }
    let cell = params.origin.w;
    let w = params.origin.xyz + vec3<f32>(rnd(q.x * cell), rnd(q.y * cell), rnd(q.z * cell));
    let v = w - params.origin.xyz;
    return vec3<f32>(div_cell(v.x), div_cell(v.y), div_cell(v.z));
}

// Lists the surface cells, so that the splat runs one thread per point with every SIMD lane
// busy instead of one per cell with most lanes idle.
@compute @workgroup_size(64)
fn compact(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = thread_index(gid, nwg);
    if idx < params.dims.w && points[idx].w != 0.0 {
        surface[atomicAdd(&surface_count, 1u)] = idx;
    }
}

// Workgroups for the splat, folded into x and y like GpuContext::dispatch_1d.
@compute @workgroup_size(1)
fn size_dispatch() {
    let groups = max((atomicLoad(&surface_count) + WORKGROUP_SIZE - 1u) / WORKGROUP_SIZE, 1u);
    let x = min(groups, params.max_groups);
    dispatch_args[0] = x;
    dispatch_args[1] = (groups + x - 1u) / x;
    dispatch_args[2] = 1u;
}

@compute @workgroup_size(64)
fn scatter(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let t = thread_index(gid, nwg);
    if t >= atomicLoad(&surface_count) {
        return;
    }
    geom_zero = params.zero;
    let s = surface[t];
    let point = points[s];
    let p = boundary_point(s, point.xyz);
    // Rows of the ball of radius `band` around p, a hair wide (SLACK): only ranges are cut
    // here; the d2 test below decides, exactly as on the CPU. The ball is a third of its cube.
    let slack = 1e-3;
    let top = vec3<f32>(params.dims.xyz) - 1.0;
    let z_lo = max(ceil(p.z - params.band - slack), 0.0);
    let z_hi = min(floor(p.z + params.band + slack), top.z);
    if z_lo > z_hi {
        return;
    }
    let nx = params.dims.x;
    let ny = params.dims.y;
    for (var k = u32(z_lo); k <= u32(z_hi); k++) {
        let dz = f32(k) - p.z;
        let dz2 = rnd(dz * dz);
        let ry = sqrt(max(params.band2 - dz2, 0.0));
        let y_lo = max(ceil(p.y - ry - slack), 0.0);
        let y_hi = min(floor(p.y + ry + slack), top.y);
        if y_lo > y_hi {
            continue;
        }
        for (var j = u32(y_lo); j <= u32(y_hi); j++) {
            let dy = f32(j) - p.y;
            // The CPU's order: (dy*dy + dz*dz), then dx*dx + that.
            let dyz2 = rnd(dy * dy) + dz2;
            let rx = sqrt(max(params.band2 - dyz2, 0.0));
            let x_lo = max(ceil(p.x - rx - slack), 0.0);
            let x_hi = min(floor(p.x + rx + slack), top.x);
            if x_lo > x_hi {
                continue;
            }
            for (var i = u32(x_lo); i <= u32(x_hi); i++) {
                let dx = f32(i) - p.x;
                let d2 = rnd(dx * dx) + dyz2;
                if d2 > params.band2 {
                    continue;
                }
                let idx = i + nx * (j + ny * k);
                let bits = bitcast<u32>(d2);
                // A plain look first: most candidates lose, and atomics are the expensive part.
                let current = atomicLoad(&best_d2[idx]);
                if params.mode == 0u {
                    if bits < current {
                        atomicMin(&best_d2[idx], bits);
                    }
                } else if current == bits {
                    atomicMin(&nearest[idx], s);
                }
            }
        }
    }
}

// The closest point to x of the triangle that owns surface cell n's point.
fn owner_closest(n: u32, x: vec3<f32>) -> vec3<f32> {
    let f = 3u * owner[n];
    return closest_point_on_triangle(x, faces[f].xyz, faces[f + 1u].xyz, faces[f + 2u].xyz);
}

@compute @workgroup_size(64)
fn finish(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = thread_index(gid, nwg);
    if idx >= params.dims.w {
        return;
    }
    geom_zero = params.zero;
    let n0 = atomicLoad(&nearest[idx]);
    if n0 == FAR {
        field[idx] = vec4<f32>(0.0, 0.0, 0.0, params.far_value);
        nearest_out[idx] = FAR;
        return;
    }
    let c = coords(idx);
    let x = vec3<f32>(c);
    let cell = params.origin.w;
    if params.refine == 0u {
        let d2 = bitcast<f32>(atomicLoad(&best_d2[idx]));
        field[idx] = vec4<f32>((points[n0].xyz - x) * cell, sqrt(d2) * cell);
        nearest_out[idx] = n0;
        return;
    }
    var best_n = n0;
    var best_face = owner[n0];
    var best_q = owner_closest(n0, x);
    var best = dot3(best_q - x, best_q - x);
    let strides = vec3<u32>(1u, params.dims.x, params.dims.x * params.dims.y);
    for (var k = 0u; k < 6u; k++) {
        let axis = k / 2u;
        var j = idx;
        if k % 2u == 0u {
            if c[axis] == 0u {
                continue;
            }
            j -= strides[axis];
        } else {
            if c[axis] + 1u >= params.dims[axis] {
                continue;
            }
            j += strides[axis];
        }
        let n = atomicLoad(&nearest[j]);
        if n == FAR {
            continue;
        }
        // Neighbours mostly share the best triangle: the same face gives the same d2 bits,
        // so only the point index can decide, and the closest point need not be recomputed.
        if owner[n] == best_face {
            best_n = min(best_n, n);
            continue;
        }
        let q = owner_closest(n, x);
        let d2 = dot3(q - x, q - x);
        // The smallest (d2, point index): the order candidates come in does not matter.
        if d2 < best || (d2 == best && n < best_n) {
            best = d2;
            best_n = n;
            best_face = owner[n];
            best_q = q;
        }
    }
    field[idx] = vec4<f32>((best_q - x) * cell, sqrt(best) * cell);
    nearest_out[idx] = best_n;
}
