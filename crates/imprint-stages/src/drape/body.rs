//! A cloth's body read through depth maps, frame after frame: fixed cameras over the body's
//! swept box (over its first pose when the box is not known before running), rebuilt wider
//! if the body leaves that box, and the body's pose at the previous frame's end, the start
//! of this one. The cloth reads [`super::DepthCollider`]s made from it every substep.

use super::{DepthCamera, DepthColliderParams, DepthPose};
use imprint_core::raster::rasterize_depth_with;
use imprint_core::{Aabb, Mesh, Result};
use serde::{Deserialize, Serialize};
use std::sync::Arc;

pub struct DepthBody {
    params: DepthColliderParams,
    eps: f32,
    /// The box the body sweeps over the run, when known before running.
    swept: Option<Aabb>,
    /// The box the cameras were made for, and the cameras.
    camera: Option<(Aabb, DepthCamera)>,
    previous: Option<(Arc<Mesh>, Arc<DepthPose>)>,
}

/// What a [`DepthBody`] carries between frames: the cameras' box and the last pose's mesh
/// (its maps are rendered again on load; the same mesh gives the same maps).
#[derive(Serialize, Deserialize)]
pub struct DepthBodyState {
    camera_box: Option<Aabb>,
    previous: Option<Mesh>,
}

impl DepthBody {
    /// A body seen with `params` by a cloth of contact distance `eps`; `swept`: the box it
    /// sweeps over the run, when known.
    pub fn new(params: DepthColliderParams, eps: f32, swept: Option<Aabb>) -> Self {
        DepthBody {
            params,
            eps,
            swept,
            camera: None,
            previous: None,
        }
    }

    /// The poses at the frame's start (None on the first frame) and end, for `mesh`.
    pub fn poses(&mut self, mesh: &Arc<Mesh>) -> Result<(Option<Arc<DepthPose>>, Arc<DepthPose>)> {
        let bounds = mesh.bounds();
        let prev_bounds = self.previous.as_ref().map(|(m, _)| m.bounds());
        let seen =
            |c: &(Aabb, DepthCamera)| c.1.sees(&bounds) && prev_bounds.is_none_or(|b| c.1.sees(&b));
        if !self.camera.as_ref().is_some_and(seen) {
            // First frame: the swept box if known. Later (the body left the box): the two
            // poses' box grown by a quarter, so that this happens rarely.
            let mut b = match (&self.camera, self.swept) {
                (None, Some(s)) => s.union(&bounds),
                _ => bounds,
            };
            if let Some(p) = prev_bounds {
                b = b.union(&p);
            }
            if self.camera.is_some() || self.swept.is_none() {
                let grow = 0.25 * b.size().max_element();
                b.min -= glam::Vec3::splat(grow);
                b.max += glam::Vec3::splat(grow);
            }
            self.set_camera(b)?;
        }
        let camera = &self.camera.as_ref().expect("set above").1;
        let end = match &self.previous {
            // A body that did not change keeps its maps.
            Some((m, pose)) if Arc::ptr_eq(m, mesh) => pose.clone(),
            _ => Arc::new(camera.pose(mesh, rasterize_depth_with)?),
        };
        let start = self
            .previous
            .replace((mesh.clone(), end.clone()))
            .map(|(_, p)| p);
        Ok((start, end))
    }

    /// The cameras (after [`DepthBody::poses`]).
    pub fn camera(&self) -> Option<&DepthCamera> {
        self.camera.as_ref().map(|(_, c)| c)
    }

    /// Cameras over box `b`; the previous pose is rendered again through them.
    fn set_camera(&mut self, b: Aabb) -> Result<()> {
        let camera = DepthCamera::new(&b, &self.params, self.eps)?;
        if let Some((m, pose)) = &mut self.previous {
            *pose = Arc::new(camera.pose(m, rasterize_depth_with)?);
        }
        self.camera = Some((b, camera));
        Ok(())
    }

    pub fn state(&self) -> DepthBodyState {
        DepthBodyState {
            camera_box: self.camera.as_ref().map(|(b, _)| *b),
            previous: self.previous.as_ref().map(|(m, _)| (**m).clone()),
        }
    }

    /// Takes back what [`DepthBody::state`] gave.
    pub fn set_state(&mut self, s: DepthBodyState) -> Result<()> {
        self.camera = None;
        self.previous = None;
        if let Some(b) = s.camera_box {
            let camera = DepthCamera::new(&b, &self.params, self.eps)?;
            if let Some(m) = s.previous {
                let pose = camera.pose(&m, rasterize_depth_with)?;
                self.previous = Some((Arc::new(m), Arc::new(pose)));
            }
            self.camera = Some((b, camera));
        }
        Ok(())
    }
}
