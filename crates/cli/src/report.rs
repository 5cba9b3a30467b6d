//! Files the lab and the demo write: CSV from the rows they print, Markdown reports.
use std::path::Path;

use anyhow::Context;
use serde::Serialize;

/// Every scalar field of each row as a CSV column, in the rows' field order (lists stay in the
/// JSON); an absent value is an empty cell.
pub fn csv_of<T: Serialize>(rows: &[T]) -> String {
    let values: Vec<serde_json::Map<String, serde_json::Value>> = rows
        .iter()
        .filter_map(|r| serde_json::to_value(r).ok()?.as_object().cloned())
        .map(|o| o.into_iter().filter(|(_, v)| !v.is_array()).collect())
        .collect();
    let keys: Vec<String> = values.first().map(|o| o.keys().cloned().collect()).unwrap_or_default();
    let mut csv = keys.join(",") + "\n";
    for o in &values {
        let cells: Vec<String> = keys
            .iter()
            .map(|k| match &o[k] {
                serde_json::Value::String(s) => s.clone(),
                serde_json::Value::Null => String::new(),
                v => v.to_string(),
            })
            .collect();
        csv.push_str(&(cells.join(",") + "\n"));
    }
    csv
}

/// Checks, before any work, that `dir` can be an output folder: missing (it is made), or a
/// folder already.
pub fn check_out_dir(dir: &Path) -> anyhow::Result<()> {
    match std::fs::metadata(dir) {
        Ok(m) if !m.is_dir() => {
            anyhow::bail!("--out {}: that is a file; --out takes a folder (made if missing)", dir.display())
        }
        _ => Ok(()),
    }
}

/// Makes the output folder `dir` (and its parents) where it is missing.
pub fn make_dir(dir: &Path) -> anyhow::Result<()> {
    check_out_dir(dir)?;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))
}

/// Writes `text` to `dir/name`, making the folder first.
pub fn write(dir: &Path, name: &str, text: &str) -> anyhow::Result<()> {
    make_dir(dir)?;
    let path = dir.join(name);
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
}

/// Says on stderr which files `dir` holds now, after an experiment wrote them there: the
/// reports by name, the figures counted.
pub fn announce(dir: &Path) -> anyhow::Result<()> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("listing {}", dir.display()))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .collect();
    names.sort();
    eprintln!("{}", announcement(dir, &names));
    Ok(())
}

fn announcement(dir: &Path, names: &[String]) -> String {
    let is = |n: &String, ext: &str| n.ends_with(ext);
    let svg = names.iter().filter(|n| is(n, ".svg")).count();
    let png = names.iter().filter(|n| is(n, ".png")).count();
    let mut parts: Vec<String> = names.iter().filter(|n| !is(n, ".svg") && !is(n, ".png")).cloned().collect();
    match (svg, png) {
        (0, 0) => {}
        (s, p) if s == p => parts.push(format!("{s} figures, each as SVG and PNG")),
        (s, p) => parts.push(format!("figures: {s} SVG, {p} PNG")),
    }
    format!("wrote {} files to {}: {}", names.len(), dir.display(), parts.join(", "))
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_figures_are_counted_and_the_reports_named() {
        let names: Vec<String> =
            ["a.csv", "a.md", "f1.png", "f1.svg", "f2.png", "f2.svg"].iter().map(|s| s.to_string()).collect();
        assert_eq!(
            super::announcement(std::path::Path::new("out"), &names),
            "wrote 6 files to out: a.csv, a.md, 2 figures, each as SVG and PNG"
        );
    }
}
