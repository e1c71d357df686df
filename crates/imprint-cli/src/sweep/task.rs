//! One task of a sweep on a farm (`imprint sweep … --task ID`, as `imprint farm` writes it),
//! and the gathering of all of them (`imprint farm collect`).
//!
//! Task `ref` runs the reference into its cache (`DIR/reference/<key>/`); task `N` runs
//! setting N into `DIR/runs/N/`, compared with the cached reference, and writes its row as
//! `DIR/runs/N/row.json`. A task keeps a checkpoint every `--checkpoint-every` frames with
//! what it measured so far, and a retry resumes from it: the row is the one an uninterrupted
//! task writes (its timing columns aside). Gathering reads the rows back and writes the same
//! files `imprint sweep` writes on one machine.

use super::measure::Reference;
use super::{Row, Setup, SweepArgs, reference_row, run_reference, run_setting, summary};
use imprint_core::io::atomic_write_bytes;
use imprint_graph::Result;
use imprint_graph::exec::RunOptions;
use imprint_graph::executor::checkpoint_path;
use indicatif::ProgressBar;
use std::path::PathBuf;

/// The file a setting's task writes its row to.
pub(crate) const ROW_FILE: &str = "row.json";

/// Runs task `id` (`ref` or a setting's number) of the sweep `setup`.
pub(crate) fn run(args: &SweepArgs, setup: &Setup, id: &str) -> Result<()> {
    let bar = ProgressBar::hidden();
    if id == "ref" {
        if let Ok(Some(_)) = setup.cache.load() {
            outln!(
                "reference: already complete in {}",
                setup.cache.dir.display()
            );
            return Ok(());
        }
        let opts = resumable(setup.opts(setup.cache.dir.join("run")), args);
        run_reference(setup, opts, &bar)?;
        outln!("reference: cached in {}", setup.cache.dir.display());
        return Ok(());
    }
    let i = setting_index(setup, id)?;
    let reference = cached_reference(setup)?;
    let ids = setup.ids();
    let dir = row_dir(args, &ids[i]);
    let row = run_setting(
        setup,
        &reference,
        i,
        ids[i].clone(),
        resumable(setup.opts(dir.clone()), args),
        &bar,
    );
    let json = serde_json::to_string_pretty(&row).expect("a row is plain data");
    atomic_write_bytes(&dir.join(ROW_FILE), json.as_bytes())?;
    outln!("setting {}: {}", row.id, summary(&row));
    match row.timing {
        Some(_) => Ok(()),
        None => Err(imprint_core::Error::Run(format!("setting {}: {}", row.id, row.status)).into()),
    }
}

/// Checkpoints every `--checkpoint-every` frames, resuming from one an earlier try left.
fn resumable(mut opts: RunOptions, args: &SweepArgs) -> RunOptions {
    opts.checkpoint_every = args.checkpoint_every.max(1);
    opts.resume = checkpoint_path(&opts.out).is_file();
    opts.stop = Some(crate::stop_on_signal());
    opts
}

/// Setting `id`'s index: its number from 1 (`3` and `03` alike).
fn setting_index(setup: &Setup, id: &str) -> Result<usize> {
    let n = setup.combos.len();
    match id.parse::<usize>() {
        Ok(k) if (1..=n).contains(&k) => Ok(k - 1),
        _ => Err(imprint_core::Error::Invalid(format!(
            "--task {id}: expected `ref` or a setting's number, 1 to {n}"
        ))
        .into()),
    }
}

/// The reference from its cache; an error when task `ref` has not completed.
fn cached_reference(setup: &Setup) -> Result<Reference> {
    match setup.cache.load() {
        Ok(Some(r)) => Ok(r),
        Ok(None) => Err(imprint_core::Error::Run(format!(
            "the reference has not been run: {} is missing (task `ref` runs first)",
            setup.cache.dir.join("reference.json").display()
        ))
        .into()),
        Err(why) => Err(imprint_core::Error::Run(format!(
            "the reference's cache cannot be used: {why}"
        ))
        .into()),
    }
}

fn row_dir(args: &SweepArgs, id: &str) -> PathBuf {
    args.out.join("runs").join(id)
}

/// What gathering found of one task of a farm job.
#[derive(Clone, Debug, PartialEq)]
pub(crate) enum TaskStatus {
    Done,
    /// It ran to its end and failed: why.
    Failed(String),
    /// It has not run, or did not finish: what is missing.
    Missing(String),
}

/// Every task's id and state, the reference's first.
pub(crate) type TaskStates = Vec<(String, TaskStatus)>;

/// The state of every task of the sweep and, when every one ran, the rows to write (the
/// reference's first).
pub(crate) fn collect(
    args: &SweepArgs,
    setup: &Setup,
) -> (TaskStates, Option<(Reference, Vec<Row>)>) {
    let reference = cached_reference(setup);
    let mut states = vec![(
        "ref".to_string(),
        match &reference {
            Ok(_) => TaskStatus::Done,
            Err(e) => TaskStatus::Missing(e.to_string()),
        },
    )];
    let mut rows = Vec::new();
    for id in setup.ids() {
        let path = row_dir(args, &id).join(ROW_FILE);
        let row = std::fs::read_to_string(&path)
            .map_err(|e| format!("no {} ({e})", path.display()))
            .and_then(|text| {
                serde_json::from_str::<Row>(&text)
                    .map_err(|e| format!("{} does not read ({e})", path.display()))
            });
        match row {
            Ok(row) => {
                let state = match &row.timing {
                    Some(_) => TaskStatus::Done,
                    None => TaskStatus::Failed(row.status.clone()),
                };
                states.push((id, state));
                rows.push(row);
            }
            Err(why) => states.push((id, TaskStatus::Missing(why))),
        }
    }
    match reference {
        Ok(r) if rows.len() == setup.combos.len() => {
            let mut all = vec![reference_row(setup, &r)];
            all.extend(rows);
            (states, Some((r, all)))
        }
        _ => (states, None),
    }
}

/// Writes the sweep's files from gathered rows ([`collect`]).
pub(crate) fn write(
    args: &SweepArgs,
    setup: &Setup,
    reference: &Reference,
    rows: &[Row],
) -> Result<()> {
    super::write_results(args, setup, reference, rows)
}
