// Depth maps: imprint_gpu::raster::GpuRasterizer, the twin of
// imprint_core::raster::rasterize_depth_with. Prepended: render/camera.wgsl.
//
// The depth test keeps the nearest surface (camera.wgsl). The colour target (Rg32Float,
// cleared to 0) receives (view depth, 1): the view depth is a varying, interpolated
// perspective-correctly, which is the CPU's 1 / lerp(1 / d) up to float rounding; it is not
// decoded from the depth buffer, whose non-linear encoding would lose digits. The 1 marks
// coverage (view depths of an orthographic camera may be zero or negative, so the depth
// cannot double as the marker).

struct DepthOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) depth: f32,
}

@vertex
fn vs_depth(@location(0) position: vec3<f32>) -> DepthOut {
    let v = to_view(position);
    return DepthOut(to_clip(v), v.z);
}

@fragment
fn fs_depth(in: DepthOut) -> @location(0) vec2<f32> {
    return vec2<f32>(in.depth, 1.0);
}
