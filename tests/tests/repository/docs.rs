//! The docs hold together, checked on the files (no network, no mdBook): every page that the
//! book's `docs/src/SUMMARY.md` lists exists and every page under `docs/src` is listed; every
//! relative link of README.md, ARCHITECTURE.md, BENCHMARKS.md and the book resolves to a file in
//! the repository, and its `#anchor` to a heading of the page it names (the ids mdBook and
//! GitHub give headings); every repository path the docs name in backticks or in a link
//! (`common/x/src/y.rs`, `scripts/bench.sh`) exists. Each checker is unit-tested below on inline
//! text, so a broken link, a missing page or a stale path fails.

use std::collections::BTreeSet;
use std::path::{Component, Path, PathBuf};

/// The top-level folders of the repository: a path in the docs that starts with one of these
/// names a file of the repository and must exist.
const REPO_DIRS: [&str; 11] = [
    "agent/",
    "leader/",
    "orchestrator/",
    "common/",
    "tests/",
    "scripts/",
    "examples/",
    "python/",
    "docs/",
    "third_party/",
    ".ci/",
];

fn repo_root() -> PathBuf {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    root.canonicalize().expect("the repository root resolves")
}

/// The lines of a Markdown text outside fenced code blocks, with their 1-based numbers.
fn prose_lines(md: &str) -> Vec<(usize, &str)> {
    let mut fence: Option<&str> = None;
    let mut out = Vec::new();
    for (i, line) in md.lines().enumerate() {
        let t = line.trim_start();
        let marker = ["```", "~~~"].into_iter().find(|m| t.starts_with(m));
        match (fence, marker) {
            (None, Some(m)) => fence = Some(m),
            (Some(f), Some(m)) if f == m => fence = None,
            (None, None) => out.push((i + 1, line)),
            _ => {}
        }
    }
    out
}

/// Splits a line into its inline code spans and the text around them (outside the spans).
fn split_code(line: &str) -> (Vec<&str>, String) {
    let mut spans = Vec::new();
    let mut text = String::new();
    let mut rest = line;
    while let Some(open) = rest.find('`') {
        text.push_str(&rest[..open]);
        let ticks = rest[open..].chars().take_while(|&c| c == '`').count();
        let after = &rest[open + ticks..];
        let close = "`".repeat(ticks);
        match after.find(&close) {
            Some(end) => {
                spans.push(after[..end].trim());
                rest = &after[end + ticks..];
            }
            None => {
                rest = after;
            }
        }
    }
    text.push_str(rest);
    (spans, text)
}

/// The targets of the inline links and images of a line (`[text](target)`, `![alt](target)`),
/// outside code spans, without an optional title.
fn link_targets(line: &str) -> Vec<String> {
    let (_, text) = split_code(line);
    let mut out = Vec::new();
    let mut rest = text.as_str();
    while let Some(at) = rest.find("](") {
        let after = &rest[at + 2..];
        let Some(end) = after.find(')') else {
            break;
        };
        let inner = after[..end].trim();
        // `<a b.md>` may hold spaces; otherwise a title may follow the target.
        let target = match inner.strip_prefix('<') {
            Some(angled) => angled.split('>').next().unwrap_or_default(),
            None => inner.split_whitespace().next().unwrap_or_default(),
        };
        if !target.is_empty() {
            out.push(target.to_owned());
        }
        rest = &after[end..];
    }
    out
}

/// A heading's id as mdBook gives it (GitHub's agree on the headings the docs use): the text
/// without Markdown marks, lowercase, whitespace to `-`, other punctuation but `-` and `_` dropped.
fn anchor_of(heading: &str) -> String {
    let mut text = String::new();
    let mut rest = heading;
    // A link's text stays, its target goes.
    while let Some(open) = rest.find('[') {
        text.push_str(&rest[..open]);
        let after = &rest[open + 1..];
        match after.find("](").zip(after.find(')')) {
            Some((mid, end)) if mid < end => {
                text.push_str(&after[..mid]);
                rest = &after[end + 1..];
            }
            _ => {
                text.push('[');
                rest = after;
            }
        }
    }
    text.push_str(rest);
    text.trim()
        .chars()
        .filter_map(|c| {
            if c.is_alphanumeric() || c == '_' || c == '-' {
                Some(c.to_ascii_lowercase())
            } else if c.is_whitespace() {
                Some('-')
            } else {
                None
            }
        })
        .collect()
}

/// Every heading id of a page, a repeated one numbered `-1`, `-2`, ... as mdBook and GitHub do.
fn anchors(md: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for (_, line) in prose_lines(md) {
        let hashes = line.chars().take_while(|&c| c == '#').count();
        if hashes == 0 || hashes > 6 || !line[hashes..].starts_with(' ') {
            continue;
        }
        let base = anchor_of(line[hashes..].trim());
        let mut id = base.clone();
        let mut n = 0;
        while out.contains(&id) {
            n += 1;
            id = format!("{base}-{n}");
        }
        out.insert(id);
    }
    out
}

/// `a/b/../c` -> `a/c` without touching the file system; `None` when it climbs above the start.
fn normalise(path: &Path) -> Option<PathBuf> {
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir => {
                if !out.pop() {
                    return None;
                }
            }
            Component::CurDir => {}
            other => out.push(other),
        }
    }
    Some(out)
}

/// What is wrong with the relative links of `md`, a page at `page` (relative to `root`).
fn broken_links(root: &Path, page: &Path, md: &str) -> Vec<String> {
    let mut out = Vec::new();
    let own = anchors(md);
    for (n, line) in prose_lines(md) {
        for target in link_targets(line) {
            if target.contains("://") || target.starts_with("mailto:") {
                continue;
            }
            let (file, anchor) = match target.split_once('#') {
                Some((f, a)) => (f, Some(a)),
                None => (target.as_str(), None),
            };
            let at = format!("{}:{n}: link `{target}`", page.display());
            let (ids, shown) = if file.is_empty() {
                (own.clone(), page.to_path_buf())
            } else {
                let dir = page.parent().unwrap_or(Path::new(""));
                let Some(rel) = normalise(&dir.join(file)) else {
                    out.push(format!("{at} leaves the repository"));
                    continue;
                };
                let full = root.join(&rel);
                if !full.exists() {
                    out.push(format!("{at}: {} does not exist", rel.display()));
                    continue;
                }
                let is_md = rel.extension().is_some_and(|e| e == "md");
                match anchor {
                    Some(_) if is_md => {
                        let text = std::fs::read_to_string(&full).unwrap_or_default();
                        (anchors(&text), rel)
                    }
                    _ => continue,
                }
            };
            if let Some(a) = anchor {
                if !ids.contains(a) {
                    out.push(format!("{at}: no heading #{a} in {}", shown.display()));
                }
            }
        }
    }
    out
}

/// The repository paths a line names: in code spans and link targets, every word that starts
/// with a top-level folder, without trailing punctuation or a `:line` suffix.
fn repo_paths(line: &str) -> Vec<String> {
    let (spans, _) = split_code(line);
    let words = spans
        .iter()
        .flat_map(|s| s.split_whitespace().map(str::to_owned))
        .chain(link_targets(line));
    let mut out = Vec::new();
    for w in words {
        let w = w.split('#').next().unwrap_or_default();
        let w = w.trim_start_matches(['(', '"', '\'']);
        let w = w.trim_end_matches([',', '.', ';', ')', '"', '\'']);
        let w = match w.rsplit_once(':') {
            Some((p, n)) if n.chars().all(|c| c.is_ascii_digit()) => p,
            _ => w,
        };
        let plain = w
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || "_-./".contains(c));
        if plain && !w.contains("..") && REPO_DIRS.iter().any(|d| w.starts_with(d)) {
            out.push(w.to_owned());
        }
    }
    out
}

/// The repository paths `md` names that do not exist.
fn missing_paths(root: &Path, page: &Path, md: &str) -> Vec<String> {
    let mut out = Vec::new();
    for (n, line) in prose_lines(md) {
        for p in repo_paths(line) {
            if !root.join(&p).exists() {
                out.push(format!("{}:{n}: `{p}` does not exist", page.display()));
            }
        }
    }
    out
}

/// The pages SUMMARY.md links to, relative to `docs/src`, in order.
fn summary_pages(summary: &str) -> Vec<String> {
    prose_lines(summary)
        .into_iter()
        .flat_map(|(_, line)| link_targets(line))
        .filter(|t| !t.contains("://"))
        .collect()
}

/// Every `.md` file under `dir`, relative to it, sorted.
fn md_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        let entries = std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display()));
        for e in entries.flatten() {
            let p = e.path();
            if p.is_dir() {
                dirs.push(p);
            } else if p.extension().is_some_and(|x| x == "md") {
                out.push(p.strip_prefix(dir).expect("under dir").to_path_buf());
            }
        }
    }
    out.sort();
    out
}

/// The summary's problems: a listed page that is missing, a page that is not listed.
fn summary_problems(listed: &[String], files: &[PathBuf]) -> Vec<String> {
    let files: BTreeSet<&Path> = files.iter().map(PathBuf::as_path).collect();
    let listed_paths: BTreeSet<&Path> = listed.iter().map(Path::new).collect();
    let mut out: Vec<String> = listed_paths
        .iter()
        .filter(|p| !files.contains(*p))
        .map(|p| format!("SUMMARY.md lists {}, which does not exist", p.display()))
        .collect();
    out.extend(
        files
            .iter()
            .filter(|f| **f != Path::new("SUMMARY.md") && !listed_paths.contains(*f))
            .map(|f| format!("docs/src/{} is not in SUMMARY.md", f.display())),
    );
    out
}

/// README.md, ARCHITECTURE.md, BENCHMARKS.md and every page of the book, relative to the root,
/// with their text.
fn doc_pages(root: &Path) -> Vec<(PathBuf, String)> {
    let mut pages: Vec<PathBuf> = ["README.md", "ARCHITECTURE.md", "BENCHMARKS.md"]
        .map(PathBuf::from)
        .to_vec();
    pages.extend(
        md_files(&root.join("docs/src"))
            .into_iter()
            .map(|p| Path::new("docs/src").join(p)),
    );
    pages
        .into_iter()
        .map(|p| {
            let text = std::fs::read_to_string(root.join(&p))
                .unwrap_or_else(|e| panic!("{}: {e}", p.display()));
            (p, text)
        })
        .collect()
}

#[test]
fn every_page_of_the_summary_exists_and_every_page_is_in_the_summary() {
    let root = repo_root();
    let src = root.join("docs/src");
    let summary = std::fs::read_to_string(src.join("SUMMARY.md")).expect("docs/src/SUMMARY.md");
    let listed = summary_pages(&summary);
    assert!(
        listed.len() > 20,
        "SUMMARY.md lists only {} pages",
        listed.len()
    );
    let problems = summary_problems(&listed, &md_files(&src));
    assert!(problems.is_empty(), "{}", problems.join("\n"));
    assert!(
        root.join("docs/book.toml").is_file(),
        "docs/book.toml is missing"
    );
}

/// Runs a checker over every page: `count` says how many things a page names (more than 50 in
/// all, or the checker is blind), `problems` what is wrong with them.
fn check_every_page(
    what: &str,
    count: impl Fn(&str) -> usize,
    problems: impl Fn(&Path, &Path, &str) -> Vec<String>,
) {
    let root = repo_root();
    let pages = doc_pages(&root);
    let named: usize = pages.iter().map(|(_, text)| count(text)).sum();
    assert!(
        named > 50,
        "the docs name only {named} {what}: is the checker blind?"
    );
    let found: Vec<String> = pages
        .iter()
        .flat_map(|(p, text)| problems(&root, p, text))
        .collect();
    assert!(found.is_empty(), "{}", found.join("\n"));
}

#[test]
fn every_relative_link_and_anchor_of_the_docs_resolves() {
    let relative = |text: &str| {
        prose_lines(text)
            .into_iter()
            .flat_map(|(_, l)| link_targets(l))
            .filter(|t| !t.contains("://"))
            .count()
    };
    check_every_page("relative links", relative, broken_links);
}

#[test]
fn every_repository_path_the_docs_name_exists() {
    let paths = |text: &str| {
        prose_lines(text)
            .into_iter()
            .map(|(_, l)| repo_paths(l).len())
            .sum()
    };
    check_every_page("repository paths", paths, missing_paths);
}

#[test]
fn the_readme_names_the_paper_and_keeps_the_test_command() {
    let readme = std::fs::read_to_string(repo_root().join("README.md")).expect("README.md");
    assert!(readme.contains("Safe Multiquadcopter System Continuum Deformation Over Moving"));
    // .ci/run ends with this line; the README is where a newcomer finds it.
    assert!(readme.contains("scripts/test-deps.sh && cargo test --release --workspace"));
    let ci = std::fs::read_to_string(repo_root().join(".ci/run")).expect(".ci/run");
    assert!(ci.contains("scripts/test-deps.sh && cargo test --release --workspace"));
}

// The checkers on inline text: each must be able to fail.

#[test]
fn anchors_are_mdbooks_ids_numbered_when_repeated() {
    assert_eq!(
        anchor_of("The certificate's E_max(T) (`linear_certificate.rs`)"),
        "the-certificates-e_maxt-linear_certificaters"
    );
    assert_eq!(
        anchor_of("Live: `launch --ros2 dds|zenoh`"),
        "live-launch---ros2-ddszenoh"
    );
    assert_eq!(
        anchor_of("See [the book](docs/x.md) now"),
        "see-the-book-now"
    );
    let md = "# Title\n## Real time\n```\n# not a heading\n```\n## Real time\n#hashtag\n";
    let ids: Vec<String> = anchors(md).into_iter().collect();
    assert_eq!(ids, ["real-time", "real-time-1", "title"]);
}

#[test]
fn links_are_read_outside_code_and_fences() {
    let line = "see [a](x.md#b), ![img](../f.png \"t\") and `[not](a link)` [c](<y z.md>)";
    assert_eq!(link_targets(line), ["x.md#b", "../f.png", "y z.md"]);
    let md = "[in](a.md)\n```\n[fenced](b.md)\n```\n~~~\n[tilde](c.md)\n~~~\n";
    let found: Vec<String> = prose_lines(md)
        .iter()
        .flat_map(|(_, l)| link_targets(l))
        .collect();
    assert_eq!(found, ["a.md"]);
}

#[test]
fn a_broken_link_a_missing_anchor_and_a_link_out_of_the_repository_are_reported() {
    let root = repo_root();
    let md = "# Here\n[ok](ARCHITECTURE.md#crates) [self](#here) [web](https://x.org/a.md)\n\
              [gone](no/such/page.md)\n[anchor](ARCHITECTURE.md#no-such-heading)\n\
              [own](#nowhere)\n[paper](../shared/paper/)\n[dir](docs/src/guide/)\n";
    let problems = broken_links(&root, Path::new("README.md"), md);
    assert_eq!(problems.len(), 4, "{problems:#?}");
    assert!(problems[0].contains("README.md:3") && problems[0].contains("does not exist"));
    assert!(problems[1].contains("no heading #no-such-heading"));
    assert!(problems[2].contains("no heading #nowhere"));
    assert!(problems[3].contains("leaves the repository"));
    // From a book page the same link climbs three levels.
    let page = Path::new("docs/src/guide/x.md");
    assert!(broken_links(&root, page, "[a](../../../ARCHITECTURE.md#seams)").is_empty());
    assert_eq!(
        broken_links(&root, page, "[a](../../ARCHITECTURE.md)").len(),
        1
    );
}

#[test]
fn repository_paths_are_found_in_code_and_links_and_checked() {
    let line = "`common/core/src/link.rs:12`, `cargo run -p x` (`scripts/bench.sh`) \
                [t](tests/tests/repository/docs.rs) `runs/<team>/` `cdm/*/host/K/**` `tls/10.0.0.1:7447`";
    assert_eq!(
        repo_paths(line),
        [
            "common/core/src/link.rs",
            "scripts/bench.sh",
            "tests/tests/repository/docs.rs"
        ]
    );
    let root = repo_root();
    let md =
        "`scripts/bench.sh` and `common/no-such-crate/src/lib.rs`\n```\ncommon/fenced.rs\n```\n";
    let missing = missing_paths(&root, Path::new("README.md"), md);
    assert_eq!(
        missing,
        ["README.md:1: `common/no-such-crate/src/lib.rs` does not exist"]
    );
}

#[test]
fn the_summary_check_finds_missing_and_unlisted_pages() {
    let summary = "# Summary\n[Intro](intro.md)\n# Guide\n- [A](guide/a.md)\n  - [B](guide/b.md)\n";
    let listed = summary_pages(summary);
    assert_eq!(listed, ["intro.md", "guide/a.md", "guide/b.md"]);
    let files: Vec<PathBuf> = ["SUMMARY.md", "intro.md", "guide/a.md", "guide/c.md"]
        .iter()
        .map(PathBuf::from)
        .collect();
    assert_eq!(
        summary_problems(&listed, &files),
        [
            "SUMMARY.md lists guide/b.md, which does not exist",
            "docs/src/guide/c.md is not in SUMMARY.md"
        ]
    );
}
