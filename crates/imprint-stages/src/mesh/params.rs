//! The Mesh node's parameters as the pipeline file states them, and their validation.
//!
//! Optional fields are written bare (`fit: (size: 1.0)`, `period: 2.0`), not `Some(...)`,
//! so that plain `ron::from_str` reads the files users write; omit a field for `None`.

use glam::Vec3;
use imprint_core::{Error, Result};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// Largest primitive we build: beyond this a typo in the tessellation is more likely than
/// an intent, and the mesh would dominate memory and voxelising time.
pub const MAX_PRIMITIVE_TRIANGLES: u64 = 1 << 24;

/// A mesh source: a file or a primitive, optionally fitted into a box, then animated.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct MeshParams {
    /// Mesh file, relative to the pipeline file's folder: OBJ, PLY (ASCII or binary), STL
    /// (ASCII or binary), glTF 2.0 (`.gltf`, `.glb`); the format is read from the content.
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "String")]
    pub path: Option<String>,
    /// A procedural shape centred on the origin (instead of `path`).
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "Primitive")]
    pub primitive: Option<Primitive>,
    /// Uniform scale and translation of the rest mesh; `None` keeps its own coordinates.
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "Fit")]
    pub fit: Option<Fit>,
    /// A glTF file's animation clip, by name (the error lists the file's): the mesh is then
    /// the file's skinned mesh posed by the clip at each frame's time (linear blend with the
    /// file's weights), fitted as it stands at time 0, before any `motion`. The same fields
    /// as the Skin node's: `speed` (clip seconds per pipeline second), `loop`,
    /// `clip_offset` (clip time at the pipeline's time 0).
    #[serde(
        default,
        with = "crate::bare_option",
        skip_serializing_if = "Option::is_none"
    )]
    #[schemars(with = "String")]
    pub clip: Option<String>,
    /// Clip seconds per pipeline second (default 1).
    #[serde(default = "one", skip_serializing_if = "is_one")]
    pub speed: f32,
    /// Play the clip again from its start when it ends (default true); else hold its end.
    #[serde(default = "yes", rename = "loop", skip_serializing_if = "is_true")]
    pub looping: bool,
    /// Clip time at the pipeline's time 0, seconds (default 0).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub clip_offset: f32,
    /// Fill the mesh's holes (fans around each boundary loop's centroid), so that an open
    /// scan such as the Stanford bunny has an inside: its distance field is then signed.
    #[serde(default, skip_serializing_if = "is_false")]
    pub close_holes: bool,
    /// Deformations applied in order to the fitted rest mesh, as functions of time.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub motion: Vec<Motion>,
    /// In a pipeline, `false` switches this node and everything that reads it off.
    #[serde(default = "yes", skip_serializing_if = "is_true")]
    pub enabled: bool,
}

fn yes() -> bool {
    true
}

fn is_one(x: &f32) -> bool {
    *x == 1.0
}

fn is_zero(x: &f32) -> bool {
    *x == 0.0
}

fn is_true(b: &bool) -> bool {
    *b
}

fn is_false(b: &bool) -> bool {
    !*b
}

/// Puts the rest mesh's bounding box, longest side `size`, centred on `center`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Fit {
    /// Longest side of the box after fitting, m (the mesh is scaled uniformly).
    pub size: f32,
    /// Where the box's centre is put, m.
    #[serde(default)]
    #[schemars(with = "[f32; 3]")]
    pub center: Vec3,
}

/// Procedural shapes (imprint_core::mesh::primitives), centred on the origin.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Primitive {
    /// Latitude/longitude sphere: `2 * segments * (rings - 1)` triangles.
    Sphere {
        /// Radius, m.
        radius: f32,
        /// Divisions around the y axis (longitude; at least 3).
        #[serde(default = "d64")]
        segments: u32,
        /// Latitude bands from pole to pole (the poles are on the y axis; at least 2).
        #[serde(default = "d32")]
        rings: u32,
    },
    /// Axis-aligned box of full extents `size`, each face split into `subdivisions`² quads
    /// (more than one so that bends and twists have vertices to move).
    Box {
        /// Full extents along x, y and z, m.
        #[schemars(with = "[f32; 3]")]
        size: Vec3,
        /// Quads along each edge of a face (at least 1).
        #[serde(default = "d16")]
        subdivisions: u32,
    },
    /// Square in x-z at y = 0 facing +y, side `size`, `subdivisions`² quads.
    Plane {
        /// Side of the square, m.
        size: f32,
        /// Quads along each side (at least 1).
        #[serde(default = "d64")]
        subdivisions: u32,
    },
    /// Torus around the y axis: ring radius `major`, tube radius `minor`.
    Torus {
        /// Distance from the y axis to the tube's centre line, m.
        major: f32,
        /// Radius of the tube, m.
        minor: f32,
        /// Divisions around the y axis, along the ring (at least 3).
        #[serde(default = "d64")]
        segments: u32,
        /// Divisions around the tube (at least 3).
        #[serde(default = "d32")]
        sides: u32,
    },
    /// Capped cylinder (a limb) along +x from x = 0 to x = `length` (not centred: a bone's
    /// head at the origin), `segments` around, `rings` quads along (an even number puts a
    /// ring at the middle joint): `2 * segments * (rings + 1)` triangles.
    Cylinder {
        /// Radius, m.
        radius: f32,
        /// Length along +x, m.
        length: f32,
        /// Divisions around the x axis (at least 3).
        #[serde(default = "d64")]
        segments: u32,
        /// Quads along the length (at least 1).
        #[serde(default = "d32")]
        rings: u32,
    },
}

fn d16() -> u32 {
    16
}
fn d32() -> u32 {
    32
}
fn d64() -> u32 {
    64
}
fn one() -> f32 {
    1.0
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize, JsonSchema)]
pub enum Axis {
    X,
    Y,
    Z,
}

impl Axis {
    pub fn index(self) -> usize {
        self as usize
    }

    pub fn unit(self) -> Vec3 {
        Vec3::AXES[self.index()]
    }

    /// Bend's default direction: the first of X, Y, Z that is not `self`.
    pub fn default_toward(self) -> Axis {
        if self == Axis::X { Axis::Y } else { Axis::X }
    }
}

/// A rotation axis: a named axis or any non-zero direction `(x, y, z)`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
#[serde(untagged)]
pub enum RotationAxis {
    Named(Axis),
    Vector(Vec3),
}

impl RotationAxis {
    pub fn vector(self) -> Vec3 {
        match self {
            RotationAxis::Named(a) => a.unit(),
            RotationAxis::Vector(v) => v,
        }
    }
}

impl<'de> Deserialize<'de> for RotationAxis {
    /// Untagged, with a message that says what is accepted (serde's says only "no variant").
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Either {
            Named(Axis),
            Vector(Vec3),
        }
        match Either::deserialize(d) {
            Ok(Either::Named(a)) => Ok(RotationAxis::Named(a)),
            Ok(Either::Vector(v)) => Ok(RotationAxis::Vector(v)),
            Err(_) => Err(serde::de::Error::custom(
                "expected an axis: X, Y, Z or a direction (x, y, z)",
            )),
        }
    }
}

/// The schema of what [`RotationAxis`]'s hand-written `Deserialize` accepts: a named axis
/// or a direction `[x, y, z]` (kept by hand beside it, as the derive cannot see that impl).
impl JsonSchema for RotationAxis {
    fn schema_name() -> std::borrow::Cow<'static, str> {
        "RotationAxis".into()
    }

    fn json_schema(g: &mut schemars::SchemaGenerator) -> schemars::Schema {
        schemars::json_schema!({
            "description": "A rotation axis: X, Y, Z or any non-zero direction [x, y, z].",
            "anyOf": [g.subschema_for::<Axis>(), g.subschema_for::<[f32; 3]>()],
        })
    }
}

/// Right-handed rotation by `degrees` about `axis`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Rotation {
    /// The axis turned about: `X`, `Y`, `Z` or a direction `(x, y, z)` (normalised).
    pub axis: RotationAxis,
    /// Angle, degrees, right-handed about `axis`.
    pub degrees: f32,
}

impl Default for Rotation {
    fn default() -> Self {
        Rotation {
            axis: RotationAxis::Named(Axis::Y),
            degrees: 0.0,
        }
    }
}

/// One keyframe of a rigid motion. Missing parts are the identity.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RigidKey {
    /// Seconds; keys must be in strictly increasing time.
    pub time: f32,
    /// Displacement of the box centre, m.
    #[serde(default)]
    #[schemars(with = "[f32; 3]")]
    pub translate: Vec3,
    /// Rotation about the box centre.
    #[serde(default)]
    pub rotate: Rotation,
    /// Uniform scale about the centre.
    #[serde(default = "one")]
    pub scale: f32,
}

/// Deformations of the rest mesh. "Centre" and "box" always mean the fitted rest mesh's
/// bounding box, not the result of earlier motions, so each motion's parameters keep one
/// meaning whatever precedes it (put `Rigid` last to move a deformed body as a whole).
/// Periodic factors are `sin(2π t / period)`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub enum Motion {
    /// Keyframes: p' = c + translate + R (scale (p - c)), c the box centre. Translation and
    /// scale interpolate linearly, rotation by slerp (shortest arc: keep successive keys
    /// under 180° apart); held constant before the first key and after the last.
    Rigid {
        /// The keyframes, in strictly increasing `time`.
        keys: Vec<RigidKey>,
    },
    /// Radial scale about the centre: p' = c + (p - c)(1 + amplitude sin(2πt/period)).
    Breathe {
        /// Relative change of scale at the peak (0.1: ±10 %).
        amplitude: f32,
        /// Duration of one cycle, seconds.
        period: f32,
    },
    /// Right-handed rotation about the axis through the centre by an angle growing linearly
    /// along the axis, 0 at the box's low end and `degrees` at its high end; scaled by
    /// sin(2πt/period) when a period is given, constant otherwise.
    Twist {
        /// The axis twisted about (through the box centre) and along which the angle grows.
        axis: Axis,
        /// Angle of the high end relative to the low end, degrees (times the cycle's sine).
        degrees: f32,
        /// Duration of one cycle, seconds; left out, the twist is constant.
        #[serde(
            default,
            with = "crate::bare_option",
            skip_serializing_if = "Option::is_none"
        )]
        #[schemars(with = "f32")]
        period: Option<f32>,
    },
    /// Barr's (1984) circular-arc bend of the whole length along `axis` toward `toward`
    /// (default: the first of X, Y, Z that is not `axis`): the low end stays fixed, the
    /// centre line keeps its length, the high end turns by `degrees` (times sin(2πt/period)
    /// when a period is given).
    Bend {
        /// The axis along which the length is bent (the low end stays fixed).
        axis: Axis,
        /// Angle the high end turns by, degrees (times the cycle's sine).
        degrees: f32,
        /// The axis the bend curves toward; default the first of X, Y, Z that is not `axis`.
        #[serde(
            default,
            with = "crate::bare_option",
            skip_serializing_if = "Option::is_none"
        )]
        #[schemars(with = "Axis")]
        toward: Option<Axis>,
        /// Duration of one cycle, seconds; left out, the bend is constant.
        #[serde(
            default,
            with = "crate::bare_option",
            skip_serializing_if = "Option::is_none"
        )]
        #[schemars(with = "f32")]
        period: Option<f32>,
    },
    /// Travelling wave: `p[displace] += amplitude sin(2π (p[direction] - speed t) / wavelength)`,
    /// with `p[direction]` the world coordinate.
    Wave {
        /// Largest displacement, m.
        amplitude: f32,
        /// Distance between crests along `direction`, m.
        wavelength: f32,
        /// Speed the crests travel along `direction`, m/s.
        speed: f32,
        /// The world axis the wave travels along.
        #[serde(default = "axis_x")]
        direction: Axis,
        /// The coordinate the wave moves.
        #[serde(default = "axis_y")]
        displace: Axis,
    },
}

fn axis_x() -> Axis {
    Axis::X
}
fn axis_y() -> Axis {
    Axis::Y
}

impl Motion {
    pub fn name(&self) -> &'static str {
        match self {
            Motion::Rigid { .. } => "Rigid",
            Motion::Breathe { .. } => "Breathe",
            Motion::Twist { .. } => "Twist",
            Motion::Bend { .. } => "Bend",
            Motion::Wave { .. } => "Wave",
        }
    }

    /// True when the motion gives the same shape at every time (the mesh is then static).
    pub fn is_time_invariant(&self) -> bool {
        match self {
            Motion::Rigid { keys } => keys.windows(2).all(|w| {
                let (a, b) = (w[0], w[1]);
                a.translate == b.translate
                    && a.scale == b.scale
                    && (a.rotate == b.rotate
                        || (a.rotate.degrees == 0.0 && b.rotate.degrees == 0.0))
            }),
            Motion::Breathe { amplitude, .. } => *amplitude == 0.0,
            Motion::Twist {
                degrees, period, ..
            }
            | Motion::Bend {
                degrees, period, ..
            } => period.is_none() || *degrees == 0.0,
            Motion::Wave {
                amplitude, speed, ..
            } => *amplitude == 0.0 || *speed == 0.0,
        }
    }
}

impl Primitive {
    pub fn name(&self) -> &'static str {
        match self {
            Primitive::Sphere { .. } => "Sphere",
            Primitive::Box { .. } => "Box",
            Primitive::Plane { .. } => "Plane",
            Primitive::Torus { .. } => "Torus",
            Primitive::Cylinder { .. } => "Cylinder",
        }
    }

    /// Triangles the primitive will have (u64: checked before anything is built).
    pub fn triangle_count(&self) -> u64 {
        match *self {
            Primitive::Sphere {
                segments, rings, ..
            } => 2 * segments as u64 * (rings as u64).saturating_sub(1),
            Primitive::Box { subdivisions, .. } => 12 * (subdivisions as u64).pow(2),
            Primitive::Plane { subdivisions, .. } => 2 * (subdivisions as u64).pow(2),
            Primitive::Torus {
                segments, sides, ..
            } => 2 * segments as u64 * sides as u64,
            Primitive::Cylinder {
                segments, rings, ..
            } => 2 * segments as u64 * (rings as u64 + 1),
        }
    }

    fn validate(&self) -> Result<()> {
        let f = |field: &str| format!("primitive {}.{field}", self.name());
        match *self {
            Primitive::Sphere {
                radius,
                segments,
                rings,
            } => {
                positive(&f("radius"), radius)?;
                at_least(&f("segments"), segments, 3)?;
                at_least(&f("rings"), rings, 2)?;
            }
            Primitive::Box { size, subdivisions } => {
                for (i, c) in ["x", "y", "z"].iter().enumerate() {
                    positive(&format!("{}.{c}", f("size")), size[i])?;
                }
                at_least(&f("subdivisions"), subdivisions, 1)?;
            }
            Primitive::Plane { size, subdivisions } => {
                positive(&f("size"), size)?;
                at_least(&f("subdivisions"), subdivisions, 1)?;
            }
            Primitive::Torus {
                major,
                minor,
                segments,
                sides,
            } => {
                positive(&f("major"), major)?;
                positive(&f("minor"), minor)?;
                at_least(&f("segments"), segments, 3)?;
                at_least(&f("sides"), sides, 3)?;
            }
            Primitive::Cylinder {
                radius,
                length,
                segments,
                rings,
            } => {
                positive(&f("radius"), radius)?;
                positive(&f("length"), length)?;
                at_least(&f("segments"), segments, 3)?;
                at_least(&f("rings"), rings, 1)?;
            }
        }
        let n = self.triangle_count();
        if n > MAX_PRIMITIVE_TRIANGLES {
            return Err(Error::Invalid(format!(
                "primitive {}: the tessellation gives {n} triangles, more than the limit of \
                 {MAX_PRIMITIVE_TRIANGLES}; lower it",
                self.name()
            )));
        }
        Ok(())
    }
}

impl MeshParams {
    /// Checks every value before anything is loaded; each message names the field.
    pub fn validate(&self) -> Result<()> {
        match (&self.path, &self.primitive) {
            (Some(_), Some(_)) => {
                return Err(Error::Invalid(
                    "Mesh takes exactly one of `path` or `primitive`, got both".into(),
                ));
            }
            (None, None) => {
                return Err(Error::Invalid(
                    "Mesh takes exactly one of `path` or `primitive`, got neither".into(),
                ));
            }
            (Some(p), None) if p.trim().is_empty() => {
                return Err(Error::Invalid("path must not be empty".into()));
            }
            (_, Some(prim)) => prim.validate()?,
            _ => {}
        }
        if let Some(fit) = &self.fit {
            positive("fit.size", fit.size)?;
            finite_vec("fit.center", fit.center)?;
        }
        if self.clip.is_some() && self.path.is_none() {
            return Err(Error::Invalid(
                "clip: only a glTF file (`path`) has clips, not a primitive".into(),
            ));
        }
        if !(self.speed.is_finite() && self.clip_offset.is_finite()) {
            return Err(Error::Invalid(format!(
                "speed {} and clip_offset {} must be finite",
                self.speed, self.clip_offset
            )));
        }
        for (i, m) in self.motion.iter().enumerate() {
            validate_motion(&format!("motion[{i}] {}", m.name()), m)?;
        }
        Ok(())
    }
}

fn validate_motion(at: &str, m: &Motion) -> Result<()> {
    match m {
        Motion::Rigid { keys } => {
            if keys.is_empty() {
                return Err(Error::Invalid(format!(
                    "{at}.keys must have at least one key"
                )));
            }
            for (k, key) in keys.iter().enumerate() {
                let f = |field: &str| format!("{at}.keys[{k}].{field}");
                finite(&f("time"), key.time)?;
                if k > 0 && key.time <= keys[k - 1].time {
                    return Err(Error::Invalid(format!(
                        "{} must be greater than keys[{}].time ({}), got {}",
                        f("time"),
                        k - 1,
                        keys[k - 1].time,
                        key.time
                    )));
                }
                finite_vec(&f("translate"), key.translate)?;
                finite(&f("rotate.degrees"), key.rotate.degrees)?;
                let axis = key.rotate.axis.vector();
                if !axis.is_finite() || axis.length_squared() <= 1e-12 {
                    return Err(Error::Invalid(format!(
                        "{} must be a finite non-zero direction, got ({}, {}, {})",
                        f("rotate.axis"),
                        axis.x,
                        axis.y,
                        axis.z
                    )));
                }
                positive(&f("scale"), key.scale)?;
            }
        }
        Motion::Breathe { amplitude, period } => {
            finite(&format!("{at}.amplitude"), *amplitude)?;
            if amplitude.abs() >= 1.0 {
                return Err(Error::Invalid(format!(
                    "{at}.amplitude must be between -1 and 1 (exclusive) so the scale stays \
                     positive, got {amplitude}"
                )));
            }
            positive(&format!("{at}.period"), *period)?;
        }
        Motion::Twist {
            degrees, period, ..
        } => {
            finite(&format!("{at}.degrees"), *degrees)?;
            if let Some(p) = period {
                positive(&format!("{at}.period"), *p)?;
            }
        }
        Motion::Bend {
            axis,
            degrees,
            toward,
            period,
        } => {
            finite(&format!("{at}.degrees"), *degrees)?;
            if *toward == Some(*axis) {
                return Err(Error::Invalid(format!(
                    "{at}.toward must differ from {at}.axis (both {axis:?})"
                )));
            }
            if let Some(p) = period {
                positive(&format!("{at}.period"), *p)?;
            }
        }
        Motion::Wave {
            amplitude,
            wavelength,
            speed,
            ..
        } => {
            finite(&format!("{at}.amplitude"), *amplitude)?;
            positive(&format!("{at}.wavelength"), *wavelength)?;
            finite(&format!("{at}.speed"), *speed)?;
        }
    }
    Ok(())
}

fn finite(field: &str, v: f32) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::Invalid(format!("{field} must be finite, got {v}")))
    }
}

fn positive(field: &str, v: f32) -> Result<()> {
    if v.is_finite() && v > 0.0 {
        Ok(())
    } else {
        Err(Error::Invalid(format!("{field} must be > 0, got {v}")))
    }
}

fn finite_vec(field: &str, v: Vec3) -> Result<()> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(Error::Invalid(format!(
            "{field} must be finite, got ({}, {}, {})",
            v.x, v.y, v.z
        )))
    }
}

fn at_least(field: &str, v: u32, min: u32) -> Result<()> {
    if v >= min {
        Ok(())
    } else {
        Err(Error::Invalid(format!("{field} must be >= {min}, got {v}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> std::result::Result<MeshParams, ron::error::SpannedError> {
        ron::from_str(s)
    }

    #[test]
    fn parses_the_design_example_and_round_trips() {
        let bunny = parse(
            r#"(path: "assets/meshes/stanford-bunny.obj", fit: (size: 1.0),
                motion: [Breathe(amplitude: 0.05, period: 2.0), Twist(axis: Y, degrees: 30)])"#,
        )
        .unwrap();
        assert_eq!(
            bunny.path.as_deref(),
            Some("assets/meshes/stanford-bunny.obj")
        );
        assert_eq!(
            bunny.fit,
            Some(Fit {
                size: 1.0,
                center: Vec3::ZERO
            })
        );
        assert_eq!(
            bunny.motion,
            vec![
                Motion::Breathe {
                    amplitude: 0.05,
                    period: 2.0
                },
                Motion::Twist {
                    axis: Axis::Y,
                    degrees: 30.0,
                    period: None
                },
            ]
        );
        bunny.validate().unwrap();

        let ball = parse(
            r#"(primitive: Sphere(radius: 0.5, segments: 64, rings: 32),
                motion: [Rigid(keys: [
                    (time: 0, translate: (0, 1, 0)),
                    (time: 2, translate: (0, 0.2, 0), rotate: (axis: (1, 0, 1), degrees: 90), scale: 1.5),
                    (time: 3, rotate: (axis: Z, degrees: 120)),
                ])])"#,
        )
        .unwrap();
        assert_eq!(
            ball.primitive,
            Some(Primitive::Sphere {
                radius: 0.5,
                segments: 64,
                rings: 32
            })
        );
        let Motion::Rigid { keys } = &ball.motion[0] else {
            panic!()
        };
        assert_eq!(
            keys[1].rotate.axis,
            RotationAxis::Vector(Vec3::new(1.0, 0.0, 1.0))
        );
        assert_eq!(keys[2].rotate.axis, RotationAxis::Named(Axis::Z));
        assert_eq!(keys[2].scale, 1.0);
        assert_eq!(keys[2].translate, Vec3::ZERO);
        ball.validate().unwrap();

        // Every variant, with and without optional fields, survives a round trip.
        let all = parse(
            r#"(primitive: Box(size: (1, 2, 3)), fit: (size: 2, center: (0, 0.5, 0)),
                motion: [Twist(axis: X, degrees: -45, period: 3), Bend(axis: Y, degrees: 60),
                         Bend(axis: Z, degrees: 10, toward: Y, period: 1.5),
                         Wave(amplitude: 0.02, wavelength: 0.5, speed: 1, direction: Z, displace: X),
                         Wave(amplitude: 0.02, wavelength: 0.5, speed: 1)])"#,
        )
        .unwrap();
        assert_eq!(
            all.primitive,
            Some(Primitive::Box {
                size: Vec3::new(1.0, 2.0, 3.0),
                subdivisions: 16
            })
        );
        assert_eq!(
            all.motion[4],
            Motion::Wave {
                amplitude: 0.02,
                wavelength: 0.5,
                speed: 1.0,
                direction: Axis::X,
                displace: Axis::Y
            }
        );
        for p in [bunny, ball, all] {
            let text = ron::to_string(&p).unwrap();
            assert_eq!(parse(&text).unwrap(), p, "{text}");
        }
        for prim in [
            "Plane(size: 2)",
            "Torus(major: 1, minor: 0.25)",
            "Cylinder(radius: 0.1, length: 1)",
        ] {
            let p = parse(&format!("(primitive: {prim})")).unwrap();
            p.validate().unwrap();
        }
    }

    #[test]
    fn parses_as_a_pipeline_node_with_the_graph_extensions() {
        // The graph reads `"name": Mesh(...)` with these extensions; optional fields written
        // bare must read the same there as with plain `ron::from_str`.
        #[derive(Deserialize)]
        enum Node {
            Mesh(MeshParams),
        }
        let options = ron::Options::default().with_default_extension(
            ron::extensions::Extensions::IMPLICIT_SOME
                | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
        );
        let text = r#"Mesh(path: "assets/meshes/stanford-bunny.obj", fit: (size: 1.0),
                           motion: [Breathe(amplitude: 0.05, period: 2.0),
                                    Twist(axis: Y, degrees: 30, period: 4)])"#;
        let Node::Mesh(p) = options.from_str(text).unwrap();
        assert_eq!(p, parse(&text["Mesh".len()..]).unwrap());
        assert_eq!(
            p.motion[1],
            Motion::Twist {
                axis: Axis::Y,
                degrees: 30.0,
                period: Some(4.0)
            }
        );
    }

    #[test]
    fn unknown_fields_are_rejected() {
        let e = parse(r#"(path: "a.obj", scale: 2.0)"#).unwrap_err();
        assert!(e.to_string().contains("scale"), "{e}");
        let e = parse(r#"(path: "a.obj", motion: [Breathe(amplitude: 0.1, period: 1, phase: 2)])"#)
            .unwrap_err();
        assert!(e.to_string().contains("phase"), "{e}");
        let e = parse(r#"(primitive: Sphere(radius: 1, segs: 3))"#).unwrap_err();
        assert!(e.to_string().contains("segs"), "{e}");
        let e = parse(r#"(path: "a.obj", fit: (size: 1, centre: (0, 0, 0)))"#).unwrap_err();
        assert!(e.to_string().contains("centre"), "{e}");
        let e = parse(
            r#"(path: "a", motion: [Rigid(keys: [(time: 0, rotate: (axis: W, degrees: 1))])])"#,
        )
        .unwrap_err();
        assert!(e.to_string().contains("X, Y, Z"), "{e}");
    }

    #[test]
    fn invalid_values_name_the_field() {
        let cases = [
            (r#"(path: "a.obj", primitive: Plane(size: 1))"#, "got both"),
            (r#"(fit: (size: 1))"#, "got neither"),
            (
                r#"(path: "a", fit: (size: 0))"#,
                "fit.size must be > 0, got 0",
            ),
            (
                r#"(path: "a", fit: (size: 1, center: (0, inf, 0)))"#,
                "fit.center must be finite",
            ),
            (
                r#"(primitive: Sphere(radius: -1))"#,
                "primitive Sphere.radius must be > 0, got -1",
            ),
            (
                r#"(primitive: Sphere(radius: 1, segments: 2))"#,
                "primitive Sphere.segments must be >= 3, got 2",
            ),
            (
                r#"(primitive: Box(size: (1, 0, 1)))"#,
                "primitive Box.size.y must be > 0",
            ),
            (
                r#"(primitive: Plane(size: 1, subdivisions: 0))"#,
                "primitive Plane.subdivisions must be >= 1",
            ),
            (
                r#"(primitive: Torus(major: 1, minor: 0.2, sides: 1))"#,
                "primitive Torus.sides must be >= 3",
            ),
            (
                r#"(primitive: Cylinder(radius: 0.1, length: 0))"#,
                "primitive Cylinder.length must be > 0, got 0",
            ),
            (
                r#"(primitive: Cylinder(radius: 0.1, length: 1, rings: 0))"#,
                "primitive Cylinder.rings must be >= 1",
            ),
            (
                r#"(primitive: Sphere(radius: 1, segments: 100000, rings: 100000))"#,
                "more than the limit",
            ),
            (
                r#"(path: "a", motion: [Twist(axis: Y, degrees: 3), Breathe(amplitude: 0.1, period: -2)])"#,
                "motion[1] Breathe.period must be > 0, got -2",
            ),
            (
                r#"(path: "a", motion: [Breathe(amplitude: 1.5, period: 1)])"#,
                "motion[0] Breathe.amplitude",
            ),
            (
                r#"(path: "a", motion: [Twist(axis: Y, degrees: 3, period: 0)])"#,
                "motion[0] Twist.period must be > 0",
            ),
            (
                r#"(path: "a", motion: [Twist(axis: Y, degrees: NaN)])"#,
                "motion[0] Twist.degrees must be finite",
            ),
            (
                r#"(path: "a", motion: [Bend(axis: Y, degrees: 3, toward: Y)])"#,
                "motion[0] Bend.toward must differ",
            ),
            (
                r#"(path: "a", motion: [Wave(amplitude: 1, wavelength: 0, speed: 1)])"#,
                "motion[0] Wave.wavelength must be > 0",
            ),
            (
                r#"(path: "a", motion: [Rigid(keys: [])])"#,
                "motion[0] Rigid.keys must have at least one key",
            ),
            (
                r#"(path: "a", motion: [Rigid(keys: [(time: 1), (time: 0.5)])])"#,
                "motion[0] Rigid.keys[1].time must be greater than keys[0].time (1), got 0.5",
            ),
            (
                r#"(path: "a", motion: [Rigid(keys: [(time: 0, scale: 0)])])"#,
                "motion[0] Rigid.keys[0].scale must be > 0",
            ),
            (
                r#"(path: "a", motion: [Rigid(keys: [(time: 0, rotate: (axis: (0, 0, 0), degrees: 5))])])"#,
                "motion[0] Rigid.keys[0].rotate.axis must be a finite non-zero direction",
            ),
        ];
        for (text, want) in cases {
            let e = parse(text)
                .unwrap_or_else(|e| panic!("{text}: {e}"))
                .validate()
                .unwrap_err();
            assert!(matches!(e, Error::Invalid(_)), "{e:?}");
            assert!(
                e.to_string().contains(want),
                "{text}\n  got: {e}\n  want: {want}"
            );
        }
    }

    #[test]
    fn time_invariance() {
        let m = |s: &str| {
            parse(&format!("(path: \"a\", motion: [{s}])"))
                .unwrap()
                .motion[0]
                .clone()
        };
        assert!(m("Twist(axis: Y, degrees: 30)").is_time_invariant());
        assert!(!m("Twist(axis: Y, degrees: 30, period: 1)").is_time_invariant());
        assert!(m("Rigid(keys: [(time: 0, translate: (1, 0, 0))])").is_time_invariant());
        assert!(!m("Rigid(keys: [(time: 0), (time: 1, scale: 2)])").is_time_invariant());
        assert!(m("Wave(amplitude: 1, wavelength: 1, speed: 0)").is_time_invariant());
        assert!(!m("Breathe(amplitude: 0.1, period: 1)").is_time_invariant());
    }
}
