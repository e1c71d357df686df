//! From text to a checked plan: parse, check every edge and value, find assets, prune.

use crate::diagnostics::{Source, ron_error};
use crate::overrides::apply_override;
use crate::schema::{Backend, GridChoice, HeightGrid, NodeSpec, PipelineFile, PortType};
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
    /// Nodes that do not run, with the reason.
    pub pruned: Vec<(String, String)>,
    /// What the user should know before running (a writer that lost its input…).
    pub warnings: Vec<String>,
}

/// Reads, overrides (`NODE.FIELD=VALUE`) and validates a pipeline file.
pub fn load(path: &Path, overrides: &[String]) -> Result<Plan> {
    let mut text = std::fs::read_to_string(path).map_err(|e| {
        imprint_core::Error::Invalid(format!("cannot read pipeline file {}: {e}", path.display()))
    })?;
    for o in overrides {
        text = apply_override(&text, o)?;
    }
    let base_dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    parse(
        Source {
            name: path.display().to_string(),
            text,
        },
        &base_dir,
    )
}

/// Validates pipeline text (`source.name` is used in messages).
pub fn parse(source: Source, base_dir: &Path) -> Result<Plan> {
    let file: PipelineFile = ron::Options::default()
        .with_default_extension(
            ron::extensions::Extensions::IMPLICIT_SOME
                | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
        )
        .from_str(&source.text)
        .map_err(|e| ron_error(&source, &e))?;
    let whole = 0..source.text.len().min(8);
    if file.frames == 0 {
        return Err(source
            .error(whole, "frames must be at least 1", "here", None)
            .into());
    }
    if !(file.fps.is_finite() && file.fps > 0.0) {
        return Err(source
            .error(
                whole,
                format!("fps must be a finite number > 0, got {}", file.fps),
                "here",
                None,
            )
            .into());
    }
    if file.nodes.is_empty() {
        return Err(source
            .error(whole, "the pipeline has no nodes", "here", None)
            .into());
    }

    // Typed edges.
    let names: Vec<&String> = file.nodes.keys().collect();
    let mut graph = DiGraph::<&str, ()>::new();
    let idx: BTreeMap<&str, NodeIndex> = names
        .iter()
        .map(|n| (n.as_str(), graph.add_node(n.as_str())))
        .collect();
    for (name, node) in &file.nodes {
        for (port, input, _) in node.inputs() {
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

    let order = match toposort(&graph, None) {
        Ok(order) => order,
        Err(cycle) => {
            let start = graph[cycle.node_id()];
            let members = kosaraju_scc(&graph)
                .into_iter()
                .find(|scc| scc.contains(&cycle.node_id()))
                .unwrap_or_default();
            let mut in_cycle: Vec<&str> = members.iter().map(|&i| graph[i]).collect();
            in_cycle.sort();
            return Err(source
                .error(
                    source.node_span(start),
                    format!(
                        "the graph has a cycle through nodes: {}",
                        in_cycle.join(" -> ")
                    ),
                    "part of a cycle",
                    Some(
                        "a node cannot depend on its own output; remove one of these inputs".into(),
                    ),
                )
                .into());
        }
    };

    for (name, node) in &file.nodes {
        for (port, input, expected) in node.inputs() {
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
                        Some(producers_of(expected, &file)),
                    )
                    .into());
            }
        }
        check_values(&source, name, node, base_dir)?;
        check_schedule(&source, name, &file)?;
    }

    // Prune what reaches no writer.
    let writers: Vec<NodeIndex> = graph
        .node_indices()
        .filter(|&i| file.nodes[graph[i]].is_writer())
        .collect();
    let mut needed = BTreeSet::new();
    let mut stack = writers.clone();
    while let Some(n) = stack.pop() {
        if needed.insert(n) {
            stack.extend(graph.neighbors_directed(n, petgraph::Direction::Incoming));
        }
    }
    // Switched off: `enabled: false` and everything downstream of it.
    let mut off: BTreeMap<NodeIndex, String> = BTreeMap::new();
    let mut warnings = Vec::new();
    for &n in &order {
        let name = graph[n];
        if !file.nodes[name].enabled() {
            off.insert(n, "disabled (enabled: false)".into());
        } else if let Some(up) = graph
            .neighbors_directed(n, petgraph::Direction::Incoming)
            .find(|u| off.contains_key(u))
        {
            off.insert(n, format!("reads '{}', which is switched off", graph[up]));
            if file.nodes[name].is_writer() && needed.contains(&n) {
                warnings.push(format!(
                    "writer '{name}' loses its input '{}' (switched off), so it writes nothing",
                    graph[up]
                ));
            }
        }
    }
    // Read ahead of time only: the mesh and boundary behind an interpolated field, when no
    // other running node reads them (the field evaluates them itself, at later times).
    let mut ahead: BTreeMap<NodeIndex, String> = BTreeMap::new();
    for &n in order.iter().rev() {
        let runs = |m: &NodeIndex| needed.contains(m) && !off.contains_key(m);
        if !runs(&n) || file.nodes[graph[n]].is_writer() {
            continue;
        }
        let consumers: Vec<NodeIndex> = graph
            .neighbors_directed(n, petgraph::Direction::Outgoing)
            .filter(runs)
            .collect();
        let reader = |c: &NodeIndex| match &file.nodes[graph[*c]] {
            NodeSpec::DistanceField(f) if f.interpolate => Some(graph[*c].to_string()),
            _ => ahead.get(c).cloned(),
        };
        let readers: Option<Vec<String>> = consumers.iter().map(reader).collect();
        if let Some(r) = readers.filter(|r| !r.is_empty()) {
            ahead.insert(n, r[0].clone());
        }
    }
    let mut run_order = Vec::new();
    let mut pruned = Vec::new();
    for n in order {
        let name = graph[n].to_string();
        if let Some(why) = off.get(&n) {
            pruned.push((name, why.clone()));
        } else if let Some(field) = ahead.get(&n) {
            pruned.push((
                name,
                format!("only '{field}' reads it, building ahead of time (interpolate)"),
            ));
        } else if needed.contains(&n) {
            run_order.push(name);
        } else {
            let reason = if writers.is_empty() {
                "the pipeline has no writer, so nothing would be kept".to_string()
            } else {
                "its output reaches no writer".to_string()
            };
            pruned.push((name, reason));
        }
    }
    Ok(Plan {
        source,
        file,
        base_dir: base_dir.to_path_buf(),
        order: run_order,
        pruned,
        warnings,
    })
}

/// Ranges and assets, checked before anything runs.
fn check_values(source: &Source, name: &str, node: &NodeSpec, base_dir: &Path) -> Result<()> {
    let fail = |field: &str, msg: String| -> Error {
        source
            .error(
                source.field_span(name, field),
                format!("node '{name}': {msg}"),
                "invalid value",
                None,
            )
            .into()
    };
    match node {
        NodeSpec::Mesh(m) => {
            m.validate().map_err(|e| fail("motion", e.to_string()))?;
            if let Some(p) = &m.path {
                let full = base_dir.join(p);
                if !full.is_file() {
                    return Err(source
                        .error(
                            source.field_span(name, "path"),
                            format!("node '{name}': mesh file not found: {}", full.display()),
                            "missing file",
                            Some("paths are relative to the pipeline file's folder".into()),
                        )
                        .into());
                }
            }
        }
        NodeSpec::Voxelize(v) => match &v.grid {
            GridChoice::Fit {
                resolution,
                padding,
            } => {
                if *resolution == 0 {
                    return Err(fail(
                        "grid",
                        "grid resolution must be at least 1, got 0".into(),
                    ));
                }
                if *resolution > imprint_core::grid::MAX_AXIS_CELLS {
                    let r = *resolution as u64;
                    return Err(fail(
                        "grid",
                        format!(
                            "a {r}^3 grid would need {} (resolution at most {})",
                            imprint_core::error::human_bytes(r * r * r * 17),
                            imprint_core::grid::MAX_AXIS_CELLS
                        ),
                    ));
                }
                if !(padding.is_finite() && *padding >= 0.0) {
                    return Err(fail(
                        "grid",
                        format!("grid padding must be finite and >= 0, got {padding}"),
                    ));
                }
            }
            GridChoice::Explicit { origin, cell, dims } => {
                let o = glam::Vec3::new(origin.0, origin.1, origin.2);
                let d = glam::UVec3::new(dims.0, dims.1, dims.2);
                imprint_core::GridSpec::new(o, *cell, d)
                    .map_err(|e| fail("grid", e.to_string()))?;
            }
        },
        NodeSpec::DistanceField(f) => {
            if !(f.band.is_finite() && f.band > 0.0) {
                return Err(fail(
                    "band",
                    format!("band must be a finite number of cells > 0, got {}", f.band),
                ));
            }
            if let crate::schema::Measure::Every(0) = f.measure {
                return Err(fail("measure", "Every(k) needs k >= 1".into()));
            }
        }
        NodeSpec::Render(r) => {
            if !r.out.contains("{frame") {
                return Err(fail(
                    "out",
                    format!(
                        "out pattern '{}' has no {{frame}} or {{frame:04}}: every frame would overwrite the last",
                        r.out
                    ),
                ));
            }
            if r.objects.is_empty() {
                return Err(fail(
                    "objects",
                    "a Render node needs at least one object".into(),
                ));
            }
            crate::exec::render_options(r, 0.0).map_err(|e| fail("camera", e.to_string()))?;
            if let Some(c) = &r.contact_sheet {
                if c.every == 0 {
                    return Err(fail("contact_sheet", "every must be at least 1".into()));
                }
                imprint_render::sequence::ContactSheet::new(c.columns, c.width)
                    .map_err(|e| fail("contact_sheet", e.to_string()))?;
            }
            if let Some(g) = &r.gif {
                if g.every == 0 {
                    return Err(fail("gif", "every must be at least 1".into()));
                }
                // Only checks the values: nothing is created before the first frame.
                imprint_render::sequence::GifWriter::create(Path::new(&g.path), g.width, 1.0)
                    .map_err(|e| fail("gif", e.to_string()))?;
            }
        }
        NodeSpec::Heightmap(h) => match h.grid {
            HeightGrid::Fit {
                resolution,
                padding,
            } => {
                let max = imprint_core::raster::MAX_SIZE;
                if resolution == 0 || resolution > max {
                    return Err(fail(
                        "grid",
                        format!("resolution must be in 1..={max}, got {resolution}"),
                    ));
                }
                if !(padding.is_finite() && padding >= 0.0) {
                    return Err(fail(
                        "grid",
                        format!("grid padding must be finite and >= 0, got {padding}"),
                    ));
                }
                if !h.empty.is_finite() {
                    return Err(fail(
                        "empty",
                        format!("empty must be finite, got {}", h.empty),
                    ));
                }
            }
            HeightGrid::Explicit { origin, cell, dims } => {
                imprint_stages::depth::HeightRegion::new(
                    glam::Vec2::new(origin.0, origin.1),
                    cell,
                    glam::UVec2::new(dims.0, dims.1),
                    h.empty,
                )
                .map_err(|e| fail("grid", e.to_string()))?;
            }
        },
        NodeSpec::Cloth(c) => {
            c.params
                .validate()
                .map_err(|e| fail("params", e.to_string()))?;
            for d in &c.depth_colliders {
                d.params
                    .validate()
                    .map_err(|e| fail("depth_colliders", e.to_string()))?;
            }
            if !c.depth_colliders.is_empty() && c.backend == Some(Backend::Gpu) {
                return Err(fail(
                    "backend",
                    "the GPU cloth reads distance-field colliders only; a cloth with \
                     depth_colliders runs on the CPU (set backend: Cpu, or leave it out)"
                        .into(),
                ));
            }
        }
        NodeSpec::WriteHeightmap(w) => {
            if w.formats.is_empty() {
                return Err(fail(
                    "formats",
                    "list at least one of Png16, Exr, Npy, Preview".into(),
                ));
            }
        }
        NodeSpec::WriteField(_) | NodeSpec::WriteMesh(_) => {}
        NodeSpec::Skin(k) => {
            let full = base_dir.join(&k.rig);
            if !full.is_file() {
                return Err(fail(
                    "rig",
                    format!("rig file not found: {}", full.display()),
                ));
            }
            // The rig file's own errors name its file, line and column.
            let loaded = crate::rig::load(&full)?;
            if k.mesh.is_none() && loaded.mesh.is_none() {
                return Err(fail(
                    "mesh",
                    format!(
                        "give the Mesh node to skin (mesh: \"...\"), or bind one in {} (mesh: \"file.obj\")",
                        full.display()
                    ),
                ));
            }
            let offset = glam::Vec3::from(k.offset);
            if !offset.is_finite() {
                return Err(fail("offset", format!("offset {offset} must be finite")));
            }
            match &k.method {
                crate::schema::SkinMethod::Particles(p) => p.validate(),
                crate::schema::SkinMethod::Linear { weights }
                | crate::schema::SkinMethod::DualQuaternion { weights } => weights.validate(),
            }
            .map_err(|e| fail("method", e.to_string()))?;
        }
        NodeSpec::Drape(d) => {
            d.params
                .validate()
                .map_err(|e| fail("params", e.to_string()))?;
        }
        NodeSpec::Snow(n) => {
            n.params
                .validate()
                .map_err(|e| fail("params", e.to_string()))?;
            if n.meshes.is_empty() {
                return Err(fail("meshes", "a Snow node needs at least one mesh".into()));
            }
            if let Some(g) = &n.ground {
                crate::exec::snow_ground(g).map_err(|e| fail("ground", e.to_string()))?;
            }
        }
        NodeSpec::Ground(g) => {
            g.params
                .validate()
                .map_err(|e| fail("params", e.to_string()))?;
            if let imprint_stages::ground::Initial::Image { path, .. } = &g.params.initial {
                let full = base_dir.join(path);
                if !full.is_file() {
                    return Err(fail(
                        "params",
                        format!("initial height image not found: {}", full.display()),
                    ));
                }
            }
        }
    }
    Ok(())
}

/// `every`, `offset`, `split` and `interpolate` (see [`crate::schedule`]).
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
    if sc.interpolate
        && let NodeSpec::DistanceField(f) = node
    {
        let NodeSpec::Voxelize(v) = &file.nodes[&f.boundary] else {
            unreachable!("edges are typed")
        };
        if !matches!(file.nodes[&v.mesh], NodeSpec::Mesh(_)) {
            return Err(fail(
                "interpolate",
                format!(
                    "interpolate builds fields ahead of time from the mesh at a later time, but \
                     '{}' reads '{}', a {} node computed frame by frame",
                    f.boundary,
                    v.mesh,
                    file.nodes[&v.mesh].kind()
                ),
                Some("interpolate fields of Mesh nodes only, or use every without it".into()),
            ));
        }
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
fn closest_name<'a>(want: &str, names: &[&'a String]) -> Option<&'a str> {
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
            for (port, input, t) in node.inputs() {
                s += &format!("  \"{input}\" -> \"{name}\" [label=\"{port}: {t}\"];\n");
            }
        }
        s + "}\n"
    }
}
