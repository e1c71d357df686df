//! Rigs: bones, the rest pose, keyframed and procedural animation, and the pose at a time.
//!
//! **File format** (RON, read by `imprint_graph::rig`; optional fields written bare):
//! ```ron
//! Rig(
//!     bones: [
//!         (name: "upper", head: (0, 0, 0), tail: (0.5, 0, 0)),
//!         (name: "lower", head: (0.5, 0, 0), tail: (1.0, 0, 0), parent: "upper"),
//!     ],
//!     mesh: "../meshes/limb.obj",   // optional binding: an OBJ path relative to the rig file
//!     animation: [
//!         Keys(bone: "lower", interpolation: Linear, keys: [       // Step | Linear | Smooth
//!             (time: 0.0, rotation: (axis: (0, 0, 1), degrees: 0)),
//!             (time: 1.0, rotation: (axis: (0, 0, 1), degrees: 90)),
//!         ]),
//!         Keys(bone: "upper", keys: [(time: 0.0, translation: (0, 0, 0))]),  // roots only
//!         Bend(bone: "lower", axis: (0, 0, 1), degrees: 90, start: 0.0, duration: 1.0),
//!         Twist(bone: "lower", degrees: 180, start: 1.0, duration: 1.0),
//!     ],
//! )
//! ```
//!
//! **Bones.** A bone is a segment head → tail with an optional parent (by name). Bones may be
//! listed in any order; the pose is evaluated parents first. A bone's rotation turns it about
//! its own head; its axes are those of the rest (world) frame carried along by the parent's
//! pose ("in the parent's posed frame"). A child's head needs not touch its parent's tail: it
//! is a point carried rigidly by the parent.
//!
//! **Pose.** `skin[b]` maps a rest-space point to where bone b puts it:
//! `skin[b] = skin[parent] · T(head) · R_b · T(−head)`, and for a root
//! `T(translation) · T(head) · R_b · T(−head)`. `world[b] = skin[b] · T(head)` is the bone's
//! posed frame (origin at the posed head; the rest frame is the world axes at the head), so
//! `skin[b] = world[b] · world_rest[b]⁻¹` as the skinning methods expect. Every skin transform
//! is rigid (rotations and translations only), which dual quaternions require.
//!
//! **Animation.** A bone's local rotation is the product of its motions in file order,
//! `R_b = R_1 · R_2 ⋯ R_n`: each motion acts in the frame the earlier ones made (intrinsic),
//! so a `Twist` listed after a `Bend` twists about the bent bone's own axis. Roots'
//! translations add up.
//! - `Keys`: keyframes of `rotation` (axis, degrees) and/or `translation` (roots only); each
//!   is a track of its own (keys without it are skipped). Before the first key the first
//!   value holds, after the last the last. `Step` holds a key until the next, `Linear`
//!   interpolates with s = (t − t0)/(t1 − t0), `Smooth` with smoothstep(s).
//!   *Rotations interpolate the angle*, not the quaternion: when two consecutive keys have
//!   the same axis (or opposite axes: the second is then read as (−axis, −degrees)), the
//!   rotation is the axis's rotation by the interpolated angle, so a 0° → 270° twist passes
//!   through 90° and 180°, the way it was written. Shortest-path slerp of the two
//!   quaternions would turn a 0° → 270° key pair the other way (through −45°) and can never
//!   express a turn of 180° or more between two keys. Keys with different axes slerp the
//!   quaternions (the shortest arc: split such a turn into keys less than 180° apart).
//! - `Bend(bone, axis, degrees, start, duration)`: a rotation about `axis` (through the
//!   head) from 0 to `degrees`, over [start, start + duration] with a smoothstep ramp.
//! - `Twist(bone, degrees, start, duration)`: the same about the bone's own axis
//!   (head → tail at rest).

use glam::{Affine3A, Quat, Vec3};
use imprint_core::{Error, Result};
use serde::{Deserialize, Serialize};

/// One bone: a segment from `head` to `tail`, turning about its head.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bone {
    pub name: String,
    pub head: Vec3,
    pub tail: Vec3,
    /// The parent bone's name; none for a root.
    #[serde(default)]
    pub parent: Option<String>,
}

/// A rig: bones, an optional mesh binding and an animation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rig {
    pub bones: Vec<Bone>,
    /// The mesh the rig is bound to: an OBJ path relative to the rig file.
    #[serde(default)]
    pub mesh: Option<String>,
    #[serde(default)]
    pub animation: Vec<Motion>,
}

/// A rotation by `degrees` about `axis` (any length but zero); degrees beyond ±180 count.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AxisAngle {
    pub axis: Vec3,
    pub degrees: f32,
}

impl AxisAngle {
    pub fn quat(&self) -> Quat {
        Quat::from_axis_angle(self.axis.normalize(), self.degrees.to_radians())
    }
}

/// One keyframe: a local rotation and/or a root translation at `time` (seconds).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Key {
    pub time: f32,
    #[serde(default)]
    pub rotation: Option<AxisAngle>,
    #[serde(default)]
    pub translation: Option<Vec3>,
}

/// How keyframes are interpolated between keys.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Interpolation {
    /// Hold each key until the next.
    Step,
    #[default]
    Linear,
    /// Smoothstep between keys (zero speed at every key).
    Smooth,
}

/// One animation track of a bone (see the module doc for how they compose).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub enum Motion {
    Keys {
        bone: String,
        #[serde(default)]
        interpolation: Interpolation,
        keys: Vec<Key>,
    },
    /// A smooth ramp from 0 to `degrees` about `axis` through the bone's head.
    Bend {
        bone: String,
        axis: Vec3,
        degrees: f32,
        #[serde(default)]
        start: f32,
        #[serde(default = "one")]
        duration: f32,
    },
    /// A smooth ramp from 0 to `degrees` about the bone's own axis (head → tail).
    Twist {
        bone: String,
        degrees: f32,
        #[serde(default)]
        start: f32,
        #[serde(default = "one")]
        duration: f32,
    },
}

fn one() -> f32 {
    1.0
}

impl Motion {
    pub fn bone(&self) -> &str {
        match self {
            Motion::Keys { bone, .. } | Motion::Bend { bone, .. } | Motion::Twist { bone, .. } => {
                bone
            }
        }
    }

    pub fn name(&self) -> &'static str {
        match self {
            Motion::Keys { .. } => "Keys",
            Motion::Bend { .. } => "Bend",
            Motion::Twist { .. } => "Twist",
        }
    }
}

/// Where in a rig a problem is, for messages that point into the file.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// `bones[bone]`, at `field` (`""`: the whole bone).
    Bone { bone: usize, field: &'static str },
    /// `animation[motion]`, at `field`, in `keys[key]` when given.
    Motion {
        motion: usize,
        key: Option<usize>,
        field: &'static str,
    },
    /// `mesh`.
    Mesh,
    /// The rig as a whole.
    Rig,
}

/// A validation problem: where it is and what to change.
#[derive(Clone, Debug, PartialEq)]
pub struct Problem {
    pub place: Place,
    pub message: String,
}

/// The pose of a rig: per bone (file order), its posed frame and its skinning transform.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    /// The bone's posed frame: origin at the posed head, rest axes carried by the pose.
    pub world: Vec<Affine3A>,
    /// Maps a rest-space point to its posed position under the bone:
    /// `world_posed · world_rest⁻¹`. Rigid.
    pub skin: Vec<Affine3A>,
}

impl Rig {
    /// Checks the rig; the message names the bone (or motion and key) and what to change.
    pub fn validate(&self) -> Result<()> {
        match self.problem() {
            Some(p) => Err(Error::Invalid(p.message)),
            None => Ok(()),
        }
    }

    /// The first problem found, with its place (for located messages).
    pub fn problem(&self) -> Option<Problem> {
        let bone_err = |bone: usize, field: &'static str, message: String| {
            Some(Problem {
                place: Place::Bone { bone, field },
                message,
            })
        };
        if self.bones.is_empty() {
            return Some(Problem {
                place: Place::Rig,
                message: "the rig has no bones; add at least one to `bones`".into(),
            });
        }
        for (i, b) in self.bones.iter().enumerate() {
            if b.name.trim().is_empty() {
                return bone_err(i, "name", format!("bone {} has an empty name", i + 1));
            }
            if let Some(j) = self.bones[..i].iter().position(|o| o.name == b.name) {
                return bone_err(
                    i,
                    "name",
                    format!(
                        "bone '{}' is declared twice (bones {} and {}); names must be unique",
                        b.name,
                        j + 1,
                        i + 1
                    ),
                );
            }
            for (field, v) in [("head", b.head), ("tail", b.tail)] {
                if !v.is_finite() {
                    return bone_err(
                        i,
                        field,
                        format!("bone '{}': {field} {v} is not finite", b.name),
                    );
                }
            }
            let len = (b.tail - b.head).length();
            if len.is_nan() || len <= 1e-6 * (1.0 + b.head.abs().max_element()) {
                return bone_err(
                    i,
                    "tail",
                    format!(
                        "bone '{}' has zero length (head = tail = {}); move its tail away \
                         from its head",
                        b.name, b.head
                    ),
                );
            }
        }
        for (i, b) in self.bones.iter().enumerate() {
            if let Some(p) = &b.parent {
                if p == &b.name {
                    return bone_err(i, "parent", format!("bone '{}' is its own parent", b.name));
                }
                if self.index(p).is_none() {
                    return bone_err(
                        i,
                        "parent",
                        format!(
                            "bone '{}': parent '{p}' is not a bone of this rig (bones: {})",
                            b.name,
                            self.names()
                        ),
                    );
                }
            }
        }
        // Cycles: walking up from any bone must reach a root within n steps.
        for (i, b) in self.bones.iter().enumerate() {
            let mut at = i;
            let mut chain = vec![b.name.as_str()];
            for _ in 0..self.bones.len() {
                match self.parent_index(at) {
                    Some(p) => {
                        at = p;
                        chain.push(&self.bones[p].name);
                    }
                    None => break,
                }
            }
            if self.parent_index(at).is_some() {
                return bone_err(
                    i,
                    "parent",
                    format!(
                        "bone '{}' is in a parent cycle ({} …); one bone of the cycle must \
                         be a root or have a parent outside it",
                        b.name,
                        chain[..chain.len().min(self.bones.len() + 1)].join(" → ")
                    ),
                );
            }
        }
        if let Some(m) = &self.mesh
            && m.trim().is_empty()
        {
            return Some(Problem {
                place: Place::Mesh,
                message: "mesh must not be empty (leave it out for no binding)".into(),
            });
        }
        for (m, motion) in self.animation.iter().enumerate() {
            if let Some(p) = self.motion_problem(m, motion) {
                return Some(p);
            }
        }
        None
    }

    fn motion_problem(&self, m: usize, motion: &Motion) -> Option<Problem> {
        let at = |key: Option<usize>, field: &'static str, message: String| {
            Some(Problem {
                place: Place::Motion {
                    motion: m,
                    key,
                    field,
                },
                message,
            })
        };
        let what = format!(
            "animation entry {} {}(bone: \"{}\")",
            m + 1,
            motion.name(),
            motion.bone()
        );
        let Some(b) = self.index(motion.bone()) else {
            return at(
                None,
                "bone",
                format!(
                    "{what}: '{}' is not a bone of this rig (bones: {})",
                    motion.bone(),
                    self.names()
                ),
            );
        };
        let finite = |key: Option<usize>, field: &'static str, v: f32| {
            if v.is_finite() {
                None
            } else {
                at(key, field, format!("{what}: {field} {v} is not finite"))
            }
        };
        let check_axis = |key: Option<usize>, field: &'static str, v: Vec3| {
            if v.is_finite() && v.length() > 1e-12 {
                None
            } else {
                at(
                    key,
                    field,
                    format!("{what}: axis {v} must be a finite, non-zero direction"),
                )
            }
        };
        match motion {
            Motion::Keys { keys, .. } => {
                if keys.is_empty() {
                    return at(None, "keys", format!("{what}: no keys; give at least one"));
                }
                for (k, key) in keys.iter().enumerate() {
                    let kw = format!("{what}, key {}", k + 1);
                    if !key.time.is_finite() {
                        return at(Some(k), "time", format!("{kw}: time is not finite"));
                    }
                    if k > 0 && key.time <= keys[k - 1].time {
                        return at(
                            Some(k),
                            "time",
                            format!(
                                "{kw}: keys out of order: time {} does not come after the \
                                 previous key's {}; list keys by increasing time",
                                key.time,
                                keys[k - 1].time
                            ),
                        );
                    }
                    if key.rotation.is_none() && key.translation.is_none() {
                        return at(
                            Some(k),
                            "time",
                            format!("{kw}: the key has neither rotation nor translation"),
                        );
                    }
                    if let Some(r) = key.rotation {
                        if let Some(p) = check_axis(Some(k), "axis", r.axis) {
                            return Some(p);
                        }
                        if let Some(p) = finite(Some(k), "degrees", r.degrees) {
                            return Some(p);
                        }
                    }
                    if let Some(t) = key.translation {
                        if self.bones[b].parent.is_some() {
                            return at(
                                Some(k),
                                "translation",
                                format!(
                                    "{kw}: translation is only for root bones, and '{}' has \
                                     parent '{}'; translate its root instead",
                                    motion.bone(),
                                    self.bones[b].parent.as_deref().unwrap_or_default()
                                ),
                            );
                        }
                        if !t.is_finite() {
                            return at(
                                Some(k),
                                "translation",
                                format!("{kw}: translation {t} is not finite"),
                            );
                        }
                    }
                }
                None
            }
            Motion::Bend {
                axis,
                degrees,
                start,
                duration,
                ..
            } => check_axis(None, "axis", *axis)
                .or_else(|| finite(None, "degrees", *degrees))
                .or_else(|| self.ramp_problem(&what, m, *start, *duration)),
            Motion::Twist {
                degrees,
                start,
                duration,
                ..
            } => finite(None, "degrees", *degrees)
                .or_else(|| self.ramp_problem(&what, m, *start, *duration)),
        }
    }

    fn ramp_problem(&self, what: &str, m: usize, start: f32, duration: f32) -> Option<Problem> {
        let place = |field| Place::Motion {
            motion: m,
            key: None,
            field,
        };
        if !start.is_finite() {
            return Some(Problem {
                place: place("start"),
                message: format!("{what}: start {start} is not finite"),
            });
        }
        if !(duration.is_finite() && duration >= 0.0) {
            return Some(Problem {
                place: place("duration"),
                message: format!("{what}: duration {duration} must be finite and ≥ 0 (seconds)"),
            });
        }
        None
    }

    /// The index of the bone named `name`.
    pub fn index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    fn parent_index(&self, b: usize) -> Option<usize> {
        self.bones[b].parent.as_deref().and_then(|p| self.index(p))
    }

    fn names(&self) -> String {
        self.bones
            .iter()
            .map(|b| format!("'{}'", b.name))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The time (seconds) after which the animation holds still: the last key's time or the
    /// end of the last ramp (0 without animation). A pipeline at `fps` poses frame f at
    /// `pose(f as f32 / fps)`.
    pub fn duration(&self) -> f32 {
        self.animation
            .iter()
            .map(|m| match m {
                Motion::Keys { keys, .. } => keys.last().map_or(0.0, |k| k.time),
                Motion::Bend {
                    start, duration, ..
                }
                | Motion::Twist {
                    start, duration, ..
                } => start + duration,
            })
            .fold(0.0, f32::max)
    }

    /// (head, tail) per bone at rest, in bone order.
    pub fn rest_segments(&self) -> Vec<(Vec3, Vec3)> {
        self.bones.iter().map(|b| (b.head, b.tail)).collect()
    }

    /// (head, tail) per bone in `pose`, in bone order.
    pub fn posed_segments(&self, pose: &Pose) -> Vec<(Vec3, Vec3)> {
        self.bones
            .iter()
            .zip(&pose.skin)
            .map(|(b, s)| (s.transform_point3(b.head), s.transform_point3(b.tail)))
            .collect()
    }

    /// Bone indices with every parent before its children (the rig must be valid).
    pub fn order(&self) -> Vec<usize> {
        let n = self.bones.len();
        let mut done = vec![false; n];
        let mut order = Vec::with_capacity(n);
        while order.len() < n {
            let before = order.len();
            for b in 0..n {
                if !done[b] && self.parent_index(b).is_none_or(|p| done[p]) {
                    done[b] = true;
                    order.push(b);
                }
            }
            assert!(
                order.len() > before,
                "rig has a parent cycle; validate it first"
            );
        }
        order
    }

    /// The pose at time `t` (seconds) under the animation (the rig must be valid).
    pub fn pose(&self, t: f32) -> Pose {
        let mut local = vec![Quat::IDENTITY; self.bones.len()];
        let mut translation = Vec3::ZERO;
        for motion in &self.animation {
            let Some(b) = self.index(motion.bone()) else {
                continue;
            };
            let bone = &self.bones[b];
            let r = match motion {
                Motion::Keys {
                    keys,
                    interpolation,
                    ..
                } => {
                    if let Some(tr) = keyed_translation(keys, *interpolation, t) {
                        translation += tr;
                    }
                    keyed_rotation(keys, *interpolation, t)
                }
                Motion::Bend {
                    axis,
                    degrees,
                    start,
                    duration,
                    ..
                } => Quat::from_axis_angle(
                    axis.normalize(),
                    degrees.to_radians() * ramp(t, *start, *duration),
                ),
                Motion::Twist {
                    degrees,
                    start,
                    duration,
                    ..
                } => Quat::from_axis_angle(
                    (bone.tail - bone.head).normalize(),
                    degrees.to_radians() * ramp(t, *start, *duration),
                ),
            };
            local[b] = (local[b] * r).normalize();
        }
        self.pose_local(&local, translation)
    }

    /// The pose for explicit local rotations (one per bone, about its head, in the parent's
    /// posed frame) and a translation of every root. Identity rotations and a zero
    /// translation give identity skin transforms exactly.
    pub fn pose_local(&self, local: &[Quat], root_translation: Vec3) -> Pose {
        assert_eq!(local.len(), self.bones.len(), "one rotation per bone");
        let n = self.bones.len();
        let mut skin = vec![Affine3A::IDENTITY; n];
        for b in self.order() {
            let head = self.bones[b].head;
            let about_head = if local[b] == Quat::IDENTITY {
                Affine3A::IDENTITY
            } else {
                Affine3A::from_translation(head)
                    * Affine3A::from_quat(local[b])
                    * Affine3A::from_translation(-head)
            };
            let up = match self.parent_index(b) {
                Some(p) => skin[p],
                None if root_translation == Vec3::ZERO => Affine3A::IDENTITY,
                None => Affine3A::from_translation(root_translation),
            };
            skin[b] = up * about_head;
        }
        let world = skin
            .iter()
            .zip(&self.bones)
            .map(|(s, b)| *s * Affine3A::from_translation(b.head))
            .collect();
        Pose { world, skin }
    }
}

/// 0 before `start`, 1 after `start + duration`, smoothstep between.
fn ramp(t: f32, start: f32, duration: f32) -> f32 {
    if t <= start {
        return if duration <= 0.0 && t >= start {
            1.0
        } else {
            0.0
        };
    }
    if duration <= 0.0 || t >= start + duration {
        return 1.0;
    }
    smoothstep((t - start) / duration)
}

fn smoothstep(s: f32) -> f32 {
    s * s * (3.0 - 2.0 * s)
}

/// The segment of a track around `t`: (a, b, s) with s the interpolation parameter.
fn bracket<T: Copy>(track: &[(f32, T)], interp: Interpolation, t: f32) -> Option<(T, T, f32)> {
    let first = track.first()?;
    if t <= first.0 {
        return Some((first.1, first.1, 0.0));
    }
    let last = track.last()?;
    if t >= last.0 {
        return Some((last.1, last.1, 0.0));
    }
    let i = track.partition_point(|k| k.0 <= t) - 1;
    let (a, b) = (track[i], track[i + 1]);
    let s = (t - a.0) / (b.0 - a.0);
    let s = match interp {
        Interpolation::Step => 0.0,
        Interpolation::Linear => s,
        Interpolation::Smooth => smoothstep(s),
    };
    Some((a.1, b.1, s))
}

fn keyed_translation(keys: &[Key], interp: Interpolation, t: f32) -> Option<Vec3> {
    let track: Vec<(f32, Vec3)> = keys
        .iter()
        .filter_map(|k| k.translation.map(|v| (k.time, v)))
        .collect();
    bracket(&track, interp, t).map(|(a, b, s)| a.lerp(b, s))
}

/// The keyed rotation at `t`: the angle interpolated about a shared axis, else a slerp.
fn keyed_rotation(keys: &[Key], interp: Interpolation, t: f32) -> Quat {
    let track: Vec<(f32, AxisAngle)> = keys
        .iter()
        .filter_map(|k| k.rotation.map(|r| (k.time, r)))
        .collect();
    let Some((a, b, s)) = bracket(&track, interp, t) else {
        return Quat::IDENTITY;
    };
    if s == 0.0 {
        return a.quat();
    }
    let (na, nb) = (a.axis.normalize(), b.axis.normalize());
    let same = na.cross(nb).length() <= 1e-6;
    if same || a.degrees == 0.0 || b.degrees == 0.0 {
        // A zero angle has any axis: take the other key's.
        let axis = if a.degrees == 0.0 { nb } else { na };
        let sign = |n: Vec3| if n.dot(axis) < 0.0 { -1.0 } else { 1.0 };
        let (da, db) = (sign(na) * a.degrees, sign(nb) * b.degrees);
        return Quat::from_axis_angle(axis, (da + s * (db - da)).to_radians());
    }
    a.quat().slerp(b.quat(), s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f32::consts::FRAC_PI_2;

    fn limb() -> Rig {
        Rig {
            bones: vec![
                Bone {
                    name: "upper".into(),
                    head: Vec3::ZERO,
                    tail: Vec3::new(0.5, 0.0, 0.0),
                    parent: None,
                },
                Bone {
                    name: "lower".into(),
                    head: Vec3::new(0.5, 0.0, 0.0),
                    tail: Vec3::new(1.0, 0.0, 0.0),
                    parent: Some("upper".into()),
                },
            ],
            mesh: None,
            animation: vec![],
        }
    }

    #[test]
    fn identity_pose_is_exact_and_rest_segments_are_the_bones() {
        let rig = limb();
        let p = rig.pose_local(&[Quat::IDENTITY; 2], Vec3::ZERO);
        assert!(p.skin.iter().all(|s| *s == Affine3A::IDENTITY));
        assert_eq!(p.world[1].translation, Vec3::new(0.5, 0.0, 0.0).into());
        assert_eq!(
            rig.rest_segments(),
            vec![
                (Vec3::ZERO, Vec3::new(0.5, 0.0, 0.0)),
                (Vec3::new(0.5, 0.0, 0.0), Vec3::X)
            ]
        );
        assert_eq!(rig.pose(3.0), p);
    }

    #[test]
    fn child_follows_parent() {
        // Parent turned 90° about z at the origin: the child's tail goes to (0, 1, 0); a
        // further 90° on the child folds it back to (-0.5, 0.5, 0).
        let mut rig = limb();
        let q = Quat::from_rotation_z(FRAC_PI_2);
        let p = rig.pose_local(&[q, Quat::IDENTITY], Vec3::ZERO);
        let seg = rig.posed_segments(&p);
        assert!((seg[1].0 - Vec3::new(0.0, 0.5, 0.0)).length() < 1e-6);
        assert!((seg[1].1 - Vec3::new(0.0, 1.0, 0.0)).length() < 1e-6);
        let p = rig.pose_local(&[q, q], Vec3::new(0.0, 0.0, 2.0));
        let seg = rig.posed_segments(&p);
        assert!(
            (seg[1].1 - Vec3::new(-0.5, 0.5, 2.0)).length() < 1e-6,
            "{seg:?}"
        );
        // Listed child first: the same pose.
        rig.bones.reverse();
        let p2 = rig.pose_local(&[q, q], Vec3::new(0.0, 0.0, 2.0));
        assert_eq!(p2.skin[0], p.skin[1]);
    }

    #[test]
    fn keyed_twist_interpolates_the_angle_through_180() {
        let mut rig = limb();
        let key = |time, degrees| Key {
            time,
            rotation: Some(AxisAngle {
                axis: Vec3::X,
                degrees,
            }),
            translation: None,
        };
        rig.animation = vec![Motion::Keys {
            bone: "lower".into(),
            interpolation: Interpolation::Linear,
            keys: vec![key(0.0, 0.0), key(1.0, 270.0)],
        }];
        rig.validate().unwrap();
        // At t = 2/3 the twist is 180°: (1, 0.1, 0) relative to the axis goes to -0.1 y.
        let p = rig.pose(2.0 / 3.0);
        let y = p.skin[1].transform_point3(Vec3::new(0.75, 0.1, 0.0));
        assert!((y - Vec3::new(0.75, -0.1, 0.0)).length() < 1e-5, "{y}");
        // At t = 1/3, 90°: +y goes to +z (not -z, which the short way would give at 270°).
        let p = rig.pose(1.0 / 3.0);
        let y = p.skin[1].transform_point3(Vec3::new(0.75, 0.1, 0.0));
        assert!((y - Vec3::new(0.75, 0.0, 0.1)).length() < 1e-5, "{y}");
    }

    #[test]
    fn step_smooth_opposite_axes_and_translation_tracks() {
        let mut rig = limb();
        let rot = |time, axis, degrees| Key {
            time,
            rotation: Some(AxisAngle { axis, degrees }),
            translation: None,
        };
        let angle_at = |rig: &Rig, t| {
            let p = rig.pose(t).skin[1].transform_point3(Vec3::new(0.5, 0.1, 0.0));
            // Turned about x through the head: the angle of (y, z).
            p.z.atan2(p.y).to_degrees()
        };
        for (interp, expect) in [
            (Interpolation::Step, 0.0),
            (Interpolation::Linear, 25.0),
            (Interpolation::Smooth, 100.0 * 0.25 * 0.25 * 2.5),
        ] {
            // The second key written with the opposite axis and angle: the same rotation.
            rig.animation = vec![Motion::Keys {
                bone: "lower".into(),
                interpolation: interp,
                keys: vec![rot(0.0, Vec3::X, 0.0), rot(1.0, -Vec3::X, -100.0)],
            }];
            let a = angle_at(&rig, 0.25);
            assert!((a - expect).abs() < 1e-3, "{interp:?}: {a} vs {expect}");
            assert!((angle_at(&rig, 5.0) - 100.0).abs() < 1e-3);
            assert!(angle_at(&rig, -1.0).abs() < 1e-3);
        }
        rig.animation = vec![Motion::Keys {
            bone: "upper".into(),
            interpolation: Interpolation::Linear,
            keys: vec![
                Key {
                    time: 1.0,
                    rotation: None,
                    translation: Some(Vec3::ZERO),
                },
                rot(2.0, Vec3::Z, 90.0),
                Key {
                    time: 3.0,
                    rotation: None,
                    translation: Some(Vec3::new(0.0, 0.0, 2.0)),
                },
            ],
        }];
        rig.validate().unwrap();
        assert_eq!(rig.duration(), 3.0);
        // At t = 2: half the translation; the rotation track has one key (held).
        let p = rig.pose(2.0);
        let tail = rig.posed_segments(&p)[1].1;
        assert!((tail - Vec3::new(0.0, 1.0, 1.0)).length() < 1e-5, "{tail}");
    }

    #[test]
    fn procedural_motions_compose_in_order() {
        let mut rig = limb();
        rig.animation = vec![
            Motion::Bend {
                bone: "lower".into(),
                axis: Vec3::Z,
                degrees: 90.0,
                start: 0.0,
                duration: 1.0,
            },
            Motion::Twist {
                bone: "lower".into(),
                degrees: 180.0,
                start: 1.0,
                duration: 1.0,
            },
        ];
        rig.validate().unwrap();
        assert_eq!(rig.duration(), 2.0);
        let p = rig.pose(0.5);
        // Half-way through the smooth ramp: 45°.
        let tail = p.skin[1].transform_point3(Vec3::X);
        let h = 0.5 * std::f32::consts::FRAC_1_SQRT_2;
        assert!(
            (tail - Vec3::new(0.5 + h, h, 0.0)).length() < 1e-5,
            "{tail}"
        );
        // Bent and twisted about its own (bent) axis: the tail stays, +z flips to -z.
        let p = rig.pose(2.0);
        let tail = p.skin[1].transform_point3(Vec3::X);
        assert!((tail - Vec3::new(0.5, 0.5, 0.0)).length() < 1e-5, "{tail}");
        let side = p.skin[1].transform_point3(Vec3::new(0.75, 0.0, 0.1));
        assert!(
            (side - Vec3::new(0.5, 0.25, -0.1)).length() < 1e-5,
            "{side}"
        );
    }

    #[test]
    fn validation_names_the_bone() {
        let mut rig = limb();
        rig.bones[1].parent = Some("uper".into());
        let e = rig.validate().unwrap_err().to_string();
        assert!(e.contains("'lower'") && e.contains("'uper'"), "{e}");
        let mut rig = limb();
        rig.bones[0].parent = Some("lower".into());
        let e = rig.validate().unwrap_err().to_string();
        assert!(e.contains("cycle") && e.contains("upper"), "{e}");
        let mut rig = limb();
        rig.bones[1].tail = rig.bones[1].head;
        let e = rig.validate().unwrap_err().to_string();
        assert!(e.contains("'lower' has zero length"), "{e}");
        let mut rig = limb();
        rig.bones[1].name = "upper".into();
        rig.bones[1].parent = None;
        assert!(rig.validate().unwrap_err().to_string().contains("twice"));
    }
}
