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
