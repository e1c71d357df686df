//! `imprint sweep`: one pipeline over a grid of settings, every run timed and compared with a
//! reference run, written as `sweep.csv`, `sweep.md` and `sweep.png` (time against error).
//!
//! - `--vary NODE.FIELD=v1,v2,…` (repeatable; values in RON, split at top-level commas): every
//!   combination runs, in the order given (the first `--vary` changes slowest).
//! - `--reference NODE.FIELD=v` (repeatable): the reference is the file with these overrides
//!   (and `--set`); without any, the file as it is. Its numbers are cached under
//!   `DIR/reference/<key>/`, the key a hash of the pipeline text after the overrides, the
//!   frame range, the backend and the imprint version, so a second sweep reuses it.
//! - Each setting runs with its writers into `DIR/runs/<setting>/`; the reference's into its
//!   cache folder.
//!
//! The CSV and the Markdown table hold the same rows: the reference first (setting `ref`, zero
//! error by definition), then one per combination. Only the timing columns (`frame_ms_*`,
//! `*_ms_per_frame`) and `pareto` change between two sweeps of the same inputs.

mod measure;
mod plot;
pub(crate) mod task;

use imprint_core::io::atomic_write_bytes;
use imprint_graph::exec::{RunOptions, run_observed};
use imprint_graph::schema::Backend;
use imprint_graph::{Error, Plan, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use measure::{Cache, Comparer, FrameError, Recorder, Reference, Timing, TrackKind};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::io::IsTerminal;
use std::ops::Range;
use std::path::PathBuf;

/// What `imprint sweep` takes.
#[derive(clap::Args)]
pub struct SweepArgs {
    file: PathBuf,
    /// A field to vary and its values: NODE.FIELD=V1,V2,… (RON, split at top-level commas);
    /// repeatable: every combination runs, the first --vary changing slowest.
    #[arg(long, value_name = "NODE.FIELD=V1,V2,…", required = true)]
    vary: Vec<String>,
    /// The reference's setting: NODE.FIELD=VALUE, repeatable (none: the file as it is).
    #[arg(long, value_name = "NODE.FIELD=VALUE")]
    reference: Vec<String>,
    /// Override for every run, the reference's included: NODE.FIELD=VALUE, repeatable.
    #[arg(long = "set", value_name = "NODE.FIELD=VALUE")]
    sets: Vec<String>,
    /// Output folder; the reference's cache goes under DIR/reference/, each setting's
    /// files under DIR/runs/.
    #[arg(long, default_value = "out/sweep")]
    out: PathBuf,
    /// Frames every run runs, `A..B` (B exclusive) or `A..=B`.
    #[arg(long, value_parser = crate::parse_frames)]
    frames: Option<Range<u32>>,
    /// Overrides the backend of the file and of every node, in every run.
    #[arg(long, value_enum)]
    backend: Option<crate::BackendArg>,
    /// The error plotted and ranked (the Pareto column): NODE or NODE.STAT, STAT one of
    /// mean, rms, max. Default: the last node in the pipeline's order with an error metric
    /// (DistanceField, Cloth, Heightmap); a cloth's max, the others' rms.
    #[arg(long, value_name = "NODE[.STAT]")]
    error: Option<String>,
    /// Run one task of a farm job (`imprint farm`) and nothing else: `ref` (the reference,
    /// into its cache) or a setting's number (into DIR/runs/N/, its row in row.json).
    /// Resumes from the task's checkpoint when an earlier try left one.
    #[arg(long, value_name = "ref|N")]
    pub(crate) task: Option<String>,
    /// With --task: keep a checkpoint every N frames, for a retry to resume from.
    #[arg(long, value_name = "N", requires = "task", default_value_t = 10)]
    pub(crate) checkpoint_every: u32,
}

/// One `--vary` (or, with one value, `--reference`): a node's field and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Vary {
    pub path: String,
    pub values: Vec<String>,
}

fn invalid(msg: String) -> Error {
    imprint_core::Error::Invalid(msg).into()
}

/// Splits at commas outside brackets and strings: `1,(2, 3),"a,b"` → `1`, `(2, 3)`, `"a,b"`.
fn split_top_level(s: &str) -> Vec<String> {
    let mut out = Vec::new();
    let mut cur = String::new();
    let (mut depth, mut in_str, mut escaped) = (0i32, false, false);
    for c in s.chars() {
        if in_str {
            in_str = escaped || c != '"';
            escaped = !escaped && c == '\\';
        } else {
            match c {
                '"' => in_str = true,
                '(' | '[' | '{' => depth += 1,
                ')' | ']' | '}' => depth -= 1,
                ',' if depth == 0 => {
                    out.push(cur.trim().to_string());
                    cur.clear();
                    continue;
                }
                _ => {}
            }
        }
        cur.push(c);
    }
    out.push(cur.trim().to_string());
    out
}

/// Parses `NODE.FIELD[.FIELD…]=v1,v2,…` given to `flag`.
pub fn parse_vary(flag: &str, s: &str) -> Result<Vary> {
    let usage = || {
        invalid(format!(
            "{flag} {s}: expected NODE.FIELD=VALUE[,VALUE…] (a node name, a dot, a field; \
             values in RON, separated by commas)"
        ))
    };
    let (path, values) = s.split_once('=').ok_or_else(usage)?;
    let path = path.trim();
    if path.split('.').count() < 2 || path.split('.').any(|p| p.trim().is_empty()) {
        return Err(usage());
    }
    let values = split_top_level(values);
    if values.iter().any(String::is_empty) {
        return Err(invalid(format!(
            "{flag} {s}: an empty value (two commas in a row, or one at either end)"
        )));
    }
    for (i, v) in values.iter().enumerate() {
        if values[..i].contains(v) {
            return Err(invalid(format!(
                "{flag} {s}: the value {v} is listed twice"
            )));
        }
    }
    Ok(Vary {
        path: path.to_string(),
        values,
    })
}

/// Every combination of the values, as `NODE.FIELD=VALUE` overrides; the first `Vary`
/// changes slowest.
pub fn combinations(vary: &[Vary]) -> Vec<Vec<String>> {
    let mut out = vec![Vec::new()];
    for v in vary {
        out = out
            .into_iter()
            .flat_map(|prefix: Vec<String>| {
                v.values.iter().map(move |value| {
                    let mut c = prefix.clone();
                    c.push(format!("{}={value}", v.path));
                    c
                })
            })
            .collect();
    }
    out
}

/// Refuses a field given twice, and a node the pipeline does not have.
fn check_paths(flag: &str, vary: &[Vary], plan: &Plan) -> Result<()> {
    for (i, v) in vary.iter().enumerate() {
        if vary[..i].iter().any(|w| w.path == v.path) {
            return Err(invalid(format!("{flag} {}: given twice", v.path)));
        }
        let node = v.path.split('.').next().unwrap_or_default();
        if !plan.file.nodes.contains_key(node) {
            let names: Vec<&str> = plan.file.nodes.keys().map(String::as_str).collect();
            return Err(invalid(format!(
                "{flag} {}: the pipeline has no node named '{node}' (its nodes: {})",
                v.path,
                names.join(", ")
            )));
        }
    }
    Ok(())
}

/// Loads the file with `overrides` after `--set`, saying which setting is wrong if it is.
fn load_setting(args: &SweepArgs, what: &str, overrides: &[String]) -> Result<Plan> {
    let all: Vec<String> = args.sets.iter().chain(overrides).cloned().collect();
    imprint_graph::load(&args.file, &all).inspect_err(|_| {
        let how = if overrides.is_empty() {
            String::new()
        } else {
            format!(" (`{}`)", overrides.join(" "))
        };
        eprintln!("error: {what}{how}: the pipeline it makes is invalid:");
    })
}

/// One row of the results (a farm task's `row.json`).
#[derive(Serialize, Deserialize)]
pub(crate) struct Row {
    /// `ref`, or the setting's number from 1.
    id: String,
    /// The overrides that make this setting.
    overrides: Vec<String>,
    /// `ok`, or why the run failed or what could not be compared.
    status: String,
    timing: Option<Timing>,
    errors: BTreeMap<String, Vec<FrameError>>,
}

impl Row {
    /// Overall (mean, RMS, max) error of `node`.
    fn error(&self, node: &str) -> Option<[f64; 3]> {
        self.errors
            .get(node)
            .and_then(|f| FrameError::total(f).stats())
    }
}

/// The error of the plot and of the Pareto front: one node's mean, RMS or max.
struct Primary {
    node: String,
    /// The node's kind, for messages.
    node_kind: &'static str,
    kind: TrackKind,
    /// 0 mean, 1 RMS, 2 max.
    stat: usize,
}

const STATS: [&str; 3] = ["mean", "rms", "max"];

impl Primary {
    /// `--error NODE[.STAT]`, or the last node of the reference's run with an error metric
    /// (a cloth's max, the others' RMS); `None` when no node has one.
    fn choose(arg: Option<&str>, plan: &Plan) -> Result<Option<Primary>> {
        let default_stat = |kind| if kind == TrackKind::Vertices { 2 } else { 1 };
        let Some(arg) = arg else {
            return Ok(plan.order.iter().rev().find_map(|n| {
                let kind = TrackKind::of(&plan.file.nodes[n])?;
                Some(Primary {
                    node: n.clone(),
                    node_kind: plan.file.nodes[n].kind(),
                    kind,
                    stat: default_stat(kind),
                })
            }));
        };
        let (node, stat) = match arg.rsplit_once('.') {
            Some((node, stat)) => {
                let i = STATS.iter().position(|s| *s == stat).ok_or_else(|| {
                    invalid(format!(
                        "--error {arg}: '{stat}' is not one of mean, rms, max"
                    ))
                })?;
                (node, Some(i))
            }
            None => (arg, None),
        };
        let kind = plan
            .file
            .nodes
            .get(node)
            .and_then(TrackKind::of)
            .filter(|_| plan.order.iter().any(|o| o == node))
            .ok_or_else(|| {
                let tracked: Vec<&str> = plan
                    .order
                    .iter()
                    .filter(|n| TrackKind::of(&plan.file.nodes[*n]).is_some())
                    .map(|n| n.as_str())
                    .collect();
                invalid(format!(
                    "--error {arg}: '{node}' is not a node with an error metric that the \
                     reference runs (those are: {})",
                    tracked.join(", ")
                ))
            })?;
        Ok(Some(Primary {
            node: node.to_string(),
            node_kind: plan.file.nodes[node].kind(),
            kind,
            stat: stat.unwrap_or(default_stat(kind)),
        }))
    }

    fn describe(&self) -> String {
        let kind = match self.kind {
            TrackKind::Field => "field",
            TrackKind::Vertices => &self.node_kind.to_lowercase(),
            TrackKind::Heights => "height field",
        };
        let stat = ["mean", "RMS", "max"][self.stat];
        format!("{kind} '{}': {stat} {}", self.node, self.kind.describe())
    }

    fn column(&self) -> String {
        stat_column(&self.node, self.kind, STATS[self.stat])
    }
}

fn stat_column(node: &str, kind: TrackKind, stat: &str) -> String {
    format!("{node}_{}_{stat}{}", kind.quantity(), kind.unit_suffix())
}

/// Everything checked before anything runs: the settings, their plans, the reference's.
pub(crate) struct Setup {
    vary: Vec<Vary>,
    ref_overrides: Vec<String>,
    ref_plan: Plan,
    combos: Vec<Vec<String>>,
    plans: Vec<Plan>,
    primary: Option<Primary>,
    frames: Range<u32>,
    backend: Option<Backend>,
    cache: Cache,
}

impl Setup {
    /// The settings' ids: their numbers from 1, zero-padded to one width.
    pub(crate) fn ids(&self) -> Vec<String> {
        let width = self.combos.len().to_string().len();
        (1..=self.combos.len())
            .map(|i| format!("{i:0width$}"))
            .collect()
    }

    /// The run options of one run into `out`.
    fn opts(&self, out: PathBuf) -> RunOptions {
        RunOptions {
            out,
            frames: Some(self.frames.clone()),
            backend: self.backend,
            ..Default::default()
        }
    }
}

/// Parses and checks the arguments, and loads every setting's pipeline.
pub(crate) fn prepare(args: &SweepArgs) -> Result<Setup> {
    let vary: Vec<Vary> = args
        .vary
        .iter()
        .map(|s| parse_vary("--vary", s))
        .collect::<Result<_>>()?;
    let reference: Vec<Vary> = args
        .reference
        .iter()
        .map(|s| parse_vary("--reference", s))
        .collect::<Result<_>>()?;
    if let Some(r) = reference.iter().find(|r| r.values.len() != 1) {
        return Err(invalid(format!(
            "--reference {}: one value only (got {})",
            r.path,
            r.values.join(", ")
        )));
    }
    let base = imprint_graph::load(&args.file, &args.sets)?;
    check_paths("--vary", &vary, &base)?;
    check_paths("--reference", &reference, &base)?;

    let ref_overrides: Vec<String> = reference
        .iter()
        .map(|r| format!("{}={}", r.path, r.values[0]))
        .collect();
    let ref_plan = load_setting(args, "the reference", &ref_overrides)?;
    let combos = combinations(&vary);
    let plans: Vec<Plan> = combos
        .iter()
        .enumerate()
        .map(|(i, c)| load_setting(args, &format!("setting {}", i + 1), c))
        .collect::<Result<_>>()?;
    let primary = Primary::choose(args.error.as_deref(), &ref_plan)?;
    let frames = args.frames.clone().unwrap_or(0..ref_plan.file.frames);
    if frames.is_empty() || frames.end > ref_plan.file.frames {
        return Err(invalid(format!(
            "--frames {}..{} is outside the pipeline's 0..{}",
            frames.start, frames.end, ref_plan.file.frames
        )));
    }
    let backend: Option<Backend> = args.backend.map(Into::into);
    let backend_key = backend.map_or_else(|| "file".to_string(), |b| format!("{b:?}"));
    let cache = Cache::new(
        &args.out.join("reference"),
        &ref_plan,
        &frames,
        &backend_key,
    );
    Ok(Setup {
        vary,
        ref_overrides,
        ref_plan,
        combos,
        plans,
        primary,
        frames,
        backend,
        cache,
    })
}

/// Runs the sweep; writes DIR/sweep.{csv,md,png} and DIR/sweep_frames.csv. With `--task`,
/// runs that one task of a farm job instead ([`task`]).
pub fn sweep(args: &SweepArgs) -> Result<()> {
    let setup = prepare(args)?;
    if let Some(id) = &args.task {
        return task::run(args, &setup, id);
    }
    let cached = match setup.cache.load() {
        Ok(r) => r,
        Err(why) => {
            outln!("reference: the cache cannot be used ({why}); running it again");
            None
        }
    };
    let bar = progress_bar((setup.combos.len() + usize::from(cached.is_none())) as u64);
    let reference = match cached {
        Some(r) => {
            outln!(
                "reference: reusing the cached run in {} (same pipeline text, frames and \
                 backend; delete it to run the reference again)",
                setup.cache.dir.display()
            );
            r
        }
        None => {
            say(
                &bar,
                format!(
                    "reference: running it ({}), cached in {}",
                    label(&setup.ref_overrides, "the file as it is"),
                    setup.cache.dir.display()
                ),
            );
            let r = run_reference(&setup, setup.opts(setup.cache.dir.join("run")), &bar)?;
            bar.inc(1);
            r
        }
    };
    let mut rows = vec![reference_row(&setup, &reference)];
    for (i, id) in setup.ids().into_iter().enumerate() {
        let row = run_setting(&setup, &reference, i, id, setup.opts_for(args, i), &bar);
        say(
            &bar,
            format!(
                "[{}/{}] {}: {}",
                i + 1,
                setup.combos.len(),
                label(&row.overrides, ""),
                summary(&row)
            ),
        );
        rows.push(row);
        bar.inc(1);
    }
    bar.finish_and_clear();
    write_results(args, &setup, &reference, &rows)
}

impl Setup {
    /// Options of setting `i`'s run: its writers into `DIR/runs/<id>/`.
    fn opts_for(&self, args: &SweepArgs, i: usize) -> RunOptions {
        self.opts(args.out.join("runs").join(&self.ids()[i]))
    }
}

/// Runs the reference with `opts`, recording its tracks, and saves it in the cache.
fn run_reference(setup: &Setup, opts: RunOptions, bar: &ProgressBar) -> Result<Reference> {
    let mut rec = Recorder::new(&setup.ref_plan);
    let report = run_observed(
        &setup.ref_plan,
        &opts,
        &mut frame_progress(bar, "reference"),
        Some(&mut rec),
    )?;
    let r = rec.finish(&report);
    setup.cache.save(&setup.ref_plan.source.name, &r)?;
    Ok(r)
}

/// The reference's own row: zero error by definition.
fn reference_row(setup: &Setup, reference: &Reference) -> Row {
    Row {
        id: "ref".into(),
        overrides: setup.ref_overrides.clone(),
        status: "ok".into(),
        timing: Some(reference.timing.clone()),
        errors: reference.zero_errors(),
    }
}

/// Runs setting `i` (id `id`) with `opts`, compared with the reference as it goes.
fn run_setting(
    setup: &Setup,
    reference: &Reference,
    i: usize,
    id: String,
    opts: RunOptions,
    bar: &ProgressBar,
) -> Row {
    let (overrides, plan) = (&setup.combos[i], &setup.plans[i]);
    let what = label(overrides, "");
    let mut cmp = Comparer::new(reference);
    let run = run_observed(plan, &opts, &mut frame_progress(bar, &what), Some(&mut cmp));
    match run {
        Ok(report) => Row {
            status: if cmp.notes.is_empty() {
                "ok".into()
            } else {
                cmp.notes.iter().cloned().collect::<Vec<_>>().join("; ")
            },
            timing: Some(cmp.timing(&report, plan)),
            errors: std::mem::take(&mut cmp.errors),
            id,
            overrides: overrides.clone(),
        },
        Err(e) => Row {
            status: format!("failed: {e}"),
            timing: None,
            errors: BTreeMap::new(),
            id,
            overrides: overrides.clone(),
        },
    }
}

/// Writes sweep.csv, sweep_frames.csv, sweep.md and sweep.png from the rows (the reference's
/// first); fails when a setting failed.
fn write_results(
    args: &SweepArgs,
    setup: &Setup,
    reference: &Reference,
    rows: &[Row],
) -> Result<()> {
    let (vary, primary) = (&setup.vary, setup.primary.as_ref());
    let pareto = pareto_of(rows, primary);
    let table = results_table(rows, vary, reference, &setup.ref_plan, &pareto);
    let out = &args.out;
    atomic_write_bytes(&out.join("sweep.csv"), table.csv().as_bytes())?;
    atomic_write_bytes(&out.join("sweep_frames.csv"), frames_csv(rows).as_bytes())?;
    let md = markdown(args, &setup.ref_overrides, &setup.frames, primary, &table);
    atomic_write_bytes(&out.join("sweep.md"), md.as_bytes())?;
    match primary {
        Some(p) => {
            let points = plot_points(rows, p, vary, &pareto);
            let name = args.file.file_name().map_or_else(
                || args.file.display().to_string(),
                |n| n.to_string_lossy().into(),
            );
            plot::write_plot(
                &out.join("sweep.png"),
                &format!("imprint sweep {name}: time against error"),
                &p.describe(),
                &points,
            )?;
        }
        None => outln!(
            "no node with an error metric (DistanceField, Cloth, Heightmap) ran: sweep.png not \
             written"
        ),
    }
    out!("{md}");
    outln!(
        "wrote {}, {}, {} and {}",
        out.join("sweep.csv").display(),
        out.join("sweep.md").display(),
        out.join("sweep.png").display(),
        out.join("sweep_frames.csv").display()
    );
    let failed: Vec<&str> = rows
        .iter()
        .filter(|r| r.timing.is_none())
        .map(|r| r.id.as_str())
        .collect();
    if !failed.is_empty() {
        return Err(imprint_core::Error::Run(format!(
            "{} of {} settings failed (setting {}); the status column says why",
            failed.len(),
            setup.combos.len(),
            failed.join(", ")
        ))
        .into());
    }
    Ok(())
}

/// A setting for people: its overrides, or `empty` when there are none.
fn label(overrides: &[String], empty: &str) -> String {
    if overrides.is_empty() {
        empty.to_string()
    } else {
        overrides.join(" ")
    }
}

/// One line per finished setting.
fn summary(row: &Row) -> String {
    let Some(t) = &row.timing else {
        return row.status.clone();
    };
    let mut s = format!("{:.2} ms/frame", t.mean_ms());
    for node in row.errors.keys() {
        if let Some([_, rms, max]) = row.error(node) {
            s += &format!(", {node} error rms {rms:.4} max {max:.4}");
        }
    }
    s
}

/// The bar over settings (hidden when stderr is not a terminal).
fn progress_bar(len: u64) -> ProgressBar {
    if !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    }
    ProgressBar::new(len).with_style(
        ProgressStyle::with_template(
            "{spinner} setting {pos}/{len} [{bar:30}] {elapsed} ETA {eta}  {msg}",
        )
        .expect("valid template")
        .progress_chars("=> "),
    )
}

/// A line on stdout, above the bar (`ProgressBar::println` says nothing when it is hidden).
fn say(bar: &ProgressBar, line: String) {
    bar.suspend(|| outln!("{line}"));
}

/// Shows the setting and its frame on the bar.
fn frame_progress<'a>(bar: &'a ProgressBar, what: &'a str) -> impl FnMut(u32, u32) + 'a {
    move |done, total| bar.set_message(format!("{what}: frame {done}/{total}"))
}

/// Which rows are on the Pareto front of (mean frame time, primary error).
fn pareto_of(rows: &[Row], primary: Option<&Primary>) -> Vec<bool> {
    let Some(p) = primary else {
        return vec![false; rows.len()];
    };
    let pts: Vec<Option<(f64, f64)>> = rows
        .iter()
        .map(|r| Some((r.timing.as_ref()?.mean_ms(), r.error(&p.node)?[p.stat])))
        .collect();
    let valid: Vec<(f64, f64)> = pts.iter().flatten().copied().collect();
    let mut front = plot::pareto_front(&valid).into_iter();
    pts.iter()
        .map(|p| p.is_some() && front.next().unwrap_or(false))
        .collect()
}

/// A point's label on the plot: the varied values, by field name where that is unambiguous.
fn plot_points(rows: &[Row], p: &Primary, vary: &[Vary], pareto: &[bool]) -> Vec<plot::Point> {
    let short = |path: &str| {
        let last = path.rsplit('.').next().unwrap_or(path);
        let unique = vary
            .iter()
            .filter(|v| v.path.ends_with(&format!(".{last}")))
            .count()
            == 1;
        if unique {
            last.to_string()
        } else {
            path.to_string()
        }
    };
    rows.iter()
        .zip(pareto)
        .filter_map(|(r, &on_front)| {
            let error = r.error(&p.node)?[p.stat];
            let label = if r.id == "ref" {
                "reference".to_string()
            } else {
                r.overrides
                    .iter()
                    .map(|o| {
                        let (path, value) = o.split_once('=').unwrap_or((o, ""));
                        format!("{}={value}", short(path))
                    })
                    .collect::<Vec<_>>()
                    .join(" ")
            };
            Some(plot::Point {
                time_ms: r.timing.as_ref()?.mean_ms(),
                error,
                label,
                reference: r.id == "ref",
                pareto: on_front,
            })
        })
        .collect()
}

/// A table cell: numbers are formatted per output (CSV: exact; Markdown: short).
enum Cell {
    Text(String),
    Ms(f64),
    Count(u64),
    Error(f64),
    Empty,
}

struct Table {
    headers: Vec<String>,
    rows: Vec<Vec<Cell>>,
}

/// Records as CSV text through the `csv` crate: `\n` line ends, a field quoted only when it
/// holds a comma, a quote or a newline (quotes inside doubled), as RFC 4180 readers expect.
fn csv_text<R, F>(records: impl IntoIterator<Item = R>) -> String
where
    R: IntoIterator<Item = F>,
    F: AsRef<[u8]>,
{
    let mut w = csv::WriterBuilder::new()
        .terminator(csv::Terminator::Any(b'\n'))
        .quote_style(csv::QuoteStyle::Necessary)
        .from_writer(Vec::new());
    for record in records {
        // Writing into memory fails only on a record of a different length: a bug here.
        w.write_record(record).expect("CSV records of one length");
    }
    let bytes = w.into_inner().expect("CSV written to memory");
    String::from_utf8(bytes).expect("CSV of UTF-8 fields is UTF-8")
}

/// About four significant digits.
fn short_number(v: f64) -> String {
    if v == 0.0 {
        "0".into()
    } else if (1e-3..1e4).contains(&v.abs()) {
        let decimals = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        format!("{v:.3e}")
    }
}

impl Table {
    fn csv(&self) -> String {
        let body = self.rows.iter().map(|row| {
            row.iter()
                .map(|c| match c {
                    Cell::Text(t) => t.clone(),
                    Cell::Ms(v) => format!("{v:.3}"),
                    Cell::Count(n) => n.to_string(),
                    Cell::Error(v) => format!("{v:.6e}"),
                    Cell::Empty => String::new(),
                })
                .collect::<Vec<String>>()
        });
        csv_text(std::iter::once(self.headers.clone()).chain(body))
    }

    fn markdown(&self) -> String {
        let mut s = format!("| {} |\n", self.headers.join(" | "));
        s += &format!("|{}\n", "---|".repeat(self.headers.len()));
        for row in &self.rows {
            let cells: Vec<String> = row
                .iter()
                .map(|c| match c {
                    Cell::Text(t) => t.replace('|', "\\|").replace('\n', " "),
                    Cell::Ms(v) => format!("{v:.2}"),
                    Cell::Count(n) => n.to_string(),
                    Cell::Error(v) => short_number(*v),
                    Cell::Empty => String::new(),
                })
                .collect();
            s += &format!("| {} |\n", cells.join(" | "));
        }
        s
    }
}

/// The rows of `sweep.csv` / `sweep.md`.
fn results_table(
    rows: &[Row],
    vary: &[Vary],
    reference: &Reference,
    ref_plan: &Plan,
    pareto: &[bool],
) -> Table {
    // Nodes timed: the reference's, then any only a setting ran, in the order first seen.
    let mut nodes: Vec<String> = Vec::new();
    for t in rows.iter().filter_map(|r| r.timing.as_ref()) {
        for (n, ..) in &t.nodes {
            if !nodes.contains(n) {
                nodes.push(n.clone());
            }
        }
    }
    let mut tracks: Vec<(&str, TrackKind)> = reference
        .tracks
        .iter()
        .map(|t| (t.node.as_str(), t.kind))
        .collect();
    tracks.sort_by_key(|(n, _)| ref_plan.order.iter().position(|o| o == n));
    let mut headers = vec!["setting".to_string()];
    headers.extend(vary.iter().map(|v| v.path.clone()));
    headers.extend(["status", "frame_ms_mean", "frame_ms_p95", "frame_ms_max"].map(String::from));
    for n in &nodes {
        headers.push(format!("{n}_ms_per_frame"));
        headers.push(format!("{n}_runs"));
    }
    for (n, kind) in &tracks {
        for stat in STATS {
            headers.push(stat_column(n, *kind, stat));
        }
    }
    headers.push("pareto".into());

    let body = rows
        .iter()
        .zip(pareto)
        .map(|(r, &on_front)| {
            let mut cells = vec![Cell::Text(r.id.clone())];
            for v in vary {
                let prefix = format!("{}=", v.path);
                cells.push(
                    r.overrides
                        .iter()
                        .find_map(|o| o.strip_prefix(&prefix))
                        .map_or(Cell::Empty, |value| Cell::Text(value.to_string())),
                );
            }
            cells.push(Cell::Text(r.status.clone()));
            match &r.timing {
                Some(t) => {
                    cells.extend([t.mean_ms(), t.p95_ms(), t.max_ms()].map(Cell::Ms));
                    let per_frame = t.frame_ms.len().max(1) as f64;
                    for n in &nodes {
                        match t.nodes.iter().find(|(m, ..)| m == n) {
                            Some((_, runs, total)) => {
                                cells.push(Cell::Ms(total / per_frame));
                                cells.push(Cell::Count(u64::from(*runs)));
                            }
                            None => cells.extend([Cell::Empty, Cell::Empty]),
                        }
                    }
                }
                None => cells.extend((0..3 + 2 * nodes.len()).map(|_| Cell::Empty)),
            }
            for (n, _) in &tracks {
                match r.error(n) {
                    Some(stats) => cells.extend(stats.map(Cell::Error)),
                    None => cells.extend((0..3).map(|_| Cell::Empty)),
                }
            }
            cells.push(Cell::Text(if on_front { "yes" } else { "" }.into()));
            cells
        })
        .collect();
    Table {
        headers,
        rows: body,
    }
}

/// `sweep_frames.csv`: every setting's error per node per frame.
fn frames_csv(rows: &[Row]) -> String {
    let header = ["setting", "node", "frame", "probes", "mean", "rms", "max"].map(String::from);
    let body = rows.iter().flat_map(|r| {
        r.errors.iter().flat_map(move |(node, frames)| {
            frames.iter().map(move |f| {
                let stats = f.stats().map_or_else(
                    || [(); 3].map(|_| String::new()),
                    |v| v.map(|x| format!("{x:.6e}")),
                );
                let mut record = vec![
                    r.id.clone(),
                    node.clone(),
                    f.frame.to_string(),
                    f.n.to_string(),
                ];
                record.extend(stats);
                record
            })
        })
    });
    csv_text(std::iter::once(header.to_vec()).chain(body))
}

fn markdown(
    args: &SweepArgs,
    ref_overrides: &[String],
    frames: &Range<u32>,
    primary: Option<&Primary>,
    table: &Table,
) -> String {
    let mut s = format!("# imprint sweep: {}\n\n", args.file.display());
    s += &format!(
        "- frames {}..{}{}\n",
        frames.start,
        frames.end,
        args.backend
            .map_or_else(String::new, |b| format!(", backend {:?}", Backend::from(b)))
    );
    if !args.sets.is_empty() {
        s += &format!("- every run: `--set {}`\n", args.sets.join(" --set "));
    }
    s += &format!(
        "- reference (row `ref`): {}\n",
        label(ref_overrides, "the file as it is")
    );
    if let Some(p) = primary {
        s += &format!(
            "- plotted error (`sweep.png`, `pareto`): {} (`{}`)\n",
            p.describe(),
            p.column()
        );
    }
    s += "- errors: fields in reference cells at probe points in the reference's band; cloth \
          and height fields in world units; mean, RMS and max over all frames \
          (`sweep_frames.csv`: per frame)\n\n";
    s + &table.markdown()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_split_at_top_level_commas_only() {
        assert_eq!(
            split_top_level(r#"1, (2, 3),"a,\"b",[4,5]"#),
            ["1", "(2, 3)", r#""a,\"b""#, "[4,5]"]
        );
    }

    #[test]
    fn vary_parses_and_refuses_what_it_cannot_use() {
        let v = parse_vary("--vary", "vox.grid.resolution=16,24").unwrap();
        assert_eq!(v.path, "vox.grid.resolution");
        assert_eq!(v.values, ["16", "24"]);
        for bad in [
            "field",
            "field=1,2",
            ".band=1",
            "field.=1",
            "field.band=1,,2",
            "a.b=1,1",
        ] {
            let e = parse_vary("--vary", bad).unwrap_err();
            assert_eq!(e.exit_code(), 2, "{bad}");
            assert!(e.to_string().contains(bad), "{bad}: {e}");
        }
    }

    #[test]
    fn combinations_follow_the_order_given() {
        let v = [
            Vary {
                path: "a.x".into(),
                values: vec!["1".into(), "2".into()],
            },
            Vary {
                path: "b.y".into(),
                values: vec!["p".into(), "q".into(), "r".into()],
            },
        ];
        let c = combinations(&v);
        assert_eq!(c.len(), 6);
        assert_eq!(c[0], ["a.x=1", "b.y=p"]);
        assert_eq!(c[1], ["a.x=1", "b.y=q"]);
        assert_eq!(c[5], ["a.x=2", "b.y=r"]);
    }

    #[test]
    fn numbers_and_text_are_escaped_per_format() {
        assert_eq!(
            csv_text([["(1, 2)", "a\"b", "plain", ""]]),
            "\"(1, 2)\",\"a\"\"b\",plain,\n"
        );
        assert_eq!(short_number(0.0123456), "0.01235");
        assert_eq!(short_number(123.456), "123.5");
        assert_eq!(short_number(1.5e-6), "1.500e-6");
    }

    #[test]
    fn csv_fields_with_commas_quotes_and_newlines_round_trip() {
        let records = vec![
            vec![
                "setting".to_string(),
                "cloth.params.offsets".into(),
                "status".into(),
            ],
            vec!["s1".into(), "(1, 2)".into(), "ok".into()],
            vec!["s2".into(), "say \"hi\", then\nleave".into(), String::new()],
        ];
        let text = csv_text(records.clone());
        assert!(text.ends_with('\n') && !text.contains('\r'));
        let mut reader = csv::ReaderBuilder::new()
            .has_headers(false)
            .from_reader(text.as_bytes());
        let back: Vec<Vec<String>> = reader
            .records()
            .map(|r| r.unwrap().iter().map(String::from).collect())
            .collect();
        assert_eq!(back, records);
    }
}
