//! The Open Job Description job: `DIR/openjd/job.json`, a job template (specification
//! `jobtemplate-2023-09`) that `openjd check` validates, `openjd run` runs on this machine,
//! and a farm that takes OpenJD (AWS Deadline Cloud…) runs on its workers.
//!
//! Steps: a sweep is `reference`, then `settings` (an INT task parameter, one task per
//! setting); independent chunks are one step `chunks`; chained chunks are a step per chunk,
//! each depending on the one before. Every job ends with `collect`, depending on the rest.
//! Each step runs an embedded bash script holding the task's command.

use super::{Job, Kind, Task, shell_words, task_case, task_lines};
use imprint_core::io::atomic_write_bytes;
use imprint_graph::Result;
use serde_json::{Value, json};
use std::path::PathBuf;

/// The template's path.
pub fn template(job: &Job) -> PathBuf {
    job.out.join("openjd").join("job.json")
}

/// Writes the template.
pub fn write(job: &Job) -> Result<Vec<PathBuf>> {
    let text = serde_json::to_string_pretty(&job_template(job)).expect("plain data") + "\n";
    let path = template(job);
    atomic_write_bytes(&path, text.as_bytes())?;
    Ok(vec![path])
}

/// `openjd run` arguments that run the whole job here (the collect step and what it
/// depends on).
pub fn run_args(job: &Job) -> Vec<String> {
    vec![
        "run".into(),
        template(job).display().to_string(),
        "--step".into(),
        "collect".into(),
        "--run-dependencies".into(),
    ]
}

/// How to run the job here, for people.
pub fn run_hint(job: &Job) -> String {
    format!(
        "{} (here), or submit {} to a farm that runs OpenJD",
        shell_words(&[vec!["openjd".to_string()], run_args(job)].concat()),
        template(job).display()
    )
}

fn job_template(job: &Job) -> Value {
    let stem = job.stem();
    let mut steps = Vec::new();
    let mut last_steps: Vec<String> = Vec::new();
    match job.kind {
        Kind::Sweep => {
            steps.push(one_task_step("reference", &job.tasks[0], &[]));
            let settings: Vec<(usize, &Task)> = job.tasks.iter().enumerate().skip(1).collect();
            if !settings.is_empty() {
                steps.push(many_task_step(
                    "settings",
                    "Setting",
                    &settings,
                    &["reference".into()],
                ));
                last_steps.push("settings".into());
            } else {
                last_steps.push("reference".into());
            }
        }
        Kind::Chunks => {
            let all: Vec<(usize, &Task)> = job.tasks.iter().enumerate().collect();
            steps.push(many_task_step("chunks", "Chunk", &all, &[]));
            last_steps.push("chunks".into());
        }
        Kind::Chain => {
            let mut prev: Vec<String> = Vec::new();
            for t in &job.tasks {
                steps.push(one_task_step(&t.id, t, &prev));
                prev = vec![t.id.clone()];
            }
            last_steps = prev;
        }
    }
    let collect = format!(
        "#!/bin/bash\nset -euo pipefail\nexec {}\n",
        shell_words(&job.collect_argv())
    );
    steps.push(step("collect", script(&collect), &last_steps, None));
    json!({
        "specificationVersion": "jobtemplate-2023-09",
        "name": format!("imprint {stem}"),
        "description": format!(
            "imprint farm: {} (written by imprint {})",
            job.pipeline.display(),
            job.imprint_version
        ),
        "steps": steps,
    })
}

fn one_task_step(name: &str, task: &Task, after: &[String]) -> Value {
    let text = format!("#!/bin/bash\nset -euo pipefail\n{}", task_lines(task));
    step(name, script(&text), after, None)
}

/// A step of several tasks: an INT task parameter `param` over the tasks' indices.
fn many_task_step(name: &str, param: &str, tasks: &[(usize, &Task)], after: &[String]) -> Value {
    let text = format!("#!/bin/bash\nset -euo pipefail\n{}", task_case(tasks, "$1"));
    let values: Vec<usize> = tasks.iter().map(|(i, _)| *i).collect();
    let space = json!({
        "taskParameterDefinitions": [{
            "name": param,
            "type": "INT",
            "range": values,
        }]
    });
    let mut s = script(&text);
    s["actions"]["onRun"]["args"]
        .as_array_mut()
        .expect("args is a list")
        .push(json!(format!("{{{{Task.Param.{param}}}}}")));
    step(name, s, after, Some(space))
}

/// An embedded bash script run by the step's action.
fn script(text: &str) -> Value {
    json!({
        "actions": {
            "onRun": {
                "command": "bash",
                "args": ["{{Task.File.Run}}"],
            }
        },
        "embeddedFiles": [{
            "name": "Run",
            "type": "TEXT",
            "data": text,
        }]
    })
}

fn step(name: &str, script: Value, after: &[String], space: Option<Value>) -> Value {
    let mut s = json!({ "name": name, "script": script });
    if !after.is_empty() {
        s["dependencies"] = after.iter().map(|a| json!({ "dependsOn": a })).collect();
    }
    if let Some(space) = space {
        s["parameterSpace"] = space;
    }
    s
}
