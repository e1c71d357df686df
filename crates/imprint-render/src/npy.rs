//! NumPy `.npy` files, so fields open with `numpy.load` and nothing else; the format is read
//! and written by the `npyz` crate.
//!
//! Arrays are written little-endian (`<f4`, `<u2`, `|u1`), C order (last index fastest), with
//! the header padded so that the data starts at a multiple of 64 bytes, as NumPy does. Writers
//! go through [`atomic_write`], so a reader never sees a half-written array.

use imprint_core::io::atomic_write;
use imprint_core::{Error, Result};
use npyz::WriterBuilder;
use std::path::Path;

/// A scalar type imprint stores in `.npy` files, with the NumPy type string it is written as.
pub trait NpyElement: npyz::Serialize + npyz::Deserialize + Copy {
    /// NumPy's `descr`: byte order, kind, size (`<f4`).
    const DESCR: &'static str;
}

impl NpyElement for f32 {
    const DESCR: &'static str = "<f4";
}

impl NpyElement for u16 {
    const DESCR: &'static str = "<u2";
}

impl NpyElement for u8 {
    // One byte has no order: NumPy writes `|u1`.
    const DESCR: &'static str = "|u1";
}

fn dtype<T: NpyElement>() -> npyz::DType {
    npyz::DType::Plain(T::DESCR.parse().expect("a valid NumPy type string"))
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
    let shape: Vec<u64> = shape.iter().map(|&d| d as u64).collect();
    atomic_write(path, |w| {
        let mut w = std::io::BufWriter::new(w);
        let mut npy = npyz::WriteOptions::new()
            .dtype(dtype::<T>())
            .shape(&shape)
            .writer(&mut w)
            .begin_nd()?;
        npy.extend(data.iter().copied())?;
        npy.finish()?;
        w.into_inner().map_err(|e| e.into_error())?.flush()
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

/// Reads an array written by [`write_npy`] (or NumPy, C order, element type `T`): its shape
/// and its values in C order.
pub fn read_npy<T: NpyElement>(path: &Path) -> Result<(Vec<usize>, Vec<T>)> {
    let bad = |why: String| {
        Error::Invalid(format!(
            "{}: not a readable .npy file: {why}",
            path.display()
        ))
    };
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let npy = npyz::NpyFile::new(std::io::BufReader::new(file)).map_err(|e| bad(e.to_string()))?;
    if npy.dtype() != dtype::<T>() {
        return Err(bad(format!(
            "element type {}, expected '{}'",
            npy.dtype().descr(),
            T::DESCR
        )));
    }
    if npy.order() != npyz::Order::C {
        return Err(bad("Fortran-ordered arrays are not supported".into()));
    }
    let shape = npy
        .shape()
        .iter()
        .map(|&d| usize::try_from(d))
        .collect::<std::result::Result<Vec<_>, _>>()
        .map_err(|_| bad(format!("shape {:?} is too large", npy.shape())))?;
    let values = npy.into_vec::<T>().map_err(|e| bad(e.to_string()))?;
    Ok((shape, values))
}

/// Reads a `<f4` array: its shape and values in C order.
pub fn read_npy_f32(path: &Path) -> Result<(Vec<usize>, Vec<f32>)> {
    read_npy(path)
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
    fn written_file_reads_back_with_npyz_itself() {
        // Independent of `read_npy`: npyz's own reader sees the dtype, shape, order and values.
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("n.npy");
        let data: Vec<f32> = (0..30).map(|i| i as f32 * 0.25 - 3.0).collect();
        write_npy_f32(&path, &[2, 3, 5], &data).unwrap();
        let npy = npyz::NpyFile::new(std::fs::File::open(&path).unwrap()).unwrap();
        assert_eq!(npy.shape(), &[2, 3, 5]);
        assert_eq!(npy.order(), npyz::Order::C);
        assert_eq!(npy.dtype().descr(), "'<f4'");
        assert_eq!(npy.into_vec::<f32>().unwrap(), data);
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
        // The dict as NumPy parses it (npyz writes a trailing comma in the shape tuple).
        let compact: String = header.chars().filter(|c| !c.is_whitespace()).collect();
        assert!(
            compact.starts_with("{'descr':'<f4','fortran_order':False,'shape':(3,4,5"),
            "{header:?}"
        );
        assert!(header.ends_with('\n'));
        assert_eq!(bytes.len(), data_start + 60 * 4);
        assert_eq!(&bytes[data_start..data_start + 4], &1.5f32.to_le_bytes());
    }

    #[test]
    fn one_and_zero_dimensional_shapes_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let p1 = dir.path().join("one.npy");
        let p0 = dir.path().join("zero.npy");
        write_npy_f32(&p1, &[5], &[1.0, 2.0, 3.0, 4.0, 5.0]).unwrap();
        write_npy_f32(&p0, &[], &[7.0]).unwrap();
        assert_eq!(
            read_npy_f32(&p1).unwrap(),
            (vec![5], vec![1.0, 2.0, 3.0, 4.0, 5.0])
        );
        assert_eq!(read_npy_f32(&p0).unwrap(), (vec![], vec![7.0]));
        for p in [p1, p0] {
            let bytes = std::fs::read(p).unwrap();
            let header_len = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
            assert_eq!((10 + header_len) % 64, 0);
        }
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
        let b16 = std::fs::read(&p16).unwrap();
        assert!(String::from_utf8_lossy(&b16).contains("'descr': '<u2'"));
        let b8 = std::fs::read(&p8).unwrap();
        assert!(String::from_utf8_lossy(&b8).contains("'descr': '|u1'"));
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
