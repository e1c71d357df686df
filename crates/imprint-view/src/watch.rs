//! Watching the pipeline file and the assets it reads (`notify`). Folders are watched, not
//! files: editors save by writing a new file and renaming it over the old one, which ends a
//! watch on the file itself. A save arrives as a burst of events; [`Watch::poll`] answers once
//! the burst has been quiet for [`SETTLE`], well inside the half second a reload may take.

use imprint_graph::Plan;
use notify::{RecommendedWatcher, RecursiveMode, Watcher};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::mpsc::{Receiver, channel};
use std::time::{Duration, Instant};

/// How long a burst of events must be quiet before it counts as one save.
pub const SETTLE: Duration = Duration::from_millis(60);

/// What changed on disk since the last poll.
#[derive(Debug, Default, PartialEq)]
pub struct Changed {
    /// The pipeline file itself.
    pub pipeline: bool,
    /// Nodes whose assets (mesh, rig files) changed.
    pub nodes: BTreeSet<String>,
}

pub struct Watch {
    watcher: RecommendedWatcher,
    events: Receiver<PathBuf>,
    pipeline: PathBuf,
    /// Asset file → the nodes that read it.
    assets: BTreeMap<PathBuf, Vec<String>>,
    folders: BTreeSet<PathBuf>,
    pending: Option<(Instant, Changed)>,
}

impl Watch {
    pub fn new(pipeline: &Path) -> notify::Result<Watch> {
        let (tx, events) = channel();
        let watcher = notify::recommended_watcher(move |e: notify::Result<notify::Event>| {
            if let Ok(e) = e
                && !matches!(e.kind, notify::EventKind::Access(_))
            {
                for p in e.paths {
                    let _ = tx.send(p);
                }
            }
        })?;
        let mut w = Watch {
            watcher,
            events,
            pipeline: canonical(pipeline),
            assets: BTreeMap::new(),
            folders: BTreeSet::new(),
            pending: None,
        };
        let own = w.pipeline.clone();
        w.watch_folder_of(&own)?;
        Ok(w)
    }

    /// Watches the files `plan`'s nodes name (any string field that is an existing file).
    pub fn track_assets(&mut self, plan: &Plan) {
        self.assets = assets(plan);
        let files: Vec<PathBuf> = self.assets.keys().cloned().collect();
        for f in files {
            // A folder that cannot be watched only loses reloads on its assets.
            let _ = self.watch_folder_of(&f);
        }
    }

    fn watch_folder_of(&mut self, file: &Path) -> notify::Result<()> {
        let folder = file.parent().unwrap_or(Path::new(".")).to_path_buf();
        if self.folders.insert(folder.clone()) {
            self.watcher.watch(&folder, RecursiveMode::NonRecursive)?;
        }
        Ok(())
    }

    /// What changed, once its burst of events has settled.
    pub fn poll(&mut self) -> Option<Changed> {
        while let Ok(path) = self.events.try_recv() {
            let path = canonical(&path);
            let is_pipeline = path == self.pipeline;
            let nodes = self.assets.get(&path);
            if !is_pipeline && nodes.is_none() {
                continue;
            }
            let (at, changed) = self
                .pending
                .get_or_insert_with(|| (Instant::now(), Changed::default()));
            *at = Instant::now();
            changed.pipeline |= is_pipeline;
            changed.nodes.extend(nodes.into_iter().flatten().cloned());
        }
        match &self.pending {
            Some((at, _)) if at.elapsed() >= SETTLE => self.pending.take().map(|(_, c)| c),
            _ => None,
        }
    }
}

/// The path with symbolic links and `..` resolved, when it exists (events name real paths).
fn canonical(p: &Path) -> PathBuf {
    std::fs::canonicalize(p).unwrap_or_else(|_| match p.parent().map(std::fs::canonicalize) {
        Some(Ok(dir)) => dir.join(p.file_name().unwrap_or_default()),
        _ => p.to_path_buf(),
    })
}

/// Every existing file a node's spec names, relative to the pipeline's folder: the node
/// kinds need not be known here.
fn assets(plan: &Plan) -> BTreeMap<PathBuf, Vec<String>> {
    let mut found: BTreeMap<PathBuf, Vec<String>> = BTreeMap::new();
    for (name, spec) in &plan.file.nodes {
        let Ok(json) = serde_json::to_value(spec) else {
            continue;
        };
        let mut strings = Vec::new();
        collect_strings(&json, &mut strings);
        for s in strings {
            let path = plan.base_dir.join(s);
            if path.is_file() {
                found
                    .entry(canonical(&path))
                    .or_default()
                    .push(name.clone());
            }
        }
    }
    found
}

fn collect_strings<'a>(v: &'a serde_json::Value, out: &mut Vec<&'a str>) {
    match v {
        serde_json::Value::String(s) => out.push(s),
        serde_json::Value::Array(a) => a.iter().for_each(|x| collect_strings(x, out)),
        serde_json::Value::Object(o) => o.values().for_each(|x| collect_strings(x, out)),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_save_by_rename_is_seen_once_settled_and_assets_name_their_nodes() {
        let dir = tempfile::tempdir().unwrap();
        let mesh = dir.path().join("tri.obj");
        std::fs::write(&mesh, "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        let file = dir.path().join("p.ron");
        let text = r#"Pipeline(frames: 2, nodes: {
            "m": Mesh(path: "tri.obj"),
            "hm": Heightmap(mesh: "m", view: Above, grid: Fit(resolution: 8, padding: 0.1)),
            "w": WriteHeightmap(heights: "hm"),
        })"#;
        std::fs::write(&file, text).unwrap();
        let plan = imprint_graph::load(&file, &[]).unwrap();
        let mut w = Watch::new(&file).unwrap();
        w.track_assets(&plan);
        assert_eq!(w.poll(), None);
        // An editor's save: a new file renamed over the old one.
        let tmp = dir.path().join(".p.ron.swp");
        std::fs::write(&tmp, text.replace("frames: 2", "frames: 3")).unwrap();
        std::fs::rename(&tmp, &file).unwrap();
        std::fs::write(&mesh, "v 0 0 0\nv 2 0 0\nv 0 2 0\nf 1 2 3\n").unwrap();
        let start = Instant::now();
        let changed = loop {
            if let Some(c) = w.poll() {
                break c;
            }
            assert!(start.elapsed() < Duration::from_secs(5), "no change seen");
            std::thread::sleep(Duration::from_millis(10));
        };
        assert!(changed.pipeline);
        assert_eq!(changed.nodes, BTreeSet::from(["m".to_string()]));
    }
}
