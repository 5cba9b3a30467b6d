#!/usr/bin/env bash
# Clean release build time of an application that uses only ferrocat-master (a raw-socket
# program of one line), in a scratch crate with its own target directory, and how many crates
# it compiles. With a git revision as argument, the master of that revision is built too, one
# after the other, for a side-by-side figure.
#
#   scripts/app-build-time.sh [REV]
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
work="$(mktemp -d)"
trap 'git -C "$root" worktree remove --force "$work/tree" 2>/dev/null || true; rm -rf "$work"' EXIT

measure() { # label, path of the workspace whose crates/master to use
  local app="$work/app-$1"
  mkdir -p "$app/src"
  cat >"$app/Cargo.toml" <<TOML
[package]
name = "app"
version = "0.1.0"
edition = "2021"
[dependencies]
ferrocat-master = { path = "$2/crates/master" }
[workspace]
TOML
  echo 'fn main() { println!("{}", ferrocat_master::io::RawIo::open("lo").is_ok()); }' >"$app/src/main.rs"
  (cd "$app" && cargo fetch -q)
  local t0 t1
  t0=$(date +%s.%N)
  (cd "$app" && CARGO_TARGET_DIR="$app/target" cargo build --release -q)
  t1=$(date +%s.%N)
  printf '%-10s %6.1f s  %3d crates\n' "$1" "$(echo "$t1 - $t0" | bc)" \
    "$(cd "$app" && cargo tree -e normal --prefix none | sort -u | wc -l)"
}

if [ $# -gt 0 ]; then
  git -C "$root" worktree add -q --detach "$work/tree" "$1"
  measure "$1" "$work/tree"
fi
measure "this tree" "$root"
