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

/// Writes `text` to `dir/name`, making the folder first.
pub fn write(dir: &Path, name: &str, text: &str) -> anyhow::Result<()> {
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let path = dir.join(name);
    std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))
}

/// Says on stderr which files `dir` holds now, after an experiment wrote them there.
pub fn announce(dir: &Path) -> anyhow::Result<()> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .with_context(|| format!("listing {}", dir.display()))?
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .collect();
    names.sort();
    eprintln!("wrote {} files to {}: {}", names.len(), dir.display(), names.join(", "));
    Ok(())
}
