#!/usr/bin/env bash
# Runs the headline experiments (quick variants, seed 1) and writes docs/results.md; the test
# crates/cli/tests/results_current.rs checks that the committed file is what the code gives.
set -euo pipefail
cd "$(dirname "$0")/.."
FERROCAT_WRITE_RESULTS=1 cargo test --release -p ferrocat --test results_current -- --nocapture
git --no-pager diff --stat -- docs/results.md || true
