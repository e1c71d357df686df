// Sets every element of a u32 buffer to one value (GpuContext::fill_u32).
struct Fill {
    value: u32,
    count: u32,
    _pad0: u32,
    _pad1: u32,
}

@group(0) @binding(0) var<uniform> fill: Fill;
@group(0) @binding(1) var<storage, read_write> target_buf: array<u32>;

@compute @workgroup_size(64)
fn fill_u32(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i < fill.count {
        target_buf[i] = fill.value;
    }
}
