//! The command lists are what `--help` says: every subcommand docs/cli.md and the README's tour
//! name exists, every option they show is one the subcommand takes, and every subcommand
//! `--help` lists is in docs/cli.md.
use std::process::Command;

fn help(path: &[&str]) -> String {
    let out = Command::new(env!("CARGO_BIN_EXE_ferrocat")).args(path).arg("--help").output().unwrap();
    assert!(out.status.success(), "ferrocat {path:?} --help: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// The subcommands a `--help` page lists under "Commands:".
fn subcommands(page: &str) -> Vec<String> {
    page.split("Commands:")
        .nth(1)
        .map(|rest| {
            rest.lines()
                .skip(1)
                .take_while(|l| l.starts_with("  "))
                .filter_map(|l| l.split_whitespace().next())
                .filter(|c| *c != "help")
                .map(String::from)
                .collect()
        })
        .unwrap_or_default()
}

/// The first ```sh block after `heading` in the file at `path` (from the repository's root).
fn block(path: &str, heading: &str) -> String {
    let text = std::fs::read_to_string(format!("{}/../../{path}", env!("CARGO_MANIFEST_DIR"))).unwrap();
    let after = text.split(heading).nth(1).unwrap_or_else(|| panic!("{path}: no {heading:?}"));
    after.split("```sh").nth(1).unwrap().split("```").next().unwrap().to_string()
}

/// Every line of `block` names a subcommand that exists and only options it takes; the
/// subcommands named.
fn check(block: &str, place: &str) -> std::collections::BTreeSet<String> {
    let mut named = std::collections::BTreeSet::new();
    for line in block.lines().filter(|l| !l.trim().is_empty()) {
        let cmd = line.split('#').next().unwrap();
        let words: Vec<&str> = cmd.split_whitespace().skip_while(|w| *w != "ferrocat").skip(1).collect();
        // The subcommand path: leading words of lower-case letters and digits (a|b|c: each).
        let path: Vec<&str> = words
            .iter()
            .take_while(|w| w.chars().all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '|' || c == '-'))
            .filter(|w| !w.starts_with('-'))
            .copied()
            .collect();
        assert!(!path.is_empty(), "{line}");
        named.insert(path[0].to_string());
        let alternatives: Vec<Vec<&str>> = match path.get(1) {
            Some(sub) => sub.split('|').map(|s| vec![path[0], s]).collect(),
            None => vec![vec![path[0]]],
        };
        let pages: Vec<String> = alternatives.iter().map(|p| help(p)).collect();
        for flag in words.iter().flat_map(|w| w.split(['[', ']', '(', ')', '|', '='])).filter(|f| f.starts_with("--")) {
            let flag = flag.trim_end_matches('…').trim_end_matches(',');
            assert!(
                pages.iter().any(|p| p.contains(&format!("{flag} ")) || p.contains(&format!("{flag}\n"))),
                "{place}: `{line}`: {flag} is not in `ferrocat {} --help`",
                path.join(" ")
            );
        }
    }
    named
}

#[test]
fn the_command_lists_match_help() {
    // docs/cli.md lists every subcommand; the README's tour only real ones and real options.
    let named = check(&block("docs/cli.md", "## Every subcommand"), "docs/cli.md");
    for sub in subcommands(&help(&[])) {
        assert!(named.contains(&sub), "`ferrocat {sub}` is in --help but not in docs/cli.md's list");
    }
    let toured = check(&block("README.md", "## A tour"), "README.md");
    assert!(toured.len() >= 8, "the tour shows {toured:?}");
}
