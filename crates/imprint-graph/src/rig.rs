//! Rig files: parsing and validating a rig (RON, the format in
//! `imprint_stages::skin::rig`'s module doc) with the file, line, column and offending text in
//! every error, as for pipeline files (exit code 2).
//!
//! RON errors (syntax, unknown fields, wrong types) come located from the parser. The rig's
//! own checks ([`Rig::problem`]: unknown parent, cycles, keys out of order, translation on a
//! non-root bone …) say *which* bone, motion and key is wrong; to point at it in the text, a
//! small scanner walks the file's brackets (skipping strings and comments) to the n-th item
//! of `bones` / `animation` / `keys` and to the named field inside it. It does not parse
//! values: serde already did, so the text is known to be well-formed RON of the right shape.

use crate::diagnostics::{PipelineError, Source, ron_error};
use crate::{Error, Result};
use imprint_stages::skin::rig::{Place, Rig};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// A rig read from a file, with its mesh binding resolved against the file's folder.
#[derive(Clone, Debug)]
pub struct LoadedRig {
    pub rig: Rig,
    /// The bound mesh's path (checked to exist), when the rig names one.
    pub mesh: Option<PathBuf>,
}

/// Reads, parses and validates a rig file.
pub fn load(path: &Path) -> Result<LoadedRig> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        imprint_core::Error::Invalid(format!("cannot read rig file {}: {e}", path.display()))
    })?;
    let base_dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf);
    parse(
        &Source {
            name: path.display().to_string(),
            text,
        },
        &base_dir,
    )
}

/// Parses and validates rig text (`source.name` is used in messages; the mesh binding is
/// resolved against `base_dir`).
pub fn parse(source: &Source, base_dir: &Path) -> Result<LoadedRig> {
    let rig: Rig = ron::Options::default()
        .with_default_extension(
            ron::extensions::Extensions::IMPLICIT_SOME
                | ron::extensions::Extensions::UNWRAP_VARIANT_NEWTYPES,
        )
        .from_str(&source.text)
        .map_err(|e| {
            let mut err = ron_error(source, &e);
            err.help = ron_help(&err.message);
            Error::from(err)
        })?;
    if let Some(p) = rig.problem() {
        return Err(locate(source, p.place, p.message).into());
    }
    let mesh = match &rig.mesh {
        Some(m) => {
            let path = base_dir.join(m);
            if !path.is_file() {
                let span = Scan::new(&source.text).place(Place::Mesh);
                return Err(source
                    .error(
                        span,
                        format!("mesh file not found: {}", path.display()),
                        "this mesh",
                        Some("the mesh path is relative to the rig file's folder".into()),
                    )
                    .into());
            }
            Some(path)
        }
        None => None,
    };
    Ok(LoadedRig { rig, mesh })
}

fn ron_help(message: &str) -> Option<String> {
    if message.contains("field") {
        Some(
            "rig fields: bones, mesh, animation; a bone: name, head, tail, parent; a key: time, \
             rotation (axis, degrees), translation; Bend: bone, axis, degrees, start, duration; \
             Twist: bone, degrees, start, duration"
                .into(),
        )
    } else if message.contains("variant") {
        Some(
            "animation entries are Keys, Bend or Twist; interpolation is Step, Linear or Smooth"
                .into(),
        )
    } else {
        None
    }
}

/// An error at the place a validation problem names.
fn locate(source: &Source, place: Place, message: String) -> PipelineError {
    let span = Scan::new(&source.text).place(place);
    let label = match place {
        Place::Bone { field, .. } | Place::Motion { field, .. } if !field.is_empty() => {
            format!("this {field}")
        }
        _ => "here".to_string(),
    };
    source.error(span, message, label, None)
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Tok {
    Open,
    Close,
    Comma,
    Colon,
    /// A word, number or string.
    Atom,
}

/// The file's tokens with their byte ranges (strings and comments skipped over whole).
struct Scan<'a> {
    text: &'a str,
    toks: Vec<(Tok, Range<usize>)>,
}

impl<'a> Scan<'a> {
    fn new(text: &'a str) -> Self {
        let b = text.as_bytes();
        let mut toks = Vec::new();
        let mut i = 0;
        while i < b.len() {
            let c = b[i];
            let start = i;
            match c {
                b'/' if b.get(i + 1) == Some(&b'/') => {
                    while i < b.len() && b[i] != b'\n' {
                        i += 1;
                    }
                    continue;
                }
                b'/' if b.get(i + 1) == Some(&b'*') => {
                    i += 2;
                    while i + 1 < b.len() && !(b[i] == b'*' && b[i + 1] == b'/') {
                        i += 1;
                    }
                    i = (i + 2).min(b.len());
                    continue;
                }
                b'"' => {
                    i += 1;
                    while i < b.len() && b[i] != b'"' {
                        i += if b[i] == b'\\' { 2 } else { 1 };
                    }
                    i = (i + 1).min(b.len());
                    toks.push((Tok::Atom, start..i));
                    continue;
                }
                b'(' | b'[' | b'{' => toks.push((Tok::Open, i..i + 1)),
                b')' | b']' | b'}' => toks.push((Tok::Close, i..i + 1)),
                b',' => toks.push((Tok::Comma, i..i + 1)),
                b':' => toks.push((Tok::Colon, i..i + 1)),
                c if c.is_ascii_whitespace() => {}
                _ => {
                    while i < b.len() && !b" \t\r\n()[]{},:\"/".contains(&b[i]) {
                        i += 1;
                    }
                    toks.push((Tok::Atom, start..i.max(start + 1)));
                    i = i.max(start + 1);
                    continue;
                }
            }
            i += 1;
        }
        Scan { text, toks }
    }

    /// Token index of the `Close` matching the `Open` at `open`.
    fn close_of(&self, open: usize) -> usize {
        let mut depth = 0;
        for (k, (t, _)) in self.toks.iter().enumerate().skip(open) {
            match t {
                Tok::Open => depth += 1,
                Tok::Close => {
                    depth -= 1;
                    if depth == 0 {
                        return k;
                    }
                }
                _ => {}
            }
        }
        self.toks.len().saturating_sub(1)
    }

    /// Byte range of the tokens `a..=b`.
    fn bytes(&self, a: usize, b: usize) -> Range<usize> {
        self.toks[a].1.start..self.toks[b].1.end
    }

    /// The first `Open` at or after token `from` (the body of `Name(...)` or `(...)`).
    fn open_at(&self, from: usize, to: usize) -> Option<usize> {
        (from..=to).find(|&k| self.toks[k].0 == Tok::Open)
    }

    /// The value of `field:` in the item spanning tokens `item` (the shallowest occurrence),
    /// as token indices (first, last).
    fn field(&self, item: (usize, usize), field: &str) -> Option<(usize, usize)> {
        let mut best: Option<(usize, usize)> = None;
        let mut depth = 0usize;
        for k in item.0..=item.1 {
            match self.toks[k].0 {
                Tok::Open => depth += 1,
                Tok::Close => depth = depth.saturating_sub(1),
                Tok::Atom
                    if &self.text[self.toks[k].1.clone()] == field
                        && self.toks.get(k + 1).is_some_and(|t| t.0 == Tok::Colon)
                        && best.is_none_or(|(d, _)| depth < d) =>
                {
                    best = Some((depth, k));
                }
                _ => {}
            }
        }
        let (_, k) = best?;
        let first = k + 2;
        if first > item.1 {
            return None;
        }
        // The value runs to the comma or close at its own depth.
        let mut depth = 0i32;
        let mut last = first;
        for j in first..=item.1 {
            match self.toks[j].0 {
                Tok::Open => depth += 1,
                Tok::Close if depth == 0 => break,
                Tok::Close => depth -= 1,
                Tok::Comma if depth == 0 => break,
                _ => {}
            }
            last = j;
        }
        Some((first, last))
    }

    /// The items of the list (or tuple) whose value spans `value`, as token ranges.
    fn items(&self, value: (usize, usize)) -> Vec<(usize, usize)> {
        let Some(open) = self.open_at(value.0, value.1) else {
            return Vec::new();
        };
        let close = self.close_of(open);
        let mut out = Vec::new();
        let mut depth = 0;
        let mut start = open + 1;
        for k in open + 1..close {
            match self.toks[k].0 {
                Tok::Open => depth += 1,
                Tok::Close => depth -= 1,
                Tok::Comma if depth == 0 => {
                    if k > start {
                        out.push((start, k - 1));
                    }
                    start = k + 1;
                }
                _ => {}
            }
        }
        if close > start {
            out.push((start, close - 1));
        }
        out
    }

    /// The byte span a rig place refers to (the best match found; the whole rig otherwise).
    fn place(&self, place: Place) -> Range<usize> {
        if self.toks.is_empty() {
            return 0..0;
        }
        let Some(root_open) = self.open_at(0, self.toks.len() - 1) else {
            return 0..0;
        };
        let root = (0, self.close_of(root_open));
        let head = self.bytes(0, root_open);
        let span = |(a, b): (usize, usize)| self.bytes(a, b);
        let pick = |item: (usize, usize), field: &str| {
            if field.is_empty() {
                span(item)
            } else {
                self.field(item, field).map_or_else(|| span(item), span)
            }
        };
        match place {
            Place::Rig => head,
            Place::Mesh => self.field(root, "mesh").map_or(head, span),
            Place::Bone { bone, field } => {
                let Some(list) = self.field(root, "bones") else {
                    return head;
                };
                match self.items(list).get(bone) {
                    Some(&item) => pick(item, field),
                    None => span(list),
                }
            }
            Place::Motion { motion, key, field } => {
                let Some(list) = self.field(root, "animation") else {
                    return head;
                };
                let Some(&item) = self.items(list).get(motion) else {
                    return span(list);
                };
                match key {
                    None => pick(item, field),
                    Some(k) => {
                        let Some(keys) = self.field(item, "keys") else {
                            return span(item);
                        };
                        match self.items(keys).get(k) {
                            Some(&key) => pick(key, field),
                            None => span(keys),
                        }
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scanner_finds_items_and_fields() {
        let text = r#"Rig( // a comment with ( and "
  bones: [ (name: "a,(", head: (0, 0, 0), tail: (1, 0, 0)),
           (name: "b", head: (1, 0, 0), tail: (2, 0, 0), parent: "a") ],
)"#;
        let s = Scan::new(text);
        let src = Source {
            name: "t".into(),
            text: text.into(),
        };
        let rig: Rig = ron::Options::default()
            .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
            .from_str(text)
            .unwrap();
        assert_eq!(rig.bones.len(), 2, "the text is a valid rig");
        let span = s.place(Place::Bone {
            bone: 1,
            field: "parent",
        });
        assert_eq!(&text[span.clone()], "\"a\"");
        assert_eq!(src.line_col(span.start), (3, 66));
        let span = s.place(Place::Bone { bone: 0, field: "" });
        assert!(text[span].starts_with("(name: \"a,(\""));
    }
}
