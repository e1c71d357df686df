//! From text to a checked plan: parse, check every edge and value, find assets, prune.

use crate::diagnostics::{Source, ron_error};
use crate::node::CheckCtx;
use crate::schema::{PipelineFile, PortType};
use crate::{Error, Result};
use petgraph::algo::{kosaraju_scc, toposort};
use petgraph::graph::{DiGraph, NodeIndex};
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A validated pipeline, ready to run.
#[derive(Clone, Debug)]
pub struct Plan {
    pub source: Source,
    pub file: PipelineFile,
    /// Relative paths in the file (meshes) are resolved against this folder: the file's own.
    pub base_dir: PathBuf,
    /// Nodes that run, in dependency order.
    pub order: Vec<String>,
    /// Every node of the file, in dependency order.
    pub topo: Vec<String>,
    /// Nodes that do not run, with the reason.
    pub pruned: Vec<(String, String)>,
    /// What would run were every writer switched on, writers included, in dependency order:
    /// a live view runs these (less the writers), showing what the file's writers would
    /// write whether or not they are on. Nodes switched off themselves are not among them.
    pub producers: Vec<String>,
    /// What the user should know before running (a writer that lost its input…).
    pub warnings: Vec<String>,
    /// The `--set` overrides applied to the file, as given (the report states them).
    pub overrides: Vec<String>,
}

/// Reads, overrides (`NODE.FIELD=VALUE`) and validates a pipeline file.
///
/// The file is parsed first (its errors located in it); each override is then applied to the
/// parsed value ([`crate::overrides::apply`]: its errors name the `--set` argument), and the
/// nodes are checked. A check that fails only because of an override says so, naming it,
/// rather than pointing at the file's text, which does not hold the value. The plan's
/// [`Source`] text describes what runs (see `described`).
pub fn load(path: &Path, overrides: &[String]) -> Result<Plan> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        imprint_core::Error::Invalid(format!("cannot read pipeline file {}: {e}", path.display()))
    })?;
    let base_dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    let source = Source {
        name: path.display().to_string(),
        text,
    };
    if overrides.is_empty() {
        return parse(source, &base_dir);
    }
    let file = read_file(&source)?;
    let edited = crate::overrides::apply(&file, overrides)?;
    let mut plan = checked(source.clone(), edited, &base_dir).map_err(|e| {
        // The file's own error (it fails without the overrides too) stays located in it.
        match checked(source.clone(), file, &base_dir) {
            Err(own) if own.to_string() == e.to_string() => own,
            _ => from_overrides(&e, overrides),
        }
    })?;
    plan.source.text = described(&source.text, overrides);
    plan.overrides = overrides.to_vec();
    Ok(plan)
}

/// The text of what runs: the file with the overrides written into it (as the viewer writes
/// its live edits back), so that it equals the file once they are; where a text edit cannot
/// express one, the file with the overrides noted after it as comments. Plans are told apart
/// by it (the viewer's reload, the sweep's cached reference).
fn described(text: &str, overrides: &[String]) -> String {
    overrides
        .iter()
        .try_fold(text.to_string(), |t, o| {
            crate::overrides::apply_override(&t, o)
        })
        .unwrap_or_else(|_| {
            let mut noted = text.to_string();
            if !noted.ends_with('\n') {
                noted.push('\n');
            }
            for o in overrides {
                noted += &format!("// --set {}\n", o.replace('\n', " "));
            }
            noted
        })
}

/// A check's error caused by `overrides`: named by the ones of its node (all, when it names
/// none of theirs), with the check's message and hint and no position in the file.
fn from_overrides(e: &Error, overrides: &[String]) -> Error {
    let (message, help) = match e {
        Error::Pipeline(p) => (p.message.clone(), p.help.clone()),
        Error::Core(c) => (c.to_string(), None),
    };
    let node_of = |o: &String| o.split(['.', '=']).next().unwrap_or("").trim().to_string();
    let mine: Vec<&String> = overrides
        .iter()
        .filter(|o| message.contains(&format!("node '{}'", node_of(o))))
        .collect();
    let named: Vec<&String> = if mine.is_empty() {
        overrides.iter().collect()
    } else {
        mine
    };
    let sets: Vec<String> = named.iter().map(|o| format!("--set {o}")).collect();
    let mut text = format!("{}: {message}", sets.join(" "));
    if let Some(h) = help {
        text += &format!(" (help: {h})");
    }
    imprint_core::Error::Invalid(text).into()
}

/// Validates pipeline text (`source.name` is used in messages).
pub fn parse(source: Source, base_dir: &Path) -> Result<Plan> {
    let file = read_file(&source)?;
    checked(source, file, base_dir)
}

/// Checks a parsed file (`source` is where its errors are located) into a plan.
fn checked(source: Source, file: PipelineFile, base_dir: &Path) -> Result<Plan> {
    let (graph, order) = typed_graph(&source, &file)?;
    let mut warnings = check_nodes(&source, &file, base_dir)?;
    let topo: Vec<String> = order.iter().map(|&n| graph[n].to_string()).collect();
    let pruning = prune(&file, &graph, &order);
    warnings.extend(pruning.warnings);
    Ok(Plan {
        source,
        file,
        base_dir: base_dir.to_path_buf(),
        order: pruning.run_order,
        topo,
        pruned: pruning.pruned,
        producers: pruning.producers,
        warnings,
        overrides: Vec::new(),
    })
}

/// The file's RON and its run-wide values.
fn read_file(source: &Source) -> Result<PipelineFile> {
    let file = from_ron(&source.text).map_err(|e| {
        let mut err = ron_error(source, &e);
        if e.code == ron::Error::IntegerOutOfBounds
            && let Some(said) = integer_bounds(
                &source.text,
                source.offset(e.span.start.line, e.span.start.col),
            )
        {
            err.message = said;
        }
        err
    })?;
    let whole = 0..source.text.len().min(8);
    let fail = |msg: String| -> Error { source.error(whole.clone(), msg, "here", None).into() };
    if file.frames == 0 {
        return Err(fail("frames must be at least 1".into()));
    }
    if !(file.fps.is_finite() && file.fps > 0.0) {
        return Err(fail(format!(
            "fps must be a finite number > 0, got {}",
            file.fps
        )));
    }
    if file.nodes.is_empty() {
        return Err(fail("the pipeline has no nodes".into()));
    }
    Ok(file)
}

fn from_ron(text: &str) -> std::result::Result<PipelineFile, ron::error::SpannedError> {
    ron::Options::default()
        .with_default_extension(
            ron::extensions::Extensions::IMPLICIT_SOME
                | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
        )
        .from_str(text)
}

/// For RON's "Integer is out of bounds" at byte `at` (in the number): the range of the field's
/// integer type, found by putting other numbers in its place (`-1` fits no unsigned type,
/// `256` no `u8`…), and what is wrong with the number: "expected an unsigned integer
/// 0..=4294967295: substeps cannot be negative".
fn integer_bounds(text: &str, at: usize) -> Option<String> {
    let is_num = |c: char| c.is_ascii_alphanumeric() || c == '_' || c == '.';
    let start = text[..at]
        .char_indices()
        .rev()
        .find(|&(_, c)| !is_num(c))
        .map_or(0, |(i, c)| i + c.len_utf8());
    let start = if text[..start].ends_with(['-', '+']) {
        start - 1
    } else {
        start
    };
    let end = text[at..]
        .find(|c: char| !is_num(c))
        .map_or(text.len(), |n| at + n);
    let number = &text[start..end];
    let out_of_bounds = |probe: &str| {
        let edited = format!("{}{probe}{}", &text[..start], &text[end..]);
        from_ron(&edited).is_err_and(|e| {
            let here = Source {
                name: String::new(),
                text: edited.clone(),
            }
            .offset(e.span.start.line, e.span.start.col);
            e.code == ron::Error::IntegerOutOfBounds && (start..=start + 1).contains(&here)
        })
    };
    let signed = !out_of_bounds("-1");
    let ty = [8u32, 16, 32, 64].into_iter().find_map(|bits| {
        let first_outside = if signed {
            1u128 << (bits - 1)
        } else {
            1u128 << bits
        };
        out_of_bounds(&first_outside.to_string())
            .then(|| format!("{}{bits}", if signed { 'i' } else { 'u' }))
    })?;
    // The field: the name before `:`, if the number is a field's value.
    let before = text[..start].trim_end();
    let field = before
        .strip_suffix(':')
        .map(str::trim_end)
        .and_then(|b| {
            let from = b
                .char_indices()
                .rev()
                .find(|&(_, c)| !(c.is_alphanumeric() || c == '_'))
                .map_or(0, |(i, c)| i + c.len_utf8());
            (from < b.len()).then(|| &b[from..])
        })
        .unwrap_or("the value");
    Some(format!(
        "{}: {}",
        crate::overrides::int_range(&ty)?,
        crate::overrides::out_of_range(field, number, signed)
    ))
}

/// The graph of every input edge (each names a node of the file) and the nodes in
/// dependency order (the graph has no cycle).
fn typed_graph<'a>(
    source: &Source,
    file: &'a PipelineFile,
) -> Result<(DiGraph<&'a str, ()>, Vec<NodeIndex>)> {
    let names: Vec<&String> = file.nodes.keys().collect();
    let mut graph = DiGraph::<&str, ()>::new();
    let idx: BTreeMap<&str, NodeIndex> = names
        .iter()
        .map(|n| (n.as_str(), graph.add_node(n.as_str())))
        .collect();
    for (name, node) in &file.nodes {
        for p in node.inputs() {
            let (port, input) = (p.port, p.node);
            if !file.nodes.contains_key(input) {
                let help = closest_name(input, &names).map_or_else(
                    || format!("nodes in this file: {}", join(&names)),
                    |c| format!("did you mean '{c}'?"),
                );
                return Err(source
                    .error(
                        source.field_span(name, port),
                        format!(
                            "node '{name}': input '{port}' names '{input}', which is not a node"
                        ),
                        "no such node",
                        Some(help),
                    )
                    .into());
            }
            graph.add_edge(idx[input], idx[name.as_str()], ());
        }
    }
    let order = toposort(&graph, None).map_err(|cycle| {
        let start = graph[cycle.node_id()];
        let members = kosaraju_scc(&graph)
            .into_iter()
            .find(|scc| scc.contains(&cycle.node_id()))
            .unwrap_or_default();
        let mut in_cycle: Vec<&str> = members.iter().map(|&i| graph[i]).collect();
        in_cycle.sort();
        Error::from(source.error(
            source.node_span(start),
            format!(
                "the graph has a cycle through nodes: {}",
                in_cycle.join(" -> ")
            ),
            "part of a cycle",
            Some("a node cannot depend on its own output; remove one of these inputs".into()),
        ))
    })?;
    Ok((graph, order))
}

/// Every edge's type, every node's values (its module's checks) and schedule; returns what
/// the nodes warn about.
fn check_nodes(source: &Source, file: &PipelineFile, base_dir: &Path) -> Result<Vec<String>> {
    let lookup = |n: &str| file.nodes.get(n).map(|s| s.node());
    let mut warnings = Vec::new();
    for (name, node) in &file.nodes {
        for p in node.inputs() {
            let (port, input, expected) = (p.port, p.node, p.ty);
            let producer = &file.nodes[input];
            if producer.output() != Some(expected) {
                let what = producer
                    .output()
                    .map_or("nothing (it is a writer)".to_string(), |t| format!("a {t}"));
                return Err(source
                    .error(
                        source.field_span(name, port),
                        format!(
                            "node '{name}': input '{port}' expects a {expected}, but '{input}' ({}) produces {what}",
                            producer.kind()
                        ),
                        format!("expects a {expected}"),
                        Some(producers_of(expected, file)),
                    )
                    .into());
            }
        }
        let ctx = CheckCtx {
            source,
            name,
            base_dir,
            fps: file.fps,
            frames: file.frames,
            lookup: &lookup,
        };
        node.node().check(&ctx)?;
        check_schedule(source, name, file)?;
        let said = node.node().warnings(&ctx);
        warnings.extend(said.into_iter().map(|w| format!("node '{name}': {w}")));
    }
    Ok(warnings)
}

/// What a plan's pruning decided.
struct Pruning {
    /// What runs, in dependency order.
    run_order: Vec<String>,
    /// What does not, and why.
    pruned: Vec<(String, String)>,
    warnings: Vec<String>,
    /// What would run were every writer switched on (see [`Plan::producers`]).
    producers: Vec<String>,
}

/// What runs (in dependency order), what is pruned and why, and what to warn about: nodes
/// that reach no writer that is switched on, nodes switched off (and what reads them), and
/// the mesh and boundary read ahead of time by an interpolated field only.
fn prune(file: &PipelineFile, graph: &DiGraph<&str, ()>, order: &[NodeIndex]) -> Pruning {
    let (off, warnings) = switched_off(file, graph, order);
    let writers: Vec<NodeIndex> = graph
        .node_indices()
        .filter(|&i| file.nodes[graph[i]].is_writer())
        .collect();
    let live: Vec<NodeIndex> = writers
        .iter()
        .copied()
        .filter(|w| !off.contains_key(w))
        .collect();
    let needed = upstream(graph, &live);
    let wanted = upstream(graph, &writers);
    let runs_from = |set: &BTreeSet<NodeIndex>| {
        let ahead = read_ahead(file, graph, order, |m| {
            set.contains(m) && !off.contains_key(m)
        });
        let runs: Vec<NodeIndex> = order
            .iter()
            .copied()
            .filter(|n| set.contains(n) && !off.contains_key(n) && !ahead.contains_key(n))
            .collect();
        (runs, ahead)
    };
    let (runs, ahead) = runs_from(&needed);
    let name = |n: &NodeIndex| graph[*n].to_string();
    let mut pruned = Vec::new();
    for n in order.iter().filter(|n| !runs.contains(n)) {
        let why = if let Some(why) = off.get(n) {
            why.clone()
        } else if let Some(field) = ahead.get(n) {
            format!("only '{field}' reads it, building ahead of time (interpolate)")
        } else if wanted.contains(n) {
            "it feeds only writers that are switched off (enabled: false)".to_string()
        } else if writers.is_empty() {
            "the pipeline has no writer, so nothing would be kept".to_string()
        } else {
            "its output reaches no writer".to_string()
        };
        pruned.push((name(n), why));
    }
    Pruning {
        run_order: runs.iter().map(name).collect(),
        pruned,
        warnings,
        producers: runs_from(&wanted).0.iter().map(name).collect(),
    }
}

/// `from` and every node upstream of them.
fn upstream(graph: &DiGraph<&str, ()>, from: &[NodeIndex]) -> BTreeSet<NodeIndex> {
    let mut seen = BTreeSet::new();
    let mut stack = from.to_vec();
    while let Some(n) = stack.pop() {
        if seen.insert(n) {
            stack.extend(graph.neighbors_directed(n, petgraph::Direction::Incoming));
        }
    }
    seen
}

/// Switched off: `enabled: false` and everything downstream of it; a writer that loses its
/// input is warned about.
fn switched_off(
    file: &PipelineFile,
    graph: &DiGraph<&str, ()>,
    order: &[NodeIndex],
) -> (BTreeMap<NodeIndex, String>, Vec<String>) {
    let mut off: BTreeMap<NodeIndex, String> = BTreeMap::new();
    let mut warnings = Vec::new();
    for &n in order {
        let name = graph[n];
        if !file.nodes[name].enabled() {
            off.insert(n, "disabled (enabled: false)".into());
        } else if let Some(up) = graph
            .neighbors_directed(n, petgraph::Direction::Incoming)
            .find(|u| off.contains_key(u))
        {
            off.insert(n, format!("reads '{}', which is switched off", graph[up]));
            if file.nodes[name].is_writer() {
                warnings.push(format!(
                    "writer '{name}' loses its input '{}' (switched off), so it writes nothing",
                    graph[up]
                ));
            }
        }
    }
    (off, warnings)
}

/// Read ahead of time only: the mesh and boundary behind an interpolated field, when no other
/// running node reads them (the field evaluates them itself, at later times). By node: the
/// field that reads it.
fn read_ahead(
    file: &PipelineFile,
    graph: &DiGraph<&str, ()>,
    order: &[NodeIndex],
    runs: impl Fn(&NodeIndex) -> bool,
) -> BTreeMap<NodeIndex, String> {
    let mut ahead: BTreeMap<NodeIndex, String> = BTreeMap::new();
    for &n in order.iter().rev() {
        if !runs(&n) || file.nodes[graph[n]].is_writer() {
            continue;
        }
        let consumers: Vec<NodeIndex> = graph
            .neighbors_directed(n, petgraph::Direction::Outgoing)
            .filter(|c| runs(c))
            .collect();
        let reader = |c: &NodeIndex| match &file.nodes[graph[*c]] {
            node if node.schedule().interpolate => Some(graph[*c].to_string()),
            _ => ahead.get(c).cloned(),
        };
        let readers: Option<Vec<String>> = consumers.iter().map(reader).collect();
        if let Some(r) = readers.filter(|r| !r.is_empty()) {
            ahead.insert(n, r[0].clone());
        }
    }
    ahead
}

/// `every`, `offset` and `split` (see [`crate::schedule`]); a field's `interpolate` is
/// checked by its node.
fn check_schedule(source: &Source, name: &str, file: &PipelineFile) -> Result<()> {
    let node = &file.nodes[name];
    let sc = node.schedule();
    let fail = |field: &str, msg: String, help: Option<String>| -> Error {
        source
            .error(
                source.field_span(name, field),
                format!("node '{name}': {msg}"),
                "invalid value",
                help,
            )
            .into()
    };
    if sc.every == 0 {
        return Err(fail("every", "every must be at least 1".into(), None));
    }
    if sc.offset >= sc.every {
        return Err(fail(
            "offset",
            format!(
                "offset must be less than every ({}), got {}",
                sc.every, sc.offset
            ),
            None,
        ));
    }
    if sc.split == 0 || sc.split > sc.every {
        return Err(fail(
            "split",
            format!(
                "split must be between 1 and every ({}), got {}: a build cannot take longer \
                 than the time between builds",
                sc.every, sc.split
            ),
            Some(format!("raise every to at least {}", sc.split.max(1))),
        ));
    }
    Ok(())
}

fn producers_of(t: PortType, file: &PipelineFile) -> String {
    let list: Vec<&String> = file
        .nodes
        .iter()
        .filter(|(_, n)| n.output() == Some(t))
        .map(|(k, _)| k)
        .collect();
    if list.is_empty() {
        format!("no node in this file produces a {t}")
    } else {
        format!("nodes producing a {t}: {}", join(&list))
    }
}

fn join(names: &[&String]) -> String {
    names
        .iter()
        .map(|s| s.as_str())
        .collect::<Vec<_>>()
        .join(", ")
}

/// The name at edit distance <= 2, if any (for "did you mean").
pub(crate) fn closest_name<'a>(want: &str, names: &[&'a String]) -> Option<&'a str> {
    names
        .iter()
        .map(|n| (edit_distance(want, n), n.as_str()))
        .filter(|(d, _)| *d <= 2)
        .min()
        .map(|(_, n)| n)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut prev: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut cur = vec![i + 1];
        for (j, cb) in b.iter().enumerate() {
            cur.push(
                (prev[j] + usize::from(ca != *cb))
                    .min(prev[j + 1] + 1)
                    .min(cur[j] + 1),
            );
        }
        prev = cur;
    }
    prev[b.len()]
}

impl Plan {
    /// The graph as Graphviz DOT: nodes labelled with their kind, edges with the port type,
    /// pruned nodes dashed.
    pub fn dot(&self) -> String {
        let mut s = String::from(
            "digraph pipeline {\n  rankdir=LR;\n  node [shape=box, fontname=\"Helvetica\"];\n",
        );
        for (name, node) in &self.file.nodes {
            let pruned = self.pruned.iter().any(|(n, _)| n == name);
            let style = if pruned {
                ", style=dashed, color=gray"
            } else if node.is_writer() {
                ", style=rounded"
            } else {
                ""
            };
            s += &format!(
                "  \"{name}\" [label=\"{name}\\n{}\"{style}];\n",
                node.kind()
            );
        }
        for (name, node) in &self.file.nodes {
            for p in node.inputs() {
                let (input, port, t) = (p.node, p.port, p.ty);
                s += &format!("  \"{input}\" -> \"{name}\" [label=\"{port}: {t}\"];\n");
            }
        }
        s + "}\n"
    }
}
