//! The `DistanceField` node's schedules (see [`crate::schedule`]): builds on keyframes, builds
//! split over frames, and interpolated builds made ahead of time from the node's own copy of
//! its mesh and voxeliser.

use crate::schedule::Schedule;
use imprint_core::{Boundary, BoundaryVariant, DistanceField, Mesh};
use imprint_stages::mesh::MeshSource;
use imprint_stages::sdf::FieldBuilder;
use imprint_stages::sdf::cpu::FieldBuild;
use imprint_stages::voxel::cpu::Voxelizer;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::Arc;

/// What consumers of a field node see on a frame.
#[derive(Clone)]
pub enum Published {
    /// One build.
    One(Arc<DistanceField>),
    /// The blend of the builds at keyframes `a` and `a + every` with weight `weight` on the
    /// second (interpolate).
    Blend {
        a: Arc<DistanceField>,
        b: Arc<DistanceField>,
        a_key: i64,
        every: u32,
        weight: f32,
    },
}

impl Published {}

/// The mesh and voxeliser an interpolated field evaluates at keyframe times.
pub struct Ahead {
    pub mesh: Box<MeshSource>,
    pub variant: BoundaryVariant,
    pub voxelizer: Voxelizer,
    pub fps: f32,
}

impl Ahead {
    fn boundary_at(&mut self, key: i64) -> imprint_core::Result<(Arc<Mesh>, Boundary)> {
        let mesh = self.mesh.at(key as f32 / self.fps);
        let b = self.voxelizer.run(&mesh, self.variant)?;
        Ok((Arc::new(mesh), b))
    }
}

/// A build under way: its keyframe and the next part to run.
#[derive(Serialize, Deserialize)]
struct Job {
    key: i64,
    next: u32,
    build: FieldBuild,
    /// The mesh it was voxelised from (interpolate), for error measurement.
    mesh: Option<Arc<Mesh>>,
}

/// A field node's state between frames (CPU builds; the GPU builds whole, on keyframes).
pub struct FieldSchedule {
    pub schedule: Schedule,
    pub band: f32,
    pub builder: FieldBuilder,
    pub ahead: Option<Ahead>,
    /// What it carries between frames (a checkpoint holds it).
    state: BuildState,
    /// Interpolate: the builds finished on this frame, with their meshes (for measurement).
    pub finished: Vec<(Arc<DistanceField>, Arc<Mesh>)>,
    /// Interpolate: builds the segment left behind, given back to `builder` once no one
    /// else holds them (last frame's value and a consumer's copy let go a frame or two
    /// later). A fresh build's buffers cost page faults: 48 MiB for a 128³ field and its
    /// cells, once every `every` frames.
    retired: Vec<Arc<DistanceField>>,
}

/// Retired builds kept waiting for their holders to let go; older ones are dropped (a
/// holder that keeps them longer keeps their memory, which is then not ours to reuse).
const RETIRED_KEPT: usize = 2;

/// A field node's builds between frames.
#[derive(Default, Serialize, Deserialize)]
pub struct BuildState {
    job: Option<Job>,
    /// Interpolate: builds by keyframe (the segment's two, and the next once finished).
    keys: BTreeMap<i64, Arc<DistanceField>>,
}

/// What a field node did on a frame.
pub struct BuildStep {
    /// A new value for consumers (None: they keep the last one).
    pub published: Option<Published>,
    /// Whether it computed anything (a build or a part of one).
    pub worked: bool,
    /// Whether a build from the input's current value began (the input is then up to date).
    pub began: bool,
}

impl FieldSchedule {
    pub fn new(schedule: Schedule, band: f32, ahead: Option<Ahead>) -> Self {
        FieldSchedule {
            schedule,
            band,
            builder: FieldBuilder::default(),
            ahead,
            state: BuildState::default(),
            finished: Vec::new(),
            retired: Vec::new(),
        }
    }

    /// Without interpolation: builds from `boundary` (the input's current value) when
    /// due. `first`: nothing published yet; `changed`: the input changed since the last
    /// build began.
    pub fn step(
        &mut self,
        frame: i64,
        first: bool,
        changed: bool,
        boundary: impl FnOnce() -> imprint_core::Result<Arc<Boundary>>,
    ) -> imprint_core::Result<BuildStep> {
        let sc = self.schedule;
        if let Some(job) = self.state.job.as_mut() {
            job.build.run_part(job.next, sc.split);
            job.next += 1;
            if job.next < sc.split {
                return Ok(BuildStep {
                    published: None,
                    worked: true,
                    began: false,
                });
            }
            let job = self.state.job.take().expect("a job");
            return Ok(BuildStep {
                published: Some(Published::One(Arc::new(
                    job.build.finish(&mut self.builder),
                ))),
                worked: true,
                began: false,
            });
        }
        if first || (sc.split == 1 && sc.is_key(frame) && changed) {
            let f = self.builder.build(&*boundary()?, self.band)?;
            return Ok(BuildStep {
                published: Some(Published::One(Arc::new(f))),
                worked: true,
                began: true,
            });
        }
        if sc.is_key(frame) && changed {
            let mut build = self.builder.start(&*boundary()?, self.band)?;
            build.run_part(0, sc.split);
            self.state.job = Some(Job {
                key: frame,
                next: 1,
                build,
                mesh: None,
            });
            return Ok(BuildStep {
                published: None,
                worked: true,
                began: true,
            });
        }
        Ok(BuildStep {
            published: None,
            worked: false,
            began: false,
        })
    }

    /// With interpolation: the segment around `frame` (builds made as needed, the next one
    /// in parts ahead of time); `first_frame` is the run's first. `is_static`: the mesh never
    /// changes, so one build serves every keyframe.
    pub fn step_interpolated(
        &mut self,
        frame: i64,
        first_frame: i64,
        is_static: bool,
    ) -> imprint_core::Result<BuildStep> {
        let sc = self.schedule;
        self.finished.clear();
        self.recycle_retired();
        let mut worked = false;
        if is_static {
            if self.state.keys.is_empty() {
                let f = self.build_now(first_frame)?;
                self.state.keys.insert(first_frame, f);
                return Ok(BuildStep {
                    published: Some(Published::One(self.state.keys[&first_frame].clone())),
                    worked: true,
                    began: true,
                });
            }
            return Ok(BuildStep {
                published: None,
                worked: false,
                began: false,
            });
        }
        // The next build's part for this frame, if any (it finishes on the frame that first
        // needs it).
        if let Some((key, part)) = sc.ahead_part_at(frame)
            && !self.state.keys.contains_key(&key)
        {
            if part == 0 {
                let ahead = self
                    .ahead
                    .as_mut()
                    .expect("interpolated fields have a mesh");
                let (mesh, b) = ahead.boundary_at(key)?;
                let build = self.builder.start(&b, self.band)?;
                self.state.job = Some(Job {
                    key,
                    next: 0,
                    build,
                    mesh: Some(mesh),
                });
            }
            if let Some(job) = self
                .state
                .job
                .as_mut()
                .filter(|j| j.key == key && j.next == part)
            {
                job.build.run_part(part, sc.split);
                job.next += 1;
                worked = true;
                if job.next == sc.split {
                    let job = self.state.job.take().expect("a job");
                    let f = Arc::new(job.build.finish(&mut self.builder));
                    self.finished.push((
                        f.clone(),
                        job.mesh.expect("interpolated jobs keep the mesh"),
                    ));
                    self.state.keys.insert(key, f);
                }
            }
        }
        let (a, weight) = sc.segment(frame, first_frame);
        let b = a + sc.every as i64;
        for k in [a, b] {
            if !self.state.keys.contains_key(&k) {
                let f = self.build_now(k)?;
                self.state.keys.insert(k, f);
                worked = true;
            }
        }
        let kept = self.state.keys.split_off(&a);
        let left = std::mem::replace(&mut self.state.keys, kept);
        self.retired.extend(left.into_values());
        let excess = self.retired.len().saturating_sub(RETIRED_KEPT);
        self.retired.drain(..excess);
        Ok(BuildStep {
            published: Some(Published::Blend {
                a: self.state.keys[&a].clone(),
                b: self.state.keys[&b].clone(),
                a_key: a,
                every: sc.every,
                weight,
            }),
            worked,
            began: worked,
        })
    }

    /// What it carries between frames, for a checkpoint.
    pub fn state(&self) -> &BuildState {
        &self.state
    }

    pub fn set_state(&mut self, state: BuildState) {
        self.state = state;
    }

    /// Gives the retired builds no one else holds back to the builder, for their buffers.
    fn recycle_retired(&mut self) {
        for f in std::mem::take(&mut self.retired) {
            match Arc::try_unwrap(f) {
                Ok(f) => self.builder.recycle(f),
                Err(held) => self.retired.push(held),
            }
        }
    }

    /// Keyframe `key`'s build, whole, now.
    fn build_now(&mut self, key: i64) -> imprint_core::Result<Arc<DistanceField>> {
        let ahead = self
            .ahead
            .as_mut()
            .expect("interpolated fields have a mesh");
        let (mesh, b) = ahead.boundary_at(key)?;
        let f = Arc::new(self.builder.build(&b, self.band)?);
        self.finished.push((f.clone(), mesh));
        Ok(f)
    }
}
