//! Checkpoints of GPU stages through their CPU types, as the executor takes them: a GPU
//! cloth mirrored into its `ClothSim` after every frame (`adopt_gpu_frame_resident`), and a
//! GPU particle skin read back into its `ParticleSkin` (`GpuParticleSkin::read_into`); the
//! CPU type goes through postcard, the GPU object is made again from what was loaded, and it
//! must step on to the same bits as the GPU object that never stopped. Skips without a GPU
//! adapter (`IMPRINT_REQUIRE_GPU=1` makes that a failure). Small scenes: CI runs these on a
//! software rasteriser (Mesa lavapipe).

use glam::{Affine3A, Vec3};
use imprint_gpu::{GpuContext, test_context};
use imprint_stages::cloth::gpu::{GpuCloth, GpuCollider};
use imprint_stages::cloth::{ClothParams, ClothSim, Pin};
use imprint_stages::skin::fill::FillParams;
use imprint_stages::skin::gpu_particles::GpuParticleSkin;
use imprint_stages::skin::particles::{ParticleParams, ParticleSkin, VertexRotation};
use imprint_tests::cloth::{grid, harada, sim, sphere_drop_field};
use imprint_tests::skin::{bend, two_bone_limb};

fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter().map(|p| p.to_array().map(f32::to_bits)).collect()
}

/// Asserts `got` equals `want` to the bit; on failure says how many differ and by how much.
fn assert_bits(got: &[Vec3], want: &[Vec3], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    let (a, b) = (bits(got), bits(want));
    if a != b {
        let n = a.iter().zip(&b).filter(|(p, q)| p != q).count();
        let d = max_dist(got, want);
        panic!("{what}: {n} of {} differ, by up to {d:.3e}", got.len());
    }
}

fn max_dist(a: &[Vec3], b: &[Vec3]) -> f32 {
    a.iter()
        .zip(b)
        .map(|(p, q)| p.distance(*q))
        .fold(0.0, f32::max)
}

/// Frame lengths alternate, so that the first substep after the checkpoint rescales the
/// Verlet velocity by dt / the last substep's dt (the sim's `dt_prev`).
fn cloth_dt(frame: u32) -> f32 {
    if frame.is_multiple_of(2) {
        1.0 / 60.0
    } else {
        1.0 / 50.0
    }
}

/// A 16 x 16 cloth hung from the two corners of one edge, 0.15 above a sphere of radius 0.3
/// (`sphere_drop_field`): it swings down onto the sphere. ε is small against a substep's
/// motion at impact, so particles cross the surface within a substep and only the contacts'
/// side memory tells that they are inside.
fn cloth_params() -> ClothParams {
    let mut p = ClothParams::new(
        grid([1.0, 1.0], [16, 16], Vec3::new(0.0, 0.45, 0.0), Vec3::Y),
        harada(60.0, 15.0),
    );
    p.substeps = 16;
    p.damping = 0.995;
    p.collision.epsilon = 0.0005;
    p.collision.friction = 0.5;
    p.pins = vec![Pin::Indices(vec![0, 15])];
    p
}

/// The pins' targets for `frame`: their rest positions, sliding along x.
fn pin_targets(sim: &ClothSim, rest: &[Vec3], frame: u32) -> Vec<Vec3> {
    sim.pinned()
        .iter()
        .map(|&i| rest[i as usize] + Vec3::new(0.002 * (frame + 1) as f32, 0.0, 0.0))
        .collect()
}

/// One executor-style GPU frame: the pins' targets set on the GPU cloth and on its mirror,
/// the frame stepped, the mirror taking in the GPU's state.
fn cloth_frame(
    ctx: &GpuContext,
    g: &mut GpuCloth,
    mirror: Option<&mut ClothSim>,
    collider: &GpuCollider,
    frame: u32,
) -> imprint_stages::cloth::gpu::GpuClothFrameMetrics {
    let m = g
        .step_frame(ctx, &[collider], &[collider], frame, cloth_dt(frame))
        .unwrap();
    if let Some(sim) = mirror {
        sim.adopt_gpu_frame_resident(g.read_state(ctx).unwrap(), g.read_side(ctx).unwrap(), &m)
            .unwrap();
    }
    m
}

/// A GPU cloth (sphere collider, moving pins, changing dt) mirrored into its `ClothSim`
/// every frame; after K frames (and the next frame's pin targets set) the sim goes through
/// postcard and `GpuCloth::new` of the loaded sim steps on: M frames bit for bit the same
/// positions as the GPU cloth that never stopped. The frame after the checkpoint has
/// particles found inside the sphere (through the side memory) and a dt unlike the last.
#[test]
fn gpu_cloth_restored_from_its_mirror_steps_on_bit_for_bit() {
    let Some(ctx) = test_context() else { return };
    const K: u32 = 12;
    const M: u32 = 8;
    let p = cloth_params();
    let field = sphere_drop_field();
    let collider = GpuCollider::from_field(ctx, &field).unwrap();
    let mut mirror = sim(&p).with_name("draped");
    let rest = mirror.positions();
    let mut g = GpuCloth::new(ctx, &mirror).unwrap();
    let mut inside_before = 0;
    for f in 0..K {
        let t = pin_targets(&mirror, &rest, f);
        g.set_pin_targets(&t).unwrap();
        mirror.set_pin_targets(&t).unwrap();
        let m = cloth_frame(ctx, &mut g, Some(&mut mirror), &collider, f);
        eprintln!(
            "frame {f}: contacts {}, inside {}, kinetic {:.4e}",
            m.contacts, m.inside, m.kinetic
        );
        inside_before += m.inside;
        assert_eq!(
            mirror.last_substep_kinetic().to_bits(),
            m.kinetic.to_bits(),
            "the mirror keeps the GPU's kinetic energy"
        );
    }
    assert!(
        inside_before > 0,
        "no particle crossed before the checkpoint"
    );
    // The checkpoint, taken with the next frame's pin targets set.
    let t = pin_targets(&mirror, &rest, K);
    g.set_pin_targets(&t).unwrap();
    mirror.set_pin_targets(&t).unwrap();
    let bytes = postcard::to_allocvec(&mirror).unwrap();
    let loaded: ClothSim = postcard::from_bytes(&bytes).unwrap();
    assert_eq!(loaded.name(), "draped");
    assert_bits(
        &loaded.positions(),
        &g.read_positions(ctx).unwrap(),
        "the checkpoint's positions",
    );
    let mut restored = GpuCloth::new(ctx, &loaded).unwrap();
    let side_bits = |g: &GpuCloth| -> Vec<[u32; 4]> {
        let side = g.read_side(ctx).unwrap();
        side.iter()
            .map(|v| v.to_array().map(f32::to_bits))
            .collect()
    };
    let same_side = side_bits(&restored) == side_bits(&g);
    for f in K..K + M {
        if f > K {
            let t = pin_targets(&mirror, &rest, f);
            g.set_pin_targets(&t).unwrap();
            restored.set_pin_targets(&t).unwrap();
        }
        let a = cloth_frame(ctx, &mut g, None, &collider, f);
        let b = cloth_frame(ctx, &mut restored, None, &collider, f);
        let (xa, xb) = (
            g.read_positions(ctx).unwrap(),
            restored.read_positions(ctx).unwrap(),
        );
        eprintln!(
            "frame {f}: contacts {}, inside {}, restored differs by {:.3e}",
            a.contacts,
            a.inside,
            max_dist(&xb, &xa)
        );
        if f == K {
            assert!(
                a.inside > 0,
                "no particle crossed in the frame after the checkpoint"
            );
        }
        assert_bits(&xb, &xa, &format!("frame {f}: restored vs uninterrupted"));
        assert_eq!(a, b, "frame {f}: metrics");
    }
    // Checked last, so that a restore without it shows what it changes first.
    assert!(
        same_side,
        "the restored cloth's side memory at the checkpoint"
    );
}

fn coarse(params: ParticleParams) -> ParticleParams {
    ParticleParams {
        fill: FillParams {
            radius: 0.025,
            levels: 2,
        },
        ..params
    }
}

/// A GPU particle skin stepped K frames into a bend, read back into its `ParticleSkin`
/// (`read_into`), through postcard, made again (`GpuParticleSkin::new`), then M frames: the
/// same particle positions and vertices to the bit as the GPU skin that never stopped, and
/// the same vertices already before the restored one's first frame (they need the bones'
/// rotations). T's set (distance springs, offsets turned by the bone), the defaults
/// (corotated springs, pressure, offsets turned by the particle's rotation), and distance
/// springs with pressure and particle rotations.
#[test]
fn gpu_particle_skin_restored_from_read_into_steps_on_bit_for_bit() {
    let Some(ctx) = test_context() else { return };
    const K: u32 = 4;
    const M: u32 = 6;
    const DT: f32 = 1.0 / 24.0;
    let (mesh, rig) = two_bone_limb(0.1, 1.0, 16, 10);
    let pose = |f: u32| -> Vec<Affine3A> { bend(&rig, 90.0 * (f.min(6) as f32 / 6.0)).skin };
    let cases = [
        ("T", coarse(ParticleParams::t_method())),
        ("defaults", coarse(ParticleParams::default())),
        (
            "distance + pressure, particle rotations",
            coarse(ParticleParams {
                volume_stiffness: 2000.0,
                vertex_rotation: VertexRotation::Particle,
                ..ParticleParams::t_method()
            }),
        ),
    ];
    for (name, params) in cases {
        let mut cpu = ParticleSkin::new(&mesh, &rig.rest_segments(), &params).unwrap();
        let mut g = GpuParticleSkin::new(ctx, &cpu).unwrap();
        for f in 0..K {
            g.step_frame(ctx, &pose(f), &pose(f + 1), f, DT).unwrap();
        }
        g.read_into(ctx, &mut cpu).unwrap();
        assert_bits(
            cpu.positions(),
            &g.read_positions(ctx).unwrap(),
            &format!("{name}: positions read back"),
        );
        let bytes = postcard::to_allocvec(&cpu).unwrap();
        let loaded: ParticleSkin = postcard::from_bytes(&bytes).unwrap();
        let mut restored = GpuParticleSkin::new(ctx, &loaded).unwrap();
        let (va, vb) = (g.vertices(ctx).unwrap(), restored.vertices(ctx).unwrap());
        eprintln!(
            "{name}: vertices before the restored skin's first frame differ by {:.2e}",
            max_dist(&vb, &va)
        );
        assert_bits(&vb, &va, &format!("{name}: vertices at the checkpoint"));
        for f in K..K + M {
            g.step_frame(ctx, &pose(f), &pose(f + 1), f, DT).unwrap();
            restored
                .step_frame(ctx, &pose(f), &pose(f + 1), f, DT)
                .unwrap();
            let (xa, xb) = (
                g.read_positions(ctx).unwrap(),
                restored.read_positions(ctx).unwrap(),
            );
            let (va, vb) = (g.vertices(ctx).unwrap(), restored.vertices(ctx).unwrap());
            eprintln!(
                "{name}, frame {f}: particles differ by {:.2e}, vertices by {:.2e}",
                max_dist(&xb, &xa),
                max_dist(&vb, &va)
            );
            assert_bits(&xb, &xa, &format!("{name}, frame {f}: particles"));
            assert_bits(&vb, &va, &format!("{name}, frame {f}: vertices"));
        }
    }
}
