//! Mesh source: a file or a primitive, fitted into a box once, then deformed as a function
//! of time by a list of motions (rigid keyframes, breathe, twist, bend, wave).
//!
//! Built once ([`MeshSource::new`]), evaluated per frame ([`MeshSource::at`]). Every motion
//! is a per-vertex map whose parameters come from the rest mesh's bounding box; evaluation
//! is parallel over vertices (rayon) and gives the same bytes for any thread count.

pub mod motion;
pub mod params;

pub use params::{Axis, Fit, MeshParams, Motion, Primitive, RigidKey, Rotation, RotationAxis};

use glam::Vec3;
use imprint_core::gltf::{ClipTime, Document};
use imprint_core::mesh::primitives;
use imprint_core::{Aabb, Mesh, Result};
use motion::{Compiled, Deform};
use rayon::prelude::*;
use std::path::Path;

/// Vertices per parallel task: enough to outweigh rayon's overhead, few enough to stay in
/// cache and to spread a 30k-vertex mesh over the cores.
const CHUNK: usize = 2048;

/// A mesh node's state: the fitted rest mesh and the compiled motions.
#[derive(Clone, Debug)]
pub struct MeshSource {
    rest: Mesh,
    rest_bounds: Aabb,
    motions: Vec<Compiled>,
    is_static: bool,
    /// A glTF clip posing the rest mesh before the motions, and the fit applied after it.
    clip: Option<Posed>,
}

/// A glTF document's skinned mesh posed by one of its clips (`MeshParams::clip`).
#[derive(Clone, Debug)]
struct Posed {
    doc: std::sync::Arc<Document>,
    clip: usize,
    time: ClipTime,
    fit: glam::Mat4,
}

impl Posed {
    /// Loads `path`, finds the clip, and fits the mesh as it stands at time 0.
    fn new(params: &MeshParams, path: &Path, name: &str) -> Result<Self> {
        let doc = Document::load(path)?;
        let clip = doc.clip(name)?;
        let index = doc
            .clips
            .iter()
            .position(|c| c.name == name)
            .expect("found above");
        let time = ClipTime {
            speed: params.speed,
            looping: params.looping,
            offset: params.clip_offset,
        };
        let first = doc.posed_mesh(Some(clip), time.local(clip, 0.0));
        let fit = params.fit.map_or(glam::Mat4::IDENTITY, |f| {
            first.fit_transform(f.size, f.center)
        });
        Ok(Posed {
            doc: std::sync::Arc::new(doc),
            clip: index,
            time,
            fit,
        })
    }

    /// The posed, fitted mesh at the pipeline's `time`.
    fn at(&self, time: f32) -> Mesh {
        let clip = &self.doc.clips[self.clip];
        let mut m = self.doc.posed_mesh(Some(clip), self.time.local(clip, time));
        m.transform(self.fit);
        m
    }
}

impl MeshSource {
    /// Validates `params`, loads the mesh file (`path` relative to `base_dir`; any format
    /// [`imprint_core::load_mesh`] reads) or builds the primitive, and applies the fit.
    pub fn new(params: &MeshParams, base_dir: &Path) -> Result<MeshSource> {
        params.validate()?;
        if let (Some(path), Some(clip)) = (&params.path, &params.clip) {
            let posed = Posed::new(params, &base_dir.join(path), clip)?;
            return Ok(Self::with_rest(posed.at(0.0), params, Some(posed)));
        }
        let mut rest = match (&params.path, &params.primitive) {
            (Some(path), _) => imprint_core::load_mesh(&base_dir.join(path))?,
            (None, Some(prim)) => build_primitive(prim),
            (None, None) => unreachable!("validate() requires a path or a primitive"),
        };
        if params.close_holes {
            rest.close_holes();
        }
        if let Some(fit) = params.fit {
            let m = rest.fit_transform(fit.size, fit.center);
            rest.transform(m);
        }
        Ok(Self::with_rest(rest, params, None))
    }

    /// The source for a fitted rest mesh: its motions compiled against its box.
    fn with_rest(rest: Mesh, params: &MeshParams, clip: Option<Posed>) -> Self {
        let rest_bounds = rest.bounds();
        let motions = params
            .motion
            .iter()
            .map(|m| Compiled::new(m, &rest_bounds))
            .collect();
        let is_static = clip.is_none() && params.motion.iter().all(Motion::is_time_invariant);
        MeshSource {
            rest,
            rest_bounds,
            motions,
            is_static,
            clip,
        }
    }

    /// The fitted mesh before any motion.
    pub fn rest(&self) -> &Mesh {
        &self.rest
    }

    /// The rest mesh's bounding box: the frame every motion's centre and ends refer to.
    pub fn rest_bounds(&self) -> Aabb {
        self.rest_bounds
    }

    /// True when the shape does not change with time (no motion, or only time-invariant
    /// ones): consumers of this mesh need not run again.
    pub fn is_static(&self) -> bool {
        self.is_static
    }

    /// The deformed mesh at `time` (seconds), normals recomputed.
    pub fn at(&self, time: f32) -> Mesh {
        let mut out = Mesh::default();
        self.at_into(time, &mut out);
        out
    }

    /// Like [`at`](Self::at), reusing `out`'s buffers (no allocation after the first frame).
    pub fn at_into(&self, time: f32, out: &mut Mesh) {
        debug_assert!(time.is_finite(), "mesh time must be finite, got {time}");
        if self.motions.is_empty() {
            match &self.clip {
                Some(c) => *out = c.at(time),
                None => out.clone_from(&self.rest),
            }
            return;
        }
        let deforms: Vec<Deform> = self.motions.iter().map(|m| m.at(time)).collect();
        self.deform_positions(time, &deforms, &mut out.positions);
        out.triangles.clone_from(&self.rest.triangles);
        out.uvs.clone_from(&self.rest.uvs);
        self.compute_normals(&out.positions, &mut out.normals);
    }

    /// Only the deformed positions at `time`, for consumers that need no normals (voxelising,
    /// distance fields): the normals are most of a frame's cost.
    pub fn positions_at_into(&self, time: f32, out: &mut Vec<Vec3>) {
        debug_assert!(time.is_finite(), "mesh time must be finite, got {time}");
        let deforms: Vec<Deform> = self.motions.iter().map(|m| m.at(time)).collect();
        self.deform_positions(time, &deforms, out);
    }

    /// Bounding box of the mesh over the given times (sampled: a grid meant to hold a
    /// moving mesh should sample densely or add a margin). The rest box when no time is given.
    pub fn sampled_bounds(&self, times: impl IntoIterator<Item = f32>) -> Aabb {
        if self.motions.is_empty() && self.clip.is_none() {
            return self.rest_bounds;
        }
        let mut b = Aabb::empty();
        let mut positions = Vec::new();
        for t in times {
            self.positions_at_into(t, &mut positions);
            b = b.union(&Aabb::from_points(positions.iter().copied()));
        }
        if b.is_empty() { self.rest_bounds } else { b }
    }

    /// The motions applied to the rest positions (to the clip's pose at `time`, when the
    /// mesh has a clip).
    fn deform_positions(&self, time: f32, deforms: &[Deform], out: &mut Vec<Vec3>) {
        let posed = self.clip.as_ref().map(|c| c.at(time));
        let base = posed
            .as_ref()
            .map_or(&self.rest.positions, |m| &m.positions);
        out.resize(base.len(), Vec3::ZERO);
        out.par_chunks_mut(CHUNK)
            .zip(base.par_chunks(CHUNK))
            .for_each(|(out, rest)| {
                out.copy_from_slice(rest);
                for d in deforms {
                    d.apply_all(out);
                }
            });
    }

    /// Area-weighted vertex normals, bit-identical to `Mesh::compute_normals`: each task owns
    /// a range of vertices and scatters into it the face normals of the triangles touching
    /// it, in triangle order. Every vertex thus gets the same sum in the same order whatever
    /// the number of tasks, and no two threads write to the same place.
    fn compute_normals(&self, positions: &[Vec3], normals: &mut Vec<Vec3>) {
        let n = positions.len();
        normals.clear();
        normals.resize(n, Vec3::ZERO);
        let tasks = rayon::current_num_threads().clamp(1, n.div_ceil(CHUNK).max(1));
        let per_task = n.div_ceil(tasks).max(1);
        normals
            .par_chunks_mut(per_task)
            .enumerate()
            .for_each(|(k, out)| {
                let low = (k * per_task) as u32;
                let high = low + out.len() as u32;
                for tri in &self.rest.triangles {
                    if !tri.iter().any(|v| (low..high).contains(v)) {
                        continue;
                    }
                    let [a, b, c] = tri.map(|v| positions[v as usize]);
                    let face = (b - a).cross(c - a);
                    for &v in tri {
                        if (low..high).contains(&v) {
                            out[(v - low) as usize] += face;
                        }
                    }
                }
                for n in out {
                    *n = n.normalize_or_zero();
                }
            });
    }
}

/// The primitive at its declared size, centred on the origin (validated beforehand).
fn build_primitive(p: &Primitive) -> Mesh {
    match *p {
        Primitive::Sphere {
            radius,
            segments,
            rings,
        } => primitives::uv_sphere(radius, segments, rings),
        Primitive::Box { size, subdivisions } => primitives::cuboid(0.5 * size, subdivisions),
        Primitive::Plane { size, subdivisions } => primitives::plane(size, subdivisions),
        Primitive::Torus {
            major,
            minor,
            segments,
            sides,
        } => primitives::torus(major, minor, segments, sides),
        Primitive::Cylinder {
            radius,
            length,
            segments,
            rings,
        } => primitives::cylinder(radius, length, segments, rings),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use imprint_core::Error;
    use std::path::PathBuf;

    fn workspace_root() -> PathBuf {
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
    }

    fn params(text: &str) -> MeshParams {
        ron::from_str(text).unwrap_or_else(|e| panic!("{text}: {e}"))
    }

    fn source(text: &str) -> MeshSource {
        MeshSource::new(&params(text), &workspace_root()).unwrap()
    }

    /// A glTF file's clip poses the mesh per frame: the hand-made two-joint file
    /// (tests/data/two_joint.gltf; its clip "Bend" turns the child 90° about z through
    /// (0, 1, 0) over one second) puts the child's vertex (0, 2, 0) at (−1, 1, 0) at 1 s and
    /// the half-and-half vertex (0.5, 1, 0) at the blend (0.25, 1.25, 0); without `loop` it
    /// holds there; a fit scales the pose at time 0; unknown clips list the file's.
    #[test]
    fn a_gltf_clip_poses_the_mesh() {
        let src = source(r#"(path: "tests/data/two_joint.gltf", clip: "Bend", loop: false)"#);
        assert!(!src.is_static());
        let near = |m: &Mesh, p: Vec3| m.positions.iter().any(|q| q.distance(p) < 1e-5);
        for t in [1.0, 3.0] {
            let m = src.at(t);
            assert!(
                near(&m, Vec3::new(-1.0, 1.0, 0.0)),
                "{t}: {:?}",
                m.positions
            );
            assert!(
                near(&m, Vec3::new(0.25, 1.25, 0.0)),
                "{t}: {:?}",
                m.positions
            );
        }
        assert!(near(&src.at(0.0), Vec3::new(0.0, 2.0, 0.0)));
        let fitted = source(r#"(path: "tests/data/two_joint.gltf", clip: "Bend", fit: (size: 4))"#);
        assert!((fitted.rest_bounds().size().max_element() - 4.0).abs() < 1e-5);
        let err = MeshSource::new(
            &params(r#"(path: "tests/data/two_joint.gltf", clip: "Run")"#),
            &workspace_root(),
        )
        .unwrap_err();
        assert!(err.to_string().contains("Bend"), "{err}");
    }

    #[test]
    fn primitives_have_their_triangle_counts() {
        for (text, want) in [
            ("Sphere(radius: 0.5, segments: 16, rings: 8)", 2 * 16 * 7),
            ("Sphere(radius: 0.5)", 2 * 64 * 31),
            ("Box(size: (1, 2, 3), subdivisions: 3)", 6 * 2 * 9),
            ("Box(size: (1, 2, 3))", 6 * 2 * 16 * 16),
            ("Plane(size: 2, subdivisions: 5)", 2 * 25),
            (
                "Torus(major: 1, minor: 0.25, segments: 12, sides: 6)",
                2 * 12 * 6,
            ),
        ] {
            let s = source(&format!("(primitive: {text})"));
            assert_eq!(s.rest().triangles.len(), want, "{text}");
            assert_eq!(
                params(&format!("(primitive: {text})"))
                    .primitive
                    .unwrap()
                    .triangle_count(),
                want as u64
            );
        }
        // Box size is the full extent, not the half.
        let b = source("(primitive: Box(size: (1, 2, 3), subdivisions: 1))").rest_bounds();
        assert!(
            (b.size() - Vec3::new(1.0, 2.0, 3.0)).length() < 1e-6,
            "{:?}",
            b
        );
    }

    #[test]
    fn fit_sets_longest_side_and_centre() {
        let s = source("(primitive: Box(size: (1, 4, 2)), fit: (size: 2, center: (1, -1, 0.5)))");
        let b = s.rest().bounds();
        assert!(
            (b.size() - Vec3::new(0.5, 2.0, 1.0)).length() < 1e-5,
            "{:?}",
            b.size()
        );
        assert!(
            (b.center() - Vec3::new(1.0, -1.0, 0.5)).length() < 1e-5,
            "{:?}",
            b.center()
        );
        assert_eq!(s.rest_bounds(), b);

        let bunny = source(r#"(path: "assets/meshes/stanford-bunny.obj", fit: (size: 1.0))"#);
        let b = bunny.rest_bounds();
        assert!((b.size().max_element() - 1.0).abs() < 1e-5);
        assert!(b.center().length() < 1e-5);
        // Without a fit the file's own coordinates are kept (the bunny is ~0.15 across).
        let raw = source(r#"(path: "assets/meshes/stanford-bunny.obj")"#);
        assert!(raw.rest_bounds().size().max_element() < 0.5);
    }

    #[test]
    fn missing_obj_names_the_path() {
        let e = MeshSource::new(
            &params(r#"(path: "meshes/no-such-mesh.obj")"#),
            Path::new("/nowhere"),
        )
        .unwrap_err();
        assert!(matches!(e, Error::Mesh { .. }), "{e:?}");
        assert!(
            e.to_string().contains("/nowhere/meshes/no-such-mesh.obj"),
            "{e}"
        );
    }

    #[test]
    fn invalid_params_are_refused_before_loading() {
        let e = MeshSource::new(
            &params(r#"(path: "missing.obj", motion: [Breathe(amplitude: 0.1, period: 0)])"#),
            Path::new("."),
        )
        .unwrap_err();
        assert!(
            e.to_string()
                .contains("motion[0] Breathe.period must be > 0"),
            "{e}"
        );
    }

    #[test]
    fn static_and_moving_meshes() {
        let plain = source("(primitive: Sphere(radius: 1, segments: 8, rings: 4))");
        assert!(plain.is_static());
        assert_eq!(&plain.at(3.0), plain.rest());

        // A constant twist is static but not the rest shape.
        let twisted =
            source("(primitive: Box(size: (1, 1, 1)), motion: [Twist(axis: Y, degrees: 45)])");
        assert!(twisted.is_static());
        assert_eq!(twisted.at(0.0), twisted.at(5.0));
        assert_ne!(twisted.at(0.0).positions, twisted.rest().positions);

        let breathing = source(
            "(primitive: Box(size: (1, 1, 1)), motion: [Breathe(amplitude: 0.1, period: 1)])",
        );
        assert!(!breathing.is_static());
        let m = breathing.at(0.25);
        assert_eq!(m.triangles, breathing.rest().triangles);
        assert!((m.bounds().size().x - 1.1).abs() < 1e-6);
    }

    #[test]
    fn normals_match_compute_normals_exactly() {
        let s = source(
            r#"(path: "assets/meshes/stanford-bunny.obj", fit: (size: 1.0),
                motion: [Breathe(amplitude: 0.05, period: 2.0), Twist(axis: Y, degrees: 30, period: 3),
                         Bend(axis: Y, degrees: 40, period: 5), Wave(amplitude: 0.01, wavelength: 0.3, speed: 0.2),
                         Rigid(keys: [(time: 0), (time: 1, translate: (0, 1, 0), rotate: (axis: (1, 1, 0), degrees: 60))])])"#,
        );
        let m = s.at(0.7);
        let mut reference = m.clone();
        reference.compute_normals();
        assert_eq!(m.normals, reference.normals);
        m.validate("bunny").unwrap();
        assert_eq!(m.uvs, s.rest().uvs);
    }

    #[test]
    fn thread_count_does_not_change_the_result() {
        let s = source(
            r#"(path: "assets/meshes/stanford-bunny.obj", fit: (size: 1.0),
                motion: [Breathe(amplitude: 0.05, period: 2.0), Twist(axis: Y, degrees: 30, period: 1.3)])"#,
        );
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap();
        let four = rayon::ThreadPoolBuilder::new()
            .num_threads(4)
            .build()
            .unwrap();
        let a = one.install(|| s.at(0.37));
        let b = four.install(|| s.at(0.37));
        assert_eq!(a, b);
        // Reusing buffers gives the same mesh.
        let mut c = s.at(1.9);
        s.at_into(0.37, &mut c);
        assert_eq!(a, c);
        let mut p = Vec::new();
        s.positions_at_into(0.37, &mut p);
        assert_eq!(p, a.positions);
    }

    #[test]
    fn motions_compose_in_order() {
        // Breathe then Rigid: the translation is not scaled; Rigid then Breathe about the
        // rest centre: it is.
        let p = |order: &str| {
            source(&format!(
                "(primitive: Box(size: (1, 1, 1), subdivisions: 1), motion: [{order}])"
            ))
            .at(0.25)
            .bounds()
            .center()
        };
        let breathe = "Breathe(amplitude: 0.5, period: 1)";
        let rigid = "Rigid(keys: [(time: 0, translate: (1, 0, 0))])";
        assert!((p(&format!("{breathe}, {rigid}")) - Vec3::X).length() < 1e-6);
        assert!((p(&format!("{rigid}, {breathe}")) - 1.5 * Vec3::X).length() < 1e-6);
    }

    #[test]
    fn sampled_bounds_cover_the_motion() {
        let s = source(
            "(primitive: Box(size: (1, 1, 1)), motion: [Breathe(amplitude: 0.2, period: 1)])",
        );
        let b = s.sampled_bounds((0..8).map(|i| i as f32 / 8.0));
        assert!((b.size().x - 1.2).abs() < 1e-6, "{:?}", b);
        // A mesh that only ever sits elsewhere does not include its rest box.
        let moved = source(
            "(primitive: Box(size: (1, 1, 1)), motion: [Rigid(keys: [(time: 0, translate: (5, 0, 0))])])",
        );
        let b = moved.sampled_bounds([0.0, 1.0]);
        assert!((b.min.x - 4.5).abs() < 1e-6, "{:?}", b);
        assert_eq!(moved.sampled_bounds([]), moved.rest_bounds());
    }

    /// Per-frame cost on the bunny; prints, asserts nothing (timings belong in benchmarks).
    /// The minimum over frames is reported, as the least disturbed by other processes.
    /// `cargo test --release -p imprint-stages --lib mesh::tests::bunny_frame_time -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn bunny_frame_time() {
        use std::time::{Duration, Instant};
        fn best(frames: usize, mut f: impl FnMut(usize)) -> Duration {
            (0..frames)
                .map(|i| {
                    let t0 = Instant::now();
                    f(i);
                    t0.elapsed()
                })
                .min()
                .unwrap()
        }
        let cases = [
            ("none", ""),
            (
                "Breathe+Twist",
                "Breathe(amplitude: 0.05, period: 2.0), Twist(axis: Y, degrees: 30)",
            ),
            ("Breathe", "Breathe(amplitude: 0.05, period: 2.0)"),
            ("Twist", "Twist(axis: Y, degrees: 30, period: 2)"),
            ("Bend", "Bend(axis: Y, degrees: 30, period: 2)"),
            ("Wave", "Wave(amplitude: 0.01, wavelength: 0.2, speed: 0.5)"),
            (
                "Rigid",
                "Rigid(keys: [(time: 0), (time: 4, rotate: (axis: Y, degrees: 90))])",
            ),
        ];
        for threads in [1, rayon::current_num_threads()] {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            for (name, motion) in cases {
                let s = source(&format!(
                    r#"(path: "assets/meshes/stanford-bunny.obj", fit: (size: 1.0), motion: [{motion}])"#
                ));
                let mut out = s.at(0.1);
                let frames = 300;
                let (positions, normals, total) = pool.install(|| {
                    let deforms: Vec<Deform> = s.motions.iter().map(|m| m.at(0.5)).collect();
                    let positions = best(frames, |_| {
                        s.deform_positions(0.0, &deforms, &mut out.positions)
                    });
                    let positions_now = out.positions.clone();
                    let normals = best(frames, |_| {
                        s.compute_normals(&positions_now, &mut out.normals)
                    });
                    let total = best(frames, |f| s.at_into(f as f32 / 60.0, &mut out));
                    (positions, normals, total)
                });
                println!(
                    "bunny {} vertices, {threads} thread(s), {name}: positions {positions:?}, normals {normals:?}, at_into {total:?} per frame",
                    s.rest().positions.len()
                );
            }
        }
    }
}
