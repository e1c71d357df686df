//! `imprint farm`: hands a pipeline's work to a farm's scheduler (Slurm, or anything that
//! runs Open Job Description templates) instead of running it here.
//!
//! `imprint farm FILE --engine E --out DIR` cuts the work into tasks, writes them as a job
//! for the engine and as `DIR/farm.json` (what `imprint farm collect DIR` reads back):
//! - with `--vary`: a sweep, one task per setting and one for the reference, which runs
//!   first (the settings are compared with it): `imprint sweep … --task ID`;
//! - a pipeline whose frames depend on no earlier frame: frame chunks of `--chunk K` frames,
//!   independent tasks, each `imprint run … --frames A..B` into its own `DIR/tasks/<id>/`;
//! - a pipeline that carries state from frame to frame (cloth, ground, snow, skinning
//!   particles, amortised builds, whole-run writers): chunks chained through checkpoints,
//!   chunk k running `imprint run … --frames S..E_k --resume` in `DIR/run/` after chunk k-1.
//!
//! Every task keeps a checkpoint (`--checkpoint-every`), so a task killed and tried again
//! resumes where it stopped and ends with the bytes of an uninterrupted run.

mod collect;
mod openjd;
mod slurm;

use crate::sweep::{self, SweepArgs};
use clap::{Parser, ValueEnum};
use imprint_core::io::atomic_write_bytes;
use imprint_graph::node::Trigger;
use imprint_graph::{Plan, Result};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

pub use collect::collect;

/// The job file `imprint farm` writes and `imprint farm collect` reads.
pub const JOB_FILE: &str = "farm.json";

/// Changes whenever the job file's layout does.
const FORMAT: u32 = 1;

/// `imprint farm FILE …`, or `imprint farm collect DIR`.
#[derive(clap::Args)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
pub struct FarmCommand {
    #[command(subcommand)]
    pub collect: Option<FarmSub>,
    #[command(flatten)]
    pub job: Option<FarmArgs>,
}

#[derive(clap::Subcommand)]
pub enum FarmSub {
    /// Say which tasks of the job in DIR are done, failed or missing; with all done, gather
    /// their results (a sweep's table and plot; frame chunks' files and one report.json in
    /// DIR/out). Exit 2, writing nothing, when a task is missing.
    Collect {
        /// The job's folder (what `imprint farm` was given as --out).
        dir: PathBuf,
    },
}

/// What `imprint farm FILE` takes.
#[derive(clap::Args)]
pub struct FarmArgs {
    /// The pipeline file.
    file: PathBuf,
    /// The scheduler the job is written for.
    #[arg(long, value_enum)]
    engine: Engine,
    /// The job's folder: the job, every task's output, the collected results.
    #[arg(long)]
    out: PathBuf,
    /// A sweep: NODE.FIELD=V1,V2,… as `imprint sweep` takes it, repeatable; one task per
    /// setting.
    #[arg(long, value_name = "NODE.FIELD=V1,V2,…")]
    vary: Vec<String>,
    /// The sweep's reference: NODE.FIELD=VALUE, repeatable (as `imprint sweep`).
    #[arg(long, value_name = "NODE.FIELD=VALUE", requires = "vary")]
    reference: Vec<String>,
    /// The sweep's plotted error: NODE or NODE.STAT (as `imprint sweep`).
    #[arg(long, value_name = "NODE[.STAT]", requires = "vary")]
    error: Option<String>,
    /// Override for every task: NODE.FIELD=VALUE, repeatable.
    #[arg(long = "set", value_name = "NODE.FIELD=VALUE")]
    sets: Vec<String>,
    /// Frames to run, `A..B` (B exclusive) or `A..=B` (default: the file's).
    #[arg(long, value_parser = crate::parse_frames)]
    frames: Option<Range<u32>>,
    /// Overrides the backend of the file and of every node, in every task.
    #[arg(long, value_enum)]
    backend: Option<crate::BackendArg>,
    /// Frames per task, for a pipeline (not a sweep: a sweep is one task per setting).
    #[arg(long, value_name = "K")]
    chunk: Option<u32>,
    /// Every task keeps a checkpoint every N frames; a task tried again resumes from it.
    #[arg(long, value_name = "N", default_value_t = 10)]
    checkpoint_every: u32,
    /// The imprint the farm's machines run (default: this one, by its absolute path).
    #[arg(long, value_name = "PATH")]
    program: Option<PathBuf>,
    /// Submit the job once written: `sbatch` (Slurm), or `openjd run` here (OpenJD).
    #[arg(long)]
    submit: bool,
}

/// A scheduler `imprint farm` writes jobs for.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Engine {
    /// An array script for `sbatch`, and `submit.sh` to submit it with its dependencies.
    Slurm,
    /// An Open Job Description job template (`openjd check`, `openjd run`, Deadline Cloud).
    Openjd,
}

impl Engine {
    /// The command that must be on PATH to submit.
    fn command(self) -> &'static str {
        match self {
            Engine::Slurm => "sbatch",
            Engine::Openjd => "openjd",
        }
    }

    fn install_hint(self) -> &'static str {
        match self {
            Engine::Slurm => {
                "install Slurm (Debian: apt-get install slurm-wlm) or submit from a machine that has it"
            }
            Engine::Openjd => "install the OpenJD CLI (pip install openjd-cli)",
        }
    }
}

/// How the job's work is cut.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// One task per setting, after the reference's.
    Sweep,
    /// Independent frame chunks, each into its own folder.
    Chunks,
    /// Frame chunks in order, each resuming from the previous one's checkpoint.
    Chain,
}

/// One task: the command it runs, and the tasks that must have succeeded before it starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Task {
    /// `ref` or a setting's number (sweeps); `chunk-NNN` (chunks).
    pub id: String,
    /// The program and its arguments.
    pub argv: Vec<String>,
    /// With `--resume` added when this checkpoint exists (a retry, or a chained chunk);
    /// `None` when the command resumes by itself (sweep tasks).
    pub resume_from: Option<PathBuf>,
    /// The frames it adds, `[start, end)` (a chained chunk's command runs from the chain's
    /// start, resuming past the frames before).
    pub frames: (u32, u32),
    /// Ids of the tasks it waits for.
    pub after: Vec<String>,
}

/// `DIR/farm.json`: the job as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Job {
    pub format: u32,
    pub imprint_version: String,
    pub engine: Engine,
    pub kind: Kind,
    /// The pipeline file, absolute.
    pub pipeline: PathBuf,
    /// The job's folder, absolute.
    pub out: PathBuf,
    pub frames: (u32, u32),
    pub chunk: Option<u32>,
    /// Why the chunks are chained (nodes that carry state…), for people.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub chained_because: Vec<String>,
    /// A sweep's arguments after `imprint sweep` (without `--task`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub sweep_args: Vec<String>,
    /// The program the tasks run, and the command that gathers their results.
    pub program: PathBuf,
    pub tasks: Vec<Task>,
}

impl Job {
    /// `DIR/farm.json` of an earlier `imprint farm`, or a clear error.
    pub fn read(dir: &Path) -> Result<Job> {
        let path = dir.join(JOB_FILE);
        let text = std::fs::read_to_string(&path).map_err(|e| {
            invalid(match e.kind() {
                std::io::ErrorKind::NotFound => format!(
                    "{} is not a farm job's folder: it has no {JOB_FILE} (`imprint farm FILE \
                     --engine E --out {}` writes one)",
                    dir.display(),
                    dir.display()
                ),
                _ => format!("cannot read {}: {e}", path.display()),
            })
        })?;
        let job: Job = serde_json::from_str(&text).map_err(|e| {
            invalid(format!(
                "{}: line {}, column {}: not a job `imprint farm` wrote ({e})",
                path.display(),
                e.line(),
                e.column()
            ))
        })?;
        if job.format != FORMAT {
            return Err(invalid(format!(
                "{}: written by another version of imprint (job format {}, this one reads {FORMAT})",
                path.display(),
                job.format
            )));
        }
        Ok(job)
    }

    /// The pipeline file's name without its extension, for job names.
    pub fn stem(&self) -> String {
        self.pipeline
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default()
    }

    /// The command that gathers the tasks' results.
    pub fn collect_argv(&self) -> Vec<String> {
        vec![
            self.program.display().to_string(),
            "farm".into(),
            "collect".into(),
            self.out.display().to_string(),
        ]
    }

    fn json(&self) -> String {
        serde_json::to_string_pretty(self).expect("a job is plain data") + "\n"
    }
}

fn invalid(msg: String) -> imprint_graph::Error {
    imprint_core::Error::Invalid(msg).into()
}

/// `imprint farm FILE …`: plans the job, writes it, and submits it with `--submit`.
pub fn farm(args: &FarmArgs) -> Result<()> {
    let job = plan_job(args)?;
    let submit_with = if args.submit {
        Some(find_on_path(args.engine.command()).ok_or_else(|| {
            invalid(format!(
                "--engine {:?}: `{}` is not on PATH, so the job cannot be submitted from here; \
                 {} (nothing was written)",
                args.engine,
                args.engine.command(),
                args.engine.install_hint()
            ))
        })?)
    } else {
        None
    };
    refuse_other_job(&job)?;
    let files = write_job(&job)?;
    outln!(
        "{} job for {} ({}): {} task(s){}",
        format!("{:?}", job.engine).to_lowercase(),
        job.pipeline.display(),
        describe_kind(&job),
        job.tasks.len(),
        if job.chained_because.is_empty() {
            String::new()
        } else {
            format!(", chained: {}", job.chained_because.join("; "))
        }
    );
    for f in &files {
        outln!("  wrote {}", f.display());
    }
    match submit_with {
        Some(tool) => submit(&job, &tool),
        None => {
            if find_on_path(job.engine.command()).is_none() {
                outln!(
                    "note: `{}` is not on this machine's PATH: submit from one that has it ({})",
                    job.engine.command(),
                    job.engine.install_hint()
                );
            }
            outln!("submit: {}", submit_hint(&job));
            outln!(
                "then gather the results: {}",
                shell_words(&job.collect_argv())
            );
            Ok(())
        }
    }
}

fn describe_kind(job: &Job) -> String {
    let (a, b) = job.frames;
    match job.kind {
        Kind::Sweep => format!(
            "a sweep of {} settings and the reference",
            job.tasks.len() - 1
        ),
        Kind::Chunks => format!(
            "frames {a}..{b} in independent chunks of {}",
            job.chunk.unwrap_or(0)
        ),
        Kind::Chain => format!(
            "frames {a}..{b} in chunks of {}, each resuming from the previous one's checkpoint",
            job.chunk.unwrap_or(0)
        ),
    }
}

/// Cuts the work into tasks; every argument is checked before anything is written.
fn plan_job(args: &FarmArgs) -> Result<Job> {
    if args.checkpoint_every == 0 {
        return Err(invalid("--checkpoint-every must be at least 1".into()));
    }
    let file =
        std::path::absolute(&args.file).map_err(|e| imprint_core::Error::io(&args.file, e))?;
    let out = std::path::absolute(&args.out).map_err(|e| imprint_core::Error::io(&args.out, e))?;
    let program = match &args.program {
        Some(p) => p.clone(),
        None => std::env::current_exe().map_err(|e| {
            invalid(format!(
                "cannot find this program's path ({e}); give --program"
            ))
        })?,
    };
    let plan = imprint_graph::load(&file, &args.sets)?;
    let frames = args.frames.clone().unwrap_or(0..plan.file.frames);
    if frames.end > plan.file.frames {
        return Err(invalid(format!(
            "--frames {}..{} is outside the pipeline's 0..{}",
            frames.start, frames.end, plan.file.frames
        )));
    }
    let mut job = Job {
        format: FORMAT,
        imprint_version: crate::VERSION.to_string(),
        engine: args.engine,
        kind: Kind::Sweep,
        pipeline: file,
        out,
        frames: (frames.start, frames.end),
        chunk: args.chunk,
        chained_because: Vec::new(),
        sweep_args: Vec::new(),
        program,
        tasks: Vec::new(),
    };
    if !args.vary.is_empty() {
        if let Some(k) = args.chunk {
            return Err(invalid(format!(
                "--chunk {k} with --vary: a sweep runs one task per setting, each over all its \
                 frames; leave --chunk out (or farm each setting's pipeline on its own)"
            )));
        }
        plan_sweep(args, &mut job)?;
    } else {
        let k = args.chunk.ok_or_else(|| {
            invalid(
                "--chunk K is needed: how many frames each task runs (or --vary for a sweep)"
                    .into(),
            )
        })?;
        check_chunk(k, &frames)?;
        job.chained_because = frame_dependencies(&plan);
        plan_chunks(args, &mut job, k);
    }
    Ok(job)
}

/// The sweep's tasks: the reference, then one per setting after it.
fn plan_sweep(args: &FarmArgs, job: &mut Job) -> Result<()> {
    let mut sweep_args = vec![job.pipeline.display().to_string()];
    for v in &args.vary {
        sweep_args.extend(["--vary".to_string(), v.clone()]);
    }
    for r in &args.reference {
        sweep_args.extend(["--reference".to_string(), r.clone()]);
    }
    for s in &args.sets {
        sweep_args.extend(["--set".to_string(), s.clone()]);
    }
    sweep_args.extend(["--out".into(), job.out.display().to_string()]);
    sweep_args.extend([
        "--frames".into(),
        format!("{}..{}", job.frames.0, job.frames.1),
    ]);
    if let Some(b) = args.backend {
        sweep_args.extend(["--backend".into(), backend_word(b).into()]);
    }
    if let Some(e) = &args.error {
        sweep_args.extend(["--error".into(), e.clone()]);
    }
    // Every setting is checked now, as `imprint sweep` checks them.
    let setup = sweep::prepare(&sweep_args_parsed(&sweep_args)?)?;
    let task = |id: &str, after: Vec<String>| {
        let mut argv = vec![job.program.display().to_string(), "sweep".into()];
        argv.extend(sweep_args.iter().cloned());
        argv.extend(["--task".into(), id.to_string()]);
        argv.extend([
            "--checkpoint-every".into(),
            args.checkpoint_every.to_string(),
        ]);
        Task {
            id: id.to_string(),
            argv,
            resume_from: None,
            frames: job.frames,
            after,
        }
    };
    let mut tasks = vec![task("ref", Vec::new())];
    for id in setup.ids() {
        tasks.push(task(&id, vec!["ref".into()]));
    }
    job.kind = Kind::Sweep;
    job.tasks = tasks;
    job.sweep_args = sweep_args;
    Ok(())
}

/// `imprint sweep`'s arguments as its parser reads them.
pub(crate) fn sweep_args_parsed(words: &[String]) -> Result<SweepArgs> {
    #[derive(Parser)]
    struct Sweep {
        #[command(flatten)]
        args: SweepArgs,
    }
    let argv = std::iter::once("imprint sweep".to_string()).chain(words.iter().cloned());
    Sweep::try_parse_from(argv)
        .map(|s| s.args)
        .map_err(|e| invalid(format!("the sweep's arguments: {e}")))
}

fn backend_word(b: crate::BackendArg) -> &'static str {
    match b {
        crate::BackendArg::Auto => "auto",
        crate::BackendArg::Cpu => "cpu",
        crate::BackendArg::Gpu => "gpu",
    }
}

/// Refuses a chunk size that does not cut `frames` sensibly.
fn check_chunk(k: u32, frames: &Range<u32>) -> Result<()> {
    let n = frames.len() as u32;
    if k == 0 {
        return Err(invalid("--chunk must be at least 1 frame".into()));
    }
    if k >= n {
        return Err(invalid(format!(
            "--chunk {k}: the run has {n} frame(s), so that is one task; use `imprint run`, or \
             a --chunk below {n}"
        )));
    }
    let last = n % k;
    if last != 0 && last * 2 < k {
        let near: Vec<String> = (1..n)
            .filter(|d| n.is_multiple_of(*d) && *d * 2 >= k && *d <= k * 2)
            .map(|d| d.to_string())
            .collect();
        return Err(invalid(format!(
            "--chunk {k} cuts {n} frames into {} chunks of {k} and a last one of {last}; \
             choose a size that divides {n}{} or leaves a last chunk of at least half a chunk",
            n / k,
            if near.is_empty() {
                String::new()
            } else {
                format!(" ({})", near.join(", "))
            }
        )));
    }
    Ok(())
}

/// Why a frame of `plan` depends on earlier frames (empty: frames can run apart).
pub fn frame_dependencies(plan: &Plan) -> Vec<String> {
    let mut why = Vec::new();
    for name in &plan.order {
        let node = plan.file.nodes[name].node();
        let sc = node.schedule();
        if node.trigger() == Trigger::EveryFrame {
            why.push(format!(
                "'{name}' ({}) carries state from frame to frame",
                node.kind()
            ));
        } else if node.output().is_some() && (sc.every > 1 || sc.split > 1) {
            why.push(format!(
                "'{name}' ({}) is amortised over frames (every {}, split {})",
                node.kind(),
                sc.every,
                sc.split
            ));
        } else if node.writes_whole_run() {
            why.push(format!(
                "'{name}' ({}) writes a file of the whole run",
                node.kind()
            ));
        }
    }
    why
}

/// Frame chunks of `k`: independent when nothing carries over, else chained.
fn plan_chunks(args: &FarmArgs, job: &mut Job, k: u32) {
    let (start, end) = job.frames;
    let chained = !job.chained_because.is_empty();
    let starts: Vec<u32> = (start..end).step_by(k as usize).collect();
    let width = (starts.len() - 1).to_string().len().max(3);
    let mut tasks: Vec<Task> = Vec::new();
    for (i, &a) in starts.iter().enumerate() {
        let b = (a + k).min(end);
        let id = format!("chunk-{i:0width$}");
        let (dir, from) = if chained {
            (job.out.join("run"), start)
        } else {
            (job.out.join("tasks").join(&id), a)
        };
        let mut argv = vec![
            job.program.display().to_string(),
            "run".into(),
            job.pipeline.display().to_string(),
            "--out".into(),
            dir.display().to_string(),
            "--frames".into(),
            format!("{from}..{b}"),
            "--checkpoint-every".into(),
            args.checkpoint_every.min(b - a).to_string(),
        ];
        for s in &args.sets {
            argv.extend(["--set".to_string(), s.clone()]);
        }
        if let Some(be) = args.backend {
            argv.extend(["--backend".into(), backend_word(be).into()]);
        }
        let after = match tasks.last() {
            Some(prev) if chained => vec![prev.id.clone()],
            _ => Vec::new(),
        };
        tasks.push(Task {
            id,
            argv,
            resume_from: Some(imprint_graph::executor::checkpoint_path(&dir)),
            frames: (a, b),
            after,
        });
    }
    job.kind = if chained { Kind::Chain } else { Kind::Chunks };
    job.tasks = tasks;
}

/// Refuses a folder that holds another job (its tasks' outputs would be mixed up); the same
/// job again is fine (the tasks' progress is kept).
fn refuse_other_job(job: &Job) -> Result<()> {
    let path = job.out.join(JOB_FILE);
    let Ok(text) = std::fs::read_to_string(&path) else {
        return Ok(());
    };
    if text == job.json() {
        return Ok(());
    }
    Err(invalid(format!(
        "{} holds another farm job ({}); give another --out, or remove the folder to start \
         over (nothing was written)",
        job.out.display(),
        path.display()
    )))
}

/// Writes farm.json and the engine's files; returns their paths.
fn write_job(job: &Job) -> Result<Vec<PathBuf>> {
    let mut files = vec![job.out.join(JOB_FILE)];
    atomic_write_bytes(&files[0], job.json().as_bytes())?;
    let engine_files = match job.engine {
        Engine::Slurm => slurm::write(job)?,
        Engine::Openjd => openjd::write(job)?,
    };
    files.extend(engine_files);
    Ok(files)
}

fn submit_hint(job: &Job) -> String {
    match job.engine {
        Engine::Slurm => shell_words(&[slurm::submit_script(job).display().to_string()]),
        Engine::Openjd => openjd::run_hint(job),
    }
}

/// Runs the engine's submission and says what it printed.
fn submit(job: &Job, tool: &Path) -> Result<()> {
    let (program, argv) = match job.engine {
        Engine::Slurm => (
            PathBuf::from("bash"),
            vec![slurm::submit_script(job).display().to_string()],
        ),
        Engine::Openjd => (tool.to_path_buf(), openjd::run_args(job)),
    };
    outln!("submitting: {} {}", program.display(), shell_words(&argv));
    let status = std::process::Command::new(&program)
        .args(&argv)
        .status()
        .map_err(|e| {
            imprint_core::Error::Run(format!("cannot start {}: {e}", program.display()))
        })?;
    if !status.success() {
        return Err(imprint_core::Error::Run(format!(
            "submitting failed ({status}); the job is in {}",
            job.out.display()
        ))
        .into());
    }
    Ok(())
}

/// The first `name` on PATH, if any.
fn find_on_path(name: &str) -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|d| d.join(name))
        .find(|p| p.is_file())
}

/// Words quoted for a POSIX shell: plain ones as they are, others in single quotes.
pub fn shell_words(words: &[String]) -> String {
    words
        .iter()
        .map(|w| shell_quote(w))
        .collect::<Vec<_>>()
        .join(" ")
}

pub fn shell_quote(w: &str) -> String {
    let plain = !w.is_empty()
        && w.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c));
    if plain {
        w.to_string()
    } else {
        format!("'{}'", w.replace('\'', r"'\''"))
    }
}

/// The lines of a bash script that run `task` (adding `--resume` when its checkpoint exists).
pub fn task_lines(task: &Task) -> String {
    match &task.resume_from {
        None => format!("exec {}\n", shell_words(&task.argv)),
        Some(ckpt) => format!(
            "resume=()\n\
             # A retry (or the next chunk of a chain) goes on from the checkpoint.\n\
             if [ -f {} ]; then resume=(--resume); fi\n\
             exec {} \"${{resume[@]}}\"\n",
            shell_quote(&ckpt.display().to_string()),
            shell_words(&task.argv)
        ),
    }
}

/// A bash `case` on `var` that runs the task of that index.
pub fn task_case(tasks: &[(usize, &Task)], var: &str) -> String {
    let mut s = format!("case \"{var}\" in\n");
    for (i, t) in tasks {
        s += &format!("{i})  # {}\n", t.id);
        for line in task_lines(t).lines() {
            s += &format!("    {line}\n");
        }
        s += "    ;;\n";
    }
    s += &format!("*) echo \"no task {var} in this job\" >&2; exit 2 ;;\nesac\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chunk_sizes_that_cut_badly_are_refused() {
        assert!(check_chunk(25, &(0..100)).is_ok());
        assert!(
            check_chunk(40, &(0..100)).is_ok(),
            "a last chunk of 20 is half of 40"
        );
        assert!(
            check_chunk(30, &(0..100)).is_err(),
            "a last chunk of 10 is a third of 30"
        );
        let e = check_chunk(33, &(0..100)).unwrap_err().to_string();
        assert!(e.contains("last one of 1") && e.contains("25, 50"), "{e}");
        assert!(check_chunk(0, &(0..10)).is_err());
        assert!(check_chunk(10, &(0..10)).is_err());
    }

    #[test]
    fn shell_quoting_survives_quotes_and_spaces() {
        assert_eq!(shell_quote("a/b-c.ron"), "a/b-c.ron");
        assert_eq!(shell_quote("it's here"), r"'it'\''s here'");
        assert_eq!(shell_quote(""), "''");
        assert_eq!(shell_quote("cloth.k=(1, 2)"), "'cloth.k=(1, 2)'");
    }
}
