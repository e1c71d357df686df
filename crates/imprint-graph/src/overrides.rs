//! `--set NODE.FIELD=VALUE`: overrides applied to the pipeline's text before parsing, so an
//! override is checked exactly like the file itself (types, ranges, unknown fields) and any
//! error points into the text the user can read. Nested fields use dots: `vox.grid.resolution`.

use imprint_core::{Error, Result};

/// Applies `assignment` (`NODE.FIELD[.FIELD…]=VALUE`, VALUE in RON syntax) to `text`.
pub fn apply_override(text: &str, assignment: &str) -> Result<String> {
    let (path, value) = assignment
        .split_once('=')
        .ok_or_else(|| Error::Invalid(format!("--set {assignment}: expected NODE.FIELD=VALUE")))?;
    let mut parts = path.trim().split('.');
    let node = parts.next().filter(|n| !n.is_empty());
    let fields: Vec<&str> = parts.collect();
    let (Some(node), false) = (node, fields.is_empty()) else {
        return Err(Error::Invalid(format!(
            "--set {assignment}: expected NODE.FIELD=VALUE (a node name, a dot, a field)"
        )));
    };
    let value = value.trim();
    let key = format!("\"{node}\"");
    let key_at = find_top_level_key(text, &key).ok_or_else(|| {
        Error::Invalid(format!(
            "--set {assignment}: the pipeline has no node named '{node}'"
        ))
    })?;
    // After `"node":` comes `Kind(`.
    let open = text[key_at..]
        .find('(')
        .map(|i| key_at + i)
        .ok_or_else(|| Error::Invalid(format!("--set {assignment}: node '{node}' has no body")))?;
    let mut body = (open + 1, matching_close(text, open)?);
    let mut out = text.to_string();
    for (depth, field) in fields.iter().enumerate() {
        let last = depth + 1 == fields.len();
        match find_field(&out, body, field) {
            Some((vstart, vend)) if last => {
                out.replace_range(vstart..vend, value);
                return Ok(out);
            }
            Some((vstart, vend)) => {
                let open = out[vstart..vend]
                    .find('(')
                    .map(|i| vstart + i)
                    .ok_or_else(|| {
                        Error::Invalid(format!(
                            "--set {assignment}: '{field}' of node '{node}' is not a structure"
                        ))
                    })?;
                body = (open + 1, matching_close(&out, open)?);
            }
            None if last => {
                out.insert_str(body.0, &format!("{field}: {value}, "));
                return Ok(out);
            }
            None => {
                return Err(Error::Invalid(format!(
                    "--set {assignment}: node '{node}' does not set '{field}' in the file; \
                     write it there first, then override its fields"
                )));
            }
        }
    }
    unreachable!("the loop returns on the last field")
}

/// Byte positions of the characters outside strings and comments, with their nesting depth.
fn scan(text: &str, from: usize, to: usize, mut visit: impl FnMut(usize, char, i32) -> bool) {
    let bytes = text.as_bytes();
    let mut i = from;
    let mut depth = 0i32;
    while i < to {
        let c = bytes[i] as char;
        match c {
            '"' => {
                i += 1;
                while i < to && bytes[i] != b'"' {
                    i += if bytes[i] == b'\\' { 2 } else { 1 };
                }
            }
            '/' if bytes.get(i + 1) == Some(&b'/') => {
                while i < to && bytes[i] != b'\n' {
                    i += 1;
                }
            }
            '/' if bytes.get(i + 1) == Some(&b'*') => {
                i += 2;
                while i + 1 < to && !(bytes[i] == b'*' && bytes[i + 1] == b'/') {
                    i += 1;
                }
                i += 1;
            }
            '(' | '[' | '{' => {
                if !visit(i, c, depth) {
                    return;
                }
                depth += 1;
            }
            ')' | ']' | '}' => {
                depth -= 1;
                if !visit(i, c, depth) {
                    return;
                }
            }
            _ => {
                if !visit(i, c, depth) {
                    return;
                }
            }
        }
        i += 1;
    }
}

/// The `)` closing the `(` at byte `open`, outside strings and comments.
pub(crate) fn matching_close(text: &str, open: usize) -> Result<usize> {
    let mut close = None;
    scan(text, open, text.len(), |i, c, depth| {
        if depth == 0 && c == ')' {
            close = Some(i);
            return false;
        }
        true
    });
    close.ok_or_else(|| Error::Invalid("unbalanced parentheses in the pipeline file".into()))
}

/// Finds `"node"` used as a map key (followed by ':'), outside comments.
fn find_top_level_key(text: &str, key: &str) -> Option<usize> {
    let mut from = 0;
    while let Some(i) = text[from..].find(key) {
        let at = from + i;
        if text[at + key.len()..].trim_start().starts_with(':') {
            return Some(at);
        }
        from = at + key.len();
    }
    None
}

/// The value range of `field:` at the top level of `body`.
fn find_field(text: &str, body: (usize, usize), field: &str) -> Option<(usize, usize)> {
    let mut key_end = None;
    let mut at_depth0_starts = Vec::new();
    scan(text, body.0, body.1, |i, c, depth| {
        if depth == 0 && c == ':' {
            at_depth0_starts.push(i);
        }
        true
    });
    for colon in at_depth0_starts {
        let before = text[body.0..colon].trim_end();
        // The identifier starts after the last character that cannot be in one (which may
        // be wider than a byte: `°band:` is the field `band`).
        let ident_start = before
            .char_indices()
            .rev()
            .find(|&(_, c)| !(c.is_alphanumeric() || c == '_'))
            .map_or(0, |(p, c)| p + c.len_utf8());
        if &before[ident_start..] == field {
            key_end = Some(colon + 1);
            break;
        }
    }
    let after = key_end?;
    // Keep the whitespace after the colon; replace only the value.
    let vstart = after + (text[after..body.1].len() - text[after..body.1].trim_start().len());
    let mut vend = body.1;
    scan(text, vstart, body.1, |i, c, depth| {
        if depth == 0 && c == ',' {
            vend = i;
            return false;
        }
        true
    });
    Some((vstart, vend))
}

#[cfg(test)]
mod tests {
    use super::*;

    const SRC: &str = r#"Pipeline(frames: 2, nodes: {
        "vox": Voxelize(mesh: "m", grid: Fit(resolution: 64, padding: 0.1)), // "vox": x
        "field": DistanceField(boundary: "vox", band: 3),
    })"#;

    #[test]
    fn replaces_inserts_and_nests() {
        let t = apply_override(SRC, "field.band=2.5").unwrap();
        assert!(t.contains("band: 2.5)"), "{t}");
        let t = apply_override(SRC, "vox.grid.resolution=128").unwrap();
        assert!(t.contains("Fit(resolution: 128, padding: 0.1)"), "{t}");
        let t = apply_override(SRC, "field.backend=Some(Cpu)").unwrap();
        assert!(
            t.contains("DistanceField(backend: Some(Cpu), boundary"),
            "{t}"
        );
    }

    #[test]
    fn bad_overrides_are_explained() {
        assert!(
            apply_override(SRC, "nobody.band=1")
                .unwrap_err()
                .to_string()
                .contains("no node named")
        );
        assert!(
            apply_override(SRC, "field=1")
                .unwrap_err()
                .to_string()
                .contains("NODE.FIELD")
        );
        assert!(
            apply_override(SRC, "field.x.y=1")
                .unwrap_err()
                .to_string()
                .contains("write it there")
        );
    }
}
