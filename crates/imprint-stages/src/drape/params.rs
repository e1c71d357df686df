//! The Drape node's parameters as a pipeline file states them, their defaults and their
//! validation (every error names the field to change).

use glam::Vec3;
use imprint_core::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Everything the drape stage needs besides the body and the garment. Every field may be left
/// out; the defaults are [`DrapeParams::default`]'s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct DrapeParams {
    /// The directions the views look along (need not be unit length). Each view renders two
    /// orthographic depth maps of the body: one looking along the direction, one against it.
    /// Default T's three: top (0, -1, 0), front (0, 0, -1) and back (0, 0, 1). Note that front
    /// and back look along the same line, so they give the same pair of maps: T's set has two
    /// distinct lines; add e.g. (1, 0, 0) for a third.
    #[schemars(with = "Vec<[f32; 3]>")]
    pub views: Vec<Vec3>,
    /// Side of the square depth maps, pixels. Default 512.
    pub resolution: u32,
    /// How far outside the surface a pushed vertex is put, m (along the push). Default 0.002.
    pub offset: f32,
    /// What to do with the inside vertices no view resolves. Default none (count them only).
    pub fallback: Fallback,
}

/// The second chance for the vertices no view resolves (beyond T).
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Fallback {
    /// Leave them where they are; they are counted in the report.
    #[default]
    None,
    /// Build the body's (unsigned) distance field and push each unresolved vertex along the
    /// field's closest-point vector to the surface, plus `offset`.
    DistanceField {
        /// Cells along the longest side of the body's box. Default 64.
        resolution: u32,
        /// Half-width of the field's band, cells: vertices deeper than this stay unresolved.
        /// Default 8.
        band: f32,
    },
}

impl Fallback {
    /// The distance-field fallback with its default settings.
    pub fn distance_field() -> Self {
        Fallback::DistanceField {
            resolution: 64,
            band: 8.0,
        }
    }
}

/// Smallest depth map side worth rendering.
pub const MIN_RESOLUTION: u32 = 16;
/// More views than this is a typo (each is two depth maps per call).
pub const MAX_VIEWS: usize = 64;
/// Field resolutions outside this range are a typo (the grid is resolution³ cells at most).
pub const FIELD_RESOLUTION: std::ops::RangeInclusive<u32> = 8..=1024;

impl Default for DrapeParams {
    fn default() -> Self {
        DrapeParams {
            views: vec![Vec3::NEG_Y, Vec3::NEG_Z, Vec3::Z],
            resolution: 512,
            offset: 0.002,
            fallback: Fallback::None,
        }
    }
}

impl DrapeParams {
    /// The unit view directions (assumes valid `views`).
    pub fn directions(&self) -> Vec<Vec3> {
        self.views.iter().map(|v| v.normalize()).collect()
    }

    /// Checks every number before anything is allocated; errors name the field.
    pub fn validate(&self) -> Result<()> {
        validate_views(&self.views, "drape")?;
        validate_resolution(self.resolution, "drape")?;
        if !(self.offset.is_finite() && self.offset >= 0.0) {
            return Err(invalid(format!(
                "offset = {}: must be a finite number >= 0 (m)",
                self.offset
            )));
        }
        if let Fallback::DistanceField { resolution, band } = self.fallback {
            if !FIELD_RESOLUTION.contains(&resolution) {
                return Err(invalid(format!(
                    "fallback.resolution = {resolution}: must be between {} and {} cells",
                    FIELD_RESOLUTION.start(),
                    FIELD_RESOLUTION.end()
                )));
            }
            if !(band.is_finite() && band > 0.0) {
                return Err(invalid(format!(
                    "fallback.band = {band}: must be a finite number of cells > 0"
                )));
            }
        }
        Ok(())
    }
}

fn invalid(message: String) -> Error {
    Error::Invalid(format!("drape: {message}"))
}

/// Checks a list of view directions (`what` names the stage in the message).
pub(crate) fn validate_views(views: &[Vec3], what: &str) -> Result<()> {
    if views.is_empty() || views.len() > MAX_VIEWS {
        return Err(Error::Invalid(format!(
            "{what}: views: {} given, must be between 1 and {MAX_VIEWS} directions",
            views.len()
        )));
    }
    for (i, v) in views.iter().enumerate() {
        if !v.is_finite() || v.length_squared() < 1e-12 {
            return Err(Error::Invalid(format!(
                "{what}: views[{i}] = {v}: must be a finite, non-zero vector (the way the view looks)"
            )));
        }
    }
    Ok(())
}

/// Checks a depth map side (`what` names the stage in the message).
pub(crate) fn validate_resolution(resolution: u32, what: &str) -> Result<()> {
    let max = imprint_core::raster::MAX_SIZE;
    if !(MIN_RESOLUTION..=max).contains(&resolution) {
        return Err(Error::Invalid(format!(
            "{what}: resolution = {resolution}: must be between {MIN_RESOLUTION} and {max} pixels"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_errors_name_the_field() {
        DrapeParams::default().validate().unwrap();
        let bad = |p: DrapeParams, field: &str| {
            let e = p.validate().unwrap_err().to_string();
            assert!(e.contains(field), "{e} does not name {field}");
        };
        bad(
            DrapeParams {
                views: vec![],
                ..Default::default()
            },
            "views",
        );
        bad(
            DrapeParams {
                views: vec![Vec3::Y, Vec3::ZERO],
                ..Default::default()
            },
            "views[1]",
        );
        bad(
            DrapeParams {
                resolution: 4,
                ..Default::default()
            },
            "resolution",
        );
        bad(
            DrapeParams {
                offset: -1.0,
                ..Default::default()
            },
            "offset",
        );
        bad(
            DrapeParams {
                fallback: Fallback::DistanceField {
                    resolution: 64,
                    band: 0.0,
                },
                ..Default::default()
            },
            "fallback.band",
        );
        bad(
            DrapeParams {
                fallback: Fallback::DistanceField {
                    resolution: 2,
                    band: 4.0,
                },
                ..Default::default()
            },
            "fallback.resolution",
        );
    }

    #[test]
    fn ron_fills_defaults_and_rejects_unknown_fields() {
        let p: DrapeParams = ron::from_str("()").unwrap();
        assert_eq!(p, DrapeParams::default());
        let p: DrapeParams = ron::from_str(
            "(views: [(1, 0, 0)], offset: 0.01, fallback: DistanceField(resolution: 32, band: 4))",
        )
        .unwrap();
        assert_eq!(p.views, vec![Vec3::X]);
        assert_eq!(
            p.fallback,
            Fallback::DistanceField {
                resolution: 32,
                band: 4.0
            }
        );
        p.validate().unwrap();
        assert!(ron::from_str::<DrapeParams>("(offset: 0.1, depth: 2)").is_err());
    }
}
