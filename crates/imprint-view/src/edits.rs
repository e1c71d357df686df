//! Live edits: the numbers of each node (substeps, stiffness, every, split, band,
//! resolution…) as `NODE.FIELD=VALUE` assignments, the same as `--set`, applied to the file's
//! text (so they are checked like the file), and written back into the file on request by
//! the same text edit, which keeps its comments and layout.

use imprint_graph::Plan;
use imprint_graph::overrides::apply_override;
use std::path::Path;

/// One number of a node's spec.
#[derive(Clone, Debug, PartialEq)]
pub struct Number {
    /// `cloth.params.substeps`: the assignment's left side.
    pub path: String,
    pub value: f64,
    pub integer: bool,
}

/// Every number `node`'s spec holds, with the path an assignment needs. Enum variants
/// (`Fit(resolution: …)`) are looked through, as a RON file writes them; lists are skipped.
pub fn numbers(plan: &Plan, node: &str) -> Vec<Number> {
    let Some(spec) = plan.file.nodes.get(node) else {
        return Vec::new();
    };
    let Ok(json) = serde_json::to_value(spec) else {
        return Vec::new();
    };
    let mut out = Vec::new();
    // The spec serialises as { "Kind": { fields } }.
    if let Some(body) = json.as_object().and_then(|o| o.values().next()) {
        walk(body, node, &mut out);
    }
    out
}

fn walk(v: &serde_json::Value, path: &str, out: &mut Vec<Number>) {
    let Some(fields) = v.as_object() else {
        return;
    };
    for (key, value) in fields {
        let here = format!("{path}.{key}");
        match value {
            serde_json::Value::Number(n) => out.push(Number {
                path: here,
                value: n.as_f64().unwrap_or(0.0),
                integer: n.is_u64() || n.is_i64(),
            }),
            serde_json::Value::Object(o) if is_variant(o) => {
                walk(o.values().next().expect("one entry"), &here, out);
            }
            serde_json::Value::Object(_) => walk(value, &here, out),
            _ => {}
        }
    }
}

/// `{ "Fit": { … } }`: an enum variant with fields, as serde writes it.
fn is_variant(o: &serde_json::Map<String, serde_json::Value>) -> bool {
    o.len() == 1
        && o.keys()
            .all(|k| k.starts_with(|c: char| c.is_ascii_uppercase()))
        && o.values().all(serde_json::Value::is_object)
}

/// `path=value`, with an integer written as one.
pub fn assignment(n: &Number, value: f64) -> String {
    if n.integer {
        format!("{}={}", n.path, value.round() as i64)
    } else {
        format!("{}={value}", n.path)
    }
}

/// Puts `new` in `edits`, replacing an earlier edit of the same field.
pub fn record(edits: &mut Vec<String>, new: String) {
    let field = |a: &str| a.split('=').next().unwrap_or("").trim().to_string();
    edits.retain(|e| field(e) != field(&new));
    edits.push(new);
}

/// Writes `edits` into the file at `path` (atomically), keeping everything else of its text.
pub fn write_back(path: &Path, edits: &[String]) -> imprint_core::Result<()> {
    let mut text = std::fs::read_to_string(path).map_err(|e| imprint_core::Error::io(path, e))?;
    for e in edits {
        text = apply_override(&text, e)?;
    }
    imprint_core::io::atomic_write_bytes(path, text.as_bytes())
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"// The cloth falls.
Pipeline(
    frames: 4,
    nodes: {
        "m": Mesh(path: "tri.obj"), // a triangle
        "vox": Voxelize(mesh: "m", grid: Fit(resolution: 32, padding: 0.1)),
        "field": DistanceField(boundary: "vox", band: 3, measure: Never),
        "w": WriteField(field: "field"),
    },
)
"#;

    fn plan(dir: &Path) -> Plan {
        std::fs::write(dir.join("tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
        std::fs::write(dir.join("p.ron"), FILE).unwrap();
        imprint_graph::load(&dir.join("p.ron"), &[]).unwrap()
    }

    #[test]
    fn numbers_have_assignable_paths_through_variants() {
        let dir = tempfile::tempdir().unwrap();
        let p = plan(dir.path());
        let vox = numbers(&p, "vox");
        let res = vox
            .iter()
            .find(|n| n.path == "vox.grid.resolution")
            .unwrap();
        assert_eq!((res.value, res.integer), (32.0, true));
        let band = numbers(&p, "field");
        assert!(band.iter().any(|n| n.path == "field.band" && !n.integer));
        // Every path found is one an assignment can reach in the file.
        for n in vox.iter().chain(&band) {
            let a = assignment(n, n.value);
            imprint_graph::overrides::apply_override(FILE, &a)
                .unwrap_or_else(|e| panic!("{a}: {e}"));
        }
    }

    #[test]
    fn write_back_keeps_comments_and_layout() {
        let dir = tempfile::tempdir().unwrap();
        let _ = plan(dir.path());
        let mut edits = Vec::new();
        record(&mut edits, "field.band=2".into());
        record(&mut edits, "vox.grid.resolution=48".into());
        record(&mut edits, "field.band=2.5".into());
        assert_eq!(edits, ["vox.grid.resolution=48", "field.band=2.5"]);
        let path = dir.path().join("p.ron");
        write_back(&path, &edits).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let expected = FILE
            .replace("resolution: 32", "resolution: 48")
            .replace("band: 3,", "band: 2.5,");
        assert_eq!(text, expected);
        let p = imprint_graph::load(&path, &[]).unwrap();
        let band = numbers(&p, "field")
            .into_iter()
            .find(|n| n.path == "field.band");
        assert_eq!(band.map(|n| n.value), Some(2.5));
    }
}
