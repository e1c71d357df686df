//! Section 13 of BENCHMARKS.md: `imprint view` live, headless under Xvfb (what a user sees
//! in a window, one frame stepped per displayed frame, paced at the file's fps or the
//! target): the fps held, and each frame's time split into simulation (the executor's
//! step), drawing (the 3D view, waited for) and UI (panel, its pass, the present). The
//! binary is built first; Xvfb must be installed (`apt-get install xvfb`).

use std::fmt::Write;
use std::path::Path;
use std::process::Command;

/// One viewer run: what was asked and what it printed at the end.
struct Run {
    what: String,
    args: Vec<String>,
    summary: String,
    budget: String,
}

fn view(root: &Path, what: &str, args: &[&str]) -> Run {
    let bin = root.join("target/release/imprint");
    let out = Command::new("xvfb-run")
        .args(["-a", "-s", "-screen 0 1920x1080x24"])
        .arg(&bin)
        .arg("view")
        .args(args)
        .env("XDG_RUNTIME_DIR", std::env::temp_dir())
        .current_dir(root)
        .output()
        .expect("xvfb-run (apt-get install xvfb)");
    let text = String::from_utf8_lossy(&out.stdout).to_string();
    let summary = text
        .lines()
        .rev()
        .find(|l| l.starts_with("view: "))
        .unwrap_or("no frames (see stderr)")
        .to_string();
    let budget = text
        .lines()
        .skip_while(|l| !l.starts_with("budget: "))
        .take_while(|l| !l.starts_with("frame "))
        .collect::<Vec<_>>()
        .join("<br>");
    let failed = String::from_utf8_lossy(&out.stderr)
        .lines()
        .filter(|l| l.starts_with("error: ") && !l.contains("XDG_RUNTIME_DIR"))
        .collect::<Vec<_>>()
        .join(" ");
    Run {
        what: what.to_string(),
        args: args.iter().map(|s| s.to_string()).collect(),
        summary: if failed.is_empty() {
            summary
        } else {
            format!("{summary}; {failed}")
        },
        budget,
    }
}

pub fn section(root: &Path, _repeat: usize) -> String {
    let built = Command::new("cargo")
        .args(["build", "--release", "-p", "imprint-cli"])
        .current_dir(root)
        .status()
        .expect("cargo");
    assert!(
        built.success(),
        "cargo build --release -p imprint-cli failed"
    );
    let runs = [
        view(
            root,
            "amortised_cloth, file's schedule (field every 4, split 2), paced at its 24 fps",
            &[
                "pipelines/amortised_cloth.ron",
                "--size",
                "960x540",
                "--exit-after",
                "96",
            ],
        ),
        view(
            root,
            "amortised_cloth, --target-fps 24",
            &[
                "pipelines/amortised_cloth.ron",
                "--size",
                "960x540",
                "--exit-after",
                "96",
                "--target-fps",
                "24",
            ],
        ),
        view(
            root,
            "harada_cloth (H's scene), --target-fps 24",
            &[
                "pipelines/harada_cloth.ron",
                "--size",
                "960x540",
                "--exit-after",
                "48",
                "--target-fps",
                "24",
            ],
        ),
    ];
    let offline = offline_run(root);
    let adapter =
        imprint_gpu::GpuContext::shared().map_or_else(|e| e.to_string(), |g| g.adapter_name());
    let mut s = format!(
        "## 13. The live viewer (`imprint view`)\n\nWindow drawing on {adapter} under Xvfb; the \
         pipeline's own nodes on their backends (Auto: the CPU beside a software GPU). \
         'fps' is frames stepped and shown per second of wall time (playback is paced, so it \
         is at most the target), over the whole run and after the first frame (loading, first \
         builds); 'per frame' is the mean work of one frame (first included): simulation \
         (the executor's step, with the in-memory checkpoints for scrubbing), drawing (the 3D \
         view, waited for) and UI (panel layout and pass, or the copy of the panel drawn last, \
         and the present).\n\n| run | command | result | frame budget \
         |\n|---|---|---|---|\n"
    );
    for r in &runs {
        let _ = writeln!(
            s,
            "| {} | `imprint view {}` | {} | {} |",
            r.what,
            r.args.join(" "),
            r.summary.trim_start_matches("view: "),
            if r.budget.is_empty() {
                "—"
            } else {
                &r.budget
            }
        );
    }
    let _ = writeln!(
        s,
        "\nWhat a user does without the viewer: edit, `imprint run`, open the PNGs. `imprint run \
         pipelines/amortised_cloth.ron --frames 0..48` (its Render node writes 480×360 frames \
         every 2nd frame on the CPU, MSAA by supersampling) took {offline:.2} s in the same run: \
         the first look at a change comes after the whole run, where the viewer shows it within \
         half a second of the save, its state kept."
    );
    s
}

/// Wall seconds of the offline run a user would make instead.
fn offline_run(root: &Path) -> f64 {
    let out = std::env::temp_dir().join("imprint-bench-view-offline");
    let t = std::time::Instant::now();
    let status = Command::new(root.join("target/release/imprint"))
        .args([
            "run",
            "pipelines/amortised_cloth.ron",
            "--frames",
            "0..48",
            "--out",
        ])
        .arg(&out)
        .current_dir(root)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .expect("imprint run");
    let secs = t.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&out);
    assert!(status.success(), "imprint run amortised_cloth failed");
    secs
}
