//! `imprint schema pipeline|report|nodes-md`: the files' JSON Schemas, and the node reference
//! `docs/nodes.md` is generated as (`imprint schema nodes-md > docs/nodes.md`).

use clap::ValueEnum;

/// What `imprint schema` prints.
#[derive(Clone, Copy, ValueEnum)]
pub enum SchemaWhat {
    /// The JSON Schema of a pipeline file (its RON read as JSON).
    Pipeline,
    /// The JSON Schema of a run's report.json.
    Report,
    /// docs/nodes.md: every node kind's fields, from the pipeline schema.
    NodesMd,
}

/// Prints `what` on standard output.
pub fn print(what: SchemaWhat) -> imprint_graph::Result<()> {
    use imprint_graph::json_schema;
    let pretty =
        |s: schemars::Schema| serde_json::to_string_pretty(&s).expect("a schema is plain JSON");
    match what {
        SchemaWhat::Pipeline => outln!("{}", pretty(json_schema::pipeline())),
        SchemaWhat::Report => outln!("{}", pretty(json_schema::report())),
        SchemaWhat::NodesMd => out!("{}", json_schema::nodes_markdown()),
    }
    Ok(())
}
