#!/usr/bin/env bash
# The whole test suite, from a fresh machine: installs what the tests need when it is missing
# (tshark, iproute2 and iputils-ping from Debian, pysoem and kickcat from PyPI into .venv, cargo-nextest and cargo-fuzz from
# crates.io), then runs unit, property and
# integration tests with nextest, and every fuzz target for a bounded time (before the tests,
# so that the run ends on the test summary).
#
#   scripts/test.sh                 everything
#   FUZZ_SECONDS=0 scripts/test.sh  skip fuzzing
#   FERROCAT_SHARED=/path/to/shared scripts/test.sh
set -euo pipefail
cd "$(dirname "$0")/.."

FUZZ_SECONDS="${FUZZ_SECONDS:-20}"
log() { printf '\n== %s\n' "$*"; }
as_root() { if [ "$(id -u)" = 0 ]; then "$@"; elif command -v sudo >/dev/null; then sudo "$@"; else
  echo "need root to run: $*" >&2; exit 1; fi; }

# --- tools ---------------------------------------------------------------------------------
if ! command -v tshark >/dev/null; then
  log "installing tshark (Debian package; Wireshark's dissectors are the independent decoder)"
  export DEBIAN_FRONTEND=noninteractive
  echo "wireshark-common wireshark-common/install-setuid boolean false" | as_root debconf-set-selections || true
  as_root apt-get update -qq
  as_root apt-get install -y -qq --no-install-recommends tshark >/dev/null
fi
if ! command -v ip >/dev/null; then
  log "installing iproute2 (network namespaces and veth pairs for the live tests)"
  as_root apt-get update -qq
  DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends iproute2 >/dev/null
fi
if ! command -v ping >/dev/null; then
  log "installing iputils-ping (Linux's own ping through an EoE bridge)"
  as_root apt-get update -qq
  DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends iputils-ping >/dev/null
fi
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c 'import pysoem, kickcat' 2>/dev/null; then
  log "creating .venv with pysoem and kickcat (SOEM and KickCAT as independent masters)"
  python3 -m venv .venv
  .venv/bin/pip install -q --disable-pip-version-check pysoem 'kickcat>=2.5'
fi
export FERROCAT_PYTHON="$(pwd)/.venv/bin/python"
if ! cargo nextest --version >/dev/null 2>&1; then
  log "installing cargo-nextest"
  cargo install cargo-nextest --locked
fi
if [ "$FUZZ_SECONDS" != 0 ] && ! cargo fuzz --version >/dev/null 2>&1; then
  log "installing cargo-fuzz"
  cargo install cargo-fuzz --locked
fi

# --- shared data ---------------------------------------------------------------------------
shared="${FERROCAT_SHARED:-$(pwd)/../shared}"
filter=()
if [ -d "$shared/captures" ]; then
  export FERROCAT_SHARED="$(cd "$shared" && pwd)"
  echo "shared test data: $FERROCAT_SHARED"
else
  echo "SKIPPED: tests named needs_shared_* — shared test data not found at $shared (set FERROCAT_SHARED)"
  filter=(-E 'not test(needs_shared)')
fi

# --- checks and tests ----------------------------------------------------------------------
log "cargo fmt --check"
cargo fmt --all -- --check
log "cargo doc (warnings are errors: broken intra-doc links)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --quiet
log "cargo package (every crate packs: licences, metadata, versions of the path dependencies)"
cargo package --workspace --no-verify --quiet

# --- fuzzing -------------------------------------------------------------------------------
if [ "$FUZZ_SECONDS" != 0 ]; then
  # cargo-fuzz needs nightly flags: use a nightly toolchain if rustup has one, else let the
  # stable compiler accept them.
  if rustup toolchain list 2>/dev/null | grep -q '^nightly'; then fuzz=(cargo +nightly fuzz); else
    export RUSTC_BOOTSTRAP=1; fuzz=(cargo fuzz); fi
  log "fuzzing each target for ${FUZZ_SECONDS}s"
  (cd fuzz && "${fuzz[@]}" build -O)
  for t in $(cd fuzz && "${fuzz[@]}" list); do
    out="$(mktemp)"
    # A target with seeds in fuzz/seeds/ starts from them (the device target: a whole ESI file,
    # more than any 20 s of mutation finds from nothing).
    corpus=()
    if [ -d "fuzz/seeds/$t" ]; then mkdir -p "fuzz/corpus/$t"; corpus=("corpus/$t" "seeds/$t"); fi
    if ! (cd fuzz && "${fuzz[@]}" run -O "$t" "${corpus[@]}" -- -max_total_time="$FUZZ_SECONDS" -max_len=8192) >"$out" 2>&1; then
      tail -n 60 "$out"
      echo "fuzz target $t FAILED (crash input saved under fuzz/artifacts/$t)"
      exit 1
    fi
    echo "fuzz target $t: $(grep -E 'DONE' "$out" | tail -n 1)"
    rm -f "$out"
  done
fi

# Tests last, so that the run closes on nextest's summary.
log "tests (cargo nextest)"
cargo nextest run --workspace --no-fail-fast "${filter[@]}"

log "all tests passed"
