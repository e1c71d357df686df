// The camera as the raster shaders see it, the GPU twin of the CPU rasteriser's projection
// (imprint_core::raster); mirrored by `GpuView` in crates/imprint-gpu/src/raster.rs.
// Prepended to render/depth.wgsl, render/shade.wgsl and render/line.wgsl.
//
// A world point goes to view coordinates as `Frame::to_view` does (subtract the eye, then dot
// with the camera axes: x right, y up, z = view depth d along forward), then to clip space:
//     x_clip = x * sx,  y_clip = y * sy,  z_clip = a * d + b,  w_clip = d (perspective) or 1.
// Perspective cameras use reversed depth (near -> 1, far -> 0, the nearer surface has the
// GREATER depth): with a Depth32Float buffer that keeps about 24 bits of relative precision at
// every distance, where the conventional mapping spends them near the 1e-3 near plane.
// Orthographic cameras keep the conventional mapping (near -> 0, far -> 1, nearer = less),
// linear in d, which is the precise one there.

struct View {
    // xyz: the eye; w: 1 for a perspective camera, 0 for an orthographic one.
    eye: vec4<f32>,
    // xyz: camera right; w: sx.
    right: vec4<f32>,
    // xyz: camera up; w: sy.
    up: vec4<f32>,
    // xyz: unit viewing direction; w: unused.
    forward: vec4<f32>,
    // x: a, y: b (z_clip = a * d + b); z: relative, w: absolute depth bias of lines.
    depth: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;

fn is_perspective() -> bool {
    return view.eye.w != 0.0;
}

// World point -> (x right, y up, view depth).
fn to_view(p: vec3<f32>) -> vec3<f32> {
    let q = p - view.eye.xyz;
    return vec3<f32>(dot(q, view.right.xyz), dot(q, view.up.xyz), dot(q, view.forward.xyz));
}

// View coordinates -> clip position.
fn to_clip(v: vec3<f32>) -> vec4<f32> {
    let w = select(1.0, v.z, is_perspective());
    return vec4<f32>(v.x * view.right.w, v.y * view.up.w, view.depth.x * v.z + view.depth.y, w);
}
