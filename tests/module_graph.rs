//! The core's modules follow the data flow: a module imports only from modules to its
//! left in [`LAYERS`] (the order `src/lib.rs` states). The graph is read from the `crate::`
//! paths of the library's code (tests, which may reach anywhere, are left out);
//! `cargo test --test module_graph -- --nocapture` prints it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The core's top-level modules, from the ground floor to the offline builder.
const LAYERS: [&str; 17] = [
    "error",
    "interrupt",
    "files",
    "geom",
    "optics",
    "sensor",
    "grid",
    "classify",
    "cues",
    "calib",
    "project",
    "water",
    "hazard",
    "mapper",
    "rig",
    "io",
    "build",
];

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// `text` without comments, string literals' contents left as they are (no `crate::` path
/// is written in one).
fn without_comments(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    let b = text.as_bytes();
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            i += 2;
            while i < b.len() && !b[i..].starts_with(b"*/") {
                i += 1;
            }
            i += 2;
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// `text` without its `#[cfg(test)]` items (a `mod tests { … }` block or a `mod tests;`).
fn without_tests(text: &str) -> String {
    let mut out = String::new();
    let mut rest = text;
    while let Some(at) = rest.find("#[cfg(test)]") {
        out.push_str(&rest[..at]);
        rest = &rest[at..];
        let (semi, brace) = (rest.find(';'), rest.find('{'));
        match (semi, brace) {
            (Some(s), b) if b.is_none_or(|b| s < b) => rest = &rest[s + 1..],
            (_, Some(b)) => {
                let mut depth = 0usize;
                let mut end = rest.len();
                for (i, c) in rest[b..].char_indices() {
                    match c {
                        '{' => depth += 1,
                        '}' => {
                            depth -= 1;
                            if depth == 0 {
                                end = b + i + 1;
                                break;
                            }
                        }
                        _ => {}
                    }
                }
                rest = &rest[end..];
            }
            _ => rest = "",
        }
    }
    out.push_str(rest);
    out
}

fn is_ident(c: char) -> bool {
    c.is_ascii_alphanumeric() || c == '_'
}

/// The top-level modules `code` names through `crate::`: `crate::x::…` and each item of a
/// `crate::{x::…, y}` group.
fn named_modules(code: &str) -> Vec<String> {
    let mut names = Vec::new();
    for (at, _) in code.match_indices("crate::") {
        if at > 0 && code[..at].ends_with(|c: char| is_ident(c)) {
            continue; // `tarn_crate::` or the like
        }
        let rest = &code[at + "crate::".len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let mut depth = 0usize;
            let mut item = String::new();
            for c in group.chars() {
                match c {
                    '{' => depth += 1,
                    '}' if depth == 0 => break,
                    '}' => depth -= 1,
                    _ => {}
                }
                if c == ',' && depth == 0 {
                    names.push(std::mem::take(&mut item));
                } else {
                    item.push(c);
                }
            }
            names.push(item);
        } else {
            names.push(rest.chars().take_while(|&c| is_ident(c)).collect());
        }
    }
    names
        .into_iter()
        .map(|n| n.trim().chars().take_while(|&c| is_ident(c)).collect())
        .filter(|n: &String| !n.is_empty())
        .collect()
}

#[test]
fn every_module_imports_only_from_modules_to_its_left() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.sort();
    let layer = |m: &str| LAYERS.iter().position(|l| *l == m);
    let mut graph: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    let mut modules = BTreeSet::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        let first = rel
            .components()
            .next()
            .unwrap()
            .as_os_str()
            .to_string_lossy();
        let module = first.trim_end_matches(".rs").to_string();
        if module == "lib" {
            continue;
        }
        modules.insert(module.clone());
        let name = f.file_name().unwrap().to_string_lossy();
        if name.ends_with("tests.rs") {
            continue;
        }
        let code = without_tests(&without_comments(&std::fs::read_to_string(f).unwrap()));
        for to in named_modules(&code) {
            if to != module {
                *graph
                    .entry(module.clone())
                    .or_default()
                    .entry(to)
                    .or_default() += 1;
            }
        }
    }
    let unplaced: Vec<_> = modules.iter().filter(|m| layer(m).is_none()).collect();
    assert!(
        unplaced.is_empty(),
        "modules not placed in LAYERS (and in lib.rs's order): {unplaced:?}"
    );
    let mut against = Vec::new();
    for (from, tos) in &graph {
        let line: Vec<String> = tos.iter().map(|(t, n)| format!("{t} ({n})")).collect();
        println!("{from} → {}", line.join(", "));
        for to in tos.keys() {
            match (layer(from), layer(to)) {
                (Some(a), Some(b)) if b < a => {}
                _ => against.push(format!("{from} → {to}")),
            }
        }
    }
    assert!(
        against.is_empty(),
        "imports against the data flow: {against:?}"
    );
}

#[test]
fn the_reader_sees_grouped_and_plain_paths_and_skips_tests() {
    let code = "use crate::grid::{a, b};\nuse crate::{cues::{x, y}, geom};\n\
                fn f() { crate::io::export::go(); }\n\
                #[cfg(test)]\nmod tests { use crate::build; }\n#[cfg(test)]\nmod more;\n";
    let names = named_modules(&without_tests(&without_comments(code)));
    assert_eq!(names, ["grid", "cues", "geom", "io"]);
    assert_eq!(named_modules("// crate::io\n"), ["io"]);
    assert!(named_modules(&without_comments("// crate::io\n/* crate::build */")).is_empty());
}
