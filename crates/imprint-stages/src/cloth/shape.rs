//! The rest shape: particles, triangles and UVs of a grid or a garment mesh, the output
//! mesh's layout, and which particles the pins hold.

use super::params::{Pin, Shape};
use glam::{Vec2, Vec3};
use imprint_core::{Error, Mesh, Result};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Particles and faces at rest, and how to write them back out as a mesh.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ClothShape {
    /// Rest position of each particle.
    pub rest: Vec<Vec3>,
    /// Faces over particles, wound so that (b - a) x (c - a) is the cloth's normal.
    pub triangles: Vec<[u32; 3]>,
    /// UV of each triangle corner (meshes with UVs; grids: from their lattice).
    pub corner_uvs: Option<Vec<[Vec2; 3]>>,
    /// Grids: particles along u and v (particle `i + nx * j`).
    pub grid: Option<[u32; 2]>,
    /// Output mesh: which particle each output vertex shows (meshes keep their UV seams).
    pub out_particle: Vec<u32>,
    pub out_triangles: Vec<[u32; 3]>,
    pub out_uvs: Option<Vec<Vec2>>,
}

impl ClothShape {
    pub fn len(&self) -> usize {
        self.rest.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rest.is_empty()
    }

    /// The grid's (u, v) axes for a plane facing `normal`: v is world up projected onto the
    /// plane (-z for a horizontal plane), u = v x n, so (u, v, n) is right-handed.
    pub fn grid_axes(normal: Vec3) -> (Vec3, Vec3, Vec3) {
        let n = normal.normalize();
        let v = if n.y.abs() > 1.0 - 1e-6 {
            Vec3::NEG_Z
        } else {
            (Vec3::Y - n.y * n).normalize()
        };
        (v.cross(n), v, n)
    }

    /// A flat `nx x ny` grid (see [`Shape::Grid`]). Quads are split along alternating
    /// diagonals so that hinge bending and the output have no preferred direction.
    pub fn grid(size: [f32; 2], resolution: [u32; 2], center: Vec3, normal: Vec3) -> Self {
        let [nx, ny] = resolution;
        let (u, v, _) = Self::grid_axes(normal);
        let uv = |i: u32, j: u32| Vec2::new(i as f32 / (nx - 1) as f32, j as f32 / (ny - 1) as f32);
        let mut rest = Vec::with_capacity((nx * ny) as usize);
        let mut uvs = Vec::with_capacity((nx * ny) as usize);
        for j in 0..ny {
            for i in 0..nx {
                let t = uv(i, j);
                rest.push(center + (t.x - 0.5) * size[0] * u + (t.y - 0.5) * size[1] * v);
                uvs.push(t);
            }
        }
        let id = |i: u32, j: u32| i + nx * j;
        let mut triangles = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                if (i + j) % 2 == 0 {
                    triangles.extend([[a, b, c], [a, c, d]]);
                } else {
                    triangles.extend([[a, b, d], [b, c, d]]);
                }
            }
        }
        let corner_uvs = triangles
            .iter()
            .map(|t| t.map(|p| uvs[p as usize]))
            .collect();
        ClothShape {
            out_particle: (0..rest.len() as u32).collect(),
            out_triangles: triangles.clone(),
            out_uvs: Some(uvs),
            rest,
            triangles,
            corner_uvs: Some(corner_uvs),
            grid: Some(resolution),
        }
    }

    /// A garment mesh: vertices at bit-identical positions become one particle (OBJ files
    /// split vertices at UV seams, and a cloth must not come apart there).
    pub fn from_mesh(mesh: &Mesh) -> Self {
        let mut index: HashMap<[u32; 3], u32> = HashMap::new();
        let mut rest = Vec::new();
        let out_particle: Vec<u32> = mesh
            .positions
            .iter()
            .map(|p| {
                *index
                    .entry(p.to_array().map(f32::to_bits))
                    .or_insert_with(|| {
                        rest.push(*p);
                        rest.len() as u32 - 1
                    })
            })
            .collect();
        let triangles = mesh
            .triangles
            .iter()
            .map(|t| t.map(|v| out_particle[v as usize]))
            .collect();
        let corner_uvs = mesh.uvs.as_ref().map(|uv| {
            mesh.triangles
                .iter()
                .map(|t| t.map(|v| uv[v as usize]))
                .collect()
        });
        ClothShape {
            rest,
            triangles,
            corner_uvs,
            grid: None,
            out_particle,
            out_triangles: mesh.triangles.clone(),
            out_uvs: mesh.uvs.clone(),
        }
    }

    /// Builds the shape the params describe; `mesh` is the loaded garment for `Shape::Mesh`.
    pub fn build(shape: &Shape, mesh: Option<&Mesh>) -> Result<Self> {
        match shape {
            Shape::Grid {
                size,
                resolution,
                center,
                normal,
            } => Ok(Self::grid(*size, *resolution, *center, *normal)),
            Shape::Mesh { path } => {
                let mesh = mesh.ok_or_else(|| {
                    Error::Invalid(format!("cloth: the garment mesh {path} was not loaded"))
                })?;
                Ok(Self::from_mesh(mesh))
            }
        }
    }

    /// The particles the pins hold, sorted, each once.
    pub fn resolve_pins(&self, pins: &[Pin]) -> Result<Vec<u32>> {
        let n = self.rest.len() as u32;
        let mut out = Vec::new();
        for (k, pin) in pins.iter().enumerate() {
            match pin {
                Pin::Indices(ids) => {
                    if let Some(&bad) = ids.iter().find(|&&i| i >= n) {
                        return Err(Error::Invalid(format!(
                            "cloth: pins[{k}] names particle {bad} but the cloth has {n} particles"
                        )));
                    }
                    out.extend_from_slice(ids);
                }
                Pin::Region { min, max } => {
                    let before = out.len();
                    out.extend((0..n).filter(|&i| {
                        let p = self.rest[i as usize];
                        p.cmpge(*min).all() && p.cmple(*max).all()
                    }));
                    if out.len() == before {
                        return Err(Error::Invalid(format!(
                            "cloth: pins[{k}]: no particle lies in the region {min}..{max}"
                        )));
                    }
                }
                Pin::TopEdge => match self.grid {
                    Some([nx, ny]) => out.extend((0..nx).map(|i| i + nx * (ny - 1))),
                    None => {
                        let (lo, hi) = self
                            .rest
                            .iter()
                            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), p| {
                                (lo.min(p.y), hi.max(p.y))
                            });
                        let extent = self
                            .rest
                            .iter()
                            .fold(Vec3::splat(f32::NEG_INFINITY), |m, p| m.max(*p))
                            - self
                                .rest
                                .iter()
                                .fold(Vec3::splat(f32::INFINITY), |m, p| m.min(*p));
                        let tol = 1e-4 * extent.max_element().max(hi - lo);
                        out.extend((0..n).filter(|&i| self.rest[i as usize].y >= hi - tol));
                    }
                },
            }
        }
        out.sort_unstable();
        out.dedup();
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_axes_are_right_handed_and_up_is_up() {
        for n in [Vec3::Y, -Vec3::Y, Vec3::Z, Vec3::new(1.0, 0.3, -0.2)] {
            let (u, v, nn) = ClothShape::grid_axes(n);
            assert!((u.cross(v) - nn).length() < 1e-6, "{n}");
            assert!(u.dot(v).abs() < 1e-6);
        }
        let (_, v, _) = ClothShape::grid_axes(Vec3::Z);
        assert!((v - Vec3::Y).length() < 1e-6);
    }

    #[test]
    fn grid_faces_face_the_normal_and_top_edge_is_up() {
        let s = ClothShape::grid([2.0, 1.0], [5, 4], Vec3::new(0.0, 1.0, 0.0), Vec3::Z);
        assert_eq!(s.len(), 20);
        assert_eq!(s.triangles.len(), 2 * 4 * 3);
        for t in &s.triangles {
            let [a, b, c] = t.map(|i| s.rest[i as usize]);
            assert!((b - a).cross(c - a).normalize().dot(Vec3::Z) > 0.999);
        }
        let top = s.resolve_pins(&[Pin::TopEdge]).unwrap();
        assert_eq!(top, vec![15, 16, 17, 18, 19]);
        assert!(
            top.iter()
                .all(|&i| (s.rest[i as usize].y - 1.5).abs() < 1e-6)
        );
    }

    #[test]
    fn mesh_shapes_weld_seams_and_pins_check_indices() {
        // Two triangles sharing an edge whose vertices are duplicated (a UV seam).
        let mut m = Mesh::new(
            vec![
                Vec3::ZERO,
                Vec3::X,
                Vec3::Y,
                Vec3::X,
                Vec3::Y,
                Vec3::new(1.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [3, 5, 4]],
            "seam",
        )
        .unwrap();
        m.uvs = Some(vec![Vec2::ZERO; 6]);
        let s = ClothShape::from_mesh(&m);
        assert_eq!(s.len(), 4);
        assert_eq!(s.triangles, vec![[0, 1, 2], [1, 3, 2]]);
        assert_eq!(s.out_particle, vec![0, 1, 2, 1, 2, 3]);
        assert_eq!(s.resolve_pins(&[Pin::TopEdge]).unwrap(), vec![2, 3]);
        let e = s.resolve_pins(&[Pin::Indices(vec![9])]).unwrap_err();
        assert!(e.to_string().contains("pins[0]"), "{e}");
    }
}
