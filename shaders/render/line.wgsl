// Lines of the GPU frame renderer (ground grid, wireframes), the twin of the CPU's LineCanvas
// in imprint_render::frame. Prepended: render/camera.wgsl.
//
// Lines are depth-tested against the surfaces (without writing depth) with the CPU's bias: a
// line point at view depth d passes where d <= surface depth * (1 + relative bias). Depth bias
// state does not apply to lines, so the shader moves the line's depth instead:
// - perspective: depth d is tested as d / (1 + bias). The reversed depth a + b / d becomes
//   a + b (1 + bias) / d, still linear in 1 / d, so z_clip = a d + b (1 + bias) interpolates
//   correctly along the line (the CPU's extra absolute 1e-5 is left out: it would break that);
// - orthographic: d is tested as d - bias |d| - absolute bias.

struct LineOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) color: vec3<f32>,
}

@vertex
fn vs_line(@location(0) position: vec3<f32>, @location(1) color: vec3<f32>) -> LineOut {
    let v = to_view(position);
    var c = to_clip(v);
    if is_perspective() {
        c.z = view.depth.x * v.z + view.depth.y * (1.0 + view.depth.z);
    } else {
        c.z = view.depth.x * (v.z - view.depth.z * abs(v.z) - view.depth.w) + view.depth.y;
    }
    return LineOut(c, color);
}

@fragment
fn fs_line(in: LineOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.color, 1.0);
}
