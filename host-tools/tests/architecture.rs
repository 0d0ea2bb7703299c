//! The host library's import graph (docs/architecture.md): no cycle between
//! its modules, and every stage imports only the stages below it.
//!
//! The graph is read from the sources: every `crate::…` and `super::…` path
//! outside comments, resolved to the module file it names (the longest
//! prefix that is a module of the crate).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// The stages, and the stages each may import (besides itself).
fn allowed(stage: &str) -> &'static [&'static str] {
    match stage {
        "leaf" => &[],
        "realize" => &["leaf"],
        "design" => &["leaf", "realize"],
        "offline" => &["leaf", "realize", "design"],
        "link" => &["leaf"],
        "eval" => &["leaf", "realize", "design", "offline", "simulate"],
        "report" => &["leaf", "realize", "design", "offline", "eval"],
        "cli" => &["leaf", "realize", "design", "offline", "link", "report", "eval", "simulate"],
        "simulate" => &["leaf"],
        other => panic!("unknown stage {other}"),
    }
}

/// The stage of a module path (`design::axis` → `design`).
fn stage(module: &[String]) -> &'static str {
    match module.first().map(String::as_str) {
        Some("realize") => "realize",
        Some("design") => "design",
        Some("offline") => "offline",
        Some("link") => "link",
        Some("report") => "report",
        Some("eval") => "eval",
        Some("cli") => "cli",
        Some("simulate") => "simulate",
        _ => "leaf",
    }
}

fn src_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every module file of the library: module path → file.
fn modules(dir: &Path, prefix: &[String], out: &mut BTreeMap<Vec<String>, PathBuf>) {
    for entry in std::fs::read_dir(dir).expect("read src") {
        let path = entry.expect("entry").path();
        let name = path.file_stem().and_then(|s| s.to_str()).expect("utf-8 name").to_string();
        if path.is_dir() {
            let mut p = prefix.to_vec();
            p.push(name);
            modules(&path, &p, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            if prefix.is_empty() && name == "main" {
                continue;
            }
            let mut p = prefix.to_vec();
            if name != "mod" && !(prefix.is_empty() && name == "lib") {
                p.push(name);
            }
            out.insert(p, path);
        }
    }
}

/// The text without comments (line comments, doc comments, block comments)
/// and without string literals' contents.
fn code_only(text: &str) -> String {
    let b = text.as_bytes();
    let mut out = String::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            i += 2;
            while i + 1 < b.len() && !b[i..].starts_with(b"*/") {
                i += 1;
            }
            i += 2;
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i += 1;
            out.push_str("\"\"");
        } else if b[i] == b'\'' && i + 2 < b.len() && (b[i + 2] == b'\'' || b[i + 1] == b'\\') {
            // a char literal ('"', '\n'); lifetimes ('a) have no closing quote
            let end = b[i + 1..].iter().position(|c| *c == b'\'').map_or(b.len(), |p| i + 2 + p);
            i = end;
        } else {
            out.push(b[i] as char);
            i += 1;
        }
    }
    out
}

/// The paths a `use` tree or expression path names, starting at `pos`
/// (just after `crate::` or `super::`), with `base` prepended.
fn paths_at(code: &[u8], mut pos: usize, base: Vec<String>, out: &mut Vec<Vec<String>>) -> usize {
    let mut path = base;
    loop {
        let start = pos;
        while pos < code.len() && (code[pos].is_ascii_alphanumeric() || code[pos] == b'_') {
            pos += 1;
        }
        if pos > start {
            path.push(String::from_utf8_lossy(&code[start..pos]).into_owned());
        }
        if code[pos..].starts_with(b"::{") {
            pos += 3;
            loop {
                while code[pos].is_ascii_whitespace() {
                    pos += 1;
                }
                if code[pos] == b'}' {
                    return pos + 1;
                }
                pos = paths_at(code, pos, path.clone(), out);
                while code[pos].is_ascii_whitespace() {
                    pos += 1;
                }
                if code[pos] == b',' {
                    pos += 1;
                }
            }
        } else if code[pos..].starts_with(b"::") {
            pos += 2;
        } else {
            // `as name`, `;`, `(`, … end the path
            while pos < code.len()
                && code[pos] != b','
                && code[pos] != b'}'
                && code[pos] != b';'
                && !code[pos].is_ascii_whitespace()
            {
                if !(code[pos].is_ascii_alphanumeric() || code[pos] == b'_') {
                    break;
                }
                pos += 1;
            }
            if code[pos..].starts_with(b" as ") {
                pos += 4;
                while pos < code.len() && (code[pos].is_ascii_alphanumeric() || code[pos] == b'_') {
                    pos += 1;
                }
            }
            out.push(path);
            return pos;
        }
    }
}

/// The modules a file imports: its `crate::` and `super::` paths resolved to
/// the longest module prefix.
fn imports(module: &[String], text: &str, all: &BTreeMap<Vec<String>, PathBuf>) -> BTreeSet<Vec<String>> {
    // Unit tests (a `#[cfg(test)]` module at the end of a file) may use
    // their siblings: they are not part of the library's graph.
    let text = text.find("#[cfg(test)]\nmod tests").map_or(text, |i| &text[..i]);
    let code = code_only(text);
    let b = code.as_bytes();
    let mut paths = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let boundary = i == 0 || !(b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_' || b[i - 1] == b':');
        if boundary && b[i..].starts_with(b"crate::") {
            i = paths_at(b, i + 7, Vec::new(), &mut paths);
        } else if boundary && b[i..].starts_with(b"super::") {
            // `super` leaves the module's own path (a mod.rs's path is its folder).
            let mut base = module.to_vec();
            let mut j = i;
            while b[j..].starts_with(b"super::") {
                base.pop();
                j += 7;
            }
            i = paths_at(b, j, base, &mut paths);
        } else {
            i += 1;
        }
    }
    let mut out = BTreeSet::new();
    for p in paths {
        let target = (1..=p.len()).rev().map(|n| p[..n].to_vec()).find(|m| all.contains_key(m));
        if let Some(t) = target {
            if t != module && !t.is_empty() {
                out.insert(t);
            }
        }
    }
    out
}

fn graph() -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let mut all = BTreeMap::new();
    modules(&src_dir(), &[], &mut all);
    all.iter()
        .map(|(m, path)| {
            let text = std::fs::read_to_string(path).expect("read module");
            (m.clone(), imports(m, &text, &all))
        })
        .collect()
}

fn name(m: &[String]) -> String {
    if m.is_empty() {
        "crate".into()
    } else {
        m.join("::")
    }
}

/// The import cycles: every strongly connected component of more than one
/// module (Tarjan's algorithm), each as its modules' names.
fn cycles(g: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<Vec<String>> {
    struct Tarjan<'g> {
        g: &'g BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        index: BTreeMap<&'g Vec<String>, (usize, usize)>,
        stack: Vec<&'g Vec<String>>,
        on_stack: BTreeSet<&'g Vec<String>>,
        out: Vec<Vec<String>>,
    }
    impl<'g> Tarjan<'g> {
        fn visit(&mut self, m: &'g Vec<String>) {
            let n = self.index.len();
            self.index.insert(m, (n, n));
            self.stack.push(m);
            self.on_stack.insert(m);
            for d in self.g.get(m).into_iter().flatten() {
                let Some((d, _)) = self.g.get_key_value(d) else { continue };
                if !self.index.contains_key(d) {
                    self.visit(d);
                    let low = self.index[d].1.min(self.index[m].1);
                    self.index.get_mut(m).expect("visited").1 = low;
                } else if self.on_stack.contains(d) {
                    let low = self.index[d].0.min(self.index[m].1);
                    self.index.get_mut(m).expect("visited").1 = low;
                }
            }
            if self.index[m].0 == self.index[m].1 {
                let mut scc = Vec::new();
                while let Some(x) = self.stack.pop() {
                    self.on_stack.remove(x);
                    scc.push(name(x));
                    if x == m {
                        break;
                    }
                }
                if scc.len() > 1 {
                    scc.sort();
                    self.out.push(scc);
                }
            }
        }
    }
    let mut t = Tarjan { g, index: BTreeMap::new(), stack: Vec::new(), on_stack: BTreeSet::new(), out: Vec::new() };
    for m in g.keys() {
        if !t.index.contains_key(m) {
            t.visit(m);
        }
    }
    t.out
}

/// Imports that break the stage order.
fn stage_violations(g: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Vec<String> {
    let mut bad = Vec::new();
    for (m, deps) in g {
        let s = stage(m);
        for d in deps {
            let t = stage(d);
            if t != s && !allowed(s).contains(&t) {
                bad.push(format!("{} ({s}) imports {} ({t})", name(m), name(d)));
            }
        }
    }
    bad
}

#[test]
fn the_module_graph_has_no_cycle() {
    let g = graph();
    assert!(g.len() > 40, "only {} modules found: the source walk is broken", g.len());
    let c = cycles(&g);
    let shown: Vec<String> = c.iter().map(|c| c.join(" ↔ ")).collect();
    assert!(c.is_empty(), "{} import cycles:\n{}", c.len(), shown.join("\n"));
}

#[test]
fn every_stage_imports_only_the_stages_below_it() {
    let v = stage_violations(&graph());
    assert!(v.is_empty(), "{} imports against the stage order:\n{}", v.len(), v.join("\n"));
}

/// Negative controls: the checks see a cycle and a stage violation when
/// one is there, and the parser resolves nested `use` trees.
#[test]
fn the_checks_see_what_they_look_for() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let mut all = BTreeMap::new();
    for k in ["design::axis", "design::kalman", "realize::modal", "report::plot", "cli::design", "frf"] {
        all.insert(m(k), PathBuf::new());
    }
    let text = "use crate::design::{axis::{A, B}, kalman};\n// use crate::cli::design;\nfn f() { crate::report::plot::x(); let s = \"crate::cli::design\"; }";
    let got = imports(&m("realize::modal"), text, &all);
    let want: BTreeSet<_> = [m("design::axis"), m("design::kalman"), m("report::plot")].into_iter().collect();
    assert_eq!(got, want);
    let with_tests = "use crate::design::kalman::X;\n#[cfg(test)]\nmod tests {\n    use crate::cli::design::Y;\n}\n";
    assert_eq!(imports(&m("realize::modal"), with_tests, &all), [m("design::kalman")].into_iter().collect());
    let sup = imports(&m("design::axis"), "use super::kalman::X;", &all);
    assert_eq!(sup, [m("design::kalman")].into_iter().collect());

    let mut g = BTreeMap::new();
    g.insert(m("design::axis"), [m("design::kalman")].into_iter().collect::<BTreeSet<_>>());
    g.insert(m("design::kalman"), [m("realize::modal")].into_iter().collect());
    g.insert(m("realize::modal"), BTreeSet::new());
    assert!(cycles(&g).is_empty());
    assert!(stage_violations(&g).is_empty());
    g.get_mut(&m("realize::modal")).unwrap().insert(m("design::axis"));
    assert_eq!(cycles(&g).len(), 1, "a cycle through three modules is missed");
    assert_eq!(stage_violations(&g).len(), 1, "realize importing design is missed");
}
