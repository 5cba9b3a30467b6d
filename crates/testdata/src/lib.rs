//! Where the project's shared test data lives.
//!
//! Data in `../shared/` stays there (see its NOTICE.md). Every test that reads it goes through
//! this crate, which honours `FERROCAT_SHARED` and otherwise looks beside the checkout.
//!
//! Tests that need the data carry `needs_shared` in their name. When the folder is absent the
//! test command (`scripts/test.sh`) leaves them out and prints that they were skipped and why;
//! run directly, they fail with the reason instead of passing silently.
//!
//! It also holds [`CountingAllocator`], for the tests that assert a path allocates nothing.
use std::path::{Path, PathBuf};

mod counting;
pub use counting::{allocations, CountingAllocator};

pub const ENV: &str = "FERROCAT_SHARED";

/// The shared folder, or why it is not available.
pub fn try_shared_dir() -> Result<PathBuf, String> {
    let dir = match std::env::var_os(ENV) {
        Some(v) => PathBuf::from(v),
        None => Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared"),
    };
    if dir.join("captures").is_dir() {
        Ok(dir.canonicalize().unwrap_or(dir))
    } else {
        Err(format!(
            "shared test data not found at {} (set {ENV} to the folder holding captures/, esi/, papers/)",
            dir.display()
        ))
    }
}

/// The shared folder; panics with the reason when it is absent (see the crate docs).
pub fn shared_dir() -> PathBuf {
    try_shared_dir().unwrap_or_else(|reason| panic!("{reason}"))
}

/// A path inside the shared folder.
pub fn shared(rel: &str) -> PathBuf {
    shared_dir().join(rel)
}

/// All files in `shared/<dir>` whose name ends with `suffix`, sorted.
pub fn shared_files(dir: &str, suffix: &str) -> Vec<PathBuf> {
    let d = shared(dir);
    let mut v: Vec<PathBuf> = std::fs::read_dir(&d)
        .unwrap_or_else(|e| panic!("reading {}: {e}", d.display()))
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.file_name().and_then(|n| n.to_str()).is_some_and(|n| n.ends_with(suffix)))
        .collect();
    v.sort();
    v
}
