// Depth maps: imprint_gpu::raster::GpuRasterizer, the twin of
// imprint_core::raster::rasterize_depth_with. Prepended: render/camera.wgsl,
// common/geom.wgsl.
//
// The depth test keeps the nearest surface (camera.wgsl). The colour target (Rg32Float,
// cleared to 0) receives (view depth, 1); the 1 marks coverage (view depths of an
// orthographic camera may be zero or negative, so the depth cannot double as the marker).
//
// The view depth is not the hardware's interpolation: a GPU interpolates over its vertices
// snapped to its subpixel grid (NVIDIA's does, lavapipe's does not), which on a steep
// triangle moves the depth at a pixel centre by the slope times the snap, millimetres on a
// heightmap's walls. The CPU fits its depth plane through the unsnapped vertices in pixel
// coordinates (`Plane` in imprint_core::raster); so does each corner here, from the CPU's
// pixel coordinates computed as it computes them, and each fragment evaluates that plane at
// its pixel centre and writes the depth to the depth buffer too, so that the nearest-surface
// decision is the CPU's as well. Vertices are pulled from storage buffers (non-indexed draw,
// vertex k of triangle k / 3), so that every corner knows the whole triangle.

struct Image {
    // The image size in pixels, and its centre.
    size: vec2<f32>,
    centre: vec2<f32>,
    // Pixels per view unit (orthographic) or per unit of x / depth (perspective), as the
    // CPU's Projector::k.
    k: f32,
    // Always 0; see `rnd` in common/geom.wgsl.
    zero: u32,
    _pad: vec2<u32>,
}

@group(0) @binding(1) var<uniform> image: Image;
// Vertex positions, three floats each (Mesh::positions).
@group(0) @binding(2) var<storage, read> positions: array<f32>;
// Three vertex indices per triangle (Mesh::triangles).
@group(0) @binding(3) var<storage, read> triangles: array<u32>;

struct DepthOut {
    @builtin(position) clip: vec4<f32>,
    // The first corner: pixel x, y and the depth quantity (view depth, or its inverse for a
    // perspective camera); w: 1 where the plane below is valid.
    @location(0) @interpolate(flat) anchor: vec4<f32>,
    // The depth quantity's change per pixel along x and y.
    @location(1) @interpolate(flat) slope: vec2<f32>,
    // The hardware's interpolated view depth, where the plane is not valid: a perspective
    // triangle reaching behind the near plane (the CPU fits its plane after clipping there).
    // The plane is not clamped to the triangle's depths: at a pixel centre that snapping
    // covers just outside the triangle, the CPU extrapolates it too.
    @location(2) depth: f32,
}

// World point -> view coordinates, in the order and roundings of Frame::to_view.
fn view_exact(p: vec3<f32>) -> vec3<f32> {
    let q = p - view.eye.xyz;
    return vec3<f32>(dot3(q, view.right.xyz), dot3(q, view.up.xyz), dot3(q, view.forward.xyz));
}

// View coordinates -> (pixel x, pixel y, depth quantity), as Projector::screen_vertex.
fn screen(v: vec3<f32>) -> vec3<f32> {
    var s = image.k;
    var z = v.z;
    if is_perspective() {
        s = div_rn(image.k, v.z);
        z = div_rn(1.0, v.z);
    }
    return vec3<f32>(image.centre.x + rnd(v.x * s), image.centre.y - rnd(v.y * s), z);
}

fn corner(t: u32, k: u32) -> vec3<f32> {
    let i = 3u * triangles[3u * t + k];
    return view_exact(vec3<f32>(positions[i], positions[i + 1u], positions[i + 2u]));
}

@vertex
fn vs_depth(@builtin(vertex_index) vi: u32) -> DepthOut {
    geom_zero = image.zero;
    let t = vi / 3u;
    let va = corner(t, 0u);
    let vb = corner(t, 1u);
    let vc = corner(t, 2u);
    let lo = min(min(va.z, vb.z), vc.z);
    let a = screen(va);
    let b = screen(vb);
    let c = screen(vc);
    // The plane through the three corners (Plane::new, in f32 here).
    let e1 = b - a;
    let e2 = c - a;
    let det = rnd(e1.x * e2.y) - rnd(e2.x * e1.y);
    var slope = vec2<f32>(0.0);
    if det != 0.0 {
        slope = vec2<f32>(
            div_rn(rnd(e1.z * e2.y) - rnd(e2.z * e1.y), det),
            div_rn(rnd(e2.z * e1.x) - rnd(e1.z * e2.x), det),
        );
    }
    let valid = !is_perspective() || lo > 0.0;
    let v = corner(t, vi % 3u);
    return DepthOut(to_clip(v), vec4<f32>(a, select(0.0, 1.0, valid)), slope, v.z);
}

struct DepthFrag {
    @builtin(frag_depth) depth: f32,
    @location(0) map: vec2<f32>,
}

@fragment
fn fs_depth(in: DepthOut) -> DepthFrag {
    geom_zero = image.zero;
    var d = in.depth;
    if in.anchor.w != 0.0 {
        // `clip.xy` is the pixel centre (i + 0.5, j + 0.5).
        let z = in.anchor.z + rnd(in.slope.x * (in.clip.x - in.anchor.x)) + rnd(in.slope.y * (in.clip.y - in.anchor.y));
        d = select(z, div_rn(1.0, z), is_perspective());
        if !(abs(d) <= 3.40282347e38) {
            d = in.depth;
        }
    }
    let z_clip = view.depth.x * d + view.depth.y;
    let z = select(z_clip, z_clip / d, is_perspective());
    return DepthFrag(clamp(z, 0.0, 1.0), vec2<f32>(d, 1.0));
}
