//! `NODE.FIELD=VALUE` overrides (nested fields with dots: `vox.grid.resolution`, VALUE in RON).
//!
//! Two ways to apply one:
//! - [`apply`] (`--set`, and the viewer's live edits): to the *parsed* file. The file is parsed
//!   first (its errors located in it), then each override replaces the value at its path in
//!   the file as serde sees it (every field present, defaults included; enum variants such as
//!   `Fit(resolution: …)` passed through) and the file is deserialized again, so an error
//!   names the `--set` argument and says what is wrong with it (an unknown node or field, with
//!   the names it could be; a value of the wrong type or out of range) instead of pointing at
//!   a line of the file that does not hold it.
//! - [`apply_override`]: to the file's *text*, keeping its comments and layout (the viewer
//!   writes its live edits back into the file with it).

use crate::schema::PipelineFile;
use imprint_core::{Error, Result};
use serde_json::{Map, Value as Json};

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

/// One `NODE.FIELD[.FIELD…]=VALUE` argument, split.
struct Assignment<'a> {
    arg: &'a str,
    node: &'a str,
    fields: Vec<&'a str>,
    value: &'a str,
}

impl<'a> Assignment<'a> {
    fn parse(arg: &'a str) -> Result<Self> {
        let (path, value) = arg
            .split_once('=')
            .ok_or_else(|| Error::Invalid(format!("--set {arg}: expected NODE.FIELD=VALUE")))?;
        let mut parts = path.trim().split('.');
        let node = parts.next().filter(|n| !n.is_empty());
        let fields: Vec<&str> = parts.collect();
        match (
            node,
            fields.is_empty() || fields.iter().any(|f| f.is_empty()),
        ) {
            (Some(node), false) => Ok(Assignment {
                arg,
                node,
                fields,
                value: value.trim(),
            }),
            _ => Err(Error::Invalid(format!(
                "--set {arg}: expected NODE.FIELD=VALUE (a node name, a dot, a field)"
            ))),
        }
    }

    fn fail(&self, msg: impl std::fmt::Display) -> Error {
        Error::Invalid(format!("--set {}: {msg}", self.arg))
    }

    /// `node.a.b` up to and including field `depth`.
    fn path(&self, depth: usize) -> String {
        std::iter::once(self.node)
            .chain(self.fields[..=depth].iter().copied())
            .collect::<Vec<_>>()
            .join(".")
    }
}

/// Applies each `NODE.FIELD=VALUE` of `overrides`, in order, to the parsed `file`: the value at
/// the path is replaced by VALUE (parsed as RON), a field the file leaves at its default is
/// set, and the result is deserialized again. Errors name the `--set` argument. The nodes'
/// own checks (ranges) are the plan's, run afterwards.
pub fn apply(file: &PipelineFile, overrides: &[String]) -> Result<PipelineFile> {
    let mut file = file.clone();
    for arg in overrides {
        file = apply_one(&file, &Assignment::parse(arg)?)?;
    }
    Ok(file)
}

fn apply_one(file: &PipelineFile, a: &Assignment<'_>) -> Result<PipelineFile> {
    let mut tree = serde_json::to_value(file)
        .map_err(|e| a.fail(format!("the pipeline cannot be edited as a value: {e}")))?;
    let nodes = tree
        .get_mut("nodes")
        .and_then(Json::as_object_mut)
        .ok_or_else(|| a.fail("the pipeline has no nodes"))?;
    let names: Vec<String> = nodes.keys().cloned().collect();
    let Some(node) = nodes.get_mut(a.node) else {
        return Err(a.fail(format!(
            "the pipeline has no node named '{}'; {}",
            a.node,
            suggest(a.node, &names, "its nodes")
        )));
    };
    let kind = variant_name(node).unwrap_or("node").to_string();
    let mut body = body_mut(node).ok_or_else(|| a.fail("the node has no fields"))?;
    let last = a.fields.len() - 1;
    for (depth, field) in a.fields.iter().enumerate() {
        let owner = if depth == 0 {
            format!("node '{}' ({kind})", a.node)
        } else {
            format!("'{}'", a.path(depth - 1))
        };
        if depth == last {
            let value = ron_to_json(a.value, body.get(*field))
                .map_err(|e| a.fail(format!("'{}' is not a RON value: {e}", a.value)))?;
            let known: Vec<String> = body.keys().cloned().collect();
            body.insert((*field).to_string(), value);
            return serde_json::from_value::<PipelineFile>(tree)
                .map_err(|e| explain(a, &e.to_string(), field, &owner, &known));
        }
        if !body.contains_key(*field) {
            // Not serialized: an unknown field (serde says so), or one left unset.
            let known: Vec<String> = body.keys().cloned().collect();
            let mut probe = serde_json::to_value(file).unwrap_or_default();
            let mut at = probe.get_mut("nodes").and_then(|n| n.get_mut(a.node));
            for f in &a.fields[..depth] {
                at = at.and_then(body_mut).and_then(|b| b.get_mut(*f));
            }
            if let Some(b) = at.and_then(body_mut) {
                b.insert((*field).to_string(), Json::Null);
            }
            let said = serde_json::from_value::<PipelineFile>(probe)
                .err()
                .map(|e| e.to_string())
                .filter(|e| e.starts_with(&format!("unknown field `{field}`")));
            return Err(match said {
                Some(said) => explain(a, &said, field, &owner, &known),
                None => a.fail(format!(
                    "{owner} leaves '{field}' unset; set it whole first: --set {}=(…)",
                    a.path(depth)
                )),
            });
        }
        let inner = body.get_mut(*field).expect("checked above");
        if inner.is_null() {
            return Err(a.fail(format!(
                "{owner} leaves '{field}' unset (None); set it whole first: --set {}=(…)",
                a.path(depth)
            )));
        }
        let what = short(inner);
        body = body_mut(inner).ok_or_else(|| {
            a.fail(format!(
                "'{}' is {what}, not a structure with fields",
                a.path(depth)
            ))
        })?;
    }
    unreachable!("the loop returns on the last field")
}

/// What serde said about the edited file, in the terms of the override.
fn explain(a: &Assignment<'_>, said: &str, field: &str, owner: &str, known: &[String]) -> Error {
    if let Some(rest) = said.strip_prefix(&format!("unknown field `{field}`")) {
        // `, expected one of `a`, `b``: the struct's fields (all of them, set or not).
        let mut fields: Vec<String> = rest
            .split('`')
            .skip(1)
            .step_by(2)
            .map(str::to_string)
            .collect();
        if fields.is_empty() {
            fields = known.to_vec();
        }
        return a.fail(format!(
            "{owner} has no field '{field}'; {}",
            suggest(field, &fields, "its fields")
        ));
    }
    if let Some((_, ty)) = said.split_once(", expected ")
        && said.starts_with("invalid value: integer")
        && let Some(range) = int_range(ty)
    {
        let n = said.split('`').nth(1).unwrap_or(a.value);
        return a.fail(format!(
            "{range}: {}",
            out_of_range(field, n, ty.trim_matches('`').starts_with('i'))
        ));
    }
    a.fail(format!("{} does not fit '{field}': {said}", a.value))
}

/// The names `want` could be a typo of, or the whole list.
fn suggest(want: &str, names: &[String], what: &str) -> String {
    let refs: Vec<&String> = names.iter().collect();
    let list = names.join(", ");
    match crate::plan::closest_name(want, &refs) {
        Some(c) => format!("did you mean '{c}'? ({what}: {list})"),
        None => format!("{what}: {list}"),
    }
}

/// `expected an unsigned integer 0..=4294967295` for serde's type name (`u32`).
pub(crate) fn int_range(ty: &str) -> Option<String> {
    let ty = ty.trim().trim_matches('`');
    let (signed, bits) = match ty.split_at_checked(1)? {
        ("u", b) => (false, b.parse::<u32>().ok()?),
        ("i", b) => (true, b.parse::<u32>().ok()?),
        _ => return None,
    };
    if !matches!(bits, 8 | 16 | 32 | 64) {
        return None;
    }
    Some(if signed {
        let half = 1i128 << (bits - 1);
        format!("expected an integer {}..={}", -half, half - 1)
    } else {
        format!("expected an unsigned integer 0..={}", (1u128 << bits) - 1)
    })
}

/// `substeps cannot be negative`, `resolution 99999999999 is too large` (of an integer
/// field of `signed` type).
pub(crate) fn out_of_range(field: &str, number: &str, signed: bool) -> String {
    match (number.trim_start().starts_with('-'), signed) {
        (true, false) => format!("{field} cannot be negative"),
        (true, true) => format!("{field} {number} is too small"),
        (false, _) => format!("{field} {number} is too large"),
    }
}

/// The fields of a struct (`{…}`), of a struct variant (`{"Fit": {…}}`) or of a node.
fn body_mut(v: &mut Json) -> Option<&mut Map<String, Json>> {
    if variant_name(v).is_some() {
        return v.as_object_mut()?.values_mut().next()?.as_object_mut();
    }
    v.as_object_mut()
}

/// The variant of `{"Fit": {…}}` (one key, a type's name: capitalised), as serde writes an
/// enum's struct variant.
fn variant_name(v: &Json) -> Option<&str> {
    let o = v.as_object()?;
    let (k, inner) = o.iter().next().filter(|_| o.len() == 1)?;
    (k.starts_with(|c: char| c.is_ascii_uppercase()) && inner.is_object()).then_some(k.as_str())
}

fn short(v: &Json) -> String {
    match v {
        Json::String(s) => format!("'{s}'"),
        Json::Array(_) => "a list".into(),
        other => other.to_string(),
    }
}

/// VALUE (RON) as serde's JSON model of it: `Fit(resolution: 48)` → `{"Fit": {"resolution":
/// 48}}`, `Cpu` → `"Cpu"`, `Some(x)`/`x` → x, `None` → null, `(1, 2)` → `[1, 2]`, `(a: 1)` →
/// `{"a": 1}`. `hint`, the value it replaces, says whether `Name(…)` is a variant or a struct
/// written with its name.
fn ron_to_json(text: &str, hint: Option<&Json>) -> std::result::Result<Json, String> {
    let mut p = RonParser { s: text, i: 0 };
    let v = p.value(hint)?;
    p.ws();
    if p.i < p.s.len() {
        return Err(format!("unexpected '{}'", &p.s[p.i..]));
    }
    Ok(v)
}

struct RonParser<'a> {
    s: &'a str,
    i: usize,
}

impl<'a> RonParser<'a> {
    fn rest(&self) -> &'a str {
        &self.s[self.i..]
    }

    fn ws(&mut self) {
        loop {
            let r = self.rest();
            let t = r.trim_start();
            self.i += r.len() - t.len();
            if t.starts_with("//") {
                self.i += t.find('\n').unwrap_or(t.len());
            } else if t.starts_with("/*") {
                self.i += t.find("*/").map_or(t.len(), |e| e + 2);
            } else {
                return;
            }
        }
    }

    fn eat(&mut self, c: char) -> bool {
        self.ws();
        if self.rest().starts_with(c) {
            self.i += c.len_utf8();
            true
        } else {
            false
        }
    }

    fn ident(&mut self) -> Option<&'a str> {
        self.ws();
        let r = self.rest();
        let n = r
            .char_indices()
            .find(|&(_, c)| !(c.is_alphanumeric() || c == '_'))
            .map_or(r.len(), |(n, _)| n);
        if n == 0 || r.starts_with(|c: char| c.is_ascii_digit()) {
            return None;
        }
        let start = self.i;
        self.i += n;
        Some(&self.s[start..start + n])
    }

    fn value(&mut self, hint: Option<&Json>) -> std::result::Result<Json, String> {
        self.ws();
        let r = self.rest();
        let Some(c) = r.chars().next() else {
            return Err("a value is missing".into());
        };
        match c {
            '"' | '\'' | 'r' if c != 'r' || r.starts_with("r\"") || r.starts_with("r#") => {
                self.string()
            }
            '[' => {
                self.i += 1;
                let item_hint = hint.and_then(Json::as_array).and_then(|a| a.first());
                let mut items = Vec::new();
                loop {
                    if self.eat(']') {
                        return Ok(Json::Array(items));
                    }
                    items.push(self.value(item_hint)?);
                    if !self.eat(',') && !self.rest().trim_start().starts_with(']') {
                        return Err("expected ',' or ']' in a list".into());
                    }
                }
            }
            '{' => {
                self.i += 1;
                let mut map = Map::new();
                loop {
                    if self.eat('}') {
                        return Ok(Json::Object(map));
                    }
                    let key = match self.value(None)? {
                        Json::String(s) => s,
                        other => other.to_string(),
                    };
                    if !self.eat(':') {
                        return Err("expected ':' after a map key".into());
                    }
                    let h = hint.and_then(|h| h.get(&key));
                    map.insert(key, self.value(h)?);
                    if !self.eat(',') && !self.rest().trim_start().starts_with('}') {
                        return Err("expected ',' or '}' in a map".into());
                    }
                }
            }
            '(' => self.parens(hint),
            c if c.is_ascii_digit() || "+-.".contains(c) => self.number(),
            _ => {
                let Some(name) = self.ident().map(str::to_string) else {
                    return Err(format!("unexpected '{r}'"));
                };
                match name.as_str() {
                    "true" => return Ok(Json::Bool(true)),
                    "false" => return Ok(Json::Bool(false)),
                    "None" => return Ok(Json::Null),
                    "inf" | "NaN" => return Err(format!("{name} cannot be given with --set")),
                    _ => {}
                }
                self.ws();
                if !self.rest().starts_with('(') {
                    return Ok(Json::String(name));
                }
                if name == "Some" {
                    self.i += 1;
                    let v = self.value(hint)?;
                    return if self.eat(')') {
                        Ok(v)
                    } else {
                        Err("expected ')' after Some(…".into())
                    };
                }
                // A struct written with its name keeps the fields only; a variant is a map
                // of its name to its fields.
                let is_struct = hint.is_some_and(|h| h.is_object() && variant_name(h).is_none());
                if is_struct {
                    return self.parens(hint);
                }
                let inner_hint = hint.and_then(|h| h.get(&name));
                let inner = self.parens(inner_hint)?;
                let inner = match inner {
                    // `V(x)`: a newtype variant's value.
                    Json::Array(mut one)
                        if one.len() == 1 && !inner_hint.is_some_and(Json::is_array) =>
                    {
                        one.pop().expect("one item")
                    }
                    other => other,
                };
                Ok(Json::Object(Map::from_iter([(name, inner)])))
            }
        }
    }

    /// `(a: 1, b: 2)` → an object, `(1, 2)` → an array, `()` → an empty one of the hint's kind.
    fn parens(&mut self, hint: Option<&Json>) -> std::result::Result<Json, String> {
        if !self.eat('(') {
            return Err("expected '('".into());
        }
        if self.eat(')') {
            return Ok(match hint {
                Some(Json::Array(_)) => Json::Array(Vec::new()),
                Some(Json::Null) => Json::Null,
                _ => Json::Object(Map::new()),
            });
        }
        // Named fields start with `ident:` (not `ident::`).
        let save = self.i;
        let named = self.ident().is_some() && self.eat(':');
        self.i = save;
        if named {
            let mut map = Map::new();
            loop {
                let key = self.ident().ok_or("expected a field name")?.to_string();
                if !self.eat(':') {
                    return Err(format!("expected ':' after '{key}'"));
                }
                let h = hint.and_then(|h| h.get(&key));
                map.insert(key, self.value(h)?);
                let comma = self.eat(',');
                if self.eat(')') {
                    return Ok(Json::Object(map));
                }
                if !comma {
                    return Err("expected ',' or ')' between fields".into());
                }
            }
        }
        let mut items = Vec::new();
        loop {
            let h = hint
                .and_then(Json::as_array)
                .and_then(|a| a.get(items.len()));
            items.push(self.value(h)?);
            let comma = self.eat(',');
            if self.eat(')') {
                return Ok(Json::Array(items));
            }
            if !comma {
                return Err("expected ',' or ')' between values".into());
            }
        }
    }

    fn number(&mut self) -> std::result::Result<Json, String> {
        let r = self.rest();
        let n = r
            .char_indices()
            .skip(1)
            .find(|&(i, c)| {
                !(c.is_ascii_alphanumeric()
                    || c == '.'
                    || c == '_'
                    || ((c == '-' || c == '+') && r[..i].ends_with(['e', 'E'])))
            })
            .map_or(r.len(), |(n, _)| n);
        let tok = r[..n].replace('_', "");
        self.i += n;
        let tok = tok.strip_prefix('+').unwrap_or(&tok);
        if let Ok(u) = tok.parse::<u64>() {
            return Ok(Json::from(u));
        }
        if let Ok(i) = tok.parse::<i64>() {
            return Ok(Json::from(i));
        }
        let is_int = tok
            .trim_start_matches('-')
            .bytes()
            .all(|b| b.is_ascii_digit());
        if is_int && !tok.trim_start_matches('-').is_empty() {
            return Err(format!("the integer {tok} is out of range for any field"));
        }
        tok.parse::<f64>()
            .ok()
            .filter(|f| f.is_finite())
            .and_then(|f| serde_json::Number::from_f64(f).map(Json::Number))
            .ok_or_else(|| format!("'{tok}' is not a number"))
    }

    fn string(&mut self) -> std::result::Result<Json, String> {
        // The token's end, then RON's own reading of it (escapes, raw strings).
        let r = self.rest();
        let end = if let Some(q) = r.strip_prefix('\'') {
            q.find('\'').map(|e| e + 2)
        } else if let Some(raw) = r.strip_prefix('r') {
            let hashes = raw.chars().take_while(|&c| c == '#').count();
            let close = format!("\"{}", "#".repeat(hashes));
            r[2 + hashes..]
                .find(&close)
                .map(|e| 2 + hashes + e + close.len())
        } else {
            let b = r.as_bytes();
            let mut i = 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            (i < b.len()).then_some(i + 1)
        };
        let end = end.ok_or("a string is not closed")?;
        let tok = &r[..end];
        self.i += end;
        if tok.starts_with('\'') {
            ron::from_str::<char>(tok).map(|c| Json::String(c.to_string()))
        } else {
            ron::from_str::<String>(tok).map(Json::String)
        }
        .map_err(|e| e.to_string())
    }
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
