//! Springs, hinges and faces, stored per particle so that each particle *gathers* its own
//! forces (no scatter, no atomics: the GPU path runs one invocation per particle over the
//! same arrays).
//!
//! Every spring appears twice, once in each end's list, with the same constants, so the two
//! ends compute equal and opposite forces. A particle's links are packed four to a
//! [`LinkQuad`] (padded with inert links to itself), so the CPU evaluates four springs per
//! SIMD operation and the GPU reads one 64-byte struct per four springs.

use super::params::{Material, StiffnessMode};
use super::shape::ClothShape;
use super::texture::AnisotropyMap;
use bytemuck::{Pod, Zeroable};
use glam::{Vec2, Vec3, Vec4};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// What a spring is for (H §4.1): its constant comes from this.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SpringKind {
    /// To the 4 grid neighbours; every unique edge of a mesh.
    Structural,
    /// To the 4 grid diagonals; across each pair of mesh triangles.
    Shear,
    /// Skip-one grid springs (Harada's optional bending).
    Bend,
}

/// A spring's direction in the weave, for T eq. 5.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum WeaveDir {
    /// Along u (texture x): Ka, the R channel.
    Warp,
    /// Along v (texture y): Kb, G.
    Weft,
    /// Along +u+v: Kc, B.
    DiagPlus,
    /// Along +u-v: Kd, A.
    DiagMinus,
}

impl WeaveDir {
    /// The nearest of the four directions to `d` (UV space): warp or weft within 22.5°.
    pub fn classify(d: Vec2) -> Option<WeaveDir> {
        let (du, dv) = (d.x.abs(), d.y.abs());
        if du == 0.0 && dv == 0.0 {
            return None;
        }
        let tan = std::f32::consts::FRAC_PI_8.tan();
        Some(if dv <= tan * du {
            WeaveDir::Warp
        } else if du <= tan * dv {
            WeaveDir::Weft
        } else if d.x * d.y > 0.0 {
            WeaveDir::DiagPlus
        } else {
            WeaveDir::DiagMinus
        })
    }

    pub fn channel(self, k: Vec4) -> f32 {
        match self {
            WeaveDir::Warp => k.x,
            WeaveDir::Weft => k.y,
            WeaveDir::DiagPlus => k.z,
            WeaveDir::DiagMinus => k.w,
        }
    }
}

/// One spring between particles `a` and `b`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Spring {
    pub a: u32,
    pub b: u32,
    pub kind: SpringKind,
    /// Its weave direction (grids: from the lattice; meshes: from the UVs) when known.
    pub dir: Option<WeaveDir>,
    /// Midpoint in UV space, where the anisotropy texture is read.
    pub uv_mid: Option<Vec2>,
}

/// The springs of a shape, in a fixed order (so the links, and the bytes, are reproducible).
pub fn enumerate_springs(shape: &ClothShape, with_bend: bool) -> Vec<Spring> {
    match shape.grid {
        Some([nx, ny]) => grid_springs(nx, ny, with_bend),
        None => mesh_springs(shape),
    }
}

fn grid_springs(nx: u32, ny: u32, with_bend: bool) -> Vec<Spring> {
    let id = |i: u32, j: u32| i + nx * j;
    let uv = |i: f32, j: f32| Vec2::new(i / (nx - 1) as f32, j / (ny - 1) as f32);
    let mut out = Vec::new();
    let mut push = |a: (u32, u32), b: (u32, u32), kind, dir| {
        out.push(Spring {
            a: id(a.0, a.1),
            b: id(b.0, b.1),
            kind,
            dir: Some(dir),
            uv_mid: Some(uv((a.0 + b.0) as f32 * 0.5, (a.1 + b.1) as f32 * 0.5)),
        })
    };
    use SpringKind::*;
    use WeaveDir::*;
    for j in 0..ny {
        for i in 0..nx {
            if i + 1 < nx {
                push((i, j), (i + 1, j), Structural, Warp);
            }
            if j + 1 < ny {
                push((i, j), (i, j + 1), Structural, Weft);
            }
            if i + 1 < nx && j + 1 < ny {
                push((i, j), (i + 1, j + 1), Shear, DiagPlus);
                push((i + 1, j), (i, j + 1), Shear, DiagMinus);
            }
            if with_bend {
                if i + 2 < nx {
                    push((i, j), (i + 2, j), Bend, Warp);
                }
                if j + 2 < ny {
                    push((i, j), (i, j + 2), Bend, Weft);
                }
            }
        }
    }
    out
}

/// Unique edges (structural), then one shear spring across each edge shared by exactly two
/// triangles, between their opposite vertices (unless those are already an edge).
fn mesh_springs(shape: &ClothShape) -> Vec<Spring> {
    let key = |a: u32, b: u32| (a.min(b), a.max(b));
    let corner_uv = |t: usize, c: usize| shape.corner_uvs.as_ref().map(|uv| uv[t][c]);
    /// An edge's first triangle, the corners of its ends and the opposite corner there, and
    /// how many triangles share it.
    #[derive(Clone, Copy)]
    struct Edge {
        tri: usize,
        ca: usize,
        cb: usize,
        opposite: usize,
        count: u32,
    }
    let mut edges: HashMap<(u32, u32), Edge> = HashMap::new();
    let mut order = Vec::new();
    for (t, tri) in shape.triangles.iter().enumerate() {
        for c in 0..3 {
            let (a, b) = (tri[c], tri[(c + 1) % 3]);
            if a == b {
                continue;
            }
            let e = edges.entry(key(a, b)).or_insert_with(|| {
                order.push(key(a, b));
                Edge {
                    tri: t,
                    ca: c,
                    cb: (c + 1) % 3,
                    opposite: (c + 2) % 3,
                    count: 0,
                }
            });
            e.count += 1;
        }
    }
    let spring = |a: u32, b: u32, kind, uva: Option<Vec2>, uvb: Option<Vec2>| {
        let (dir, uv_mid) = match (uva, uvb) {
            (Some(p), Some(q)) => (WeaveDir::classify(q - p), Some(0.5 * (p + q))),
            _ => (None, None),
        };
        Spring {
            a,
            b,
            kind,
            dir,
            uv_mid,
        }
    };
    let mut out: Vec<Spring> = order
        .iter()
        .map(|&(a, b)| {
            let Edge { tri: t, ca, cb, .. } = edges[&(a, b)];
            let (ua, ub) = (corner_uv(t, ca), corner_uv(t, cb));
            // Keep the UVs in the same order as the particles.
            let (ua, ub) = if shape.triangles[t][ca] == a {
                (ua, ub)
            } else {
                (ub, ua)
            };
            spring(a, b, SpringKind::Structural, ua, ub)
        })
        .collect();
    // Second pass: the other triangle of each interior edge.
    let mut seen = std::collections::HashSet::new();
    for (t, tri) in shape.triangles.iter().enumerate() {
        for c in 0..3 {
            let (a, b) = (tri[c], tri[(c + 1) % 3]);
            if a == b {
                continue;
            }
            let Edge {
                tri: t0,
                opposite: opp0,
                count,
                ..
            } = edges[&key(a, b)];
            if count != 2 || t0 == t {
                continue;
            }
            let (p, q) = (shape.triangles[t0][opp0], tri[(c + 2) % 3]);
            if p == q || edges.contains_key(&key(p, q)) || !seen.insert(key(p, q)) {
                continue;
            }
            out.push(spring(
                p,
                q,
                SpringKind::Shear,
                corner_uv(t0, opp0),
                corner_uv(t, (c + 2) % 3),
            ));
        }
    }
    out
}

/// How force grows with extension e = r - l: `k e` (H eq. 9) or `k e |e|` (T eq. 1), with k
/// the stretch constant for e >= 0 and the compression constant for e < 0.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum SpringLaw {
    #[default]
    Linear,
    Quadratic,
}

impl SpringLaw {
    /// Potential energy of a spring at extension `e` with constant `k`.
    #[inline]
    pub fn energy(self, k: f32, e: f32) -> f32 {
        match self {
            SpringLaw::Linear => 0.5 * k * e * e,
            SpringLaw::Quadratic => k * e.abs() * e * e / 3.0,
        }
    }

    /// d(force)/d(length) at extension `e`: the spring's stiffness there.
    pub fn stiffness(self, k: f32, e: f32) -> f32 {
        match self {
            SpringLaw::Linear => k,
            SpringLaw::Quadratic => 2.0 * k * e.abs(),
        }
    }
}

/// Four springs of one particle: the other ends, rest lengths and constants. Inert padding
/// links point at the particle itself with rest length and constants 0.
#[repr(C, align(16))]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
pub struct LinkQuad {
    pub other: [u32; 4],
    pub rest: [f32; 4],
    pub k_stretch: [f32; 4],
    pub k_compress: [f32; 4],
}

/// Per-particle spring lists (CSR over [`LinkQuad`]s).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Links {
    pub law: SpringLaw,
    /// Particle i's quads are `quads[offsets[i]..offsets[i + 1]]`.
    pub offsets: Vec<u32>,
    pub quads: Vec<LinkQuad>,
    /// Number of springs (each listed twice).
    pub springs: usize,
}

/// The stretch and compression constants of each spring, and the law they follow.
pub fn spring_constants(
    springs: &[Spring],
    rest: &[Vec3],
    material: &Material,
    mode: StiffnessMode,
    anisotropy: Option<&AnisotropyMap>,
) -> (SpringLaw, Vec<[f32; 2]>) {
    let len = |s: &Spring| (rest[s.b as usize] - rest[s.a as usize]).length();
    match material {
        Material::Harada {
            k_structural,
            k_shear,
            k_bend,
        } => {
            let ks = springs
                .iter()
                .map(|s| {
                    let k = match s.kind {
                        SpringKind::Structural => *k_structural,
                        SpringKind::Shear => *k_shear,
                        SpringKind::Bend => k_bend.unwrap_or(0.0),
                    };
                    let k = match mode {
                        StiffnessMode::Force => k,
                        StiffnessMode::Strain => k / len(s).max(f32::MIN_POSITIVE),
                    };
                    [k, k]
                })
                .collect();
            (SpringLaw::Linear, ks)
        }
        Material::Tokoi {
            a_compress,
            b_stretch,
            ..
        } => {
            let ks = springs
                .iter()
                .map(|s| {
                    let m = match (anisotropy, s.dir, s.uv_mid) {
                        (Some(map), Some(dir), Some(uv)) => dir.channel(map.sample(uv)),
                        (Some(map), None, Some(uv)) => {
                            let k = map.sample(uv);
                            0.5 * (k.x + k.y)
                        }
                        _ => 1.0,
                    };
                    let scale = match mode {
                        StiffnessMode::Force => m,
                        StiffnessMode::Strain => m / len(s).powi(2).max(f32::MIN_POSITIVE),
                    };
                    [b_stretch * scale, a_compress * scale]
                })
                .collect();
            (SpringLaw::Quadratic, ks)
        }
    }
}

impl Links {
    /// Packs the springs into per-particle quads; rest lengths from `rest`.
    pub fn build(
        n: usize,
        springs: &[Spring],
        k: &[[f32; 2]],
        law: SpringLaw,
        rest: &[Vec3],
    ) -> Self {
        let mut per: Vec<Vec<(u32, f32, f32, f32)>> = vec![Vec::new(); n];
        for (s, &[ks, kc]) in springs.iter().zip(k) {
            let l = (rest[s.b as usize] - rest[s.a as usize]).length();
            per[s.a as usize].push((s.b, l, ks, kc));
            per[s.b as usize].push((s.a, l, ks, kc));
        }
        let mut offsets = Vec::with_capacity(n + 1);
        let mut quads = Vec::new();
        offsets.push(0);
        for (i, list) in per.iter().enumerate() {
            for chunk in list.chunks(4) {
                let mut q = LinkQuad {
                    other: [i as u32; 4],
                    ..Default::default()
                };
                for (lane, &(o, l, ks, kc)) in chunk.iter().enumerate() {
                    q.other[lane] = o;
                    q.rest[lane] = l;
                    q.k_stretch[lane] = ks;
                    q.k_compress[lane] = kc;
                }
                quads.push(q);
            }
            offsets.push(quads.len() as u32);
        }
        Links {
            law,
            offsets,
            quads,
            springs: springs.len(),
        }
    }

    /// The quads of particle `i`.
    #[inline]
    pub fn of(&self, i: usize) -> &[LinkQuad] {
        &self.quads[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

/// T eq. 2: bending across the edge (v0, v1) shared by triangles (v0, v1, v2) and
/// (v1, v0, v3); potential c (|φ| - sin|φ|) in φ = θ - θ_rest, whose force on a wing is
/// c (1 - cos φ) / (its distance to the hinge), Tokoi's c (cos θ - 1) / d.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable, Serialize, Deserialize)]
pub struct Hinge {
    pub v: [u32; 4],
    pub rest_angle: f32,
    pub c: f32,
    pub _pad: [f32; 2],
}

/// Per-particle hinge lists: entries are `hinge * 4 + role` (role = the particle's slot in
/// `Hinge::v`).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Hinges {
    pub hinges: Vec<Hinge>,
    pub offsets: Vec<u32>,
    pub refs: Vec<u32>,
}

impl Hinges {
    /// One hinge per edge shared by exactly two consistently wound triangles.
    pub fn build(n: usize, triangles: &[[u32; 3]], rest: &[Vec3], c: f32) -> Self {
        let mut by_edge: HashMap<(u32, u32), (usize, usize)> = HashMap::new();
        let mut order = Vec::new();
        let mut count: HashMap<(u32, u32), u32> = HashMap::new();
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_default() += 1;
                if let std::collections::hash_map::Entry::Vacant(e) = by_edge.entry((a, b)) {
                    e.insert((t, (k + 2) % 3));
                    order.push((a, b));
                }
            }
        }
        let mut hinges = Vec::new();
        for &(a, b) in &order {
            if a > b || count[&(a, b)] != 2 {
                continue;
            }
            // The opposite half-edge (b, a) belongs to the neighbouring triangle.
            let (Some(&(t0, o0)), Some(&(t1, o1))) = (by_edge.get(&(a, b)), by_edge.get(&(b, a)))
            else {
                continue;
            };
            let v = [a, b, triangles[t0][o0], triangles[t1][o1]];
            if v[2] == v[3] {
                continue;
            }
            let x = v.map(|i| rest[i as usize]);
            if let Some((theta, _)) = hinge_angle_gradient(x) {
                hinges.push(Hinge {
                    v,
                    rest_angle: theta,
                    c,
                    _pad: [0.0; 2],
                });
            }
        }
        let mut per: Vec<Vec<u32>> = vec![Vec::new(); n];
        for (h, hinge) in hinges.iter().enumerate() {
            for (role, &p) in hinge.v.iter().enumerate() {
                per[p as usize].push(4 * h as u32 + role as u32);
            }
        }
        let (offsets, refs) = csr(&per);
        Hinges {
            hinges,
            offsets,
            refs,
        }
    }

    pub fn is_empty(&self) -> bool {
        self.hinges.is_empty()
    }
}

/// The signed dihedral angle θ of a hinge, atan2((n1 x n2)·ê, n1·n2) with n1, n2 the two
/// triangles' normals and ê the hinge edge (0 when flat), and dθ/dx for its four vertices
/// (the bending modes of Bridson et al. 2003, checked against finite differences in the unit
/// tests); None when a triangle is degenerate.
#[inline]
pub fn hinge_angle_gradient(x: [Vec3; 4]) -> Option<(f32, [Vec3; 4])> {
    let e = x[1] - x[0];
    let n1 = e.cross(x[2] - x[0]);
    let n2 = (x[0] - x[1]).cross(x[3] - x[1]);
    let (l1, l2, le2) = (n1.length_squared(), n2.length_squared(), e.length_squared());
    if !(l1 > 1e-12 * le2 * le2 && l2 > 1e-12 * le2 * le2 && le2 > 0.0) {
        return None;
    }
    let le = le2.sqrt();
    let eh = e / le;
    let (m1, m2) = (n1 / l1, n2 / l2);
    let sin = n1.cross(n2).dot(eh) / (l1 * l2).sqrt();
    let cos = n1.dot(n2) / (l1 * l2).sqrt();
    let theta = sin.atan2(cos);
    // Bridson et al. 2003's bending modes u_i, which are -dθ/dx_i for this orientation.
    let g2 = -le * m1;
    let g3 = -le * m2;
    let g0 = -((x[2] - x[1]).dot(eh) * m1 + (x[3] - x[1]).dot(eh) * m2);
    let g1 = (x[2] - x[0]).dot(eh) * m1 + (x[3] - x[0]).dot(eh) * m2;
    Some((theta, [g0, g1, g2, g3]))
}

/// Hinge potential c (|φ| - sin|φ|) and its derivative c (1 - cos φ) sign(φ).
#[inline]
pub fn hinge_energy(c: f32, phi: f32) -> f32 {
    c * (phi.abs() - phi.abs().sin())
}

#[inline]
pub fn hinge_slope(c: f32, phi: f32) -> f32 {
    c * (1.0 - phi.cos()) * phi.signum()
}

/// Per-particle face lists for normals and wind: entries are the face's other two particles
/// in winding order, so (x_a - x_i) x (x_b - x_i) is twice the face's area vector.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Faces {
    pub offsets: Vec<u32>,
    pub others: Vec<[u32; 2]>,
}

impl Faces {
    pub fn build(n: usize, triangles: &[[u32; 3]]) -> Self {
        let mut per: Vec<Vec<[u32; 2]>> = vec![Vec::new(); n];
        for t in triangles {
            if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
                continue;
            }
            per[t[0] as usize].push([t[1], t[2]]);
            per[t[1] as usize].push([t[2], t[0]]);
            per[t[2] as usize].push([t[0], t[1]]);
        }
        let (offsets, others) = csr(&per);
        Faces { offsets, others }
    }

    /// A third of the adjacent faces' area vectors (area-weighted normal, length = the
    /// particle's share of the area).
    #[inline]
    pub fn area_normal(&self, i: usize, pos: &[Vec4]) -> Vec3 {
        self.area_normal_by(i, |j| pos[j].truncate())
    }

    /// [`Faces::area_normal`] with particle `j` at `at(j)`.
    #[inline]
    pub fn area_normal_by(&self, i: usize, at: impl Fn(usize) -> Vec3) -> Vec3 {
        let xi = at(i);
        let mut n = Vec3::ZERO;
        for &[a, b] in &self.others[self.offsets[i] as usize..self.offsets[i + 1] as usize] {
            n += (at(a as usize) - xi).cross(at(b as usize) - xi);
        }
        n * (1.0 / 6.0)
    }
}

fn csr<T: Copy>(per: &[Vec<T>]) -> (Vec<u32>, Vec<T>) {
    let mut offsets = Vec::with_capacity(per.len() + 1);
    let mut flat = Vec::new();
    offsets.push(0);
    for list in per {
        flat.extend_from_slice(list);
        offsets.push(flat.len() as u32);
    }
    (offsets, flat)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn theta(x: [Vec3; 4]) -> f64 {
        hinge_angle_gradient(x).unwrap().0 as f64
    }

    #[test]
    fn hinge_gradient_matches_finite_differences() {
        let x = [
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(1.0, 0.1, 0.0),
            Vec3::new(0.4, 0.8, 0.3),
            Vec3::new(0.6, -0.7, 0.5),
        ];
        let (_, g) = hinge_angle_gradient(x).unwrap();
        let h = 1e-3;
        for v in 0..4 {
            for a in 0..3 {
                let mut p = x;
                let mut m = x;
                p[v][a] += h;
                m[v][a] -= h;
                let fd = (theta(p) - theta(m)) / (2.0 * h as f64);
                assert!(
                    (fd - g[v][a] as f64).abs() < 2e-3,
                    "vertex {v} axis {a}: {fd} vs {}",
                    g[v][a]
                );
            }
        }
        // Translation invariance: the gradients sum to zero.
        let s: Vec3 = g.iter().sum();
        assert!(s.length() < 1e-5);
    }

    #[test]
    fn flat_hinge_has_zero_angle() {
        let x = [
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.5, 1.0, 0.0),
            Vec3::new(0.5, -1.0, 0.0),
        ];
        assert!(theta(x).abs() < 1e-7);
    }

    #[test]
    fn weave_directions() {
        assert_eq!(
            WeaveDir::classify(Vec2::new(1.0, 0.2)),
            Some(WeaveDir::Warp)
        );
        assert_eq!(
            WeaveDir::classify(Vec2::new(-0.1, 1.0)),
            Some(WeaveDir::Weft)
        );
        assert_eq!(
            WeaveDir::classify(Vec2::new(-1.0, -1.0)),
            Some(WeaveDir::DiagPlus)
        );
        assert_eq!(
            WeaveDir::classify(Vec2::new(1.0, -0.9)),
            Some(WeaveDir::DiagMinus)
        );
        assert_eq!(WeaveDir::classify(Vec2::ZERO), None);
    }

    #[test]
    fn grid_links_are_symmetric_and_padded() {
        let shape = ClothShape::grid([1.0, 1.0], [4, 3], Vec3::ZERO, Vec3::Y);
        let springs = enumerate_springs(&shape, true);
        // 3*3 + 4*2 structural, 2*3*2 shear, 2*3 + 4*1 bend
        assert_eq!(springs.len(), 17 + 12 + 10);
        let k = vec![[1.0, 1.0]; springs.len()];
        let links = Links::build(shape.len(), &springs, &k, SpringLaw::Linear, &shape.rest);
        let mut listed = 0;
        for i in 0..shape.len() {
            for q in links.of(i) {
                for lane in 0..4 {
                    if q.k_stretch[lane] == 0.0 {
                        assert_eq!(q.other[lane], i as u32);
                        continue;
                    }
                    listed += 1;
                    let j = q.other[lane] as usize;
                    let back = links
                        .of(j)
                        .iter()
                        .flat_map(|p| (0..4).map(move |l| (p.other[l], p.rest[l])))
                        .find(|&(o, _)| o == i as u32)
                        .unwrap();
                    assert_eq!(back.1, q.rest[lane]);
                }
            }
        }
        assert_eq!(listed, 2 * springs.len());
    }

    #[test]
    fn mesh_springs_add_the_missing_quad_diagonal() {
        // One quad as two triangles: 5 unique edges, and one shear spring across the diagonal.
        let shape = ClothShape::from_mesh(
            &imprint_core::Mesh::new(
                vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
                vec![[0, 1, 2], [0, 2, 3]],
                "quad",
            )
            .unwrap(),
        );
        let s = enumerate_springs(&shape, false);
        assert_eq!(
            s.iter()
                .filter(|s| s.kind == SpringKind::Structural)
                .count(),
            5
        );
        let shear: Vec<_> = s.iter().filter(|s| s.kind == SpringKind::Shear).collect();
        assert_eq!(shear.len(), 1);
        assert_eq!(
            (shear[0].a.min(shear[0].b), shear[0].a.max(shear[0].b)),
            (1, 3)
        );
        let h = Hinges::build(4, &shape.triangles, &shape.rest, 1.0);
        assert_eq!(h.hinges.len(), 1);
        assert_eq!(h.hinges[0].rest_angle, 0.0);
    }
}
