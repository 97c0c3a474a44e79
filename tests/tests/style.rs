//! The style rules that a reviewer would otherwise count by hand, checked on the sources: no
//! function outside tests is longer than 80 lines (STYLE.md: a long function is a sign to split),
//! and no module is mounted with `#[path]` (a file's module is where its path says).

use std::path::{Path, PathBuf};

/// The longest a function outside tests may be, in lines from `fn` to its closing brace.
const MAX_FN_LINES: usize = 80;

/// Every `.rs` file of the workspace's library and binary sources (`src/` of each package),
/// without the test modules mounted as files (`tests.rs`, `*_tests.rs`).
fn sources() -> Vec<PathBuf> {
    let root = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/.."));
    let mut out = Vec::new();
    let mut dirs: Vec<PathBuf> = ["agent", "leader", "orchestrator", "tests"]
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
