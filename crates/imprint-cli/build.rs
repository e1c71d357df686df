//! `imprint --version`: the crate's version and the git revision it was built from
//! (`IMPRINT_GIT_REV`: the short hash, `-dirty` when the tree had changes, or `unknown`
//! where git or the repository is absent, as in a crates.io tarball).

use std::path::{Path, PathBuf};
use std::process::Command;

fn git(dir: &Path, args: &[&str]) -> Option<String> {
    let out = Command::new("git")
        .args(args)
        .current_dir(dir)
        .output()
        .ok()?;
    out.status
        .success()
        .then(|| String::from_utf8_lossy(&out.stdout).trim().to_string())
}

fn main() {
    let here = PathBuf::from(std::env::var_os("CARGO_MANIFEST_DIR").expect("set by cargo"));
    println!("cargo::rerun-if-changed=build.rs");
    println!("cargo::rerun-if-env-changed=IMPRINT_GIT_REV");
    // Packagers building outside a repository can name the revision themselves.
    let rev = if let Some(rev) = std::env::var("IMPRINT_GIT_REV")
        .ok()
        .filter(|r| !r.is_empty())
    {
        rev
    } else if let Some(hash) = git(&here, &["rev-parse", "--short", "HEAD"]) {
        // Rebuild when HEAD moves (a checkout, a commit on the branch) or the index changes
        // (staging; `git status` refreshes it too). Edits not yet seen by git are only
        // noticed when something else reruns this script.
        if let Some(git_dir) = git(&here, &["rev-parse", "--absolute-git-dir"]) {
            let git_dir = PathBuf::from(git_dir);
            for f in ["HEAD", "index", "packed-refs"] {
                println!("cargo::rerun-if-changed={}", git_dir.join(f).display());
            }
            if let Some(head_ref) = git(&here, &["symbolic-ref", "-q", "HEAD"]) {
                let common = git(&here, &["rev-parse", "--git-common-dir"])
                    .map(|c| here.join(c))
                    .unwrap_or(git_dir);
                println!(
                    "cargo::rerun-if-changed={}",
                    common.join(head_ref).display()
                );
            }
        }
        let dirty = git(&here, &["status", "--porcelain", "--untracked-files=no"])
            .is_some_and(|s| !s.is_empty());
        if dirty { format!("{hash}-dirty") } else { hash }
    } else {
        // git failed (absent, or busy): where a repository is there after all, run again
        // when it changes, so a passing failure does not stick in the build cache.
        if let Some(git_dir) = here
            .ancestors()
            .map(|a| a.join(".git"))
            .find(|g| g.exists())
        {
            for f in ["HEAD", "index"] {
                println!("cargo::rerun-if-changed={}", git_dir.join(f).display());
            }
        }
        "unknown".to_string()
    };
    println!("cargo::rustc-env=IMPRINT_GIT_REV={rev}");
}
