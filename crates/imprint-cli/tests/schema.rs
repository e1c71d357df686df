//! Files that explain themselves: `imprint schema pipeline|report|nodes-md`, the shipped
//! pipelines and a run's `report.json` valid under those schemas (and the schemas strict
//! enough to refuse what serde refuses), `docs/nodes.md` current, and height maps whose
//! PNG and `.npy` put the cells where their sidecars say.

use serde_json::{Value, json};
use std::path::{Path, PathBuf};

mod common;
use common::{imprint, run_ok};

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
}

/// `imprint schema WHAT`, parsed.
fn schema(what: &str) -> Value {
    let out = run_ok(&["schema", what], &root());
    serde_json::from_slice(&out.stdout).expect("the schema is JSON")
}

fn validator(schema: &Value) -> jsonschema::Validator {
    jsonschema::validator_for(schema).expect("a valid JSON Schema")
}

/// The schema's complaints about `value` (empty: valid).
fn errors(v: &jsonschema::Validator, value: &Value) -> Vec<String> {
    v.iter_errors(value)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect()
}

#[test]
fn schema_prints_each_file_s_schema_and_refuses_other_names() {
    for (what, title) in [("pipeline", "Pipeline"), ("report", "Report")] {
        let s = schema(what);
        assert_eq!(s["title"], title);
        assert!(s["$schema"].as_str().unwrap().contains("json-schema.org"));
    }
    let out = imprint(&["schema", "pipelines"], &root());
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("invalid value 'pipelines'"), "{err}");
    assert!(err.contains("pipeline, report"), "{err}");
}

/// The regenerating command, named by the failure.
const BLESS: &str = "cargo run -p imprint-cli -- schema nodes-md > docs/nodes.md";

#[test]
fn docs_nodes_md_is_generated_from_the_current_schema() {
    let out = run_ok(&["schema", "nodes-md"], &root());
    let fresh = String::from_utf8(out.stdout).unwrap();
    let path = root().join("docs/nodes.md");
    if std::env::var_os("IMPRINT_BLESS").is_some() {
        std::fs::write(&path, &fresh).unwrap();
    }
    let committed = std::fs::read_to_string(&path).unwrap_or_default();
    assert!(
        committed == fresh,
        "docs/nodes.md is stale (a node's fields or doc comments changed): regenerate it with \
         `{BLESS}` (or IMPRINT_BLESS=1 cargo test -p imprint-cli --test schema)"
    );
    // One section per node kind, in the order `imprint` lists them.
    let kinds: Vec<&str> = fresh
        .lines()
        .filter_map(|l| l.strip_prefix("## "))
        .filter(|h| !["Pipeline", "Types"].contains(h))
        .collect();
    let s = schema("pipeline");
    let variants = s["$defs"]["NodeSpec"]["oneOf"].as_array().unwrap();
    assert_eq!(kinds.len(), variants.len(), "{kinds:?}");
    for kind in ["Mesh", "Cloth", "Ground", "Skin"] {
        assert!(kinds.contains(&kind), "{kinds:?}");
    }
    assert!(
        fresh.contains("| `band` | f32 | `3.0` |"),
        "a field row with its default"
    );
}

/// Every shipped pipeline, read as `imprint` reads it, then written as JSON.
fn shipped_pipelines() -> Vec<(PathBuf, Value)> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(root().join("pipelines"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "ron"))
        .collect();
    files.sort();
    assert!(files.len() >= 10, "{files:?}");
    files
        .into_iter()
        .map(|f| {
            let plan = imprint_graph::load(&f, &[]).unwrap_or_else(|e| panic!("{f:?}: {e}"));
            let json = serde_json::to_value(&plan.file).unwrap();
            (f, json)
        })
        .collect()
}

#[test]
fn shipped_pipelines_are_valid_and_typos_are_not() {
    let v = validator(&schema("pipeline"));
    let pipelines = shipped_pipelines();
    for (file, json) in &pipelines {
        let e = errors(&v, json);
        assert!(e.is_empty(), "{file:?} fails its schema: {e:#?}");
    }
    // What serde refuses, the schema refuses: an unknown field at the top, in a node, in a
    // node's params; an unknown kind; a missing required field; a wrong type.
    let (_, walk) = pipelines
        .iter()
        .find(|(f, _)| f.ends_with("footprints.ron"))
        .expect("footprints.ron");
    let (name, node) = walk["nodes"]
        .as_object()
        .unwrap()
        .iter()
        .find(|(_, n)| n.get("Ground").is_some())
        .expect("a Ground node");
    let bad = |f: &dyn Fn(&mut Value)| {
        let mut j = walk.clone();
        f(&mut j);
        j
    };
    let cases = [
        ("unknown top field", bad(&|j| j["frame"] = json!(3))),
        (
            "unknown node field",
            bad(&|j| j["nodes"][name]["Ground"]["colour"] = json!(1)),
        ),
        (
            "unknown params field",
            bad(&|j| j["nodes"][name]["Ground"]["params"]["sise"] = json!(1)),
        ),
        (
            "unknown kind",
            bad(&|j| j["nodes"][name] = json!({ "Grund": node["Ground"] })),
        ),
        (
            "missing frames",
            bad(&|j| drop(j.as_object_mut().unwrap().remove("frames"))),
        ),
        ("wrong type", bad(&|j| j["fps"] = json!("thirty"))),
        (
            "unknown unit variant",
            bad(&|j| j["backend"] = json!("Tpu")),
        ),
    ];
    for (what, json) in cases {
        assert!(
            !errors(&v, &json).is_empty(),
            "{what}: the schema accepts it"
        );
        let text = serde_json::to_string(&json).unwrap();
        let serde_says = serde_json::from_str::<imprint_graph::schema::PipelineFile>(&text);
        assert!(serde_says.is_err(), "{what}: serde accepts it");
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// A box in the +x, +z quadrant only (x, z in 0.3..0.7, top at y = 0.4), seen from above on
/// a 20 x 20 grid of 0.1 m cells centred from -0.95: cells i, k in 13..=16 are covered.
const QUADRANT: &str = r#"Pipeline(
    frames: 1,
    backend: Cpu,
    nodes: {
        "box": Mesh(primitive: Box(size: (1, 1, 1), subdivisions: 1), fit: (size: 0.4, center: (0.5, 0.2, 0.5))),
        "top": Heightmap(mesh: "box", grid: Explicit(origin: (-0.95, -0.95), cell: 0.1, dims: (20, 20)), empty: 0.0),
        "hm": WriteHeightmap(heights: "top", formats: [Png16, Npy]),
    },
)"#;

fn covered(i: usize, k: usize) -> bool {
    (13..=16).contains(&i) && (13..=16).contains(&k)
}

#[test]
fn a_run_s_report_states_its_versions_overrides_units_and_axes() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "p.ron", QUADRANT);
    let sets = ["top.empty=0.0", "hm.every=1"];
    let f = file.to_str().unwrap();
    run_ok(
        &["run", f, "--out", "o", "--set", sets[0], "--set", sets[1]],
        dir.path(),
    );
    let text = std::fs::read_to_string(dir.path().join("o/report.json")).unwrap();
    let report: Value = serde_json::from_str(&text).unwrap();
    assert_eq!(report["schema_version"], 1);
    let version = report["imprint_version"].as_str().unwrap();
    assert!(
        version.starts_with(env!("CARGO_PKG_VERSION")) && version.contains("(git "),
        "{version}"
    );
    assert_eq!(report["overrides"], json!(sets));
    assert_eq!(report["units"]["length"], "metre");
    assert_eq!(report["units"]["time"], "second");
    assert_eq!(report["units"]["angle"], "degree");
    assert_eq!(report["axes"]["up"], "+y");
    assert_eq!(report["axes"]["handedness"], "right-handed");
    assert_eq!(
        report["axes"]["heightmap_rows"],
        imprint_render::heightmap::ROWS
    );
    // Valid under `imprint schema report`, which requires what every report has.
    let v = validator(&schema("report"));
    let e = errors(&v, &report);
    assert!(e.is_empty(), "report.json fails its schema: {e:#?}");
    for field in ["schema_version", "units", "overrides", "nodes"] {
        let mut less = report.clone();
        less.as_object_mut().unwrap().remove(field);
        assert!(
            !errors(&v, &less).is_empty(),
            "a report without {field} passes"
        );
    }
    let mut wrong = report.clone();
    wrong["schema_version"] = json!("1");
    assert!(
        !errors(&v, &wrong).is_empty(),
        "a string schema_version passes"
    );
}

#[test]
fn png_and_npy_height_maps_put_cells_where_their_sidecars_say() {
    let dir = tempfile::tempdir().unwrap();
    let file = write(dir.path(), "p.ron", QUADRANT);
    run_ok(&["run", file.to_str().unwrap(), "--out", "o"], dir.path());
    let hm = dir.path().join("o/hm");
    let (nx, nz) = (20usize, 20usize);
    for ext in ["png", "npy"] {
        let side: Value = serde_json::from_str(
            &std::fs::read_to_string(hm.join(format!("top_0000.{ext}.json"))).unwrap(),
        )
        .unwrap_or_else(|e| panic!("{ext} sidecar: {e}"));
        // The sidecar says row 0 is the largest z and column 0 the smallest x.
        assert_eq!(side["rows"], imprint_render::heightmap::ROWS, "{ext}");
        assert_eq!(side["columns"], imprint_render::heightmap::COLUMNS, "{ext}");
        assert!(
            side["rows"]
                .as_str()
                .unwrap()
                .contains("row 0 is the largest z")
        );
        assert!(
            side["columns"]
                .as_str()
                .unwrap()
                .contains("column 0 is the smallest x")
        );
        assert_eq!(side["dims"], json!([nx, nz]), "{ext}");
    }
    let png = image::open(hm.join("top_0000.png")).unwrap().into_luma16();
    let (shape, npy) = imprint_render::read_npy_f32(&hm.join("top_0000.npy")).unwrap();
    assert_eq!(shape, [nz, nx]);
    for r in 0..nz {
        for c in 0..nx {
            // Row r is z index k = nz - 1 - r; column c is x index i = c.
            let (i, k) = (c, nz - 1 - r);
            let want = covered(i, k);
            let level = png.get_pixel(c as u32, r as u32).0[0];
            assert_eq!(level > 0, want, "png row {r} column {c}: level {level}");
            let h = npy[r * nx + c];
            assert_eq!(h > 0.0, want, "npy row {r} column {c}: {h}");
            if want {
                assert!((h - 0.4).abs() < 1e-4, "npy row {r} column {c}: {h}");
            }
        }
    }
    // The box sits in the top right of both: small rows (large z), large columns (large x).
    assert!(png.get_pixel(14, 4).0[0] > 0 && npy[4 * nx + 14] > 0.0);
    assert_eq!(png.get_pixel(14, 15).0[0], 0);
}
