//! `Render`: meshes, height fields and field slices drawn to a PNG per frame, with an
//! optional contact sheet and GIF of the run.

use crate::node::{
    Backend, BuildCtx, CheckCtx, FrameCtx, Node, Port, PortType, Stage, Step, Trigger, load_state,
    save_state,
};
use crate::report::NodeReport;
use crate::schedule::Schedule;
use crate::schema::defaults;
use crate::value::{FieldIn, HeightsIn, MeshIn, Values};
use imprint_gpu::GpuContext;
use imprint_render::frame::{GroundGrid, Object, RenderOptions, Scene, orbit, render_cpu};
use imprint_render::gpu_frame::GpuRenderer;
use imprint_render::sequence::{ContactSheet, GifWriter};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};
use std::any::Any;
use std::path::{Path, PathBuf};

#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct RenderNode {
    /// What to draw, nearest surface wins.
    pub objects: Vec<RenderObject>,
    /// Where the camera is and where it looks: `Orbit(…)` or `LookAt(…)`.
    pub camera: CameraSpec,
    /// Image width, pixels.
    #[serde(default = "default_width")]
    pub width: u32,
    /// Image height, pixels.
    #[serde(default = "default_height")]
    pub height: u32,
    /// Supersampling per axis (1..=4): the CPU renderer's anti-aliasing.
    #[serde(default = "two")]
    pub samples: u32,
    /// A grid on the ground plane y = 0, for orientation.
    #[serde(default = "defaults::yes")]
    pub ground_grid: bool,
    /// File pattern under the run's output folder; `{frame:04}` (or `{frame}`) is replaced.
    #[serde(default = "default_pattern")]
    pub out: String,
    /// Render every k-th frame (1 = every frame).
    #[serde(default = "defaults::one")]
    pub every: u32,
    /// Frames written are those where (frame - offset) mod every = 0.
    #[serde(default)]
    pub offset: u32,
    /// `false` switches this node and everything that reads it off.
    #[serde(default = "defaults::yes")]
    pub enabled: bool,
    /// A grid of every k-th rendered frame in one PNG.
    #[serde(default)]
    pub contact_sheet: Option<ContactSheetSpec>,
    /// An animated GIF of the rendered frames, playing at the run's speed.
    #[serde(default)]
    pub gif: Option<GifSpec>,
    /// Where the frames are rendered: `Auto`, `Cpu` or `Gpu`; null: the pipeline's `backend`.
    #[serde(default)]
    pub backend: Option<Backend>,
}

/// Where and how a Render node writes its contact sheet.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ContactSheetSpec {
    /// Path under the run's output folder.
    #[serde(default = "default_sheet_path")]
    pub path: String,
    /// Take every k-th rendered frame.
    #[serde(default = "four")]
    pub every: u32,
    /// Thumbnails per row (1..=64).
    #[serde(default = "four")]
    pub columns: u32,
    /// Thumbnail width in pixels.
    #[serde(default = "default_thumb_width")]
    pub width: u32,
}

/// Where and how a Render node writes its GIF preview.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct GifSpec {
    /// Path under the run's output folder.
    #[serde(default = "default_gif_path")]
    pub path: String,
    /// Take every k-th rendered frame.
    #[serde(default = "defaults::one")]
    pub every: u32,
    /// Frame width in pixels (frames are scaled down, never up).
    #[serde(default = "default_gif_width")]
    pub width: u32,
}

fn four() -> u32 {
    4
}
fn default_sheet_path() -> String {
    "contact_sheet.png".into()
}
fn default_thumb_width() -> u32 {
    320
}
fn default_gif_path() -> String {
    "preview.gif".into()
}
fn default_gif_width() -> u32 {
    480
}
fn default_width() -> u32 {
    640
}
fn default_height() -> u32 {
    480
}
fn two() -> u32 {
    2
}
fn default_pattern() -> String {
    "frames/{frame:04}.png".into()
}

/// One thing a Render node draws.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
pub enum RenderObject {
    /// A Mesh node's mesh, lit, in a linear RGB colour (0..1).
    Mesh {
        /// The node whose mesh is drawn (a Mesh, Skin, Cloth, Drape, … node).
        mesh: String,
        /// Surface colour, linear RGB in 0..1.
        #[serde(default = "default_color")]
        color: (f32, f32, f32),
        /// Overlay the triangle edges as thin dark lines.
        #[serde(default)]
        wireframe: bool,
    },
    /// A plane of a DistanceField node's grid, colour-mapped (0 at the surface, band at the edge).
    FieldSlice {
        /// The DistanceField node whose grid is sliced.
        field: String,
        /// The grid axis the slice plane is normal to.
        #[serde(default = "default_axis")]
        axis: imprint_render::slice::Axis,
        /// Which plane along `axis`: `Middle`, `Cell(i)` or `Fraction(f)`.
        #[serde(default)]
        index: imprint_render::slice::SliceIndex,
    },
    /// A HeightField node's surface through its cell centres, lit like a mesh.
    HeightField {
        /// The node whose height field is drawn (a Heightmap, Ground, … node).
        heights: String,
        /// Surface colour, linear RGB in 0..1.
        #[serde(default = "default_ground_color")]
        color: (f32, f32, f32),
        /// Overlay the triangle edges as thin dark lines.
        #[serde(default)]
        wireframe: bool,
    },
}

fn default_ground_color() -> (f32, f32, f32) {
    (0.55, 0.6, 0.5)
}
fn default_color() -> (f32, f32, f32) {
    (0.8, 0.45, 0.35)
}
fn default_axis() -> imprint_render::slice::Axis {
    imprint_render::slice::Axis::Z
}

/// Where the camera is. Angles in degrees; `spin` turns an orbit at degrees per second.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
pub enum CameraSpec {
    Orbit {
        /// The point looked at and orbited, m.
        #[serde(default)]
        target: (f32, f32, f32),
        /// Distance from `target` to the camera, m (> 0).
        distance: f32,
        /// Angle above the x-z plane, degrees (not ±90).
        #[serde(default = "default_elevation")]
        elevation: f32,
        /// Angle around +y, measured from +z toward +x, degrees (at time 0 with `spin`).
        #[serde(default)]
        azimuth: f32,
        /// Vertical field of view, degrees.
        #[serde(default = "default_fov")]
        fov: f32,
        /// Turn of the orbit, degrees per second, added to `azimuth` as time passes.
        #[serde(default)]
        spin: f32,
    },
    LookAt {
        /// Camera position, m.
        eye: (f32, f32, f32),
        /// The point looked at, m.
        #[serde(default)]
        target: (f32, f32, f32),
        /// Vertical field of view, degrees.
        #[serde(default = "default_fov")]
        fov: f32,
    },
}

fn default_elevation() -> f32 {
    20.0
}
fn default_fov() -> f32 {
    40.0
}

impl RenderNode {
    /// The renderer's options at `time` (the orbit spins with time).
    pub fn options(&self, time: f32) -> imprint_core::Result<RenderOptions> {
        let v = |t: (f32, f32, f32)| glam::Vec3::new(t.0, t.1, t.2);
        let camera = match self.camera {
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
            width: self.width,
            height: self.height,
            samples: self.samples,
            camera,
        };
        opts.validate()?;
        Ok(opts)
    }
}

impl Node for RenderNode {
    fn kind(&self) -> &'static str {
        "Render"
    }
    fn inputs(&self) -> Vec<Port<'_>> {
        self.objects
            .iter()
            .map(|o| match o {
                RenderObject::Mesh { mesh, .. } => Port::new("objects", mesh, PortType::Mesh),
                RenderObject::FieldSlice { field, .. } => {
                    Port::new("objects", field, PortType::DistanceField)
                }
                RenderObject::HeightField { heights, .. } => {
                    Port::new("objects", heights, PortType::HeightField)
                }
            })
            .collect()
    }
    fn output(&self) -> Option<PortType> {
        None
    }
    fn enabled(&self) -> bool {
        self.enabled
    }
    fn trigger(&self) -> Trigger {
        Trigger::Writes
    }
    fn schedule(&self) -> Schedule {
        Schedule::every(self.every, self.offset)
    }
    fn writes_whole_run(&self) -> bool {
        self.contact_sheet.is_some() || self.gif.is_some()
    }
    fn backend(&self) -> Option<Backend> {
        self.backend
    }
    fn has_gpu_path(&self) -> bool {
        true
    }
    fn check(&self, ctx: &CheckCtx<'_>) -> crate::Result<()> {
        if !self.out.contains("{frame") {
            return Err(ctx.fail(
                "out",
                format!(
                    "out pattern '{}' has no {{frame}} or {{frame:04}}: every frame would \
                     overwrite the last",
                    self.out
                ),
            ));
        }
        if self.objects.is_empty() {
            return Err(ctx.fail("objects", "a Render node needs at least one object"));
        }
        self.options(0.0).map_err(|e| ctx.fail("camera", e))?;
        if let Some(c) = &self.contact_sheet {
            if c.every == 0 {
                return Err(ctx.fail("contact_sheet", "every must be at least 1"));
            }
            ContactSheet::new(c.columns, c.width).map_err(|e| ctx.fail("contact_sheet", e))?;
        }
        if let Some(g) = &self.gif {
            if g.every == 0 {
                return Err(ctx.fail("gif", "every must be at least 1"));
            }
            // Only checks the values: nothing is created before the run ends.
            GifWriter::create(Path::new(&g.path), g.width, 1.0).map_err(|e| ctx.fail("gif", e))?;
        }
        Ok(())
    }
    fn build(&self, ctx: &mut BuildCtx<'_>) -> crate::Result<Box<dyn Stage>> {
        let gpu = match ctx.choose_gpu()? {
            Some(g) => Some((g, Box::new(GpuRenderer::new(g)?))),
            None => None,
        };
        let fps = ctx.check.fps;
        let objects = self
            .objects
            .iter()
            .map(|o| match o {
                RenderObject::Mesh {
                    mesh,
                    color,
                    wireframe,
                } => ObjectIn::Mesh(ctx.mesh_in(mesh), rgb(*color), *wireframe),
                RenderObject::FieldSlice { field, axis, index } => {
                    ObjectIn::Slice(ctx.field_in(field), *axis, *index)
                }
                RenderObject::HeightField {
                    heights,
                    color,
                    wireframe,
                } => ObjectIn::Heights(ctx.heights_in(heights), rgb(*color), *wireframe),
            })
            .collect();
        let state = RenderState {
            rendered: 0,
            sheet: match &self.contact_sheet {
                Some(c) => Some(ContactSheet::new(c.columns, c.width)?),
                None => None,
            },
            gif: match &self.gif {
                // Real-time playback: each GIF frame stands for `every * g.every` frames.
                Some(g) => Some(GifWriter::create(
                    &ctx.out.join(&g.path),
                    g.width,
                    (self.every * g.every) as f32 / fps,
                )?),
                None => None,
            },
        };
        Ok(Box::new(RenderStage {
            node: Box::new(self.clone()),
            objects,
            out: ctx.out.to_path_buf(),
            state,
            gpu,
        }))
    }
    fn as_any(&self) -> &dyn Any {
        self
    }
}

fn rgb(c: (f32, f32, f32)) -> [f32; 3] {
    [c.0, c.1, c.2]
}

/// A Render object with its input resolved.
enum ObjectIn {
    Mesh(MeshIn, [f32; 3], bool),
    Slice(
        FieldIn,
        imprint_render::slice::Axis,
        imprint_render::slice::SliceIndex,
    ),
    Heights(HeightsIn, [f32; 3], bool),
}

/// What a Render node carries between frames.
#[derive(Serialize, Deserialize)]
struct RenderState {
    /// Frames rendered so far (the contact sheet and GIF count these).
    rendered: u32,
    sheet: Option<ContactSheet>,
    gif: Option<GifWriter>,
}

struct RenderStage {
    node: Box<RenderNode>,
    objects: Vec<ObjectIn>,
    out: PathBuf,
    state: RenderState,
    /// The GPU renderer when the node runs on the GPU.
    gpu: Option<(&'static GpuContext, Box<GpuRenderer>)>,
}

impl RenderStage {
    fn scene(&self, values: &Values, gpu: Option<&GpuContext>) -> imprint_core::Result<Scene> {
        let mut scene = Scene {
            ground_grid: self.node.ground_grid.then(GroundGrid::default),
            ..Default::default()
        };
        for o in &self.objects {
            scene.objects.push(match o {
                ObjectIn::Mesh(m, color, wireframe) => Object::Mesh {
                    mesh: values.mesh(m)?.clone(),
                    color: *color,
                    wireframe: *wireframe,
                },
                ObjectIn::Slice(f, axis, index) => Object::FieldSlice {
                    field: values.field(f)?.cpu(gpu)?,
                    axis: *axis,
                    index: *index,
                    colormap: Default::default(),
                },
                ObjectIn::Heights(h, color, wireframe) => {
                    Object::mesh(values.heights(h)?.to_mesh(), *color).with_wireframe(*wireframe)
                }
            });
        }
        Ok(scene)
    }
}

impl Stage for RenderStage {
    fn run(&mut self, ctx: &mut FrameCtx<'_>) -> imprint_core::Result<Step> {
        if !ctx.key {
            return Ok(Step::idle());
        }
        let scene = self.scene(ctx.values, ctx.gpu)?;
        let ro = self.node.options(ctx.time)?;
        let img = match &mut self.gpu {
            Some((gpu, r)) => r.render(gpu, &scene, &ro)?,
            None => render_cpu(&scene, &ro)?,
        };
        let path = self.out.join(frame_path(&self.node.out, ctx.frame));
        imprint_render::png::write_png(&path, &img)?;
        let s = &mut self.state;
        if let (Some(sheet), Some(spec)) = (s.sheet.as_mut(), &self.node.contact_sheet)
            && s.rendered.is_multiple_of(spec.every)
        {
            sheet.push(ctx.frame, &img);
        }
        if let (Some(g), Some(spec)) = (s.gif.as_mut(), &self.node.gif)
            && s.rendered.is_multiple_of(spec.every)
        {
            g.push(&img)?;
        }
        s.rendered += 1;
        ctx.metric("last", path.display().to_string());
        Ok(Step::wrote(vec![path]))
    }

    fn finish(&mut self, report: &mut NodeReport) -> imprint_core::Result<Vec<PathBuf>> {
        let mut files = Vec::new();
        // A node that rendered nothing in this frame range writes no sheet or GIF either.
        if let (Some(s), Some(spec)) = (&self.state.sheet, &self.node.contact_sheet)
            && !s.is_empty()
        {
            let path = self.out.join(&spec.path);
            s.write(&path)?;
            files.push(path);
        }
        if let (Some(g), Some(spec)) = (self.state.gif.take(), &self.node.gif)
            && g.frames() > 0
        {
            g.finish()?;
            let path = self.out.join(&spec.path);
            report
                .metrics
                .insert("gif".into(), path.display().to_string().into());
            files.push(path);
        }
        Ok(files)
    }

    fn save(&self, _values: &Values) -> imprint_core::Result<Vec<u8>> {
        save_state(&self.state)
    }

    fn load(&mut self, bytes: &[u8], _values: &Values) -> imprint_core::Result<()> {
        self.state = load_state(bytes)?;
        Ok(())
    }

    fn on_gpu(&self) -> bool {
        self.gpu.is_some()
    }
}

/// `frames/{frame:04}.png` for frame 12 is `frames/0012.png`; `{frame}` is unpadded.
fn frame_path(pattern: &str, frame: u32) -> String {
    pattern
        .replace("{frame:04}", &format!("{frame:04}"))
        .replace("{frame}", &frame.to_string())
}
