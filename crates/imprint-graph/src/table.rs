//! What `imprint check` shows of a plan's schedule: which nodes compute once, and what each
//! running node does on each of the first frames, found by the executor's rules from what
//! each node declares ([`Trigger`], [`crate::schedule::Schedule`]).

use crate::node::Trigger;
use crate::plan::Plan;
use crate::schema::{CameraSpec, NodeSpec};
use std::collections::{BTreeMap, BTreeSet};

impl Plan {
    /// Nodes that compute once: every mesh upstream of them is static (no motion that depends
    /// on time), so their inputs never change after the first frame. Nodes that do not run
    /// count too (the mesh behind an interpolated field decides whether the field is static).
    pub fn static_nodes(&self) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        for name in &self.topo {
            let node = self.file.nodes[name].node();
            let is_static = match node.trigger() {
                Trigger::Time { moves } => !moves,
                Trigger::EveryFrame => false,
                Trigger::Inputs | Trigger::Writes => {
                    let inputs = node.inputs();
                    !inputs.is_empty() && inputs.iter().all(|p| out.contains(p.node))
                }
            };
            if is_static {
                out.insert(name.clone());
            }
        }
        out
    }

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
                    .map(|p| version.get(p.node).copied().unwrap_or(0))
                    .collect();
                let changed = seen.get(name) != Some(&inputs);
                let first = f == 0;
                let trigger = node.node().trigger();
                let (c, publish, began) = if trigger == Trigger::Writes {
                    (if sc.is_key(f) { 'w' } else { '.' }, false, false)
                } else if statics.contains(name) {
                    if first {
                        ('#', true, true)
                    } else {
                        ('.', false, false)
                    }
                } else if matches!(trigger, Trigger::Time { .. } | Trigger::EveryFrame) {
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
                // A writer writes on each of its keyframes, whatever its inputs do.
                _ if nodes[name].is_writer() => {
                    let every = match sc.every {
                        1 => String::new(),
                        k => format!("every {k}, offset {}; ", sc.offset),
                    };
                    match (statics.contains(name), camera_spins(&nodes[name])) {
                        (_, true) => format!("{every}moves with time: its camera spins"),
                        (true, false) => format!("{every}inputs static: the same each write"),
                        (false, false) => every.trim_end_matches("; ").to_string(),
                    }
                }
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

/// Whether a node's output changes with time when its inputs do not: a Render whose orbit
/// camera spins.
fn camera_spins(spec: &NodeSpec) -> bool {
    matches!(spec, NodeSpec::Render(r)
        if matches!(r.camera, CameraSpec::Orbit { spin, .. } if spin != 0.0))
}

fn part_char(p: u32) -> char {
    char::from_digit(p + 1, 36).unwrap_or('+')
}
