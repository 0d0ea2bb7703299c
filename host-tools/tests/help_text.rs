//! Help texts refer only to things a user has: README sections and files in
//! docs/, never the source (`crate::` paths, module docs), issue numbers or
//! files outside the repository.

use crate::cli_common;

use std::path::Path;

/// The stdout of a successful `dynocomp args`.
fn help(args: &[&str]) -> String {
    let (ok, out, err) = cli_common::dynocomp(args);
    assert!(ok, "dynocomp {args:?} failed: {err}");
    out
}

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap()
}

/// What is wrong with `help` (empty when nothing): forbidden words, README
/// sections that are not headings of `readme`, docs/ files that do not exist.
fn problems(help: &str, readme: &str) -> Vec<String> {
    let mut bad = Vec::new();
    for word in ["crate::", "issue #", "DESIGN.md", "module doc", "BENCHMARKS.md"] {
        if help.contains(word) {
            bad.push(format!("mentions `{word}`"));
        }
    }
    let headings: Vec<String> =
        readme.lines().filter(|l| l.starts_with('#')).map(|l| l.trim_start_matches('#').trim().to_string()).collect();
    for (i, _) in help.match_indices("README \"") {
        let rest = &help[i + 8..];
        let name = &rest[..rest.find('"').unwrap_or(rest.len())];
        if !headings.iter().any(|h| h == name) {
            bad.push(format!("README section \"{name}\" does not exist"));
        }
    }
    for (i, _) in help.match_indices("docs/") {
        let rest = &help[i..];
        let end = rest.find(|c: char| !(c.is_alphanumeric() || "/-_.".contains(c))).unwrap_or(rest.len());
        let file = rest[..end].trim_end_matches('.');
        if !repo().join(file).is_file() {
            bad.push(format!("{file} does not exist"));
        }
    }
    bad
}

#[test]
fn every_help_text_refers_only_to_what_users_have() {
    let readme = std::fs::read_to_string(repo().join("README.md")).unwrap();
    let top = help(&["--help"]);
    let commands: Vec<&str> = top
        .lines()
        .skip_while(|l| !l.starts_with("Commands:"))
        .skip(1)
        .take_while(|l| l.starts_with("  "))
        .filter_map(|l| l.split_whitespace().next())
        .filter(|c| *c != "help")
        .collect();
    assert!(commands.len() >= 7, "commands not found in: {top}");
    let mut all = Vec::new();
    for c in &commands {
        let text = help(&[c, "--help"]);
        all.extend(problems(&text, &readme).into_iter().map(|p| format!("{c} --help: {p}")));
    }
    assert!(all.is_empty(), "{}", all.join("\n"));

    // Control: each kind of problem is caught.
    let bad = "see `crate::design` (module doc), issue #15, DESIGN.md, README \"No such\" and docs/none.md";
    assert_eq!(problems(bad, &readme).len(), 6, "{:?}", problems(bad, &readme));
}
