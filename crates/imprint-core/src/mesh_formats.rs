//! Reading a user's mesh file whatever its format: [`load_mesh`] looks at the file's first
//! bytes (and its length) to tell OBJ, PLY, STL and glTF apart, and falls back on the
//! extension only where the content cannot decide. A file that is none of them is refused with
//! a message that says what it looks like (an image, an archive, binary data) and what is read.
//!
//! Why content first: users rename files, exporters write `.stl` files that start with
//! `solid` but are binary, and a PNG handed to the OBJ reader used to come back as "the mesh
//! has no triangles", which says nothing about the real mistake.

use crate::{Error, Mesh, Result};
use glam::Vec3;
use std::collections::HashMap;
use std::io::Read;
use std::path::Path;

/// The formats [`load_mesh`] reads, as error messages list them.
pub const SUPPORTED: &str =
    "OBJ, PLY (ASCII and binary), STL (ASCII and binary), glTF 2.0 (.gltf, .glb)";

/// How much of a file detection looks at: enough for every header and for the first lines
/// of a text format, little enough to cost nothing on a large mesh.
const SNIFF_BYTES: u64 = 64 * 1024;

/// Lines of a text file that must all look like OBJ statements for it to count as OBJ.
const OBJ_SNIFF_LINES: usize = 50;

/// A mesh file format [`load_mesh`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeshFormat {
    /// Wavefront OBJ (text).
    Obj,
    /// Stanford PLY: ASCII, binary little- or big-endian.
    Ply,
    /// STL: ASCII or binary.
    Stl,
    /// glTF 2.0 JSON (`.gltf`, buffers beside it or embedded).
    Gltf,
    /// glTF 2.0 binary container (`.glb`).
    Glb,
}

impl MeshFormat {
    /// The format a file's first bytes show, given the file's whole length (binary STL is
    /// recognised by its length: an 80-byte header, a triangle count n, then 50 bytes per
    /// triangle). `None` when the bytes do not decide.
    pub fn sniff(head: &[u8], file_len: u64) -> Option<MeshFormat> {
        if head.starts_with(b"ply\n") || head.starts_with(b"ply\r\n") {
            return Some(MeshFormat::Ply);
        }
        if head.starts_with(b"glTF") {
            return Some(MeshFormat::Glb);
        }
        // Before ASCII STL: a binary STL's free-form header often starts with "solid" too.
        if is_binary_stl(head, file_len) {
            return Some(MeshFormat::Stl);
        }
        let text = trim_start(head);
        if text.starts_with(b"solid") && (contains(head, b"facet") || contains(head, b"endsolid")) {
            return Some(MeshFormat::Stl);
        }
        if text.starts_with(b"{") && contains(head, b"\"asset\"") {
            return Some(MeshFormat::Gltf);
        }
        looks_like_obj(head).then_some(MeshFormat::Obj)
    }

    /// The format a file name's extension names (case-insensitive).
    pub fn from_extension(path: &Path) -> Option<MeshFormat> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        Some(match ext.as_str() {
            "obj" => MeshFormat::Obj,
            "ply" => MeshFormat::Ply,
            "stl" => MeshFormat::Stl,
            "gltf" => MeshFormat::Gltf,
            "glb" => MeshFormat::Glb,
            _ => return None,
        })
    }

    /// The format's name in messages.
    pub fn name(self) -> &'static str {
        match self {
            MeshFormat::Obj => "OBJ",
            MeshFormat::Ply => "PLY",
            MeshFormat::Stl => "STL",
            MeshFormat::Gltf => "glTF",
            MeshFormat::Glb => "GLB",
        }
    }

    /// The format of the file at `path`: its content first, then its extension for the
    /// formats whose content test is a heuristic (OBJ, glTF JSON), when the file is text. PLY,
    /// STL and GLB have signatures, so a file named `.ply` without one is refused rather than
    /// misread.
    pub fn detect(path: &Path) -> Result<MeshFormat> {
        let (head, len) = read_head(path)?;
        if let Some(f) = MeshFormat::sniff(&head, len) {
            return Ok(f);
        }
        let text = !head.is_empty() && text_prefix(&head).is_some();
        let found = describe(&head);
        let problem = match MeshFormat::from_extension(path) {
            Some(f @ (MeshFormat::Obj | MeshFormat::Gltf)) if text => return Ok(f),
            Some(f) => format!(
                "the name says {} but the file is {found}{}",
                f.name(),
                signature(f)
            ),
            None => format!("{found}{}, not a mesh", extension(path)),
        };
        Err(Error::mesh(
            path,
            format!("{problem}; imprint reads {SUPPORTED}"),
        ))
    }
}

/// Loads a mesh from an OBJ, PLY, STL, glTF or GLB file, whichever the file is (see
/// [`MeshFormat::detect`]). Errors name the file and the problem (exit code 2 in the CLI).
pub fn load_mesh(path: &Path) -> Result<Mesh> {
    match MeshFormat::detect(path)? {
        MeshFormat::Obj => Mesh::load_obj(path),
        MeshFormat::Ply => load_ply(path),
        MeshFormat::Stl => load_stl(path),
        MeshFormat::Gltf | MeshFormat::Glb => crate::gltf::Document::load(path).map(|d| d.mesh),
    }
}

/// The first [`SNIFF_BYTES`] of `path` and its length.
fn read_head(path: &Path) -> Result<(Vec<u8>, u64)> {
    if !path.exists() {
        return Err(Error::mesh(path, "file not found"));
    }
    if path.is_dir() {
        return Err(Error::mesh(path, "is a folder, not a mesh file"));
    }
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut head = Vec::new();
    file.take(SNIFF_BYTES)
        .read_to_end(&mut head)
        .map_err(|e| Error::io(path, e))?;
    Ok((head, len))
}

/// An 80-byte header, a little-endian u32 triangle count n, and exactly 50 bytes per triangle.
fn is_binary_stl(head: &[u8], file_len: u64) -> bool {
    let Some(count) = head.get(80..84) else {
        return false;
    };
    let n = u32::from_le_bytes(count.try_into().expect("4 bytes")) as u64;
    file_len == 84 + 50 * n
}

fn trim_start(bytes: &[u8]) -> &[u8] {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    let start = bytes
        .iter()
        .position(|b| !b.is_ascii_whitespace())
        .unwrap_or(bytes.len());
    &bytes[start..]
}

fn contains(haystack: &[u8], needle: &[u8]) -> bool {
    haystack.windows(needle.len()).any(|w| w == needle)
}

/// Text whose first non-blank lines all start with an OBJ statement, at least one of them
/// more than a comment.
fn looks_like_obj(head: &[u8]) -> bool {
    const KEYWORDS: [&str; 16] = [
        "v", "vn", "vt", "vp", "f", "l", "p", "o", "g", "s", "mtllib", "usemtl", "cstype", "deg",
        "curv", "surf",
    ];
    let Some(text) = text_prefix(head) else {
        return false;
    };
    let mut lines: Vec<&str> = text
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .collect();
    if head.len() as u64 >= SNIFF_BYTES {
        lines.pop(); // the prefix may cut its last line
    }
    lines.truncate(OBJ_SNIFF_LINES);
    let statement = |l: &&str| {
        let word = l.split_whitespace().next().unwrap_or("");
        KEYWORDS.contains(&word)
    };
    let comment = |l: &&str| l.starts_with('#');
    lines.iter().all(|l| comment(l) || statement(l)) && lines.iter().any(statement)
}

/// The bytes as text, when they are UTF-8 without NULs (a multi-byte character cut at the
/// end of the prefix is allowed).
fn text_prefix(head: &[u8]) -> Option<&str> {
    if head.contains(&0) {
        return None;
    }
    match std::str::from_utf8(head) {
        Ok(s) => Some(s),
        Err(e) if e.error_len().is_none() => std::str::from_utf8(&head[..e.valid_up_to()]).ok(),
        Err(_) => None,
    }
}

/// What a file that is no mesh looks like, for the message that refuses it.
fn describe(head: &[u8]) -> String {
    const MAGIC: [(&[u8], &str); 9] = [
        (b"\x89PNG", "a PNG image"),
        (b"\xFF\xD8\xFF", "a JPEG image"),
        (b"GIF8", "a GIF image"),
        (b"PK\x03\x04", "a ZIP archive"),
        (b"PK\x05\x06", "a ZIP archive"),
        (b"\x1F\x8B", "a gzip archive"),
        (b"%PDF", "a PDF document"),
        (b"\x7FELF", "an executable"),
        (
            b"BLENDER",
            "a .blend file (export it as glTF, OBJ, PLY or STL)",
        ),
    ];
    if head.is_empty() {
        return "an empty file".into();
    }
    if let Some((_, what)) = MAGIC.iter().find(|(m, _)| head.starts_with(m)) {
        return (*what).into();
    }
    match text_prefix(head) {
        Some(text) if trim_start(head).starts_with(b"{") => {
            format!("JSON without a glTF \"asset\" ({})", first_line(text))
        }
        Some(text) if !trim_start(head).is_empty() => format!("text ({})", first_line(text)),
        Some(_) => "blank text".into(),
        None => "binary data".into(),
    }
}

/// The first non-blank line, shortened, quoted.
fn first_line(text: &str) -> String {
    let line = text
        .lines()
        .map(str::trim)
        .find(|l| !l.is_empty())
        .unwrap_or("");
    let short: String = line.chars().take(40).collect();
    let more = if short.len() < line.len() { "..." } else { "" };
    format!("first line '{short}{more}'")
}

/// " (extension .xyz)" or " (no extension)", for messages.
fn extension(path: &Path) -> String {
    match path.extension() {
        Some(e) => format!(" (extension .{})", e.to_string_lossy()),
        None => " (no extension)".into(),
    }
}

/// What a file of format `f` starts with, for the message that refuses an impostor.
fn signature(f: MeshFormat) -> &'static str {
    match f {
        MeshFormat::Ply => " (a PLY file starts with the line 'ply')",
        MeshFormat::Glb => " (a GLB file starts with 'glTF')",
        MeshFormat::Stl => {
            " (an ASCII STL starts with 'solid' and has facets; a binary one is 84 bytes plus \
             50 per triangle)"
        }
        MeshFormat::Obj | MeshFormat::Gltf => "",
    }
}

/// Validates a mesh read from `path`, as a Mesh-kind error (exit code 2: fix the input)
/// that names the file once.
fn validate(mesh: &Mesh, path: &Path) -> Result<()> {
    let source = path.display().to_string();
    mesh.validate(&source).map_err(|e| match e {
        Error::Invalid(p) => {
            let problem = p.strip_prefix(&format!("{source}: ")).unwrap_or(&p);
            Error::mesh(path, problem)
        }
        other => other,
    })
}

/// One-line form of a parser's message (ply-rs puts tabs and newlines in its own), cut to a
/// readable length (an STL reader quotes the tokens it choked on, which may be binary junk).
fn one_line(msg: impl std::fmt::Display) -> String {
    let line = msg
        .to_string()
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    match line.char_indices().nth(200) {
        Some((cut, _)) => format!("{}...", &line[..cut]),
        None => line,
    }
}

// ---------------------------------------------------------------------------------------------
// PLY

/// What a PLY element's properties give: the position and normal of a vertex, the index list
/// of a face. One type for every element (ply-rs parses all elements into one type); the
/// properties of other elements are ignored.
#[derive(Default)]
struct PlyElement {
    xyz: [Option<f32>; 3],
    normal: [Option<f32>; 3],
    indices: Option<Vec<u32>>,
    /// A face's index list held a negative number.
    negative: bool,
}

impl ply_rs_bw::ply::PropertyAccess for PlyElement {
    fn new() -> Self {
        PlyElement::default()
    }

    fn set_property(
        &mut self,
        name: &str,
        property: ply_rs_bw::ply::Property,
    ) -> ply_rs_bw::ply::PropertyAccessResult {
        use ply_rs_bw::ply::PropertyAccessResult::{Ignored, Set};
        let slot = match name {
            "x" => &mut self.xyz[0],
            "y" => &mut self.xyz[1],
            "z" => &mut self.xyz[2],
            "nx" => &mut self.normal[0],
            "ny" => &mut self.normal[1],
            "nz" => &mut self.normal[2],
            "vertex_indices" | "vertex_index" => {
                self.indices = property.to_u32_list();
                self.negative = self.indices.is_none();
                return Set;
            }
            _ => return Ignored,
        };
        *slot = property.to_f32_lossy();
        if slot.is_some() { Set } else { Ignored }
    }
}

/// Reads a PLY file (ASCII, binary little- or big-endian): `vertex` elements with `x y z`
/// (any scalar type, any order, other properties ignored; `nx ny nz` taken when present) and
/// `face` elements with a `vertex_indices` (or `vertex_index`) list, polygons fan-triangulated.
pub fn load_ply(path: &Path) -> Result<Mesh> {
    use ply_rs_bw::parser::{Parser, Reader};
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut reader = Reader::new(std::io::BufReader::new(file));
    let parser = Parser::<PlyElement>::new();
    let bad = |e: ply_rs_bw::parser::ParseError| {
        Error::mesh(path, format!("not a readable PLY file ({})", one_line(e)))
    };
    let header = parser.read_header(&mut reader).map_err(bad)?;
    let face_list = check_ply_header(&header).map_err(|p| Error::mesh(path, p))?;
    let mut payload = parser.read_payload(&mut reader, &header).map_err(bad)?;
    let vertices = payload.swap_remove("vertex").unwrap_or_default();
    let faces = payload.swap_remove("face").unwrap_or_default();
    let (positions, normals) = ply_vertices(&vertices);
    let triangles = ply_triangles(&faces, face_list).map_err(|p| Error::mesh(path, p))?;
    let mut mesh = Mesh {
        positions,
        triangles,
        normals: Vec::new(),
        uvs: None,
    };
    validate(&mesh, path)?;
    match normals {
        Some(n) => mesh.normals = n,
        None => mesh.compute_normals(),
    }
    Ok(mesh)
}

/// Checks the header declares what a mesh needs; returns the face list property's name.
fn check_ply_header(header: &ply_rs_bw::ply::Header) -> std::result::Result<&'static str, String> {
    let element = |name: &str, why: &str| {
        header.elements.get(name).ok_or_else(|| {
            let has: Vec<&str> = header.elements.keys().map(String::as_str).collect();
            format!(
                "the PLY header declares no '{name}' element (it has: {}){why}",
                has.join(", ")
            )
        })
    };
    check_ply_vertex(element("vertex", "")?)?;
    ply_face_list(element("face", ": a point cloud has no surface to use")?)
}

/// The properties of `element`, listed for messages.
fn ply_properties(element: &ply_rs_bw::ply::ElementDef) -> String {
    let names: Vec<&str> = element.properties.keys().map(String::as_str).collect();
    names.join(", ")
}

/// A vertex needs numbers `x`, `y` and `z`.
fn check_ply_vertex(vertex: &ply_rs_bw::ply::ElementDef) -> std::result::Result<(), String> {
    use ply_rs_bw::ply::PropertyType;
    for axis in ["x", "y", "z"] {
        match vertex.properties.get(axis).map(|p| &p.data_type) {
            Some(PropertyType::Scalar(_)) => {}
            Some(PropertyType::List(..)) => {
                return Err(format!(
                    "the 'vertex' element's '{axis}' is a list, not a number"
                ));
            }
            None => {
                return Err(format!(
                    "the 'vertex' element has no '{axis}' property (it has: {})",
                    ply_properties(vertex)
                ));
            }
        }
    }
    Ok(())
}

/// The face's list of integer vertex indices: `vertex_indices`, or `vertex_index` as some
/// exporters name it.
fn ply_face_list(face: &ply_rs_bw::ply::ElementDef) -> std::result::Result<&'static str, String> {
    use ply_rs_bw::ply::{PropertyType, ScalarType};
    for name in ["vertex_indices", "vertex_index"] {
        match face.properties.get(name).map(|p| &p.data_type) {
            Some(PropertyType::List(_, ScalarType::Float | ScalarType::Double)) => {
                return Err(format!(
                    "the 'face' element's '{name}' holds floats, not indices"
                ));
            }
            Some(PropertyType::List(..)) => return Ok(name),
            Some(PropertyType::Scalar(_)) => {
                return Err(format!(
                    "the 'face' element's '{name}' is a number, not a list"
                ));
            }
            None => {}
        }
    }
    Err(format!(
        "the 'face' element has no 'vertex_indices' (or 'vertex_index') list (it has: {})",
        ply_properties(face)
    ))
}

/// Positions, and normals when every vertex has a finite one. Unit normals are kept as they
/// are (so a file imprint wrote reads back bit for bit); others are normalised.
fn ply_vertices(vertices: &[PlyElement]) -> (Vec<Vec3>, Option<Vec<Vec3>>) {
    // The header check guarantees x, y, z on every vertex; NaN marks any that the parser
    // did not set, and validation then names it.
    let get = |v: [Option<f32>; 3]| Vec3::from(v.map(|c| c.unwrap_or(f32::NAN)));
    let positions = vertices.iter().map(|v| get(v.xyz)).collect();
    let normals: Vec<Vec3> = vertices.iter().map(|v| get(v.normal)).collect();
    let usable = !normals.is_empty() && normals.iter().all(|n| n.is_finite() && *n != Vec3::ZERO);
    let unit = |n: Vec3| {
        if (n.length_squared() - 1.0).abs() < 1e-6 {
            n
        } else {
            n.normalize()
        }
    };
    (
        positions,
        usable.then(|| normals.into_iter().map(unit).collect()),
    )
}

/// Fan-triangulates every face of three or more corners (faces of one or two are lines and
/// points, skipped).
fn ply_triangles(faces: &[PlyElement], list: &str) -> std::result::Result<Vec<[u32; 3]>, String> {
    let mut triangles = Vec::with_capacity(faces.len());
    for (f, face) in faces.iter().enumerate() {
        if face.negative {
            return Err(format!(
                "face {} has a negative vertex index in '{list}'",
                f + 1
            ));
        }
        let idx = face.indices.as_deref().unwrap_or(&[]);
        for k in 1..idx.len().saturating_sub(1) {
            triangles.push([idx[0], idx[k], idx[k + 1]]);
        }
    }
    Ok(triangles)
}

// ---------------------------------------------------------------------------------------------
// STL

/// Reads an STL file, ASCII or binary (told apart as [`MeshFormat::sniff`] does, not by the
/// `solid` that binary headers may start with), and welds corners at identical positions so
/// the mesh is indexed: STL stores three corners per triangle, and without welding no mesh
/// read from one would be closed. Normals are computed from the welded mesh.
pub fn load_stl(path: &Path) -> Result<Mesh> {
    let mut bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let binary = is_binary_stl(&bytes, bytes.len() as u64);
    // stl_io decides between its readers by a leading "solid ": make its choice ours.
    if binary {
        if bytes.starts_with(b"solid") {
            bytes[..5].copy_from_slice(b"SOLID");
        }
    } else if !trim_start(&bytes).starts_with(b"solid") {
        return Err(Error::mesh(
            path,
            format!(
                "not an STL file: not ASCII (no leading 'solid') and not binary (its {} bytes are \
                 not 84 plus 50 per triangle)",
                bytes.len()
            ),
        ));
    } else {
        bytes = ascii_stl_for_reader(&bytes);
    }
    let kind = if binary { "binary" } else { "ASCII" };
    let mut cursor = std::io::Cursor::new(bytes);
    let reader = stl_io::create_stl_reader(&mut cursor)
        .map_err(|e| Error::mesh(path, format!("not a readable {kind} STL file ({e})")))?;
    let mut weld = Weld::default();
    let mut triangles = Vec::new();
    for (t, tri) in reader.enumerate() {
        let tri = tri.map_err(|e| {
            Error::mesh(
                path,
                format!("{kind} STL, triangle {}: {}", t + 1, one_line(e)),
            )
        })?;
        triangles.push(tri.vertices.map(|v| weld.index(Vec3::from(v.0))));
    }
    let mut mesh = Mesh {
        positions: weld.positions,
        triangles,
        normals: Vec::new(),
        uvs: None,
    };
    validate(&mesh, path)?;
    mesh.compute_normals();
    Ok(mesh)
}

/// ASCII STL text from its first non-blank byte, with a first line that stl_io accepts
/// (`solid NAME`: a bare `solid` is legal but stl_io wants the space).
fn ascii_stl_for_reader(bytes: &[u8]) -> Vec<u8> {
    let text = trim_start(bytes);
    let rest = &text[5..];
    let mut out = b"solid ".to_vec();
    out.extend_from_slice(rest.strip_prefix(b" ").unwrap_or(rest));
    out
}

/// Positions met so far and their indices; -0 and +0 are the same position.
#[derive(Default)]
struct Weld {
    positions: Vec<Vec3>,
    index_of: HashMap<[u32; 3], u32>,
}

impl Weld {
    fn index(&mut self, p: Vec3) -> u32 {
        let p = p + Vec3::ZERO; // -0.0 + 0.0 = +0.0
        let next = self.positions.len() as u32;
        let i = *self
            .index_of
            .entry(p.to_array().map(f32::to_bits))
            .or_insert(next);
        if i == next {
            self.positions.push(p);
        }
        i
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sniff_tells_formats_apart_by_content() {
        assert_eq!(
            MeshFormat::sniff(b"ply\nformat ascii 1.0\n", 30),
            Some(MeshFormat::Ply)
        );
        assert_eq!(
            MeshFormat::sniff(b"ply\r\nformat", 30),
            Some(MeshFormat::Ply)
        );
        assert_eq!(
            MeshFormat::sniff(b"glTF\x02\0\0\0", 100),
            Some(MeshFormat::Glb)
        );
        let ascii = b"solid x\n facet normal 0 0 1\n";
        assert_eq!(
            MeshFormat::sniff(ascii, ascii.len() as u64),
            Some(MeshFormat::Stl)
        );
        // "solid" alone is not enough: no facets, no endsolid.
        assert_eq!(MeshFormat::sniff(b"solid state drive", 17), None);
        let gltf = b"  {\n \"asset\": {\"version\": \"2.0\"}}";
        assert_eq!(MeshFormat::sniff(gltf, 40), Some(MeshFormat::Gltf));
        assert_eq!(MeshFormat::sniff(b"{\"a\": 1}", 8), None);
        let obj = b"# made by hand\nmtllib m.mtl\no cube\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n";
        assert_eq!(
            MeshFormat::sniff(obj, obj.len() as u64),
            Some(MeshFormat::Obj)
        );
        assert_eq!(MeshFormat::sniff(b"# only a comment\n", 17), None);
        assert_eq!(MeshFormat::sniff(b"hello world\nv 0 0 0\n", 20), None);
    }

    #[test]
    fn binary_stl_is_known_by_its_length() {
        let mut b = vec![0u8; 84 + 50 * 2];
        b[..5].copy_from_slice(b"solid");
        b[80..84].copy_from_slice(&2u32.to_le_bytes());
        assert_eq!(MeshFormat::sniff(&b, b.len() as u64), Some(MeshFormat::Stl));
        // One byte more and the count no longer fits: not a binary STL.
        assert_eq!(MeshFormat::sniff(&b, b.len() as u64 + 1), None);
    }

    #[test]
    fn descriptions_name_what_was_found() {
        assert_eq!(describe(b""), "an empty file");
        assert_eq!(describe(b"\x89PNG\r\n\x1a\n"), "a PNG image");
        assert_eq!(describe(b"PK\x03\x04rest"), "a ZIP archive");
        assert_eq!(describe(&[0x00, 0xff, 0x13, 0x80]), "binary data");
        assert!(describe(b"hello\nworld").contains("first line 'hello'"));
    }
}
