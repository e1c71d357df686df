//! A distance field on disk, for NumPy and for people: per frame, three files
//!
//! - `<name>_<frame:04>_dist.npy`: `<f4`, shape `[nz, ny, nx]`, distance in world units
//!   (far cells hold the `far` value of the JSON);
//! - `<name>_<frame:04>_vec.npy`: `<f4`, shape `[nz, ny, nx, 3]`, the closest-point vector
//!   (x, y, z) from the cell centre toward the nearest boundary point, zero in far cells;
//! - `<name>_<frame:04>_field.json`: the grid and band ([`FieldMeta`]).
//!
//! The grid stores x fastest, so `[nz, ny, nx]` is the data as it lies in memory: a reader
//! indexes `dist[k, j, i]` for cell (i, j, k) with no transposition. The JSON is written last,
//! so a reader that finds it finds both arrays complete.

use crate::npy::write_npy_f32;
use imprint_core::io::atomic_write;
use imprint_core::{DistanceField, Error, Result};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The index-order sentence written into every `_field.json`.
pub const LAYOUT: &str = "dist[k, j, i] (shape [nz, ny, nx], x fastest) is cell (i, j, k), \
centred at origin + (i, j, k) * cell_size; vec[k, j, i, :] is (x, y, z) from that centre to \
its nearest boundary point; far cells: dist = far, vec = 0";

/// The `_field.json` beside each pair of arrays.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FieldMeta {
    /// The name the files were written under.
    pub name: String,
    pub frame: u32,
    /// Centre of cell (0, 0, 0), world units.
    pub origin: [f32; 3],
    /// Edge of a cubic cell, world units.
    pub cell_size: f32,
    /// Cells along x, y, z (the arrays' shape is the reverse).
    pub dims: [u32; 3],
    /// Half-width of the band, in cells.
    pub band: f32,
    /// The distance stored in far cells, world units (band * cell_size).
    pub far: f32,
    pub layout: String,
    /// Number of boundary points the field was built from.
    pub boundary_points: usize,
    /// Number of cells inside the band.
    pub band_cells: usize,
    /// File names (in the same folder) of the two arrays.
    pub dist_file: String,
    pub vec_file: String,
}

/// Refuses a field whose arrays disagree with its grid, before anything indexes them.
pub fn check_field(field: &DistanceField) -> Result<()> {
    let n = field.spec.len();
    if field.dist.len() != n || field.nearest.len() != n {
        return Err(Error::Invalid(format!(
            "distance field arrays ({} distances, {} nearest) do not match its {}x{}x{} grid",
            field.dist.len(),
            field.nearest.len(),
            field.spec.dims.x,
            field.spec.dims.y,
            field.spec.dims.z
        )));
    }
    if !(field.band.is_finite() && field.band > 0.0) {
        return Err(Error::Invalid(format!(
            "distance field band {} must be a positive number of cells",
            field.band
        )));
    }
    let points = field.points.len();
    if let Some(bad) = field
        .nearest
        .iter()
        .find(|&&p| p != DistanceField::FAR && p as usize >= points)
    {
        return Err(Error::Invalid(format!(
            "distance field names boundary point {bad} but has only {points}"
        )));
    }
    Ok(())
}

/// The three file names of `name` at `frame`: dist, vec, json.
pub fn field_file_names(name: &str, frame: u32) -> [String; 3] {
    ["dist.npy", "vec.npy", "field.json"].map(|suffix| format!("{name}_{frame:04}_{suffix}"))
}

/// Writes `field` as `dir/<name>_<frame:04>_{dist.npy, vec.npy, field.json}` and returns the
/// three paths in that order. `name` must be a plain file-name stem (no separators).
pub fn write_field(
    dir: &Path,
    name: &str,
    frame: u32,
    field: &DistanceField,
) -> Result<Vec<PathBuf>> {
    if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
        return Err(Error::Invalid(format!(
            "field name {name:?} must be a non-empty file name without path separators"
        )));
    }
    check_field(field)?;
    let spec = &field.spec;
    let shape = [
        spec.dims.z as usize,
        spec.dims.y as usize,
        spec.dims.x as usize,
    ];
    let [dist_name, vec_name, json_name] = field_file_names(name, frame);
    let paths: Vec<PathBuf> = [&dist_name, &vec_name, &json_name]
        .iter()
        .map(|f| dir.join(f))
        .collect();

    write_npy_f32(&paths[0], &shape, &field.dist)?;

    let vectors: Vec<f32> = (0..spec.len())
        .flat_map(|i| field.vector(i).to_array())
        .collect();
    write_npy_f32(&paths[1], &[shape[0], shape[1], shape[2], 3], &vectors)?;

    let meta = FieldMeta {
        name: name.to_string(),
        frame,
        origin: spec.origin.to_array(),
        cell_size: spec.cell,
        dims: spec.dims.to_array(),
        band: field.band,
        far: field.far_value(),
        layout: LAYOUT.to_string(),
        boundary_points: field.points.len(),
        band_cells: field.band_cells(),
        dist_file: dist_name,
        vec_file: vec_name,
    };
    atomic_write(&paths[2], |w| {
        serde_json::to_writer_pretty(&mut *w, &meta)?;
        w.write_all(b"\n")
    })?;
    Ok(paths)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::npy::read_npy_f32;
    use imprint_core::GridSpec;
    use imprint_core::glam::{UVec3, Vec3};

    /// A field on a 5x4x3 grid: distance to the plane x = 1.3, band 2 cells of 0.5.
    fn plane_field() -> DistanceField {
        let spec = GridSpec::new(Vec3::new(0.25, -1.0, 2.0), 0.5, UVec3::new(5, 4, 3)).unwrap();
        let band = 2.0;
        let plane_x = 1.3;
        DistanceField::from_closest_points(spec, band, |c| Vec3::new(plane_x, c.y, c.z))
    }

    #[test]
    fn files_parse_back_with_the_right_layout() {
        let dir = tempfile::tempdir().unwrap();
        let field = plane_field();
        let paths = write_field(dir.path(), "body", 12, &field).unwrap();
        let names: Vec<String> = paths
            .iter()
            .map(|p| p.file_name().unwrap().to_string_lossy().into())
            .collect();
        assert_eq!(
            names,
            [
                "body_0012_dist.npy",
                "body_0012_vec.npy",
                "body_0012_field.json"
            ]
        );

        let (shape, dist) = read_npy_f32(&paths[0]).unwrap();
        assert_eq!(shape, [3, 4, 5], "[nz, ny, nx]");
        // C order over [nz, ny, nx] is the grid's own index.
        assert_eq!(dist, field.dist);

        let (vshape, vec) = read_npy_f32(&paths[1]).unwrap();
        assert_eq!(vshape, [3, 4, 5, 3]);
        // A chosen in-band cell (i, j, k) = (1, 2, 1) and a far one (0, 0, 2), x = 0.25 being 1.05 from the plane.
        for c in [
            UVec3::new(1, 2, 1),
            UVec3::new(0, 0, 2),
            UVec3::new(3, 3, 0),
        ] {
            let index = field.spec.index(c);
            let at = ((c.z as usize * 4 + c.y as usize) * 5 + c.x as usize) * 3;
            assert_eq!(
                Vec3::from_slice(&vec[at..at + 3]),
                field.vector(index),
                "cell {c}"
            );
        }
        let far = field.spec.index(UVec3::new(0, 0, 2));
        assert!(field.is_far(far));
        assert_eq!(&vec[far * 3..far * 3 + 3], &[0.0; 3]);
        let near = field.spec.index(UVec3::new(1, 2, 1));
        assert!(!field.is_far(near));
        // Cell x = 0.75 is 0.55 from the plane: the vector points +x by that much.
        assert!((vec[near * 3] - 0.55).abs() < 1e-6 && vec[near * 3 + 1] == 0.0);
    }

    #[test]
    fn json_holds_grid_band_and_counts() {
        let dir = tempfile::tempdir().unwrap();
        let field = plane_field();
        let paths = write_field(dir.path(), "body", 3, &field).unwrap();
        let text = std::fs::read_to_string(&paths[2]).unwrap();
        let meta: FieldMeta = serde_json::from_str(&text).unwrap();
        assert_eq!(meta.origin, [0.25, -1.0, 2.0]);
        assert_eq!(meta.cell_size, 0.5);
        assert_eq!(meta.dims, [5, 4, 3]);
        assert_eq!(meta.band, 2.0);
        assert_eq!(meta.far, 1.0);
        assert_eq!(meta.frame, 3);
        assert_eq!(meta.boundary_points, field.points.len());
        assert_eq!(meta.band_cells, field.band_cells());
        // x = 0.25..2.25 in steps of 0.5; |x - 1.3| <= 1 for x = 0.75, 1.25, 1.75, 2.25.
        assert_eq!(meta.band_cells, 4 * 4 * 3);
        assert_eq!(meta.dist_file, "body_0003_dist.npy");
        assert!(!meta.layout.contains('\n'));
        // The raw keys a non-Rust reader uses.
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        for key in [
            "origin",
            "cell_size",
            "dims",
            "band",
            "far",
            "frame",
            "layout",
            "boundary_points",
            "band_cells",
        ] {
            assert!(v.get(key).is_some(), "missing {key}");
        }
    }

    #[test]
    fn bad_names_and_inconsistent_fields_are_refused() {
        let dir = tempfile::tempdir().unwrap();
        let field = plane_field();
        for name in ["", "a/b", "..", "x\\y"] {
            assert!(matches!(
                write_field(dir.path(), name, 0, &field),
                Err(Error::Invalid(_))
            ));
        }
        let mut short = field.clone();
        short.dist.pop();
        assert!(matches!(
            write_field(dir.path(), "s", 0, &short),
            Err(Error::Invalid(_))
        ));
        let mut dangling = field;
        dangling.nearest[0] = 10_000;
        let e = write_field(dir.path(), "d", 0, &dangling).unwrap_err();
        assert!(e.to_string().contains("10000"), "{e}");
        assert_eq!(
            std::fs::read_dir(dir.path()).unwrap().count(),
            0,
            "nothing written"
        );
    }
}
