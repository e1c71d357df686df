// Narrow-band distance field from a discrete boundary (METHODS §2), the GPU twin of
// imprint_stages::sdf::cpu. Prepended: common/dispatch.wgsl.
//
// In grid coordinates (cell centres at integers). Each boundary point writes into the cells
// within `band` of it (H's splat), deterministically in three passes:
//   scatter, mode 0 (per surface cell s): atomicMin of the bits of |x - p_s|^2 in every cell x
//                   with |x - p_s|^2 <= band^2 (non-negative floats order like their bits);
//   scatter, mode 1 (per surface cell s): where the bits equal the stored minimum, atomicMin
//                   of s, so ties go to the smaller surface-cell index = smaller point index;
//   finish          (per cell): distance and closest-point vector in world units.
// Modes 0 and 1 are one entry point so both compute the distance with the same code.
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
    // cells (a * cell), and the correctly rounded 1 / cell.
    band: f32,
    band2: f32,
    far_value: f32,
    inv_cell: f32,
    // scatter: 0 = minimum distance, 1 = minimum point at that distance.
    mode: u32,
    // 1 when the boundary is the Centre variant (points at cell centres).
    centre: u32,
    // Always 0; see `rnd`.
    zero: u32,
    // The device's max_compute_workgroups_per_dimension (for the indirect dispatch).
    max_groups: u32,
}

const FAR: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> params: FieldParams;
// Per cell: xyz the boundary point (grid coordinates), w = 1 for surface cells (GpuBoundary).
@group(0) @binding(1) var<storage, read> points: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read_write> best_d2: array<atomic<u32>>;
// Per cell: linear index of the surface cell whose point is nearest, or FAR.
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

// The value of x, rounded on its own: an unknowable (to the compiler) no-op that keeps
// `a * b + c` from being fused into one fma, which would round differently from the CPU and
// decide exact ties (very common with Centre points) differently.
fn rnd(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) ^ params.zero);
}

fn coords(idx: u32) -> vec3<u32> {
    let nx = params.dims.x;
    let ny = params.dims.y;
    return vec3<u32>(idx % nx, (idx / nx) % ny, idx / (nx * ny));
}

// x / cell correctly rounded (Markstein: one fma correction of x * RN(1/cell)), as the CPU's
// division is; WGSL's `/` may be off by an ulp or two.
fn div_cell(x: f32) -> f32 {
    let q = x * params.inv_cell;
    let r = fma(-q, params.origin.w, x);
    return fma(r, params.inv_cell, q);
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
    let s = surface[t];
    let point = points[s];
    let p = boundary_point(s, point.xyz);
    // Rows of the ball of radius `band` around p, a hair wide (SLACK): only ranges are cut
    // here; the d2 test below decides, exactly as on the CPU. The ball is a third of its cube.
    let slack = 0.05;
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

@compute @workgroup_size(64)
fn finish(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = thread_index(gid, nwg);
    if idx >= params.dims.w {
        return;
    }
    let n = atomicLoad(&nearest[idx]);
    if n == FAR {
        field[idx] = vec4<f32>(0.0, 0.0, 0.0, params.far_value);
        return;
    }
    let x = vec3<f32>(coords(idx));
    let d2 = bitcast<f32>(atomicLoad(&best_d2[idx]));
    let cell = params.origin.w;
    field[idx] = vec4<f32>((points[n].xyz - x) * cell, sqrt(d2) * cell);
}
