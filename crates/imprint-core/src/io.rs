//! Writing files so that a reader never sees a half-written file under its final name:
//! write to a temporary sibling, flush, then rename over the final name.

use crate::{Error, Result};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

/// A file being written under a temporary sibling name; [`AtomicFile::commit`] flushes it
/// and renames it over the final name. Dropped without a commit (an error, a panic, an
/// interrupted run), it removes the temporary file, so `path` keeps its previous state.
/// Streaming writers (a GIF that grows frame by frame) hold one for the whole run.
pub struct AtomicFile {
    path: PathBuf,
    tmp: PathBuf,
    writer: Option<BufWriter<File>>,
}

impl AtomicFile {
    /// Creates the temporary sibling of `path` (and `path`'s folder if missing).
    pub fn create(path: &Path) -> Result<Self> {
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
        let file_name = path
            .file_name()
            .ok_or_else(|| Error::Invalid(format!("{}: not a file path", path.display())))?;
        let tmp = path.with_file_name(format!(
            ".{}.{}.tmp",
            file_name.to_string_lossy(),
            std::process::id()
        ));
        let file = File::create(&tmp).map_err(|e| Error::io(&tmp, e))?;
        Ok(AtomicFile {
            path: path.to_path_buf(),
            tmp,
            writer: Some(BufWriter::new(file)),
        })
    }

    /// The final name.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes, syncs and renames the file to its final name.
    pub fn commit(mut self) -> Result<()> {
        let w = self.writer.take().expect("writer present until commit");
        let synced = w
            .into_inner()
            .map_err(|e| e.into_error())
            .and_then(|f| f.sync_data());
        let result = synced.and_then(|()| std::fs::rename(&self.tmp, &self.path));
        // On success the temporary name no longer exists; on failure Drop removes it.
        result.map_err(|e| Error::io(&self.path, e))
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.writer.as_mut().expect("not committed").write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.writer.as_mut().expect("not committed").flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        drop(self.writer.take());
        let _ = std::fs::remove_file(&self.tmp);
    }
}

/// Writes `path` through `write`; on any error the temporary file is removed and `path` is
/// left as it was (absent, or the previous complete version).
pub fn atomic_write(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> Result<()> {
    let mut file = AtomicFile::create(path)?;
    write(&mut file).map_err(|e| Error::io(path, e))?;
    file.commit()
}

/// Writes bytes atomically.
pub fn atomic_write_bytes(path: &Path, bytes: &[u8]) -> Result<()> {
    atomic_write(path, |w| w.write_all(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_no_final_file_and_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        let err = atomic_write(&path, |w| {
            w.write_all(b"partial")?;
            Err(std::io::Error::other("disk full"))
        });
        assert!(err.is_err());
        assert!(!path.exists());
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
    }

    #[test]
    fn failed_rewrite_keeps_previous_version() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("out.bin");
        atomic_write_bytes(&path, b"complete").unwrap();
        let _ = atomic_write(&path, |w| {
            w.write_all(b"x")?;
            Err(std::io::Error::other("boom"))
        });
        assert_eq!(std::fs::read(&path).unwrap(), b"complete");
    }

    #[test]
    fn dropped_atomic_file_leaves_nothing_and_commit_renames() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stream.gif");
        {
            let mut f = AtomicFile::create(&path).unwrap();
            f.write_all(b"half a stream").unwrap();
            // Dropped without commit, as on an error half-way through a run.
        }
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);
        let mut f = AtomicFile::create(&path).unwrap();
        f.write_all(b"whole").unwrap();
        assert!(!path.exists(), "nothing under the final name before commit");
        f.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"whole");
        assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    }
}
