//! The layering rule, checked on the source: `model` uses neither `solver` nor
//! `app`, `solver` does not use `app`, and no modules import each other in a
//! cycle, neither between layers nor between the modules inside one.
use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

const LAYERS: [&str; 3] = ["model", "solver", "app"];

/// Every `.rs` file under `dir`.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// The module a file belongs to, as `layer::module` (or the top-level name).
fn module_of(src: &Path, file: &Path) -> String {
    let rel = file.strip_prefix(src).unwrap();
    let parts: Vec<String> = rel
        .components()
        .map(|c| {
            c.as_os_str()
                .to_string_lossy()
                .trim_end_matches(".rs")
                .to_string()
        })
        .collect();
    match parts.as_slice() {
        [layer, module, ..] if LAYERS.contains(&layer.as_str()) && module != "mod" => {
            // `bridge_tests.rs` is part of `bridge`.
            format!("{layer}::{}", module.trim_end_matches("_tests"))
        }
        [first, ..] => first.clone(),
        [] => unreachable!(),
    }
}

/// Modules a file refers to through `crate::layer::module` paths, test modules excluded.
fn references(text: &str) -> BTreeSet<String> {
    let text = match text.find("#[cfg(test)]\nmod tests {") {
        Some(i) => &text[..i],
        None => text,
    };
    let mut out = BTreeSet::new();
    // Expand `crate::layer::{a, b::c}` groups one level.
    for (i, _) in text.match_indices("crate::") {
        let rest = &text[i + "crate::".len()..];
        let layer: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect();
        if !LAYERS.contains(&layer.as_str()) {
            if layer == "error" {
                out.insert(layer);
            }
            continue;
        }
        let after = &rest[layer.len()..];
        let Some(after) = after.strip_prefix("::") else {
            out.insert(layer);
            continue;
        };
        if let Some(group) = after.strip_prefix('{') {
            let group = &group[..group.find('}').unwrap_or(group.len())];
            for item in group.split(',') {
                let name: String = item
                    .trim()
                    .chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect();
                if !name.is_empty() && name != "self" {
                    out.insert(format!("{layer}::{name}"));
                }
            }
        } else {
            let name: String = after
                .chars()
                .take_while(|c| c.is_alphanumeric() || *c == '_')
                .collect();
            out.insert(format!("{layer}::{name}"));
        }
    }
    out
}

fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in &files {
        let from = module_of(&src, file);
        let text = std::fs::read_to_string(file).unwrap();
        let entry = edges.entry(from.clone()).or_default();
        for to in references(&text) {
            if to != from {
                entry.insert(to);
            }
        }
    }
    edges
}

fn layer_rank(module: &str) -> Option<usize> {
    let layer = module.split("::").next()?;
    LAYERS.iter().position(|l| *l == layer)
}

#[test]
fn layers_depend_one_way() {
    let mut wrong = Vec::new();
    for (from, tos) in graph() {
        let Some(rank) = layer_rank(&from) else {
            continue;
        };
        for to in tos {
            if layer_rank(&to).is_some_and(|r| r > rank) {
                wrong.push(format!("{from} -> {to}"));
            }
        }
    }
    assert!(
        wrong.is_empty(),
        "imports against the layer order: {wrong:#?}"
    );
}

#[test]
fn no_import_cycles() {
    let edges = graph();
    let cycle = find_cycle(&edges);
    assert!(
        cycle.is_none(),
        "import cycle: {}",
        cycle.unwrap().join(" -> ")
    );
}

#[test]
fn the_checker_sees_a_cycle() {
    // The parser must find both kinds of reference, or the tests above prove nothing.
    let refs = references("use crate::model::{camera::Pose, target};\nuse crate::app::fsio::x;");
    assert!(refs.contains("model::camera") && refs.contains("model::target"));
    assert!(refs.contains("app::fsio"));
    assert!(graph()
        .get("solver::problem")
        .is_some_and(|t| t.contains("solver::bridge")));
}

/// Most lines a source file may have: what a reader can hold in their head.
const MAX_FILE_LINES: usize = 800;

/// Every file under `dir` whose name ends in one of `extensions`.
fn files_with(dir: &Path, extensions: &[&str], out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries {
        let path = entry.unwrap().path();
        if path.is_dir() {
            files_with(&path, extensions, out);
        } else if path
            .extension()
            .is_some_and(|e| extensions.iter().any(|x| e == *x))
        {
            out.push(path);
        }
    }
}

#[test]
fn no_source_file_over_800_lines() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    for dir in [
        "src", "cpp", "include", "tests", "benches", "examples", "fuzz",
    ] {
        files_with(
            &root.join(dir),
            &["rs", "cc", "cpp", "h", "hpp", "c"],
            &mut files,
        );
    }
    assert!(files.len() > 100, "too few sources found: {}", files.len());
    let mut long = Vec::new();
    for file in &files {
        let rel = file
            .strip_prefix(root)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        let lines = std::fs::read_to_string(file).unwrap().lines().count();
        if lines > MAX_FILE_LINES {
            long.push(format!("{rel}: {lines} lines"));
        }
    }
    assert!(
        long.is_empty(),
        "source files over {MAX_FILE_LINES} lines (split them along their seams): {long:#?}"
    );
}

/// `text` with comments, string literals and character literals blanked (their
/// bytes replaced by spaces, newlines kept), so that paths named in them count
/// for nothing.
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = b.to_vec();
    let blank = |out: &mut Vec<u8>, from: usize, to: usize| {
        for c in &mut out[from..to.min(b.len())] {
            if *c != b'\n' {
                *c = b' ';
            }
        }
    };
    let mut i = 0;
    while i < b.len() {
        let rest = &b[i..];
        let end = if rest.starts_with(b"//") {
            i + rest.iter().position(|&c| c == b'\n').unwrap_or(rest.len())
        } else if rest.starts_with(b"/*") {
            i + 2
                + rest[2..]
                    .windows(2)
                    .position(|w| w == b"*/")
                    .map_or(rest.len() - 2, |p| p + 2)
        } else if rest.starts_with(b"r#") || rest.starts_with(b"r\"") {
            let hashes = rest[1..].iter().take_while(|&&c| c == b'#').count();
            if rest.get(1 + hashes) != Some(&b'"') || (i > 0 && b[i - 1].is_ascii_alphanumeric()) {
                i += 1;
                continue;
            }
            let close: Vec<u8> = std::iter::once(b'"')
                .chain(std::iter::repeat_n(b'#', hashes))
                .collect();
            let from = 2 + hashes;
            i + from
                + rest[from..]
                    .windows(close.len())
                    .position(|w| w == close)
                    .map_or(rest.len() - from, |p| p + close.len())
        } else if rest[0] == b'"' {
            let mut j = 1;
            while j < rest.len() && rest[j] != b'"' {
                j += if rest[j] == b'\\' { 2 } else { 1 };
            }
            i + j + 1
        } else if rest[0] == b'\'' {
            // A char literal ('a', '\n', '\u{..}', '{'); a lifetime ('a) is kept.
            match rest.iter().skip(1).take(10).position(|&c| c == b'\'') {
                Some(p) if p == 1 || rest[1] == b'\\' || !rest[1].is_ascii() => i + p + 2,
                _ => {
                    i += 1;
                    continue;
                }
            }
        } else {
            i += 1;
            continue;
        };
        blank(&mut out, i, end);
        i = end;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// The module path of a library source file: `src/solver/calibrate/fit.rs` is
/// `solver::calibrate::fit`; `mod.rs` and `lib.rs` name their folder.
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).unwrap().with_extension("");
    let mut parts: Vec<String> = rel
        .components()
        .map(|c| c.as_os_str().to_string_lossy().into_owned())
        .collect();
    if matches!(parts.last().map(String::as_str), Some("mod" | "lib")) {
        parts.pop();
    }
    parts
}

/// The paths (as segments) of one `use` tree or path expression starting at
/// `at` in `code`, each below `prefix`: `{a, b::{c, d}}` gives `a`, `b::c`, `b::d`.
fn path_tree(code: &[u8], mut at: usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) -> usize {
    let skip_ws = |at: &mut usize| {
        while *at < code.len() && code[*at].is_ascii_whitespace() {
            *at += 1;
        }
    };
    let mut path = prefix;
    loop {
        skip_ws(&mut at);
        if code.get(at) == Some(&b'{') {
            at += 1;
            loop {
                at = path_tree(code, at, path.clone(), out);
                skip_ws(&mut at);
                match code.get(at) {
                    Some(b',') => at += 1,
                    Some(b'}') => return at + 1,
                    _ => return at,
                }
                skip_ws(&mut at);
                if code.get(at) == Some(&b'}') {
                    return at + 1;
                }
            }
        }
        let start = at;
        while at < code.len() && (code[at].is_ascii_alphanumeric() || code[at] == b'_') {
            at += 1;
        }
        let name = std::str::from_utf8(&code[start..at]).unwrap();
        if !name.is_empty() && name != "self" {
            path.push(name.to_string());
        }
        skip_ws(&mut at);
        if name.is_empty() || !code[at..].starts_with(b"::") {
            out.push(path);
            // `as alias` and the rest of the expression are no part of the path.
            return at;
        }
        at += 2;
    }
}

/// The absolute paths a library file names: `crate::`, `super::` and `self::`
/// paths and those through the child modules it declares, `use` trees expanded.
/// The inline test module is left out.
fn named_paths(text: &str, module: &[String]) -> Vec<Vec<String>> {
    let code = code_only(text);
    let code = match code.find("#[cfg(test)]\nmod tests {") {
        Some(i) => &code[..i],
        None => &code,
    };
    let bytes = code.as_bytes();
    let is_ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
    // Child modules declared with `mod name;` (files), which the file may name bare.
    let children: Vec<String> = code
        .lines()
        .filter_map(|l| {
            let l = l.trim();
            let l = l.strip_prefix("pub ").unwrap_or(l);
            let l = l.strip_prefix("pub(crate) ").unwrap_or(l);
            let name = l.strip_prefix("mod ")?.strip_suffix(';')?;
            Some(name.trim().to_string())
        })
        .collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        if !is_ident(bytes[i]) || (i > 0 && (is_ident(bytes[i - 1]) || bytes[i - 1] == b':')) {
            i += 1;
            continue;
        }
        let start = i;
        while i < bytes.len() && is_ident(bytes[i]) {
            i += 1;
        }
        let word = &code[start..i];
        if !code[i..].starts_with("::") {
            continue;
        }
        let mut base: Vec<String> = match word {
            "crate" => Vec::new(),
            "self" => module.to_vec(),
            "super" => module[..module.len().saturating_sub(1)].to_vec(),
            w if children.iter().any(|c| c == w) => {
                let mut m = module.to_vec();
                m.push(w.to_string());
                m
            }
            _ => continue,
        };
        i += 2;
        // `super::super::`.
        while code[i..].starts_with("super::") {
            base.pop();
            i += "super::".len();
        }
        i = path_tree(bytes, i, base, &mut out);
    }
    out
}

/// Which library file each library file uses: an edge to the file of the
/// longest module path that a named path starts with. Test-only files
/// (`tests.rs`, `*_tests.rs`), the binary's `main.rs` and `lib.rs` (the crate's
/// front door: its re-exports are for users, and `crate::Result` is no cycle)
/// are left out.
fn file_graph() -> BTreeMap<String, BTreeSet<String>> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut files = Vec::new();
    rust_files(&src, &mut files);
    files.retain(|f| {
        let name = f.file_name().unwrap().to_string_lossy();
        let front = f.parent() == Some(src.as_path()) && (name == "main.rs" || name == "lib.rs");
        !front && name != "tests.rs" && !name.ends_with("_tests.rs")
    });
    let modules: BTreeMap<Vec<String>, String> = files
        .iter()
        .map(|f| {
            let rel = f
                .strip_prefix(&src)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            (module_path(&src, f), rel)
        })
        .collect();
    let mut edges: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (module, from) in &modules {
        let text = std::fs::read_to_string(src.join(from)).unwrap();
        let entry = edges.entry(from.clone()).or_default();
        for path in named_paths(&text, module) {
            let to = (1..=path.len()).rev().find_map(|n| modules.get(&path[..n]));
            if let Some(to) = to.filter(|to| *to != from) {
                entry.insert(to.clone());
            }
        }
    }
    edges
}

/// A cycle in `edges`, if there is one, as the list of its nodes.
fn find_cycle(edges: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    fn visit(
        node: &str,
        edges: &BTreeMap<String, BTreeSet<String>>,
        state: &mut BTreeMap<String, u8>,
        stack: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        state.insert(node.to_string(), 1);
        stack.push(node.to_string());
        for next in edges.get(node).into_iter().flatten() {
            match state.get(next.as_str()) {
                Some(1) => {
                    let start = stack.iter().position(|n| n == next).unwrap();
                    return Some(stack[start..].to_vec());
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(next, edges, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(node.to_string(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for node in edges.keys() {
        if !state.contains_key(node) {
            if let Some(c) = visit(node, edges, &mut state, &mut Vec::new()) {
                return Some(c);
            }
        }
    }
    None
}

/// Every edge `a -> b` of `edges` that lies on a cycle (`b` reaches `a`).
fn edges_on_cycles(edges: &BTreeMap<String, BTreeSet<String>>) -> Vec<String> {
    let reaches = |from: &str, to: &str| {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.to_string()];
        while let Some(n) = todo.pop() {
            if n == to {
                return true;
            }
            if seen.insert(n.clone()) {
                todo.extend(edges.get(&n).into_iter().flatten().cloned());
            }
        }
        false
    };
    let mut out = Vec::new();
    for (a, tos) in edges {
        for b in tos {
            if reaches(b, a) {
                out.push(format!("{a} -> {b}"));
            }
        }
    }
    out
}

#[test]
fn no_import_cycles_between_files() {
    let edges = file_graph();
    let on_cycles = edges_on_cycles(&edges);
    assert!(
        on_cycles.is_empty(),
        "imports on a cycle between files (move what both need into a file of its own): {on_cycles:#?}"
    );
}

#[test]
fn the_file_checker_sees_super_and_child_paths() {
    let module: Vec<String> = ["solver", "calibrate", "fit"].map(String::from).to_vec();
    let text = "use super::{types::Stage, warm::{self, WarmStart}};\n\
                // use crate::app::config;\n\
                fn f() { let s = \"crate::app::x\"; super::super::robust::go(); }\n\
                use crate::model::{camera::Pose, target};\n";
    let paths = named_paths(text, &module);
    let expect: Vec<Vec<String>> = [
        "solver::calibrate::types::Stage",
        "solver::calibrate::warm",
        "solver::calibrate::warm::WarmStart",
        "solver::robust::go",
        "model::camera::Pose",
        "model::target",
    ]
    .iter()
    .map(|p| p.split("::").map(String::from).collect())
    .collect();
    assert_eq!(paths, expect);
    // A parent that names its child and a child that names its parent close a cycle.
    let parent = named_paths("mod a;\npub use a::Thing;\n", &["m".to_string()]);
    assert_eq!(
        parent,
        vec![vec!["m".to_string(), "a".into(), "Thing".into()]]
    );
    let mut edges = BTreeMap::new();
    edges.insert(
        "m/mod.rs".to_string(),
        BTreeSet::from(["m/a.rs".to_string()]),
    );
    edges.insert(
        "m/a.rs".to_string(),
        BTreeSet::from(["m/mod.rs".to_string()]),
    );
    assert!(find_cycle(&edges).is_some());
    // And the real graph has the edges it must have.
    let graph = file_graph();
    assert!(graph["solver/problem.rs"].contains("solver/bridge.rs"));
    assert!(graph["solver/calibrate/mod.rs"].contains("solver/calibrate/fit.rs"));
    assert!(graph["app/protocol/plan.rs"].contains("app/protocol/run.rs"));
}
