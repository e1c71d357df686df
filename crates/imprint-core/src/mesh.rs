//! Triangle meshes: OBJ loading (tobj; polygons fan-triangulated), validation with messages
//! that name the file and the problem, normals, fitting into a box, and procedural primitives.

use crate::{Aabb, Error, Result};
use glam::{Mat4, Vec2, Vec3};
use serde::{Deserialize, Serialize};
use std::f32::consts::{PI, TAU};
use std::path::Path;

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub triangles: Vec<[u32; 3]>,
    /// Per-vertex normals, same length as `positions` (computed when the file has none).
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates, when the source has them.
    pub uvs: Option<Vec<Vec2>>,
}

impl Mesh {
    /// Whether every edge borders an even number of triangles, edges compared by their ends'
    /// positions (so unwelded copies of a vertex count as one; even by vertex index implies
    /// even by position): the triangles then bound closed pieces, so "inside" means something
    /// and the parity of a ray's crossings changes only across the surface.
    pub fn is_closed(&self) -> bool {
        // Each vertex as the first index with its position, bit for bit: an edge of these ids
        // is an edge by position, and ids bucket where positions would have to be sorted.
        let canon = self.first_with_position();
        // The edges grouped by their smaller end (a counting sort), then each group's other
        // ends sorted: a vertex has a handful of edges, so this is linear where one sort of
        // all the edges took most of the test (the bunny's 208k edges).
        // Listed once (a `flat_map` over the triangles, walked twice by the counting sort, was
        // not inlined there: the other half of the test's time).
        let mut edges = Vec::with_capacity(3 * self.triangles.len());
        for t in &self.triangles {
            let [a, b, c] = t.map(|i| canon[i as usize]);
            edges.extend([(a, b), (b, c), (c, a)].map(|(p, q)| (p.min(q), p.max(q))));
        }
        let ends = || edges.iter().map(|&(a, b)| (a as usize, b));
        let mut by_end = crate::buckets::Buckets::build(self.positions.len(), ends);
        (0..self.positions.len()).all(|v| {
            let ends = by_end.of_mut(v);
            ends.sort_unstable();
            ends.chunk_by(|a, b| a == b).all(|run| run.len() % 2 == 0)
        })
    }

    /// Per vertex, the first index with its position bit for bit: the ids by which
    /// [`Mesh::is_closed`] and [`Mesh::welded`] compare vertices. Hashed in index order
    /// (sorting the vertices by their bits was half of `is_closed`'s time on the bunny).
    fn first_with_position(&self) -> Vec<u32> {
        let mut first = rustc_hash::FxHashMap::default();
        first.reserve(self.positions.len());
        (0..self.positions.len() as u32)
            .map(|i| {
                let key = self.positions[i as usize].to_array().map(f32::to_bits);
                *first.entry(key).or_insert(i)
            })
            .collect()
    }

    /// The signed volume enclosed (divergence theorem, in f64): positive when a closed mesh
    /// is wound outward; for an open one, the volume of the cone it spans from the origin.
    pub fn signed_volume(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangle(t).map(Vec3::as_dvec3);
                a.dot(b.cross(c)) / 6.0
            })
            .sum()
    }

    /// The mesh with vertices at the same position merged (exact bit patterns; the first
    /// index wins), normals recomputed and texture coordinates dropped: files split vertices
    /// along UV seams, which leaves an otherwise closed surface with "holes" by index that
    /// [`Mesh::close_holes`] cannot tell from real ones.
    pub fn welded(&self) -> Mesh {
        self.welded_with_map().0
    }

    /// [`Mesh::welded`] and, per vertex of the result, the vertex of `self` it was first
    /// (to carry per-vertex data such as skin weights across).
    pub fn welded_with_map(&self) -> (Mesh, Vec<u32>) {
        let canon = self.first_with_position();
        let mut positions = Vec::new();
        let mut origin = Vec::new();
        // New ids in order of first appearance; a vertex's first index is never after it.
        let mut id = vec![0u32; canon.len()];
        let remap: Vec<u32> = (0..canon.len())
            .map(|i| {
                if canon[i] as usize == i {
                    id[i] = positions.len() as u32;
                    origin.push(i as u32);
                    positions.push(self.positions[i]);
                }
                id[canon[i] as usize]
            })
            .collect();
        let mut m = Mesh {
            positions,
            triangles: self
                .triangles
                .iter()
                .map(|t| t.map(|v| remap[v as usize]))
                .collect(),
            normals: Vec::new(),
            uvs: None,
        };
        m.compute_normals();
        (m, origin)
    }

    /// Closes the mesh's holes: each loop of boundary edges (an edge of one triangle only, by
    /// vertex index) is filled with a fan around the loop's centroid, wound to match its
    /// neighbours, so that a scanned body with an open base (the Stanford bunny) has an inside
    /// and a signed field. Where boundaries meet at a vertex (two ways on), the walk takes
    /// the smallest unused way, which splits the boundary into closed loops all the same.
    /// Returns the number of holes filled. A mesh that is not welded (every triangle would
    /// be a hole: see [`Mesh::welded`]) is left open; [`Mesh::is_closed`] tells whether it
    /// worked.
    pub fn close_holes(&mut self) -> usize {
        let mut filled = 0;
        for lp in self.boundary_loops() {
            let c = lp.iter().map(|&i| self.positions[i as usize]).sum::<Vec3>() / lp.len() as f32;
            let ci = self.positions.len() as u32;
            self.positions.push(c);
            for k in 0..lp.len() {
                self.triangles.push([lp[k], lp[(k + 1) % lp.len()], ci]);
            }
            filled += 1;
        }
        if filled > 0 {
            self.uvs = None;
            self.compute_normals();
        }
        filled
    }

    /// The holes' boundaries as closed loops of vertex indices, each running against its
    /// triangles (so a fan over it is wound like them); loops of fewer than 3 vertices, and
    /// walks that cannot close, are left out.
    fn boundary_loops(&self) -> Vec<Vec<u32>> {
        use std::collections::{BTreeMap, BTreeSet};
        let directed: BTreeSet<(u32, u32)> = self
            .triangles
            .iter()
            .flat_map(|t| [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])])
            .collect();
        // A boundary edge a → b has no twin b → a; the hole runs the other way, b → a.
        let mut ways: BTreeMap<u32, BTreeSet<u32>> = BTreeMap::new();
        for &(a, b) in &directed {
            if !directed.contains(&(b, a)) {
                ways.entry(b).or_default().insert(a);
            }
        }
        let mut loops = Vec::new();
        while let Some((&start, _)) = ways.iter().find(|(_, w)| !w.is_empty()) {
            let mut lp = vec![start];
            let mut v = start;
            let closed = loop {
                let Some(n) = ways.get_mut(&v).and_then(|w| w.pop_first()) else {
                    break false;
                };
                if n == start {
                    break true;
                }
                lp.push(n);
                v = n;
            };
            if closed && lp.len() >= 3 {
                loops.push(lp);
            }
        }
        loops
    }

    /// Builds a mesh from positions and triangles, validating it and computing normals.
    /// `source` names the mesh in errors (a path or a primitive's name).
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>, source: &str) -> Result<Self> {
        let mut m = Mesh {
            positions,
            triangles,
            normals: Vec::new(),
            uvs: None,
        };
        m.validate(source)?;
        m.compute_normals();
        Ok(m)
    }

    /// Loads an OBJ file: every object and group merged, polygons triangulated, missing normals
    /// computed. Errors name the file and the problem (exit code 2 in the CLI).
    pub fn load_obj(path: &Path) -> Result<Self> {
        if !path.exists() {
            return Err(Error::mesh(path, "file not found"));
        }
        let file = std::fs::File::open(path).map_err(|e| {
            Error::mesh(
                path,
                format!(
                    "not a readable OBJ file ({}: {e})",
                    tobj::LoadError::OpenFileFailed
                ),
            )
        })?;
        let dir = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Self::read_obj(&mut std::io::BufReader::new(file), path, |mtl| {
            tobj::load_mtl(dir.join(mtl))
        })
    }

    /// Reads OBJ text held in memory, as [`Mesh::load_obj`] reads a file (`name` stands for
    /// the path in errors; `mtllib` lines are ignored: no file is opened). Any bytes give a
    /// mesh or an error, never a panic.
    pub fn from_obj_bytes(bytes: &[u8], name: &str) -> Result<Self> {
        Self::read_obj(&mut &bytes[..], Path::new(name), |_| {
            Ok((Vec::new(), Default::default()))
        })
    }

    /// The OBJ reader behind [`Mesh::load_obj`] and [`Mesh::from_obj_bytes`]; `materials`
    /// loads an `mtllib` (materials split objects into models, nothing more is used).
    fn read_obj(
        reader: &mut impl std::io::BufRead,
        path: &Path,
        materials: impl Fn(&Path) -> tobj::MTLLoadResult,
    ) -> Result<Self> {
        let opts = tobj::LoadOptions {
            triangulate: true,
            single_index: true,
            ..Default::default()
        };
        let (models, _materials) = tobj::load_obj_buf(reader, &opts, materials)
            .map_err(|e| Error::mesh(path, format!("not a readable OBJ file ({e})")))?;
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        let mut normals = Vec::new();
        let mut uvs = Vec::new();
        let mut all_have_normals = true;
        let mut all_have_uvs = true;
        for model in &models {
            let m = &model.mesh;
            let base = positions.len() as u32;
            let n = m.positions.len() / 3;
            positions.extend(
                m.positions
                    .chunks_exact(3)
                    .map(|p| Vec3::new(p[0], p[1], p[2])),
            );
            if m.normals.len() == m.positions.len() {
                normals.extend(
                    m.normals
                        .chunks_exact(3)
                        .map(|p| Vec3::new(p[0], p[1], p[2])),
                );
            } else {
                all_have_normals = false;
            }
            if m.texcoords.len() == 2 * n {
                uvs.extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], t[1])));
            } else {
                all_have_uvs = false;
            }
            for t in m.indices.chunks_exact(3) {
                triangles.push([base + t[0], base + t[1], base + t[2]]);
            }
        }
        let mut mesh = Mesh {
            positions,
            triangles,
            normals: Vec::new(),
            uvs: (all_have_uvs && !models.is_empty()).then_some(uvs),
        };
        mesh.validate(&path.display().to_string())
            .map_err(|e| match e {
                Error::Invalid(problem) => Error::mesh(path, problem),
                other => other,
            })?;
        if all_have_normals
            && normals.len() == mesh.positions.len()
            && normals.iter().all(|n| n.is_finite())
        {
            mesh.normals = normals.iter().map(|n| n.normalize_or_zero()).collect();
        } else {
            mesh.compute_normals();
        }
        Ok(mesh)
    }

    /// Checks what every stage relies on: at least one triangle, finite coordinates, indices
    /// in range. Degenerate, duplicated, flipped or unwelded triangles are fine.
    pub fn validate(&self, source: &str) -> Result<()> {
        let bad = |problem: String| Error::Invalid(format!("{source}: {problem}"));
        if self.triangles.is_empty() {
            return Err(bad(format!(
                "the mesh has no triangles ({} vertices); nothing to voxelise",
                self.positions.len()
            )));
        }
        if let Some((i, p)) = self
            .positions
            .iter()
            .enumerate()
            .find(|(_, p)| !p.is_finite())
        {
            return Err(bad(format!(
                "vertex {} has a non-finite coordinate ({}, {}, {})",
                i + 1,
                p.x,
                p.y,
                p.z
            )));
        }
        let n = self.positions.len() as u32;
        if let Some((f, t)) = self
            .triangles
            .iter()
            .enumerate()
            .find(|(_, t)| t.iter().any(|&i| i >= n))
        {
            return Err(bad(format!(
                "triangle {} uses vertex index {} but the mesh has {} vertices",
                f + 1,
                t.iter().max().unwrap() + 1,
                n
            )));
        }
        Ok(())
    }

    pub fn bounds(&self) -> Aabb {
        Aabb::from_points(self.positions.iter().copied())
    }

    #[inline]
    pub fn triangle(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.triangles[t];
        [
            self.positions[a as usize],
            self.positions[b as usize],
            self.positions[c as usize],
        ]
    }

    /// Area-weighted vertex normals (zero-area triangles contribute nothing).
    pub fn compute_normals(&mut self) {
        let mut normals = vec![Vec3::ZERO; self.positions.len()];
        for (t, tri) in self.triangles.iter().enumerate() {
            let [a, b, c] = self.triangle(t);
            let n = (b - a).cross(c - a);
            for &i in tri {
                normals[i as usize] += n;
            }
        }
        for n in &mut normals {
            *n = n.normalize_or_zero();
        }
        self.normals = normals;
    }

    pub fn surface_area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| {
                let [a, b, c] = self.triangle(t);
                0.5 * (b - a).cross(c - a).length() as f64
            })
            .sum()
    }

    /// Applies an affine transform to positions (and normals by the inverse transpose).
    pub fn transform(&mut self, m: Mat4) {
        for p in &mut self.positions {
            *p = m.transform_point3(*p);
        }
        let nm = m.inverse().transpose();
        for n in &mut self.normals {
            *n = nm.transform_vector3(*n).normalize_or_zero();
        }
    }

    /// The uniform scale and translation that puts this mesh's bounding box, centred on
    /// `center`, with its longest side equal to `size`.
    pub fn fit_transform(&self, size: f32, center: Vec3) -> Mat4 {
        let b = self.bounds();
        let longest = b.size().max_element();
        let s = if longest > 0.0 { size / longest } else { 1.0 };
        Mat4::from_translation(center)
            * Mat4::from_scale(Vec3::splat(s))
            * Mat4::from_translation(-b.center())
    }

    /// Appends another mesh (a union of surfaces; no welding).
    pub fn append(&mut self, other: &Mesh) {
        let base = self.positions.len() as u32;
        self.positions.extend_from_slice(&other.positions);
        self.normals.extend_from_slice(&other.normals);
        self.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + base, t[1] + base, t[2] + base]),
        );
        self.uvs = None;
    }
}

/// Procedural primitives, each centred on the origin, at a chosen tessellation.
pub mod primitives {
    use super::*;

    /// A latitude/longitude sphere: `2 * segments * (rings - 1)` triangles.
    pub fn uv_sphere(radius: f32, segments: u32, rings: u32) -> Mesh {
        let segments = segments.max(3);
        let rings = rings.max(2);
        let mut pos = vec![Vec3::new(0.0, radius, 0.0)];
        for r in 1..rings {
            let phi = PI * r as f32 / rings as f32;
            for s in 0..segments {
                let th = TAU * s as f32 / segments as f32;
                pos.push(radius * Vec3::new(phi.sin() * th.cos(), phi.cos(), phi.sin() * th.sin()));
            }
        }
        pos.push(Vec3::new(0.0, -radius, 0.0));
        let south = pos.len() as u32 - 1;
        let ring = |r: u32, s: u32| 1 + (r - 1) * segments + (s % segments);
        let mut tris = Vec::new();
        for s in 0..segments {
            tris.push([0, ring(1, s + 1), ring(1, s)]);
            tris.push([south, ring(rings - 1, s), ring(rings - 1, s + 1)]);
        }
        for r in 1..rings - 1 {
            for s in 0..segments {
                let (a, b, c, d) = (
                    ring(r, s),
                    ring(r, s + 1),
                    ring(r + 1, s),
                    ring(r + 1, s + 1),
                );
                tris.push([a, b, d]);
                tris.push([a, d, c]);
            }
        }
        Mesh::new(pos, tris, "sphere").expect("sphere is valid")
    }

    /// An axis-aligned box with half-extents `half`, each face split into `n x n` quads.
    pub fn cuboid(half: Vec3, n: u32) -> Mesh {
        let n = n.max(1);
        let mut mesh = Mesh::default();
        // (normal axis, u axis, v axis) for the six faces, wound outward.
        let faces = [
            (Vec3::X, Vec3::Y, Vec3::Z),
            (-Vec3::X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::Z, Vec3::X),
            (-Vec3::Y, Vec3::X, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y),
            (-Vec3::Z, Vec3::Y, Vec3::X),
        ];
        for (nrm, u, v) in faces {
            let face = grid_patch(n, n, |a, b| {
                (nrm + u * (2.0 * a - 1.0) + v * (2.0 * b - 1.0)) * half
            });
            mesh.append(&face);
        }
        mesh.compute_normals();
        mesh
    }

    /// A plane in x-z at y = 0, side `size`, `n x n` quads, facing +y.
    pub fn plane(size: f32, n: u32) -> Mesh {
        let n = n.max(1);
        let mut m = grid_patch(n, n, |a, b| {
            Vec3::new((a - 0.5) * size, 0.0, (0.5 - b) * size)
        });
        m.uvs = Some(
            (0..=n)
                .flat_map(|j| {
                    (0..=n).map(move |i| Vec2::new(i as f32 / n as f32, j as f32 / n as f32))
                })
                .collect(),
        );
        m
    }

    /// A torus around the y axis: major radius `major`, tube radius `minor`.
    pub fn torus(major: f32, minor: f32, segments: u32, sides: u32) -> Mesh {
        let segments = segments.max(3);
        let sides = sides.max(3);
        let mut pos = Vec::new();
        for s in 0..segments {
            let th = TAU * s as f32 / segments as f32;
            for k in 0..sides {
                let ph = TAU * k as f32 / sides as f32;
                let r = major + minor * ph.cos();
                pos.push(Vec3::new(r * th.cos(), minor * ph.sin(), r * th.sin()));
            }
        }
        let idx = |s: u32, k: u32| (s % segments) * sides + (k % sides);
        let mut tris = Vec::new();
        for s in 0..segments {
            for k in 0..sides {
                let (a, b, c, d) = (idx(s, k), idx(s + 1, k), idx(s, k + 1), idx(s + 1, k + 1));
                tris.push([a, c, d]);
                tris.push([a, d, b]);
            }
        }
        Mesh::new(pos, tris, "torus").expect("torus is valid")
    }

    /// A closed limb: a capped cylinder of `radius` along +x from x = 0 to x = `length` (not
    /// centred: a bone's head at the origin), `segments` around and `rings` quads along, so
    /// `rings + 1` vertex rings (an even `rings` puts one at the middle, where a joint bends).
    /// Welded and wound outward: `2 * segments * (rings + 1)` triangles.
    pub fn cylinder(radius: f32, length: f32, segments: u32, rings: u32) -> Mesh {
        let segments = segments.max(3);
        let rings = rings.max(1);
        let mut pos = Vec::new();
        for i in 0..=rings {
            let x = length * i as f32 / rings as f32;
            for k in 0..segments {
                let th = TAU * k as f32 / segments as f32;
                pos.push(Vec3::new(x, radius * th.cos(), radius * th.sin()));
            }
        }
        let start = pos.len() as u32;
        pos.push(Vec3::ZERO);
        pos.push(Vec3::new(length, 0.0, 0.0));
        let id = |i: u32, k: u32| i * segments + (k % segments);
        let mut tris = Vec::new();
        for i in 0..rings {
            for k in 0..segments {
                let (a, b, c, d) = (id(i, k), id(i, k + 1), id(i + 1, k), id(i + 1, k + 1));
                tris.push([a, b, d]);
                tris.push([a, d, c]);
            }
        }
        for k in 0..segments {
            tris.push([start, id(0, k + 1), id(0, k)]);
            tris.push([start + 1, id(rings, k), id(rings, k + 1)]);
        }
        Mesh::new(pos, tris, "cylinder").expect("cylinder is valid")
    }

    /// A patch of `nu x nv` quads (two triangles each) over (a, b) in [0,1]^2 mapped by `f`,
    /// wound so that the normal is (df/da x df/db).
    fn grid_patch(nu: u32, nv: u32, f: impl Fn(f32, f32) -> Vec3) -> Mesh {
        let mut pos = Vec::new();
        for j in 0..=nv {
            for i in 0..=nu {
                pos.push(f(i as f32 / nu as f32, j as f32 / nv as f32));
            }
        }
        let id = |i: u32, j: u32| j * (nu + 1) + i;
        let mut tris = Vec::new();
        for j in 0..nv {
            for i in 0..nu {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        Mesh::new(pos, tris, "patch").expect("patch is valid")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sphere with both polar caps cut off is open; closing its two holes gives a closed,
    /// outward mesh whose volume is the sphere's less what the flat lids cut.
    #[test]
    fn closing_holes_gives_a_closed_outward_mesh() {
        let s = primitives::uv_sphere(1.0, 32, 16);
        let pole = |i: u32| s.positions[i as usize].y.abs() > 0.99;
        let kept: Vec<[u32; 3]> = s
            .triangles
            .iter()
            .filter(|t| !t.iter().any(|&i| pole(i)))
            .copied()
            .collect();
        let mut cut = Mesh::new(s.positions.clone(), kept, "cut sphere").unwrap();
        assert!(!cut.is_closed());
        assert_eq!(cut.close_holes(), 2);
        assert!(cut.is_closed());
        let full = s.signed_volume();
        let v = cut.signed_volume();
        assert!(v > 0.97 * full && v < full, "{v} vs {full}");
        // Nothing left to close.
        assert_eq!(cut.close_holes(), 0);
    }

    /// A box split along a seam (each face with its own four corners, as files split
    /// vertices for texture coordinates) is open by index: welding makes it closed again,
    /// with 8 vertices, and the map names a first vertex at each corner.
    #[test]
    fn welding_closes_a_mesh_split_at_seams() {
        let c = primitives::cuboid(Vec3::ONE, 1);
        let mut positions = Vec::new();
        let mut triangles = Vec::new();
        for t in &c.triangles {
            let base = positions.len() as u32;
            positions.extend(t.map(|v| c.positions[v as usize]));
            triangles.push([base, base + 1, base + 2]);
        }
        let split = Mesh::new(positions, triangles, "split box").unwrap();
        assert_eq!(split.boundary_loops().len(), 12);
        let (w, origin) = split.welded_with_map();
        assert_eq!(w.positions.len(), 8);
        assert!(w.is_closed() && w.boundary_loops().is_empty());
        for (v, &o) in origin.iter().enumerate() {
            assert_eq!(w.positions[v], split.positions[o as usize]);
            // The first index wins, and ids follow first appearance.
            let first = split.positions.iter().position(|p| *p == w.positions[v]);
            assert_eq!(first, Some(o as usize));
        }
        assert!(origin.windows(2).all(|o| o[0] < o[1]));
        for (t, u) in split.triangles.iter().zip(&w.triangles) {
            assert_eq!(
                t.map(|i| split.positions[i as usize]),
                u.map(|i| w.positions[i as usize])
            );
        }
    }

    /// Two holes that touch at one vertex (a bow tie of boundary) are both closed: the walk
    /// splits the boundary into two loops there.
    #[test]
    fn holes_meeting_at_a_vertex_are_both_closed() {
        let s = primitives::uv_sphere(1.0, 16, 8);
        // Drop two triangles that share exactly one vertex: their holes meet there.
        let shared = s.triangles[20][0];
        let other = (0..s.triangles.len())
            .find(|&t| {
                t != 20
                    && s.triangles[t].contains(&shared)
                    && s.triangles[t]
                        .iter()
                        .filter(|v| s.triangles[20].contains(v))
                        .count()
                        == 1
            })
            .unwrap();
        let kept: Vec<[u32; 3]> = (0..s.triangles.len())
            .filter(|&t| t != 20 && t != other)
            .map(|t| s.triangles[t])
            .collect();
        let mut cut = Mesh::new(s.positions.clone(), kept, "bow tie").unwrap();
        assert!(!cut.is_closed());
        assert_eq!(cut.close_holes(), 2);
        assert!(cut.is_closed());
    }

    /// `is_closed` against a plain count of every edge by its ends' positions, on random
    /// triangle soups over a few positions (some vertices copies of others, some triangles
    /// repeated or degenerate), closed or not as chance has it.
    #[test]
    fn closedness_matches_a_count_of_edges_by_position() {
        use std::collections::HashMap;
        let mut seed = 7u32;
        let mut next = |n: u32| {
            seed = seed.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (seed >> 8) % n
        };
        let (mut closed, mut open) = (0, 0);
        for _ in 0..400 {
            let spots = 2 + next(5);
            let positions: Vec<Vec3> = (0..2 + next(8))
                .map(|_| Vec3::new(next(spots) as f32, 0.5, 0.0))
                .collect();
            let n = positions.len() as u32;
            let mut triangles: Vec<[u32; 3]> = (0..1 + next(6))
                .map(|_| [next(n), next(n), next(n)])
                .collect();
            if next(2) == 0 {
                triangles.extend(triangles.clone()); // every edge twice: closed
            }
            // Not `Mesh::new`: its validation would refuse the degenerate triangles.
            let mesh = Mesh {
                positions: positions.clone(),
                triangles: triangles.clone(),
                normals: Vec::new(),
                uvs: None,
            };
            let mut count: HashMap<([u32; 3], [u32; 3]), u32> = HashMap::new();
            for t in &triangles {
                for k in 0..3 {
                    let [a, b] = [t[k], t[(k + 1) % 3]]
                        .map(|i| positions[i as usize].to_array().map(f32::to_bits));
                    *count.entry((a.min(b), a.max(b))).or_default() += 1;
                }
            }
            let want = count.values().all(|c| c % 2 == 0);
            assert_eq!(mesh.is_closed(), want, "{positions:?} {triangles:?}");
            (closed, open) = if want {
                (closed + 1, open)
            } else {
                (closed, open + 1)
            };
        }
        assert!(closed > 100 && open > 100, "{closed} closed, {open} open");
    }

    #[test]
    fn primitives_are_closed_and_outward() {
        // Closed, outward meshes have positive signed volume close to the analytic one.
        let volume = Mesh::signed_volume;
        let s = primitives::uv_sphere(1.0, 64, 32);
        let v = volume(&s);
        assert!((v - 4.0 / 3.0 * std::f64::consts::PI).abs() < 0.03, "{v}");
        let b = primitives::cuboid(Vec3::new(1.0, 2.0, 3.0), 3);
        assert!((volume(&b) - 48.0).abs() < 1e-3, "{}", volume(&b));
        let t = primitives::torus(2.0, 0.5, 64, 32);
        let exact = 2.0 * std::f64::consts::PI.powi(2) * 2.0 * 0.25;
        assert!((volume(&t) - exact).abs() / exact < 0.01);
        let c = primitives::cylinder(0.5, 2.0, 64, 4);
        let exact = 64.0 / 2.0 * 0.25 * (std::f64::consts::TAU / 64.0).sin() * 2.0;
        assert!((volume(&c) - exact).abs() < 1e-5, "{} {exact}", volume(&c));
        assert_eq!(c.triangles.len(), 2 * 64 * 5);
        let p = primitives::plane(2.0, 4);
        assert!(p.normals.iter().all(|n| (*n - Vec3::Y).length() < 1e-6));
    }

    /// Closedness is by position: a cube whose triangles each have their own corners is
    /// closed, and stays so with a triangle doubled in reverse (a fin of two faces); without
    /// one triangle it is open, welded or not.
    #[test]
    fn closed_by_position_whatever_the_welding() {
        let welded = primitives::cuboid(Vec3::ONE, 2);
        assert!(welded.is_closed());
        let soup = |m: &Mesh, skip: Option<usize>| {
            let tris: Vec<[Vec3; 3]> = (0..m.triangles.len())
                .filter(|&t| Some(t) != skip)
                .map(|t| m.triangle(t))
                .collect();
            let positions = tris.iter().flatten().copied().collect();
            let triangles = (0..tris.len() as u32)
                .map(|t| [3 * t, 3 * t + 1, 3 * t + 2])
                .collect();
            Mesh::new(positions, triangles, "soup").unwrap()
        };
        assert!(soup(&welded, None).is_closed());
        let mut fin = soup(&welded, None);
        let [a, b, c] = fin.triangles[5];
        fin.triangles.push([a, c, b]);
        fin.triangles.push([a, b, c]);
        assert!(fin.is_closed());
        assert!(!soup(&welded, Some(7)).is_closed());
        let mut cut = welded.clone();
        cut.triangles.remove(3);
        assert!(!cut.is_closed());
    }

    #[test]
    fn validation_names_the_problem() {
        let e = Mesh::new(vec![Vec3::ZERO; 3], vec![], "m").unwrap_err();
        assert!(e.to_string().contains("no triangles"), "{e}");
        let e = Mesh::new(vec![Vec3::ZERO, Vec3::X, Vec3::NAN], vec![[0, 1, 2]], "m").unwrap_err();
        assert!(e.to_string().contains("vertex 3"), "{e}");
        let e = Mesh::new(vec![Vec3::ZERO; 3], vec![[0, 1, 7]], "m").unwrap_err();
        assert!(
            e.to_string().contains("triangle 1 uses vertex index 8"),
            "{e}"
        );
    }

    #[test]
    fn fit_transform_scales_longest_side() {
        let mut m = primitives::cuboid(Vec3::new(1.0, 0.5, 0.25), 1);
        m.transform(Mat4::from_translation(Vec3::new(5.0, 5.0, 5.0)));
        let t = m.fit_transform(1.0, Vec3::ZERO);
        m.transform(t);
        let b = m.bounds();
        assert!((b.size().x - 1.0).abs() < 1e-5);
        assert!(b.center().length() < 1e-5);
    }
}
