//! Logging and verbosity: warnings reach stderr through `tracing` as `warning: …`; `-q` keeps
//! errors only, `-v`/`-vv` add info and debug lines, `IMPRINT_LOG` overrides both; and no
//! library crate prints to stderr or stdout by itself.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A pipeline whose writer `w_off` loses its input (`off` is switched off): the plan warns,
/// and the run goes on without it.
const WARNS: &str = r#"Pipeline(
    frames: 2,
    backend: Cpu,
    nodes: {
        "ball": Mesh(primitive: Sphere(radius: 0.3, segments: 16, rings: 8)),
        "vox": Voxelize(mesh: "ball", grid: Fit(resolution: 16)),
        "field": DistanceField(boundary: "vox", measure: Never),
        "off": DistanceField(boundary: "vox", measure: Never, enabled: false),
        "w": WriteField(field: "field", npy: false),
        "w_off": WriteField(field: "off", npy: false),
    },
)
"#;

const WARNING: &str = "warning: writer 'w_off' loses its input 'off'";

/// Runs `imprint run p.ron --out o EXTRA…` on [`WARNS`] in a fresh folder, with
/// `IMPRINT_LOG` set to `log` (or removed).
fn run(extra: &[&str], log: Option<&str>) -> Output {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.ron"), WARNS).unwrap();
    let mut args = vec!["run", "p.ron", "--out", "o"];
    args.extend_from_slice(extra);
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_imprint"));
    cmd.args(&args)
        .current_dir(dir.path())
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env_remove("IMPRINT_LOG");
    if let Some(log) = log {
        cmd.env("IMPRINT_LOG", log);
    }
    let out = cmd.output().expect("imprint runs");
    assert_eq!(
        out.status.code(),
        Some(0),
        "{args:?} IMPRINT_LOG={log:?}: {}",
        stderr(&out)
    );
    // Logging never touches the result on stdout.
    assert!(stdout(&out).contains("file(s) written"), "{}", stdout(&out));
    out
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Lines of `text` that start with `prefix`.
fn lines<'a>(text: &'a str, prefix: &str) -> Vec<&'a str> {
    text.lines().filter(|l| l.starts_with(prefix)).collect()
}

#[test]
fn warnings_show_by_default_as_before() {
    let err = stderr(&run(&[], None));
    // Worded as the CLI printed it before it logged: no level column, no target, no time.
    assert!(err.lines().any(|l| l.starts_with(WARNING)), "{err}");
    assert!(lines(&err, "info:").is_empty(), "{err}");
    assert!(lines(&err, "debug:").is_empty(), "{err}");
}

#[test]
fn quiet_hides_warnings() {
    let err = stderr(&run(&["-q"], None));
    assert!(err.trim().is_empty(), "-q printed: {err}");
    // Global: before the subcommand too.
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("p.ron"), WARNS).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(["--quiet", "run", "p.ron", "--out", "o"])
        .current_dir(dir.path())
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env_remove("IMPRINT_LOG")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(0), "{}", stderr(&out));
    assert!(!stderr(&out).contains("warning"), "{}", stderr(&out));
}

#[test]
fn quiet_still_shows_errors() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(["-q", "check", "missing.ron"])
        .current_dir(dir.path())
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .env_remove("IMPRINT_LOG")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr(&out).starts_with("error: "), "{}", stderr(&out));
    assert!(stderr(&out).contains("missing.ron"), "{}", stderr(&out));
}

#[test]
fn verbose_adds_info_then_debug() {
    let err = stderr(&run(&["-v"], None));
    assert!(err.contains(WARNING), "{err}");
    let info = lines(&err, "info: ");
    assert!(
        info.iter()
            .any(|l| l.contains("node 'field': DistanceField on the cpu")),
        "{err}"
    );
    assert!(info.iter().any(|l| l.contains("frames 0..2")), "{err}");
    assert!(lines(&err, "debug:").is_empty(), "{err}");

    // -vv: debug lines too, naming the module they come from.
    let err = stderr(&run(&["-vv"], None));
    assert!(!lines(&err, "info: ").is_empty(), "{err}");
    let debug = lines(&err, "debug: imprint_graph::executor: frame ");
    assert_eq!(debug.len(), 2, "one per frame: {err}");
    assert!(lines(&err, "trace:").is_empty(), "{err}");
}

#[test]
fn verbose_and_quiet_conflict() {
    let dir = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_imprint"))
        .args(["-v", "-q", "check", "p.ron"])
        .current_dir(dir.path())
        .env_remove("IMPRINT_LOG")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(
        stderr(&out).contains("cannot be used with"),
        "{}",
        stderr(&out)
    );
}

#[test]
fn imprint_log_overrides_the_flags() {
    // off: not even warnings.
    let err = stderr(&run(&[], Some("off")));
    assert!(err.trim().is_empty(), "IMPRINT_LOG=off printed: {err}");
    // As RUST_LOG: warnings everywhere and one crate at debug, without -v.
    let err = stderr(&run(&[], Some("warn,imprint_graph=debug")));
    assert!(err.contains(WARNING), "{err}");
    assert_eq!(
        lines(&err, "debug: imprint_graph::executor: frame ").len(),
        2,
        "{err}"
    );
    assert!(lines(&err, "trace:").is_empty(), "{err}");
    // Set, it wins over -q.
    let err = stderr(&run(&["-q"], Some("warn")));
    assert!(err.contains(WARNING), "{err}");
    // A directive that does not parse is said, and the flags apply.
    let err = stderr(&run(&[], Some("imprint=loud")));
    assert!(err.contains("IMPRINT_LOG="), "{err}");
    assert!(err.contains(WARNING), "{err}");
}

// ---- No library crate prints by itself ----

/// Every `.rs` file under `dir`, recursively.
fn rust_files(dir: &Path, into: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, into);
        } else if p.extension().is_some_and(|x| x == "rs") {
            into.push(p);
        }
    }
}

/// `src` with comments and the insides of string and character literals made spaces (lines
/// kept), so what is left is code.
fn code_only(src: &str) -> String {
    let b: Vec<char> = src.chars().collect();
    let mut out = String::with_capacity(src.len());
    let blank = |c: char| if c == '\n' { '\n' } else { ' ' };
    let mut i = 0;
    while i < b.len() {
        let c = b[i];
        let next = b.get(i + 1).copied();
        if c == '/' && next == Some('/') {
            while i < b.len() && b[i] != '\n' {
                out.push(' ');
                i += 1;
            }
        } else if c == '/' && next == Some('*') {
            let mut depth = 0;
            while i < b.len() {
                if b[i] == '/' && b.get(i + 1) == Some(&'*') {
                    depth += 1;
                    out.push_str("  ");
                    i += 2;
                } else if b[i] == '*' && b.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    out.push_str("  ");
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
        } else if c == 'r'
            && (next == Some('"') || next == Some('#'))
            && !(i > 0 && (b[i - 1].is_alphanumeric() || b[i - 1] == '_'))
        {
            // A raw string: r"…", r#"…"#, …
            let mut j = i + 1;
            let mut hashes = 0;
            while b.get(j) == Some(&'#') {
                hashes += 1;
                j += 1;
            }
            if b.get(j) != Some(&'"') {
                out.push(c);
                i += 1;
                continue;
            }
            out.push('"');
            for _ in i..j {
                out.push(' ');
            }
            i = j + 1;
            loop {
                if i >= b.len() {
                    break;
                }
                if b[i] == '"' && (0..hashes).all(|k| b.get(i + 1 + k) == Some(&'#')) {
                    out.push('"');
                    for _ in 0..hashes {
                        out.push(' ');
                    }
                    i += 1 + hashes;
                    break;
                }
                out.push(blank(b[i]));
                i += 1;
            }
        } else if c == '"' {
            out.push('"');
            i += 1;
            while i < b.len() && b[i] != '"' {
                if b[i] == '\\' {
                    out.push(' ');
                    i += 1;
                }
                if i < b.len() {
                    out.push(blank(b[i]));
                    i += 1;
                }
            }
            out.push('"');
            i += 1;
        } else if c == '\'' {
            // A character literal ('x', '\n', '\u{7b}'), or a lifetime ('a), left as it is.
            let end = if next == Some('\\') {
                (i + 2..b.len()).find(|&k| b[k] == '\'')
            } else if b.get(i + 2) == Some(&'\'') {
                Some(i + 2)
            } else {
                None
            };
            match end {
                Some(end) => {
                    out.push('\'');
                    for _ in i + 1..end {
                        out.push(' ');
                    }
                    out.push('\'');
                    i = end + 1;
                }
                None => {
                    out.push(c);
                    i += 1;
                }
            }
        } else {
            out.push(c);
            i += 1;
        }
    }
    out
}

/// `code` (from [`code_only`]) with every `#[cfg(test)]` item blanked: what tests print is
/// the test harness's business.
fn without_tests(code: &str) -> String {
    let mut out: Vec<char> = code.chars().collect();
    let text: String = out.iter().collect();
    let mut from = 0;
    while let Some(at) = text[from..].find("#[cfg(test)]") {
        let start = from + at;
        // The item ends at its closing brace, or at a `;` before any brace (`mod x;`).
        let mut depth = 0usize;
        let mut end = text.len();
        for (k, ch) in text[start..].char_indices() {
            match ch {
                '{' => depth += 1,
                '}' => {
                    depth -= 1;
                    if depth == 0 {
                        end = start + k + 1;
                        break;
                    }
                }
                ';' if depth == 0 => {
                    end = start + k + 1;
                    break;
                }
                _ => {}
            }
        }
        // `text` is ASCII wherever code is (literals were blanked), so byte offsets are
        // char offsets there; map through char_indices to be safe.
        let (s, e) = (text[..start].chars().count(), text[..end].chars().count());
        for ch in &mut out[s..e] {
            if *ch != '\n' {
                *ch = ' ';
            }
        }
        from = end;
    }
    out.into_iter().collect()
}

/// What prints without going through `tracing`.
const PRINTS: [&str; 7] = [
    "println!",
    "print!",
    "eprintln!",
    "eprint!",
    "dbg!",
    "stdout()",
    "stderr()",
];

/// The only places a library crate may print, each with why.
const ALLOWED: [(&str, &str, &str); 2] = [
    // The viewer's protocol lines (`ready`, `frame …`, `error: …`) are its output on stdout,
    // which scripts and tests read (`say`).
    (
        "imprint-view/src/app.rs",
        "stdout()",
        "let mut out = std::io::stdout().lock();",
    ),
    // The GPU tests' helper tells the test log that a test skipped for want of an adapter
    // (the README promises it); only tests call it.
    (
        "imprint-gpu/src/lib.rs",
        "eprintln!",
        "eprintln!(\"skipped: no GPU adapter",
    ),
];

#[test]
fn library_crates_do_not_print() {
    let crates = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut files = Vec::new();
    for e in std::fs::read_dir(&crates).unwrap() {
        let dir = e.unwrap().path();
        let name = dir.file_name().unwrap().to_string_lossy().into_owned();
        if name == "imprint-cli" || !dir.join("src").is_dir() {
            continue;
        }
        rust_files(&dir.join("src"), &mut files);
    }
    assert!(files.len() > 20, "found only {files:?}");
    let mut found = Vec::new();
    let mut allowed_seen = [false; ALLOWED.len()];
    for f in &files {
        let src = std::fs::read_to_string(f).unwrap();
        let code = without_tests(&code_only(&src));
        let rel = f
            .strip_prefix(&crates)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        for (n, (line, original)) in code.lines().zip(src.lines()).enumerate() {
            for p in PRINTS {
                // `print!` inside `eprint!`/`println!` is the same hit.
                let hit = line.match_indices(p).any(|(at, _)| {
                    !line[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_')
                });
                if !hit {
                    continue;
                }
                match ALLOWED.iter().position(|(file, what, text)| {
                    rel == *file && p == *what && original.trim().starts_with(text)
                }) {
                    Some(k) => allowed_seen[k] = true,
                    None => found.push(format!("{rel}:{}: {}", n + 1, original.trim())),
                }
            }
        }
    }
    assert!(
        found.is_empty(),
        "library crates print by themselves; use tracing::warn!/info!/debug! (the CLI shows \
         them by -v/-q and IMPRINT_LOG):\n{}",
        found.join("\n")
    );
    // The check itself still sees the allowed places (so it reads the sources it means to).
    assert_eq!(allowed_seen, [true; ALLOWED.len()], "{ALLOWED:?}");
}

#[test]
fn the_source_check_finds_prints_outside_tests() {
    let src = r##"
/// Docs may say println!("x").
fn f() { let s = "eprintln!(\"x\")"; let r = r#"dbg!(1)"#; let c = '"'; }
fn g<'a>(x: &'a str) { eprintln!("warning: {x}"); }
#[cfg(test)]
mod tests {
    fn h() { println!("{}", '}'); }
}
fn k() { std::io::stderr(); }
"##;
    let code = without_tests(&code_only(src));
    let hits: Vec<usize> = code
        .lines()
        .enumerate()
        .filter(|(_, l)| PRINTS.iter().any(|p| l.contains(p)))
        .map(|(n, _)| n)
        .collect();
    assert_eq!(hits, [3, 8], "{code}");
}
