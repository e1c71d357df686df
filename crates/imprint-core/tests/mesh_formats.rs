//! `load_mesh` reads the same box from every format it supports, with the known answer each
//! time (8 vertices, 12 triangles, its bounds, its volume, closed), tells binary STL from
//! ASCII by length rather than by a leading "solid", and refuses what is no mesh with a
//! message naming the file, what it looks like and the formats it reads.

use imprint_core::glam::Vec3;
use imprint_core::mesh_formats::{MeshFormat, SUPPORTED, load_mesh};
use imprint_core::{Error, Mesh};
use std::path::{Path, PathBuf};

/// The box's corner extents per axis: different on each axis so a swapped axis shows.
const LO: [f32; 3] = [-1.0, 0.0, -0.5];
const HI: [f32; 3] = [2.0, 3.0, 0.5];
const VOLUME: f64 = 3.0 * 3.0 * 1.0;

/// Corner `i`: bit 0 picks x, bit 1 y, bit 2 z.
fn corner(i: usize) -> [f32; 3] {
    [0, 1, 2].map(|a| if i >> a & 1 == 1 { HI[a] } else { LO[a] })
}

/// The six faces as quads wound outward.
const QUADS: [[usize; 4]; 6] = [
    [0, 4, 6, 2],
    [1, 3, 7, 5],
    [0, 1, 5, 4],
    [2, 6, 7, 3],
    [0, 2, 3, 1],
    [4, 5, 7, 6],
];

/// The twelve triangles as corner positions (each quad fanned from its first corner).
fn triangles() -> Vec<[[f32; 3]; 3]> {
    QUADS
        .iter()
        .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
        .map(|t| t.map(corner))
        .collect()
}

/// What every reading of the box must give.
fn assert_is_the_box(m: &Mesh, what: &str) {
    assert_eq!(m.positions.len(), 8, "{what}: vertices");
    assert_eq!(m.triangles.len(), 12, "{what}: triangles");
    let b = m.bounds();
    assert_eq!(b.min, Vec3::from(LO), "{what}: min");
    assert_eq!(b.max, Vec3::from(HI), "{what}: max");
    assert!(m.is_closed(), "{what}: welded and closed");
    let v = m.signed_volume();
    assert!(
        (v - VOLUME).abs() < 1e-9,
        "{what}: volume {v}, want {VOLUME}"
    );
    assert_eq!(m.normals.len(), 8, "{what}: normals");
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn f32s_le(v: [f32; 3]) -> Vec<u8> {
    v.iter().flat_map(|c| c.to_le_bytes()).collect()
}

/// A binary STL of the box with `header` (at most 80 bytes) at the front.
fn binary_stl(header: &[u8]) -> Vec<u8> {
    let mut b = header.to_vec();
    b.resize(80, b' ');
    b.extend_from_slice(&12u32.to_le_bytes());
    for t in triangles() {
        b.extend(f32s_le([0.0; 3])); // a zero normal: readers recompute it
        for c in t {
            b.extend(f32s_le(c));
        }
        b.extend_from_slice(&[0, 0]);
    }
    assert_eq!(b.len(), 84 + 50 * 12);
    b
}

#[test]
fn ascii_ply_with_double_z_and_properties_in_any_order() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from(
        "ply\nformat ascii 1.0\ncomment the box\nelement vertex 8\nproperty double z\n\
         property uchar red\nproperty float x\nproperty float y\n\
         element face 6\nproperty list uchar int vertex_indices\nend_header\n",
    );
    for i in 0..8 {
        let [x, y, z] = corner(i);
        text += &format!("{z} 200 {x} {y}\n");
    }
    for q in QUADS {
        text += &format!("4 {} {} {} {}\n", q[0], q[1], q[2], q[3]);
    }
    let p = write(dir.path(), "box.ply", text.as_bytes());
    assert_is_the_box(&load_mesh(&p).unwrap(), "ASCII PLY");
    // Written on Windows: CRLF line ends.
    let p = write(
        dir.path(),
        "crlf.ply",
        text.replace('\n', "\r\n").as_bytes(),
    );
    assert_is_the_box(&load_mesh(&p).unwrap(), "ASCII PLY with CRLF");
}

#[test]
fn binary_ply_little_and_big_endian() {
    let dir = tempfile::tempdir().unwrap();
    for (endian, name, list) in [
        ("little", "le.ply", "vertex_indices"),
        ("big", "be.ply", "vertex_index"),
    ] {
        let mut b = format!(
            "ply\nformat binary_{endian}_endian 1.0\nelement vertex 8\nproperty float x\n\
             property float y\nproperty float z\nelement face 6\n\
             property list uchar uint {list}\nend_header\n"
        )
        .into_bytes();
        let word = |b: &mut Vec<u8>, bits: u32| {
            b.extend(match endian {
                "little" => bits.to_le_bytes(),
                _ => bits.to_be_bytes(),
            })
        };
        for i in 0..8 {
            for c in corner(i) {
                word(&mut b, c.to_bits());
            }
        }
        for q in QUADS {
            b.push(4);
            for i in q {
                word(&mut b, i as u32);
            }
        }
        let p = write(dir.path(), name, &b);
        assert_is_the_box(&load_mesh(&p).unwrap(), &format!("{endian}-endian PLY"));
    }
}

#[test]
fn ascii_stl_welds_corners_into_the_box() {
    let dir = tempfile::tempdir().unwrap();
    // A bare "solid" first line (legal, though some readers insist on a name) and CRLF ends.
    let mut text = String::from("solid\r\n");
    for t in triangles() {
        text += "  facet normal 0 0 0\r\n    outer loop\r\n";
        for [x, y, z] in t {
            text += &format!("      vertex {x:e} {y:e} {z:e}\r\n");
        }
        text += "    endloop\r\n  endfacet\r\n";
    }
    text += "endsolid\r\n";
    let p = write(dir.path(), "box.stl", text.as_bytes());
    assert_eq!(MeshFormat::detect(&p).unwrap(), MeshFormat::Stl);
    assert_is_the_box(&load_mesh(&p).unwrap(), "ASCII STL");
}

#[test]
fn binary_stl_welds_corners_into_the_box() {
    let dir = tempfile::tempdir().unwrap();
    let p = write(dir.path(), "box.stl", &binary_stl(b"binary box"));
    assert_is_the_box(&load_mesh(&p).unwrap(), "binary STL");
}

#[test]
fn binary_stl_whose_header_starts_with_solid_is_read_as_binary() {
    let dir = tempfile::tempdir().unwrap();
    // Exporters write such headers; the length (84 + 50 n) says binary, and the name says
    // nothing: it is called .dat here.
    let p = write(
        dir.path(),
        "box.dat",
        &binary_stl(b"solid box exported by a tool that writes facet in its header"),
    );
    assert_eq!(MeshFormat::detect(&p).unwrap(), MeshFormat::Stl);
    assert_is_the_box(&load_mesh(&p).unwrap(), "binary STL with a 'solid' header");
}

#[test]
fn obj_still_reads_and_content_beats_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let mut text = String::from("# the box\no box\n");
    for i in 0..8 {
        let [x, y, z] = corner(i);
        text += &format!("v {x} {y} {z}\n");
    }
    for q in QUADS {
        text += &format!("f {} {} {} {}\n", q[0] + 1, q[1] + 1, q[2] + 1, q[3] + 1);
    }
    let p = write(dir.path(), "box.obj", text.as_bytes());
    assert_is_the_box(&load_mesh(&p).unwrap(), "OBJ");
    // The same OBJ under a PLY's name is still read as the OBJ it is.
    let renamed = write(dir.path(), "box.ply", text.as_bytes());
    assert_eq!(MeshFormat::detect(&renamed).unwrap(), MeshFormat::Obj);
    assert_is_the_box(&load_mesh(&renamed).unwrap(), "OBJ named .ply");
}

#[test]
fn gltf_files_are_detected_as_gltf() {
    let dir = tempfile::tempdir().unwrap();
    let glb = write(dir.path(), "a.bin", b"glTF\x02\0\0\0\x0c\0\0\0");
    assert_eq!(MeshFormat::detect(&glb).unwrap(), MeshFormat::Glb);
    let json = write(
        dir.path(),
        "a.txt",
        b"\n{ \"asset\": { \"version\": \"2.0\" }, \"meshes\": [] }",
    );
    assert_eq!(MeshFormat::detect(&json).unwrap(), MeshFormat::Gltf);
}

/// `load_mesh(path)` fails with an input error (exit code 2) whose message names the file,
/// says `found`, and lists the supported formats.
fn assert_refused(path: &Path, found: &str) {
    let e = load_mesh(path).unwrap_err();
    let msg = e.to_string();
    assert!(matches!(e, Error::Mesh { .. }), "{msg}");
    assert_eq!(e.exit_code(), 2);
    assert!(msg.contains(&path.display().to_string()), "{msg}");
    assert!(msg.contains(found), "want {found:?} in: {msg}");
    assert!(msg.contains(SUPPORTED), "{msg}");
    assert!(!msg.contains("no triangles"), "{msg}");
}

#[test]
fn what_is_no_mesh_is_refused_with_what_it_is() {
    let dir = tempfile::tempdir().unwrap();
    let png = write(
        dir.path(),
        "photo.png",
        b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR\0\0\0\x10",
    );
    assert_refused(&png, "a PNG image");
    let zip = write(
        dir.path(),
        "meshes.zip",
        b"PK\x03\x04\x14\0\0\0\x08\0rest of a zip",
    );
    assert_refused(&zip, "a ZIP archive");
    let empty = write(dir.path(), "empty.obj", b"");
    assert_refused(&empty, "an empty file");
    // Deterministic noise (xorshift), with no format's signature.
    let mut x: u32 = 0x9E37_79B9;
    let noise: Vec<u8> = (0..4096)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            (x >> 24) as u8
        })
        .collect();
    let random = write(dir.path(), "noise", &noise);
    assert_refused(&random, "binary data");
    // A PNG given a mesh's name is still called a PNG.
    let disguised = write(dir.path(), "photo.stl", b"\x89PNG\r\n\x1a\n\0\0\0\rIHDR");
    assert_refused(&disguised, "a PNG image");
    let absent = dir.path().join("absent.ply");
    let msg = load_mesh(&absent).unwrap_err().to_string();
    assert!(msg.contains("absent.ply: file not found"), "{msg}");
}

#[test]
fn ply_errors_name_the_file_and_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let no_z = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                element face 0\nproperty list uchar int vertex_indices\nend_header\n0 0\n";
    let p = write(dir.path(), "no_z.ply", no_z.as_bytes());
    let msg = load_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("no_z.ply") && msg.contains("no 'z' property"),
        "{msg}"
    );

    let points = "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
                  property float z\nend_header\n0 0 0\n";
    let p = write(dir.path(), "points.ply", points.as_bytes());
    let msg = load_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("points.ply") && msg.contains("no 'face' element"),
        "{msg}"
    );

    let out_of_range = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
                        property float y\nproperty float z\nelement face 1\n\
                        property list uchar int vertex_indices\nend_header\n\
                        0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n";
    let p = write(dir.path(), "range.ply", out_of_range.as_bytes());
    let msg = load_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("range.ply") && msg.contains("triangle 1 uses vertex index 8"),
        "{msg}"
    );

    let truncated = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\n\
                     property float y\nproperty float z\nelement face 1\n\
                     property list uchar int vertex_indices\nend_header\n0 0 0\n";
    let p = write(dir.path(), "cut.ply", truncated.as_bytes());
    let msg = load_mesh(&p).unwrap_err().to_string();
    assert!(
        msg.contains("cut.ply") && msg.contains("not a readable PLY file"),
        "{msg}"
    );
}

/// The shipped meshes and characters are recognised by their content, not their names: the
/// same bytes under a name without an extension give the same format.
#[test]
fn shipped_assets_are_recognised_by_content() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets");
    let dir = tempfile::tempdir().unwrap();
    let mut seen = 0;
    for sub in ["meshes", "characters"] {
        for entry in std::fs::read_dir(root.join(sub)).unwrap() {
            let path = entry.unwrap().path();
            let Some(want) = MeshFormat::from_extension(&path) else {
                continue;
            };
            let anonymous = dir.path().join(format!("asset{seen}"));
            std::fs::copy(&path, &anonymous).unwrap();
            let got = MeshFormat::detect(&anonymous).unwrap();
            assert_eq!(got, want, "{}", path.display());
            seen += 1;
        }
    }
    assert!(seen >= 4, "{seen} assets");
}
