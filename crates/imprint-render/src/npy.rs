//! NumPy `.npy` files (format version 1.0), so fields open with `numpy.load` and nothing else.
//!
//! The format (numpy/lib/format.py, "NEP 1"):
//!
//! ```text
//! "\x93NUMPY"  major=1 minor=0  header_len: u16 LE  header: ASCII dict  data
//! ```
//!
//! The header is a Python dict literal, `{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }`,
//! padded with spaces and ended by `\n` so that the data starts at a multiple of 64 bytes
//! (aligned reads, memory mapping). Data is little-endian, C order (last index fastest).
//! Writers go through [`atomic_write`], so a reader never sees a half-written array.

use imprint_core::io::atomic_write;
use imprint_core::{Error, Result};
use std::path::Path;

/// The file's magic string: `\x93NUMPY`.
pub const MAGIC: &[u8; 6] = b"\x93NUMPY";
/// The data of a file we write starts at a multiple of this many bytes.
pub const ALIGN: usize = 64;

/// A scalar type `.npy` can store, with its NumPy type string.
pub trait NpyElement: Copy {
    /// NumPy's `descr`: byte order, kind, size (`<f4`).
    const DESCR: &'static str;
    const SIZE: usize;
    fn write_le(self, out: &mut Vec<u8>);
    fn read_le(bytes: &[u8]) -> Self;
}

impl NpyElement for f32 {
    const DESCR: &'static str = "<f4";
    const SIZE: usize = 4;
    fn write_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn read_le(b: &[u8]) -> Self {
        f32::from_le_bytes([b[0], b[1], b[2], b[3]])
    }
}

impl NpyElement for u16 {
    const DESCR: &'static str = "<u2";
    const SIZE: usize = 2;
    fn write_le(self, out: &mut Vec<u8>) {
        out.extend_from_slice(&self.to_le_bytes());
    }
    fn read_le(b: &[u8]) -> Self {
        u16::from_le_bytes([b[0], b[1]])
    }
}

impl NpyElement for u8 {
    // One byte has no order: NumPy writes `|u1`.
    const DESCR: &'static str = "|u1";
    const SIZE: usize = 1;
    fn write_le(self, out: &mut Vec<u8>) {
        out.push(self);
    }
    fn read_le(b: &[u8]) -> Self {
        b[0]
    }
}

/// The magic, version and padded header dict for an array of `shape` (everything before the data).
pub fn header_bytes(descr: &str, shape: &[usize]) -> Vec<u8> {
    // Python tuple syntax: `()`, `(5,)`, `(2, 3)`.
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut dict =
        format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape_text}, }}");
    // 6 magic + 2 version + 2 length bytes precede the dict; pad it so the total, with the
    // final newline, is a multiple of ALIGN.
    let unpadded = MAGIC.len() + 2 + 2 + dict.len() + 1;
    let pad = (ALIGN - unpadded % ALIGN) % ALIGN;
    dict.extend(std::iter::repeat_n(' ', pad));
    dict.push('\n');

    let mut out = Vec::with_capacity(10 + dict.len());
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&[1, 0]);
    // A version 1.0 header length is a u16; even a 32-axis shape stays far below that.
    out.extend_from_slice(&(dict.len() as u16).to_le_bytes());
    out.extend_from_slice(dict.as_bytes());
    out
}

/// Writes `data` as an array of `shape` (C order). The shape's product must equal `data.len()`.
pub fn write_npy<T: NpyElement>(path: &Path, shape: &[usize], data: &[T]) -> Result<()> {
    let count = shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| Error::Invalid(format!("{}: shape {shape:?} overflows", path.display())))?;
    if count != data.len() {
        return Err(Error::Invalid(format!(
            "{}: shape {shape:?} holds {count} values but {} were given",
            path.display(),
            data.len()
        )));
    }
    let header = header_bytes(T::DESCR, shape);
    atomic_write(path, |w| {
        w.write_all(&header)?;
        // Convert in chunks: no second full-size copy of a large field in memory.
        let mut buf = Vec::with_capacity(16384 * T::SIZE);
        for chunk in data.chunks(16384) {
            buf.clear();
            for &v in chunk {
                v.write_le(&mut buf);
            }
            w.write_all(&buf)?;
        }
        Ok(())
    })
}

/// Writes a little-endian `<f4` array.
pub fn write_npy_f32(path: &Path, shape: &[usize], data: &[f32]) -> Result<()> {
    write_npy(path, shape, data)
}

/// Writes a little-endian `<u2` array.
pub fn write_npy_u16(path: &Path, shape: &[usize], data: &[u16]) -> Result<()> {
    write_npy(path, shape, data)
}

/// Writes a `|u1` array.
pub fn write_npy_u8(path: &Path, shape: &[usize], data: &[u8]) -> Result<()> {
    write_npy(path, shape, data)
}

/// Reads an array written by [`write_npy`] (or NumPy, versions 1-3, C order, element type `T`).
pub fn read_npy<T: NpyElement>(path: &Path) -> Result<(Vec<usize>, Vec<T>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |why: &str| {
        Error::Invalid(format!(
            "{}: not a readable .npy file: {why}",
            path.display()
        ))
    };
    if bytes.len() < 10 || &bytes[..6] != MAGIC {
        return Err(bad("no \\x93NUMPY magic"));
    }
    let (header_len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(bad(&format!("unknown format version {v}"))),
    };
    let data_start = start + header_len;
    let header = bytes
        .get(start..data_start)
        .and_then(|h| std::str::from_utf8(h).ok())
        .ok_or_else(|| bad("truncated or non-text header"))?;

    let descr = dict_value(header, "descr").ok_or_else(|| bad("no 'descr'"))?;
    if descr.trim_matches(['\'', '"']) != T::DESCR {
        return Err(bad(&format!(
            "element type {descr}, expected '{}'",
            T::DESCR
        )));
    }
    let fortran = dict_value(header, "fortran_order").ok_or_else(|| bad("no 'fortran_order'"))?;
    if fortran != "False" {
        return Err(bad("Fortran-ordered arrays are not supported"));
    }
    let shape_text = dict_value(header, "shape").ok_or_else(|| bad("no 'shape'"))?;
    let shape = shape_text
        .trim_matches(['(', ')'])
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(|s| s.parse::<usize>())
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|_| bad(&format!("bad shape {shape_text}")))?;

    let count = shape
        .iter()
        .try_fold(1usize, |n, &d| n.checked_mul(d))
        .ok_or_else(|| bad(&format!("shape {shape:?} overflows")))?;
    let data = &bytes[data_start..];
    if data.len() != count * T::SIZE {
        return Err(bad(&format!(
            "shape {shape:?} needs {} data bytes, file has {}",
            count * T::SIZE,
            data.len()
        )));
    }
    let values = data.chunks_exact(T::SIZE).map(T::read_le).collect();
    Ok((shape, values))
}

/// Reads a `<f4` array: its shape and values in C order.
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>)> {
    read_npy(path)
}

/// The text of `'key': value` in the header dict, up to the next top-level comma.
fn dict_value<'a>(header: &'a str, key: &str) -> Option<&'a str> {
    let at = header
        .find(&format!("'{key}'"))
        .or_else(|| header.find(&format!("\"{key}\"")))?;
    let rest = header[at + key.len() + 2..]
        .trim_start()
        .strip_prefix(':')?
        .trim_start();
    // A tuple runs to its closing parenthesis; anything else to the next comma.
    let end = if rest.starts_with('(') {
        rest.find(')')? + 1
    } else {
        rest.find([',', '}'])?
    };
    Some(rest[..end].trim())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_keeps_shape_and_values_exactly() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("a.npy");
        // Values that a lossy or byte-swapped writer would change.
        let data: Vec<f32> = (0..24)
            .map(|i| (i as f32 - 11.5) * std::f32::consts::PI * 1e-3)
            .chain([f32::MIN_POSITIVE, -0.0, f32::MAX, 1.0e-40])
            .collect();
        let shape = [2, 2, 7];
        write_npy_f32(&path, &shape, &data).unwrap();
        let (s, d) = read_npy_f32(&path).unwrap();
        assert_eq!(s, shape);
        assert_eq!(d.len(), data.len());
        for (a, b) in d.iter().zip(&data) {
            assert_eq!(a.to_bits(), b.to_bits());
        }
    }

    #[test]
    fn header_follows_the_spec() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("h.npy");
        write_npy_f32(&path, &[3, 4, 5], &[1.5; 60]).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(&bytes[..6], b"\x93NUMPY");
        assert_eq!(&bytes[6..8], &[1, 0], "version 1.0");
        let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
        let data_start = 10 + header_len;
        assert_eq!(data_start % 64, 0, "data must start on a 64-byte boundary");
        let header = std::str::from_utf8(&bytes[10..data_start]).unwrap();
        assert!(
            header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (3, 4, 5), }"),
            "{header:?}"
        );
        assert!(header.ends_with('\n'));
        assert_eq!(bytes.len(), data_start + 60 * 4);
        assert_eq!(&bytes[data_start..data_start + 4], &1.5f32.to_le_bytes());
    }

    #[test]
    fn one_and_zero_dimensional_shapes_use_python_tuples() {
        let h1 = header_bytes("<f4", &[5]);
        let h0 = header_bytes("<f4", &[]);
        assert!(String::from_utf8_lossy(&h1).contains("'shape': (5,), }"));
        assert!(String::from_utf8_lossy(&h0).contains("'shape': (), }"));
        assert_eq!(h1.len() % 64, 0);
        assert_eq!(h0.len() % 64, 0);
    }

    #[test]
    fn integer_arrays_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p16 = dir.path().join("u16.npy");
        let p8 = dir.path().join("u8.npy");
        let v16: Vec<u16> = vec![0, 1, 258, u16::MAX];
        let v8: Vec<u8> = vec![0, 7, 255];
        write_npy_u16(&p16, &[2, 2], &v16).unwrap();
        write_npy_u8(&p8, &[3], &v8).unwrap();
        assert_eq!(read_npy::<u16>(&p16).unwrap(), (vec![2, 2], v16));
        assert_eq!(read_npy::<u8>(&p8).unwrap(), (vec![3], v8));
        // The element type is checked on reading.
        assert!(read_npy_f32(&p16).is_err());
    }

    #[test]
    fn wrong_length_is_refused_and_nothing_is_written() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.npy");
        let e = write_npy_f32(&path, &[2, 3], &[0.0; 5]).unwrap_err();
        assert!(matches!(e, Error::Invalid(_)), "{e}");
        assert!(e.to_string().contains("[2, 3]"), "{e}");
        assert!(!path.exists());
    }
}
