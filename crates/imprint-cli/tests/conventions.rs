//! The conventions users expect of a command-line tool: messages that are current, a
//! `--version` that names the build, shell completions, a README that lists the commands
//! `--help` lists.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

mod common;
use common::{imprint, run_ok};

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Writes `text` as `p.ron` in `dir`.
fn pipeline(dir: &Path, text: &str) -> PathBuf {
    let p = dir.join("p.ron");
    std::fs::write(&p, text).unwrap();
    p
}

/// The backticked names in `text`, in order.
fn backticked(text: &str) -> Vec<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(str::to_string)
        .collect()
}

#[test]
fn an_unknown_node_kind_is_answered_with_every_kind() {
    let dir = tempfile::tempdir().unwrap();
    let p = pipeline(
        dir.path(),
        "Pipeline(\n    frames: 1,\n    nodes: {\n        \"m\": Mesh(primitive: Sphere(radius: 0.5)),\n        \"x\": Renderr(objects: []),\n    },\n)\n",
    );
    let out = imprint(&["check", p.to_str().unwrap()], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    // RON's own message lists the enum's variants (serde derives it from the enum itself);
    // the help must name each of them.
    let expected = err
        .split("expected one of")
        .nth(1)
        .and_then(|s| s.split("instead").next())
        .unwrap_or_else(|| panic!("no list of variants in: {err}"));
    let kinds: Vec<String> = backticked(expected);
    assert!(kinds.len() >= 13, "{kinds:?}");
    let help = err
        .split("help:")
        .nth(1)
        .unwrap_or_else(|| panic!("no help in: {err}"));
    let help = help.split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(help.starts_with("node kinds are:"), "{help}");
    let listed: Vec<&str> = help["node kinds are:".len()..]
        .split('(')
        .next()
        .unwrap()
        .split(',')
        .map(str::trim)
        .collect();
    assert_eq!(listed, kinds, "help: {help}");
}

#[test]
fn an_unknown_camera_is_not_answered_with_node_kinds() {
    let dir = tempfile::tempdir().unwrap();
    let p = pipeline(
        dir.path(),
        "Pipeline(\n    frames: 1,\n    nodes: {\n        \"m\": Mesh(primitive: Sphere(radius: 0.5)),\n        \"r\": Render(objects: [Mesh(mesh: \"m\")], camera: Orbitt(distance: 2)),\n    },\n)\n",
    );
    let out = imprint(&["check", p.to_str().unwrap()], dir.path());
    assert_eq!(out.status.code(), Some(2));
    let err = stderr(&out);
    assert!(err.contains("Orbitt"), "{err}");
    assert!(!err.contains("node kinds are"), "{err}");
}

/// An `Auto` run, as a user without a runtime folder (a container, `sudo`, cron) starts it.
fn run_without_runtime_dir(xdg: Option<&str>, tmp: &Path) -> Output {
    let out = tmp.join("out");
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imprint"));
    cmd.args([
        "run",
        "pipelines/footprints.ron",
        "--frames",
        "0..2",
        "--out",
    ])
    .arg(&out)
    .current_dir(root())
    .env("TMPDIR", tmp)
    .env_remove("XDG_RUNTIME_DIR");
    if let Some(x) = xdg {
        cmd.env("XDG_RUNTIME_DIR", x);
    }
    let o = cmd.output().expect("imprint runs");
    assert_eq!(o.status.code(), Some(0), "{}", stderr(&o));
    o
}

#[test]
fn a_run_without_a_runtime_folder_prints_no_graphics_stack_noise() {
    for xdg in [None, Some(""), Some("relative/dir")] {
        let tmp = tempfile::tempdir().unwrap();
        let o = run_without_runtime_dir(xdg, tmp.path());
        let err = stderr(&o);
        assert!(
            !err.lines().any(|l| l.contains("XDG_RUNTIME_DIR")),
            "XDG_RUNTIME_DIR={xdg:?}: {err}"
        );
        assert!(stdout(&o).contains("file(s) written"), "{}", stdout(&o));
        // The private runtime folder is gone when the program ends.
        let left: Vec<_> = std::fs::read_dir(tmp.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("imprint-runtime-"))
            .collect();
        assert!(left.is_empty(), "left behind: {left:?}");
    }
}

#[test]
fn check_says_a_spinning_render_moves_with_time() {
    let dir = tempfile::tempdir().unwrap();
    let p = pipeline(
        dir.path(),
        r#"Pipeline(
    frames: 4,
    nodes: {
        "ball": Mesh(primitive: Sphere(radius: 0.3)),
        "spinning": Render(objects: [Mesh(mesh: "ball")], camera: Orbit(distance: 2, spin: 30),
            width: 32, height: 32, out: "a/{frame}.png"),
        "still": Render(objects: [Mesh(mesh: "ball")], camera: Orbit(distance: 2),
            width: 32, height: 32, out: "b/{frame}.png", every: 2),
    },
)
"#,
    );
    let out = stdout(&run_ok(&["check", p.to_str().unwrap()], dir.path()));
    let table = out
        .split("schedule (first")
        .nth(1)
        .expect("a schedule table");
    let row = |name: &str| {
        table
            .lines()
            .find(|l| l.split_whitespace().next() == Some(name))
            .unwrap_or_else(|| panic!("no row {name} in {table}"))
            .to_string()
    };
    let spinning = row("spinning");
    assert!(spinning.contains("wwww"), "{spinning}");
    assert!(spinning.contains("moves with time"), "{spinning}");
    assert!(!spinning.contains("static"), "{spinning}");
    let still = row("still");
    assert!(still.contains("w.w."), "{still}");
    assert!(!still.contains("computes once"), "{still}");
    assert!(!still.contains("moves with time"), "{still}");
    // The mesh itself is static.
    assert!(
        row("ball").contains("static: computes once"),
        "{}",
        row("ball")
    );
}

/// The default `--help` shows for `option`.
fn shown_default(help: &str, option: &str) -> String {
    let line = help
        .lines()
        .find(|l| l.trim_start().starts_with(option))
        .unwrap_or_else(|| panic!("no {option} in {help}"));
    line.split("[default: ")
        .nth(1)
        .and_then(|s| s.split(']').next())
        .unwrap_or_else(|| panic!("no default in {line}"))
        .to_string()
}

#[test]
fn stress_help_shows_defaults_that_the_options_accept() {
    let help = stdout(&run_ok(&["stress", "--help"], &root()));
    let scales = shown_default(&help, "--scales");
    let ratios = shown_default(&help, "--ratios");
    assert_eq!(scales, "1,10,100,1000");
    assert!(!ratios.contains(' '), "{ratios}");
    let out = run_ok(
        &[
            "stress",
            "cloth",
            "pipelines/stress_cloth.ron",
            "--scales",
            &scales,
            "--ratios",
            &ratios,
            "--frames",
            "1",
        ],
        &root(),
    );
    let table = stdout(&out);
    for s in ["1x", "10x", "100x", "1000x"] {
        assert!(
            table
                .lines()
                .any(|l| l.trim_start().starts_with(&format!("{s} |"))),
            "{s}: {table}"
        );
    }
    assert_eq!(ratios.split(',').count(), 7);
}

#[test]
fn version_names_the_crate_version_and_the_git_revision() {
    let out = stdout(&run_ok(&["--version"], &root()));
    let line = out.trim();
    assert!(
        line.starts_with(&format!("imprint {} ", env!("CARGO_PKG_VERSION"))),
        "{line}"
    );
    let rev = line
        .split("(git ")
        .nth(1)
        .and_then(|s| s.strip_suffix(')'))
        .unwrap_or_else(|| panic!("no revision in {line}"));
    let hash = rev.strip_suffix("-dirty").unwrap_or(rev);
    let looks_like_a_hash =
        (7..=40).contains(&hash.len()) && hash.chars().all(|c| c.is_ascii_hexdigit());
    if root().join(".git").exists() {
        assert!(looks_like_a_hash, "{line}");
    } else {
        assert!(looks_like_a_hash || rev == "unknown", "{line}");
    }
}

#[test]
fn completions_for_each_shell_name_the_commands() {
    let dir = tempfile::tempdir().unwrap();
    for shell in ["bash", "zsh", "fish"] {
        let script = stdout(&run_ok(&["completions", shell], dir.path()));
        assert!(script.len() > 200, "{shell}: {script}");
        for cmd in ["run", "view", "sweep", "check", "completions"] {
            assert!(
                script
                    .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == '-'))
                    .any(|w| w == cmd),
                "{shell} does not mention {cmd}"
            );
        }
        if shell == "bash" {
            let f = dir.path().join("imprint.bash");
            std::fs::write(&f, &script).unwrap();
            let check = Command::new("bash").arg("-n").arg(&f).output().unwrap();
            assert!(check.status.success(), "bash -n: {}", stderr(&check));
        }
    }
    let bad = imprint(&["completions", "tcsh"], dir.path());
    assert_eq!(bad.status.code(), Some(2));
}

/// The subcommands `imprint --help` lists (without `help`).
fn help_commands() -> Vec<String> {
    let help = stdout(&run_ok(&["--help"], &root()));
    help.split("Commands:")
        .nth(1)
        .expect("a Commands section")
        .lines()
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .filter(|c| c != "help")
        .collect()
}

#[test]
fn the_readme_lists_the_commands_help_lists() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let section = readme
        .split("\n## Commands\n")
        .nth(1)
        .expect("a ## Commands section");
    let block = section
        .split("```")
        .nth(1)
        .expect("a code block in ## Commands");
    let mut listed: Vec<String> = Vec::new();
    for line in block.lines() {
        if let Some(rest) = line.strip_prefix("imprint ") {
            let word = rest.split_whitespace().next().unwrap_or("").to_string();
            if !word.starts_with('-') && word != "help" && !listed.contains(&word) {
                listed.push(word);
            }
        }
    }
    assert_eq!(listed, help_commands(), "README's list: {block}");
    assert!(block.contains("imprint --version"), "{block}");
}
