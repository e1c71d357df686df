//! The viewer's orbit camera: starts as the pipeline's Render camera (following its spin, so
//! the picture is the offline frame's) until the user drags, scrolls or presses a key, then
//! stays where the user put it.

use glam::Vec3;
use imprint_core::{Aabb, Camera};
use imprint_graph::nodes::render::CameraSpec;
use imprint_render::frame::orbit;

/// Degrees of orbit per pixel dragged.
const DEGREES_PER_PIXEL: f32 = 0.3;
/// Zoom factor per scroll line.
const ZOOM_PER_LINE: f32 = 0.9;
/// Elevation stays short of the poles, where the up vector would be undefined.
const MAX_ELEVATION: f32 = 89.0;

#[derive(Clone, Debug, PartialEq)]
pub struct OrbitCamera {
    pub target: Vec3,
    pub distance: f32,
    /// Degrees above the horizon.
    pub elevation: f32,
    /// Degrees about +Y, 0 looking along -Z (as the Render node's `Orbit`).
    pub azimuth: f32,
    /// Vertical field of view, degrees.
    pub fov: f32,
    /// Degrees per second the file's orbit turns; dropped once the user moves the camera.
    pub spin: f32,
}

impl OrbitCamera {
    /// The Render node's camera (a `LookAt` becomes the orbit through its eye).
    pub fn from_spec(spec: &CameraSpec) -> OrbitCamera {
        let v = |t: (f32, f32, f32)| Vec3::new(t.0, t.1, t.2);
        match *spec {
            CameraSpec::Orbit {
                target,
                distance,
                elevation,
                azimuth,
                fov,
                spin,
            } => OrbitCamera {
                target: v(target),
                distance,
                elevation,
                azimuth,
                fov,
                spin,
            },
            CameraSpec::LookAt { eye, target, fov } => {
                let d = v(eye) - v(target);
                let distance = d.length().max(1e-6);
                OrbitCamera {
                    target: v(target),
                    distance,
                    elevation: (d.y / distance).clamp(-1.0, 1.0).asin().to_degrees(),
                    azimuth: d.x.atan2(d.z).to_degrees(),
                    fov,
                    spin: 0.0,
                }
            }
        }
    }

    /// A camera that frames `bounds` (a pipeline with no Render node).
    pub fn framing(bounds: Aabb) -> OrbitCamera {
        let size = (bounds.max - bounds.min).length().max(1e-3);
        OrbitCamera {
            target: (bounds.min + bounds.max) * 0.5,
            distance: size * 1.6,
            elevation: 20.0,
            azimuth: 35.0,
            fov: 40.0,
            spin: 0.0,
        }
    }

    /// The camera at `time` seconds.
    pub fn camera(&self, time: f32) -> imprint_core::Result<Camera> {
        let azimuth = self.azimuth + self.spin * time;
        orbit(
            self.target,
            self.distance,
            self.elevation,
            azimuth,
            self.fov,
        )
    }

    /// Turns by a drag of (dx, dy) pixels; the spin at `time` is frozen into the azimuth.
    pub fn rotate(&mut self, time: f32, dx: f32, dy: f32) {
        self.freeze(time);
        self.azimuth -= dx * DEGREES_PER_PIXEL;
        self.elevation =
            (self.elevation + dy * DEGREES_PER_PIXEL).clamp(-MAX_ELEVATION, MAX_ELEVATION);
    }

    /// Moves the target in the view plane by a drag of (dx, dy) pixels in a view
    /// `height` pixels tall (the point under the cursor follows it at the target's depth).
    pub fn pan(&mut self, time: f32, dx: f32, dy: f32, height: f32) {
        self.freeze(time);
        let Ok(cam) = self.camera(time) else {
            return;
        };
        let forward = (self.target - cam.eye).normalize_or_zero();
        let right = forward.cross(Vec3::Y).normalize_or_zero();
        let up = right.cross(forward);
        let world_per_pixel =
            2.0 * self.distance * (self.fov.to_radians() * 0.5).tan() / height.max(1.0);
        self.target += (-right * dx + up * dy) * world_per_pixel;
    }

    /// Moves closer (`lines > 0`) or away by scroll lines.
    pub fn zoom(&mut self, time: f32, lines: f32) {
        self.freeze(time);
        self.distance = (self.distance * ZOOM_PER_LINE.powf(lines)).max(1e-4);
    }

    fn freeze(&mut self, time: f32) {
        self.azimuth += self.spin * time;
        self.spin = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_round_trips_through_the_orbit() {
        let spec = CameraSpec::LookAt {
            eye: (1.0, 2.0, 3.0),
            target: (0.5, 0.25, -1.0),
            fov: 35.0,
        };
        let cam = OrbitCamera::from_spec(&spec).camera(0.0).unwrap();
        assert!(
            (cam.eye - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-5,
            "{:?}",
            cam.eye
        );
    }

    #[test]
    fn a_drag_freezes_the_spin_where_it_was() {
        let spec = CameraSpec::Orbit {
            target: (0.0, 0.0, 0.0),
            distance: 2.0,
            elevation: 20.0,
            azimuth: 10.0,
            fov: 40.0,
            spin: 5.0,
        };
        let mut c = OrbitCamera::from_spec(&spec);
        let before = c.camera(2.0).unwrap();
        c.rotate(2.0, 0.0, 0.0);
        assert_eq!(c.spin, 0.0);
        assert_eq!(c.azimuth, 20.0);
        let after = c.camera(7.0).unwrap();
        assert!((before.eye - after.eye).length() < 1e-6);
    }

    #[test]
    fn pan_moves_the_target_across_the_view_and_zoom_scales_distance() {
        let mut c = OrbitCamera::framing(Aabb {
            min: Vec3::splat(-1.0),
            max: Vec3::splat(1.0),
        });
        let d = c.distance;
        c.zoom(0.0, 1.0);
        assert!((c.distance - d * ZOOM_PER_LINE).abs() < 1e-6);
        let cam = c.camera(0.0).unwrap();
        let forward = (c.target - cam.eye).normalize();
        let t0 = c.target;
        c.pan(0.0, 10.0, -4.0, 500.0);
        // The target moves perpendicular to the line of sight.
        assert!((c.target - t0).dot(forward).abs() < 1e-5);
        assert!((c.target - t0).length() > 0.0);
    }
}
