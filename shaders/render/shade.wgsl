// Surfaces of the GPU frame renderer (imprint_render::gpu_frame), the twin of the shading in
// imprint_render::frame::render_cpu. Prepended: render/camera.wgsl.
//
// Meshes: Lambert on the interpolated vertex normal, flipped towards the camera (two-sided),
// `color * (ambient + sun * max(0, n . l))` clamped to 1, in linear space (the sRGB target
// encodes). Field slices: unlit, one texel per cell, looked up with the CPU's rounding.

struct Shading {
    // xyz: unit direction towards the sun; w: sun intensity.
    sun: vec4<f32>,
    // x: ambient intensity; yzw: unused.
    ambient: vec4<f32>,
}

@group(0) @binding(1) var<uniform> shading: Shading;

struct MeshOut {
    @builtin(position) clip: vec4<f32>,
    // Centroid: with MSAA, a pixel whose centre is off the triangle is shaded at a point on
    // it, not extrapolated.
    @location(0) @interpolate(perspective, centroid) world: vec3<f32>,
    @location(1) @interpolate(perspective, centroid) normal: vec3<f32>,
    @location(2) @interpolate(flat) color: vec3<f32>,
}

@vertex
fn vs_mesh(
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) color: vec3<f32>,
) -> MeshOut {
    return MeshOut(to_clip(to_view(position)), position, normal, color);
}

@fragment
fn fs_mesh(in: MeshOut) -> @location(0) vec4<f32> {
    // The face normal, for vertex normals that cancel out (the CPU's fallback); derivatives
    // must be taken in uniform control flow, so always.
    let face = cross(dpdx(in.world), dpdy(in.world));
    var n = vec3<f32>(0.0);
    if dot(in.normal, in.normal) > 0.0 {
        n = normalize(in.normal);
    } else if dot(face, face) > 0.0 {
        n = normalize(face);
    }
    let to_cam = select(-view.forward.xyz, view.eye.xyz - in.world, is_perspective());
    if dot(n, to_cam) < 0.0 {
        n = -n;
    }
    let k = shading.ambient.x + shading.sun.w * max(0.0, dot(n, shading.sun.xyz));
    return vec4<f32>(clamp(in.color * k, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}

// Linear colour per cell of the slice: texel (u, v) is the cell with those in-plane indices.
@group(1) @binding(0) var slice_colors: texture_2d<f32>;

struct SliceOut {
    @builtin(position) clip: vec4<f32>,
    // The point's in-plane grid coordinates (cell centres at integers).
    @location(0) cell: vec2<f32>,
}

@vertex
fn vs_slice(@location(0) position: vec3<f32>, @location(1) cell: vec2<f32>) -> SliceOut {
    return SliceOut(to_clip(to_view(position)), cell);
}

@fragment
fn fs_slice(in: SliceOut) -> @location(0) vec4<f32> {
    let dims = vec2<i32>(textureDimensions(slice_colors));
    // The CPU's `to_cell(p).round()`, clamped to the grid (floor(x + 0.5) = round(x) for
    // x >= -0.5, and below that both clamp to 0).
    let t = clamp(vec2<i32>(floor(in.cell + 0.5)), vec2<i32>(0), dims - 1);
    return vec4<f32>(textureLoad(slice_colors, t, 0).rgb, 1.0);
}
