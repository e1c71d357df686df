//! The shaders' correctly rounded division (`div_rn` in shaders/common/geom.wgsl) against the
//! CPU's IEEE division, bit for bit. Vulkan lets a driver's `/` be 2.5 ulp off (NVIDIA's is;
//! lavapipe's is exact), and the voxeliser, field and collider ports decide near-ties with
//! their quotients, so a GPU whose division is not exact gives other fields than the CPU. Skips without a GPU adapter
//! (`IMPRINT_REQUIRE_GPU=1` makes that a failure).

use imprint_gpu::test_context;

const DISPATCH: &str = include_str!("../../shaders/common/dispatch.wgsl");
const GEOM: &str = include_str!("../../shaders/common/geom.wgsl");

const KERNEL: &str = r#"
@group(0) @binding(0) var<storage, read> input: array<vec2<f32>>;
@group(0) @binding(1) var<storage, read_write> output: array<vec2<f32>>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = thread_index(gid, nwg);
    if i >= arrayLength(&input) {
        return;
    }
    let v = input[i];
    output[i] = vec2<f32>(div_rn(v.x, v.y), v.x / v.y);
}
"#;

/// Operand pairs: random significands over many binades, ratios near 1, significands of all
/// ones, zeros, infinities and a NaN.
fn operands() -> Vec<[f32; 2]> {
    let mut s = 0x2545_f491_4f6c_dd1du64;
    let mut next = move || {
        s ^= s << 13;
        s ^= s >> 7;
        s ^= s << 17;
        s
    };
    let mut v = Vec::new();
    for _ in 0..200_000 {
        let r = next();
        let a = f32::from_bits(((r as u32) & 0x807f_ffff) | ((100 + (r >> 32) as u32 % 56) << 23));
        let b = f32::from_bits(
            ((r >> 40) as u32 & 0x007f_ffff) | ((110 + (r >> 33) as u32 % 36) << 23),
        );
        v.push([a, b]);
        v.push([a, a * (1.0 + f32::EPSILON * ((r >> 60) as f32))]);
    }
    let ones = f32::from_bits(0x3fff_ffff);
    v.extend([
        [1.0, ones],
        [ones, ones],
        [3.0, ones],
        [0.0, 2.0],
        [-0.0, 2.0],
    ]);
    v.extend([
        [1.0, f32::INFINITY],
        [f32::INFINITY, 2.0],
        [1.0, 3.0],
        [2.0, 9.0],
        [f32::NAN, 1.0],
    ]);
    v
}

#[test]
fn division_is_correctly_rounded() {
    let Some(ctx) = test_context() else { return };
    let pairs = operands();
    let pipeline = ctx
        .pipeline("arith", &[DISPATCH, GEOM, KERNEL], "main")
        .unwrap();
    let input = ctx.storage_buffer("arith in", &pairs).unwrap();
    let output = ctx
        .zeroed_buffer("arith out", (pairs.len() * 8) as u64)
        .unwrap();
    let bind = ctx.bind_group("arith", &pipeline, &[(0, &input), (1, &output)]);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder.begin_compute_pass(&Default::default());
        pass.set_pipeline(&pipeline);
        pass.set_bind_group(0, &bind, &[]);
        ctx.dispatch_1d(&mut pass, pairs.len() as u32);
    }
    ctx.queue.submit([encoder.finish()]);
    let got: Vec<[f32; 2]> = ctx.read_buffer(&output).unwrap();
    let mut bad = Vec::new();
    let mut plain_off = 0;
    for (&[a, b], &[q, plain]) in pairs.iter().zip(&got) {
        let want = a / b;
        if q.to_bits() != want.to_bits() && !(q.is_nan() && want.is_nan()) {
            bad.push((a, b, q, want));
        }
        plain_off += usize::from(plain.to_bits() != want.to_bits() && !want.is_nan());
    }
    eprintln!(
        "{} quotients on {}: div_rn differs in {}, the shader's own `/` in {plain_off}",
        pairs.len(),
        ctx.adapter_name(),
        bad.len(),
    );
    assert!(bad.is_empty(), "a / b: {:?}", &bad[..bad.len().min(5)]);
}
