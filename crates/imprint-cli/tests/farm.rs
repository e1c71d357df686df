//! `imprint farm`: the jobs it writes, run task by task as the engine would run them, gather
//! (`imprint farm collect`) to the bytes of one `imprint run` (frame chunks, independent or
//! chained through checkpoints) or to the rows of one `imprint sweep`; a task killed mid-run
//! resumes; bad input exits with 2 and overwrites nothing. OpenJD's own CLI checks and runs
//! the templates where it is installed (`openjd-cli`; `IMPRINT_REQUIRE_FARM_TOOLS=1` makes
//! its absence a failure, as CI sets it). The real Slurm cluster test is `tests/slurm.rs`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

mod common;
use common::scenes::{assert_same_files, assert_same_outputs, root, stateful_scene, untimed_csv};
use common::{imprint, run_ok};

fn job(dir: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(dir.join("farm.json")).unwrap()).unwrap()
}

fn task_count(dir: &Path) -> usize {
    job(dir)["tasks"].as_array().unwrap().len()
}

/// Runs task `i` of the Slurm job in `dir` as a Slurm node would (`SLURM_ARRAY_TASK_ID`).
fn run_task(dir: &Path, i: usize) -> Output {
    Command::new("bash")
        .arg(dir.join("slurm/tasks.sbatch"))
        .env("SLURM_ARRAY_TASK_ID", i.to_string())
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap()
}

fn run_all_tasks(dir: &Path) {
    for i in 0..task_count(dir) {
        let out = run_task(dir, i);
        assert!(
            out.status.success(),
            "task {i}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

fn text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// A field of a breathing bunny written every frame, its slices rendered: no frame depends
/// on another.
fn stateless_scene(frames: u32) -> String {
    let bunny = root().join("assets/meshes/stanford-bunny.obj");
    format!(
        r#"Pipeline(
    frames: {frames},
    nodes: {{
        "bunny": Mesh(path: "{bunny}", fit: (size: 0.6, center: (0, 0.3, 0)),
                      motion: [Breathe(amplitude: 0.05, period: 1.0)]),
        "vox": Voxelize(mesh: "bunny", grid: Fit(resolution: 24, padding: 0.15)),
        "field": DistanceField(boundary: "vox", band: 2.5, measure: Every(2)),
        "fields": WriteField(field: "field", slices: [(axis: X)]),
        "bunny_obj": WriteMesh(mesh: "bunny", format: Ply, every: 2),
        "render": Render(objects: [Mesh(mesh: "bunny"), FieldSlice(field: "field", axis: Z)],
                         camera: Orbit(distance: 2.0, spin: 10), width: 64, height: 48, samples: 1),
    }},
)
"#,
        bunny = bunny.display()
    )
}

/// A pipeline file in a fresh folder, and the folder `job/` beside it for its farm job.
struct Scene {
    tmp: tempfile::TempDir,
    file: String,
    dir: PathBuf,
}

impl Scene {
    fn new(text: &str) -> Scene {
        let tmp = tempfile::tempdir().unwrap();
        let file = tmp.path().join("scene.ron");
        std::fs::write(&file, text).unwrap();
        let dir = tmp.path().join("job");
        let file = file.to_str().unwrap().to_string();
        Scene { tmp, file, dir }
    }

    fn d(&self) -> &str {
        self.dir.to_str().unwrap()
    }

    /// `imprint farm FILE --engine slurm --out job/` and `args`, expected to succeed.
    fn farm(&self, args: &[&str]) {
        let mut all = vec!["farm", &self.file, "--engine", "slurm", "--out", self.d()];
        all.extend(args);
        run_ok(&all, self.tmp.path());
    }

    fn collect(&self) -> Output {
        imprint(&["farm", "collect", self.d()], self.tmp.path())
    }

    /// One uninterrupted `imprint run` of the file into `whole/`.
    fn whole_run(&self) -> PathBuf {
        let whole = self.tmp.path().join("whole");
        run_ok(
            &["run", &self.file, "--out", whole.to_str().unwrap()],
            self.tmp.path(),
        );
        whole
    }
}

#[test]
fn independent_chunks_gather_to_the_bytes_of_one_run() {
    let sc = Scene::new(&stateless_scene(6));
    sc.farm(&["--chunk", "2"]);
    let j = job(&sc.dir);
    assert_eq!(j["kind"], "chunks", "{j}");
    assert_eq!(task_count(&sc.dir), 3);
    let tasks = j["tasks"].as_array().unwrap();
    assert!(
        tasks
            .iter()
            .all(|t| t["after"].as_array().unwrap().is_empty())
    );
    run_all_tasks(&sc.dir);
    assert!(sc.collect().status.success());
    let whole = sc.whole_run();
    assert_same_files(&whole, &sc.dir.join("out"), 15);
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(sc.dir.join("out/report.json")).unwrap()).unwrap();
    assert_eq!(r["frames"], serde_json::json!([0, 1, 2, 3, 4, 5]));
    assert_eq!(r["nodes"]["field"]["runs"], 6);
    // The gathered manifest is the one run's, so a later run into out/ cleans up after it.
    assert_eq!(
        std::fs::read(whole.join("manifest.json")).unwrap(),
        std::fs::read(sc.dir.join("out/manifest.json")).unwrap()
    );
}

#[test]
fn chained_chunks_gather_to_the_bytes_of_one_run() {
    let sc = Scene::new(&stateful_scene(8));
    let args = ["--chunk", "3", "--checkpoint-every", "2"];
    sc.farm(&args);
    let j = job(&sc.dir);
    assert_eq!(j["kind"], "chain");
    let why = j["chained_because"].to_string();
    assert!(
        why.contains("'cloth' (Cloth) carries state") && why.contains("amortised"),
        "{why}"
    );
    assert_eq!(j["tasks"][2]["after"], serde_json::json!(["chunk-001"]));
    // The same job again into its folder is fine (a different one is refused: see below).
    sc.farm(&args);
    run_all_tasks(&sc.dir);
    assert!(sc.collect().status.success());
    assert_same_outputs(&sc.whole_run(), &sc.dir.join("out"));
}

/// Starts task `i` of the Slurm job in `dir` in the background, as [`run_task`] runs it.
fn spawn_task(dir: &Path, i: usize) -> std::process::Child {
    Command::new("bash")
        .arg(dir.join("slurm/tasks.sbatch"))
        .env("SLURM_ARRAY_TASK_ID", i.to_string())
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap()
}

/// SIGKILLs `child` once `ready()` (polled), mid-run: the task must not have ended first.
fn kill_when(mut child: std::process::Child, ready: impl Fn() -> bool) {
    let deadline = Instant::now() + Duration::from_secs(120);
    while !ready() {
        assert!(
            child.try_wait().unwrap().is_none(),
            "the task ended before it was killed"
        );
        assert!(Instant::now() < deadline, "not ready in 120 s");
        std::thread::sleep(Duration::from_millis(10));
    }
    // `exec` made the task's shell the imprint process itself.
    child.kill().unwrap();
    child.wait().unwrap();
}

/// Frames done by the run in `dir`, as its report (written at every checkpoint) says.
fn frames_done(dir: &Path) -> usize {
    std::fs::read(dir.join("report.json"))
        .ok()
        .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
        .map_or(0, |r| r["frames"].as_array().map_or(0, Vec::len))
}

#[test]
fn a_task_killed_mid_chunk_resumes_to_the_same_bytes() {
    let sc = Scene::new(&stateful_scene(6));
    sc.farm(&["--chunk", "3", "--checkpoint-every", "1"]);
    let dir = &sc.dir;
    // Killed once it checkpointed past frame 1, mid-chunk.
    kill_when(spawn_task(dir, 0), || frames_done(&dir.join("run")) >= 2);

    // Collect names what is missing and how to retry it, and writes nothing.
    let out = sc.collect();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    let said = text(&out);
    assert!(
        said.contains("chunk-000") && said.contains("stopped after frame"),
        "{said}"
    );
    assert!(said.contains("submit.sh 0 1"), "{said}");
    assert!(!dir.join("out").exists(), "collect wrote nothing");

    let retry = run_task(dir, 0);
    assert!(retry.status.success(), "{}", text(&retry));
    assert!(
        text(&retry).contains("resuming at frame"),
        "{}",
        text(&retry)
    );
    let r: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("run/report.json")).unwrap()).unwrap();
    assert!(
        r["resumed_at"].as_u64().unwrap() >= 2,
        "{}",
        r["resumed_at"]
    );
    run_all_tasks(dir);
    assert!(sc.collect().status.success());
    assert_same_outputs(&sc.whole_run(), &dir.join("out"));
    let stray: Vec<PathBuf> = common::files_under(dir)
        .into_iter()
        .filter(|p| p.to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(stray.is_empty(), "temporary files left: {stray:?}");
}

#[test]
fn a_sweep_on_the_farm_gathers_the_rows_of_imprint_sweep() {
    let sc = Scene::new(&stateless_scene(3));
    let sweep = [
        "--vary",
        "vox.grid.resolution=16,24",
        "--vary",
        "field.band=1.5,2.5",
        "--reference",
        "vox.grid.resolution=32",
    ];
    sc.farm(&[&sweep[..], &["--checkpoint-every", "1"]].concat());
    let dir = &sc.dir;
    assert_eq!(task_count(dir), 5);

    // Before any task ran: every one is missing, nothing is written.
    let out = sc.collect();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        text(&out).contains("5 of 5 tasks have not finished"),
        "{}",
        text(&out)
    );
    assert!(!dir.join("sweep.csv").exists());
    // A setting before its reference fails and says why.
    let early = run_task(dir, 1);
    assert_eq!(early.status.code(), Some(1));
    assert!(
        text(&early).contains("task `ref` runs first"),
        "{}",
        text(&early)
    );

    run_all_tasks(dir);
    assert!(sc.collect().status.success());
    let local = sc.tmp.path().join("local");
    let mut args = vec!["sweep", &sc.file, "--out", local.to_str().unwrap()];
    args.extend(sweep);
    run_ok(&args, sc.tmp.path());
    let csv = |d: &Path| std::fs::read_to_string(d.join("sweep.csv")).unwrap();
    assert_eq!(untimed_csv(&csv(dir)), untimed_csv(&csv(&local)));
    assert_eq!(
        std::fs::read_to_string(dir.join("sweep_frames.csv")).unwrap(),
        std::fs::read_to_string(local.join("sweep_frames.csv")).unwrap()
    );
    assert!(dir.join("sweep.png").is_file() && dir.join("sweep.md").is_file());
}

/// A setting's task killed mid-run resumes with what it had measured: its row equals an
/// uninterrupted one's.
#[test]
fn a_sweep_task_killed_mid_run_resumes_its_comparison() {
    let sc = Scene::new(&stateful_scene(6));
    sc.farm(&[
        "--checkpoint-every",
        "1",
        "--vary",
        "cloth.params.substeps=4,8",
        "--set",
        "render.enabled=false",
    ]);
    let dir = &sc.dir;
    assert!(run_task(dir, 0).status.success());
    let row_of = |dir: &Path| -> serde_json::Value {
        let mut row: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join("runs/2/row.json")).unwrap()).unwrap();
        row["timing"] = serde_json::Value::Null;
        row
    };
    let uninterrupted = run_task(dir, 2);
    assert!(uninterrupted.status.success(), "{}", text(&uninterrupted));
    let whole = row_of(dir);
    std::fs::remove_dir_all(dir.join("runs/2")).unwrap();

    let ckpt = dir.join("runs/2/checkpoint.bin");
    kill_when(spawn_task(dir, 2), || ckpt.exists());
    let retry = run_task(dir, 2);
    assert!(retry.status.success(), "{}", text(&retry));
    assert_eq!(row_of(dir), whole);
}

#[test]
fn bad_farm_input_exits_2_and_overwrites_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let file = tmp.path().join("scene.ron");
    std::fs::write(&file, stateless_scene(7)).unwrap();
    let f = file.to_str().unwrap();
    let dir = tmp.path().join("job");
    let d = dir.to_str().unwrap();
    let refused = |args: &[&str], says: &str| {
        let out = imprint(args, tmp.path());
        assert_eq!(out.status.code(), Some(2), "{args:?}: {}", text(&out));
        assert!(text(&out).contains(says), "{args:?}: {}", text(&out));
    };
    refused(
        &["farm", f, "--engine", "pbs", "--out", d, "--chunk", "2"],
        "pbs",
    );
    refused(
        &["farm", f, "--engine", "slurm", "--out", d, "--chunk", "0"],
        "at least 1",
    );
    refused(
        &["farm", f, "--engine", "slurm", "--out", d, "--chunk", "5"],
        "a last one of 2",
    );
    refused(
        &["farm", f, "--engine", "slurm", "--out", d, "--chunk", "7"],
        "one task",
    );
    refused(
        &["farm", f, "--engine", "slurm", "--out", d],
        "--chunk K is needed",
    );
    refused(
        &[
            "farm",
            f,
            "--engine",
            "slurm",
            "--out",
            d,
            "--chunk",
            "2",
            "--vary",
            "field.band=1,2",
        ],
        "one task per setting",
    );
    refused(
        &[
            "farm",
            f,
            "--engine",
            "slurm",
            "--out",
            d,
            "--vary",
            "nope.band=1,2",
        ],
        "nope",
    );
    assert!(!dir.exists(), "nothing written for refused input");

    // An engine that is not installed: --submit cannot submit, and writes nothing.
    let out = Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args([
            "farm", f, "--engine", "slurm", "--out", d, "--chunk", "4", "--submit",
        ])
        .env("PATH", tmp.path())
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", text(&out));
    assert!(
        text(&out).contains("`sbatch` is not on PATH"),
        "{}",
        text(&out)
    );
    assert!(!dir.exists());

    // Another job into a folder that holds one is refused; the first job is kept.
    run_ok(
        &["farm", f, "--engine", "slurm", "--out", d, "--chunk", "4"],
        tmp.path(),
    );
    let before = std::fs::read(dir.join("farm.json")).unwrap();
    refused(
        &["farm", f, "--engine", "slurm", "--out", d, "--chunk", "2"],
        "another farm job",
    );
    assert_eq!(std::fs::read(dir.join("farm.json")).unwrap(), before);

    refused(
        &["farm", "collect", tmp.path().to_str().unwrap()],
        "no farm.json",
    );
}

/// Whether `openjd` runs here; its absence fails with IMPRINT_REQUIRE_FARM_TOOLS=1.
fn openjd_available() -> bool {
    let found = Command::new("openjd")
        .arg("--help")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var("IMPRINT_REQUIRE_FARM_TOOLS").as_deref() != Ok("1"),
            "openjd is not installed (pip install openjd-cli) and IMPRINT_REQUIRE_FARM_TOOLS=1"
        );
        eprintln!("skipped: openjd is not installed (pip install openjd-cli)");
    }
    found
}

#[test]
fn openjd_checks_every_template_and_runs_one() {
    if !openjd_available() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let stateless = tmp.path().join("stateless.ron");
    std::fs::write(&stateless, stateless_scene(4)).unwrap();
    let stateful = tmp.path().join("stateful.ron");
    std::fs::write(&stateful, stateful_scene(4)).unwrap();
    let (a, b) = (stateless.to_str().unwrap(), stateful.to_str().unwrap());
    let jobs: [(&str, Vec<&str>); 3] = [
        ("chunks", vec![a, "--chunk", "2"]),
        ("chain", vec![b, "--chunk", "2"]),
        ("sweep", vec![a, "--vary", "field.band=1.5,2.5"]),
    ];
    for (name, extra) in &jobs {
        let dir = tmp.path().join(name);
        let mut args = vec!["farm", "--engine", "openjd", "--out", dir.to_str().unwrap()];
        args.extend(extra);
        run_ok(&args, tmp.path());
        let template = dir.join("openjd/job.json");
        let check = Command::new("openjd")
            .arg("check")
            .arg(&template)
            .output()
            .unwrap();
        assert!(check.status.success(), "{name}: {}", text(&check));
    }
    // The chunks job, run here by OpenJD: the collect step and all it depends on.
    let dir = tmp.path().join("chunks");
    let run = Command::new("openjd")
        .args([
            "run",
            dir.join("openjd/job.json").to_str().unwrap(),
            "--step",
            "collect",
            "--run-dependencies",
        ])
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .output()
        .unwrap();
    assert!(run.status.success(), "{}", text(&run));
    let whole = tmp.path().join("whole");
    run_ok(&["run", a, "--out", whole.to_str().unwrap()], tmp.path());
    assert_same_files(&whole, &dir.join("out"), 10);
}
