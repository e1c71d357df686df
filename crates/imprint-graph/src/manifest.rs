//! What a run wrote into its output folder (`manifest.json`), so that a rerun into the same
//! folder removes what the previous run wrote and this one did not (the frames past a shorter
//! rerun's end, a renamed writer's files, an old checkpoint). Only files a manifest lists are
//! ever removed: the user's own files in the folder, and files written outside it, are left
//! alone. Stale files are removed when the new run succeeds; until then the manifest keeps
//! them listed as `stale`, so an interrupted or failed run loses nothing and the next complete
//! run still cleans up.

use imprint_core::Error;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Component, Path, PathBuf};

/// The manifest's name in the output folder.
pub const MANIFEST: &str = "manifest.json";

/// The key of files the run itself writes (its checkpoint), beside the writer nodes' names.
pub const RUN_KEY: &str = "(run)";

#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Manifest {
    /// The pipeline file of the run.
    pub pipeline: String,
    /// The files the run wrote, by writer node, relative to the folder with `/` separators.
    pub files: BTreeMap<String, BTreeSet<String>>,
    /// Files an earlier run wrote that this one has not (yet) replaced: removed when this run
    /// completes.
    #[serde(default, skip_serializing_if = "BTreeSet::is_empty")]
    pub stale: BTreeSet<String>,
}

impl Manifest {
    /// The folder's manifest, if it has one. A manifest that cannot be read is an error
    /// naming it: without it the stale files cannot be told from the user's.
    pub fn read(out: &Path) -> crate::Result<Option<Manifest>> {
        let path = out.join(MANIFEST);
        let text = match std::fs::read_to_string(&path) {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
            Err(e) => {
                return Err(Error::Invalid(format!("cannot read {}: {e}", path.display())).into());
            }
        };
        serde_json::from_str(&text).map(Some).map_err(|e| {
            Error::Invalid(format!(
                "{}:{}:{}: {e}; it lists what the previous run wrote, so that its stale files \
                 can be removed (delete it to keep every file in the folder as it is)",
                path.display(),
                e.line(),
                e.column()
            ))
            .into()
        })
    }

    /// Every file it lists, by node or as stale.
    pub fn all(&self) -> BTreeSet<String> {
        let mut all: BTreeSet<String> = self.files.values().flatten().cloned().collect();
        all.extend(self.stale.iter().cloned());
        all
    }

    /// Adds `written` (absolute or relative to the working folder) under `node`; files outside
    /// `out` are not listed (they are never removed either).
    pub fn add(&mut self, out: &Path, node: &str, written: impl IntoIterator<Item = PathBuf>) {
        let listed = written.into_iter().filter_map(|p| relative(out, &p));
        self.files
            .entry(node.to_string())
            .or_default()
            .extend(listed);
    }

    /// Marks what `previous` lists and this manifest does not as stale.
    pub fn inherit_stale(&mut self, previous: &Manifest) {
        let mine: BTreeSet<String> = self.files.values().flatten().cloned().collect();
        self.stale = previous.all().difference(&mine).cloned().collect();
    }

    /// Writes it into `out` (to a temporary name, then renamed).
    pub fn write(&self, out: &Path) -> crate::Result<()> {
        let json = serde_json::to_string_pretty(self).expect("manifest is plain data");
        imprint_core::io::atomic_write_bytes(&out.join(MANIFEST), json.as_bytes())?;
        Ok(())
    }

    /// Removes the stale files from `out` (and the folders they leave empty); returns how
    /// many files went. A listed path that would leave the folder is skipped.
    pub fn remove_stale(&mut self, out: &Path) -> crate::Result<usize> {
        let mut removed = 0;
        for rel in std::mem::take(&mut self.stale) {
            if !is_inside(Path::new(&rel)) {
                continue;
            }
            let path = out.join(&rel);
            match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
                Err(e) => {
                    return Err(Error::Invalid(format!(
                        "cannot remove {} (written by the previous run into this folder): {e}",
                        path.display()
                    ))
                    .into());
                }
            }
            remove_empty_parents(out, &path);
        }
        Ok(removed)
    }
}

/// `path` relative to `out` with `/` separators, when it lies inside `out`.
fn relative(out: &Path, path: &Path) -> Option<String> {
    let rel = path.strip_prefix(out).ok()?;
    is_inside(rel).then(|| {
        rel.components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect::<Vec<_>>()
            .join("/")
    })
}

/// A relative path of plain names only (no `..`, no root): it cannot leave the folder.
fn is_inside(rel: &Path) -> bool {
    rel.components().next().is_some() && rel.components().all(|c| matches!(c, Component::Normal(_)))
}

/// Removes the folders between `file` and `out` that are empty now.
fn remove_empty_parents(out: &Path, file: &Path) {
    let mut dir = file.parent();
    while let Some(d) = dir.filter(|d| *d != out && d.starts_with(out)) {
        // Fails, and stops, at the first folder that still holds something.
        if std::fs::remove_dir(d).is_err() {
            break;
        }
        dir = d.parent();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_paths_inside_the_folder_are_listed() {
        let out = Path::new("/o");
        assert_eq!(
            relative(out, Path::new("/o/a/b.png")).as_deref(),
            Some("a/b.png")
        );
        assert_eq!(relative(out, Path::new("/elsewhere/b.png")), None);
        assert_eq!(relative(out, Path::new("/o/../b.png")), None);
        assert!(!is_inside(Path::new("../x")));
        assert!(!is_inside(Path::new("/x")));
        assert!(is_inside(Path::new("frames/0001.png")));
    }

    #[test]
    fn stale_is_what_the_previous_run_listed_and_this_one_did_not() {
        let out = Path::new("/o");
        let mut old = Manifest::default();
        old.add(
            out,
            "render",
            ["/o/f/1.png", "/o/f/2.png"].map(PathBuf::from),
        );
        old.stale.insert("older.png".into());
        let mut new = Manifest::default();
        new.add(out, "render", [PathBuf::from("/o/f/1.png")]);
        new.inherit_stale(&old);
        assert_eq!(
            new.stale,
            ["f/2.png", "older.png"]
                .map(String::from)
                .into_iter()
                .collect()
        );
    }

    #[test]
    fn removing_keeps_unlisted_files_and_non_empty_folders() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path();
        std::fs::create_dir_all(out.join("a/b")).unwrap();
        std::fs::create_dir_all(out.join("c")).unwrap();
        for f in ["a/b/1.png", "c/2.png", "c/mine.txt"] {
            std::fs::write(out.join(f), b"x").unwrap();
        }
        let mut m = Manifest {
            stale: ["a/b/1.png", "c/2.png", "gone.png", "../escape.png"]
                .map(String::from)
                .into_iter()
                .collect(),
            ..Default::default()
        };
        assert_eq!(m.remove_stale(out).unwrap(), 2);
        assert!(!out.join("a").exists(), "emptied folders go");
        assert!(out.join("c/mine.txt").is_file(), "unlisted files stay");
        assert!(m.stale.is_empty());
    }
}
