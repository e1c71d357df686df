//! When each node computes: the per-node `every`, `offset`, `split` and `interpolate` of the
//! pipeline file, as arithmetic on frame numbers (the executor asks; `imprint check` prints).
//!
//! - **Keyframes** are the frames where (frame − offset) mod every = 0. A compute node
//!   computes on a keyframe when one of its inputs changed since it last computed (and always
//!   on the run's first frame, so that its consumers have something); in between, consumers
//!   reuse its last result, at most `every − 1` frames old.
//! - **Split** spreads a build over `split` frames: keyframe K's parts run on frames
//!   K … K + split − 1, all from the inputs as they were at K, and the result appears on the
//!   last of them (`split − 1` frames after K).
//! - **Interpolate** (fields): consumers of frame f see the linear blend of the builds at the
//!   two keyframes around it, so the builds must exist before they are needed: keyframe K is
//!   first needed on frame K − every + 1 (when the cloth starts stepping from K − every toward
//!   K), and its parts run on the `split` frames ending there, from the mesh at K's own time.
//!   The blend adds no lag; it costs a third field in memory while the next build is under way.

use crate::plan::Plan;
use crate::schema::NodeSpec;
use std::collections::{BTreeMap, BTreeSet};

/// A node's schedule. Frames are signed: an interpolated node's first segment may start at
/// a keyframe before frame 0 (its mesh is a function of time, so that is fine).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Schedule {
    pub every: u32,
    pub offset: u32,
    pub split: u32,
    pub interpolate: bool,
}

impl Default for Schedule {
    fn default() -> Self {
        Schedule {
            every: 1,
            offset: 0,
            split: 1,
            interpolate: false,
        }
    }
}

impl Schedule {
    fn k(&self) -> i64 {
        self.every.max(1) as i64
    }

    /// Whether (frame − offset) mod every = 0.
    pub fn is_key(&self, frame: i64) -> bool {
        (frame - self.offset as i64).rem_euclid(self.k()) == 0
    }

    /// The latest keyframe at or before `frame`.
    pub fn key_at_or_before(&self, frame: i64) -> i64 {
        frame - (frame - self.offset as i64).rem_euclid(self.k())
    }

    /// Without interpolation: the keyframe whose build has a part on `frame`, and which part
    /// (0-based); parts of keyframe K run on K … K + split − 1.
    pub fn part_at(&self, frame: i64) -> Option<(i64, u32)> {
        let key = self.key_at_or_before(frame);
        let part = frame - key;
        (part < self.split as i64).then_some((key, part as u32))
    }

    /// With interpolation: the segment [a, a + every] whose blend the consumers of `frame`
    /// see, and the weight of its end. The segment holds the whole step from frame − 1 to
    /// frame (what the cloth integrates over); on the run's `first` frame, frame itself.
    pub fn segment(&self, frame: i64, first: i64) -> (i64, f32) {
        let t = if frame == first { frame } else { frame - 1 };
        let a = self.key_at_or_before(t);
        (a, (frame - a) as f32 / self.k() as f32)
    }

    /// With interpolation: the keyframe whose build has a part on `frame`, and which part:
    /// keyframe K is first needed on frame K − every + 1, and its parts run on the `split`
    /// frames ending there.
    pub fn ahead_part_at(&self, frame: i64) -> Option<(i64, u32)> {
        let (k, s) = (self.k(), self.split as i64);
        (0..s)
            .map(|p| (frame + k + s - 2 - p, p as u32))
            .find(|&(key, _)| self.is_key(key))
    }
}

impl NodeSpec {
    /// The node's schedule as the file sets it (nodes without those fields: every frame).
    pub fn schedule(&self) -> Schedule {
        let (every, offset) = match self {
            NodeSpec::Voxelize(v) => (v.every, v.offset),
            NodeSpec::DistanceField(f) => (f.every, f.offset),
            NodeSpec::Heightmap(h) => (h.every, h.offset),
            NodeSpec::WriteField(w) => (w.every, w.offset),
            NodeSpec::WriteMesh(w) => (w.every, w.offset),
            NodeSpec::WriteHeightmap(w) => (w.every, w.offset),
            NodeSpec::Render(r) => (r.every, r.offset),
            NodeSpec::Mesh(_)
            | NodeSpec::Cloth(_)
            | NodeSpec::Ground(_)
            | NodeSpec::Snow(_)
            | NodeSpec::Drape(_)
            | NodeSpec::Skin(_) => (1, 0),
        };
        let (split, interpolate) = match self {
            NodeSpec::DistanceField(f) => (f.split, f.interpolate),
            _ => (1, false),
        };
        Schedule {
            every,
            offset,
            split,
            interpolate,
        }
    }

    /// `enabled` as the file sets it.
    pub fn enabled(&self) -> bool {
        match self {
            NodeSpec::Mesh(m) => m.enabled,
            NodeSpec::Voxelize(v) => v.enabled,
            NodeSpec::DistanceField(f) => f.enabled,
            NodeSpec::Heightmap(h) => h.enabled,
            NodeSpec::Cloth(c) => c.enabled,
            NodeSpec::WriteField(w) => w.enabled,
            NodeSpec::WriteMesh(w) => w.enabled,
            NodeSpec::WriteHeightmap(w) => w.enabled,
            NodeSpec::Render(r) => r.enabled,
            NodeSpec::Ground(g) => g.enabled,
            NodeSpec::Snow(n) => n.enabled,
            NodeSpec::Drape(d) => d.enabled,
            NodeSpec::Skin(k) => k.enabled,
        }
    }
}

impl Plan {
    /// Nodes that compute once: every mesh upstream of them is static (no motion that depends
    /// on time), so their inputs never change after the first frame.
    pub fn static_nodes(&self) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        let nodes = &self.file.nodes;
        let mut all: Vec<&String> = self.order.iter().collect();
        // Meshes read ahead by interpolated fields do not run, but decide those fields.
        for (n, _) in &self.pruned {
            if let NodeSpec::Mesh(_) = nodes[n] {
                all.insert(0, n);
            }
        }
        for name in all {
            let node = &nodes[name];
            let is_static = match node {
                NodeSpec::Mesh(m) => m.motion.iter().all(|mo| mo.is_time_invariant()),
                NodeSpec::Cloth(_)
                | NodeSpec::Ground(_)
                | NodeSpec::Snow(_)
                | NodeSpec::Skin(_) => false,
                NodeSpec::DistanceField(f) if f.interpolate => {
                    let NodeSpec::Voxelize(v) = &nodes[&f.boundary] else {
                        unreachable!("edges are typed")
                    };
                    matches!(&nodes[&v.mesh], NodeSpec::Mesh(m) if m.motion.iter().all(|mo| mo.is_time_invariant()))
                }
                _ => {
                    !node.inputs().is_empty()
                        && node.inputs().iter().all(|(_, i, _)| out.contains(*i))
                }
            };
            if is_static {
                out.insert(name.clone());
            }
        }
        out
    }

    /// `imprint check`'s schedule: per running node, what it does on each of the first
    /// `frames` frames, found by the executor's rules (a node computes on its keyframes when
    /// an input has a new value): `#` computes, `1`…`9` runs that part of a split build,
    /// `w` writes, `.` reuses its last result (interpolated: blends its two builds).
    pub fn schedule_table(&self, frames: u32) -> String {
        let statics = self.static_nodes();
        let nodes = &self.file.nodes;
        let n = frames.min(self.file.frames) as i64;
        let mut rows: BTreeMap<&str, String> = BTreeMap::new();
        let mut version: BTreeMap<&str, u64> = BTreeMap::new();
        let mut seen: BTreeMap<&str, Vec<u64>> = BTreeMap::new();
        // Split builds under way: node -> next part.
        let mut jobs: BTreeMap<&str, u32> = BTreeMap::new();
        for f in 0..n {
            for name in &self.order {
                let name = name.as_str();
                let node = &nodes[name];
                let sc = node.schedule();
                let inputs: Vec<u64> = node
                    .inputs()
                    .iter()
                    .map(|(_, i, _)| version.get(i).copied().unwrap_or(0))
                    .collect();
                let changed = seen.get(name) != Some(&inputs);
                let first = f == 0;
                let (c, publish, began) = if node.is_writer() {
                    (if sc.is_key(f) { 'w' } else { '.' }, false, false)
                } else if statics.contains(name) {
                    if first {
                        ('#', true, true)
                    } else {
                        ('.', false, false)
                    }
                } else if matches!(
                    node,
                    NodeSpec::Mesh(_)
                        | NodeSpec::Cloth(_)
                        | NodeSpec::Ground(_)
                        | NodeSpec::Snow(_)
                        | NodeSpec::Skin(_)
                ) {
                    ('#', true, true)
                } else if sc.interpolate {
                    // Frame 0 builds its segment's two keyframes whole; later ones in parts.
                    let bootstrap = sc.key_at_or_before(0) + sc.every as i64;
                    let c = match sc.ahead_part_at(f) {
                        _ if first => '#',
                        Some((k, _)) if k <= bootstrap => '.',
                        Some((_, p)) if sc.split > 1 => part_char(p),
                        Some(_) => '#',
                        None => '.',
                    };
                    (c, true, c != '.')
                } else if let Some(p) = jobs.get(name).copied() {
                    if p + 1 == sc.split {
                        jobs.remove(name);
                    } else {
                        jobs.insert(name, p + 1);
                    }
                    (part_char(p), p + 1 == sc.split, false)
                } else if first || (sc.is_key(f) && changed) {
                    if !first && sc.split > 1 {
                        jobs.insert(name, 1);
                        ('1', false, true)
                    } else {
                        ('#', true, true)
                    }
                } else {
                    ('.', false, false)
                };
                if began {
                    seen.insert(name, inputs);
                }
                if publish {
                    *version.entry(name).or_default() += 1;
                }
                rows.entry(name).or_default().push(c);
            }
        }
        let width = self.order.iter().map(|s| s.len()).max().unwrap_or(4).max(4);
        let ruler: String = (0..n)
            .map(|f| if f % 10 == 0 { '|' } else { ' ' })
            .collect();
        let mut s = format!("{:<width$}  {ruler}  (frames 0..{n}; | every 10)\n", "node");
        for name in &self.order {
            let sc = nodes[name].schedule();
            let what = match (sc.interpolate, sc.split, sc.every) {
                _ if statics.contains(name) => "static: computes once".to_string(),
                (true, s, k) => format!("every {k}, split {s}, interpolated (built {k} ahead)"),
                (false, s, k) if s > 1 => format!("every {k}, split {s} (ready {} later)", s - 1),
                (false, _, 1) => String::new(),
                (false, _, k) => format!("every {k}, offset {}", sc.offset),
            };
            s += &format!("{name:<width$}  {}  {what}\n", rows[name.as_str()]);
        }
        s += "# computes, 1-9 part of a split build, w writes, . reuses (interpolated: blends)\n";
        s
    }
}

fn part_char(p: u32) -> char {
    char::from_digit(p + 1, 36).unwrap_or('+')
}

#[cfg(test)]
mod tests {
    use super::*;

    fn s(every: u32, offset: u32, split: u32, interpolate: bool) -> Schedule {
        Schedule {
            every,
            offset,
            split,
            interpolate,
        }
    }

    #[test]
    fn keyframes_follow_every_and_offset() {
        let sc = s(4, 1, 1, false);
        let keys: Vec<i64> = (0..12).filter(|&f| sc.is_key(f)).collect();
        assert_eq!(keys, [1, 5, 9]);
        assert_eq!(sc.key_at_or_before(0), -3);
        assert_eq!(sc.key_at_or_before(8), 5);
    }

    #[test]
    fn split_parts_run_on_the_frames_after_each_keyframe() {
        let sc = s(4, 0, 3, false);
        let parts: Vec<Option<(i64, u32)>> = (0..9).map(|f| sc.part_at(f)).collect();
        assert_eq!(
            parts,
            [
                Some((0, 0)),
                Some((0, 1)),
                Some((0, 2)),
                None,
                Some((4, 0)),
                Some((4, 1)),
                Some((4, 2)),
                None,
                Some((8, 0))
            ]
        );
    }

    #[test]
    fn interpolated_builds_finish_the_frame_they_are_first_needed() {
        let sc = s(4, 0, 2, true);
        // Frames 1..=4 step from 0 to 4: segment [0, 4]; frame 5 steps from 4: [4, 8].
        assert_eq!(sc.segment(0, 0), (0, 0.0));
        assert_eq!(sc.segment(1, 0), (0, 0.25));
        assert_eq!(sc.segment(4, 0), (0, 1.0));
        assert_eq!(sc.segment(5, 0), (4, 0.25));
        // Keyframe 8 is first needed on frame 5: its two parts run on frames 4 and 5.
        assert_eq!(sc.ahead_part_at(4), Some((8, 0)));
        assert_eq!(sc.ahead_part_at(5), Some((8, 1)));
        assert_eq!(sc.ahead_part_at(6), None);
        assert_eq!(sc.ahead_part_at(7), None);
        assert_eq!(sc.ahead_part_at(8), Some((12, 0)));
        // Unsplit: the build runs on the frame it is first needed.
        let one = s(4, 0, 1, true);
        assert_eq!(one.ahead_part_at(5), Some((8, 0)));
        assert_eq!(one.ahead_part_at(4), None);
    }
}
