//! Errors about a pipeline file, shown with the file, line, column and the offending text
//! (miette renders the labelled source span).

use miette::{Diagnostic, NamedSource, SourceSpan};

/// An invalid pipeline: the CLI prints it with its source excerpt and exits with code 2.
#[derive(Debug, thiserror::Error, Diagnostic)]
#[error("{file}:{line}:{column}: {message}")]
pub struct PipelineError {
    pub file: String,
    pub line: usize,
    pub column: usize,
    pub message: String,
    #[source_code]
    pub src: NamedSource<String>,
    #[label("{label}")]
    pub span: SourceSpan,
    pub label: String,
    #[help]
    pub help: Option<String>,
}

/// A pipeline file's text and name, for locating things in it.
#[derive(Clone, Debug)]
pub struct Source {
    pub name: String,
    pub text: String,
}

impl Source {
    /// An error at byte range `span` of the file.
    pub fn error(
        &self,
        span: std::ops::Range<usize>,
        message: impl Into<String>,
        label: impl Into<String>,
        help: Option<String>,
    ) -> PipelineError {
        let start = span.start.min(self.text.len());
        let end = span.end.clamp(start, self.text.len());
        let (line, column) = self.line_col(start);
        PipelineError {
            file: self.name.clone(),
            line,
            column,
            message: message.into(),
            src: NamedSource::new(&self.name, self.text.clone()),
            span: (start, end - start).into(),
            label: label.into(),
            help,
        }
    }

    /// 1-based line and column of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rfind('\n').map_or(before.chars().count(), |nl| {
            before[nl + 1..].chars().count()
        }) + 1;
        (line, column)
    }

    /// Byte offset of a 1-based (line, column).
    pub fn offset(&self, line: usize, column: usize) -> usize {
        let mut offset = 0;
        for (i, l) in self.text.split_inclusive('\n').enumerate() {
            if i + 1 == line {
                return offset
                    + l.char_indices()
                        .nth(column.saturating_sub(1))
                        .map_or(l.len(), |(b, _)| b);
            }
            offset += l.len();
        }
        self.text.len()
    }

    /// Span of a node's key (`"name"`) in the file, or the whole file when not found.
    pub fn node_span(&self, name: &str) -> std::ops::Range<usize> {
        let key = format!("\"{name}\"");
        let mut from = 0;
        while let Some(i) = self.text[from..].find(&key) {
            let at = from + i;
            if self.text[at + key.len()..].trim_start().starts_with(':') {
                return at..at + key.len();
            }
            from = at + key.len();
        }
        0..0
    }

    /// Span of `field:` (its value included up to the end of the line) inside node `name`, or
    /// the node's key when not found.
    pub fn field_span(&self, name: &str, field: &str) -> std::ops::Range<usize> {
        let node = self.node_span(name);
        if node.is_empty() {
            return node;
        }
        let rest = &self.text[node.end..];
        // Within the node's body: from its `Kind(` to the matching `)` (strings and comments
        // skipped), so a field after a string value (`mesh: "m", grid: …`) is found.
        let limit = rest
            .find('(')
            .and_then(|open| crate::overrides::matching_close(&self.text, node.end + open).ok())
            .map_or(rest.len(), |close| close - node.end);
        let pat = format!("{field}:");
        let mut from = 0;
        while let Some(i) = rest[from..limit.max(from)].find(&pat) {
            let at = from + i;
            let before = rest[..at].chars().last();
            if !before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                let start = node.end + at;
                let end = self.text[start..]
                    .find([',', '\n', ')'])
                    .map_or(self.text.len(), |e| start + e);
                return start..end;
            }
            from = at + pat.len();
        }
        node
    }
}

/// Converts a RON parse error into a located diagnostic.
pub fn ron_error(src: &Source, e: &ron::error::SpannedError) -> PipelineError {
    let start = src.offset(e.span.start.line, e.span.start.col);
    let mut end = src.offset(e.span.end.line, e.span.end.col);
    if end <= start {
        // Point at the token that starts here (at least its first character, whole: the
        // span must not split a character such as U+2000 or U+00A0).
        let rest = &src.text[start..];
        end = rest
            .find(|c: char| c.is_whitespace() || ",:()[]{}".contains(c))
            .map_or(src.text.len(), |n| {
                start + n.max(rest.chars().next().map_or(0, char::len_utf8))
            });
    }
    let message = e.code.to_string();
    let help = if message.contains("unknown variant") || message.contains("Unexpected variant") {
        // RON names the enum: only a node's kind gets the list of node kinds (a camera's or
        // a motion's variant is listed by the message itself).
        Some(if message.contains("`NodeSpec`") {
            format!(
                "node kinds are: {} (see README: writing a pipeline)",
                crate::schema::NodeSpec::KINDS.join(", ")
            )
        } else {
            "check the spelling against the README's pipeline reference".to_string()
        })
    } else if message.contains("Unexpected field") || message.contains("unknown field") {
        Some("check the field's spelling against the README's pipeline reference".to_string())
    } else {
        None
    };
    src.error(start..end, message, "here", help)
}

#[cfg(test)]
mod field_span_tests {
    use super::Source;

    #[test]
    fn a_field_after_a_string_value_is_found_in_its_own_node_only() {
        let text = r#"Pipeline(frames: 2, nodes: {
    "top": Heightmap(
        mesh: "m", // "quoted", in a comment
        grid: Fit(resolution: 0),
    ),
    "other": Heightmap(mesh: "m", every: 3, grid: Fit(resolution: 8)),
})"#;
        let src = Source {
            name: "p.ron".into(),
            text: text.into(),
        };
        let span = src.field_span("top", "grid");
        assert_eq!(&text[span.clone()], "grid: Fit(resolution: 0");
        assert_eq!(src.line_col(span.start), (4, 9));
        // A field the node does not set is not taken from the next node.
        let span = src.field_span("top", "every");
        assert_eq!(span, src.node_span("top"));
    }
}
