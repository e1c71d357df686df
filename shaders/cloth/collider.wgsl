// A GPU distance field (shaders/sdf/field.wgsl's output) turned into the cloth's collider
// cells on the device: per cell the vec4 that imprint_core::DistanceField::cells computes for
// the field GpuField::to_cpu reads back, so GpuCollider::from_gpu_field holds the bits that
// GpuCollider::from_field(ctx, &field.to_cpu(ctx)?) uploads, without the round trip.
// Prepended: common/dispatch.wgsl, common/geom.wgsl.
//
// DistanceField::cells, per cell c with distance d and nearest boundary point n:
//   far (n = FAR):  (0, 0, 0, -d);
//   near:           (closest - centre, d), centre = origin + c * cell (world units),
//                   closest = the point n (Centre boundaries: origin + q * cell from its grid
//                   coordinates q, as GpuBoundary::to_cpu computes it) or the closest point to
//                   the centre of its owning triangle in world units (Closest boundaries).
// Every product is rounded on its own (`rnd`, common/geom.wgsl), as the CPU rounds it.

struct ColliderParams {
    // xyz: cells per axis; w: number of cells.
    dims: vec4<u32>,
    // xyz: world position of cell (0, 0, 0)'s centre; w: cell edge.
    origin: vec4<f32>,
    // 1: closest points on the owning triangles (Closest boundaries); 0: the points.
    closest: u32,
    // Always 0; see `rnd` in common/geom.wgsl.
    zero: u32,
    _pad0: u32,
    _pad1: u32,
}

const FAR: u32 = 0xffffffffu;

@group(0) @binding(0) var<uniform> params: ColliderParams;
// GpuField::field: per cell xyz (grid-scaled vector, unused here), w the distance.
@group(0) @binding(1) var<storage, read> field: array<vec4<f32>>;
// GpuField::nearest_cell: the surface cell whose point is nearest, or FAR.
@group(0) @binding(2) var<storage, read> nearest: array<u32>;
// GpuBoundary::points: per cell xyz the boundary point in grid coordinates.
@group(0) @binding(3) var<storage, read> points: array<vec4<f32>>;
// GpuBoundary::owner: per cell the owning face.
@group(0) @binding(4) var<storage, read> owner: array<u32>;
// GpuBoundary::faces_world: per face three vertices, world units (xyz).
@group(0) @binding(5) var<storage, read> faces_world: array<vec4<f32>>;
@group(0) @binding(6) var<storage, read_write> cells: array<vec4<f32>>;

@compute @workgroup_size(64)
fn collider_cells(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let idx = thread_index(gid, nwg);
    if idx >= params.dims.w {
        return;
    }
    geom_zero = params.zero;
    let d = field[idx].w;
    let n = nearest[idx];
    if n == FAR {
        cells[idx] = vec4<f32>(0.0, 0.0, 0.0, -d);
        return;
    }
    let nx = params.dims.x;
    let ny = params.dims.y;
    let c = vec3<u32>(idx % nx, (idx / nx) % ny, idx / (nx * ny));
    let cell = params.origin.w;
    let centre = params.origin.xyz + rnd3(vec3<f32>(c) * cell);
    var q: vec3<f32>;
    if params.closest == 1u {
        let f = 3u * owner[n];
        q = closest_point_on_triangle(centre, faces_world[f].xyz, faces_world[f + 1u].xyz, faces_world[f + 2u].xyz);
    } else {
        q = params.origin.xyz + rnd3(points[n].xyz * cell);
    }
    cells[idx] = vec4<f32>(q - centre, d);
}
