//! `imprint`: run, check and draw pipeline files, and compute one-shot distance fields.
//!
//! Exit codes: 0 success; 2 invalid input (pipeline file, mesh file, arguments); 1 a failure
//! while running.

use clap::{Parser, Subcommand, ValueEnum};
use imprint_graph::exec::{Run, RunOptions};
use imprint_graph::schema::Backend;
use imprint_graph::{Error, Plan};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

/// `print!` and `println!` to standard output, ending the program quietly (exit 0) when it
/// is a closed pipe (`imprint check FILE | head`), as command-line tools do, not panicking.
macro_rules! out {
    ($($t:tt)*) => {
        $crate::emit(format_args!($($t)*))
    };
}
macro_rules! outln {
    ($($t:tt)*) => {{
        $crate::emit(format_args!($($t)*));
        $crate::emit(format_args!("\n"));
    }};
}

mod farm;
mod log;
mod schema_cmd;
mod sweep;

/// `imprint --version`, and the version every report.json states.
const VERSION: &str = concat!(
    env!("CARGO_PKG_VERSION"),
    " (git ",
    env!("IMPRINT_GIT_REV"),
    ")"
);

#[derive(Parser)]
#[command(
    name = "imprint",
    version = VERSION,
    about = "How deforming bodies touch soft things: distance fields, cloth, snow, ground"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
    /// More messages on stderr: -v info, -vv debug, -vvv trace (IMPRINT_LOG, a filter as
    /// RUST_LOG takes it, e.g. `warn,imprint_graph=debug`, overrides -v and -q).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,
    /// Errors only on stderr: no warnings, notes or progress bar.
    #[arg(short, long, global = true, conflicts_with = "verbose")]
    quiet: bool,
}

#[derive(Subcommand)]
enum Command {
    /// Run a pipeline: progress bar, per-node timing table, DIR/report.json.
    Run {
        file: PathBuf,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Frames to run, `A..B` (B exclusive) or `A..=B`.
        #[arg(long, value_parser = parse_frames)]
        frames: Option<Range<u32>>,
        /// Overrides the backend of the file and of every node.
        #[arg(long, value_enum)]
        backend: Option<BackendArg>,
        /// Override a node's field: NODE.FIELD=VALUE (VALUE in RON), repeatable.
        #[arg(long = "set", value_name = "NODE.FIELD=VALUE")]
        sets: Vec<String>,
        /// Keep DIR/checkpoint.bin, written every N frames and at the end.
        #[arg(long, value_name = "N")]
        checkpoint_every: Option<u32>,
        /// Continue from DIR/checkpoint.bin (an interrupted run, or one that ran fewer
        /// frames) to the same bytes as one uninterrupted run of --frames.
        #[arg(long)]
        resume: bool,
    },
    /// Run a pipeline live in a window: orbit, play, scrub, hide objects, edit numbers; the
    /// file and its assets reload on save, keeping the state of nodes that did not change.
    View {
        file: PathBuf,
        /// Overrides the backend of the file and of every node (the window always draws
        /// with wgpu: a hardware adapter if there is one, the software one otherwise).
        #[arg(long, value_enum)]
        backend: Option<BackendArg>,
        /// Choose `every`, `split` and `interpolate` of the expensive nodes to hold N frames
        /// per second; the choice is printed as RON to paste into the file.
        #[arg(long, value_name = "N")]
        target_fps: Option<f64>,
        /// Frames to run, `A..B` (B exclusive) or `A..=B`.
        #[arg(long, value_parser = parse_frames)]
        frames: Option<Range<u32>>,
        /// Override a node's field: NODE.FIELD=VALUE (VALUE in RON), repeatable.
        #[arg(long = "set", value_name = "NODE.FIELD=VALUE")]
        sets: Vec<String>,
        /// Size of the 3D view, WxH pixels (default: the Render node's image, else 960x540).
        #[arg(long, value_parser = parse_size)]
        size: Option<[u32; 2]>,
        /// Save the window's last frame as PNG (with --exit-after).
        #[arg(long, value_name = "FILE", requires = "exit_after")]
        screenshot: Option<PathBuf>,
        /// Run N frames, then exit (0; 2 if the file never ran; 1 if a frame failed).
        #[arg(long, value_name = "N")]
        exit_after: Option<u32>,
    },
    /// Validate a pipeline; list what will run, on which frames, and what is pruned and why.
    Check {
        file: PathBuf,
        #[arg(long = "set", value_name = "NODE.FIELD=VALUE")]
        sets: Vec<String>,
    },
    /// Print the pipeline's graph.
    Graph {
        file: PathBuf,
        /// Graphviz DOT (the only format for now).
        #[arg(long, default_value_t = true)]
        dot: bool,
    },
    /// One-shot distance field of one mesh, in its own coordinates, without a pipeline file.
    Field {
        mesh: PathBuf,
        /// Cells along the longest side of the padded box.
        #[arg(long, default_value_t = 128)]
        resolution: u32,
        /// Band half-width, in cells.
        #[arg(long, default_value_t = 3.0)]
        band: f32,
        /// Padding on every side, as a fraction of the longest side.
        #[arg(long, default_value_t = 0.1)]
        padding: f32,
        /// Boundary points: the closest surface point (sub-voxel) or H's cell centres.
        #[arg(long, value_enum, default_value_t = VariantArg::Closest)]
        variant: VariantArg,
        #[arg(long, value_enum)]
        backend: Option<BackendArg>,
        #[arg(long, default_value = "out")]
        out: PathBuf,
    },
    /// Run a pipeline over a grid of settings; time and error of each against a reference:
    /// DIR/sweep.csv, sweep.md, sweep.png (time against error, Pareto front marked).
    Sweep(sweep::SweepArgs),
    /// Hand the work to a farm: write a Slurm array or an OpenJD job template of resumable
    /// tasks (a sweep's settings, or frame chunks), and gather their results with
    /// `imprint farm collect DIR`.
    Farm(farm::FarmCommand),
    /// Stability map of a pipeline's Cloth node: stiffness multipliers × substep over the
    /// estimated critical step; each cell runs the cloth (perturbed, no colliders) and says
    /// whether it stayed stable or blew up.
    Stress {
        /// What to stress.
        #[arg(value_enum)]
        what: StressWhat,
        file: PathBuf,
        /// The Cloth node (default: the pipeline's only one).
        #[arg(long)]
        node: Option<String>,
        /// Stiffness multipliers (rows), comma-separated.
        #[arg(long, value_delimiter = ',', default_value = "1,10,100,1000")]
        scales: Vec<f32>,
        /// Substep / estimated critical substep (columns), comma-separated.
        #[arg(
            long,
            value_delimiter = ',',
            default_value = "0.5,0.75,0.9,1.1,1.25,1.5,2"
        )]
        ratios: Vec<f32>,
        /// Frames each cell runs.
        #[arg(long, default_value_t = 12)]
        frames: u32,
        #[arg(long = "set", value_name = "NODE.FIELD=VALUE")]
        sets: Vec<String>,
    },
    /// Print a completion script for a shell, e.g. `imprint completions bash >
    /// ~/.local/share/bash-completion/completions/imprint`.
    Completions {
        #[arg(value_enum)]
        shell: clap_complete::Shell,
    },
    /// Print the JSON Schema of a pipeline file or of report.json, or the node reference
    /// (`imprint schema nodes-md > docs/nodes.md`).
    Schema {
        #[arg(value_enum)]
        what: schema_cmd::SchemaWhat,
    },
}

#[derive(Clone, Copy, ValueEnum)]
enum StressWhat {
    Cloth,
}

#[derive(Clone, Copy, ValueEnum)]
enum BackendArg {
    Auto,
    Cpu,
    Gpu,
}

impl From<BackendArg> for Backend {
    fn from(b: BackendArg) -> Self {
        match b {
            BackendArg::Auto => Backend::Auto,
            BackendArg::Cpu => Backend::Cpu,
            BackendArg::Gpu => Backend::Gpu,
        }
    }
}

#[derive(Clone, Copy, ValueEnum)]
enum VariantArg {
    Closest,
    Centre,
}

fn parse_frames(s: &str) -> Result<Range<u32>, String> {
    let bad = || format!("'{s}': expected A..B or A..=B with whole numbers");
    let (a, b, inclusive) = if let Some((a, b)) = s.split_once("..=") {
        (a, b, true)
    } else if let Some((a, b)) = s.split_once("..") {
        (a, b, false)
    } else {
        return Err(bad());
    };
    let a: u32 = a.trim().parse().map_err(|_| bad())?;
    let b: u32 = b.trim().parse().map_err(|_| bad())?;
    let end = if inclusive { b + 1 } else { b };
    if end <= a {
        return Err(format!("'{s}' is an empty range"));
    }
    Ok(a..end)
}

fn parse_size(s: &str) -> Result<[u32; 2], String> {
    let bad = || format!("'{s}': expected WxH in pixels, e.g. 960x540");
    let (w, h) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (
        w.trim().parse().map_err(|_| bad())?,
        h.trim().parse().map_err(|_| bad())?,
    );
    if w == 0 || h == 0 || w > 16384 || h > 16384 {
        return Err(format!("'{s}': each side must be 1 to 16384 pixels"));
    }
    Ok([w, h])
}

fn main() -> ExitCode {
    imprint_core::pool::retain_freed_memory();
    let cli = Cli::parse();
    // Before anything else runs, while this is the only thread (see `quiet_display_probe`).
    quiet_display_probe();
    log::init(cli.verbose, cli.quiet);
    imprint_graph::report::set_program_version(VERSION);
    let code = run_command(cli);
    remove_runtime_dir();
    code
}

fn run_command(cli: Cli) -> ExitCode {
    if let Command::View { .. } = cli.command {
        return view(cli.command);
    }
    match execute(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            report_error(&e);
            ExitCode::from(e.exit_code() as u8)
        }
    }
}

/// The runtime folder [`quiet_display_probe`] made, removed on the way out ([`exit`]).
static RUNTIME_DIR: std::sync::OnceLock<PathBuf> = std::sync::OnceLock::new();

/// Gives the process a private, empty `XDG_RUNTIME_DIR` when it has none (or one that is
/// not an absolute path, which libwayland rejects alike), removed when the program ends.
///
/// Creating a Vulkan instance runs Mesa's device-select layer, which asks the Wayland
/// display (`wl_display_connect`) which GPU drives the screen; without a runtime folder
/// libwayland prints "error: XDG_RUNTIME_DIR is invalid or not set in the environment." to
/// stderr, on every run, though nothing is wrong (a headless machine, a container, `sudo`,
/// a cron job). With a folder that holds no display socket the probe fails quietly, as it
/// does on a desktop without Wayland. A session that has a runtime folder keeps it.
fn quiet_display_probe() {
    let key = "XDG_RUNTIME_DIR";
    if std::env::var_os(key).is_some_and(|d| Path::new(&d).is_absolute()) {
        return;
    }
    // Mode 0700 and a random name: no other user can place a socket in it.
    let Ok(dir) = tempfile::Builder::new()
        .prefix("imprint-runtime-")
        .tempdir()
    else {
        return;
    };
    let dir = dir.keep();
    // SAFETY: called first thing in `main` after parsing the arguments, before this
    // process starts any thread, so nothing reads or writes the environment concurrently.
    unsafe { std::env::set_var(key, &dir) };
    let _ = RUNTIME_DIR.set(dir);
}

fn remove_runtime_dir() {
    if let Some(dir) = RUNTIME_DIR.get() {
        let _ = std::fs::remove_dir_all(dir);
    }
}

/// Ends the program at once with `code`, removing the runtime folder first.
fn exit(code: i32) -> ! {
    remove_runtime_dir();
    std::process::exit(code)
}

/// `imprint view`: its own exit codes (see `imprint_view::ViewError`).
fn view(cmd: Command) -> ExitCode {
    let Command::View {
        file,
        backend,
        target_fps,
        frames,
        sets,
        size,
        screenshot,
        exit_after,
    } = cmd
    else {
        unreachable!("called for View only");
    };
    if target_fps.is_some_and(|f| !(f.is_finite() && f > 0.0)) {
        eprintln!("error: --target-fps must be a number of frames per second > 0");
        return ExitCode::from(2);
    }
    let opts = imprint_view::ViewOptions {
        file,
        backend: backend.map(Into::into),
        target_fps,
        frames,
        sets,
        size,
        exit_after,
        screenshot,
    };
    match imprint_view::run(opts) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(e.code)
        }
    }
}

/// Writes to standard output (see `out!`).
pub(crate) fn emit(text: std::fmt::Arguments) {
    use std::io::Write;
    let mut stdout = std::io::stdout().lock();
    if let Err(e) = stdout.write_fmt(text).and_then(|_| stdout.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            exit(0);
        }
        eprintln!("error: cannot write to standard output: {e}");
        exit(1);
    }
}

fn report_error(e: &Error) {
    match e {
        Error::Pipeline(p) => {
            let handler =
                miette::GraphicalReportHandler::new_themed(if std::io::stderr().is_terminal() {
                    miette::GraphicalTheme::unicode()
                } else {
                    miette::GraphicalTheme::unicode_nocolor()
                });
            let mut s = String::new();
            let _ = handler.render_report(&mut s, p.as_ref());
            eprintln!("error: {s}");
        }
        Error::Core(c) => eprintln!("error: {c}"),
    }
}

fn execute(cmd: Command) -> imprint_graph::Result<()> {
    match cmd {
        Command::Run {
            file,
            out,
            frames,
            backend,
            sets,
            checkpoint_every,
            resume,
        } => {
            if checkpoint_every == Some(0) {
                return Err(imprint_core::Error::Invalid(
                    "--checkpoint-every must be at least 1".into(),
                )
                .into());
            }
            let plan = imprint_graph::load(&file, &sets)?;
            let opts = RunOptions {
                out,
                frames,
                backend: backend.map(Into::into),
                checkpoint_every: checkpoint_every.unwrap_or(0),
                resume,
                stop: Some(stop_on_signal()),
            };
            run_plan(&plan, opts)
        }
        Command::Check { file, sets } => {
            let plan = imprint_graph::load(&file, &sets)?;
            out!("{}", describe(&plan));
            Ok(())
        }
        Command::Graph { file, .. } => {
            let plan = imprint_graph::load(&file, &[])?;
            out!("{}", plan.dot());
            Ok(())
        }
        Command::Sweep(args) => sweep::sweep(&args),
        Command::Farm(cmd) => match (cmd.collect, cmd.job) {
            (Some(farm::FarmSub::Collect { dir }), _) => farm::collect(&dir),
            (None, Some(job)) => farm::farm(&job),
            (None, None) => unreachable!("clap requires FILE without a subcommand"),
        },
        Command::Schema { what } => schema_cmd::print(what),
        Command::Completions { shell } => {
            use clap::CommandFactory;
            let mut script = Vec::new();
            clap_complete::generate(shell, &mut Cli::command(), "imprint", &mut script);
            out!("{}", String::from_utf8_lossy(&script));
            Ok(())
        }
        Command::View { .. } => unreachable!("main() runs `view` with its own exit codes"),
        Command::Stress {
            what: StressWhat::Cloth,
            file,
            node,
            scales,
            ratios,
            frames,
            sets,
        } => {
            let plan = imprint_graph::load(&file, &sets)?;
            out!(
                "{}",
                stress_cloth(&plan, node.as_deref(), &scales, &ratios, frames)?
            );
            Ok(())
        }
        Command::Field {
            mesh,
            resolution,
            band,
            padding,
            variant,
            backend,
            out,
        } => {
            let text = field_pipeline(&mesh, resolution, band, padding, variant)?;
            let plan = imprint_graph::parse(
                imprint_graph::diagnostics::Source {
                    name: "imprint field".into(),
                    text,
                },
                Path::new("."),
            )?;
            let opts = RunOptions {
                out,
                backend: backend.map(Into::into),
                stop: Some(stop_on_signal()),
                ..Default::default()
            };
            run_plan(&plan, opts)
        }
    }
}

/// The table of `imprint stress cloth`.
fn stress_cloth(
    plan: &Plan,
    node: Option<&str>,
    scales: &[f32],
    ratios: &[f32],
    frames: u32,
) -> imprint_graph::Result<String> {
    use imprint_graph::schema::NodeSpec;
    use imprint_stages::cloth::{ClothAssets, stress_map};
    let cloths: Vec<(&String, &imprint_graph::schema::ClothNode)> = plan
        .file
        .nodes
        .iter()
        .filter_map(|(n, s)| match s {
            NodeSpec::Cloth(c) => Some((n, c)),
            _ => None,
        })
        .collect();
    let (name, cloth) = match (node, cloths.as_slice()) {
        (Some(want), _) => cloths
            .iter()
            .find(|(n, _)| n.as_str() == want)
            .copied()
            .ok_or_else(|| {
                imprint_core::Error::Invalid(format!("--node {want}: no Cloth node of that name"))
            })?,
        (None, [one]) => *one,
        (None, _) => {
            return Err(imprint_core::Error::Invalid(format!(
                "{} Cloth nodes in the pipeline; name one with --node",
                cloths.len()
            ))
            .into());
        }
    };
    if frames == 0 {
        return Err(imprint_core::Error::Invalid("--frames must be at least 1".into()).into());
    }
    let assets = ClothAssets::load(&cloth.params, &plan.base_dir)?;
    let cases = stress_map(&cloth.params, &assets, scales, ratios, frames)?;
    let mut s = format!(
        "cloth '{name}': {} substeps per frame at {} fps, {frames} frames per cell, every \
         particle nudged by 1% of the shortest rest length, no colliders\n\
         cell: ok = stable (largest strain), BOOM@f = stopped at frame f; * = the estimate \
         predicted the other outcome\n\n",
        cloth.params.substeps, plan.file.fps
    );
    s += &format!("{:>10} |", "stiffness");
    for r in ratios {
        s += &format!(" {:>11}", format!("dt/dc {r}"));
    }
    s += "\n";
    s += &format!("{}\n", "-".repeat(12 + 12 * ratios.len()));
    let mut agree = 0;
    for (row, scale) in cases.chunks(ratios.len()).zip(scales) {
        s += &format!("{:>9}x |", scale);
        for c in row {
            let cell = match &c.outcome {
                imprint_stages::cloth::StressOutcome::Stable { max_strain } => {
                    format!("ok {max_strain:.2}")
                }
                imprint_stages::cloth::StressOutcome::Exploded { frame, .. } => {
                    format!("BOOM@{frame}")
                }
            };
            let right = c.predicted_stable == c.outcome.is_stable();
            agree += right as usize;
            s += &format!(" {:>11}", format!("{cell}{}", if right { "" } else { "*" }));
        }
        s += "\n";
    }
    s += &format!(
        "\nthe stability estimate predicted {agree} of {} cells\n",
        cases.len()
    );
    Ok(s)
}

/// A flag that Ctrl-C or SIGTERM sets: the run stops before its next frame, keeping its
/// report (and checkpoint, with --checkpoint-every), and exits with 130.
fn stop_on_signal() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    // A second signal ends the program at once.
    let handler = move || {
        if flag.swap(true, Ordering::SeqCst) {
            exit(130);
        }
    };
    if let Err(e) = ctrlc::set_handler(handler) {
        tracing::warn!("Ctrl-C will end the run without its report: {e}");
    }
    stop
}

fn run_plan(plan: &Plan, opts: RunOptions) -> imprint_graph::Result<()> {
    let out = opts.out.clone();
    let run = Run::start(plan, &opts)?;
    for w in run.warnings() {
        tracing::warn!("{w}");
    }
    let said = run.warnings().len();
    if let Some(c) = run.executor().report().resumed_at
        && !log::quiet()
    {
        eprintln!(
            "resuming at frame {c} from {}",
            out.join("checkpoint.bin").display()
        );
    }
    let bar = ProgressBar::new(0);
    if std::io::stderr().is_terminal() && !log::quiet() {
        bar.set_style(
            ProgressStyle::with_template(
                "{spinner} frame {pos}/{len} [{bar:30}] {elapsed} ETA {eta}",
            )
            .expect("valid template")
            .progress_chars("=> "),
        );
    } else {
        bar.set_draw_target(ProgressDrawTarget::hidden());
    }
    let drawing = log::drawing(&bar);
    let report = run.finish(
        &mut |done, total| {
            bar.set_length(total as u64);
            bar.set_position(done as u64);
        },
        None,
    )?;
    drop(drawing);
    bar.finish_and_clear();
    // What the stages' self-checks counted while running (each kind once).
    for w in report.warnings.iter().skip(said) {
        tracing::warn!("{w}");
    }
    outln!("{}", report.table(&plan.order));
    outln!(
        "{} file(s) written; report: {}",
        report.files_written,
        out.join("report.json").display()
    );
    Ok(())
}

/// The pipeline `imprint field` runs: the same nodes and checks a user's file gets.
fn field_pipeline(
    mesh: &Path,
    resolution: u32,
    band: f32,
    padding: f32,
    variant: VariantArg,
) -> imprint_graph::Result<String> {
    let abs = std::path::absolute(mesh).map_err(|e| imprint_core::Error::io(mesh, e))?;
    let path = abs
        .display()
        .to_string()
        .replace('\\', "\\\\")
        .replace('"', "\\\"");
    let variant = match variant {
        VariantArg::Closest => "Closest",
        VariantArg::Centre => "Centre",
    };
    Ok(format!(
        r#"Pipeline(
    frames: 1,
    nodes: {{
        "mesh": Mesh(path: "{path}"),
        "boundary": Voxelize(mesh: "mesh", grid: Fit(resolution: {resolution}, padding: {padding:?}), variant: {variant}),
        "field": DistanceField(boundary: "boundary", band: {band:?}, measure: First),
        "write": WriteField(field: "field", dir: ".", slices: [(axis: X), (axis: Y), (axis: Z)]),
    }},
)"#
    ))
}

/// What `imprint check` prints: nodes that run (in order, with frames and backend) and pruned.
fn describe(plan: &Plan) -> String {
    let f = &plan.file;
    let mut s = format!(
        "{}: valid. {} frame(s) at {} fps, backend {:?}, seed {}\n\nwill run (in order; Auto = a hardware GPU if there is one, else the CPU):\n",
        plan.source.name, f.frames, f.fps, f.backend, f.seed
    );
    let statics = plan.static_nodes();
    for name in &plan.order {
        let node = &f.nodes[name];
        let sc = node.schedule();
        let when = if node.is_writer() {
            if sc.every > 1 {
                format!("every {} frames (offset {})", sc.every, sc.offset)
            } else {
                "every frame".into()
            }
        } else if statics.contains(name) {
            "frame 0 only (inputs never change; reused after)".into()
        } else if sc.every > 1 || sc.split > 1 {
            format!(
                "every {} (offset {}){}{}",
                sc.every,
                sc.offset,
                if sc.split > 1 {
                    format!(", split {}", sc.split)
                } else {
                    String::new()
                },
                if sc.interpolate { ", interpolated" } else { "" }
            )
        } else {
            "every frame".into()
        };
        let inputs: Vec<String> = node
            .inputs()
            .iter()
            .map(|p| format!("{}={} ({})", p.port, p.node, p.ty))
            .collect();
        // Nodes with two paths run where the file says; the rest run on the CPU.
        let on = match node.backend().or(Some(f.backend)) {
            Some(b) if node.has_gpu_path() => format!("{b:?}"),
            _ => "Cpu".to_string(),
        };
        s += &format!(
            "  {:<16} {:<14} {:<5} {:<40} {}\n",
            name,
            node.kind(),
            on,
            when,
            if inputs.is_empty() {
                String::new()
            } else {
                format!("<- {}", inputs.join(", "))
            }
        );
    }
    s += &format!(
        "\nschedule (first {} frames):\n{}",
        plan.file.frames.min(24),
        plan.schedule_table(24)
    );
    for w in &plan.warnings {
        s += &format!("\nwarning: {w}\n");
    }
    if plan.pruned.is_empty() {
        s += "\npruned: none\n";
    } else {
        s += "\npruned (will not run):\n";
        for (n, why) in &plan.pruned {
            s += &format!("  {n:<16} {why}\n");
        }
    }
    s
}
