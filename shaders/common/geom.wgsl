// Geometric kernels, ported operation for operation from imprint_core::geom so that the GPU
// makes the same decisions as the CPU reference: dot and cross products written out in glam's
// order, and every product rounded on its own (`rnd`) as the CPU rounds it.

// Must hold 0: each entry point that uses these helpers copies it from a uniform first.
var<private> geom_zero: u32;

// x, rounded on its own. Vulkan lets a driver fuse `a * b + c` into one fma (NVIDIA does),
// which rounds once where the CPU rounds twice and can decide a near-tie the other way; an
// xor with a value the compiler cannot know is 0 keeps the product a separate operation.
fn rnd(x: f32) -> f32 {
    return bitcast<f32>(bitcast<u32>(x) ^ geom_zero);
}

fn rnd3(v: vec3<f32>) -> vec3<f32> {
    return bitcast<vec3<f32>>(bitcast<vec3<u32>>(v) ^ vec3<u32>(geom_zero));
}

// a / b correctly rounded, as the CPU divides. Vulkan lets `/` be off by 2.5 ulp (NVIDIA's
// is), enough to move a closest point by an ulp and flip a near-tie the CPU decides the
// other way, and `fma` need not be fused (lavapipe's is not), so the quotient is formed in
// integers: 25 bits of the significands' long division, then round to nearest even on the
// remainder. Zero, subnormal, infinite or NaN operands and results take the plain `/`.
fn div_rn(a: f32, b: f32) -> f32 {
    let ba = bitcast<u32>(a);
    let bb = bitcast<u32>(b);
    let ea = (ba >> 23u) & 0xffu;
    let eb = (bb >> 23u) & 0xffu;
    if ea == 0u || eb == 0u || ea == 0xffu || eb == 0xffu {
        return a / b;
    }
    let mb = (bb & 0x7fffffu) | 0x800000u;
    var r = (ba & 0x7fffffu) | 0x800000u;
    var e = i32(ea) - i32(eb) + 127;
    if r < mb {
        r <<= 1u;
        e -= 1;
    }
    // mb <= r < 2 mb: the quotient is in [1, 2); 24 significand bits and a round bit.
    var q = 0u;
    for (var i = 0u; i < 25u; i++) {
        q <<= 1u;
        if r >= mb {
            r -= mb;
            q |= 1u;
        }
        r <<= 1u;
    }
    let round = q & 1u;
    q >>= 1u;
    if round == 1u && (r != 0u || (q & 1u) == 1u) {
        q += 1u;
    }
    if q == 0x1000000u {
        q >>= 1u;
        e += 1;
    }
    if e <= 0 || e >= 255 {
        return a / b;
    }
    return bitcast<f32>(((ba ^ bb) & 0x80000000u) | (u32(e) << 23u) | (q & 0x7fffffu));
}

fn dot3(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return rnd(a.x * b.x) + rnd(a.y * b.y) + rnd(a.z * b.z);
}

// glam's operand order (WGSL's cross() leaves it to the implementation).
fn cross3(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(
        rnd(a.y * b.z) - rnd(b.y * a.z),
        rnd(a.z * b.x) - rnd(b.z * a.x),
        rnd(a.x * b.y) - rnd(b.x * a.y),
    );
}

fn closest_on_segment(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let l2 = dot3(ab, ab);
    if l2 <= 0.0 {
        return a;
    }
    return a + rnd3(ab * clamp(div_rn(dot3(p - a, ab), l2), 0.0, 1.0));
}

// Collinear vertices not caught by the Voronoi regions: the closest of the three edges.
fn closest_on_degenerate(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    var best = closest_on_segment(p, a, b);
    let q1 = closest_on_segment(p, b, c);
    let q2 = closest_on_segment(p, c, a);
    let d_best = best - p;
    let d1 = q1 - p;
    var best_d2 = dot3(d_best, d_best);
    if dot3(d1, d1) < best_d2 {
        best = q1;
        best_d2 = dot3(d1, d1);
    }
    let d2 = q2 - p;
    if dot3(d2, d2) < best_d2 {
        best = q2;
    }
    return best;
}

// The point of triangle (a, b, c) closest to p (Ericson, Real-Time Collision Detection §5.1.5),
// with the degenerate-triangle fallback of the CPU version.
fn closest_point_on_triangle(p: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> vec3<f32> {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = dot3(ab, ap);
    let d2 = dot3(ac, ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = dot3(ab, bp);
    let d4 = dot3(ac, bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = rnd(d1 * d4) - rnd(d3 * d2);
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = div_rn(d1, d1 - d3);
        return a + rnd3(v * ab);
    }
    let cp = p - c;
    let d5 = dot3(ab, cp);
    let d6 = dot3(ac, cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = rnd(d5 * d2) - rnd(d1 * d6);
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = div_rn(d2, d2 - d6);
        return a + rnd3(w * ac);
    }
    let va = rnd(d3 * d6) - rnd(d5 * d4);
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = div_rn(d4 - d3, (d4 - d3) + (d5 - d6));
        return b + rnd3(w * (c - b));
    }
    let denom = va + vb + vc;
    // f32::MIN_POSITIVE; `!(x <= MAX)` also catches inf and NaN.
    if abs(denom) <= 1.17549435e-38 || !(abs(denom) <= 3.40282347e38) {
        return closest_on_degenerate(p, a, b, c);
    }
    let inv = div_rn(1.0, denom);
    let v = vb * inv;
    let w = vc * inv;
    return a + rnd3(ab * v) + rnd3(ac * w);
}

// Does triangle (a, b, c) touch the closed box center ± half? Akenine-Möller's separating-axis
// test: the 3 box axes, the 9 edge cross products, the triangle plane.
fn sat_axis(axis: vec3<f32>, v0: vec3<f32>, v1: vec3<f32>, v2: vec3<f32>, half: vec3<f32>) -> bool {
    let p0 = dot3(axis, v0);
    let p1 = dot3(axis, v1);
    let p2 = dot3(axis, v2);
    let r = rnd(half.x * abs(axis.x)) + rnd(half.y * abs(axis.y)) + rnd(half.z * abs(axis.z));
    let lo = min(min(p0, p1), p2);
    let hi = max(max(p0, p1), p2);
    return !(lo > r || hi < -r);
}

fn sat_edge(e: vec3<f32>, v0: vec3<f32>, v1: vec3<f32>, v2: vec3<f32>, half: vec3<f32>) -> bool {
    return sat_axis(vec3<f32>(0.0, -e.z, e.y), v0, v1, v2, half)
        && sat_axis(vec3<f32>(e.z, 0.0, -e.x), v0, v1, v2, half)
        && sat_axis(vec3<f32>(-e.y, e.x, 0.0), v0, v1, v2, half);
}

fn triangle_box_overlap(center: vec3<f32>, half: vec3<f32>, a: vec3<f32>, b: vec3<f32>, c: vec3<f32>) -> bool {
    let v0 = a - center;
    let v1 = b - center;
    let v2 = c - center;
    let mn = min(min(v0, v1), v2);
    let mx = max(max(v0, v1), v2);
    if any(mn > half) || any(mx < -half) {
        return false;
    }
    let e0 = v1 - v0;
    let e1 = v2 - v1;
    let e2 = v0 - v2;
    if !(sat_edge(e0, v0, v1, v2, half) && sat_edge(e1, v0, v1, v2, half) && sat_edge(e2, v0, v1, v2, half)) {
        return false;
    }
    let n = cross3(e0, e1);
    let r = rnd(half.x * abs(n.x)) + rnd(half.y * abs(n.y)) + rnd(half.z * abs(n.z));
    let s = dot3(n, v0);
    return abs(s) <= r;
}
