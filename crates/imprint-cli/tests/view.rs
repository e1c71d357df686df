//! `imprint view` headless, as CI meets it: under an Xvfb of its own per test (so tests run
//! in parallel and leave no daemon), with `--exit-after N --screenshot`, reading the lines it
//! prints as they come. The view matches the offline render of the same frame; a save
//! reloads without restarting the frames; a broken save is shown and the last good pipeline
//! runs on; a broken file at start and a missing display exit 2.
//!
//! Tests needing the window skip (with a note) where `Xvfb` or a GPU adapter is missing;
//! with `IMPRINT_REQUIRE_GPU=1` (CI) that is a failure instead.

use image::RgbImage;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::OnceLock;
use std::sync::mpsc::{Receiver, RecvTimeoutError, channel};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

mod common;
use common::{imprint, run_ok};

/// The longest any one viewer may run before the test kills it and fails.
const VIEWER_LIMIT: Duration = Duration::from_secs(120);

// ---- skipping ----------------------------------------------------------------------------

/// Skips (a note on stderr), or fails with `IMPRINT_REQUIRE_GPU=1`.
fn skip<T>(why: &str) -> Option<T> {
    assert!(
        std::env::var("IMPRINT_REQUIRE_GPU").as_deref() != Ok("1"),
        "IMPRINT_REQUIRE_GPU=1 but {why}"
    );
    eprintln!("skipped: {why} (set IMPRINT_REQUIRE_GPU=1 to fail instead)");
    None
}

fn on_path(program: &str) -> bool {
    std::env::var_os("PATH")
        .is_some_and(|p| std::env::split_paths(&p).any(|d| d.join(program).is_file()))
}

/// Whether `imprint run --backend gpu` finds an adapter (asked once per test binary).
fn gpu_adapter() -> bool {
    static FOUND: OnceLock<bool> = OnceLock::new();
    *FOUND.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let text = r#"Pipeline(frames: 1, nodes: {
            "m": Mesh(primitive: Sphere(radius: 0.3, segments: 8, rings: 4)),
            "r": Render(objects: [Mesh(mesh: "m")], camera: Orbit(distance: 2),
                        width: 16, height: 16, samples: 1),
        })"#;
        std::fs::write(dir.path().join("p.ron"), text).unwrap();
        let out = imprint(
            &["run", "p.ron", "--out", "o", "--backend", "gpu"],
            dir.path(),
        );
        let err = String::from_utf8_lossy(&out.stderr);
        if out.status.code() == Some(1) && err.contains("no GPU adapter") {
            return false;
        }
        assert_eq!(out.status.code(), Some(0), "GPU probe: {err}");
        true
    })
}

/// A display for the viewer, or `None` (skipped) without Xvfb or a GPU adapter.
fn display() -> Option<Xvfb> {
    if !on_path("Xvfb") {
        return skip("Xvfb is not installed (Debian: apt-get install xvfb xauth)");
    }
    if !gpu_adapter() {
        return skip("no GPU adapter");
    }
    Some(Xvfb::start())
}

// ---- Xvfb --------------------------------------------------------------------------------

/// An X server of the test's own, on the display number it chose; stopped on drop. Its
/// stderr (with `-audit 4`: each client's connection and disconnection) goes to `log`.
struct Xvfb {
    child: Child,
    display: String,
    log: tempfile::NamedTempFile,
}

impl Xvfb {
    fn start() -> Xvfb {
        let log = tempfile::NamedTempFile::new().unwrap();
        let mut child = Command::new("Xvfb")
            .args([
                "-displayfd",
                "1",
                "-screen",
                "0",
                "1600x1000x24",
                "-nolisten",
                "tcp",
                "-audit",
                "4",
            ])
            .stdout(Stdio::piped())
            .stderr(log.reopen().unwrap())
            .spawn()
            .expect("Xvfb starts");
        // Xvfb writes the display number once it accepts connections.
        let stdout = child.stdout.take().unwrap();
        let (tx, rx) = channel();
        std::thread::spawn(move || {
            let mut line = String::new();
            let _ = BufReader::new(stdout).read_line(&mut line);
            let _ = tx.send(line);
        });
        let mut xvfb = Xvfb {
            child,
            display: String::new(),
            log,
        };
        let n = rx.recv_timeout(Duration::from_secs(20)).unwrap_or_default();
        let n = n.trim();
        assert!(
            !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()),
            "Xvfb did not say its display within 20 s: {n:?}"
        );
        xvfb.display = format!(":{n}");
        xvfb
    }

    /// What the server has written so far.
    fn log(&self) -> String {
        std::fs::read_to_string(self.log.path()).unwrap_or_default()
    }

    /// Whether the server was left without clients and then connected again: an X server
    /// resets when its last client leaves and refuses connections during the reset, so a
    /// viewer that lets its display connection count fall to zero while starting can fail
    /// to open its window.
    fn emptied_then_reconnected(&self) -> bool {
        let mut clients = 0i32;
        let mut emptied = false;
        for line in self.log().lines() {
            if line.contains("connected from") {
                if emptied {
                    return true;
                }
                clients += 1;
            } else if line.ends_with(" disconnected") {
                clients -= 1;
                emptied |= clients == 0;
            }
        }
        false
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        // SIGTERM lets Xvfb remove its lock file and socket; SIGKILL if it does not stop.
        let _ = Command::new("kill")
            .args(["-TERM", &self.child.id().to_string()])
            .status();
        let t = Instant::now();
        while t.elapsed() < Duration::from_secs(5) {
            if let Ok(Some(_)) = self.child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

// ---- the viewer --------------------------------------------------------------------------

/// A running `imprint view`: its stdout lines as they come, its stderr when it ends. Killed
/// on drop (a failing test leaves no process behind).
struct Viewer {
    child: Child,
    lines: Receiver<String>,
    /// Every stdout line received so far.
    seen: Vec<String>,
    stderr: Option<JoinHandle<String>>,
    started: Instant,
}

/// What a finished viewer said.
struct Said {
    code: Option<i32>,
    lines: Vec<String>,
    err: String,
}

impl Viewer {
    /// `imprint view ARGS` on `display` (None: no display variable at all), in `cwd`.
    fn spawn(display: Option<&Xvfb>, args: &[&str], cwd: &Path) -> Viewer {
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_imprint"));
        cmd.arg("view")
            .args(args)
            .current_dir(cwd)
            .env("XDG_RUNTIME_DIR", std::env::temp_dir())
            .env_remove("WAYLAND_DISPLAY")
            .env_remove("DISPLAY")
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        if let Some(x) = display {
            cmd.env("DISPLAY", &x.display);
        }
        let mut child = cmd.spawn().expect("imprint view starts");
        let (tx, lines) = channel();
        let stdout = child.stdout.take().unwrap();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut stderr = child.stderr.take().unwrap();
        let stderr = std::thread::spawn(move || {
            let mut s = String::new();
            let _ = std::io::Read::read_to_string(&mut stderr, &mut s);
            s
        });
        Viewer {
            child,
            lines,
            seen: Vec::new(),
            stderr: Some(stderr),
            started: Instant::now(),
        }
    }

    fn left(&self) -> Duration {
        VIEWER_LIMIT.saturating_sub(self.started.elapsed())
    }

    /// The next line `want`s, within `timeout`; fails the test (killing the viewer) on
    /// timeout or when the viewer ends first.
    fn wait_for(&mut self, what: &str, timeout: Duration, want: impl Fn(&str) -> bool) -> String {
        let deadline = Instant::now() + timeout.min(self.left());
        loop {
            match self
                .lines
                .recv_timeout(deadline.saturating_duration_since(Instant::now()))
            {
                Ok(line) => {
                    self.seen.push(line.clone());
                    if want(&line) {
                        return line;
                    }
                }
                Err(RecvTimeoutError::Timeout) => self.fail(&format!("no {what} in {timeout:?}")),
                Err(RecvTimeoutError::Disconnected) => {
                    self.fail(&format!("the viewer ended before {what}"))
                }
            }
        }
    }

    /// Waits for the viewer to exit (killing it past the limit): its code, lines, stderr.
    fn finish(&mut self) -> Said {
        loop {
            match self.lines.recv_timeout(self.left()) {
                Ok(line) => self.seen.push(line),
                Err(RecvTimeoutError::Disconnected) => break,
                Err(RecvTimeoutError::Timeout) => self.fail("the viewer did not exit"),
            }
        }
        let code = loop {
            if let Some(s) = self.child.try_wait().unwrap() {
                break s.code();
            }
            if self.left().is_zero() {
                self.fail("the viewer did not exit");
            }
            std::thread::sleep(Duration::from_millis(20));
        };
        Said {
            code,
            lines: self.seen.clone(),
            err: self.stderr.take().unwrap().join().unwrap_or_default(),
        }
    }

    fn fail(&mut self, why: &str) -> ! {
        let _ = self.child.kill();
        let _ = self.child.wait();
        let err = self.stderr.take().map(|h| h.join().unwrap_or_default());
        panic!(
            "{why}\nstdout so far:\n{}\nstderr:\n{}",
            self.seen.join("\n"),
            err.unwrap_or_default()
        );
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        if let Ok(None) = self.child.try_wait() {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }
}

/// Runs the viewer to its end, expecting exit 0; what it said.
/// Also checks that the viewer held a display connection from its first to its last (see
/// [`Xvfb::emptied_then_reconnected`]).
fn view_ok(x: &Xvfb, args: &[&str], cwd: &Path) -> Said {
    let said = Viewer::spawn(Some(x), args, cwd).finish();
    assert_eq!(
        said.code,
        Some(0),
        "{args:?}\nstdout:\n{}\nstderr:\n{}\nXvfb:\n{}",
        said.lines.join("\n"),
        said.err,
        x.log()
    );
    assert!(
        !x.emptied_then_reconnected(),
        "{args:?}: the X server was left without clients while the viewer ran:\n{}",
        x.log()
    );
    said
}

// ---- what it prints ----------------------------------------------------------------------

/// F of a `frame F: sim …` line.
fn frame_of(line: &str) -> Option<u32> {
    line.strip_prefix("frame ")?.split_once(':')?.0.parse().ok()
}

/// The view's rectangle `[x, y, w, h]` from the `screenshot PATH: WxH, view at X Y WxH` line.
fn view_rect(lines: &[String]) -> [u32; 4] {
    let line = lines
        .iter()
        .find(|l| l.starts_with("screenshot "))
        .unwrap_or_else(|| panic!("no screenshot line in:\n{}", lines.join("\n")));
    let rest = line
        .rsplit_once("view at ")
        .expect("the view's rectangle")
        .1;
    let n: Vec<u32> = rest
        .split(|c: char| c == 'x' || c.is_whitespace())
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap_or_else(|_| panic!("{line}")))
        .collect();
    n.try_into().unwrap_or_else(|_| panic!("{line}"))
}

fn frames_seen(lines: &[String]) -> Vec<u32> {
    lines.iter().filter_map(|l| frame_of(l)).collect()
}

// ---- images ------------------------------------------------------------------------------

fn load(path: &Path) -> RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

fn crop(img: &RgbImage, [x, y, w, h]: [u32; 4]) -> RgbImage {
    assert!(
        x + w <= img.width() && y + h <= img.height(),
        "view {x} {y} {w}x{h} outside the {}x{} screenshot",
        img.width(),
        img.height()
    );
    image::imageops::crop_imm(img, x, y, w, h).to_image()
}

/// The largest and the mean absolute difference over all channels, in 8-bit levels.
fn difference(a: &RgbImage, b: &RgbImage) -> (u8, f64) {
    assert_eq!(a.dimensions(), b.dimensions(), "image sizes differ");
    let (mut max, mut sum) = (0u8, 0u64);
    for (p, q) in a.as_raw().iter().zip(b.as_raw()) {
        let d = p.abs_diff(*q);
        max = max.max(d);
        sum += d as u64;
    }
    (max, sum as f64 / a.as_raw().len() as f64)
}

/// Pixels for which `f(r, g, b)` holds.
fn count(img: &RgbImage, f: impl Fn(i32, i32, i32) -> bool) -> usize {
    img.pixels()
        .filter(|p| f(p[0] as i32, p[1] as i32, p[2] as i32))
        .count()
}

// ---- pipelines ---------------------------------------------------------------------------

const COPPER: &str = "(0.80, 0.50, 0.38)";

/// A twisting Suzanne (and with `cloth`, a 16 x 16 cloth falling onto the ground beside
/// her) under an orbiting camera, 320 x 240 with one sample (what the viewer draws on a
/// software adapter), written as `dir/p.ron`.
fn pipeline(dir: &Path, frames: u32, cloth: bool) -> PathBuf {
    let mesh = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../assets/meshes/suzanne.obj"
    ));
    let (cloth_node, cloth_object) = if cloth {
        (
            r#"
        "cloth": Cloth(params: (
            shape: Grid(size: (0.8, 0.8), resolution: (16, 16), center: (1.1, 1.0, 0), normal: (0, 1, 0)),
            material: Harada(k_structural: 20.0, k_shear: 5.0),
            collision: (epsilon: 0.01, friction: 0.3, ground: 0.0),
            substeps: 16)),"#,
            r#"
                Mesh(mesh: "cloth", color: (0.25, 0.45, 0.75)),"#,
        )
    } else {
        ("", "")
    };
    let text = format!(
        r#"Pipeline(
    frames: {frames},
    fps: 24,
    backend: Auto,
    nodes: {{
        "monkey": Mesh(
            path: "{mesh}",
            fit: (size: 1.0, center: (0, 0.5, 0)),
            motion: [Twist(axis: Y, degrees: 40, period: 1.0)],
        ),{cloth_node}
        "render": Render(
            objects: [
                Mesh(mesh: "monkey", color: {COPPER}),{cloth_object}
            ],
            camera: Orbit(target: (0.3, 0.5, 0), distance: 3.0, elevation: 20, azimuth: 30, spin: 60),
            width: 320,
            height: 240,
            samples: 1,
        ),
    }},
)
"#,
        mesh = mesh.display()
    );
    let file = dir.join("p.ron");
    std::fs::write(&file, text).unwrap();
    file
}

/// Saves `text` over `file` as editors do: a new file renamed over the old one.
fn save(file: &Path, text: &str) {
    let tmp = file.with_extension("ron.tmp");
    std::fs::write(&tmp, text).unwrap();
    std::fs::rename(&tmp, file).unwrap();
}

/// `text` with a syntax error (a stray number) on the line of `samples: 1,`; that line's
/// number (1-based).
fn broken(text: &str) -> (String, usize) {
    let line = 1 + text
        .lines()
        .position(|l| l.contains("samples: 1,"))
        .unwrap();
    (text.replace("samples: 1,", "samples: 1 7,"), line)
}

// ---- the tests ---------------------------------------------------------------------------

/// After 10 frames stepped the view shows frame 9, drawn as `imprint run --backend gpu`
/// draws it: the view's rectangle in the screenshot is frames/0009.png within rounding.
#[test]
fn screenshot_matches_the_offline_render() {
    let Some(x) = display() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    pipeline(d, 24, false);
    let t = Instant::now();
    let said = view_ok(
        &x,
        &["p.ron", "--exit-after", "10", "--screenshot", "shot.png"],
        d,
    );
    let viewer_s = t.elapsed().as_secs_f64();
    assert_eq!(frames_seen(&said.lines), (0..10).collect::<Vec<_>>());
    let t = Instant::now();
    run_ok(
        &[
            "run",
            "p.ron",
            "--frames",
            "0..10",
            "--backend",
            "gpu",
            "--out",
            "o",
        ],
        d,
    );
    let offline_s = t.elapsed().as_secs_f64();

    let shot = load(&d.join("shot.png"));
    let rect = view_rect(&said.lines);
    assert_eq!(
        [rect[2], rect[3]],
        [320, 240],
        "the view is the Render node's size"
    );
    let view = crop(&shot, rect);
    let (max, mean) = difference(&view, &load(&d.join("o/frames/0009.png")));
    eprintln!(
        "view vs offline frame 9: max {max} levels, mean {mean:.4} (viewer {viewer_s:.1} s, \
         offline {offline_s:.1} s)"
    );
    // The same renderer, camera and frame: only the view's trip through the window (egui's
    // textured quad, the surface's format) may round, by a level here and there.
    assert!(
        max <= 8 && mean < 0.5,
        "view vs frame 9: max {max}, mean {mean}"
    );
    // The frame count matters: the frame before (2.5° of spin earlier) is outside that
    // tolerance, and frame 0 (another camera angle and twist) is far off.
    let (max8, mean8) = difference(&view, &load(&d.join("o/frames/0008.png")));
    let (_, mean0) = difference(&view, &load(&d.join("o/frames/0000.png")));
    eprintln!("view vs frame 8: max {max8}, mean {mean8:.2}; vs frame 0: mean {mean0:.2}");
    assert!(
        max8 > 8 && mean8 >= 0.5,
        "the view is frame 8's too: max {max8}, mean {mean8}"
    );
    assert!(mean0 > 2.0, "the view is frame 0's too: mean {mean0}");
    // The panel drew: left of the view, not one flat colour.
    let panel = crop(&shot, [0, 0, rect[0], shot.height()]);
    let first = panel.get_pixel(0, 0);
    let other = panel.pixels().filter(|p| *p != first).count();
    assert!(
        other > 500,
        "the panel is {other} pixels off its background"
    );
}

/// A save that only recolours a Render object reloads without rebuilding any simulation
/// node: the frames go on from where they were (no restart at 0), and the view shows the new
/// colour.
#[test]
fn reload_keeps_state_and_shows_the_change() {
    let Some(x) = display() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = pipeline(d, 200, true);
    let text = std::fs::read_to_string(&file).unwrap();
    let mut v = Viewer::spawn(
        Some(&x),
        &["p.ron", "--exit-after", "60", "--screenshot", "shot.png"],
        d,
    );
    let secs = Duration::from_secs(60);
    v.wait_for("frame 5", secs, |l| frame_of(l).is_some_and(|f| f >= 5));
    let saved = Instant::now();
    save(&file, &text.replace(COPPER, "(0.0, 1.0, 0.0)"));
    let reloaded = v.wait_for("reloaded line", secs, |l| l.starts_with("reloaded "));
    let seen_at = saved.elapsed();
    let before = frames_seen(&v.seen);
    let said = v.finish();
    eprintln!("{reloaded} (seen {seen_at:?} after the save)");
    assert_eq!(said.code, Some(0), "{}\nXvfb:\n{}", said.err, x.log());
    assert!(reloaded.contains("p.ron"), "{reloaded}");
    assert!(reloaded.ends_with("rebuilt []"), "{reloaded}");
    // Frame numbers only go up, across the reload too: the state was kept.
    let frames = frames_seen(&said.lines);
    assert_eq!(frames.len(), 60, "{}", said.lines.join("\n"));
    assert!(
        frames.windows(2).all(|w| w[1] == w[0] + 1),
        "frames not consecutive: {frames:?}"
    );
    assert!(frames.len() > before.len(), "no frame after the reload");

    let view = crop(&load(&d.join("shot.png")), view_rect(&said.lines));
    let green = count(&view, |r, g, b| g > 60 && g > r + 40 && g > b + 40);
    let copper = count(&view, |r, g, b| r > 60 && r > g + 30 && r > b + 30);
    eprintln!("after the reload: {green} green pixels, {copper} copper");
    assert!(green > 2000, "{green} green pixels in the view");
    assert!(copper < 50, "{copper} copper pixels still in the view");
}

/// A broken save is reported (file:line:col) while the last good pipeline keeps running;
/// the view shows the error over it; the run ends normally.
#[test]
fn broken_edit_keeps_running_and_shows_the_error() {
    let Some(x) = display() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let file = pipeline(d, 200, false);
    let (bad, line) = broken(&std::fs::read_to_string(&file).unwrap());
    let mut v = Viewer::spawn(
        Some(&x),
        &["p.ron", "--exit-after", "40", "--screenshot", "shot.png"],
        d,
    );
    let secs = Duration::from_secs(60);
    v.wait_for("frame 5", secs, |l| frame_of(l).is_some_and(|f| f >= 5));
    save(&file, &bad);
    let error = v.wait_for("error line", secs, |l| l.starts_with("error: "));
    let at_error = frames_seen(&v.seen).last().copied().unwrap();
    let said = v.finish();
    eprintln!("{error}");
    assert_eq!(said.code, Some(0), "{}\nXvfb:\n{}", said.err, x.log());
    assert!(error.contains(&format!("p.ron:{line}:")), "{error}");
    assert!(
        error.contains("the last good pipeline keeps running"),
        "{error}"
    );
    let last = *frames_seen(&said.lines).last().unwrap();
    assert!(last > at_error, "no frame after the error (last {last})");

    let view = crop(&load(&d.join("shot.png")), view_rect(&said.lines));
    let dark_red = count(&view, |r, g, b| {
        (r - 60).abs() <= 6 && (g - 16).abs() <= 6 && (b - 16).abs() <= 6
    });
    eprintln!("error overlay: {dark_red} dark red pixels");
    assert!(dark_red > 3000, "{dark_red} pixels of the error box");
}

#[test]
fn broken_file_at_start_exits_2() {
    let Some(x) = display() else { return };
    let dir = tempfile::tempdir().unwrap();
    let file = pipeline(dir.path(), 24, false);
    let (bad, line) = broken(&std::fs::read_to_string(&file).unwrap());
    std::fs::write(&file, bad).unwrap();
    let said = Viewer::spawn(Some(&x), &["p.ron", "--exit-after", "5"], dir.path()).finish();
    assert_eq!(said.code, Some(2), "{}", said.err);
    assert!(said.err.contains(&format!("p.ron:{line}:")), "{}", said.err);
    assert!(frames_seen(&said.lines).is_empty(), "{:?}", said.lines);
}

/// No DISPLAY and no WAYLAND_DISPLAY: exit 2 with what to do (needs no Xvfb, always runs).
#[test]
fn no_display_exits_2() {
    let dir = tempfile::tempdir().unwrap();
    pipeline(dir.path(), 24, false);
    let said = Viewer::spawn(None, &["p.ron", "--exit-after", "5"], dir.path()).finish();
    assert_eq!(said.code, Some(2), "{}", said.err);
    for needle in ["DISPLAY", "WAYLAND_DISPLAY", "Xvfb"] {
        assert!(
            said.err.contains(needle),
            "missing {needle:?} in: {}",
            said.err
        );
    }
}
