//! Look-at cameras (orthographic and perspective) shared by the CPU rasteriser, depth maps and
//! the renderers.
//!
//! Conventions (right-handed, as glam's `*_rh` functions and wgpu):
//! - view space: x to the right, y up, the camera looks down -z;
//! - "view depth" is the distance along the viewing direction, `dot(p - eye, forward)`:
//!   positive in front of the camera, linear in world units (not NDC);
//! - [`Camera::view_proj`] maps to clip space with NDC depth in [0, 1] (near → 0, far → 1);
//! - pixel coordinates: x to the right, y DOWN, row 0 is the top row of the image, pixel
//!   (i, j) covers [i, i + 1) × [j, j + 1) and its centre is (i + 0.5, j + 0.5).

use crate::{Error, Result};
use glam::{Mat4, Vec3, Vec4};
use serde::{Deserialize, Serialize};

/// How view space is projected onto the image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Projection {
    /// Parallel rays; `half_height` is half the visible height in world units (the visible
    /// width is `half_height * aspect`).
    Orthographic { half_height: f32 },
    /// Pinhole camera with a vertical field of view in degrees, in (0, 180).
    Perspective { fov_y_degrees: f32 },
}

/// A look-at camera: position, target, up hint, projection and the depth range [near, far]
/// (view depths; for an orthographic camera `near` may be zero or negative).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Camera {
    pub eye: Vec3,
    pub target: Vec3,
    pub up: Vec3,
    pub projection: Projection,
    pub near: f32,
    pub far: f32,
}

/// The camera's orthonormal frame: `right`, `up` and `forward` (towards the target).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub eye: Vec3,
    pub right: Vec3,
    pub up: Vec3,
    pub forward: Vec3,
}

impl Frame {
    /// World point → view coordinates (x right, y up, view depth along `forward`).
    #[inline]
    pub fn to_view(&self, p: Vec3) -> Vec3 {
        let q = p - self.eye;
        Vec3::new(q.dot(self.right), q.dot(self.up), q.dot(self.forward))
    }

    /// View coordinates (x right, y up, view depth) → world point.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.eye + self.right * v.x + self.up * v.y + self.forward * v.z
    }
}

/// Default depth range: far plane for both kinds, near plane for perspective cameras.
pub const DEFAULT_FAR: f32 = 1.0e4;
pub const DEFAULT_PERSPECTIVE_NEAR: f32 = 1.0e-3;

impl Camera {
    /// An orthographic camera with depth range [0, `DEFAULT_FAR`]; validated.
    pub fn orthographic(eye: Vec3, target: Vec3, up: Vec3, half_height: f32) -> Result<Self> {
        let c = Camera {
            eye,
            target,
            up,
            projection: Projection::Orthographic { half_height },
            near: 0.0,
            far: DEFAULT_FAR,
        };
        c.validate()?;
        Ok(c)
    }

    /// A perspective camera with depth range [`DEFAULT_PERSPECTIVE_NEAR`, `DEFAULT_FAR`];
    /// validated.
    pub fn perspective(eye: Vec3, target: Vec3, up: Vec3, fov_y_degrees: f32) -> Result<Self> {
        let c = Camera {
            eye,
            target,
            up,
            projection: Projection::Perspective { fov_y_degrees },
            near: DEFAULT_PERSPECTIVE_NEAR,
            far: DEFAULT_FAR,
        };
        c.validate()?;
        Ok(c)
    }

    /// The same camera with another depth range; validated.
    pub fn with_depth_range(mut self, near: f32, far: f32) -> Result<Self> {
        self.near = near;
        self.far = far;
        self.validate()?;
        Ok(self)
    }

    /// Checks every field; errors name the field and the problem.
    pub fn validate(&self) -> Result<()> {
        let bad = |m: String| Err(Error::Invalid(format!("camera: {m}")));
        for (name, v) in [("eye", self.eye), ("target", self.target), ("up", self.up)] {
            if !v.is_finite() {
                return bad(format!("{name} must be finite, got {v}"));
            }
        }
        let dir = self.target - self.eye;
        if dir.length_squared() == 0.0 || !dir.normalize_or_zero().is_normalized() {
            return bad(format!(
                "eye and target must differ (both are {}); the view direction is undefined",
                self.eye
            ));
        }
        let fwd = dir.normalize();
        let up = self.up.normalize_or_zero();
        if up == Vec3::ZERO || fwd.cross(up).length() < 1.0e-6 {
            return bad(format!(
                "up {} is zero or parallel to the view direction {fwd}; choose another up",
                self.up
            ));
        }
        match self.projection {
            Projection::Orthographic { half_height } => {
                if !(half_height.is_finite() && half_height > 0.0) {
                    return bad(format!(
                        "half_height must be finite and > 0, got {half_height}"
                    ));
                }
                if !self.near.is_finite() {
                    return bad(format!("near must be finite, got {}", self.near));
                }
            }
            Projection::Perspective { fov_y_degrees } => {
                if !(fov_y_degrees > 0.0 && fov_y_degrees < 180.0) {
                    return bad(format!(
                        "fov_y_degrees must be in (0, 180), got {fov_y_degrees}"
                    ));
                }
                if !(self.near.is_finite() && self.near > 0.0) {
                    return bad(format!(
                        "near must be > 0 for a perspective camera, got {}",
                        self.near
                    ));
                }
            }
        }
        if !(self.far.is_finite() && self.far > self.near) {
            return bad(format!(
                "far must be finite and > near ({}), got {}",
                self.near, self.far
            ));
        }
        Ok(())
    }

    /// The orthonormal camera frame (assumes a valid camera).
    pub fn frame(&self) -> Frame {
        let forward = (self.target - self.eye).normalize();
        let right = forward.cross(self.up).normalize();
        let up = right.cross(forward);
        Frame {
            eye: self.eye,
            right,
            up,
            forward,
        }
    }

    /// Half the visible height: in world units (orthographic) or per unit of view depth
    /// (perspective, `tan(fov_y / 2)`).
    pub fn half_height_scale(&self) -> f32 {
        match self.projection {
            Projection::Orthographic { half_height } => half_height,
            Projection::Perspective { fov_y_degrees } => (0.5 * fov_y_degrees.to_radians()).tan(),
        }
    }

    pub fn is_perspective(&self) -> bool {
        matches!(self.projection, Projection::Perspective { .. })
    }

    /// World → view matrix (right-handed: the camera looks down -z; view depth is `-z`).
    pub fn view(&self) -> Mat4 {
        let f = self.frame();
        Mat4::from_cols(
            Vec4::new(f.right.x, f.up.x, -f.forward.x, 0.0),
            Vec4::new(f.right.y, f.up.y, -f.forward.y, 0.0),
            Vec4::new(f.right.z, f.up.z, -f.forward.z, 0.0),
            Vec4::new(
                -f.right.dot(f.eye),
                -f.up.dot(f.eye),
                f.forward.dot(f.eye),
                1.0,
            ),
        )
    }

    /// View → clip matrix for an image of `aspect = width / height` (NDC depth in [0, 1],
    /// as glam's `perspective_rh` / `orthographic_rh` and wgpu).
    pub fn projection_matrix(&self, aspect: f32) -> Mat4 {
        let (n, f) = (self.near, self.far);
        let hh = self.half_height_scale();
        let hw = hh * aspect;
        match self.projection {
            Projection::Orthographic { .. } => {
                let r = 1.0 / (n - f);
                Mat4::from_cols(
                    Vec4::new(1.0 / hw, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, 1.0 / hh, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, r, 0.0),
                    Vec4::new(0.0, 0.0, r * n, 1.0),
                )
            }
            Projection::Perspective { .. } => {
                let r = f / (n - f);
                Mat4::from_cols(
                    Vec4::new(1.0 / hw, 0.0, 0.0, 0.0),
                    Vec4::new(0.0, 1.0 / hh, 0.0, 0.0),
                    Vec4::new(0.0, 0.0, r, -1.0),
                    Vec4::new(0.0, 0.0, r * n, 0.0),
                )
            }
        }
    }

    /// World → clip matrix: `projection_matrix(aspect) * view()`.
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        self.projection_matrix(aspect) * self.view()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_close(a: Vec3, b: Vec3, tol: f32) {
        assert!((a - b).abs().max_element() <= tol, "{a} vs {b}");
    }

    #[test]
    fn validation_names_the_field() {
        let e = |r: Result<Camera>| r.unwrap_err().to_string();
        assert!(e(Camera::perspective(Vec3::ZERO, Vec3::ZERO, Vec3::Y, 60.0)).contains("target"));
        assert!(e(Camera::perspective(Vec3::ZERO, -Vec3::Z, Vec3::Z, 60.0)).contains("up"));
        assert!(
            e(Camera::perspective(Vec3::ZERO, -Vec3::Z, Vec3::Y, 180.0)).contains("fov_y_degrees")
        );
        assert!(
            e(Camera::orthographic(Vec3::ZERO, -Vec3::Z, Vec3::Y, 0.0)).contains("half_height")
        );
        assert!(
            e(Camera::orthographic(Vec3::NAN, -Vec3::Z, Vec3::Y, 1.0))
                .contains("eye must be finite")
        );
        let p = Camera::perspective(Vec3::ZERO, -Vec3::Z, Vec3::Y, 60.0).unwrap();
        assert!(e(p.with_depth_range(0.0, 10.0)).contains("near"));
        assert!(e(p.with_depth_range(1.0, 1.0)).contains("far"));
        let o = Camera::orthographic(Vec3::ZERO, -Vec3::Z, Vec3::Y, 1.0).unwrap();
        assert!(o.with_depth_range(-1.0, 1.0).is_ok());
    }

    #[test]
    fn matrices_agree_with_the_frame() {
        let cam = Camera::perspective(
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-0.5, 0.2, 0.1),
            Vec3::Y,
            50.0,
        )
        .unwrap()
        .with_depth_range(0.5, 20.0)
        .unwrap();
        let f = cam.frame();
        let p = Vec3::new(-1.0, 0.5, -2.0);
        let v = cam.view().transform_point3(p);
        let fv = f.to_view(p);
        assert_close(v, Vec3::new(fv.x, fv.y, -fv.z), 1e-5);
        assert_close(f.to_world(fv), p, 1e-5);
        // Near plane → NDC depth 0, far → 1.
        let vp = cam.view_proj(1.5);
        let at = |d: f32| vp.project_point3(f.eye + f.forward * d).z;
        assert!(at(0.5).abs() < 1e-5 && (at(20.0) - 1.0).abs() < 1e-5);
        let o = Camera::orthographic(Vec3::ZERO, -Vec3::Z, Vec3::Y, 2.0)
            .unwrap()
            .with_depth_range(1.0, 3.0)
            .unwrap();
        let vp = o.view_proj(2.0);
        assert_close(
            vp.project_point3(Vec3::new(4.0, 2.0, -1.0)),
            Vec3::new(1.0, 1.0, 0.0),
            1e-6,
        );
        assert_close(
            vp.project_point3(Vec3::new(0.0, 0.0, -3.0)),
            Vec3::new(0.0, 0.0, 1.0),
            1e-6,
        );
    }
}
