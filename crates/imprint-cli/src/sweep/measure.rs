//! What a sweep compares between runs, and the reference run's cache.
//!
//! The reference run keeps, per frame, a compact picture of every node that has an error
//! metric (a *track*):
//! - a distance field: up to [`MAX_PROBES`] probe points (centres of the reference's band
//!   cells, every k-th in index order) and the reference's distance there;
//! - a cloth: every particle's position;
//! - a height field: up to [`MAX_PROBES`] cell centres (every k-th cell) and their height.
//!
//! Another run is compared with it probe by probe, on the same frames: a field is sampled
//! (trilinear, [`Sampling::Distance`]) at the probes, the error in the reference's cells; a
//! cloth's particles are compared one to one (world units); a height field is sampled
//! bilinearly at the probes (world units). The reference's own values are taken through the
//! same sampling, so a run identical to the reference measures exactly zero.
//!
//! The cache is `reference.json` (what was run, the tracks, the timing) and `reference.bin`
//! (every track's numbers, little-endian f32, in the order the header lists them).

use imprint_core::io::atomic_write_bytes;
use imprint_core::{DistanceField, Error, HeightField, Result, Sampling};
use imprint_graph::Plan;
use imprint_graph::exec::{Observed, Observer};
use imprint_graph::report::Report;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::ops::Range;
use std::path::Path;

/// Probes kept per field or height field per frame.
pub const MAX_PROBES: usize = 4096;

/// Changes whenever the cache's layout or what it measures changes.
const FORMAT: u32 = 1;

/// The three kinds of node with an error metric.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrackKind {
    Field,
    /// Vertex positions (a cloth, a skin, a drape, snow on a mesh).
    Vertices,
    Heights,
}

impl TrackKind {
    /// What a node's error is measured on, as its kind declares it.
    pub fn of(node: &imprint_graph::schema::NodeSpec) -> Option<TrackKind> {
        use imprint_graph::node::Track;
        Some(match node.node().track()? {
            Track::Field => TrackKind::Field,
            Track::Vertices => TrackKind::Vertices,
            Track::Heights => TrackKind::Heights,
        })
    }

    /// Numbers per probe in the cache: xyz + distance, xyz, xz + height.
    fn stride(self) -> usize {
        match self {
            TrackKind::Field => 4,
            TrackKind::Vertices | TrackKind::Heights => 3,
        }
    }

    /// The name of the error in column headers.
    pub fn quantity(self) -> &'static str {
        match self {
            TrackKind::Field => "err",
            TrackKind::Vertices => "dist",
            TrackKind::Heights => "height",
        }
    }

    /// The unit of the error in column headers ("" for world units).
    pub fn unit_suffix(self) -> &'static str {
        match self {
            TrackKind::Field => "_cells",
            TrackKind::Vertices | TrackKind::Heights => "",
        }
    }

    /// What the error is, for people.
    pub fn describe(self) -> &'static str {
        match self {
            TrackKind::Field => "distance error, in reference cells",
            TrackKind::Vertices => "particle distance from the reference, world units",
            TrackKind::Heights => "height difference, world units",
        }
    }
}

/// One node's per-frame record in the reference.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct Track {
    pub node: String,
    pub kind: TrackKind,
    /// Errors are divided by this: the reference's cell size for fields, 1 otherwise.
    pub unit: f32,
    pub frames: Vec<TrackFrame>,
}

/// Where one frame of a track lies in the data (in f32s).
#[derive(Clone, Copy, Debug, Serialize, Deserialize)]
pub struct TrackFrame {
    pub frame: u32,
    pub offset: usize,
    pub len: usize,
}

/// A run's timing: frame wall times without the sweep's own measuring, and per-node totals.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Timing {
    pub frame_ms: Vec<f64>,
    /// Per node, in the plan's order: (name, frames it computed on, total ms).
    pub nodes: Vec<(String, u32, f64)>,
}

impl Timing {
    /// `report`'s timing (its frame times leave out what observers took, the measuring
    /// here included).
    pub fn from_report(report: &Report, plan: &Plan) -> Self {
        let frame_ms = report.frame_ms.clone();
        let nodes = plan
            .order
            .iter()
            .filter_map(|n| report.nodes.get(n).map(|r| (n.clone(), r.runs, r.total_ms)))
            .collect();
        Timing { frame_ms, nodes }
    }

    pub fn mean_ms(&self) -> f64 {
        self.frame_ms.iter().sum::<f64>() / self.frame_ms.len().max(1) as f64
    }

    /// Nearest-rank 95th percentile.
    pub fn p95_ms(&self) -> f64 {
        let mut v = self.frame_ms.clone();
        v.sort_by(f64::total_cmp);
        let rank = (0.95 * v.len() as f64).ceil() as usize;
        v.get(rank.saturating_sub(1)).copied().unwrap_or(0.0)
    }

    pub fn max_ms(&self) -> f64 {
        self.frame_ms.iter().copied().fold(0.0, f64::max)
    }
}

/// What the cache header says was run.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
struct Identity {
    format: u32,
    imprint: String,
    base_dir: String,
    frames: (u32, u32),
    backend: String,
    text: String,
}

impl Identity {
    fn new(plan: &Plan, frames: &Range<u32>, backend: &str) -> Self {
        let base_dir =
            std::path::absolute(&plan.base_dir).unwrap_or_else(|_| plan.base_dir.clone());
        Identity {
            format: FORMAT,
            imprint: env!("CARGO_PKG_VERSION").to_string(),
            base_dir: base_dir.display().to_string(),
            frames: (frames.start, frames.end),
            backend: backend.to_string(),
            text: plan.source.text.clone(),
        }
    }

    /// FNV-1a over everything the reference depends on that the sweep can see.
    fn key(&self) -> String {
        let mut h: u64 = 0xcbf2_9ce4_8422_2325;
        let frames = format!("{}..{}", self.frames.0, self.frames.1);
        let format = self.format.to_string();
        for part in [
            &format,
            &self.imprint,
            &self.base_dir,
            &frames,
            &self.backend,
            &self.text,
        ] {
            for b in part.bytes().chain([0xff]) {
                h ^= u64::from(b);
                h = h.wrapping_mul(0x0000_0100_0000_01b3);
            }
        }
        format!("{h:016x}")
    }
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Header {
    #[serde(flatten)]
    identity: Identity,
    pipeline: String,
    tracks: Vec<Track>,
    timing: Timing,
}

/// The reference run: its tracks, their numbers, its timing.
pub struct Reference {
    pub tracks: Vec<Track>,
    pub data: Vec<f32>,
    pub timing: Timing,
}

/// Where a reference lives, and what it must match to be reused.
pub struct Cache {
    identity: Identity,
    pub dir: std::path::PathBuf,
}

impl Cache {
    /// The cache folder for `plan` (the reference's plan) under `root`.
    pub fn new(root: &Path, plan: &Plan, frames: &Range<u32>, backend: &str) -> Self {
        let identity = Identity::new(plan, frames, backend);
        let dir = root.join(identity.key());
        Cache { identity, dir }
    }

    /// The cached reference, if a complete one for the same run is there; `Err(why)` says
    /// why one that is there cannot be used.
    pub fn load(&self) -> std::result::Result<Option<Reference>, String> {
        let json = self.dir.join("reference.json");
        let Ok(text) = std::fs::read_to_string(&json) else {
            return Ok(None);
        };
        let header: Header = serde_json::from_str(&text)
            .map_err(|e| format!("{} is unreadable ({e})", json.display()))?;
        if header.identity != self.identity {
            return Err(format!(
                "{} was made from another pipeline, frame range, backend or imprint version",
                json.display()
            ));
        }
        let bin = self.dir.join("reference.bin");
        let bytes = std::fs::read(&bin).map_err(|e| format!("{}: {e}", bin.display()))?;
        let want: usize = header
            .tracks
            .iter()
            .flat_map(|t| &t.frames)
            .map(|f| f.len)
            .sum();
        if bytes.len() != want * 4 {
            return Err(format!(
                "{} holds {} bytes, the header lists {}",
                bin.display(),
                bytes.len(),
                want * 4
            ));
        }
        let data = bytes
            .chunks_exact(4)
            .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
            .collect();
        Ok(Some(Reference {
            tracks: header.tracks,
            data,
            timing: header.timing,
        }))
    }

    /// Writes the reference: the numbers first, then the header that makes them valid.
    pub fn save(&self, pipeline: &str, reference: &Reference) -> Result<()> {
        let bytes: Vec<u8> = reference
            .data
            .iter()
            .flat_map(|v| v.to_le_bytes())
            .collect();
        atomic_write_bytes(&self.dir.join("reference.bin"), &bytes)?;
        let header = Header {
            identity: self.identity.clone(),
            pipeline: pipeline.to_string(),
            tracks: reference.tracks.clone(),
            timing: reference.timing.clone(),
        };
        let json = serde_json::to_string_pretty(&header)
            .map_err(|e| Error::Run(format!("reference header: {e}")))?;
        atomic_write_bytes(&self.dir.join("reference.json"), json.as_bytes())
    }
}

/// Every k-th of `n` items, so that at most [`MAX_PROBES`] are kept.
fn probe_stride(n: usize) -> usize {
    n.div_ceil(MAX_PROBES).max(1)
}

/// Bilinear height at world (x, z), clamped to the field's cells.
fn height_at(h: &HeightField, x: f32, z: f32) -> f32 {
    let last = h.dims - 1;
    let fx = ((x - h.origin.x) / h.cell).clamp(0.0, last.x as f32);
    let fz = ((z - h.origin.y) / h.cell).clamp(0.0, last.y as f32);
    let (i0, k0) = (fx.floor() as u32, fz.floor() as u32);
    let (i1, k1) = ((i0 + 1).min(last.x), (k0 + 1).min(last.y));
    let (tx, tz) = (fx - i0 as f32, fz - k0 as f32);
    let row = |k| h.get(i0, k) * (1.0 - tx) + h.get(i1, k) * tx;
    row(k0) * (1.0 - tz) + row(k1) * tz
}

/// A field's probes: centres of every k-th band cell, with the distance sampled there.
fn field_probes(f: &DistanceField) -> Vec<f32> {
    let band: Vec<usize> = (0..f.dist.len()).filter(|&i| !f.is_far(i)).collect();
    let mut out = Vec::with_capacity(4 * band.len().min(MAX_PROBES));
    for &i in band.iter().step_by(probe_stride(band.len())) {
        let p = f.spec.center(f.spec.coords(i));
        out.extend([p.x, p.y, p.z, f.sample(p, Sampling::Distance).distance]);
    }
    out
}

/// A height field's probes: centres of every k-th cell, with the height there.
fn height_probes(h: &HeightField) -> Vec<f32> {
    let n = h.heights.len();
    let mut out = Vec::with_capacity(3 * n.min(MAX_PROBES));
    for c in (0..n).step_by(probe_stride(n)) {
        let (i, k) = (c as u32 % h.dims.x, c as u32 / h.dims.x);
        let (x, z) = (
            h.origin.x + i as f32 * h.cell,
            h.origin.y + k as f32 * h.cell,
        );
        out.extend([x, z, height_at(h, x, z)]);
    }
    out
}

/// Records the reference run.
pub struct Recorder<'a> {
    plan: &'a Plan,
    tracks: Vec<Track>,
    data: Vec<f32>,
}

impl<'a> Recorder<'a> {
    pub fn new(plan: &'a Plan) -> Self {
        Recorder {
            plan,
            tracks: Vec::new(),
            data: Vec::new(),
        }
    }

    /// The reference, with the run's timing (less the recording).
    pub fn finish(self, report: &Report) -> Reference {
        Reference {
            timing: Timing::from_report(report, self.plan),
            tracks: self.tracks,
            data: self.data,
        }
    }
}

impl Observer for Recorder<'_> {
    fn save(&self) -> Vec<u8> {
        save_or_empty(&(&self.tracks, &self.data))
    }

    fn load(&mut self, bytes: &[u8]) -> std::result::Result<(), String> {
        (self.tracks, self.data) = load_saved(bytes, "the reference's probes")?;
        Ok(())
    }

    fn observe(&mut self, node: &str, frame: u32, value: Observed<'_>) {
        let Some(kind) = self.plan.file.nodes.get(node).and_then(TrackKind::of) else {
            return;
        };
        let (values, unit) = match value {
            Observed::Field(f) => (field_probes(f), f.spec.cell),
            Observed::Mesh(m) => (m.positions.iter().flat_map(|p| p.to_array()).collect(), 1.0),
            Observed::Heights(h) => (height_probes(h), 1.0),
        };
        let at = match self.tracks.iter().position(|t| t.node == node) {
            Some(i) => i,
            None => {
                self.tracks.push(Track {
                    node: node.to_string(),
                    kind,
                    unit,
                    frames: Vec::new(),
                });
                self.tracks.len() - 1
            }
        };
        self.tracks[at].frames.push(TrackFrame {
            frame,
            offset: self.data.len(),
            len: values.len(),
        });
        self.data.extend(values);
    }
}

/// One frame's error statistics for one node.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FrameError {
    pub frame: u32,
    /// Probes (or particles) compared.
    pub n: usize,
    pub sum: f64,
    pub sum_sq: f64,
    pub max: f64,
}

impl FrameError {
    fn push(&mut self, e: f64) {
        self.n += 1;
        self.sum += e;
        self.sum_sq += e * e;
        self.max = self.max.max(e);
    }

    /// Mean, RMS and max, or `None` when nothing was compared.
    pub fn stats(&self) -> Option<[f64; 3]> {
        (self.n > 0).then(|| {
            let n = self.n as f64;
            [self.sum / n, (self.sum_sq / n).sqrt(), self.max]
        })
    }

    /// All frames together.
    pub fn total(frames: &[FrameError]) -> FrameError {
        frames
            .iter()
            .fold(FrameError::default(), |a, f| FrameError {
                frame: 0,
                n: a.n + f.n,
                sum: a.sum + f.sum,
                sum_sq: a.sum_sq + f.sum_sq,
                max: a.max.max(f.max),
            })
    }
}

impl Reference {
    /// The reference compared with itself: zero everywhere, on every probe.
    pub fn zero_errors(&self) -> BTreeMap<String, Vec<FrameError>> {
        self.tracks
            .iter()
            .map(|t| {
                let frames = t
                    .frames
                    .iter()
                    .map(|f| FrameError {
                        frame: f.frame,
                        n: f.len / t.kind.stride(),
                        ..Default::default()
                    })
                    .collect();
                (t.node.clone(), frames)
            })
            .collect()
    }
}

/// Compares a run with the reference as it goes.
pub struct Comparer<'a> {
    reference: &'a Reference,
    /// Per tracked node, per frame compared.
    pub errors: BTreeMap<String, Vec<FrameError>>,
    /// What could not be compared, for the row's status.
    pub notes: BTreeSet<String>,
}

impl<'a> Comparer<'a> {
    pub fn new(reference: &'a Reference) -> Self {
        Comparer {
            reference,
            errors: BTreeMap::new(),
            notes: BTreeSet::new(),
        }
    }

    /// The run's timing (the comparing is not in it).
    pub fn timing(&self, report: &Report, plan: &Plan) -> Timing {
        Timing::from_report(report, plan)
    }
}

impl Comparer<'_> {
    /// `value` against the reference's record of `node` on `frame`, if it has one.
    fn compare(&mut self, node: &str, frame: u32, value: Observed<'_>) -> Option<FrameError> {
        let track = self.reference.tracks.iter().find(|t| t.node == node)?;
        let at = track.frames.iter().find(|f| f.frame == frame)?;
        let want = &self.reference.data[at.offset..at.offset + at.len];
        let mut err = FrameError {
            frame,
            ..Default::default()
        };
        let unit = f64::from(track.unit);
        match (track.kind, value) {
            (TrackKind::Field, Observed::Field(f)) => {
                for p in want.chunks_exact(4) {
                    let got = f.sample(glam::Vec3::new(p[0], p[1], p[2]), Sampling::Distance);
                    err.push(f64::from((got.distance - p[3]).abs()) / unit);
                }
            }
            (TrackKind::Vertices, Observed::Mesh(m)) if m.positions.len() * 3 == want.len() => {
                for (p, q) in m.positions.iter().zip(want.chunks_exact(3)) {
                    let d = *p - glam::Vec3::new(q[0], q[1], q[2]);
                    err.push(f64::from(d.length()) / unit);
                }
            }
            (TrackKind::Vertices, Observed::Mesh(m)) => {
                self.notes.insert(format!(
                    "cloth '{node}' has {} particles, the reference {}: not compared",
                    m.positions.len(),
                    want.len() / 3
                ));
                return None;
            }
            (TrackKind::Heights, Observed::Heights(h)) => {
                for p in want.chunks_exact(3) {
                    err.push(f64::from((height_at(h, p[0], p[1]) - p[2]).abs()) / unit);
                }
            }
            _ => return None,
        }
        Some(err)
    }
}

impl Observer for Comparer<'_> {
    fn save(&self) -> Vec<u8> {
        save_or_empty(&(&self.errors, &self.notes))
    }

    fn load(&mut self, bytes: &[u8]) -> std::result::Result<(), String> {
        (self.errors, self.notes) = load_saved(bytes, "the errors measured so far")?;
        Ok(())
    }

    fn observe(&mut self, node: &str, frame: u32, value: Observed<'_>) {
        if let Some(err) = self.compare(node, frame, value) {
            self.errors.entry(node.to_string()).or_default().push(err);
        }
    }
}

/// An observer's state as a checkpoint keeps it (plain data: serialising cannot fail).
fn save_or_empty<T: Serialize>(state: &T) -> Vec<u8> {
    imprint_graph::node::save_state(state).expect("plain data serialises")
}

/// Reads back [`save_or_empty`]'s bytes; `what` names them when they are missing (a
/// checkpoint of a run that had no such observer) or unreadable.
fn load_saved<T: for<'de> Deserialize<'de>>(
    bytes: &[u8],
    what: &str,
) -> std::result::Result<T, String> {
    if bytes.is_empty() {
        return Err(format!("it holds no record of {what}"));
    }
    imprint_graph::node::load_state(bytes).map_err(|e| format!("{what}: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::{UVec2, Vec2};

    #[test]
    fn heights_sample_bilinearly_and_clamp() {
        let h = HeightField::from_fn(Vec2::ZERO, 1.0, UVec2::new(2, 2), |i, k| (i + 2 * k) as f32)
            .unwrap();
        assert_eq!(height_at(&h, 0.0, 0.0), 0.0);
        assert_eq!(height_at(&h, 1.0, 1.0), 3.0);
        assert_eq!(height_at(&h, 0.5, 0.5), 1.5);
        assert_eq!(height_at(&h, -5.0, 9.0), 2.0);
    }

    #[test]
    fn stride_keeps_at_most_max_probes() {
        for n in [0, 1, MAX_PROBES, MAX_PROBES + 1, 10 * MAX_PROBES + 3] {
            assert!(n.div_ceil(probe_stride(n)) <= MAX_PROBES, "{n}");
        }
    }

    #[test]
    fn frame_errors_combine() {
        let mut a = FrameError::default();
        a.push(1.0);
        a.push(3.0);
        let mut b = FrameError::default();
        b.push(2.0);
        let t = FrameError::total(&[a, b]);
        let [mean, rms, max] = t.stats().unwrap();
        assert_eq!(mean, 2.0);
        assert!((rms - (14.0f64 / 3.0).sqrt()).abs() < 1e-12);
        assert_eq!(max, 3.0);
        assert_eq!(FrameError::default().stats(), None);
    }

    #[test]
    fn percentile_is_nearest_rank() {
        let t = Timing {
            frame_ms: (1..=20).map(f64::from).collect(),
            nodes: vec![],
        };
        assert_eq!(t.p95_ms(), 19.0);
        assert_eq!(t.max_ms(), 20.0);
        assert_eq!(t.mean_ms(), 10.5);
    }
}
