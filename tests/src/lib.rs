//! Shared helpers for imprint's cross-crate tests.

use imprint_core::Mesh;
use std::path::PathBuf;

/// A file under the workspace's `assets/`.
pub fn asset(rel: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../assets")).join(rel)
}

/// Loads one of the shipped test meshes.
pub fn mesh(name: &str) -> Mesh {
    Mesh::load_obj(&asset(&format!("meshes/{name}.obj"))).expect("shipped mesh loads")
}

/// Cloth test pieces shared by the CPU and GPU cloth tests.
pub mod cloth {
    use glam::{UVec3, Vec3};
    use imprint_core::{DistanceField, GridSpec};
    use imprint_stages::cloth::{ClothAssets, ClothParams, ClothSim, Material, Shape};

    /// An exact field of the sphere (c, r) on the box [lo, hi] with cells of `cell`.
    pub fn sphere_field(
        c: Vec3,
        r: f32,
        lo: Vec3,
        hi: Vec3,
        cell: f32,
        band: f32,
    ) -> DistanceField {
        let dims = ((hi - lo) / cell).ceil().as_uvec3() + UVec3::ONE;
        let spec = GridSpec::new(lo, cell, dims).unwrap();
        DistanceField::from_closest_points(spec, band, |p| {
            let d = p - c;
            let l = d.length();
            if l > 0.0 {
                c + r * d / l
            } else {
                c + Vec3::new(r, 0.0, 0.0)
            }
        })
    }

    /// The sphere of the drop tests: radius 0.3 at the origin, 2 cm cells, band 4.
    pub fn sphere_drop_field() -> DistanceField {
        sphere_field(
            Vec3::ZERO,
            0.3,
            Vec3::splat(-0.46),
            Vec3::splat(0.46),
            0.02,
            4.0,
        )
    }

    /// The sphere drop of the CPU cloth tests: a 24 x 24 cloth (1 m) 0.15 above
    /// [`sphere_drop_field`]'s sphere, 16 substeps, ε = 1 cm, friction 0.5.
    pub fn sphere_drop_params() -> ClothParams {
        let mut p = ClothParams::new(
            grid([1.0, 1.0], [24, 24], Vec3::new(0.0, 0.45, 0.0), Vec3::Y),
            harada(60.0, 15.0),
        );
        p.substeps = 16;
        p.damping = 0.995;
        p.collision.epsilon = 0.01;
        p.collision.friction = 0.5;
        p
    }

    /// A flat grid cloth.
    pub fn grid(size: [f32; 2], resolution: [u32; 2], center: Vec3, normal: Vec3) -> Shape {
        Shape::Grid {
            size,
            resolution,
            center,
            normal,
        }
    }

    /// Harada's linear springs, no bending.
    pub fn harada(k: f32, shear: f32) -> Material {
        Material::Harada {
            k_structural: k,
            k_shear: shear,
            k_bend: None,
        }
    }

    /// A simulator from in-memory params (no files).
    pub fn sim(params: &ClothParams) -> ClothSim {
        ClothSim::from_assets(params, &ClothAssets::default()).unwrap()
    }

    /// A cloth falling into the 6 cm gap between two spheres (radius [`gap::R`]) that move
    /// sideways at 0.6 m/s, 1 cm per frame at 60 fps: well within the band (4 cm, 5 mm
    /// cells). A particle in the gap is nearer one sphere in one frame's field and the other
    /// in the next, and within a cell of the gap's middle the cells' vectors point to
    /// different spheres. Each frame's grid moves with the spheres.
    pub mod gap {
        use super::*;

        pub const R: f32 = 0.12;
        pub const FPS: f32 = 60.0;

        /// The spheres' centres at frame `f`.
        pub fn centres(f: u32) -> (Vec3, Vec3) {
            let s = Vec3::new(0.6 * f as f32 / FPS, 0.0, 0.0);
            (
                Vec3::new(-0.15, 0.0, 0.0) + s,
                Vec3::new(0.15, 0.0, 0.0) + s,
            )
        }

        /// The spheres' field at frame `f` (an open body's: unsigned).
        pub fn field(f: u32) -> DistanceField {
            let (a, b) = centres(f);
            // The gap's middle on a face between cells: the blend there is at its shortest.
            let lo = Vec3::new(-0.3225, -0.17, -0.1711) + (a + b) / 2.0;
            let (cell, dims) = (0.005, UVec3::new(129, 69, 69));
            let spec = GridSpec::new(lo, cell, dims).unwrap();
            let on = |c: Vec3, p: Vec3| c + R * (p - c).try_normalize().unwrap_or(Vec3::Y);
            DistanceField::from_closest_points(spec, 8.0, |p| {
                let (pa, pb) = (on(a, p), on(b, p));
                if (pa - p).length() <= (pb - p).length() {
                    pa
                } else {
                    pb
                }
            })
        }

        /// The cloth: 31 x 21 particles, 40 substeps, ε = 8 mm.
        pub fn params() -> ClothParams {
            let mut p = ClothParams::new(
                grid([0.6, 0.4], [31, 21], Vec3::new(0.0, 0.14, 0.0), Vec3::Y),
                harada(60.0, 15.0),
            );
            p.mass = 0.001;
            p.substeps = 40;
            p.collision.epsilon = 0.008;
            p.collision.friction = 0.3;
            p
        }

        /// How far the particle deepest in a sphere at frame `f` is inside it (negative:
        /// all outside).
        pub fn depth(f: u32, positions: &[Vec3]) -> f32 {
            let (a, b) = centres(f);
            let inside = |x: &Vec3| R - (*x - a).length().min((*x - b).length());
            positions.iter().map(inside).fold(f32::MIN, f32::max)
        }

        /// Particles hanging in the gap at frame `f`, below the spheres' tops.
        pub fn in_gap(f: u32, positions: &[Vec3]) -> usize {
            let (a, b) = centres(f);
            let middle = (a.x + b.x) / 2.0;
            (positions.iter())
                .filter(|x| (x.x - middle).abs() < 0.02 && x.y < 0.08)
                .count()
        }
    }
}

/// Ground test pieces: fields, objects placed on them, and a sphere rolling across.
pub mod ground {
    use glam::{Mat4, Vec3};
    use imprint_core::Mesh;
    use imprint_core::mesh::primitives::{cuboid, uv_sphere};
    use imprint_stages::ground::{GroundFrameMetrics, GroundParams, GroundSim, Initial, Material};
    use std::time::Instant;

    /// The largest difference between 4-neighbours neither in contact this frame, units.
    pub fn worst_free_difference(g: &GroundSim) -> i64 {
        let dims = g.grid().dims;
        let nx = dims.x as usize;
        let mut held = vec![false; g.heights_units().len()];
        if let Some(maps) = g.maps() {
            let (win, w) = (maps.window, maps.window.w as usize);
            for (j, _) in maps.contact.iter().enumerate().filter(|c| *c.1) {
                held[win.global((j % w) as u32, (j / w) as u32, dims.x)] = true;
            }
        }
        let h = g.heights_units();
        let mut d = 0i64;
        for j in 0..h.len() {
            if held[j] {
                continue;
            }
            let mut pair = |n: usize| {
                if !held[n] {
                    d = d.max((h[j] as i64 - h[n] as i64).abs());
                }
            };
            if j % nx + 1 < nx {
                pair(j + 1);
            }
            if j + nx < h.len() {
                pair(j + nx);
            }
        }
        d
    }

    /// A flat field of `n × n` cells of `cell` m centred on the origin, `h0` m high.
    pub fn params(n: u32, cell: f32, h0: f32, material: Material) -> GroundParams {
        let mut p = GroundParams::new([n as f32 * cell; 2], [n, n], material);
        p.initial = Initial::Flat(h0);
        p
    }

    /// A simulator from in-memory params (no files).
    pub fn sim(p: &GroundParams) -> GroundSim {
        GroundSim::new(p, std::path::Path::new(".")).unwrap()
    }

    /// A fine sphere of radius `r` centred at `c`.
    pub fn sphere(r: f32, c: Vec3) -> Mesh {
        let mut m = uv_sphere(r, 128, 64);
        m.transform(Mat4::from_translation(c));
        m
    }

    /// An axis-aligned box with half-extents `half` centred at `c`.
    pub fn cuboid_at(half: Vec3, c: Vec3) -> Mesh {
        let mut m = cuboid(half, 1);
        m.transform(Mat4::from_translation(c));
        m
    }

    /// A sphere of radius `r` sunk `depth` into ground at `h0`, rolled along x from `x0` in
    /// steps of `dx` for `frames` frames: the metrics of each frame.
    pub fn roll(
        g: &mut GroundSim,
        r: f32,
        depth: f32,
        h0: f32,
        x0: f32,
        dx: f32,
        frames: u32,
    ) -> Vec<GroundFrameMetrics> {
        (0..frames)
            .map(|f| {
                let c = Vec3::new(x0 + f as f32 * dx, h0 + r - depth, 0.0);
                g.step(&[&sphere(r, c)]).unwrap()
            })
            .collect()
    }

    /// Milliseconds per contact frame (wall time of `step`) of a sphere, radius 1/10 of the
    /// field's x size and sunk 1/40 of it, crossing the flat field `p` in `frames` frames.
    /// The sphere's mesh is placed outside the timed region.
    pub fn time_rolling_sphere(p: &GroundParams, frames: u32) -> f64 {
        let mut g = sim(p);
        let size = p.size[0];
        let h0 = match p.initial {
            Initial::Flat(h) => h,
            Initial::Image { .. } => panic!("time_rolling_sphere wants a flat field"),
        };
        let (r, depth) = (0.1 * size, 0.025 * size);
        let base = uv_sphere(r, 64, 32);
        let mut total = 0.0;
        let mut contact_frames = 0;
        for f in 0..frames {
            let x = -0.3 * size + 0.6 * size * f as f32 / frames as f32;
            let mut m = base.clone();
            m.transform(Mat4::from_translation(Vec3::new(x, h0 + r - depth, 0.0)));
            let t = Instant::now();
            let metrics = g.step(&[&m]).unwrap();
            let dt = t.elapsed().as_secs_f64() * 1e3;
            if metrics.contact_cells > 0 {
                total += dt;
                contact_frames += 1;
            }
        }
        total / contact_frames.max(1) as f64
    }
}

/// Drape test bodies shared by the tests and the benchmarks.
pub mod drape {
    use glam::Vec3;
    use imprint_core::Mesh;
    use imprint_core::mesh::primitives::cuboid;

    /// A closed box from `min` to `max`.
    pub fn boxed(min: Vec3, max: Vec3) -> Mesh {
        let mut m = cuboid(0.5 * (max - min), 2);
        let c = 0.5 * (min + max);
        for p in &mut m.positions {
            *p += c;
        }
        m
    }

    /// A U in the y-z plane (extruded along x, the axis no default view looks along): a bar
    /// along z at the bottom, a thick arm and a thin arm, a narrow gap between them. A vertex
    /// in the thick arm next to the gap is nearest (of the views' surfaces) to the thin arm's
    /// outer face: the shortest view push jumps through the gap and the thin arm. No view
    /// resolves it; the distance field pushes it out through the inner face into the gap.
    pub fn u_body() -> Mesh {
        let mut body = boxed(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.3, 0.8));
        body.append(&boxed(Vec3::new(-0.5, 0.3, 0.0), Vec3::new(0.5, 1.0, 0.6)));
        body.append(&boxed(Vec3::new(-0.5, 0.3, 0.7), Vec3::new(0.5, 1.0, 0.8)));
        body
    }

    /// An `n`³ lattice of points at the cell centres of `bounds` split `n` ways per axis (a
    /// garment that fills a body's box).
    pub fn lattice(bounds: &imprint_core::Aabb, n: usize) -> Vec<Vec3> {
        (0..n * n * n)
            .map(|i| {
                let t = Vec3::new(
                    (i % n) as f32 + 0.5,
                    ((i / n) % n) as f32 + 0.5,
                    (i / (n * n)) as f32 + 0.5,
                ) / n as f32;
                bounds.min + t * (bounds.max - bounds.min)
            })
            .collect()
    }

    /// The view sets the drape is measured with: the six axis directions, and those with the
    /// eight cube diagonals (T's own three are `DrapeParams::default().views`).
    pub fn axes_and_diagonals() -> (Vec<Vec3>, Vec<Vec3>) {
        let axes = vec![
            Vec3::X,
            Vec3::NEG_X,
            Vec3::Y,
            Vec3::NEG_Y,
            Vec3::Z,
            Vec3::NEG_Z,
        ];
        let mut fourteen = axes.clone();
        for i in 0..8 {
            let s = |b: u32| if i & b == 0 { 1.0 } else { -1.0 };
            fourteen.push(Vec3::new(s(1), s(2), s(4)).normalize());
        }
        (axes, fourteen)
    }
}

pub mod skin;
pub mod stress;
