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

/// Cloth test pieces shared by the CPU and GPU cloth tests.
pub mod cloth {
    use glam::{UVec3, Vec3};
    use imprint_core::{DistanceField, GridSpec};
    use imprint_stages::cloth::{ClothAssets, ClothParams, ClothSim, Material, Shape};

    /// An exact field of the sphere (c, r) on the box [lo, hi] with cells of `cell`.
    pub fn sphere_field(
        c: Vec3,
        r: f32,
        lo: Vec3,
        hi: Vec3,
        cell: f32,
        band: f32,
    ) -> DistanceField {
        let dims = ((hi - lo) / cell).ceil().as_uvec3() + UVec3::ONE;
        let spec = GridSpec::new(lo, cell, dims).unwrap();
        DistanceField::from_closest_points(spec, band, |p| {
            let d = p - c;
            let l = d.length();
            if l > 0.0 {
                c + r * d / l
            } else {
                c + Vec3::new(r, 0.0, 0.0)
            }
        })
    }

    /// The sphere of the drop tests: radius 0.3 at the origin, 2 cm cells, band 4.
    pub fn sphere_drop_field() -> DistanceField {
        sphere_field(
            Vec3::ZERO,
            0.3,
            Vec3::splat(-0.46),
            Vec3::splat(0.46),
            0.02,
            4.0,
        )
    }

    /// A flat grid cloth.
    pub fn grid(size: [f32; 2], resolution: [u32; 2], center: Vec3, normal: Vec3) -> Shape {
        Shape::Grid {
            size,
            resolution,
            center,
            normal,
        }
    }

    /// Harada's linear springs, no bending.
    pub fn harada(k: f32, shear: f32) -> Material {
        Material::Harada {
            k_structural: k,
            k_shear: shear,
            k_bend: None,
        }
    }

    /// A simulator from in-memory params (no files).
    pub fn sim(params: &ClothParams) -> ClothSim {
        ClothSim::from_assets(params, &ClothAssets::default()).unwrap()
    }
}
