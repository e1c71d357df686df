// Thread index of a 1D dispatch folded into x and y (GpuContext::dispatch_1d): workgroups of
// 64 threads along x, and as many rows of them along y as the per-dimension limit requires.
const WORKGROUP_SIZE: u32 = 64u;

fn thread_index(gid: vec3<u32>, num_workgroups: vec3<u32>) -> u32 {
    return gid.x + gid.y * num_workgroups.x * WORKGROUP_SIZE;
}
