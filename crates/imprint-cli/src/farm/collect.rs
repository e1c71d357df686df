//! `imprint farm collect DIR`: says which tasks of the job in DIR are done, failed or
//! missing, and, when every one ran, gathers their results:
//! - a sweep: `sweep.csv`, `sweep_frames.csv`, `sweep.md`, `sweep.png` in DIR, as
//!   `imprint sweep` writes them on one machine;
//! - frame chunks: every file the tasks wrote, hard-linked (copied across file systems) into
//!   `DIR/out/` under the names one `imprint run` gives them, with one `report.json` (the
//!   tasks' reports joined: frames and frame times in order, node times summed) and a
//!   `manifest.json`.
//!
//! With a task missing nothing is written or overwritten (exit 2); the tasks to submit again
//! are named. Temporary files a killed task left in its folder are removed.

use super::{Job, Kind, Task};
use crate::sweep::task::TaskStatus;
use imprint_graph::Result;
use imprint_graph::manifest::{Manifest, RUN_KEY};
use imprint_graph::report::{NodeReport, Report};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Gathers the job in `dir`.
pub fn collect(dir: &Path) -> Result<()> {
    let job = Job::read(dir)?;
    match job.kind {
        Kind::Sweep => collect_sweep(&job),
        Kind::Chunks | Kind::Chain => collect_frames(&job),
    }
}

fn collect_sweep(job: &Job) -> Result<()> {
    let args = super::sweep_args_parsed(&job.sweep_args)?;
    let setup = crate::sweep::prepare(&args)?;
    let (states, rows) = crate::sweep::task::collect(&args, &setup);
    print_states(job, &states)?;
    let (reference, rows) = rows.expect("print_states refuses a job with a task missing");
    crate::sweep::task::write(&args, &setup, &reference, &rows)
}

/// Prints every task's state; an error naming the missing tasks when any is.
fn print_states(job: &Job, states: &[(String, TaskStatus)]) -> Result<()> {
    outln!("{:<12} state", "task");
    for (id, s) in states {
        let text = match s {
            TaskStatus::Done => "done".to_string(),
            TaskStatus::Failed(why) => format!("failed: {why}"),
            TaskStatus::Missing(why) => format!("missing: {why}"),
        };
        outln!("{id:<12} {text}");
    }
    let missing: Vec<&str> = states
        .iter()
        .filter(|(_, s)| matches!(s, TaskStatus::Missing(_)))
        .map(|(id, _)| id.as_str())
        .collect();
    if missing.is_empty() {
        return Ok(());
    }
    let indices: Vec<String> = missing
        .iter()
        .filter_map(|id| job.tasks.iter().position(|t| t.id == *id))
        .map(|i| i.to_string())
        .collect();
    let again = match job.engine {
        super::Engine::Slurm => format!(
            "submit them again ({} {}), then collect again",
            super::slurm::submit_script(job).display(),
            indices.join(" ")
        ),
        super::Engine::Openjd => "run their steps again, then collect again".to_string(),
    };
    Err(imprint_core::Error::Invalid(format!(
        "{} of {} tasks have not finished ({}): {again}; nothing was written",
        missing.len(),
        states.len(),
        missing.join(", ")
    ))
    .into())
}

/// The folder a frame task runs in.
fn task_dir(task: &Task) -> PathBuf {
    let i = task
        .argv
        .iter()
        .position(|a| a == "--out")
        .expect("run tasks name --out");
    PathBuf::from(&task.argv[i + 1])
}

fn read_report(dir: &Path) -> std::result::Result<Report, String> {
    let path = dir.join("report.json");
    let text =
        std::fs::read_to_string(&path).map_err(|e| format!("no {} ({e})", path.display()))?;
    serde_json::from_str(&text).map_err(|e| format!("{} does not read ({e})", path.display()))
}

/// A frame task's state from the report of the folder it ran in (a chain's chunks share
/// one: a chunk is done once the run went past its end).
fn frame_task_state(task: &Task, report: &std::result::Result<Report, String>) -> TaskStatus {
    let (a, b) = task.frames;
    let report = match report {
        Ok(r) => r,
        Err(why) => return TaskStatus::Missing(why.clone()),
    };
    let start = report.frames.first().copied().unwrap_or(a);
    let done_to = start + report.frames.len() as u32;
    if done_to > b || (done_to == b && report.complete) {
        return TaskStatus::Done;
    }
    let interrupted = report
        .error
        .as_ref()
        .is_none_or(|e| e.contains("interrupted"));
    match &report.error {
        Some(e) if !interrupted && done_to >= a => TaskStatus::Failed(e.clone()),
        _ if done_to > a => TaskStatus::Missing(format!(
            "stopped after frame {} of {a}..{b}; a retry resumes from its checkpoint",
            done_to - 1
        )),
        _ => TaskStatus::Missing(format!("has not run frames {a}..{b}")),
    }
}

fn collect_frames(job: &Job) -> Result<()> {
    let reports: Vec<std::result::Result<Report, String>> = job
        .tasks
        .iter()
        .map(|t| read_report(&task_dir(t)))
        .collect();
    let states: Vec<(String, TaskStatus)> = job
        .tasks
        .iter()
        .zip(&reports)
        .map(|(t, r)| (t.id.clone(), frame_task_state(t, r)))
        .collect();
    print_states(job, &states)?;
    let failed: Vec<String> = states
        .iter()
        .filter_map(|(id, s)| match s {
            TaskStatus::Failed(why) => Some(format!("{id}: {why}")),
            _ => None,
        })
        .collect();
    if !failed.is_empty() {
        return Err(imprint_core::Error::Run(format!(
            "{} task(s) failed ({}); nothing was gathered",
            failed.len(),
            failed.join("; ")
        ))
        .into());
    }
    // A chain's chunks share one folder; the last one's report covers them all.
    let (folders, reports): (Vec<PathBuf>, Vec<Report>) = match job.kind {
        Kind::Chain => {
            let last = job.tasks.last().expect("a job has tasks");
            let r = reports.into_iter().last().expect("one per task");
            (vec![task_dir(last)], vec![r.expect("done")])
        }
        _ => (
            job.tasks.iter().map(task_dir).collect(),
            reports.into_iter().map(|r| r.expect("done")).collect(),
        ),
    };
    let out = job.out.join("out");
    let (manifest, temporaries) = gather_files(&folders, &out, &job.pipeline)?;
    let report = join_reports(reports);
    let json = serde_json::to_string_pretty(&report).expect("plain data");
    imprint_core::io::atomic_write_bytes(&out.join("report.json"), json.as_bytes())?;
    outln!(
        "gathered {} frame(s) from {} task(s): {} file(s) in {}{}",
        report.frames.len(),
        job.tasks.len(),
        manifest.all().len(),
        out.display(),
        if temporaries > 0 {
            format!(" ({temporaries} temporary file(s) of killed tries removed)")
        } else {
            String::new()
        }
    );
    Ok(())
}

/// Links every file the folders' manifests list into `out`, replaces `out`'s manifest, and
/// removes what an earlier collect put there that is no longer listed. Returns the manifest
/// and the number of stray temporary files removed from the folders.
fn gather_files(folders: &[PathBuf], out: &Path, pipeline: &Path) -> Result<(Manifest, usize)> {
    let previous = Manifest::read(out)?.unwrap_or_default();
    let mut manifest = Manifest {
        pipeline: pipeline.display().to_string(),
        ..Default::default()
    };
    let mut owner: BTreeMap<String, &Path> = BTreeMap::new();
    let mut temporaries = 0;
    for folder in folders {
        temporaries += remove_temporaries(folder);
        let m = Manifest::read(folder)?.ok_or_else(|| {
            imprint_core::Error::Run(format!("{} has no manifest.json", folder.display()))
        })?;
        for (node, files) in m.files.iter().filter(|(n, _)| n.as_str() != RUN_KEY) {
            for rel in files {
                if let Some(other) = owner.insert(rel.clone(), folder) {
                    return Err(imprint_core::Error::Run(format!(
                        "{} and {} both wrote {rel}: the tasks overlap",
                        other.display(),
                        folder.display()
                    ))
                    .into());
                }
                link_or_copy(&folder.join(rel), &out.join(rel))?;
            }
            manifest.add(out, node, files.iter().map(|f| out.join(f)));
        }
    }
    manifest.inherit_stale(&previous);
    manifest.remove_stale(out)?;
    manifest.write(out)?;
    Ok((manifest, temporaries))
}

/// `dst` becomes `src`'s bytes: a hard link, or a copy across file systems; never
/// half-written under its name.
fn link_or_copy(src: &Path, dst: &Path) -> Result<()> {
    let io = |p: &Path, e| imprint_graph::Error::from(imprint_core::Error::io(p, e));
    if let Some(parent) = dst.parent() {
        std::fs::create_dir_all(parent).map_err(|e| io(parent, e))?;
    }
    let name = dst
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = dst.with_file_name(format!(".{name}.{}.tmp", std::process::id()));
    let _ = std::fs::remove_file(&tmp);
    if std::fs::hard_link(src, &tmp).is_err() {
        std::fs::copy(src, &tmp).map_err(|e| io(src, e))?;
    }
    std::fs::rename(&tmp, dst).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        io(dst, e)
    })
}

/// Removes `.NAME.PID.tmp` files (what an atomic write leaves when its process is killed)
/// under `dir`; returns how many.
fn remove_temporaries(dir: &Path) -> usize {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return 0;
    };
    let mut n = 0;
    for e in entries.flatten() {
        let path = e.path();
        let name = e.file_name().to_string_lossy().into_owned();
        if path.is_dir() {
            n += remove_temporaries(&path);
        } else if name.starts_with('.') && name.ends_with(".tmp") {
            n += usize::from(std::fs::remove_file(&path).is_ok());
        }
    }
    n
}

/// The tasks' reports as one: frames and frame times in order, node times and file counts
/// summed, warnings once; figures (`metrics`) of the last task that reported them.
fn join_reports(reports: Vec<Report>) -> Report {
    let mut it = reports.into_iter();
    let mut all = it.next().expect("a job has tasks");
    for r in it {
        all.frames.extend(&r.frames);
        all.frame_ms.extend(&r.frame_ms);
        all.wall_ms += r.wall_ms;
        all.files_written += r.files_written;
        for w in r.warnings {
            if !all.warnings.contains(&w) {
                all.warnings.push(w);
            }
        }
        for (name, n) in r.nodes {
            join_node(all.nodes.entry(name).or_default(), n);
        }
        all.adapter = all.adapter.or(r.adapter);
    }
    all.resumed_at = None;
    all.stale_removed = 0;
    all
}

fn join_node(a: &mut NodeReport, b: NodeReport) {
    if a.kind.is_empty() {
        a.kind = b.kind.clone();
        a.backend = b.backend.clone();
    }
    a.runs += b.runs;
    a.frames_run.extend(b.frames_run);
    a.total_ms += b.total_ms;
    a.measure_ms += b.measure_ms;
    a.max_ms = a.max_ms.max(b.max_ms);
    a.mean_ms = a.total_ms / f64::from(a.runs.max(1));
    a.transfers.extend(b.transfers);
    a.metrics.extend(b.metrics);
    for w in b.warnings {
        if !a.warnings.contains(&w) {
            a.warnings.push(w);
        }
    }
}
