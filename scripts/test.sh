#!/usr/bin/env bash
# The whole test suite, from a fresh machine: installs what the tests need when it is missing
# (tshark, iproute2, iputils-ping and libcap2-bin from Debian, pysoem, kickcat, pyetg1510 and
# pytest from PyPI
# into .venv with ferrocat's own Python package built from python/, cargo-nextest and cargo-fuzz
# from crates.io), then checks formatting, clippy, the API
# docs, `cargo package` and the Debian package, runs every fuzz target for a bounded time, and
# last the unit, property and integration tests with nextest (so that the run ends on the test
# summary). The live tests (cli/tests/*_live.rs) need root; without it they are skipped.
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
if ! command -v setcap >/dev/null || ! command -v setpriv >/dev/null; then
  log "installing libcap2-bin and util-linux (setcap, setpriv: the unprivileged-run tests)"
  as_root apt-get update -qq
  DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends libcap2-bin util-linux >/dev/null
fi
if ! command -v ping >/dev/null; then
  log "installing iputils-ping (Linux's own ping through an EoE bridge)"
  as_root apt-get update -qq
  DEBIAN_FRONTEND=noninteractive as_root apt-get install -y -qq --no-install-recommends iputils-ping >/dev/null
fi
if [ ! -x .venv/bin/python ] || ! .venv/bin/python -c 'import pysoem, kickcat, pyetg1510' 2>/dev/null; then
  log "creating .venv with pysoem, kickcat and pyetg1510 (SOEM and KickCAT as independent masters, an ETG.1510 client)"
  python3 -m venv .venv
  .venv/bin/pip install -q --disable-pip-version-check pysoem 'kickcat>=2.5' 'pyetg1510==0.1.3'
fi
# The Python package (python/, PyO3 + maturin) is built and installed into .venv on every run,
# so that it cannot rot: pip fetches maturin and cargo builds the extension (python/target).
log "building the Python package (pip install ./python) and pytest into .venv"
.venv/bin/pip install -q --disable-pip-version-check pytest ./python
export FERROCAT_PYTHON="$(pwd)/.venv/bin/python"
# The masters the tests start keep their locks, control sockets and shared images in a
# directory of the run's own (docs/service.md), not in /run/ferrocat.
export FERROCAT_RUN_DIR="$(mktemp -d -t ferrocat-run.XXXXXX)"
chmod 1777 "$FERROCAT_RUN_DIR"
trap 'rm -rf "$FERROCAT_RUN_DIR"' EXIT
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
skip=()
if [ -d "$shared/captures" ]; then
  export FERROCAT_SHARED="$(cd "$shared" && pwd)"
  echo "shared test data: $FERROCAT_SHARED"
else
  echo "SKIPPED: tests named needs_shared_* — shared test data not found at $shared (set FERROCAT_SHARED)"
  skip+=('test(needs_shared)')
fi
# The live tests (cli/tests/*_live.rs) make network namespaces, veth pairs and raw sockets.
if [ "$(id -u)" != 0 ]; then
  echo "SKIPPED: the live tests (cli/tests/*_live.rs) — they make network namespaces and raw sockets, which needs root"
  skip+=('binary(~_live)')
fi
filter=()
if [ ${#skip[@]} -gt 0 ]; then
  joined=$(printf ' or %s' "${skip[@]}")
  filter=(-E "not (${joined# or })")
fi

# --- checks and tests ----------------------------------------------------------------------
log "cargo fmt --check"
cargo fmt --all -- --check
if cargo clippy --version >/dev/null 2>&1; then
  log "cargo clippy (warnings are errors)"
  cargo clippy --workspace --all-targets --quiet -- -D warnings
else
  echo "SKIPPED: cargo clippy — this toolchain has no clippy component"
fi
# An application on a real NIC compiles no simulator: the master depends on the wire, link and
# ESI crates only (docs/architecture.md).
log "layering: what ferrocat-master compiles in"
deps=$(cargo tree -p ferrocat-master -e normal --prefix none --format '{p}' | cut -d' ' -f1 | sort -u)
for banned in ferrocat-segment ferrocat-sim ferrocat-esc ferrocat-capture ferrocat-lab rand rand_chacha rand_distr roxmltree; do
  if grep -qx "$banned" <<<"$deps"; then echo "ferrocat-master depends on $banned"; exit 1; fi
done
echo "ferrocat-master depends on: $(grep '^ferrocat-' <<<"$deps" | grep -vx ferrocat-master | tr '\n' ' ')(and $(grep -vc '^ferrocat-' <<<"$deps") outside crates)"
# The simulated segment is deterministic and compiles no socket: serving it live is ferrocat-sim's.
segdeps=$(cargo tree -p ferrocat-segment -e normal --prefix none --format '{p}' | cut -d' ' -f1 | sort -u)
for banned in ferrocat-link io-uring; do
  if grep -qx "$banned" <<<"$segdeps"; then echo "ferrocat-segment depends on $banned"; exit 1; fi
done
log "the Python package's crate: rustfmt and clippy (its own workspace)"
cargo fmt --manifest-path python/Cargo.toml -- --check
if cargo clippy --version >/dev/null 2>&1; then
  cargo clippy --manifest-path python/Cargo.toml --quiet -- -D warnings
fi
log "cargo doc (warnings are errors: broken intra-doc links)"
RUSTDOCFLAGS="-D warnings" cargo doc --workspace --no-deps --quiet
log "doctests (nextest runs none)"
cargo test --doc --workspace --quiet
log "cargo package (every crate packs: licences, metadata, versions of the path dependencies)"
cargo package --workspace --no-verify --quiet

# The Debian package: built by its script (cargo install --locked inside), then inspected.
log "Debian package (scripts/package-deb.sh), and what it holds"
deb=$(scripts/package-deb.sh target/debian)
debroot=$(mktemp -d)
dpkg-deb -x "$deb" "$debroot"
dpkg-deb -e "$deb" "$debroot/DEBIAN"
for f in usr/bin/ferrocat usr/share/man/man1/ferrocat.1.gz usr/share/man/man1/ferrocat-run.1.gz \
  usr/share/man/man1/ferrocat-sdo-read.1.gz usr/share/bash-completion/completions/ferrocat \
  usr/share/zsh/vendor-completions/_ferrocat usr/share/fish/vendor_completions.d/ferrocat.fish \
  usr/share/doc/ferrocat/copyright usr/share/doc/ferrocat/examples/ferrocat-run@.service \
  usr/share/doc/ferrocat/examples/ferrocat-sim@.service; do
  [ -s "$debroot/$f" ] || { echo "the package lacks $f"; exit 1; }
done
"$debroot/usr/bin/ferrocat" --version | grep -q "^ferrocat " || { echo "the packaged binary does not run"; exit 1; }
zcat "$debroot/usr/share/man/man1/ferrocat-run.1.gz" | grep -qF 'cycle\-us' || { echo "ferrocat-run(1) lacks --cycle-us"; exit 1; }
grep -q "Depends: .*libcap2-bin" "$debroot/DEBIAN/control" || { echo "control lacks libcap2-bin"; exit 1; }
grep -q "setcap cap_net_raw,cap_sys_nice,cap_ipc_lock+ep /usr/bin/ferrocat" "$debroot/DEBIAN/postinst" \
  || { echo "postinst grants no capabilities"; exit 1; }
bash -n "$debroot/usr/share/bash-completion/completions/ferrocat"
echo "$(basename "$deb"): $(dpkg-deb -c "$deb" | wc -l) entries, $(du -h "$deb" | cut -f1); postinst: setcap cap_net_raw,cap_sys_nice,cap_ipc_lock+ep"
rm -rf "$debroot"

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

log "the Python package's tests (pytest, virtual time; its live tests are crates/cli/tests/python_live.rs)"
.venv/bin/python -m pytest -q python/tests

# The examples the live tests run (examples_live, service_live) are built here, as those tests
# build them (one package each: its own features), so that their build does not run inside a
# test beside the others (219 s in a fresh clone, past the live tests' 60 s warning).
log "the examples the live tests run"
cargo build --quiet -p ferrocat-master --examples
cargo build --quiet -p ferrocat-service --examples
# Tests last, so that the run closes on nextest's summary.
log "tests (cargo nextest)"
cargo nextest run --workspace --no-fail-fast "${filter[@]}"

log "all tests passed"
