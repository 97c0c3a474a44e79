//! The style rules that a reviewer would otherwise count by hand, checked on the sources: no
//! function outside tests is longer than 80 lines (STYLE.md: a long function is a sign to split),
//! no module is mounted with `#[path]` (a file's module is where its path says), no two modules
//! of a crate import each other (directly or through others), no public type, trait or enum
//! name means two things in the workspace, and no library under common/ prints or depends on
//! clap (the binaries do both).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The longest a function outside tests may be, in lines from `fn` to its closing brace.
const MAX_FN_LINES: usize = 80;

/// Every `.rs` file of the workspace's library and binary sources (`src/` of each package),
/// without the test modules mounted as files (`tests.rs`, `*_tests.rs`).
fn sources() -> Vec<PathBuf> {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut out = Vec::new();
    let mut dirs: Vec<PathBuf> = ["agent", "leader", "orchestrator", "python", "tests"]
        .iter()
        .map(|p| root.join(p).join("src"))
        .collect();
    let common = std::fs::read_dir(root.join("common")).expect("common/ is readable");
    dirs.extend(common.flatten().map(|e| e.path().join("src")));
    while let Some(dir) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&dir) else {
            continue;
        };
        for e in entries.flatten() {
            let p = e.path();
            let name = p.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if p.is_dir() {
                dirs.push(p);
            } else if name.ends_with(".rs") && name != "tests.rs" && !name.ends_with("_tests.rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    assert!(out.len() > 100, "found only {} source files", out.len());
    out
}

/// A line without its string literals and its `//` comment, so braces in them do not count.
fn code_of(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars().peekable();
    let mut in_str = false;
    while let Some(c) = chars.next() {
        match (in_str, c) {
            (true, '\\') => {
                chars.next();
            }
            (true, '"') => in_str = false,
            (true, _) => {}
            (false, '"') => in_str = true,
            (false, '\'') => {
                // A char literal ('{', '\n') is skipped whole; a lifetime ('a) is kept out too.
                let rest: String = chars.clone().take(3).collect();
                if rest.starts_with('\\') {
                    chars.nth(2);
                } else if rest.chars().nth(1) == Some('\'') {
                    chars.nth(1);
                }
            }
            (false, '/') if chars.peek() == Some(&'/') => break,
            (false, _) => out.push(c),
        }
    }
    out
}

/// The functions of `text` longer than [`MAX_FN_LINES`], outside its `#[cfg(test)] mod`, as
/// (first line, name, lines).
fn long_functions(text: &str) -> Vec<(usize, String, usize)> {
    let lines: Vec<&str> = text.lines().collect();
    let tests_from = lines
        .windows(2)
        .position(|w| w[0].starts_with("#[cfg(test)]") && w[1].starts_with("mod "))
        .unwrap_or(lines.len());
    let mut out = Vec::new();
    for start in 0..tests_from {
        let code = code_of(lines[start]);
        let Some(at) = code.find("fn ") else { continue };
        let before = code[..at].trim();
        let is_item = before.split_whitespace().all(|w| {
            ["pub", "const", "unsafe", "async", "extern"].contains(&w) || w.starts_with("pub(")
        });
        if !is_item {
            continue;
        }
        let name: String = code[at + 3..]
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        let (mut depth, mut opened) = (0i64, false);
        for (k, line) in lines.iter().enumerate().skip(start) {
            let code = code_of(line);
            for c in code.chars() {
                match c {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    _ => {}
                }
            }
            if !opened && code.trim_end().ends_with(';') {
                break;
            }
            if opened && depth <= 0 {
                let n = k - start + 1;
                if n > MAX_FN_LINES {
                    out.push((start + 1, name.clone(), n));
                }
                break;
            }
        }
    }
    out
}

#[test]
fn no_function_outside_tests_is_longer_than_80_lines() {
    let mut long = Vec::new();
    for p in sources() {
        let text = std::fs::read_to_string(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
        for (line, name, n) in long_functions(&text) {
            long.push(format!("{}:{line} fn {name}: {n} lines", p.display()));
        }
    }
    assert!(
        long.is_empty(),
        "functions over {MAX_FN_LINES} lines:\n{}",
        long.join("\n")
    );
}

#[test]
fn the_counter_finds_a_long_function_and_ignores_braces_in_strings() {
    let body = "    x += 1;\n".repeat(MAX_FN_LINES);
    let long =
        format!("pub fn long() {{\n{body}}}\nfn short() {{ let s = \"}}}}\"; let c = '}}'; }}\n");
    assert_eq!(
        long_functions(&long),
        vec![(1, "long".to_owned(), MAX_FN_LINES + 2)]
    );
    let in_tests = format!("#[cfg(test)]\nmod tests {{\n{long}}}\n");
    assert!(long_functions(&in_tests).is_empty());
    let just_fits = format!(
        "fn fits() {{\n{}}}\n",
        "    x += 1;\n".repeat(MAX_FN_LINES - 2)
    );
    assert!(long_functions(&just_fits).is_empty());
}

#[test]
fn no_module_is_mounted_with_a_path_attribute() {
    let mut mounted = Vec::new();
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut files = sources();
    // The integration tests and the crates' own test directories too.
    for dir in [root.join("tests/tests"), root.join("tests/tests/support")] {
        for e in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            files.push(e.path());
        }
    }
    for e in std::fs::read_dir(root.join("common"))
        .into_iter()
        .flatten()
        .flatten()
    {
        for t in std::fs::read_dir(e.path().join("tests"))
            .into_iter()
            .flatten()
            .flatten()
        {
            files.push(t.path());
        }
    }
    for p in files
        .iter()
        .filter(|p| p.extension().is_some_and(|x| x == "rs"))
    {
        let text = std::fs::read_to_string(p).unwrap_or_default();
        for (k, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("#[path") {
                mounted.push(format!("{}:{}", p.display(), k + 1));
            }
        }
    }
    assert!(
        mounted.is_empty(),
        "#[path] mounts:\n{}",
        mounted.join("\n")
    );
}

/// Import circles that belong to crates being reworked elsewhere, each a crate and the modules
/// of one circle: a circle in that crate among these modules only is tolerated. Empty this list
/// as they are untangled; nothing may be added to it.
const ALLOWED_CIRCLES: &[(&str, &[&str])] = &[
    // The launch's set-up modules (the team's one loop is `fly.rs`; the set-up still calls back
    // and forth between lockstep, real time and arming).
    (
        "common/launch",
        &["flight", "launch", "realtime", "team_arm"],
    ),
];

/// Public type names defined twice that belong to crates being reworked elsewhere (with the
/// files that define them). Empty this list as they are renamed; nothing may be added to it.
const ALLOWED_TWICE: &[(&str, &[&str])] = &[];

/// The text of `text` before its `#[cfg(test)] mod`, without comments and string contents.
fn code_outside_tests(text: &str) -> String {
    let lines: Vec<&str> = text.lines().collect();
    let tests_from = lines
        .windows(2)
        .position(|w| w[0].starts_with("#[cfg(test)]") && w[1].starts_with("mod "))
        .unwrap_or(lines.len());
    let code: Vec<String> = lines[..tests_from].iter().map(|l| code_of(l)).collect();
    code.join("\n")
}

/// The module path of `file` inside its package's `src/` (`lib.rs`, `main.rs`: the root;
/// `a.rs` and `a/mod.rs`: `a`; `a/b.rs`: `a::b`); `None` for the binaries in `src/bin/`.
fn module_of(src: &Path, file: &Path) -> Option<Vec<String>> {
    let rel = file.strip_prefix(src).ok()?;
    let mut parts: Vec<String> = rel
        .iter()
        .map(|s| s.to_string_lossy().trim_end_matches(".rs").to_owned())
        .collect();
    if parts.first().is_some_and(|p| p == "bin") {
        return None;
    }
    if parts.len() == 1 && (parts[0] == "lib" || parts[0] == "main") || parts.last()? == "mod" {
        parts.pop();
    }
    Some(parts)
}

/// The paths a `crate::` or `super::` reference names after its prefix: one for `a::b::X`,
/// one per item of a group `{a::X, b::{Y, Z}}`, each as its segments.
fn referenced_paths(after: &str) -> Vec<Vec<String>> {
    let Some(group) = after.strip_prefix('{') else {
        let path: String = (after.chars())
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect();
        let segs = path.split("::").filter(|s| !s.is_empty());
        return vec![segs.map(str::to_owned).collect()];
    };
    let (mut depth, mut item, mut out) = (0, String::new(), Vec::new());
    for c in group.chars() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => break,
            '}' => depth -= 1,
            ',' if depth == 0 => {
                out.extend(referenced_paths(item.trim()));
                item.clear();
                continue;
            }
            _ => {}
        }
        item.push(c);
    }
    out.extend(referenced_paths(item.trim()));
    out
}

/// The modules of one crate that each module references through `crate::` or `super::`
/// (outside its tests), resolved to the longest known module; a module's own ancestors and
/// descendants are not edges (a child uses its parent's items, a parent mounts its children).
fn module_edges(modules: &[(Vec<String>, String)]) -> BTreeMap<String, BTreeSet<String>> {
    let known: BTreeSet<&Vec<String>> = modules.iter().map(|(m, _)| m).collect();
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (module, text) in modules {
        let code = code_outside_tests(text);
        for (at, _) in code
            .match_indices("crate::")
            .chain(code.match_indices("super::"))
        {
            let ident = |c: char| c.is_alphanumeric() || c == '_';
            if code[..at].chars().next_back().is_some_and(ident) {
                continue; // `pub(crate)`, `my_crate::`.
            }
            let (mut base, mut rest) = if code[at..].starts_with("crate::") {
                (Vec::new(), &code[at + 7..])
            } else {
                (
                    module[..module.len().saturating_sub(1)].to_vec(),
                    &code[at + 7..],
                )
            };
            while let Some(r) = rest.strip_prefix("super::") {
                base.pop();
                rest = r;
            }
            for path in referenced_paths(rest) {
                let mut target = base.clone();
                let mut found = base.clone();
                for seg in path {
                    target.push(seg);
                    if known.contains(&target) {
                        found = target.clone();
                    }
                }
                let related = found.starts_with(module) || module.starts_with(&found);
                if !related {
                    let entry = edges.entry(module.join("::")).or_default();
                    entry.insert(found.join("::"));
                }
            }
        }
    }
    edges
}

/// The import circles among `modules` (module path, source): each circle's modules, sorted.
fn import_circles(modules: &[(Vec<String>, String)]) -> Vec<Vec<String>> {
    let edges = module_edges(modules);
    let reach = |from: &String| {
        let (mut seen, mut stack) = (BTreeSet::new(), vec![from.clone()]);
        while let Some(m) = stack.pop() {
            for n in edges.get(&m).into_iter().flatten() {
                if seen.insert(n.clone()) {
                    stack.push(n.clone());
                }
            }
        }
        seen
    };
    let reaches: BTreeMap<&String, BTreeSet<String>> =
        edges.keys().map(|m| (m, reach(m))).collect();
    let mut circles: BTreeSet<Vec<String>> = BTreeSet::new();
    for (m, r) in &reaches {
        if !r.contains(*m) {
            continue;
        }
        // The circle through `m`: every module `m` reaches that reaches `m` back.
        let mut circle: Vec<String> = (r.iter())
            .filter(|n| reaches.get(n).is_some_and(|back| back.contains(*m)))
            .cloned()
            .collect();
        circle.sort();
        circles.insert(circle);
    }
    circles.into_iter().collect()
}

/// Every package directory with a `src/` (relative to the workspace root).
fn packages() -> Vec<String> {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut out: Vec<String> = ["agent", "leader", "orchestrator", "python", "tests"]
        .map(str::to_owned)
        .to_vec();
    for e in std::fs::read_dir(root.join("common"))
        .expect("common/ is readable")
        .flatten()
    {
        if e.path().join("src").is_dir() {
            out.push(format!("common/{}", e.file_name().to_string_lossy()));
        }
    }
    out.sort();
    out
}

#[test]
fn no_module_imports_itself_through_others() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let all = sources();
    let mut found = Vec::new();
    for package in packages() {
        let src = root.join(&package).join("src");
        let modules: Vec<(Vec<String>, String)> = (all.iter())
            .filter(|p| p.starts_with(&src))
            .filter_map(|p| Some((module_of(&src, p)?, std::fs::read_to_string(p).ok()?)))
            .collect();
        for circle in import_circles(&modules) {
            let allowed = ALLOWED_CIRCLES
                .iter()
                .any(|(c, m)| *c == package && circle.iter().all(|x| m.contains(&x.as_str())));
            if !allowed {
                found.push(format!("{package}: {}", circle.join(" <-> ")));
            }
        }
    }
    assert!(found.is_empty(), "import circles:\n{}", found.join("\n"));
}

#[test]
fn the_circle_finder_finds_direct_transitive_and_grouped_circles() {
    let m = |path: &str, text: &str| {
        let segs = path
            .split("::")
            .filter(|s| !s.is_empty())
            .map(str::to_owned);
        (segs.collect::<Vec<_>>(), text.to_owned())
    };
    let two = [m("a", "use crate::b::X;\n"), m("b", "use crate::a::Y;\n")];
    assert_eq!(
        import_circles(&two),
        vec![vec!["a".to_owned(), "b".to_owned()]]
    );
    let three = [
        m("a", "use crate::{b::X, d};\n"),
        m("b", "fn f() { crate::c::g() }\n"),
        m("c", "use super::a::Z;\n"),
        m("d", ""),
    ];
    assert_eq!(
        import_circles(&three),
        vec![["a", "b", "c"].map(str::to_owned).to_vec()]
    );
    let line = [
        m("a", "use crate::b::X;\n"),
        m("b", "use crate::c::X;\n"),
        m("c", ""),
    ];
    assert!(import_circles(&line).is_empty());
    // Parents and children, comments, strings and test modules are not imports.
    let not_imports = [
        m("", "pub mod a;\nuse crate::a::X;\n"),
        m(
            "a",
            "use super::Y; // crate::b::\nconst S: &str = \"crate::b::X\";\n",
        ),
        m(
            "b",
            "use crate::a::X;\n#[cfg(test)]\nmod tests {\n    use crate::a::tests::T;\n}\n",
        ),
        m("a::tests", "use crate::b::Z;\n"),
    ];
    assert!(
        import_circles(&not_imports).is_empty(),
        "{:?}",
        module_edges(&not_imports)
    );
}

/// Public types, traits, enums and aliases defined in more than one place (outside tests): each
/// name with the files that define it.
fn defined_twice(files: &[(String, String)]) -> BTreeMap<String, Vec<String>> {
    let mut defs: BTreeMap<String, Vec<String>> = BTreeMap::new();
    for (file, text) in files {
        let code = code_outside_tests(text);
        let mut previous = "";
        for line in code.lines() {
            // A stand-in compiled only without a feature is the same name, not a second meaning.
            let stand_in = previous.trim_start().starts_with("#[cfg(not(feature");
            previous = line;
            let words: Vec<&str> = line.split_whitespace().collect();
            let Some(k) =
                (words.iter()).position(|w| ["struct", "enum", "trait", "type"].contains(w))
            else {
                continue;
            };
            if stand_in || k == 0 || !words[..k].iter().any(|w| w.starts_with("pub")) {
                continue;
            }
            let name: String = (words.get(k + 1).unwrap_or(&"").chars())
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            if name.starts_with(|c: char| c.is_ascii_uppercase()) {
                defs.entry(name).or_default().push(file.clone());
            }
        }
    }
    defs.retain(|_, files| files.len() > 1);
    defs
}

#[test]
fn no_public_type_name_is_defined_twice() {
    let root = std::fs::canonicalize(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).unwrap();
    let files: Vec<(String, String)> = (sources().iter())
        .filter_map(|p| {
            let rel = std::fs::canonicalize(p).ok()?;
            let rel = rel.strip_prefix(&root).ok()?.to_string_lossy().into_owned();
            Some((rel, std::fs::read_to_string(p).ok()?))
        })
        .collect();
    let twice: Vec<String> = defined_twice(&files)
        .into_iter()
        .filter(|(name, at)| {
            let allowed = ALLOWED_TWICE.iter().find(|(n, _)| n == name);
            !allowed.is_some_and(|(_, files)| at.iter().all(|f| files.contains(&f.as_str())))
        })
        .map(|(name, at)| format!("{name}: {}", at.join(", ")))
        .collect();
    assert!(
        twice.is_empty(),
        "public names defined twice:\n{}",
        twice.join("\n")
    );
}

#[test]
fn the_name_finder_finds_a_name_defined_twice() {
    let f = |path: &str, text: &str| (path.to_owned(), text.to_owned());
    let files = [
        f(
            "a/src/x.rs",
            "pub struct Role;\npub(crate) enum Kind { A }\nstruct Private;\n",
        ),
        f(
            "b/src/y.rs",
            "pub enum Role { A }\n// pub struct Kind\nstruct Private;\n",
        ),
        f(
            "c/src/z.rs",
            "pub trait Kind {}\n#[cfg(test)]\nmod tests {\n    pub struct Role;\n}\n",
        ),
        f(
            "d/src/w.rs",
            "#[cfg(not(feature = \"live\"))]\npub struct Kind;\npub struct Only;\n",
        ),
    ];
    let twice = defined_twice(&files);
    assert_eq!(
        twice.keys().collect::<Vec<_>>(),
        ["Kind", "Role"],
        "{twice:?}"
    );
    assert_eq!(twice["Role"], ["a/src/x.rs", "b/src/y.rs"]);
    assert_eq!(twice["Kind"], ["a/src/x.rs", "c/src/z.rs"]);
}

/// A comment that names a ticket ("issue 27") says which request a line came from, not why it
/// is there; the ticket means nothing to a reader of the code. Returns the offending lines.
fn ticket_references(text: &str) -> Vec<(usize, String)> {
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let lower = line.to_ascii_lowercase();
        let mut rest = lower.as_str();
        while let Some(at) = rest.find("issue") {
            let after = rest[at + "issue".len()..].trim_start_matches('s');
            let after = after.strip_prefix(' ').unwrap_or(after);
            let after = after.strip_prefix('#').unwrap_or(after);
            if after.starts_with(|c: char| c.is_ascii_digit()) {
                out.push((i + 1, line.trim().to_string()));
                break;
            }
            rest = &rest[at + "issue".len()..];
        }
    }
    out
}

#[test]
fn no_comment_names_an_issue_number() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut files = sources();
    for dir in [
        "tests/tests",
        "tests/tests/support",
        "scripts",
        "tests/python",
        "python",
    ] {
        for e in std::fs::read_dir(root.join(dir))
            .into_iter()
            .flatten()
            .flatten()
        {
            files.push(e.path());
        }
    }
    let tomls = ["Cargo.toml", "tests/Cargo.toml", "python/Cargo.toml"];
    files.extend(tomls.iter().map(|t| root.join(t)));
    let mut found = Vec::new();
    for f in files.iter().filter(|f| f.is_file()) {
        let Ok(text) = std::fs::read_to_string(f) else {
            continue;
        };
        // This file names the pattern it looks for.
        if f.ends_with("tests/tests/repository/style.rs") {
            continue;
        }
        for (line, text) in ticket_references(&text) {
            found.push(format!("{}:{line}: {text}", f.display()));
        }
    }
    assert!(
        found.is_empty(),
        "comments that name an issue number:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_ticket_finder_finds_an_issue_number_and_nothing_else() {
    let text = "// the airspace (issue 27)\n// Issues #12 and 13\n// an issue with links\n";
    let found: Vec<usize> = ticket_references(text).iter().map(|(l, _)| *l).collect();
    assert_eq!(found, vec![1, 2]);
}

/// Library files under common/ that still print, and why; a binary (src/main.rs, src/bin/)
/// prints, a library hands its notices to the binary's sink (`cdm_team::notices::NoticeSink`).
const ALLOWED_PRINTING: &[(&str, &str)] = &[
    // The watchdog of the tests aborts a hung test: its last word goes to the test's stderr.
    ("common/test-support/src/lib.rs", "a test's watchdog"),
    // The member binaries' front end: their logging, their error line, the template's ready line.
    (
        "common/member-cli/src/lib.rs",
        "the member binaries' error line",
    ),
    (
        "common/member-cli/src/template.rs",
        "the member template's ready line",
    ),
];

/// Crates under common/ that depend on clap (cdm-mavlink's clap is its example's, a
/// dev-dependency). cdm-member-cli is no library: it is the command line the two member
/// binaries (agent, leader) share, kept with the shared crates as the workspace's layout asks.
/// cdm-unified-features has no code: it lists every feature the workspace builds its
/// third-party crates with, clap's among them, for the Python module.
const ALLOWED_CLAP: &[&str] = &["common/member-cli", "common/unified-features"];

/// The lines of `text` (outside its tests) that print: `println!`, `eprintln!`, `print!`,
/// `eprint!`, the orchestrator's `out!`, or a write to `io::stdout()` or `io::stderr()`.
fn printing_lines(text: &str) -> Vec<usize> {
    let printing = [
        "println!(",
        "eprintln!(",
        "print!(",
        "eprint!(",
        "out!(",
        "io::stdout()",
        "io::stderr()",
    ];
    code_outside_tests(text)
        .lines()
        .enumerate()
        .filter(|(_, l)| {
            printing.iter().any(|p| {
                l.match_indices(p).any(|(at, _)| {
                    // A whole name: `eprintln!(` is not `println!(` and `layout!(` not `out!(`.
                    !l[..at].ends_with(|c: char| c.is_alphanumeric() || c == '_')
                })
            })
        })
        .map(|(i, _)| i + 1)
        .collect()
}

/// True when a Cargo.toml's `[dependencies]` (not its dev- or build-dependencies) names clap.
fn depends_on_clap(manifest: &str) -> bool {
    let mut in_deps = false;
    for line in manifest.lines().map(str::trim) {
        if line.starts_with('[') {
            in_deps = line == "[dependencies]";
        } else if in_deps && (line.starts_with("clap ") || line.starts_with("clap.")) {
            return true;
        }
    }
    false
}

#[test]
fn no_library_under_common_prints_or_parses_arguments() {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut found = Vec::new();
    for file in sources() {
        let rel = file.strip_prefix(root).unwrap_or(&file).to_string_lossy();
        let rel = rel.trim_start_matches("./").to_string();
        let binary = rel.contains("/src/bin/") || rel.ends_with("/src/main.rs");
        if !rel.starts_with("common/") || binary {
            continue;
        }
        let text = std::fs::read_to_string(&file).expect("source is readable");
        let lines = printing_lines(&text);
        if !lines.is_empty() && !ALLOWED_PRINTING.iter().any(|(f, _)| *f == rel) {
            found.push(format!("{rel}: prints on lines {lines:?}"));
        }
    }
    for package in packages().iter().filter(|p| p.starts_with("common/")) {
        let manifest = std::fs::read_to_string(root.join(package).join("Cargo.toml"))
            .expect("Cargo.toml is readable");
        if depends_on_clap(&manifest) && !ALLOWED_CLAP.contains(&package.as_str()) {
            found.push(format!("{package}: depends on clap"));
        }
    }
    assert!(
        found.is_empty(),
        "libraries print or parse arguments (hand notices to the binary's sink; clap belongs \
         to agent/, leader/, common/member-cli/, orchestrator/):\n{}",
        found.join("\n")
    );
}

#[test]
fn the_printing_finder_finds_prints_and_clap_and_nothing_else() {
    let text = "fn a() {\n    out!(\"x\");\n    let s = \"println!(\";\n    layout!(1);\n}\n\
                fn b() { eprintln!(\"y\"); }\nfn c() { let _ = std::io::stderr().write_all(b); }\n#[cfg(test)]\nmod tests {\n    fn c() { println!(); }\n}\n";
    assert_eq!(printing_lines(text), vec![2, 6, 7]);
    assert!(depends_on_clap("[dependencies]\nclap.workspace = true\n"));
    assert!(depends_on_clap(
        "[dependencies]\nserde = \"1\"\nclap = { version = \"4\" }\n"
    ));
    assert!(!depends_on_clap(
        "[dev-dependencies]\nclap.workspace = true\n"
    ));
    assert!(!depends_on_clap("[dependencies]\nclap-verbosity = \"1\"\n"));
}
