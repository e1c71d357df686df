//! The executor: builds each node's stage once, then runs the plan frame by frame.
//!
//! A node computes on a frame only when one of its inputs changed (a static mesh is loaded
//! once and everything downstream of it reuses its result); writers write every `every`-th
//! frame. A resource stays where its producer made it: a GPU boundary feeding a GPU field never
//! comes back to the CPU; only writers and error measurement read fields back.

use crate::field_stage::{Ahead, FieldSchedule, Published};
use crate::plan::Plan;
use crate::report::{NodeReport, Report};
use crate::schema::{
    Backend, CameraSpec, GridChoice, HeightGrid, HeightmapFormat, Measure, MeshFormat, NodeSpec,
    RenderNode, RenderObject,
};
use imprint_core::bvh::Bvh;
use imprint_core::raster::rasterize_depth_with;
use imprint_core::{Boundary, BoundaryVariant, DistanceField, Error, GridSpec, HeightField, Mesh};
use imprint_gpu::GpuContext;
use imprint_gpu::raster::GpuRasterizer;
use imprint_render::frame::{GroundGrid, Object, RenderOptions, Scene, orbit, render_cpu};
use imprint_render::gpu_frame::GpuRenderer;
use imprint_render::sequence::{ContactSheet, GifWriter};
use imprint_render::slice::SliceOptions;
use imprint_stages::cloth::gpu::{GpuCloth, GpuCollider};
use imprint_stages::cloth::{Body, ClothSim};
use imprint_stages::depth::{HeightRegion, HeightView};
use imprint_stages::drape::{DepthCamera, DepthColliderParams, DepthPose};
use imprint_stages::mesh::MeshSource;
use imprint_stages::sdf::gpu::GpuField;
use imprint_stages::voxel::cpu::Voxelizer;
use imprint_stages::voxel::gpu::GpuBoundary;
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// How to run a plan.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Output folder for writers and `report.json`.
    pub out: PathBuf,
    /// Frames to run (default: all the file declares).
    pub frames: Option<Range<u32>>,
    /// Overrides the backend of the file and of every node.
    pub backend: Option<Backend>,
}

#[derive(Clone)]
enum Value {
    Mesh(Arc<Mesh>),
    Boundary(BoundaryValue),
    Field(FieldValue),
    Heights(Arc<HeightField>),
}

#[derive(Clone)]
enum BoundaryValue {
    Cpu(Arc<Boundary>),
    Gpu(Arc<GpuBoundary>),
}

/// A cloth collider over one frame: start field (if blending), end field, span of the blend.
type BodyFields = (Option<Arc<DistanceField>>, Arc<DistanceField>, (f32, f32));

#[derive(Clone)]
enum FieldValue {
    Cpu(Arc<DistanceField>),
    Gpu(Arc<GpuField>),
    /// Two builds and the weight between them (an interpolated field node).
    Blend(Published),
}

enum Stage {
    Mesh(Box<MeshSource>),
    Voxelize {
        input: String,
        spec: GridSpec,
        variant: BoundaryVariant,
        gpu: bool,
        cpu: Option<Voxelizer>,
    },
    Field {
        input: String,
        gpu: bool,
        measure: Measure,
        /// The Mesh node behind the boundary: the exact reference for error measurement.
        mesh_node: String,
        measured: u32,
        /// Builds finished so far (`Measure::Every` counts these).
        builds: u32,
        /// Builds, parts of builds and interpolation (see `field_stage`).
        sched: Box<FieldSchedule>,
    },
    WriteField {
        input: String,
        dir: PathBuf,
        npy: bool,
        slices: Vec<SliceOptions>,
        every: u32,
    },
    WriteMesh {
        input: String,
        dir: PathBuf,
        format: MeshFormat,
        every: u32,
    },
    Cloth {
        colliders: Vec<String>,
        sim: Box<ClothSim>,
        /// The colliders' fields at the end of the previous frame: the start of this one.
        previous: Vec<Arc<DistanceField>>,
        /// The GPU cloth when the node runs on the GPU, and the colliders it saw last frame
        /// (uploaded once per field: a static field is not uploaded again).
        gpu: Option<Box<GpuCloth>>,
        gpu_previous: Vec<(Arc<DistanceField>, Arc<GpuCollider>)>,
        /// Bodies read through depth maps (CPU cloth only).
        depth: Vec<DepthBody>,
    },
    /// A ground that keeps its prints from frame to frame.
    Ground {
        objects: Vec<String>,
        sim: Box<imprint_stages::ground::GroundSim>,
        /// The `accumulate` input and its heights last frame (their rise is added).
        accumulate: Option<String>,
        last: Option<Arc<HeightField>>,
        /// The GPU rasteriser for the contact view, when the node runs on the GPU.
        gpu: Option<Box<GpuRasterizer>>,
        /// The ground's passes on the GPU too (heights kept there), when they can be.
        gpu_ground: Option<Box<imprint_stages::ground::gpu::GpuGround>>,
    },
    /// A mesh deformed by a rig, every frame.
    Skin {
        input: Option<String>,
        stage: Box<crate::skin_stage::SkinStage>,
    },
    /// A garment fitted out of a body, every frame the body or garment changes.
    Drape {
        body: String,
        garment: String,
        params: imprint_stages::drape::DrapeParams,
        /// The GPU rasteriser for the views, when the node runs on the GPU.
        gpu: Option<Box<GpuRasterizer>>,
    },
    /// Snow building up on meshes (and a flat ground) over the run.
    Snow {
        meshes: Vec<String>,
        sim: Box<imprint_stages::snow::SnowSim>,
        ground: Option<HeightField>,
        /// The GPU rasteriser for the depth maps, when the node runs on the GPU, and the
        /// look-ups and slides there too.
        gpu: Option<Box<GpuRasterizer>>,
        gpu_relax: Box<imprint_stages::snow::gpu::GpuSnowRelax>,
    },
    Heightmap {
        input: String,
        region: HeightRegion,
        view: HeightView,
        /// The GPU rasteriser when the node runs on the GPU.
        gpu: Option<Box<GpuRasterizer>>,
    },
    WriteHeightmap {
        input: String,
        dir: PathBuf,
        formats: Vec<HeightmapFormat>,
        every: u32,
    },
    Render {
        node: Box<RenderNode>,
        out: PathBuf,
        /// Frames rendered so far (the contact sheet and GIF count these).
        rendered: u32,
        sheet: Option<ContactSheet>,
        gif: Option<GifWriter>,
        /// The GPU renderer when the node runs on the GPU.
        gpu: Option<Box<GpuRenderer>>,
    },
}

/// A resource as consumers saw it on one frame (see [`Observer`]).
pub enum Observed<'a> {
    Mesh(&'a Mesh),
    Field(&'a DistanceField),
    Heights(&'a HeightField),
}

/// Sees every resource a run produces, frame by frame: what `imprint sweep` compares between
/// runs. Boundaries are not shown (they have no error metric of their own).
pub trait Observer {
    /// Called after `node` ran (or reused its result) on `frame`, with the value its consumers
    /// see on that frame. The time it takes (and a field's read-back or blend for it) is left
    /// out of the report's frame times.
    fn observe(&mut self, node: &str, frame: u32, value: Observed<'_>);

    /// Whether to show `node` at all (a field may need a read-back or a blend to be shown).
    fn wants(&self, _node: &str) -> bool {
        true
    }
}

/// Runs `plan`; `progress(done, total)` is called after every frame.
pub fn run(
    plan: &Plan,
    opts: &RunOptions,
    progress: &mut dyn FnMut(u32, u32),
) -> crate::Result<Report> {
    run_observed(plan, opts, progress, None)
}

/// [`run`], showing every frame's resources to `observer`.
pub fn run_observed(
    plan: &Plan,
    opts: &RunOptions,
    progress: &mut dyn FnMut(u32, u32),
    mut observer: Option<&mut dyn Observer>,
) -> crate::Result<Report> {
    let frames = opts.frames.clone().unwrap_or(0..plan.file.frames);
    if frames.is_empty() || frames.end > plan.file.frames {
        return Err(Error::Invalid(format!(
            "--frames {}..{} is outside the pipeline's 0..{}",
            frames.start, frames.end, plan.file.frames
        ))
        .into());
    }
    let start = Instant::now();
    let mut gpu: Option<&'static GpuContext> = None;
    let mut stages = build_stages(plan, opts, &mut gpu)?;
    let mut report = Report {
        pipeline: plan.source.name.clone(),
        fps: plan.file.fps,
        threads: rayon::current_num_threads(),
        pruned: plan.pruned.clone(),
        ..Default::default()
    };
    for name in &plan.order {
        let node = &plan.file.nodes[name];
        let on_gpu = match &stages[name] {
            Stage::Voxelize { gpu, .. } | Stage::Field { gpu, .. } => *gpu,
            Stage::Heightmap { gpu, .. }
            | Stage::Ground { gpu, .. }
            | Stage::Snow { gpu, .. }
            | Stage::Drape { gpu, .. } => gpu.is_some(),
            Stage::Render { gpu, .. } => gpu.is_some(),
            Stage::Cloth { gpu, .. } => gpu.is_some(),
            Stage::Skin { stage, .. } => stage.on_gpu(),
            _ => false,
        };
        report.nodes.insert(
            name.clone(),
            NodeReport {
                kind: node.kind().to_string(),
                backend: if on_gpu { "gpu" } else { "cpu" }.to_string(),
                ..Default::default()
            },
        );
    }
    report.adapter = gpu.map(|g| g.adapter_name());

    let mut values: BTreeMap<String, Value> = BTreeMap::new();
    // A node's output version goes up with every new value; a node recomputes on its
    // keyframes only when its inputs' versions moved since it last began computing.
    let mut versions: BTreeMap<String, u64> = BTreeMap::new();
    let mut seen: BTreeMap<String, Vec<u64>> = BTreeMap::new();
    let first_frame = frames.start as i64;
    let total = frames.len() as u32;
    for (done, frame) in frames.clone().enumerate() {
        let frame_start = Instant::now();
        let mut observed_ms = 0.0;
        let time = frame as f32 / plan.file.fps;
        let mut cpu_fields: BTreeMap<String, Arc<DistanceField>> = BTreeMap::new();
        for name in &plan.order {
            let first_run = !values.contains_key(name);
            let spec = &plan.file.nodes[name];
            let sc = spec.schedule();
            let key = sc.is_key(frame as i64);
            let input_versions: Vec<u64> = spec
                .inputs()
                .iter()
                .map(|(_, i, _)| versions.get(*i).copied().unwrap_or(0))
                .collect();
            let changed = seen.get(name) != Some(&input_versions);
            // Computed from the inputs as they are now (they are then up to date).
            let mut began = false;
            // A field node published a new build (not only a new blend weight).
            let mut new_build = false;
            let stage = stages
                .get_mut(name)
                .expect("every planned node has a stage");
            let nr = report.nodes.get_mut(name).expect("report has every node");
            let t0 = Instant::now();
            let did_run = match stage {
                Stage::Mesh(source) => {
                    if first_run || !source.is_static() {
                        began = true;
                        let mesh = source.at(time);
                        if let Some(i) = mesh.positions.iter().position(|p| !p.is_finite()) {
                            return Err(Error::Numerical {
                                node: name.clone(),
                                frame,
                                message: format!("vertex {i} is not finite after the motion"),
                                hint: "lower the motion's amplitude or degrees".into(),
                            }
                            .into());
                        }
                        nr.metrics
                            .insert("triangles".into(), mesh.triangles.len().into());
                        values.insert(name.clone(), Value::Mesh(Arc::new(mesh)));
                        true
                    } else {
                        false
                    }
                }
                Stage::Voxelize {
                    input,
                    spec,
                    variant,
                    gpu: on_gpu,
                    cpu,
                } => {
                    if first_run || (key && changed) {
                        began = true;
                        let Some(Value::Mesh(mesh)) = values.get(input.as_str()) else {
                            unreachable!("edges are typed")
                        };
                        let b = if *on_gpu {
                            let ctx = gpu.expect("GPU chosen at build");
                            let b = imprint_stages::voxel::gpu::voxelize_gpu(
                                ctx, mesh, spec, *variant,
                            )?;
                            ctx.wait()?;
                            BoundaryValue::Gpu(Arc::new(b))
                        } else {
                            let vox = cpu.as_mut().expect("CPU voxeliser built");
                            let b = vox.run(mesh, *variant)?;
                            nr.metrics.insert("boundary_points".into(), b.len().into());
                            BoundaryValue::Cpu(Arc::new(b))
                        };
                        values.insert(name.clone(), Value::Boundary(b));
                        true
                    } else {
                        false
                    }
                }
                Stage::Field {
                    input,
                    gpu: on_gpu,
                    sched,
                    ..
                } => {
                    let step = if sched.schedule.interpolate {
                        sched.step_interpolated(
                            frame as i64,
                            first_frame,
                            sched.ahead.as_ref().is_some_and(|a| a.mesh.is_static()),
                        )?
                    } else if *on_gpu {
                        if first_run || (key && changed) {
                            let Some(Value::Boundary(b)) = values.get(input.as_str()) else {
                                unreachable!("edges are typed")
                            };
                            let ctx = gpu.expect("GPU chosen at build");
                            let gb = match b {
                                BoundaryValue::Gpu(g) => g.clone(),
                                BoundaryValue::Cpu(c) => Arc::new(GpuBoundary::from_cpu(ctx, c)?),
                            };
                            let f =
                                imprint_stages::sdf::gpu::build_field_gpu(ctx, &gb, sched.band)?;
                            ctx.wait()?;
                            values.insert(name.clone(), Value::Field(FieldValue::Gpu(Arc::new(f))));
                            bump(&mut versions, name);
                            began = true;
                            new_build = true;
                        }
                        crate::field_stage::Step {
                            published: None,
                            worked: began,
                            began,
                        }
                    } else {
                        // Last frame's field, if nobody holds it any more, lends its buffers.
                        if (first_run || (key && changed))
                            && sched.schedule.split == 1
                            && let Some(Value::Field(FieldValue::Cpu(old))) =
                                values.get(name.as_str())
                            && Arc::strong_count(old) == 1
                            && let Some(Value::Field(FieldValue::Cpu(old))) =
                                values.remove(name.as_str())
                            && let Ok(old) = Arc::try_unwrap(old)
                        {
                            sched.builder.recycle(old);
                        }
                        let Some(Value::Boundary(b)) = values.get(input.as_str()) else {
                            unreachable!("edges are typed")
                        };
                        let cb = match b {
                            BoundaryValue::Cpu(c) => c.clone(),
                            BoundaryValue::Gpu(g) => Arc::new(g.to_cpu(gpu.expect("GPU in use"))?),
                        };
                        sched.step(frame as i64, first_run, changed, &cb)?
                    };
                    began |= step.began;
                    if let Some(p) = step.published {
                        new_build |= matches!(p, Published::One(_));
                        let v = match p {
                            Published::One(f) => FieldValue::Cpu(f),
                            blend => FieldValue::Blend(blend),
                        };
                        // A static interpolated field publishes the same build again: no change.
                        let same = matches!(
                            (&v, values.get(name.as_str())),
                            (FieldValue::Cpu(n), Some(Value::Field(FieldValue::Cpu(o)))) if Arc::ptr_eq(n, o)
                        );
                        values.insert(name.clone(), Value::Field(v));
                        if !same {
                            bump(&mut versions, name);
                        }
                    }
                    step.worked
                }
                Stage::Cloth {
                    colliders,
                    sim,
                    previous,
                    gpu: gpu_cloth,
                    gpu_previous,
                    depth,
                } => {
                    let dt = 1.0 / plan.file.fps;
                    let (m, mesh) = if let Some(g) = gpu_cloth {
                        // Interpolated colliders arrive as fields blended at the frame's end
                        // (and last frame's end is this frame's start).
                        let end = colliders
                            .iter()
                            .map(|c| cpu_field(c, &values, &mut cpu_fields, gpu))
                            .collect::<crate::Result<Vec<_>>>()?;
                        let ctx = gpu.expect("GPU chosen at build");
                        let mut now = Vec::with_capacity(end.len());
                        for (k, f) in end.iter().enumerate() {
                            let same = gpu_previous.get(k).filter(|(cf, _)| Arc::ptr_eq(cf, f));
                            let up = match same {
                                Some((_, u)) => u.clone(),
                                None => Arc::new(GpuCollider::from_field(ctx, f)?),
                            };
                            now.push((f.clone(), up));
                        }
                        let start: Vec<&GpuCollider> =
                            gpu_previous.iter().map(|(_, u)| &**u).collect();
                        let end_refs: Vec<&GpuCollider> = now.iter().map(|(_, u)| &**u).collect();
                        let gm = g.step_frame(ctx, &start, &end_refs, frame, dt)?;
                        *gpu_previous = now;
                        // The CPU simulator mirrors the GPU's state once per frame: the same
                        // metrics as the CPU path, and the mesh from one read-back.
                        let fields: Vec<&DistanceField> = end.iter().map(|f| &**f).collect();
                        let m = sim.adopt_gpu_frame(
                            g.read_state(ctx)?,
                            g.read_side(ctx)?,
                            &fields,
                            &gm,
                        )?;
                        (serde_json::to_value(m).expect("plain data"), sim.to_mesh())
                    } else {
                        // Per collider: the two fields the frame blends between and its span
                        // of the blend: last frame's and this frame's field, or an
                        // interpolated node's two builds around the frame.
                        let mut ends: Vec<BodyFields> = Vec::with_capacity(colliders.len());
                        for (k, c) in colliders.iter().enumerate() {
                            ends.push(match values.get(c.as_str()) {
                                Some(Value::Field(FieldValue::Blend(Published::Blend {
                                    a,
                                    b,
                                    a_key,
                                    every,
                                    weight,
                                }))) => {
                                    let s0 = if frame as i64 == first_frame {
                                        *weight
                                    } else {
                                        (frame as i64 - 1 - a_key) as f32 / *every as f32
                                    };
                                    (Some(a.clone()), b.clone(), (s0, *weight))
                                }
                                _ => (
                                    previous.get(k).cloned(),
                                    cpu_field(c, &values, &mut cpu_fields, gpu)?,
                                    (0.0, 1.0),
                                ),
                            });
                        }
                        let bodies: Vec<Body> = ends
                            .iter()
                            .map(|(start, end, span)| Body {
                                start: start.as_deref(),
                                end,
                                span: *span,
                            })
                            .collect();
                        let mut poses = Vec::with_capacity(depth.len());
                        for d in depth.iter_mut() {
                            let Some(Value::Mesh(mesh)) = values.get(d.body.as_str()) else {
                                unreachable!("edges are typed")
                            };
                            poses.push(d.poses(mesh)?);
                        }
                        let depth_colliders: Vec<_> = depth
                            .iter()
                            .zip(&poses)
                            .map(|(d, (start, end))| {
                                d.camera
                                    .as_ref()
                                    .expect("poses set it")
                                    .collider(start.as_deref(), end)
                            })
                            .collect();
                        let m = sim.step_frame_between(&bodies, &depth_colliders, frame, dt)?;
                        *previous = ends.into_iter().map(|(_, e, _)| e).collect();
                        (serde_json::to_value(m).expect("plain data"), sim.to_mesh())
                    };
                    push_per_frame(nr, m);
                    nr.metrics.insert("particles".into(), sim.len().into());
                    values.insert(name.clone(), Value::Mesh(Arc::new(mesh)));
                    bump(&mut versions, name);
                    began = true;
                    true
                }
                Stage::Heightmap {
                    input,
                    region,
                    view,
                    gpu: raster,
                } => {
                    if first_run || (key && changed) {
                        began = true;
                        let Some(Value::Mesh(mesh)) = values.get(input.as_str()) else {
                            unreachable!("edges are typed")
                        };
                        let hf = match raster {
                            Some(r) => imprint_stages::depth::height_field_with(
                                mesh,
                                region,
                                *view,
                                |m, cam, w, h, o| {
                                    r.depth_map(gpu.expect("GPU chosen at build"), m, cam, w, h, o)
                                },
                            )?,
                            None => imprint_stages::depth::height_field_cpu(mesh, region, *view)?,
                        };
                        let (lo, hi) = hf.height_range();
                        nr.metrics.insert("height_min".into(), lo.into());
                        nr.metrics.insert("height_max".into(), hi.into());
                        values.insert(name.clone(), Value::Heights(Arc::new(hf)));
                        true
                    } else {
                        false
                    }
                }
                Stage::Ground {
                    objects,
                    sim,
                    accumulate,
                    last,
                    gpu: raster,
                    gpu_ground,
                } => {
                    // Fresh snow (or anything piling up) first: the rise since last frame.
                    if let Some(a) = accumulate {
                        let Some(Value::Heights(now)) = values.get(a.as_str()) else {
                            unreachable!("edges are typed")
                        };
                        if let Some(before) = last.as_ref() {
                            let rise: Vec<f32> = now
                                .heights
                                .iter()
                                .zip(&before.heights)
                                .map(|(n, b)| n - b)
                                .collect();
                            sim.add_heights(&rise)
                                .map_err(|e| at_node(e, name, frame))?;
                        }
                        *last = Some(now.clone());
                    }
                    let meshes = meshes_of(objects, &values);
                    let refs: Vec<&Mesh> = meshes.iter().map(|m| &**m).collect();
                    let stepped = match (raster, gpu_ground.as_mut()) {
                        (Some(r), Some(g)) => {
                            let ctx = gpu.expect("GPU chosen at build");
                            g.step_with(ctx, &refs, |m, cam, w, h, o| {
                                r.depth_map(ctx, m, cam, w, h, o)
                            })
                        }
                        (Some(r), None) => sim.step_with(&refs, |m, cam, w, h, o| {
                            r.depth_map(gpu.expect("GPU chosen at build"), m, cam, w, h, o)
                        }),
                        (None, _) => sim.step(&refs),
                    };
                    let m = stepped.map_err(|e| at_node(e, name, frame))?;
                    push_per_frame(nr, serde_json::to_value(m).expect("plain data"));
                    let heights = match gpu_ground {
                        Some(g) => g.to_height_field(),
                        None => sim.to_height_field(),
                    };
                    values.insert(name.clone(), Value::Heights(Arc::new(heights)));
                    bump(&mut versions, name);
                    began = true;
                    true
                }
                Stage::Snow {
                    meshes,
                    sim,
                    ground,
                    gpu: raster,
                    gpu_relax,
                } => {
                    let ms = meshes_of(meshes, &values);
                    let refs: Vec<&Mesh> = ms.iter().map(|m| &**m).collect();
                    let dt = 1.0 / plan.file.fps;
                    let step = match raster {
                        // Depth maps, look-ups and slides on the GPU; the deposit on the CPU.
                        Some(r) => {
                            let ctx = gpu.expect("GPU chosen at build");
                            let mut look_ups = imprint_stages::snow::gpu::GpuSnowArrival::new();
                            sim.step_with_parts(
                                &refs,
                                ground.as_ref(),
                                dt,
                                |occluder, receivers, directions, params| {
                                    look_ups.arrival_with(
                                        ctx,
                                        occluder,
                                        receivers,
                                        directions,
                                        params,
                                        |m, cam, w, h, o| r.depth_map(ctx, m, cam, w, h, o),
                                    )
                                },
                                gpu_relax.relaxer(ctx),
                            )
                        }
                        None => sim.step(&refs, ground.as_ref(), dt),
                    }
                    .map_err(|e| at_node(e, name, frame))?;
                    let mut m = serde_json::Map::new();
                    m.insert("frame".into(), frame.into());
                    m.insert("reached".into(), step.reached.into());
                    if let Some(g) = sim.ground() {
                        m.insert("ground_snow_volume".into(), g.volume().into());
                    }
                    let deepest = sim.mesh_depth(0).iter().copied().fold(0.0f32, f32::max);
                    m.insert("mesh_max_depth".into(), deepest.into());
                    push_per_frame(nr, serde_json::Value::Object(m));
                    // Only what the node outputs: the ground's surface, or the first mesh.
                    let v = match sim.ground() {
                        Some(g) => Value::Heights(Arc::new(g.surface())),
                        None => Value::Mesh(Arc::new(sim.displaced(0, refs[0]))),
                    };
                    values.insert(name.clone(), v);
                    bump(&mut versions, name);
                    began = true;
                    true
                }
                Stage::Skin { input, stage } => {
                    let mesh_in = input.as_ref().map(|i| match values.get(i.as_str()) {
                        Some(Value::Mesh(m)) => m.clone(),
                        _ => unreachable!("edges are typed"),
                    });
                    let (mesh, m) = stage
                        .frame(mesh_in.as_ref(), frame, plan.file.fps)
                        .map_err(|e| at_node(e, name, frame))?;
                    if first_run {
                        for (k, v) in stage.summary() {
                            nr.metrics.insert(k, v);
                        }
                    }
                    push_per_frame(nr, m);
                    values.insert(name.clone(), Value::Mesh(Arc::new(mesh)));
                    bump(&mut versions, name);
                    began = true;
                    true
                }
                Stage::Drape {
                    body,
                    garment,
                    params,
                    gpu: raster,
                } => {
                    if first_run || changed {
                        began = true;
                        let (Some(Value::Mesh(b)), Some(Value::Mesh(g))) =
                            (values.get(body.as_str()), values.get(garment.as_str()))
                        else {
                            unreachable!("edges are typed")
                        };
                        let mut fitted = (**g).clone();
                        let r = match raster {
                            Some(r) => imprint_stages::drape::drape_with(
                                b,
                                &mut fitted.positions,
                                params,
                                |m, cam, w, h, o| {
                                    r.depth_map(gpu.expect("GPU chosen at build"), m, cam, w, h, o)
                                },
                            ),
                            None => {
                                imprint_stages::drape::drape_cpu(b, &mut fitted.positions, params)
                            }
                        }
                        .map_err(|e| at_node(e, name, frame))?;
                        fitted.compute_normals();
                        let mut m = serde_json::to_value(&r).expect("plain data");
                        m["frame"] = frame.into();
                        push_per_frame(nr, m);
                        values.insert(name.clone(), Value::Mesh(Arc::new(fitted)));
                        bump(&mut versions, name);
                        true
                    } else {
                        false
                    }
                }
                Stage::WriteField { .. }
                | Stage::WriteMesh { .. }
                | Stage::WriteHeightmap { .. }
                | Stage::Render { .. } => false,
            };
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            if did_run {
                nr.record(frame, ms);
            }
            if began {
                seen.insert(name.clone(), input_versions);
                // Mesh, boundary and height nodes publish a new value whenever they compute
                // (fields and cloths count their own).
                if matches!(
                    spec,
                    NodeSpec::Mesh(_) | NodeSpec::Voxelize(_) | NodeSpec::Heightmap(_)
                ) {
                    bump(&mut versions, name);
                }
            }
            if let Some(obs) = observer.as_deref_mut().filter(|o| o.wants(name)) {
                // Not part of the frame's time: reading back or blending a field for the
                // observer, and the observer itself.
                let t = Instant::now();
                match values.get(name.as_str()) {
                    Some(Value::Mesh(m)) => obs.observe(name, frame, Observed::Mesh(m)),
                    Some(Value::Heights(h)) => obs.observe(name, frame, Observed::Heights(h)),
                    Some(Value::Field(_)) => {
                        let f = cpu_field(name, &values, &mut cpu_fields, gpu)?;
                        obs.observe(name, frame, Observed::Field(&f));
                    }
                    Some(Value::Boundary(_)) | None => {}
                }
                observed_ms += t.elapsed().as_secs_f64() * 1e3;
            }

            // After the timed part: error measurement and writers.
            match stages.get_mut(name).expect("stage") {
                Stage::Field {
                    measure,
                    mesh_node,
                    measured,
                    builds,
                    sched,
                    ..
                } if did_run || new_build => {
                    // The builds finished this frame, with the mesh each was made from. A
                    // build split over frames read the mesh of its first frame, which is gone.
                    let finished: Vec<(Arc<DistanceField>, Arc<Mesh>)> =
                        if sched.schedule.interpolate {
                            sched
                                .finished
                                .iter()
                                .map(|(f, m)| (f.clone(), m.clone()))
                                .collect()
                        } else if new_build && sched.schedule.split == 1 {
                            let Some(Value::Mesh(mesh)) = values.get(mesh_node.as_str()) else {
                                unreachable!("the mesh node ran before the field")
                            };
                            vec![(
                                cpu_field(name, &values, &mut cpu_fields, gpu)?,
                                mesh.clone(),
                            )]
                        } else {
                            Vec::new()
                        };
                    let nr = report.nodes.get_mut(name).expect("report");
                    if sched.schedule.split > 1 && !sched.schedule.interpolate {
                        nr.metrics.insert(
                            "error_cells".into(),
                            "not measured: a split build's mesh is gone when it finishes".into(),
                        );
                    }
                    for (field, mesh) in finished {
                        *builds += 1;
                        nr.metrics
                            .insert("band_cells".into(), field.band_cells().into());
                        nr.metrics
                            .insert("boundary_points".into(), field.points.len().into());
                        let due = match *measure {
                            Measure::Never => false,
                            Measure::First => *measured == 0,
                            Measure::Every(k) => (*builds - 1).is_multiple_of(k),
                        };
                        if !due {
                            continue;
                        }
                        let t = Instant::now();
                        let err =
                            imprint_stages::metrics::field_error_with(&field, &Bvh::new(&mesh));
                        nr.measure_ms += t.elapsed().as_secs_f64() * 1e3;
                        *measured += 1;
                        let worst = nr
                            .metrics
                            .get("error_max_cells")
                            .and_then(|v| v.as_f64())
                            .unwrap_or(0.0);
                        nr.metrics.insert("error_frame".into(), frame.into());
                        nr.metrics.insert(
                            "error_cells".into(),
                            serde_json::to_value(err).expect("plain data"),
                        );
                        nr.metrics
                            .insert("error_max_cells".into(), worst.max(err.max as f64).into());
                        nr.metrics
                            .insert("frames_measured".into(), (*measured).into());
                        if !(err.max.is_finite()) {
                            return Err(Error::Numerical {
                                node: name.clone(),
                                frame,
                                message:
                                    "the field's error against the exact distance is not finite"
                                        .into(),
                                hint: "check the mesh for huge coordinates; lower the resolution"
                                    .into(),
                            }
                            .into());
                        }
                    }
                }
                Stage::WriteField {
                    input,
                    dir,
                    npy,
                    slices,
                    every,
                } if key => {
                    let t = Instant::now();
                    let field = cpu_field(input, &values, &mut cpu_fields, gpu)?;
                    let mut n = 0;
                    if *npy {
                        n +=
                            imprint_render::field_io::write_field(dir, input, frame, &field)?.len();
                    }
                    for s in slices.iter() {
                        write_slice(dir, input, frame, &field, s)?;
                        n += 1;
                    }
                    report.files_written += n;
                    let nr = report.nodes.get_mut(name).expect("report");
                    nr.record(frame, t.elapsed().as_secs_f64() * 1e3);
                    nr.metrics
                        .insert("dir".into(), dir.display().to_string().into());
                    let files = nr
                        .metrics
                        .get("files")
                        .and_then(|v| v.as_u64())
                        .unwrap_or(0);
                    nr.metrics.insert("files".into(), (files + n as u64).into());
                }
                Stage::WriteMesh {
                    input,
                    dir,
                    format,
                    every,
                } if key => {
                    let t = Instant::now();
                    let Some(Value::Mesh(mesh)) = values.get(input.as_str()) else {
                        unreachable!("edges are typed")
                    };
                    let path = match format {
                        MeshFormat::Obj => {
                            let p = dir.join(format!("{input}_{frame:04}.obj"));
                            imprint_render::mesh_io::write_obj(&p, mesh, &Default::default())?;
                            p
                        }
                        MeshFormat::Ply => {
                            let p = dir.join(format!("{input}_{frame:04}.ply"));
                            imprint_render::mesh_io::write_ply(&p, mesh)?;
                            p
                        }
                    };
                    report.files_written += 1;
                    let nr = report.nodes.get_mut(name).expect("report");
                    nr.record(frame, t.elapsed().as_secs_f64() * 1e3);
                    nr.metrics
                        .insert("last".into(), path.display().to_string().into());
                    let files = nr
                        .metrics
                        .get("files")
                        .and_then(|v| v.as_u64())
                        .unwrap_or(0);
                    nr.metrics.insert("files".into(), (files + 1).into());
                }
                Stage::WriteHeightmap {
                    input,
                    dir,
                    formats,
                    every,
                } if key => {
                    let t = Instant::now();
                    let Some(Value::Heights(hf)) = values.get(input.as_str()) else {
                        unreachable!("edges are typed")
                    };
                    use imprint_render::heightmap as hm;
                    for f in formats.iter() {
                        let stem = format!("{input}_{frame:04}");
                        match f {
                            HeightmapFormat::Png16 => {
                                hm::write_heightmap_png16(&dir.join(format!("{stem}.png")), hf)?;
                                report.files_written += 1; // and its JSON sidecar
                            }
                            HeightmapFormat::Exr => {
                                hm::write_heightmap_exr(&dir.join(format!("{stem}.exr")), hf)?
                            }
                            HeightmapFormat::Npy => {
                                hm::write_heightmap_npy(&dir.join(format!("{stem}.npy")), hf)?
                            }
                            HeightmapFormat::Preview => hm::write_heightmap_preview(
                                &dir.join(format!("{stem}_preview.png")),
                                hf,
                            )?,
                        }
                    }
                    report.files_written += formats.len();
                    let nr = report.nodes.get_mut(name).expect("report");
                    nr.record(frame, t.elapsed().as_secs_f64() * 1e3);
                    nr.metrics
                        .insert("dir".into(), dir.display().to_string().into());
                }
                Stage::Render {
                    node,
                    out,
                    rendered,
                    sheet,
                    gif,
                    gpu: renderer,
                } if key => {
                    let t = Instant::now();
                    let mut scene = Scene {
                        ground_grid: node.ground_grid.then(GroundGrid::default),
                        ..Default::default()
                    };
                    for o in &node.objects {
                        scene.objects.push(match o {
                            RenderObject::Mesh {
                                mesh,
                                color,
                                wireframe,
                            } => {
                                let Some(Value::Mesh(m)) = values.get(mesh.as_str()) else {
                                    unreachable!("edges are typed")
                                };
                                Object::Mesh {
                                    mesh: m.clone(),
                                    color: [color.0, color.1, color.2],
                                    wireframe: *wireframe,
                                }
                            }
                            RenderObject::FieldSlice { field, axis, index } => Object::FieldSlice {
                                field: cpu_field(field, &values, &mut cpu_fields, gpu)?,
                                axis: *axis,
                                index: *index,
                                colormap: Default::default(),
                            },
                            RenderObject::HeightField {
                                heights,
                                color,
                                wireframe,
                            } => {
                                let Some(Value::Heights(hf)) = values.get(heights.as_str()) else {
                                    unreachable!("edges are typed")
                                };
                                Object::mesh(hf.to_mesh(), [color.0, color.1, color.2])
                                    .with_wireframe(*wireframe)
                            }
                        });
                    }
                    let ro = render_options(node, time)?;
                    let img = match renderer {
                        Some(r) => r.render(gpu.expect("GPU chosen at build"), &scene, &ro)?,
                        None => render_cpu(&scene, &ro)?,
                    };
                    let path = out.join(frame_path(&node.out, frame));
                    imprint_render::png::write_png(&path, &img)?;
                    report.files_written += 1;
                    if let (Some(s), Some(spec)) = (sheet.as_mut(), &node.contact_sheet)
                        && rendered.is_multiple_of(spec.every)
                    {
                        s.push(frame, &img);
                    }
                    if let (Some(g), Some(spec)) = (gif.as_mut(), &node.gif)
                        && rendered.is_multiple_of(spec.every)
                    {
                        g.push(&img)?;
                    }
                    *rendered += 1;
                    let nr = report.nodes.get_mut(name).expect("report");
                    nr.record(frame, t.elapsed().as_secs_f64() * 1e3);
                    nr.metrics
                        .insert("last".into(), path.display().to_string().into());
                }
                _ => {}
            }
        }
        report.frames.push(frame);
        report
            .frame_ms
            .push(frame_start.elapsed().as_secs_f64() * 1e3 - observed_ms);
        progress(done as u32 + 1, total);
    }
    // Whole-run writers: only now, after every frame succeeded.
    for (name, stage) in stages {
        if let Stage::Render {
            node,
            out,
            sheet,
            gif,
            ..
        } = stage
        {
            // A node that rendered nothing in this frame range writes no sheet or GIF either.
            if let (Some(s), Some(spec)) = (sheet, &node.contact_sheet)
                && !s.is_empty()
            {
                s.write(&out.join(&spec.path))?;
                report.files_written += 1;
            }
            if let (Some(g), Some(spec)) = (gif, &node.gif)
                && g.frames() > 0
            {
                g.finish()?;
                report.files_written += 1;
                let nr = report.nodes.get_mut(&name).expect("report");
                nr.metrics.insert(
                    "gif".into(),
                    out.join(&spec.path).display().to_string().into(),
                );
            }
        }
    }
    report.wall_ms = start.elapsed().as_secs_f64() * 1e3;
    let json = serde_json::to_string_pretty(&report).expect("report is plain data");
    imprint_core::io::atomic_write_bytes(&opts.out.join("report.json"), json.as_bytes())?;
    Ok(report)
}

/// Writes `DIR/<field>_<frame:04>_<axis><index>.png`, titled with the field and frame.
fn write_slice(
    dir: &std::path::Path,
    field_name: &str,
    frame: u32,
    field: &DistanceField,
    opts: &SliceOptions,
) -> crate::Result<()> {
    let index = opts.resolve_index(&field.spec)?;
    let mut opts = opts.clone();
    if opts.title.is_none() {
        opts.title = Some(format!("{field_name}  frame {frame:04}"));
    }
    let path = dir.join(format!(
        "{field_name}_{frame:04}_{}{index}.png",
        opts.axis.letter()
    ));
    imprint_render::slice::write_field_slice(&path, field, &opts)?;
    Ok(())
}

/// The renderer's options for a Render node at `time` (the orbit spins with time).
pub fn render_options(node: &RenderNode, time: f32) -> imprint_core::Result<RenderOptions> {
    let v = |t: (f32, f32, f32)| glam::Vec3::new(t.0, t.1, t.2);
    let camera = match node.camera {
        CameraSpec::Orbit {
            target,
            distance,
            elevation,
            azimuth,
            fov,
            spin,
        } => orbit(v(target), distance, elevation, azimuth + spin * time, fov)?,
        CameraSpec::LookAt { eye, target, fov } => {
            imprint_core::Camera::perspective(v(eye), v(target), glam::Vec3::Y, fov)?
        }
    };
    let opts = RenderOptions {
        width: node.width,
        height: node.height,
        samples: node.samples,
        camera,
    };
    opts.validate()?;
    Ok(opts)
}

/// `frames/{frame:04}.png` for frame 12 is `frames/0012.png`; `{frame}` is unpadded.
fn frame_path(pattern: &str, frame: u32) -> String {
    pattern
        .replace("{frame:04}", &format!("{frame:04}"))
        .replace("{frame}", &frame.to_string())
}

/// The CPU copy of a field node's value this frame (read back once per frame if on the GPU).
fn cpu_field(
    name: &str,
    values: &BTreeMap<String, Value>,
    cache: &mut BTreeMap<String, Arc<DistanceField>>,
    gpu: Option<&'static GpuContext>,
) -> crate::Result<Arc<DistanceField>> {
    if let Some(f) = cache.get(name) {
        return Ok(f.clone());
    }
    let Some(Value::Field(f)) = values.get(name) else {
        unreachable!("edges are typed")
    };
    let f = match f {
        FieldValue::Cpu(f) => f.clone(),
        FieldValue::Gpu(g) => Arc::new(g.to_cpu(gpu.expect("GPU in use"))?),
        FieldValue::Blend(p) => p.field()?,
    };
    cache.insert(name.to_string(), f.clone());
    Ok(f)
}

/// A stage's error as the run reports it: named after the node and frame, its kind (and so
/// the exit code: 2 for bad input, 1 for a failure while running) kept.
fn at_node(e: Error, node: &str, frame: u32) -> Error {
    match e {
        Error::Numerical { message, hint, .. } => Error::Numerical {
            node: node.to_string(),
            frame,
            message,
            hint,
        },
        Error::Invalid(m) => Error::Invalid(format!("node '{node}', frame {frame}: {m}")),
        Error::Run(m) => Error::Run(format!("node '{node}', frame {frame}: {m}")),
        other => other,
    }
}

/// The current values of Mesh nodes `names`, in order.
fn meshes_of(names: &[String], values: &BTreeMap<String, Value>) -> Vec<Arc<Mesh>> {
    names
        .iter()
        .map(|n| match values.get(n.as_str()) {
            Some(Value::Mesh(m)) => m.clone(),
            _ => unreachable!("edges are typed"),
        })
        .collect()
}

/// A node published a new value: its consumers see its version move.
fn bump(versions: &mut BTreeMap<String, u64>, name: &str) {
    *versions.entry(name.to_string()).or_default() += 1;
}

/// Appends one frame's metrics to the node's `per_frame` list in `report.json`.
fn push_per_frame(nr: &mut NodeReport, frame_metrics: serde_json::Value) {
    let per_frame = nr
        .metrics
        .entry("per_frame".into())
        .or_insert_with(|| serde_json::Value::Array(Vec::new()));
    if let serde_json::Value::Array(a) = per_frame {
        a.push(frame_metrics);
    }
}

/// The flat ground of a `Snow` node as a height field (square cells, centred on the origin
/// unless an origin is given).
pub fn snow_ground(g: &crate::schema::SnowGround) -> imprint_core::Result<HeightField> {
    let (nx, nz) = g.resolution;
    if nx == 0 || nz == 0 {
        return Err(Error::Invalid(format!(
            "ground resolution must be at least 1 x 1, got {nx} x {nz}"
        )));
    }
    let cell = g.size.0 / nx as f32;
    if !(cell.is_finite() && cell > 0.0) || (g.size.1 / nz as f32 - cell).abs() > 1e-6 * cell {
        return Err(Error::Invalid(format!(
            "ground cells must be square: size ({}, {}) over resolution ({nx}, {nz}) gives \
             {} x {}",
            g.size.0,
            g.size.1,
            cell,
            g.size.1 / nz as f32
        )));
    }
    let origin = match g.origin {
        Some((x, z)) => glam::Vec2::new(x, z),
        None => glam::Vec2::new(-g.size.0, -g.size.1) * 0.5 + glam::Vec2::splat(cell * 0.5),
    };
    HeightField::new(
        origin,
        cell,
        glam::UVec2::new(nx, nz),
        vec![g.height; nx as usize * nz as usize],
    )
}

/// A depth rasteriser on the GPU for a node whose depth maps run there.
fn gpu_rasterizer(
    want: Backend,
    node: &str,
    gpu: &mut Option<&'static GpuContext>,
) -> crate::Result<Option<Box<GpuRasterizer>>> {
    Ok(if choose_gpu(want, node, gpu)? {
        Some(Box::new(GpuRasterizer::new(gpu.expect("chosen"))?))
    } else {
        None
    })
}

/// A cloth's body read through depth maps: its fixed cameras (over the body's swept box when
/// it is a Mesh node, else over its first pose, and rebuilt wider if it leaves that box) and
/// its pose at the previous frame's end, the start of this one.
struct DepthBody {
    body: String,
    params: DepthColliderParams,
    eps: f32,
    swept: Option<imprint_core::Aabb>,
    camera: Option<DepthCamera>,
    previous: Option<(Arc<Mesh>, Arc<DepthPose>)>,
}

impl DepthBody {
    /// The poses at the frame's start (None on the first frame) and end, for `mesh`.
    fn poses(
        &mut self,
        mesh: &Arc<Mesh>,
    ) -> crate::Result<(Option<Arc<DepthPose>>, Arc<DepthPose>)> {
        let render = rasterize_depth_with;
        let bounds = mesh.bounds();
        let prev_bounds = self.previous.as_ref().map(|(m, _)| m.bounds());
        let seen = |c: &DepthCamera| c.sees(&bounds) && prev_bounds.is_none_or(|b| c.sees(&b));
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
            let camera = DepthCamera::new(&b, &self.params, self.eps)?;
            if let Some((m, pose)) = &mut self.previous {
                *pose = Arc::new(camera.pose(m, render)?);
            }
            self.camera = Some(camera);
        }
        let camera = self.camera.as_ref().expect("set above");
        let end = match &self.previous {
            // A body that did not change keeps its maps.
            Some((m, pose)) if Arc::ptr_eq(m, mesh) => pose.clone(),
            _ => Arc::new(camera.pose(mesh, render)?),
        };
        let start = self
            .previous
            .replace((mesh.clone(), end.clone()))
            .map(|(_, p)| p);
        Ok((start, end))
    }
}

/// Which backend a node with two paths runs on.
fn choose_gpu(
    want: Backend,
    node: &str,
    gpu: &mut Option<&'static GpuContext>,
) -> crate::Result<bool> {
    match want {
        Backend::Cpu => Ok(false),
        Backend::Gpu => {
            let ctx = GpuContext::shared()
                .map_err(|e| Error::Gpu(format!("node '{node}' asks for backend Gpu, but {e}")))?;
            *gpu = Some(ctx);
            Ok(true)
        }
        Backend::Auto => match GpuContext::shared() {
            Ok(ctx) if !ctx.is_software() => {
                *gpu = Some(ctx);
                Ok(true)
            }
            _ => Ok(false),
        },
    }
}

/// The box a mesh sweeps over the whole run (every frame up to 64 samples), so a fitted grid
/// holds the motion and partial runs get the same grid.
fn swept_bounds(plan: &Plan, src: &MeshSource) -> imprint_core::Aabb {
    let frames = plan.file.frames;
    let step = frames.div_ceil(64).max(1) as usize;
    let times = (0..frames)
        .step_by(step)
        .chain([frames - 1])
        .map(|f| f as f32 / plan.file.fps);
    src.sampled_bounds(times)
}

/// The grid of Voxelize node `name` (a fitted grid takes its mesh's swept box, found in
/// `bounds` or computed for a mesh that does not run itself).
fn voxel_spec(
    plan: &Plan,
    name: &str,
    v: &crate::schema::VoxelizeNode,
    bounds: &mut BTreeMap<String, imprint_core::Aabb>,
) -> crate::Result<GridSpec> {
    Ok(match v.grid {
        GridChoice::Fit {
            resolution,
            padding,
        } => {
            if !bounds.contains_key(&v.mesh)
                && let NodeSpec::Mesh(p) = &plan.file.nodes[&v.mesh]
            {
                let src = MeshSource::new(p, &plan.base_dir)?;
                bounds.insert(v.mesh.clone(), swept_bounds(plan, &src));
            }
            let b = bounds.get(&v.mesh).ok_or_else(|| {
                Error::Invalid(format!(
                    "node '{name}': Fit needs the swept box of a Mesh node, and '{}' is computed while running; give an Explicit grid",
                    v.mesh
                ))
            })?;
            GridSpec::fit(b, resolution, padding)?
        }
        GridChoice::Explicit { origin, cell, dims } => GridSpec::new(
            glam::Vec3::new(origin.0, origin.1, origin.2),
            cell,
            glam::UVec3::new(dims.0, dims.1, dims.2),
        )?,
    })
}

fn build_stages(
    plan: &Plan,
    opts: &RunOptions,
    gpu: &mut Option<&'static GpuContext>,
) -> crate::Result<BTreeMap<String, Stage>> {
    let mut stages = BTreeMap::new();
    let mut rest_bounds = BTreeMap::new();
    for name in &plan.order {
        let node = &plan.file.nodes[name];
        let want = opts.backend.or(node.backend()).unwrap_or(plan.file.backend);
        let stage = match node {
            NodeSpec::Mesh(p) => {
                let src = MeshSource::new(p, &plan.base_dir)?;
                rest_bounds.insert(name.clone(), swept_bounds(plan, &src));
                Stage::Mesh(Box::new(src))
            }
            NodeSpec::Voxelize(v) => {
                let spec = voxel_spec(plan, name, v, &mut rest_bounds)?;
                // Scratch, field and the writers' copies: refuse now rather than fail later.
                spec.check_memory(
                    &format!("node '{name}': voxelisation and distance field"),
                    9 + 8 + 16,
                )?;
                let on_gpu = choose_gpu(want, name, gpu)?;
                Stage::Voxelize {
                    input: v.mesh.clone(),
                    spec,
                    variant: v.variant,
                    gpu: on_gpu,
                    cpu: if on_gpu {
                        None
                    } else {
                        Some(Voxelizer::new(spec)?)
                    },
                }
            }
            NodeSpec::DistanceField(f) => {
                let NodeSpec::Voxelize(v) = &plan.file.nodes[&f.boundary] else {
                    unreachable!("edges are typed")
                };
                // Interpolated fields voxelise their own mesh at keyframe times, on the CPU.
                let ahead = if f.interpolate {
                    let NodeSpec::Mesh(m) = &plan.file.nodes[&v.mesh] else {
                        unreachable!("checked by the plan")
                    };
                    let spec = voxel_spec(plan, &f.boundary, v, &mut rest_bounds)?;
                    Some(Ahead {
                        mesh: Box::new(MeshSource::new(m, &plan.base_dir)?),
                        variant: v.variant,
                        voxelizer: Voxelizer::new(spec)?,
                        fps: plan.file.fps,
                    })
                } else {
                    None
                };
                let sc = node.schedule();
                Stage::Field {
                    input: f.boundary.clone(),
                    // Split and interpolated builds run on the CPU (in parts, ahead of time).
                    gpu: sc.split == 1 && !sc.interpolate && choose_gpu(want, name, gpu)?,
                    measure: f.measure,
                    mesh_node: v.mesh.clone(),
                    measured: 0,
                    builds: 0,
                    sched: Box::new(FieldSchedule::new(sc, f.band, ahead)),
                }
            }
            NodeSpec::Render(r) => Stage::Render {
                gpu: if choose_gpu(want, name, gpu)? {
                    Some(Box::new(GpuRenderer::new(gpu.expect("chosen"))?))
                } else {
                    None
                },
                node: Box::new(r.clone()),
                out: opts.out.clone(),
                rendered: 0,
                sheet: match &r.contact_sheet {
                    Some(c) => Some(ContactSheet::new(c.columns, c.width)?),
                    None => None,
                },
                gif: match &r.gif {
                    // Real-time playback: each GIF frame stands for `every * g.every` frames.
                    Some(g) => Some(GifWriter::create(
                        &opts.out.join(&g.path),
                        g.width,
                        (r.every * g.every) as f32 / plan.file.fps,
                    )?),
                    None => None,
                },
            },
            NodeSpec::Cloth(c) => {
                let sim = ClothSim::new(&c.params, &plan.base_dir)
                    .map_err(|e| Error::Invalid(format!("node '{name}': {e}")))?
                    .with_name(name.clone());
                if let Some(w) = sim
                    .stability()
                    .warning(c.params.substeps, 1.0 / plan.file.fps)
                {
                    eprintln!("warning: node '{name}': {w}");
                }
                let depth_only_cpu = !c.depth_colliders.is_empty();
                if depth_only_cpu
                    && (want == Backend::Gpu || (want == Backend::Auto && gpu.is_some()))
                {
                    eprintln!(
                        "note: node '{name}' runs on the CPU: the GPU cloth reads distance-field \
                         colliders only, and it has depth_colliders"
                    );
                }
                let gpu_cloth = if !depth_only_cpu && choose_gpu(want, name, gpu)? {
                    match GpuCloth::new(gpu.expect("chosen"), &sim) {
                        Ok(g) => Some(Box::new(g.with_name(name.clone()))),
                        // Auto falls back to the CPU when the GPU cannot take this cloth (limits).
                        Err(e) if want == Backend::Auto => {
                            eprintln!("note: node '{name}' runs on the CPU: {e}");
                            None
                        }
                        Err(e) => return Err(e.into()),
                    }
                } else {
                    None
                };
                Stage::Cloth {
                    colliders: c.colliders.clone(),
                    sim: Box::new(sim),
                    previous: Vec::new(),
                    gpu: gpu_cloth,
                    gpu_previous: Vec::new(),
                    depth: c
                        .depth_colliders
                        .iter()
                        .map(|d| DepthBody {
                            body: d.body.clone(),
                            params: d.params.clone(),
                            eps: c.params.collision.epsilon,
                            swept: rest_bounds.get(&d.body).copied(),
                            camera: None,
                            previous: None,
                        })
                        .collect(),
                }
            }
            NodeSpec::Heightmap(h) => {
                let region = match h.grid {
                    HeightGrid::Fit {
                        resolution,
                        padding,
                    } => {
                        let bounds = rest_bounds.get(&h.mesh).ok_or_else(|| {
                            Error::Invalid(format!(
                                "node '{name}': Fit needs the swept box of a Mesh node; give an Explicit grid"
                            ))
                        })?;
                        HeightRegion::fit(bounds, resolution, padding, h.empty)?
                    }
                    HeightGrid::Explicit { origin, cell, dims } => HeightRegion::new(
                        glam::Vec2::new(origin.0, origin.1),
                        cell,
                        glam::UVec2::new(dims.0, dims.1),
                        h.empty,
                    )?,
                };
                Stage::Heightmap {
                    input: h.mesh.clone(),
                    region,
                    view: h.view,
                    gpu: gpu_rasterizer(want, name, gpu)?,
                }
            }
            NodeSpec::WriteHeightmap(w) => {
                let mut formats = w.formats.clone();
                formats.sort();
                formats.dedup();
                Stage::WriteHeightmap {
                    input: w.heights.clone(),
                    dir: opts.out.join(w.dir.as_deref().unwrap_or(name)),
                    formats,
                    every: w.every,
                }
            }
            NodeSpec::Skin(k) => {
                let ctx = if choose_gpu(want, name, gpu)? {
                    *gpu
                } else {
                    None
                };
                Stage::Skin {
                    input: k.mesh.clone(),
                    stage: Box::new(crate::skin_stage::SkinStage::new(
                        name,
                        k,
                        &plan.base_dir,
                        ctx,
                    )?),
                }
            }
            NodeSpec::Drape(d) => Stage::Drape {
                body: d.body.clone(),
                garment: d.garment.clone(),
                params: d.params.clone(),
                gpu: gpu_rasterizer(want, name, gpu)?,
            },
            NodeSpec::Snow(n) => Stage::Snow {
                meshes: n.meshes.clone(),
                sim: Box::new(
                    imprint_stages::snow::SnowSim::new(&n.params)
                        .map_err(|e| Error::Invalid(format!("node '{name}': {e}")))?,
                ),
                ground: n.ground.as_ref().map(snow_ground).transpose()?,
                gpu: gpu_rasterizer(want, name, gpu)?,
                gpu_relax: Box::new(imprint_stages::snow::gpu::GpuSnowRelax::new()),
            },
            NodeSpec::Ground(g) => {
                let sim = imprint_stages::ground::GroundSim::new(&g.params, &plan.base_dir)
                    .map_err(|e| Error::Invalid(format!("node '{name}': {e}")))?;
                let raster = gpu_rasterizer(want, name, gpu)?;
                // The passes go to the GPU too, except what has no port yet: full relaxation,
                // and taking a layer in (`accumulate`), which run on the CPU.
                let gpu_ground = match raster {
                    Some(_)
                        if g.accumulate.is_none()
                            && g.params.relaxation
                                == imprint_stages::ground::Relaxation::Labelled =>
                    {
                        Some(Box::new(imprint_stages::ground::gpu::GpuGround::from_sim(
                            gpu.expect("chosen"),
                            &sim,
                        )?))
                    }
                    Some(_) => {
                        eprintln!(
                            "note: node '{name}': contact view on the GPU, passes on the CPU \
                             (full relaxation and accumulate have no GPU port yet)"
                        );
                        None
                    }
                    None => None,
                };
                Stage::Ground {
                    accumulate: g.accumulate.clone(),
                    last: None,
                    gpu: raster,
                    gpu_ground,
                    objects: g.objects.clone(),
                    sim: Box::new(sim),
                }
            }
            NodeSpec::WriteMesh(w) => Stage::WriteMesh {
                input: w.mesh.clone(),
                dir: opts.out.join(w.dir.as_deref().unwrap_or(name)),
                format: w.format,
                every: w.every,
            },
            NodeSpec::WriteField(w) => Stage::WriteField {
                input: w.field.clone(),
                dir: opts.out.join(w.dir.as_deref().unwrap_or(name)),
                npy: w.npy,
                slices: w.slices.clone(),
                every: w.every,
            },
        };
        stages.insert(name.clone(), stage);
    }
    Ok(stages)
}
