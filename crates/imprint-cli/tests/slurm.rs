//! `imprint farm` on a real Slurm: a one-node cluster on localhost (`tests/farm/slurm-local.sh`
//! installs Debian's slurm-wlm and munge when missing, writes a slurm.conf, starts munged,
//! slurmctld and slurmd under a temporary folder, and stops them when the test ends).
//! The generated `submit.sh` submits the jobs with `sbatch`:
//! - a chained job whose first task is SIGKILLed mid-chunk (`scancel --signal=KILL`): its
//!   dependents are cancelled, the collect job says what is missing; submitted again, the
//!   task resumes from its checkpoint and the gathered files equal one local run's bytes;
//! - a sweep as an array after its reference: the same rows as `imprint sweep`.
//!
//! Needs root (slurmd launches the jobs) and takes about a minute; it says it skipped
//! without root or Slurm, and fails instead with `IMPRINT_REQUIRE_FARM_TOOLS=1` (CI).

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

mod common;
use common::run_ok;
use common::scenes::{assert_same_outputs, root, stateful_scene, untimed_csv};

/// The cluster, stopped when dropped (also when the test fails).
struct Cluster {
    dir: PathBuf,
    conf: String,
}

impl Cluster {
    fn start(dir: &Path) -> Option<Cluster> {
        let required = std::env::var("IMPRINT_REQUIRE_FARM_TOOLS").as_deref() == Ok("1");
        let is_root = Command::new("id")
            .arg("-u")
            .output()
            .is_ok_and(|o| o.stdout.starts_with(b"0\n"));
        if !is_root {
            assert!(
                !required,
                "the Slurm test needs root (slurmd launches the jobs)"
            );
            eprintln!("skipped: the Slurm test needs root (slurmd launches the jobs)");
            return None;
        }
        let out = Command::new("bash")
            .arg(root().join("tests/farm/slurm-local.sh"))
            .args(["start", dir.to_str().unwrap()])
            .output()
            .unwrap();
        if !out.status.success() {
            let why = String::from_utf8_lossy(&out.stderr);
            assert!(!required, "cannot start a local Slurm: {why}");
            eprintln!("skipped: cannot start a local Slurm: {why}");
            return None;
        }
        let conf = dir.join("slurm.conf").display().to_string();
        Some(Cluster {
            dir: dir.to_path_buf(),
            conf,
        })
    }

    /// Runs a Slurm command (or a script calling them) against this cluster.
    fn run(&self, program: &str, args: &[&str]) -> String {
        let out = Command::new(program)
            .args(args)
            .env("SLURM_CONF", &self.conf)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{program} {args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// Submits the job in `job` with its submit.sh; returns (name, job id) per job.
    fn submit(&self, job: &Path) -> Vec<(String, String)> {
        let script = job.join("slurm/submit.sh");
        self.run("bash", &[script.to_str().unwrap()]);
        submitted(job)
    }

    /// Waits until none of `ids` is pending or running.
    fn wait(&self, ids: &[&str]) {
        let deadline = Instant::now() + Duration::from_secs(300);
        let list = ids.join(",");
        loop {
            let out = Command::new("squeue")
                .args([
                    "-h",
                    "-j",
                    &list,
                    "-t",
                    "PD,R,CG,CF,S,RQ,RS,RH,SE",
                    "-o",
                    "%i",
                ])
                .env("SLURM_CONF", &self.conf)
                .output()
                .unwrap();
            if out.stdout.iter().all(u8::is_ascii_whitespace) {
                return;
            }
            assert!(Instant::now() < deadline, "Slurm jobs {list} still queued");
            std::thread::sleep(Duration::from_millis(250));
        }
    }

    /// A finished job's state (COMPLETED, FAILED, CANCELLED…), while Slurm remembers it.
    fn state(&self, id: &str) -> String {
        let out = self.run("scontrol", &["show", "job", "-o", id]);
        out.split_whitespace()
            .find_map(|w| w.strip_prefix("JobState="))
            .unwrap_or("?")
            .to_string()
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        let _ = Command::new("bash")
            .arg(root().join("tests/farm/slurm-local.sh"))
            .args(["stop", self.dir.to_str().unwrap()])
            .output();
    }
}

/// The jobs submit.sh submitted last, (name, job id), from `slurm/submitted`.
fn submitted(job: &Path) -> Vec<(String, String)> {
    std::fs::read_to_string(job.join("slurm/submitted"))
        .unwrap()
        .lines()
        .filter_map(|l| l.split_once(' '))
        .map(|(a, b)| (a.to_string(), b.trim().to_string()))
        .collect()
}

fn id_of<'a>(jobs: &'a [(String, String)], name: &str) -> &'a str {
    &jobs
        .iter()
        .find(|(n, _)| n == name)
        .unwrap_or_else(|| panic!("{name} in {jobs:?}"))
        .1
}

fn frames_done(run: &Path) -> usize {
    std::fs::read(run.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .map_or(0, |r| r["frames"].as_array().map_or(0, Vec::len))
}

#[test]
fn slurm_runs_the_jobs_and_a_killed_task_resumes() {
    let tmp = tempfile::tempdir().unwrap();
    let Some(cluster) = Cluster::start(&tmp.path().join("slurm")) else {
        return;
    };
    let file = tmp.path().join("scene.ron");
    std::fs::write(&file, stateful_scene(8)).unwrap();
    let f = file.to_str().unwrap();

    // A chain of 4 chunks; the first one killed once it has checkpointed 2 frames.
    let job = tmp.path().join("chain");
    let j = job.to_str().unwrap();
    run_ok(
        &[
            "farm",
            f,
            "--engine",
            "slurm",
            "--out",
            j,
            "--chunk",
            "2",
            "--checkpoint-every",
            "1",
        ],
        tmp.path(),
    );
    let jobs = cluster.submit(&job);
    let first = id_of(&jobs, "chunk-0").to_string();
    let deadline = Instant::now() + Duration::from_secs(120);
    while frames_done(&job.join("run")) < 1 {
        assert!(Instant::now() < deadline, "chunk 0 did not start: {jobs:?}");
        std::thread::sleep(Duration::from_millis(20));
    }
    cluster.run("scancel", &["--signal=KILL", "--full", &first]);
    let ids: Vec<&str> = jobs.iter().map(|(_, id)| id.as_str()).collect();
    cluster.wait(&ids);
    assert_ne!(cluster.state(&first), "COMPLETED", "killed before its end");
    // The collect job ran after all and said what is missing (exit 2).
    assert_eq!(cluster.state(id_of(&jobs, "collect")), "FAILED");
    assert!(!job.join("out").exists());

    // Submitted again: chunk 0 resumes from its checkpoint; the rest follow.
    let jobs = cluster.submit(&job);
    let ids: Vec<&str> = jobs.iter().map(|(_, id)| id.as_str()).collect();
    cluster.wait(&ids);
    for (name, id) in &jobs {
        assert_eq!(cluster.state(id), "COMPLETED", "{name}");
    }
    let log = std::fs::read_dir(job.join("logs"))
        .unwrap()
        .map(|e| std::fs::read_to_string(e.unwrap().path()).unwrap())
        .collect::<String>();
    assert!(log.contains("resuming at frame"), "{log}");
    let whole = tmp.path().join("whole");
    run_ok(&["run", f, "--out", whole.to_str().unwrap()], tmp.path());
    assert_same_outputs(&whole, &job.join("out"));

    // A sweep: the reference, then the settings as one array after it.
    let sweep = tmp.path().join("sweep");
    let vary = [
        "--vary",
        "cloth.params.substeps=6,8",
        "--vary",
        "field.every=3,6",
        "--set",
        "render.enabled=false",
    ];
    // Submitted by `imprint farm --submit` itself.
    let out = Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(["farm", f, "--engine", "slurm", "--submit", "--out"])
        .arg(&sweep)
        .args(vary)
        .env("SLURM_CONF", &cluster.conf)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let jobs = submitted(&sweep);
    let ids: Vec<&str> = jobs.iter().map(|(_, id)| id.as_str()).collect();
    cluster.wait(&ids);
    assert_eq!(
        cluster.state(id_of(&jobs, "collect")),
        "COMPLETED",
        "{jobs:?}"
    );
    let local = tmp.path().join("local");
    let mut args = vec!["sweep", f, "--out", local.to_str().unwrap()];
    args.extend(vary);
    run_ok(&args, tmp.path());
    let csv = |d: &Path| std::fs::read_to_string(d.join("sweep.csv")).unwrap();
    assert_eq!(untimed_csv(&csv(&sweep)), untimed_csv(&csv(&local)));
}
