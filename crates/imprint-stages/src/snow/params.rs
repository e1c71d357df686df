//! The Snow node's parameters as a pipeline file states them, their defaults and their
//! validation (every error names the field to change).

use glam::Vec3;
use imprint_core::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Everything the snow stage needs besides the scene (the meshes and the ground of the frame).
/// Every field may be left out; the defaults are [`SnowParams::default`]'s.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(default, deny_unknown_fields)]
pub struct SnowParams {
    /// The way snow moves (need not be unit length); default straight down, (0, -1, 0). The
    /// cos φ factor of the deposit is taken against this direction.
    #[schemars(with = "[f32; 3]")]
    pub direction: Vec3,
    /// K, the number of fall directions (depth maps) per step: the arrival probability of a
    /// point is the fraction of them that reach it, so it comes in steps of 1/K. Default 16.
    pub directions: u32,
    /// Angle, degrees, between `direction` and each of the K jittered directions: they lie on
    /// the surface of this cone, evenly spread in azimuth (T's "irregular fall"; see
    /// [`super::arrival::fall_directions`]). 0 = every direction is `direction` (one depth map
    /// is rendered whatever K). Default 10.
    pub jitter_degrees: f32,
    /// Turns the ring of jittered directions about `direction`, so that two seeds give two
    /// different (but each reproducible) sets of directions. Default 0.
    pub seed: u64,
    /// Side of the square depth maps, pixels. A texel must be small against the gaps snow
    /// should fall through and the overhangs it should not. Default 512.
    pub resolution: u32,
    /// Constant part of the depth bias, in texels: how far behind the first surface a point
    /// may lie and still count as that surface (the shadow-map "acne" guard). A slope term of
    /// one texel per unit of tan(angle to the fall) is always added. Default 1.
    pub bias_texels: f32,
    /// Snow depth gained per second on open ground facing the fall (flat ground for vertical
    /// fall), m/s. Scenes run at animation speed, so the default is a fast snowfall: 0.01.
    pub rate: f32,
    /// Angle of repose, degrees: snow on the ground steeper than this slides to lower cells.
    /// 90 turns the stabilisation off. Dry fresh snow stands at roughly 30-50°; default 38.
    pub repose_degrees: f32,
    /// Stabilisation passes per step (each moves snow one stencil step at most). A pass that
    /// moves nothing ends the step's stabilisation early. Default 16.
    pub relax_passes: u32,
    /// Meshes: the displaced mesh moves each vertex along its normal by `displacement` times
    /// its snow depth (1 = the true depth, the default; 0 = the mesh as it is).
    pub displacement: f32,
}

/// More directions than this is a typo (each one is a depth map per step).
pub const MAX_DIRECTIONS: u32 = 1024;
/// Jitter cones wider than this tip directions toward the horizontal, where a depth map of the
/// scene is mostly sides.
pub const MAX_JITTER_DEGREES: f32 = 60.0;
/// Smallest depth map side worth rendering.
pub const MIN_RESOLUTION: u32 = 16;
/// More stabilisation passes per step than this is a typo, not an intent.
pub const MAX_RELAX_PASSES: u32 = 1_000_000;

impl Default for SnowParams {
    fn default() -> Self {
        SnowParams {
            direction: Vec3::NEG_Y,
            directions: 16,
            jitter_degrees: 10.0,
            seed: 0,
            resolution: 512,
            bias_texels: 1.0,
            rate: 0.01,
            repose_degrees: 38.0,
            relax_passes: 16,
            displacement: 1.0,
        }
    }
}

impl SnowParams {
    /// The unit fall direction (assumes a valid `direction`).
    pub fn fall(&self) -> Vec3 {
        self.direction.normalize()
    }

    /// tan of the angle of repose; `None` at 90° (no stabilisation).
    pub fn tan_repose(&self) -> Option<f32> {
        (self.repose_degrees < 90.0).then(|| self.repose_degrees.to_radians().tan())
    }

    /// Checks every number before anything is allocated; errors name the field.
    pub fn validate(&self) -> Result<()> {
        if !self.direction.is_finite() || self.direction.length_squared() < 1e-12 {
            return Err(invalid(format!(
                "direction = {}: must be a finite, non-zero vector (the way snow moves)",
                self.direction
            )));
        }
        if self.directions == 0 || self.directions > MAX_DIRECTIONS {
            return Err(invalid(format!(
                "directions = {}: must be between 1 and {MAX_DIRECTIONS}",
                self.directions
            )));
        }
        let j = self.jitter_degrees;
        if !(j.is_finite() && (0.0..=MAX_JITTER_DEGREES).contains(&j)) {
            return Err(invalid(format!(
                "jitter_degrees = {j}: must be in [0, {MAX_JITTER_DEGREES}]"
            )));
        }
        let max = imprint_core::raster::MAX_SIZE;
        if !(MIN_RESOLUTION..=max).contains(&self.resolution) {
            return Err(invalid(format!(
                "resolution = {}: must be between {MIN_RESOLUTION} and {max} pixels",
                self.resolution
            )));
        }
        for (field, v) in [("bias_texels", self.bias_texels), ("rate", self.rate)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(invalid(format!(
                    "{field} = {v}: must be a finite number >= 0"
                )));
            }
        }
        let r = self.repose_degrees;
        if !(r.is_finite() && r > 0.0 && r <= 90.0) {
            return Err(invalid(format!(
                "repose_degrees = {r}: must be in (0, 90] (90 turns stabilisation off)"
            )));
        }
        if self.relax_passes > MAX_RELAX_PASSES {
            return Err(invalid(format!(
                "relax_passes = {}: must be at most {MAX_RELAX_PASSES}",
                self.relax_passes
            )));
        }
        if !self.displacement.is_finite() {
            return Err(invalid(format!(
                "displacement = {} is not finite",
                self.displacement
            )));
        }
        Ok(())
    }
}

fn invalid(message: String) -> Error {
    Error::Invalid(format!("snow: {message}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid_and_read_from_an_empty_struct() {
        SnowParams::default().validate().unwrap();
        let p: SnowParams = ron::from_str("()").unwrap();
        assert_eq!(p, SnowParams::default());
        let p: SnowParams =
            ron::from_str("(directions: 4, jitter_degrees: 0, direction: (1, -2, 0))").unwrap();
        assert_eq!(p.directions, 4);
        assert!((p.fall() - Vec3::new(1.0, -2.0, 0.0).normalize()).length() < 1e-7);
    }

    #[test]
    fn unknown_fields_are_refused() {
        assert!(ron::from_str::<SnowParams>("(rate: 0.1, depth: 2)").is_err());
    }

    /// Breaks one field of the parameters.
    type Break = fn(&mut SnowParams);

    #[test]
    fn errors_name_the_field() {
        let cases: [(&str, Break); 9] = [
            ("direction", |p| p.direction = Vec3::ZERO),
            ("directions", |p| p.directions = 0),
            ("jitter_degrees", |p| p.jitter_degrees = 75.0),
            ("resolution", |p| p.resolution = 4),
            ("bias_texels", |p| p.bias_texels = -1.0),
            ("rate", |p| p.rate = f32::NAN),
            ("repose_degrees", |p| p.repose_degrees = 0.0),
            ("relax_passes", |p| p.relax_passes = u32::MAX),
            ("displacement", |p| p.displacement = f32::INFINITY),
        ];
        for (field, break_it) in cases {
            let mut p = SnowParams::default();
            break_it(&mut p);
            let e = p.validate().unwrap_err();
            assert!(
                matches!(e, Error::Invalid(_)) && e.to_string().contains(field),
                "{field}: {e}"
            );
        }
    }

    #[test]
    fn repose_of_90_turns_stabilisation_off() {
        let mut p = SnowParams::default();
        assert!((p.tan_repose().unwrap() - 38f32.to_radians().tan()).abs() < 1e-6);
        p.repose_degrees = 90.0;
        p.validate().unwrap();
        assert_eq!(p.tan_repose(), None);
    }
}
