//! Loaders that never panic: structure-aware fuzzing (proptest, stable Rust) of the four
//! places where user input enters imprint: the pipeline RON ([`imprint_graph::parse`]), rig
//! files ([`imprint_graph::rig::parse`]), `--set NODE.FIELD=VALUE` overrides
//! ([`imprint_graph::overrides::apply_override`], then parsed as `plan::load` does) and the
//! OBJ reader ([`Mesh::from_obj_bytes`], the reader behind [`Mesh::load_obj`]).
//!
//! Inputs start from valid ones (the shipped `pipelines/*.ron`, `assets/rigs/limb.ron`,
//! small OBJ texts below) and are mutated: byte ranges deleted, inserted, replaced, copied;
//! tokens swapped; numbers made huge, negative, NaN, inf or 0; lines duplicated, dropped or
//! swapped; brackets unbalanced or nested deep; unknown fields and kinds; non-UTF-8 bytes.
//! Fully random inputs and random token soups are mixed in. The property: the loader
//! returns (Ok or Err) without panicking, every error says something, and a pipeline
//! error's line, column and span lie within the text it points into (on character
//! boundaries, so the CLI's excerpt can be drawn). A mesh read is valid (indices in range,
//! finite positions, one normal per vertex). Nothing is written to disk.
//!
//! The plain tests run a few thousand cases per loader, from a fixed seed. The ignored ones
//! run 100,000 cases each, from a random seed (the failing input is printed, shrunk):
//!
//! ```sh
//! cargo test --release -p imprint-tests --test fuzz_loaders -- --ignored --nocapture
//! ```
//!
//! (`FUZZ_CASES=N` changes the ignored tests' count; `FUZZ_SEED=N` fixes their seed.)

use imprint_core::Mesh;
use imprint_graph::diagnostics::{PipelineError, Source};
use imprint_graph::overrides::apply_override;
use imprint_graph::{Error, rig};
use proptest::prelude::*;
use proptest::sample::{Index, select};
use proptest::test_runner::{Config, RngSeed, TestCaseError, TestRunner};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

/// Cases per loader in the plain (CI) tests.
const CI_CASES: u32 = 3000;
/// Cases per loader in the ignored tests.
const FULL_CASES: u32 = 100_000;

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

fn pipelines_dir() -> PathBuf {
    root().join("pipelines")
}

fn rigs_dir() -> PathBuf {
    root().join("assets/rigs")
}

/// The shipped pipelines' texts, sorted by name.
fn shipped_pipelines() -> Vec<String> {
    let mut paths: Vec<PathBuf> = std::fs::read_dir(pipelines_dir())
        .expect("pipelines folder")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "ron"))
        .collect();
    paths.sort();
    assert!(!paths.is_empty(), "no shipped pipelines found");
    paths
        .iter()
        .map(|p| std::fs::read_to_string(p).expect("pipeline text"))
        .collect()
}

fn shipped_rig() -> String {
    std::fs::read_to_string(rigs_dir().join("limb.ron")).expect("limb.ron")
}

/// Small valid OBJ texts: a triangle, a quad, a cube with normals and texture coordinates
/// over two objects and groups, relative (negative) indices, a polygon, comments.
const OBJ_SEEDS: &[&str] = &[
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
    "# quad\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n",
    "o cube\nv -1 -1 -1\nv 1 -1 -1\nv 1 1 -1\nv -1 1 -1\nv -1 -1 1\nv 1 -1 1\nv 1 1 1\nv -1 1 1\n\
     vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 -1\nvn 0 0 1\nvn -1 0 0\nvn 1 0 0\nvn 0 -1 0\nvn 0 1 0\n\
     g front\nf 1/1/1 4/4/1 3/3/1 2/2/1\nf 5/1/2 6/2/2 7/3/2 8/4/2\n\
     g sides\nf 1/1/3 5/2/3 8/3/3 4/4/3\nf 2/1/4 3/2/4 7/3/4 6/4/4\n\
     o caps\nf 1//5 2//5 6//5 5//5\nf 4//6 8//6 7//6 3//6\n",
    "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0.5 0.5 1 1.0\nf -5 -4 -1\nf -4 -3 -1\nf -3 -2 -1\nf -2 -5 -1\n",
    "s 1\nusemtl none\nv 0 0 0 0.5 0.5 0.5\nv 2 0 0 1 0 0\nv 2 2 0 0 1 0\nv 1 3 0 0 0 1\nv 0 2 0 1 1 1\nvt 0 0\nf 1/1 2/1 3/1 4/1 5/1\nl 1 2\np 3\n",
    "v 0 0 0\nv 2 0 0\nv 2 2 0\nv 1 3 0\nv 0 2 0\nvt 0 0\nf 1/1 2/1 3/1 4/1 5/1\nl 1 2\np 3\n",
];

// ---------------------------------------------------------------------------------------
// Tokens: a small lexer (strings and comments whole), the words of the seeds and the
// paths of fields inside each node.

#[derive(Clone, Copy, Debug, PartialEq)]
enum Tk {
    Word,
    Str,
    Punct,
}

/// The tokens of `text` with their byte ranges (comments skipped).
fn lex(text: &[u8]) -> Vec<(Tk, std::ops::Range<usize>)> {
    let mut out = Vec::new();
    let mut i = 0;
    let word = |c: u8| c.is_ascii_alphanumeric() || b"_.+-".contains(&c) || c >= 0x80;
    while i < text.len() {
        let c = text[i];
        let start = i;
        if c == b'/' && text.get(i + 1) == Some(&b'/') {
            while i < text.len() && text[i] != b'\n' {
                i += 1;
            }
        } else if c == b'/' && text.get(i + 1) == Some(&b'*') {
            i += 2;
            while i + 1 < text.len() && !(text[i] == b'*' && text[i + 1] == b'/') {
                i += 1;
            }
            i = (i + 2).min(text.len());
        } else if c == b'"' {
            i += 1;
            while i < text.len() && text[i] != b'"' {
                i += if text[i] == b'\\' { 2 } else { 1 };
            }
            i = (i + 1).min(text.len());
            out.push((Tk::Str, start..i));
        } else if word(c) {
            while i < text.len() && word(text[i]) {
                i += 1;
            }
            out.push((Tk::Word, start..i));
        } else if c.is_ascii_whitespace() {
            i += 1;
        } else {
            i += 1;
            out.push((Tk::Punct, start..i));
        }
    }
    out
}

fn is_number(tok: &[u8]) -> bool {
    let t = tok.strip_prefix(b"-").unwrap_or(tok);
    t.first().is_some_and(|c| c.is_ascii_digit())
        || (t.first() == Some(&b'.') && t.get(1).is_some_and(|c| c.is_ascii_digit()))
}

/// Every distinct word and string of the texts (identifiers, kinds, node names, paths).
fn words_of(texts: &[String]) -> Vec<String> {
    let mut set = std::collections::BTreeSet::new();
    for t in texts {
        for (k, r) in lex(t.as_bytes()) {
            if k != Tk::Punct && !is_number(&t.as_bytes()[r.clone()]) {
                set.insert(t[r].to_string());
            }
        }
    }
    set.into_iter().collect()
}

/// `NODE.FIELD[.FIELD…]` for every field written inside a node of a pipeline (nested
/// structures included, list items too), from the keys at each bracket depth, with the
/// value's text as written.
fn field_values(text: &str) -> Vec<(String, String)> {
    let toks = lex(text.as_bytes());
    let tok = |k: usize| &text[toks[k].1.clone()];
    let mut keys: Vec<Option<String>> = vec![None; 64];
    let mut depth = 0usize;
    let mut out = Vec::new();
    for k in 0..toks.len() {
        let s = tok(k);
        match (toks[k].0, s) {
            (Tk::Punct, "(" | "[" | "{") => depth = (depth + 1).min(63),
            (Tk::Punct, ")" | "]" | "}") => {
                keys[depth] = None;
                depth = depth.saturating_sub(1);
            }
            (Tk::Word | Tk::Str, _) if k + 2 < toks.len() && tok(k + 1) == ":" => {
                keys[depth] = Some(s.trim_matches('"').to_string());
                // depth 2: node keys inside `nodes: { … }`.
                if depth > 2
                    && let Some(path) = (2..=depth)
                        .map(|d| keys[d].clone())
                        .collect::<Option<Vec<String>>>()
                {
                    // The value: up to the comma or closer at its own depth.
                    let (mut d, mut last) = (0i32, k + 2);
                    for j in k + 2..toks.len() {
                        match tok(j) {
                            "(" | "[" | "{" => d += 1,
                            ")" | "]" | "}" if d == 0 => break,
                            ")" | "]" | "}" => d -= 1,
                            "," if d == 0 => break,
                            _ => {}
                        }
                        last = j;
                    }
                    let value = &text[toks[k + 2].1.start..toks[last].1.end];
                    out.push((path.join("."), value.to_string()));
                }
            }
            _ => {}
        }
    }
    out.sort();
    out.dedup();
    out
}

fn field_paths(text: &str) -> Vec<String> {
    let mut paths: Vec<String> = field_values(text).into_iter().map(|(p, _)| p).collect();
    paths.dedup();
    paths
}

/// Node names of a pipeline (keys at depth 2).
fn node_names(text: &str) -> Vec<String> {
    let mut names: Vec<String> = field_paths(text)
        .iter()
        .filter_map(|p| p.split('.').next().map(str::to_string))
        .collect();
    names.sort();
    names.dedup();
    names
}

// ---------------------------------------------------------------------------------------
// Mutations.

/// One edit of an input; positions are fractions of its current length.
#[derive(Clone, Debug)]
enum Edit {
    Delete(Index, usize),
    Insert(Index, Vec<u8>),
    Replace(Index, usize, Vec<u8>),
    /// Copy a byte range to another place (duplicated fields, nodes, lines).
    Copy(Index, usize, Index),
    SwapTokens(Index, Index),
    /// Replace the n-th number by another.
    Number(Index, Vec<u8>),
    /// Replace the n-th word or string by another token.
    Word(Index, Vec<u8>),
    DupLine(Index),
    DropLine(Index),
    SwapLines(Index, Index),
    /// Insert `n` copies of an opening (or closing) bracket.
    Nest(Index, u8, usize),
}

fn at(i: &Index, len: usize) -> usize {
    if len == 0 { 0 } else { i.index(len + 1) }
}

fn pick<'a, T>(i: &Index, v: &'a [T]) -> Option<&'a T> {
    (!v.is_empty()).then(|| &v[i.index(v.len())])
}

fn line_ranges(b: &[u8]) -> Vec<std::ops::Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for (i, &c) in b.iter().enumerate() {
        if c == b'\n' {
            out.push(start..i + 1);
            start = i + 1;
        }
    }
    if start < b.len() {
        out.push(start..b.len());
    }
    out
}

fn apply(mut b: Vec<u8>, edits: &[Edit]) -> Vec<u8> {
    for e in edits {
        let len = b.len();
        match e {
            Edit::Delete(p, n) => {
                let s = at(p, len);
                b.drain(s..(s + n).min(len));
            }
            Edit::Insert(p, t) => {
                let s = at(p, len);
                b.splice(s..s, t.iter().copied());
            }
            Edit::Replace(p, n, t) => {
                let s = at(p, len);
                b.splice(s..(s + n).min(len), t.iter().copied());
            }
            Edit::Copy(p, n, to) => {
                let s = at(p, len);
                let piece = b[s..(s + n).min(len)].to_vec();
                let d = at(to, len);
                b.splice(d..d, piece);
            }
            Edit::SwapTokens(x, y) => {
                let toks = lex(&b);
                if let (Some(x), Some(y)) = (pick(x, &toks), pick(y, &toks)) {
                    let (x, y) = if x.1.start <= y.1.start {
                        (x, y)
                    } else {
                        (y, x)
                    };
                    if x.1.end <= y.1.start {
                        let (tx, ty) = (b[x.1.clone()].to_vec(), b[y.1.clone()].to_vec());
                        b.splice(y.1.clone(), tx);
                        b.splice(x.1.clone(), ty);
                    }
                }
            }
            Edit::Number(i, t) => {
                let nums: Vec<_> = lex(&b)
                    .into_iter()
                    .filter(|(k, r)| *k == Tk::Word && is_number(&b[r.clone()]))
                    .collect();
                if let Some((_, r)) = pick(i, &nums) {
                    b.splice(r.clone(), t.iter().copied());
                }
            }
            Edit::Word(i, t) => {
                let words: Vec<_> = lex(&b)
                    .into_iter()
                    .filter(|(k, r)| *k != Tk::Punct && !is_number(&b[r.clone()]))
                    .collect();
                if let Some((_, r)) = pick(i, &words) {
                    b.splice(r.clone(), t.iter().copied());
                }
            }
            Edit::DupLine(i) => {
                if let Some(r) = pick(i, &line_ranges(&b)).cloned() {
                    let line = b[r.clone()].to_vec();
                    b.splice(r.end..r.end, line);
                }
            }
            Edit::DropLine(i) => {
                if let Some(r) = pick(i, &line_ranges(&b)).cloned() {
                    b.drain(r);
                }
            }
            Edit::SwapLines(x, y) => {
                let lines = line_ranges(&b);
                if let (Some(x), Some(y)) = (pick(x, &lines), pick(y, &lines)) {
                    let (x, y) = if x.start <= y.start { (x, y) } else { (y, x) };
                    if x.end <= y.start {
                        let (tx, ty) = (b[x.clone()].to_vec(), b[y.clone()].to_vec());
                        b.splice(y.clone(), tx);
                        b.splice(x.clone(), ty);
                    }
                }
            }
            Edit::Nest(p, c, n) => {
                let s = at(p, len);
                b.splice(s..s, std::iter::repeat_n(*c, *n));
            }
        }
    }
    b
}

/// Numbers that break things: huge, negative, NaN, inf, zero, malformed.
const NUMBERS: &[&str] = &[
    "0",
    "-0",
    "0.0",
    "-0.0",
    "1",
    "-1",
    "2",
    "3",
    "-3",
    "0.5",
    "-0.5",
    "NaN",
    "nan",
    "-NaN",
    "inf",
    "-inf",
    "+inf",
    "infinity",
    "1e39",
    "-1e39",
    "3.4028235e38",
    "1e308",
    "1e309",
    "-1e309",
    "1e-45",
    "1e-320",
    "4294967295",
    "4294967296",
    "-4294967296",
    "2147483647",
    "-2147483648",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "340282366920938463463374607431768211456",
    "99999999999999999999999999999999999999999",
    "65535",
    "65536",
    "16777217",
    "100000",
    "1000000",
    "0x10",
    "0b101",
    "0o17",
    "1_000",
    ".5",
    "5.",
    "+1",
    "1e",
    "--1",
    "1.2.3",
    "-",
    ".",
    "e5",
    "1e+",
    "0x",
    "00",
    "007",
];

/// Tokens of RON and of the loaders' formats, good and bad.
const TOKENS: &[&str] = &[
    "(",
    ")",
    "[",
    "]",
    "{",
    "}",
    ",",
    ":",
    "\"",
    "'",
    "//",
    "/*",
    "*/",
    "\\",
    "\n",
    " ",
    "#",
    "Some(",
    "None",
    "true",
    "false",
    "()",
    "[]",
    "{}",
    "\"\"",
    "Some(())",
    "r#\"raw\"#",
    "b\"bytes\"",
    "'c'",
    "\"\\u{0}\"",
    "\"\\x\"",
    "\"\\u{110000}\"",
    "#![enable(implicit_some)]",
    "#![enable(unwrap_newtypes)]",
    "Bogus(",
    "NotAKind()",
    "unknown_field: 1,",
    "nodes: {},",
    "\"nope\"",
    "\"../nope.obj\"",
    "\"/\"",
    "\"\"",
    "\u{b0}",
    "\u{e9}",
    "\u{2192}",
    "\u{1f980}",
    "\u{0}",
    "\u{feff}",
    "\u{fffd}",
    "\u{b0}band",
    "\u{2192}x: 1",
    "\t",
    "\r\n",
    ": :",
    ",,",
    "Pipeline(",
    "Rig(",
    "frames:",
    "fps:",
    "nodes:",
    "bones:",
    "animation:",
    "mesh:",
    "(1, 2)",
    "(0, 0, 0)",
    "(1, 2, 3, 4)",
    "[1, 2, 3]",
    "Fit(",
    "Mesh(",
    "Keys(",
    "Bend(",
    "Twist(",
    "parent:",
    "name:",
    "keys:",
    "Linear",
    "Step",
    "Smooth",
    "Cpu",
    "Gpu",
    "Auto",
];

/// OBJ lines and pieces: faces of 0, 1, 2 vertices, out-of-range, zero and negative
/// indices, odd statements.
const OBJ_TOKENS: &[&str] = &[
    "\nf\n",
    "\nf 1\n",
    "\nf 1 2\n",
    "\nf 1 2 3\n",
    "\nf 0 0 0\n",
    "\nf -1 -2 -3\n",
    "\nf -100 1 2\n",
    "\nf 1 2 99\n",
    "\nf 4294967295 1 2\n",
    "\nf 4294967296 1 2\n",
    "\nf 1/1/1 2/2/2 3/3/3\n",
    "\nf 1//1 2//2 3//3\n",
    "\nf 1/ 2/ 3/\n",
    "\nf 1/-1 2/-9 3/0\n",
    "\nf a b c\n",
    "\nf 1 1 1 1 1 1 1\n",
    "\nv\n",
    "\nv 1\n",
    "\nv 1 2\n",
    "\nv 1 2 3\n",
    "\nv 1 2 3 4\n",
    "\nv 1 2 3 4 5\n",
    "\nv 1 2 3 4 5 6\n",
    "\nv 1 2 3 4 5 6 7\n",
    "\nv nan nan nan\n",
    "\nv inf 0 0\n",
    "\nv 1e39 0 0\n",
    "\nvt\n",
    "\nvt 1\n",
    "\nvt 1 2 3\n",
    "\nvn\n",
    "\nvn 0 0 0\n",
    "\nvn nan 1 0\n",
    "\no\n",
    "\no x\n",
    "\ng\n",
    "\ng a b\n",
    "\nusemtl\n",
    "\nusemtl m\n",
    "\nmtllib\n",
    "\nmtllib x.mtl\n",
    "\ns off\n",
    "\nl 1 2\n",
    "\np 1\n",
    "\n# c\n",
    "\\\n",
    "\r\n",
    "\t",
    " ",
    "/",
    "//",
    "-",
    "\u{0}",
    "\u{fffd}",
];

/// Bytes that are not UTF-8 (for the OBJ reader; the text loaders see them as U+FFFD).
const NON_UTF8: &[&[u8]] = &[
    b"\xff",
    b"\xfe\xff",
    b"\xc3",
    b"\xe2\x82",
    b"\xf0\x9f\xa6",
    b"\x80",
    b"\xed\xa0\x80",
    b"\xc0\xaf",
];

fn bytes_of(v: &[&str]) -> Vec<Vec<u8>> {
    v.iter().map(|s| s.as_bytes().to_vec()).collect()
}

/// A token: from the format's dictionary, a number, random printable text, any bytes.
fn token(dict: Vec<Vec<u8>>) -> BoxedStrategy<Vec<u8>> {
    prop_oneof![
        6 => select(dict),
        3 => select(bytes_of(NUMBERS)),
        1 => select(NON_UTF8.iter().map(|b| b.to_vec()).collect::<Vec<_>>()),
        2 => "[ -~]{0,12}".prop_map(String::into_bytes),
        1 => any::<String>().prop_map(|s| s.chars().take(8).collect::<String>().into_bytes()),
        1 => proptest::collection::vec(any::<u8>(), 0..8),
    ]
    .boxed()
}

fn edit(dict: Vec<Vec<u8>>) -> BoxedStrategy<Edit> {
    let tok = token(dict);
    prop_oneof![
        3 => (any::<Index>(), 1usize..40).prop_map(|(p, n)| Edit::Delete(p, n)),
        3 => (any::<Index>(), tok.clone()).prop_map(|(p, t)| Edit::Insert(p, t)),
        3 => (any::<Index>(), 1usize..12, tok.clone()).prop_map(|(p, n, t)| Edit::Replace(p, n, t)),
        1 => (any::<Index>(), 1usize..200, any::<Index>()).prop_map(|(p, n, d)| Edit::Copy(p, n, d)),
        2 => (any::<Index>(), any::<Index>()).prop_map(|(x, y)| Edit::SwapTokens(x, y)),
        4 => (any::<Index>(), select(bytes_of(NUMBERS))).prop_map(|(i, t)| Edit::Number(i, t)),
        3 => (any::<Index>(), tok).prop_map(|(i, t)| Edit::Word(i, t)),
        1 => any::<Index>().prop_map(Edit::DupLine),
        1 => any::<Index>().prop_map(Edit::DropLine),
        1 => (any::<Index>(), any::<Index>()).prop_map(|(x, y)| Edit::SwapLines(x, y)),
        1 => (any::<Index>(), select(b"([{)]}\"".to_vec()), prop_oneof![1usize..8, 100usize..3000])
            .prop_map(|(p, c, n)| Edit::Nest(p, c, n)),
    ]
    .boxed()
}

/// Inputs: a seed with up to 8 edits (most cases), random bytes, or a soup of tokens.
fn inputs(seeds: Vec<Vec<u8>>, dict: Vec<Vec<u8>>) -> BoxedStrategy<Vec<u8>> {
    let mutated = (
        select(seeds),
        proptest::collection::vec(edit(dict.clone()), 0..8),
    )
        .prop_map(|(seed, edits)| apply(seed, &edits));
    prop_oneof![
        16 => mutated,
        1 => proptest::collection::vec(any::<u8>(), 0..400),
        2 => proptest::collection::vec(token(dict), 0..80).prop_map(|ts| ts.join(&b' ')),
    ]
    .boxed()
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

// ---------------------------------------------------------------------------------------
// Properties.

/// Counts of what the loader said, printed after a run.
#[derive(Default)]
struct Tally {
    ok: AtomicUsize,
    err: AtomicUsize,
}

impl Tally {
    fn add<T, E>(&self, r: &Result<T, E>) {
        let c = if r.is_ok() { &self.ok } else { &self.err };
        c.fetch_add(1, Ordering::Relaxed);
    }
}

/// An error's message is not empty; a pipeline error's line, column and span lie within the
/// text it points into (the text parsed, or a file it names, such as a rig), on character
/// boundaries, and agree with each other.
fn check_error(parsed_name: &str, parsed: &str, e: &Error) -> Result<(), TestCaseError> {
    let msg = e.to_string();
    prop_assert!(!msg.trim().is_empty(), "empty error message: {e:?}");
    if let Error::Pipeline(p) = e {
        check_located(parsed_name, parsed, p)?;
    }
    Ok(())
}

fn check_located(parsed_name: &str, parsed: &str, p: &PipelineError) -> Result<(), TestCaseError> {
    prop_assert!(!p.message.trim().is_empty(), "empty message: {p:?}");
    let text: &str = p.src.inner();
    if p.file == parsed_name {
        prop_assert_eq!(text, parsed, "the error's source is not the text parsed");
    }
    let lines: Vec<&str> = text.split('\n').collect();
    prop_assert!(
        (1..=lines.len()).contains(&p.line),
        "line {} outside 1..={} ({})",
        p.line,
        lines.len(),
        p.message
    );
    let width = lines[p.line - 1].chars().count();
    prop_assert!(
        (1..=width + 1).contains(&p.column),
        "column {} outside 1..={} on line {} ({})",
        p.column,
        width + 1,
        p.line,
        p.message
    );
    let (start, end) = (p.span.offset(), p.span.offset() + p.span.len());
    prop_assert!(
        end <= text.len(),
        "span {start}..{end} past the end ({})",
        text.len()
    );
    prop_assert!(
        text.is_char_boundary(start) && text.is_char_boundary(end),
        "span {start}..{end} splits a character"
    );
    let src = Source {
        name: p.file.clone(),
        text: text.to_string(),
    };
    prop_assert_eq!(
        src.line_col(start),
        (p.line, p.column),
        "line/column is not the span's start"
    );
    Ok(())
}

const PIPELINE_NAME: &str = "fuzz.ron";

fn parse_pipeline(t: &str) -> imprint_graph::Result<imprint_graph::Plan> {
    imprint_graph::parse(
        Source {
            name: PIPELINE_NAME.into(),
            text: t.to_string(),
        },
        &pipelines_dir(),
    )
}

fn pipeline_property(tally: &Tally, b: &[u8]) -> Result<(), TestCaseError> {
    let t = text(b);
    let r = parse_pipeline(&t);
    tally.add(&r);
    if let Err(e) = &r {
        check_error(PIPELINE_NAME, &t, e)?;
    }
    Ok(())
}

const RIG_NAME: &str = "fuzz_rig.ron";

fn rig_property(tally: &Tally, b: &[u8]) -> Result<(), TestCaseError> {
    let t = text(b);
    let r = rig::parse(
        &Source {
            name: RIG_NAME.into(),
            text: t.clone(),
        },
        &rigs_dir(),
    );
    tally.add(&r);
    if let Err(e) = &r {
        check_error(RIG_NAME, &t, e)?;
    }
    Ok(())
}

fn obj_property(tally: &Tally, b: &[u8]) -> Result<(), TestCaseError> {
    let r = Mesh::from_obj_bytes(b, "fuzz.obj");
    tally.add(&r);
    match r {
        Err(e) => {
            let msg = e.to_string();
            prop_assert!(!msg.trim().is_empty(), "empty error message: {e:?}");
        }
        Ok(m) => {
            m.validate("fuzz.obj")
                .map_err(|e| TestCaseError::fail(format!("an invalid mesh was read: {e}")))?;
            prop_assert_eq!(m.normals.len(), m.positions.len());
            if let Some(uv) = &m.uvs {
                prop_assert_eq!(uv.len(), m.positions.len());
            }
        }
    }
    Ok(())
}

/// `--set` cases: a shipped pipeline (sometimes itself mutated) and 1 to 3 assignments.
#[derive(Clone, Debug)]
struct SetCase {
    text: Vec<u8>,
    sets: Vec<String>,
}

fn set_cases() -> BoxedStrategy<SetCase> {
    let texts = shipped_pipelines();
    let all_values: Vec<String> = texts
        .iter()
        .flat_map(|t| field_values(t).into_iter().map(|(_, v)| v))
        .collect();
    let all_fields: Vec<String> = texts
        .iter()
        .flat_map(|t| field_paths(t))
        .flat_map(|p| p.split('.').skip(1).map(str::to_string).collect::<Vec<_>>())
        .collect();
    let dict: Vec<Vec<u8>> = bytes_of(TOKENS)
        .into_iter()
        .chain(words_of(&texts).into_iter().map(String::into_bytes))
        .collect();
    let value: BoxedStrategy<String> = prop_oneof![
        // A value written somewhere in a shipped pipeline (often the right type).
        5 => select(all_values),
        4 => select(NUMBERS.iter().map(|s| s.to_string()).collect::<Vec<_>>()),
        3 => select(TOKENS.iter().map(|s| s.to_string()).collect::<Vec<_>>()),
        2 => proptest::collection::vec(token(dict.clone()), 0..6).prop_map(|t| text(&t.join(&b' '))),
        1 => Just(String::new()),
        1 => any::<String>(),
    ]
    .boxed();
    let part = |names: Vec<String>| -> BoxedStrategy<String> {
        prop_oneof![
            8 => select(names),
            1 => Just(String::new()),
            1 => "[a-z_]{1,8}",
            1 => "[ -~]{0,6}",
            1 => any::<String>().prop_map(|s| s.chars().take(6).collect()),
        ]
        .boxed()
    };
    let sep = select(vec!["=", "=", "=", "=", "=", "=", " = ", "", "==", ":"]);
    // Per pipeline: its own node names and field paths.
    let per_pipeline: Vec<BoxedStrategy<SetCase>> = texts
        .iter()
        .map(|t| {
            let path: BoxedStrategy<String> = prop_oneof![
                // A real path of this pipeline (nested fields included).
                6 => select(field_paths(t)),
                // A node and 0 to 3 fields of any node.
                3 => (part(node_names(t)), proptest::collection::vec(part(all_fields.clone()), 0..4))
                    .prop_map(|(n, f)| std::iter::once(n).chain(f).collect::<Vec<_>>().join(".")),
            ]
            .boxed();
            let set = prop_oneof![
                // A field of this pipeline set to what it already says (a valid override).
                1 => select(field_values(t)).prop_map(|(p, v)| format!("{p}={v}")),
                4 => (path, sep.clone(), value.clone()).prop_map(|(p, s, v)| format!("{p}{s}{v}")),
            ];
            let light = proptest::collection::vec(edit(dict.clone()), 0..3);
            let base = (
                Just(t.clone().into_bytes()),
                prop_oneof![4 => Just(Vec::new()), 1 => light],
            )
                .prop_map(|(t, edits)| apply(t, &edits));
            (base, proptest::collection::vec(set, 1..4))
                .prop_map(|(text, sets)| SetCase { text, sets })
                .boxed()
        })
        .collect();
    proptest::strategy::Union::new(per_pipeline).boxed()
}

fn set_property(tally: &Tally, case: &SetCase) -> Result<(), TestCaseError> {
    let mut t = text(&case.text);
    for s in &case.sets {
        match apply_override(&t, s) {
            Ok(next) => t = next,
            Err(e) => {
                tally.add(&Err::<(), _>(()));
                prop_assert!(!e.to_string().trim().is_empty(), "empty --set error: {e:?}");
                return Ok(());
            }
        }
    }
    pipeline_property(tally, t.as_bytes())
}

// ---------------------------------------------------------------------------------------
// Runner.

fn seed_from_env(fixed: Option<u64>) -> RngSeed {
    match std::env::var("FUZZ_SEED").ok().and_then(|s| s.parse().ok()) {
        Some(s) => RngSeed::Fixed(s),
        None => fixed.map_or(RngSeed::Random, RngSeed::Fixed),
    }
}

/// Runs `property` over `cases` inputs of `strategy`; fails with the shrunk input on the
/// first panic or broken property. CI runs use a fixed seed.
fn fuzz<T: std::fmt::Debug>(
    what: &str,
    cases: u32,
    seed: RngSeed,
    strategy: BoxedStrategy<T>,
    property: impl Fn(&Tally, &T) -> Result<(), TestCaseError>,
) {
    let config = Config {
        cases,
        failure_persistence: None,
        max_shrink_iters: 20_000,
        rng_seed: seed,
        ..Config::default()
    };
    let mut runner = TestRunner::new(config);
    let tally = Tally::default();
    let start = Instant::now();
    let result = runner.run(&strategy, |v| property(&tally, &v));
    let secs = start.elapsed().as_secs_f64();
    let (ok, err) = (tally.ok.into_inner(), tally.err.into_inner());
    if let Err(e) = result {
        panic!(
            "{what}: {e} ({} inputs tried, shrinking included, in {secs:.1} s)",
            ok + err
        );
    }
    println!(
        "{what}: {cases} cases in {secs:.1} s ({:.0}/s): {ok} read, {err} refused",
        cases as f64 / secs.max(1e-9)
    );
}

fn full_cases() -> u32 {
    std::env::var("FUZZ_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(FULL_CASES)
}

fn pipeline_inputs() -> BoxedStrategy<Vec<u8>> {
    let texts = shipped_pipelines();
    let dict = bytes_of(TOKENS)
        .into_iter()
        .chain(words_of(&texts).into_iter().map(String::into_bytes))
        .collect();
    inputs(texts.into_iter().map(String::into_bytes).collect(), dict)
}

fn rig_inputs() -> BoxedStrategy<Vec<u8>> {
    let texts = vec![shipped_rig(), rig_with_keys()];
    let dict = bytes_of(TOKENS)
        .into_iter()
        .chain(words_of(&texts).into_iter().map(String::into_bytes))
        .collect();
    inputs(texts.into_iter().map(String::into_bytes).collect(), dict)
}

/// A second valid rig seed: keyed motion (every field of a key), three bones, a mesh
/// binding, comments.
fn rig_with_keys() -> String {
    r#"// keys
Rig(
    mesh: "../meshes/cow.obj", /* bound */
    bones: [
        (name: "root", head: (0, 0, 0), tail: (0, 1, 0)),
        (name: "a", head: (0, 1, 0), tail: (0, 2, 0), parent: "root"),
        (name: "b", head: (0, 2, 0), tail: (0, 3, 0), parent: "a"),
    ],
    animation: [
        Keys(bone: "root", keys: [
            (time: 0.0, translation: (0, 0, 0)),
            (time: 1.0, translation: (0, 1, 0), rotation: (axis: (0, 0, 1), degrees: 45)),
        ]),
        Keys(bone: "b", interpolation: Linear, keys: [
            (time: 0.0, rotation: (axis: (1, 0, 0), degrees: 0)),
            (time: 0.5, rotation: (axis: (1, 0, 0), degrees: 90)),
        ]),
        Twist(bone: "a", degrees: 30, start: 0.0, duration: 2.0),
    ],
)
"#
    .to_string()
}

fn obj_inputs() -> BoxedStrategy<Vec<u8>> {
    let seeds = OBJ_SEEDS.iter().map(|s| s.as_bytes().to_vec()).collect();
    let dict = bytes_of(OBJ_TOKENS);
    prop_oneof![
        12 => inputs(seeds, dict.clone()),
        // OBJ lines in any order and number.
        4 => proptest::collection::vec(token(dict), 0..60).prop_map(|ls| ls.concat()),
    ]
    .boxed()
}

// ---------------------------------------------------------------------------------------
// The seeds are valid: the mutations start from inputs that load.

#[test]
fn seeds_load() {
    for (i, t) in shipped_pipelines().iter().enumerate() {
        if let Err(e) = parse_pipeline(t) {
            panic!("shipped pipeline {i} does not parse: {e}");
        }
        assert!(!field_paths(t).is_empty() && !node_names(t).is_empty());
    }
    for t in [shipped_rig(), rig_with_keys()] {
        let src = Source {
            name: RIG_NAME.into(),
            text: t,
        };
        if let Err(e) = rig::parse(&src, &rigs_dir()) {
            panic!("rig seed does not parse: {e}");
        }
    }
    for s in OBJ_SEEDS {
        if let Err(e) = Mesh::from_obj_bytes(s.as_bytes(), "seed.obj") {
            panic!("OBJ seed does not load: {e}\n{s}");
        }
    }
    // The in-memory reader is the file reader.
    let path = root().join("assets/meshes/suzanne.obj");
    let bytes = std::fs::read(&path).expect("suzanne.obj");
    let from_file = Mesh::load_obj(&path).expect("suzanne loads");
    assert_eq!(
        Mesh::from_obj_bytes(&bytes, "suzanne.obj").expect("from bytes"),
        from_file
    );
}

// ---------------------------------------------------------------------------------------
// CI scale.

#[test]
fn pipeline_parse_never_panics() {
    fuzz(
        "pipeline",
        CI_CASES,
        seed_from_env(Some(1)),
        pipeline_inputs(),
        |t, b| pipeline_property(t, b),
    );
}

#[test]
fn rig_parse_never_panics() {
    fuzz(
        "rig",
        CI_CASES,
        seed_from_env(Some(2)),
        rig_inputs(),
        |t, b| rig_property(t, b),
    );
}

#[test]
fn set_overrides_never_panic() {
    fuzz(
        "--set",
        CI_CASES,
        seed_from_env(Some(3)),
        set_cases(),
        set_property,
    );
}

#[test]
fn obj_reader_never_panics() {
    fuzz(
        "obj",
        CI_CASES,
        seed_from_env(Some(4)),
        obj_inputs(),
        |t, b| obj_property(t, b),
    );
}

// ---------------------------------------------------------------------------------------
// Full scale (ignored): 100,000 cases each, random seed.
//   cargo test --release -p imprint-tests --test fuzz_loaders -- --ignored --nocapture

/// 100,000 pipeline texts (`FUZZ_CASES`, `FUZZ_SEED` to change):
/// `cargo test --release -p imprint-tests --test fuzz_loaders -- --ignored`
#[test]
#[ignore = "long: 100,000 cases"]
fn pipeline_parse_never_panics_full() {
    fuzz(
        "pipeline (full)",
        full_cases(),
        seed_from_env(None),
        pipeline_inputs(),
        |t, b| pipeline_property(t, b),
    );
}

/// 100,000 rig texts:
/// `cargo test --release -p imprint-tests --test fuzz_loaders -- --ignored`
#[test]
#[ignore = "long: 100,000 cases"]
fn rig_parse_never_panics_full() {
    fuzz(
        "rig (full)",
        full_cases(),
        seed_from_env(None),
        rig_inputs(),
        |t, b| rig_property(t, b),
    );
}

/// 100,000 `--set` cases:
/// `cargo test --release -p imprint-tests --test fuzz_loaders -- --ignored`
#[test]
#[ignore = "long: 100,000 cases"]
fn set_overrides_never_panic_full() {
    fuzz(
        "--set (full)",
        full_cases(),
        seed_from_env(None),
        set_cases(),
        set_property,
    );
}

/// 100,000 OBJ byte strings:
/// `cargo test --release -p imprint-tests --test fuzz_loaders -- --ignored`
#[test]
#[ignore = "long: 100,000 cases"]
fn obj_reader_never_panics_full() {
    fuzz(
        "obj (full)",
        full_cases(),
        seed_from_env(None),
        obj_inputs(),
        |t, b| obj_property(t, b),
    );
}

// ---------------------------------------------------------------------------------------
// Regressions: panics the fuzzing found, as plain tests.

/// `--set` panicked ("byte index is not a char boundary", overrides.rs `find_field`) when a
/// field name in the node's body followed a character wider than a byte that cannot be part
/// of a name (`°band:`, or U+FFFD where a file had a byte that is not UTF-8): the name's
/// start was taken as one byte past that character. Found by `set_overrides_never_panic`
/// (`cloth.colliders=…` on a pipeline with U+FFFD before `colliders:`).
#[test]
fn set_after_a_wide_character_does_not_panic() {
    for wide in ["\u{b0}", "\u{fffd}", "\u{1f980}"] {
        let text = format!(
            "Pipeline(frames: 2, nodes: {{\n    \"m\": Mesh(primitive: Sphere(radius: 1.0)),\n    \
             \"vox\": Voxelize(mesh: \"m\", {wide}grid: Fit(resolution: 64, padding: 0.1)),\n}})"
        );
        let set = apply_override(&text, "vox.grid=Fit(resolution: 32, padding: 0.1)")
            .expect("the field after the wide character is found");
        assert!(
            set.contains(&format!("{wide}grid: Fit(resolution: 32, padding: 0.1)")),
            "{set}"
        );
        let nested = apply_override(&text, "vox.grid.resolution=16").expect("nested");
        assert!(
            nested.contains("Fit(resolution: 16, padding: 0.1)"),
            "{nested}"
        );
        // The character itself is then a located RON error, not a panic.
        let e = parse_pipeline(&set).expect_err("the wide character is not RON");
        check_error(PIPELINE_NAME, &set, &e).expect("located");
    }
}

/// A RON error at a character wider than a byte that ends a token (U+2000 EN QUAD, U+00A0
/// NO-BREAK SPACE: whitespace) got a span of one byte, splitting the character
/// (diagnostics.rs `ron_error`); the span now covers the whole character. Found by the
/// full-scale pipeline and rig runs (a pipeline of just U+2000; `head\u{a0} (0.5, 0, 0)` in
/// limb.ron).
#[test]
fn ron_error_spans_whole_characters() {
    for text in [
        "\u{2000}",
        "\u{a0}",
        "Pipeline(\u{2000}frames: 1)",
        "\u{1f980}",
    ] {
        let e = parse_pipeline(text).expect_err("not a pipeline");
        check_error(PIPELINE_NAME, text, &e).expect("located on whole characters");
    }
    let rig = shipped_rig().replacen("head:", "head\u{a0}", 2);
    let src = Source {
        name: RIG_NAME.into(),
        text: rig.clone(),
    };
    let e = rig::parse(&src, &rigs_dir()).expect_err("not a rig");
    check_error(RIG_NAME, &rig, &e).expect("located on whole characters");
}
