//! The Slurm job: `DIR/slurm/tasks.sbatch`, one array script whose index picks the task;
//! `DIR/slurm/collect.sbatch`, which gathers the results; and `DIR/slurm/submit.sh`, which
//! submits them with the job's dependencies (the reference before a sweep's settings, each
//! chained chunk after the one before, the collect after all) and writes the job ids to
//! `DIR/slurm/submitted`. `submit.sh INDEX…` submits those tasks again, e.g. after a node
//! failed: they resume from their checkpoints. Logs go to `DIR/logs/`.

use super::{Job, Kind, shell_quote, shell_words, task_case};
use imprint_core::io::atomic_write_bytes;
use imprint_graph::Result;
use std::path::{Path, PathBuf};

fn dir(job: &Job) -> PathBuf {
    job.out.join("slurm")
}

/// The script that submits the job.
pub fn submit_script(job: &Job) -> PathBuf {
    dir(job).join("submit.sh")
}

/// Writes the three scripts (and the log folder, which Slurm does not create).
pub fn write(job: &Job) -> Result<Vec<PathBuf>> {
    let logs = job.out.join("logs");
    std::fs::create_dir_all(&logs).map_err(|e| imprint_core::Error::io(&logs, e))?;
    let name = job_name(job);
    let files = [
        (
            dir(job).join("tasks.sbatch"),
            tasks_script(job, &name, &logs),
        ),
        (
            dir(job).join("collect.sbatch"),
            collect_script(job, &name, &logs),
        ),
        (submit_script(job), submit(job)),
    ];
    for (path, text) in &files {
        atomic_write_bytes(path, text.as_bytes())?;
        make_executable(path)?;
    }
    Ok(files.into_iter().map(|(p, _)| p).collect())
}

/// `imprint-<pipeline stem>`, in the characters Slurm's job names keep as they are.
fn job_name(job: &Job) -> String {
    let stem = job.stem();
    let clean: String = stem
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("imprint-{clean}")
}

fn header(job: &Job, what: &str) -> String {
    format!(
        "#!/bin/bash\n# imprint farm: {what} of {} (written by imprint {}).\n",
        job.pipeline.display(),
        job.imprint_version
    )
}

fn tasks_script(job: &Job, name: &str, logs: &Path) -> String {
    let log = shell_quote(&logs.join("%x-%A_%a.out").display().to_string());
    let mut s = header(job, "the tasks");
    s += "# The array index is the task; submit.sh submits it with its dependencies. To run a\n";
    s += "# task by hand: bash tasks.sbatch INDEX.\n";
    s += &format!("#SBATCH --job-name={name}\n");
    s += &format!("#SBATCH --output={log}\n");
    s += "#SBATCH --open-mode=append\n";
    s += &format!("#SBATCH --array=0-{}\n", job.tasks.len() - 1);
    s += "set -euo pipefail\n";
    s += "# As many threads as CPUs Slurm gave the task (results do not depend on it).\n";
    s += "if [ -n \"${SLURM_CPUS_ON_NODE:-}\" ] && [ -z \"${RAYON_NUM_THREADS:-}\" ]; then\n";
    s += "    export RAYON_NUM_THREADS=\"$SLURM_CPUS_ON_NODE\"\n";
    s += "fi\n";
    s += "task=\"${SLURM_ARRAY_TASK_ID:-${1:?give the task index}}\"\n";
    let tasks: Vec<(usize, &super::Task)> = job.tasks.iter().enumerate().collect();
    s + &task_case(&tasks, "$task")
}

fn collect_script(job: &Job, name: &str, logs: &Path) -> String {
    let log = shell_quote(&logs.join("%x-%j.out").display().to_string());
    let mut s = header(job, "gathering the results");
    s += &format!("#SBATCH --job-name={name}-collect\n");
    s += &format!("#SBATCH --output={log}\n");
    s += "set -euo pipefail\n";
    s + &format!("exec {}\n", shell_words(&job.collect_argv()))
}

fn submit(job: &Job) -> String {
    let n = job.tasks.len();
    let mut s = header(job, "submitting the job");
    s += "# No argument: every task, with its dependencies, then the collect. INDEX...: those\n";
    s += "# tasks again (they resume from their checkpoints). Job ids go to ./submitted.\n";
    s += "set -euo pipefail\n";
    s += "here=\"$(cd \"$(dirname \"$0\")\" && pwd)\"\n";
    s += "sub() { sbatch --parsable --kill-on-invalid-dep=yes \"$@\" | cut -d';' -f1; }\n";
    s += "say() { echo \"$1 $2\" | tee -a \"$here/submitted\"; }\n";
    s += "if [ $# -gt 0 ]; then\n";
    s += "    for i in \"$@\"; do say \"task-$i\" \"$(sub --array=\"$i\" \"$here/tasks.sbatch\")\"; done\n";
    s += "    exit 0\n";
    s += "fi\n";
    s += ": > \"$here/submitted\"\n";
    match job.kind {
        Kind::Sweep => {
            s += "last=$(sub --array=0 \"$here/tasks.sbatch\")\n";
            s += "say reference \"$last\"\n";
            if n > 1 {
                s += &format!(
                    "last=$(sub --array=1-{} --dependency=afterok:\"$last\" \"$here/tasks.sbatch\")\n",
                    n - 1
                );
                s += "say settings \"$last\"\n";
            }
        }
        Kind::Chunks => {
            s += &format!("last=$(sub --array=0-{} \"$here/tasks.sbatch\")\n", n - 1);
            s += "say chunks \"$last\"\n";
        }
        Kind::Chain => {
            s += "last=$(sub --array=0 \"$here/tasks.sbatch\")\n";
            s += "say chunk-0 \"$last\"\n";
            s += &format!("for i in $(seq 1 {}); do\n", n - 1);
            s += "    last=$(sub --array=\"$i\" --dependency=afterok:\"$last\" \"$here/tasks.sbatch\")\n";
            s += "    say \"chunk-$i\" \"$last\"\n";
            s += "done\n";
        }
    }
    s += "say collect \"$(sub --dependency=afterany:\"$last\" \"$here/collect.sbatch\")\"\n";
    s
}

#[cfg(unix)]
fn make_executable(path: &Path) -> Result<()> {
    use std::os::unix::fs::PermissionsExt;
    let mut perm = std::fs::metadata(path)
        .map_err(|e| imprint_core::Error::io(path, e))?
        .permissions();
    perm.set_mode(perm.mode() | 0o755);
    std::fs::set_permissions(path, perm).map_err(|e| imprint_core::Error::io(path, e).into())
}

#[cfg(not(unix))]
fn make_executable(_path: &Path) -> Result<()> {
    Ok(())
}
