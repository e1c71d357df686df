//! The documentation stands alone: every relative link in `README.md` and `docs/*.md` (links
//! `[text](target)`, images `![alt](target)` and reference definitions `[label]: target`)
//! names a file or folder that exists inside the repository, so nothing breaks in a fresh
//! clone. Web links (`http:`, `https:`), `mailto:` and links to an anchor of the same page
//! (`#…`) are not checked; a `#fragment` after a path is dropped before the path is checked.
//! Links inside code (fenced blocks, inline code spans) are not links and are skipped.

use std::path::{Component, Path, PathBuf};

fn root() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .canonicalize()
        .expect("the repository root exists")
}

/// A link found in a Markdown text: its 1-based line and its target as written.
#[derive(Debug, PartialEq)]
struct Link {
    line: usize,
    target: String,
}

/// Every link target of `text`, with its line: inline links and images (`[…](target)`,
/// `![…](target "title")`, `[…](<target>)`) and reference definitions (`[label]: target`).
/// Fenced code blocks and inline code spans are skipped.
fn links(text: &str) -> Vec<Link> {
    let mut out = Vec::new();
    let mut fence: Option<String> = None;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let trimmed = line.trim_start();
        // Fenced code blocks: ``` or ~~~ (three or more), closed by the same kind.
        let marker: String = trimmed
            .chars()
            .take_while(|&c| c == '`' || c == '~')
            .collect();
        if marker.len() >= 3 && marker.chars().all(|c| c == marker.chars().next().unwrap()) {
            match &fence {
                None => {
                    fence = Some(marker);
                    continue;
                }
                Some(open)
                    if marker.starts_with(open.as_str())
                        && trimmed[marker.len()..].trim().is_empty() =>
                {
                    fence = None;
                    continue;
                }
                Some(_) => {}
            }
        }
        if fence.is_some() {
            continue;
        }
        let visible = without_code_spans(line);
        // Reference definition: `[label]: target` at the start of a line.
        if let Some(rest) = trimmed.strip_prefix('[')
            && let Some(close) = rest.find("]:")
            && !rest[..close].is_empty()
            && !rest[..close].contains(']')
        {
            let target = rest[close + 2..].trim();
            if let Some(t) = first_token(target) {
                out.push(Link {
                    line: line_no,
                    target: t,
                });
            }
            continue;
        }
        // Inline links and images: `](` followed by the destination up to its closing `)`.
        let chars: Vec<char> = visible.chars().collect();
        let mut k = 0;
        while k + 1 < chars.len() {
            if chars[k] == ']' && chars[k + 1] == '(' {
                let mut depth = 1;
                let mut j = k + 2;
                let start = j;
                let mut in_angle = false;
                while j < chars.len() {
                    match chars[j] {
                        '<' if j == start => in_angle = true,
                        '>' if in_angle => in_angle = false,
                        '(' if !in_angle => depth += 1,
                        ')' if !in_angle => {
                            depth -= 1;
                            if depth == 0 {
                                break;
                            }
                        }
                        _ => {}
                    }
                    j += 1;
                }
                if j < chars.len() {
                    let dest: String = chars[start..j].iter().collect();
                    if let Some(t) = first_token(dest.trim()) {
                        out.push(Link {
                            line: line_no,
                            target: t,
                        });
                    }
                    k = j;
                }
            }
            k += 1;
        }
    }
    out
}

/// The line with every inline code span (`` `…` ``, any run of backticks) blanked out.
fn without_code_spans(line: &str) -> String {
    let chars: Vec<char> = line.chars().collect();
    let mut out = String::with_capacity(line.len());
    let mut i = 0;
    while i < chars.len() {
        if chars[i] == '`' {
            let run = chars[i..].iter().take_while(|&&c| c == '`').count();
            // Find the closing run of the same length.
            let mut j = i + run;
            let mut closed = None;
            while j < chars.len() {
                if chars[j] == '`' {
                    let r = chars[j..].iter().take_while(|&&c| c == '`').count();
                    if r == run {
                        closed = Some(j + r);
                        break;
                    }
                    j += r;
                } else {
                    j += 1;
                }
            }
            match closed {
                Some(end) => {
                    out.extend(std::iter::repeat_n(' ', end - i));
                    i = end;
                }
                None => {
                    out.extend(&chars[i..i + run]);
                    i += run;
                }
            }
        } else {
            out.push(chars[i]);
            i += 1;
        }
    }
    out
}

/// The destination of a link: `<…>` as a whole, else up to the first space (a title follows).
fn first_token(dest: &str) -> Option<String> {
    if let Some(rest) = dest.strip_prefix('<') {
        return rest.find('>').map(|e| rest[..e].to_string());
    }
    dest.split_whitespace().next().map(str::to_string)
}

/// `%XX` escapes decoded (a link to `my%20file.md` names `my file.md`).
fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i] == b'%' && i + 2 < bytes.len() {
            let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok();
            if let Some(v) = hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                out.push(v);
                i += 3;
                continue;
            }
        }
        out.push(bytes[i]);
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Why a link target does not resolve inside `root` from the Markdown file `file`, or `None`
/// when it does (or is not checked: web, mail and same-page anchor links).
fn problem(root: &Path, file: &Path, target: &str) -> Option<String> {
    let lower = target.to_ascii_lowercase();
    if lower.starts_with("http:")
        || lower.starts_with("https:")
        || lower.starts_with("mailto:")
        || target.starts_with('#')
    {
        return None;
    }
    if let Some(colon) = target.find(':') {
        let scheme = &target[..colon];
        if scheme.len() > 1
            && scheme
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || matches!(c, '+' | '-' | '.'))
        {
            // Another scheme (`ftp:`, `file:`…): not something a clone carries.
            return Some(format!("a `{scheme}:` link, not a file of the repository"));
        }
    }
    let path = target.split('#').next().unwrap_or("");
    let path = percent_decode(path.split('?').next().unwrap_or(""));
    if path.is_empty() {
        return Some("an empty link".into());
    }
    // A leading `/` is the repository root (as GitHub reads it); anything else is relative to
    // the Markdown file's folder.
    let base = if Path::new(&path).has_root() {
        root.to_path_buf()
    } else {
        file.parent().expect("a file has a folder").to_path_buf()
    };
    let joined = Path::new(&path)
        .components()
        .filter(|c| !matches!(c, Component::RootDir | Component::Prefix(_)))
        .fold(base, |p, c| p.join(c));
    match joined.canonicalize() {
        Err(_) => Some("no such file in the repository".into()),
        Ok(real) if !real.starts_with(root) => Some(format!(
            "resolves outside the repository ({}), which a clone does not have",
            real.display()
        )),
        Ok(_) => None,
    }
}

/// One message per broken link of `text` (the Markdown file `file`, shown as `shown`).
fn broken_links(root: &Path, file: &Path, shown: &str, text: &str) -> Vec<String> {
    links(text)
        .into_iter()
        .filter_map(|l| {
            problem(root, file, &l.target)
                .map(|why| format!("{shown}:{}: broken link `{}`: {why}", l.line, l.target))
        })
        .collect()
}

/// `README.md` and every `.md` file under `docs/`, in a fixed order.
fn documents(root: &Path) -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        let mut entries: Vec<PathBuf> = entries.filter_map(|e| Some(e.ok()?.path())).collect();
        entries.sort();
        for p in entries {
            if p.is_dir() {
                walk(&p, out);
            } else if p.extension().is_some_and(|e| e.eq_ignore_ascii_case("md")) {
                out.push(p);
            }
        }
    }
    let mut out = vec![root.join("README.md")];
    walk(&root.join("docs"), &mut out);
    out
}

#[test]
fn readme_and_docs_links_resolve_inside_the_repository() {
    let root = root();
    let docs = documents(&root);
    assert!(
        docs.iter().any(|p| p.ends_with("docs/methods.md"))
            && docs.iter().any(|p| p.ends_with("docs/design.md")),
        "docs/methods.md and docs/design.md should exist: found {docs:?}"
    );
    let mut broken = Vec::new();
    let mut checked = 0;
    for file in &docs {
        let text =
            std::fs::read_to_string(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let shown = file
            .strip_prefix(&root)
            .unwrap_or(file)
            .display()
            .to_string();
        checked += links(&text).len();
        broken.extend(broken_links(&root, file, &shown, &text));
    }
    assert!(
        checked > 0,
        "no links found in {docs:?}: the scanner is broken"
    );
    assert!(
        broken.is_empty(),
        "{} broken link(s) in the documentation:\n{}",
        broken.len(),
        broken.join("\n")
    );
}

#[test]
fn the_readme_links_the_projects_own_docs() {
    let root = root();
    let readme = std::fs::read_to_string(root.join("README.md")).unwrap();
    let targets: Vec<String> = links(&readme).into_iter().map(|l| l.target).collect();
    for want in ["docs/methods.md", "docs/design.md", "docs/architecture.md"] {
        assert!(
            targets.iter().any(|t| t == want),
            "README.md should link {want}; its links: {targets:?}"
        );
    }
}

/// The README as it was: its first paragraph linked the team's notes beside the checkout.
/// Those files may exist on a developer's machine, but outside the repository: broken.
#[test]
fn links_out_of_the_repository_are_caught() {
    let root = root();
    let readme = root.join("README.md");
    let old = "imprint computes how deforming bodies touch soft things.\n\
               The methods come from three papers restated in\n\
               English in [`../shared/METHODS.md`](../shared/METHODS.md); the code's shape is in\n\
               [`../shared/DESIGN.md`](../shared/DESIGN.md); how a frame runs is in\n\
               [`docs/architecture.md`](docs/architecture.md).\n";
    let broken = broken_links(&root, &readme, "README.md", old);
    assert_eq!(broken.len(), 2, "{broken:#?}");
    assert!(broken[0].starts_with("README.md:3: broken link `../shared/METHODS.md`"));
    assert!(broken[1].starts_with("README.md:4: broken link `../shared/DESIGN.md`"));

    // And with the same text in a file under docs/, `../shared` is inside the repository
    // only if such a folder exists there: it does not.
    let doc = root.join("docs").join("architecture.md");
    let broken = broken_links(&root, &doc, "docs/x.md", "see [x](../shared/METHODS.md)\n");
    assert_eq!(broken.len(), 1, "{broken:#?}");
    assert!(broken[0].contains("docs/x.md:1:"), "{broken:?}");
}

#[test]
fn what_the_scanner_reads_and_skips() {
    let text = "\
intro [a](README.md) and ![b](docs/frame.png \"a title\")
[c](docs/architecture.md#how-a-frame-runs) [d](#local) [e](https://example.com/x) [f](mailto:x@y.z)
`[not](a-link.md)` in code
```ron
[g](inside-a-fence.md)
```
[ref]: docs/missing.md
[nested ![img](docs/view.png)](docs/design.md) [h](<docs/methods.md>)
[i](missing.md) [j](foo(bar).md)
";
    let found: Vec<(usize, String)> = links(text)
        .into_iter()
        .map(|l| (l.line, l.target))
        .collect();
    let want: Vec<(usize, String)> = [
        (1, "README.md"),
        (1, "docs/frame.png"),
        (2, "docs/architecture.md#how-a-frame-runs"),
        (2, "#local"),
        (2, "https://example.com/x"),
        (2, "mailto:x@y.z"),
        (7, "docs/missing.md"),
        (8, "docs/view.png"),
        (8, "docs/design.md"),
        (8, "docs/methods.md"),
        (9, "missing.md"),
        (9, "foo(bar).md"),
    ]
    .into_iter()
    .map(|(l, t)| (l, t.to_string()))
    .collect();
    assert_eq!(found, want);

    let root = root();
    let readme = root.join("README.md");
    let broken = broken_links(&root, &readme, "README.md", text);
    let targets: Vec<&str> = broken
        .iter()
        .map(|m| m.split('`').nth(1).unwrap())
        .collect();
    assert_eq!(
        targets,
        ["docs/missing.md", "missing.md", "foo(bar).md"],
        "{broken:#?}"
    );
    assert_eq!(percent_decode("a%20b.md"), "a b.md");
}
