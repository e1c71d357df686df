//! Skeletons: what the skinning methods need of a rig, whichever file it came from: the
//! project's rig RON (bones as segments, procedural bends and keys; [`super::rig`]) or a
//! glTF skin with one of its clips ([`imprint_core::gltf`]).
//!
//! Both give, per bone (a glTF joint is a bone here), a name, a parent, a rest segment
//! (head → tail: what particles are tied to and joint sections are measured across) and, at
//! any time, a [`Pose`]: each bone's skinning transform (rest point → posed point) and posed
//! frame. A glTF joint's skinning transform is `jointWorld(t) · inverseBind`, its frame
//! `jointWorld(t)`; its segment runs from its bind position to the mean of its children's
//! (`Document::joint_segments`).
//!
//! **Scale.** glTF joints may scale. A stretch all joints share at the first frame (an
//! armature exported at 100× for centimetres) is moved into the rest mesh, so the transforms
//! left are rigid. Linear blend skinning takes the rest as it is; dual quaternions and the
//! particles' bone targets need rigid transforms, so [`Skeleton::rigid_pose`] keeps each
//! transform's rotation and translation and reports the largest scale it dropped.

use super::rig::{Pose, Rig};
use super::weights::{self, Weights};
use glam::{Affine3A, Mat4, Vec3};
use imprint_core::gltf::{ClipTime, Document};
use imprint_core::{Error, Mesh, Result};
use std::sync::Arc;

/// A skeleton and its animation, ready to pose at any time.
#[derive(Clone, Debug)]
pub struct Skeleton {
    /// How the file's skinning transforms S are re-expressed: the posed mesh is
    /// `post · S · rest⁻¹` applied to the rest mesh, which is the file's mesh under `rest`
    /// (None: both identity). See [`Skeleton::fitted`] and the module doc's **Scale**.
    map: Option<Map>,
    /// Per bone: its name (unique within the file only for rigs; glTF names may repeat).
    pub names: Vec<String>,
    /// Per bone: its parent bone.
    pub parents: Vec<Option<usize>>,
    /// Per bone: (head, tail) at rest.
    pub segments: Vec<(Vec3, Vec3)>,
    source: Source,
}

#[derive(Clone, Copy, Debug)]
struct Map {
    post: Affine3A,
    rest: Affine3A,
    rest_inv: Affine3A,
}

#[derive(Clone, Debug)]
enum Source {
    Rig(Box<Rig>),
    Gltf {
        doc: Arc<Document>,
        /// The document's mesh welded by position (files split vertices along UV seams,
        /// which opens the surface for the particle fill and cracks snow layers), and per
        /// welded vertex the file's vertex whose weights it takes.
        welded: Arc<Mesh>,
        origin: Vec<u32>,
        /// The clip's name; none poses the bind pose.
        clip: Option<String>,
        time: ClipTime,
    },
}

impl Skeleton {
    /// The skeleton of a (validated) rig RON.
    pub fn from_rig(rig: Rig) -> Self {
        let names = rig.bones.iter().map(|b| b.name.clone()).collect();
        let parents = (0..rig.bones.len())
            .map(|b| {
                let parent = rig.bones[b].parent.as_deref()?;
                rig.index(parent)
            })
            .collect();
        Skeleton {
            map: None,
            names,
            parents,
            segments: rig.rest_segments(),
            source: Source::Rig(Box::new(rig)),
        }
    }

    /// The skin of a glTF document, animated by the clip named `clip` (none: held at the
    /// bind pose) at the pipeline's time mapped through `time`. Errors: a document without a
    /// skin, an unknown clip (the message lists the clips there are).
    pub fn from_gltf(doc: Arc<Document>, clip: Option<&str>, time: ClipTime) -> Result<Self> {
        let Some(skin) = &doc.skin else {
            return Err(Error::Invalid(format!(
                "{}: has no skin (no joints and weights), so it cannot drive a Skin node; \
                 load it with a Mesh node instead, or export the character with its armature",
                doc.path.display()
            )));
        };
        if let Some(name) = clip {
            doc.clip(name)?;
        }
        if !(time.speed.is_finite() && time.offset.is_finite()) {
            return Err(Error::Invalid(format!(
                "clip speed {} and offset {} must be finite",
                time.speed, time.offset
            )));
        }
        let (welded, origin) = doc.mesh.welded_with_map();
        let sk = Skeleton {
            map: None,
            names: skin.joints.iter().map(|j| j.name.clone()).collect(),
            parents: skin.joints.iter().map(|j| j.parent).collect(),
            segments: doc.joint_segments(),
            source: Source::Gltf {
                clip: clip.map(str::to_string),
                welded: Arc::new(welded),
                origin,
                doc,
                time,
            },
        };
        // A skin whose joints all stretch the mesh alike (an armature exported at 100× for
        // centimetres, or a scaled mesh node baked into the inverse binds) scales the mesh:
        // that stretch moves into the rest mesh, so the transforms left are rigid, as dual
        // quaternions and particles need.
        Ok(match sk.common_stretch() {
            Some(s) => sk.remapped(Affine3A::IDENTITY, Affine3A::from_scale(s)),
            None => sk,
        })
    }

    /// The stretch along the rest axes that every skinning transform applies at the first
    /// frame, when they share one that is not 1 (each transform is then a rigid motion after
    /// it, to 1e-3).
    fn common_stretch(&self) -> Option<Vec3> {
        let skin = self.file_pose(0.0).skin;
        let s = skin.first()?.to_scale_rotation_translation().0;
        if !(s.is_finite() && s.min_element() > 0.0) || (s - Vec3::ONE).abs().max_element() < 1e-3 {
            return None;
        }
        let unstretch = Affine3A::from_scale(s.recip());
        let rigid = skin.iter().all(|m| {
            let k = (*m * unstretch).to_scale_rotation_translation().0;
            (k - Vec3::ONE).abs().max_element() < 1e-3
        });
        rigid.then_some(s)
    }

    /// Composes `post` after the output and `rest` on the rest side (see [`Map`]): the rest
    /// mesh and segments move by `post · rest`.
    fn remapped(mut self, post: Affine3A, rest: Affine3A) -> Self {
        let old = self.map.unwrap_or(Map {
            post: Affine3A::IDENTITY,
            rest: Affine3A::IDENTITY,
            rest_inv: Affine3A::IDENTITY,
        });
        let moved = post * rest;
        for (h, t) in &mut self.segments {
            (*h, *t) = (moved.transform_point3(*h), moved.transform_point3(*t));
        }
        if let Source::Gltf { welded, .. } = &mut self.source {
            let mut m = (**welded).clone();
            m.transform(glam::Mat4::from(moved));
            *welded = Arc::new(m);
        }
        let new_rest = moved * old.rest;
        self.map = Some(Map {
            post: post * old.post,
            rest: new_rest,
            rest_inv: new_rest.inverse(),
        });
        self
    }

    /// The skeleton and its bound mesh moved into `fit` (a uniform scale and a translation:
    /// a character exported in centimetres, or far from the origin, brought where the scene
    /// wants it). Skinning transforms are conjugated (`fit · skin · fit⁻¹`), so rigid ones
    /// stay rigid and the mesh deforms as it did, at the new size and place.
    pub fn fitted(self, fit: Affine3A) -> Self {
        self.remapped(fit, Affine3A::IDENTITY)
    }

    pub fn len(&self) -> usize {
        self.names.len()
    }

    pub fn is_empty(&self) -> bool {
        self.names.is_empty()
    }

    /// The pose at the pipeline's time `t` (seconds).
    pub fn pose(&self, t: f32) -> Pose {
        let pose = self.file_pose(t);
        match self.map {
            None => pose,
            Some(m) => Pose {
                world: pose.world.iter().map(|w| m.post * *w).collect(),
                skin: pose.skin.iter().map(|s| m.post * *s * m.rest_inv).collect(),
            },
        }
    }

    /// The pose in the file's own space.
    fn file_pose(&self, t: f32) -> Pose {
        match &self.source {
            Source::Rig(rig) => rig.pose(t),
            Source::Gltf {
                doc, clip, time, ..
            } => {
                let clip = clip
                    .as_deref()
                    .map(|c| doc.clip(c).expect("checked when the skeleton was made"));
                let local = clip.map_or(0.0, |c| time.local(c, t));
                let affine = |m: Vec<Mat4>| m.into_iter().map(Affine3A::from_mat4).collect();
                Pose {
                    world: affine(doc.joint_worlds(clip, local)),
                    skin: affine(doc.skin_matrices(clip, local)),
                }
            }
        }
    }

    /// [`Skeleton::pose`] with every skinning transform made rigid (rotation and translation
    /// kept, scale dropped), and the largest relative scale dropped (0 for a rig RON, whose
    /// transforms are rigid by construction).
    pub fn rigid_pose(&self, t: f32) -> (Pose, f32) {
        let mut pose = self.pose(t);
        if matches!(self.source, Source::Rig(_)) {
            return (pose, 0.0);
        }
        let mut dropped = 0.0f32;
        for m in &mut pose.skin {
            let (s, r, tr) = m.to_scale_rotation_translation();
            dropped = dropped.max((s - Vec3::ONE).abs().max_element());
            *m = Affine3A::from_rotation_translation(r.normalize(), tr);
        }
        (pose, dropped)
    }

    /// The rest pose: identity skinning transforms.
    pub fn rest_pose(&self) -> Pose {
        match &self.source {
            Source::Rig(rig) => {
                rig.pose_local(&vec![glam::Quat::IDENTITY; rig.bones.len()], Vec3::ZERO)
            }
            Source::Gltf { doc, .. } => {
                let fit = self.map.map_or(Affine3A::IDENTITY, |m| m.post);
                let world = doc.joint_worlds(None, 0.0);
                Pose {
                    world: world
                        .into_iter()
                        .map(|w| fit * Affine3A::from_mat4(w))
                        .collect(),
                    skin: vec![Affine3A::IDENTITY; self.len()],
                }
            }
        }
    }

    /// The bones' segments carried by `pose`.
    pub fn posed_segments(&self, pose: &Pose) -> Vec<(Vec3, Vec3)> {
        self.segments
            .iter()
            .zip(&pose.skin)
            .map(|(&(h, t), s)| (s.transform_point3(h), s.transform_point3(t)))
            .collect()
    }

    /// The weights the file carries (a glTF skin's, the 4 largest per vertex renormalised),
    /// for its mesh ([`Skeleton::bound_mesh`], `vertices` vertices); none for a rig RON.
    pub fn file_weights(&self, vertices: usize) -> Result<Option<Weights>> {
        let Source::Gltf { doc, origin, .. } = &self.source else {
            return Ok(None);
        };
        if origin.len() != vertices {
            return Err(Error::Invalid(format!(
                "{}: its skin weighs the {} vertices of its own mesh but the mesh to skin has \
                 {}; skin the document's own mesh (leave the Skin node's `mesh` out)",
                doc.path.display(),
                origin.len(),
                vertices
            )));
        }
        let lists: Vec<Vec<(u32, f32)>> = origin
            .iter()
            .map(|&v| doc.influences[v as usize].clone())
            .collect();
        weights::from_influences(&lists, self.len()).map(Some)
    }

    /// The document's bind-pose mesh, welded by position, when the skeleton came from one.
    pub fn bound_mesh(&self) -> Option<&Arc<Mesh>> {
        match &self.source {
            Source::Gltf { welded, .. } => Some(welded),
            Source::Rig(_) => None,
        }
    }
}
