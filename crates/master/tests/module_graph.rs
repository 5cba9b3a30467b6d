//! The master's modules depend on one another without a cycle: each top-level module's
//! `crate::` paths (outside comments and test code, root re-exports resolved through lib.rs),
//! and its calls of the `Master`'s methods that another module defines, form an acyclic
//! graph. A module that both uses `master` and is used by it would tie the two together
//! again; types the master keeps live in leaf modules instead (`cycle_state`, `eoe_link`,
//! `event`, `sync::SyncState`, `far_clock`), the mailbox layer and the CoE client over it
//! borrow the engine and the slave table without knowing the master (`mailbox`, `coe`), and
//! the clients (DC, process data, bring-up, FoE, EoE, CiA402) build on `master` from outside.
use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

fn sources(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            sources(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The code of a file: test modules and comments left out.
fn code(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        let line = line.split("//").next().unwrap_or("");
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// The modules named by `crate::…` paths in `code`; capitalised names through `reexports`.
fn targets(code: &str, reexports: &BTreeMap<String, String>) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(at) = rest.find("crate::") {
        rest = &rest[at + "crate::".len()..];
        let names: Vec<&str> = if let Some(group) = rest.strip_prefix('{') {
            group.split('}').next().unwrap_or("").split(',').map(str::trim).collect()
        } else {
            vec![rest]
        };
        for n in names {
            let ident: String = n.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            if ident.is_empty() {
                continue;
            }
            match ident.chars().next() {
                Some(c) if c.is_uppercase() => {
                    if let Some(m) = reexports.get(&ident) {
                        found.insert(m.clone());
                    }
                }
                _ => {
                    found.insert(ident);
                }
            }
        }
    }
    found
}

/// The names of the functions in `code`'s `impl<I: Io> Master<I>` blocks and in its blocks of
/// the master's parts (`impl<'a, I: Io> crate::master::part::Dc<'a, I>`), and of every other
/// function in it.
fn functions(code: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let (mut on_master, mut other) = (BTreeSet::new(), BTreeSet::new());
    let fn_name = |s: &str| s.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect::<String>();
    // Depth of braces, and the depth at which a Master impl block's body starts.
    let (mut depth, mut master_body) = (0usize, None::<usize>);
    let mut rest = code;
    while !rest.is_empty() {
        if rest.starts_with("impl<I: Io> Master<I> {") || rest.starts_with("impl<'a, I: Io> crate::master::part::") {
            master_body = Some(depth + 1);
        }
        if let Some(after) = rest.strip_prefix("fn ") {
            let name = fn_name(after);
            if !name.is_empty() {
                if master_body == Some(depth) {
                    on_master.insert(name);
                } else {
                    other.insert(name);
                }
            }
        }
        let c = rest.chars().next().unwrap();
        match c {
            '{' => depth += 1,
            '}' => {
                if master_body == Some(depth) {
                    master_body = None;
                }
                depth = depth.saturating_sub(1);
            }
            _ => {}
        }
        rest = &rest[c.len_utf8()..];
    }
    (on_master, other)
}

/// The `Master` methods (and its parts') that `code` calls on `self`, on a master (`m.`,
/// `master.`) or on a part (`.dc().`), of those in `methods`.
fn master_calls<'a>(code: &str, methods: &'a BTreeMap<String, String>) -> BTreeSet<&'a str> {
    methods
        .iter()
        .filter(|(name, _)| {
            let parts = ["states", "config", "cyclic", "image", "dc", "clock", "acyclic", "diagnosis"];
            let on_part = parts.iter().any(|p| code.contains(&format!(".{p}().{name}(")));
            on_part
                || ["self.", "m.", "master."].iter().any(|recv| {
                    code.match_indices(&format!("{recv}{name}(")).any(|(at, _)| {
                        // A whole receiver: `self.coe(`, not `myself.coe(`.
                        code[..at].chars().next_back().is_none_or(|c| !(c.is_alphanumeric() || c == '_' || c == '.'))
                    })
                })
        })
        .map(|(_, module)| module.as_str())
        .collect()
}

#[test]
fn the_masters_modules_form_no_cycle() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let lib = std::fs::read_to_string(src.join("lib.rs")).unwrap();
    // `pub use module::{A, B};` and `pub use module::A;` at the crate root.
    let mut reexports = BTreeMap::new();
    for line in lib.lines().filter_map(|l| l.trim().strip_prefix("pub use ")) {
        let Some((module, names)) = line.trim_end_matches(';').split_once("::") else { continue };
        for n in names.trim_matches(|c| c == '{' || c == '}').split(',') {
            reexports.insert(n.trim().to_string(), module.to_string());
        }
    }
    let mut files = Vec::new();
    sources(&src, &mut files);
    let mut modules = Vec::new();
    for f in &files {
        let rel = f.strip_prefix(&src).unwrap();
        if rel == Path::new("lib.rs") || rel.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let top = rel.components().next().unwrap().as_os_str().to_string_lossy().trim_end_matches(".rs").to_string();
        modules.push((top, code(&std::fs::read_to_string(f).unwrap())));
    }
    // Each method of the `Master`, by the module that defines it; a name that any other
    // function also has (another type's method, a free function) is left out: a call of it
    // could be either.
    let (mut defined, mut elsewhere): (BTreeMap<String, BTreeSet<String>>, BTreeSet<String>) = Default::default();
    for (top, code) in &modules {
        let (on_master, other) = functions(code);
        for name in on_master {
            defined.entry(name).or_default().insert(top.clone());
        }
        elsewhere.extend(other);
    }
    let methods: BTreeMap<String, String> = defined
        .into_iter()
        .filter(|(name, tops)| tops.len() == 1 && !elsewhere.contains(name))
        .map(|(name, tops)| (name, tops.into_iter().next().unwrap()))
        .collect();
    assert!(methods.get("coe").is_some_and(|m| m == "master"), "the master's methods were read: {methods:?}");
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (top, code) in &modules {
        let deps = targets(code, &reexports);
        let calls = master_calls(code, &methods).into_iter().map(str::to_string);
        graph.entry(top.clone()).or_default().extend(deps.into_iter().chain(calls).filter(|d| d != top));
    }
    for (m, deps) in &graph {
        println!("{m} → {}", deps.iter().cloned().collect::<Vec<_>>().join(", "));
    }
    assert!(
        graph["master"].contains("engine") && graph["bring_up"].contains("process") && graph["dc"].contains("master"),
        "the graph was read: {graph:?}"
    );
    // Depth-first search for a back edge.
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        path: &mut Vec<String>,
        done: &mut BTreeSet<String>,
    ) -> Option<Vec<String>> {
        if let Some(i) = path.iter().position(|p| p == m) {
            let mut cycle = path[i..].to_vec();
            cycle.push(m.to_string());
            return Some(cycle);
        }
        if done.contains(m) {
            return None;
        }
        path.push(m.to_string());
        for d in graph.get(m).into_iter().flatten() {
            if let Some(c) = visit(d, graph, path, done) {
                return Some(c);
            }
        }
        path.pop();
        done.insert(m.to_string());
        None
    }
    let mut done = BTreeSet::new();
    for m in graph.keys() {
        if let Some(cycle) = visit(m, &graph, &mut Vec::new(), &mut done) {
            panic!("module cycle: {}", cycle.join(" → "));
        }
    }
}
