//! Mesh files: Wavefront OBJ (text) and binary little-endian PLY, written through
//! [`atomic_write`] (a reader never finds a half-written file under its final name).
//!
//! Floats are written with Rust's `{}` Display for f32, which prints the shortest decimal that
//! parses back to the same f32, so positions, normals and uvs round-trip bit-exactly.
//! Non-finite values are refused (the write fails and no file appears).

use imprint_core::io::atomic_write;
use imprint_core::{Mesh, Result};
use std::io::Error as IoError;
use std::path::Path;

/// What an OBJ file carries besides positions and faces.
#[derive(Clone, Debug)]
pub struct ObjOptions {
    /// Write `vn` lines (when the mesh has one normal per vertex).
    pub normals: bool,
    /// Write `vt` lines (when the mesh has one uv per vertex).
    pub uvs: bool,
    /// A `#` comment line at the top (e.g. the node and frame); none when empty.
    pub comment: String,
}

impl Default for ObjOptions {
    fn default() -> Self {
        ObjOptions {
            normals: true,
            uvs: true,
            comment: String::new(),
        }
    }
}

fn non_finite(what: &str, index: usize) -> IoError {
    IoError::new(
        std::io::ErrorKind::InvalidData,
        format!("{what} {index} is not finite; nothing written"),
    )
}

/// Writes `mesh` as OBJ: `v x y z`, then `vt u v` and `vn x y z` where the mesh has them (and
/// `opts` asks for them), then one `f` per triangle with 1-based indices in the form that
/// matches: `f a b c`, `f a/a b/b c/c` (uvs), `f a//a ...` (normals) or `f a/a/a ...` (both).
pub fn write_obj(path: &Path, mesh: &Mesh, opts: &ObjOptions) -> Result<()> {
    let n = mesh.positions.len();
    let normals = opts.normals && mesh.normals.len() == n && n > 0;
    let uvs = match &mesh.uvs {
        Some(uv) if opts.uvs && uv.len() == n && n > 0 => Some(uv.as_slice()),
        _ => None,
    };
    atomic_write(path, |w| {
        for line in opts.comment.lines() {
            writeln!(w, "# {line}")?;
        }
        writeln!(
            w,
            "# imprint: {} vertices, {} triangles",
            n,
            mesh.triangles.len()
        )?;
        for (j, p) in mesh.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(non_finite("position", j));
            }
            writeln!(w, "v {} {} {}", p.x, p.y, p.z)?;
        }
        if let Some(uvs) = uvs {
            for (j, t) in uvs.iter().enumerate() {
                if !t.is_finite() {
                    return Err(non_finite("uv", j));
                }
                writeln!(w, "vt {} {}", t.x, t.y)?;
            }
        }
        if normals {
            for (j, v) in mesh.normals.iter().enumerate() {
                if !v.is_finite() {
                    return Err(non_finite("normal", j));
                }
                writeln!(w, "vn {} {} {}", v.x, v.y, v.z)?;
            }
        }
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if tri.iter().any(|&i| i as usize >= n) {
                return Err(IoError::new(
                    std::io::ErrorKind::InvalidData,
                    format!("triangle {t} indexes past the {n} vertices; nothing written"),
                ));
            }
            let [a, b, c] = tri.map(|i| i as u64 + 1);
            match (uvs.is_some(), normals) {
                (false, false) => writeln!(w, "f {a} {b} {c}")?,
                (true, false) => writeln!(w, "f {a}/{a} {b}/{b} {c}/{c}")?,
                (false, true) => writeln!(w, "f {a}//{a} {b}//{b} {c}//{c}")?,
                (true, true) => writeln!(w, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?,
            }
        }
        Ok(())
    })
}

/// The PLY header [`write_ply`] writes for `vertices` vertices (with normals or not) and
/// `faces` triangles.
pub fn ply_header(vertices: usize, faces: usize, normals: bool) -> String {
    let mut h = String::from("ply\nformat binary_little_endian 1.0\ncomment written by imprint\n");
    h += &format!("element vertex {vertices}\n");
    h += "property float x\nproperty float y\nproperty float z\n";
    if normals {
        h += "property float nx\nproperty float ny\nproperty float nz\n";
    }
    h += &format!("element face {faces}\n");
    h += "property list uchar uint vertex_indices\nend_header\n";
    h
}

/// Writes `mesh` as binary little-endian PLY: per vertex x y z (and nx ny nz when the mesh has
/// one normal per vertex) as f32, per face a `uchar` count (3) and three `uint` indices.
pub fn write_ply(path: &Path, mesh: &Mesh) -> Result<()> {
    let n = mesh.positions.len();
    let normals = mesh.normals.len() == n && n > 0;
    atomic_write(path, |w| {
        w.write_all(ply_header(n, mesh.triangles.len(), normals).as_bytes())?;
        for (j, p) in mesh.positions.iter().enumerate() {
            if !p.is_finite() {
                return Err(non_finite("position", j));
            }
            let mut rec = [0u8; 24];
            for (c, v) in p.to_array().into_iter().enumerate() {
                rec[4 * c..4 * c + 4].copy_from_slice(&v.to_le_bytes());
            }
            if normals {
                let v = mesh.normals[j];
                if !v.is_finite() {
                    return Err(non_finite("normal", j));
                }
                for (c, v) in v.to_array().into_iter().enumerate() {
                    rec[12 + 4 * c..16 + 4 * c].copy_from_slice(&v.to_le_bytes());
                }
                w.write_all(&rec)?;
            } else {
                w.write_all(&rec[..12])?;
            }
        }
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if tri.iter().any(|&i| i as usize >= n) {
                return Err(IoError::new(
                    std::io::ErrorKind::InvalidData,
                    format!("triangle {t} indexes past the {n} vertices; nothing written"),
                ));
            }
            let mut rec = [3u8; 13];
            for (c, i) in tri.iter().enumerate() {
                rec[1 + 4 * c..5 + 4 * c].copy_from_slice(&i.to_le_bytes());
            }
            w.write_all(&rec)?;
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::glam::{Vec2, Vec3};
    use imprint_core::mesh::primitives;

    fn bits(v: Vec3) -> [u32; 3] {
        v.to_array().map(f32::to_bits)
    }

    #[test]
    fn display_of_f32_round_trips_bit_exactly() {
        // A deterministic spread of bit patterns: every exponent, scrambled mantissas.
        let mut x: u32 = 0x1234_5678;
        let mut checked = 0;
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let f = f32::from_bits(x);
            if !f.is_finite() {
                continue;
            }
            let back: f32 = format!("{f}").parse().unwrap();
            assert_eq!(back.to_bits(), f.to_bits(), "{f:e} printed as {f}");
            checked += 1;
        }
        for f in [
            f32::MIN_POSITIVE,
            f32::MAX,
            f32::MIN,
            f32::EPSILON,
            1e-45,
            -0.0,
            0.1,
            1.0 / 3.0,
        ] {
            let back: f32 = format!("{f}").parse().unwrap();
            assert_eq!(back.to_bits(), f.to_bits());
        }
        assert!(checked > 100_000);
    }

    /// A mesh whose faces reference vertices in order of first use, so a reader that
    /// renumbers vertices by first use (tobj with `single_index`) keeps the numbering.
    fn ordered_mesh() -> Mesh {
        let mut m = primitives::plane(1.0, 3);
        // Awkward values that need many digits.
        for (j, p) in m.positions.iter_mut().enumerate() {
            p.y = (j as f32 * 0.1 + 1.0 / 3.0).sin() * 1e-3 + f32::EPSILON;
            p.x *= std::f32::consts::PI;
        }
        m.compute_normals();
        let n = m.positions.len();
        m.uvs = Some(
            (0..n)
                .map(|j| Vec2::new(j as f32 / 7.0, 1.0 - j as f32 / 11.0))
                .collect(),
        );
        // Renumber vertices by first use in the faces.
        let mut map = vec![u32::MAX; n];
        let mut order = Vec::new();
        for t in &mut m.triangles {
            for i in t.iter_mut() {
                if map[*i as usize] == u32::MAX {
                    map[*i as usize] = order.len() as u32;
                    order.push(*i as usize);
                }
                *i = map[*i as usize];
            }
        }
        let uvs = m.uvs.as_ref().unwrap();
        Mesh {
            positions: order.iter().map(|&j| m.positions[j]).collect(),
            triangles: m.triangles.clone(),
            normals: order.iter().map(|&j| m.normals[j]).collect(),
            uvs: Some(order.iter().map(|&j| uvs[j]).collect()),
        }
    }

    #[test]
    fn obj_round_trips_bit_exactly_through_load_obj() {
        let dir = tempfile::tempdir().unwrap();
        let m = ordered_mesh();
        for (normals, uvs) in [(true, true), (true, false), (false, true), (false, false)] {
            let path = dir.path().join(format!("m_{normals}_{uvs}.obj"));
            let opts = ObjOptions {
                normals,
                uvs,
                comment: "frame 3".into(),
            };
            write_obj(&path, &m, &opts).unwrap();
            let text = std::fs::read_to_string(&path).unwrap();
            assert!(text.starts_with("# frame 3\n"));
            assert_eq!(text.contains("\nvn "), normals);
            assert_eq!(text.contains("\nvt "), uvs);
            let back = Mesh::load_obj(&path).unwrap();
            assert_eq!(back.triangles, m.triangles);
            assert_eq!(back.positions.len(), m.positions.len());
            for (a, b) in back.positions.iter().zip(&m.positions) {
                assert_eq!(bits(*a), bits(*b));
            }
            if normals {
                // load_obj normalises normals: unit normals come back within an ulp or so.
                for (a, b) in back.normals.iter().zip(&m.normals) {
                    assert!((*a - *b).length() < 1e-6);
                }
            }
            if uvs {
                let (a, b) = (back.uvs.unwrap(), m.uvs.clone().unwrap());
                assert_eq!(a.len(), b.len());
                for (a, b) in a.iter().zip(&b) {
                    assert_eq!(
                        a.to_array().map(f32::to_bits),
                        b.to_array().map(f32::to_bits)
                    );
                }
            } else {
                assert!(back.uvs.is_none());
            }
        }
    }

    #[test]
    fn obj_of_a_general_mesh_keeps_every_triangle_corner() {
        // uv_sphere's faces do not use vertices in order; compare corners, not numbering.
        let m = primitives::uv_sphere(1.3, 12, 7);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.obj");
        write_obj(&path, &m, &ObjOptions::default()).unwrap();
        let back = Mesh::load_obj(&path).unwrap();
        assert_eq!(back.triangles.len(), m.triangles.len());
        for t in 0..m.triangles.len() {
            let (a, b) = (m.triangle(t), back.triangle(t));
            for c in 0..3 {
                assert_eq!(bits(a[c]), bits(b[c]));
            }
        }
    }

    #[test]
    fn ply_header_and_length_are_exact() {
        let m = primitives::cuboid(Vec3::new(1.0, 2.0, 0.5), 2);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.ply");
        write_ply(&path, &m).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let (nv, nf) = (m.positions.len(), m.triangles.len());
        let header = format!(
            "ply\nformat binary_little_endian 1.0\ncomment written by imprint\n\
             element vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n\
             property float nx\nproperty float ny\nproperty float nz\n\
             element face {nf}\nproperty list uchar uint vertex_indices\nend_header\n"
        );
        assert!(bytes.starts_with(header.as_bytes()));
        let body = &bytes[header.len()..];
        assert_eq!(body.len(), nv * 24 + nf * 13);
        // First vertex and first face decode back.
        let f = |o: usize| f32::from_le_bytes(body[o..o + 4].try_into().unwrap());
        assert_eq!(Vec3::new(f(0), f(4), f(8)), m.positions[0]);
        assert_eq!(Vec3::new(f(12), f(16), f(20)), m.normals[0]);
        let face = &body[nv * 24..nv * 24 + 13];
        assert_eq!(face[0], 3);
        let idx = |o: usize| u32::from_le_bytes(face[o..o + 4].try_into().unwrap());
        assert_eq!([idx(1), idx(5), idx(9)], m.triangles[0]);

        // Without normals: 12 bytes per vertex, no normal properties.
        let mut bare = m.clone();
        bare.normals.clear();
        write_ply(&path, &bare).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let header = ply_header(nv, nf, false);
        assert!(!header.contains("nx"));
        assert!(bytes.starts_with(header.as_bytes()));
        assert_eq!(bytes.len() - header.len(), nv * 12 + nf * 13);
    }

    #[test]
    fn a_failing_write_leaves_no_file() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = primitives::uv_sphere(1.0, 8, 5);
        // The last normal is NaN: the writers fail after writing most of the file.
        let last = m.normals.len() - 1;
        m.normals[last] = Vec3::NAN;
        let obj = dir.path().join("bad.obj");
        let ply = dir.path().join("bad.ply");
        assert!(write_obj(&obj, &m, &ObjOptions::default()).is_err());
        assert!(write_ply(&ply, &m).is_err());
        assert!(!obj.exists() && !ply.exists());
        // Nor any temporary file.
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);

        // A failed rewrite keeps the previous complete file.
        let good = primitives::uv_sphere(1.0, 8, 5);
        write_obj(&obj, &good, &ObjOptions::default()).unwrap();
        let before = std::fs::read(&obj).unwrap();
        assert!(write_obj(&obj, &m, &ObjOptions::default()).is_err());
        assert_eq!(std::fs::read(&obj).unwrap(), before);
    }
}
