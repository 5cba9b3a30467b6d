#!/usr/bin/env bash
# ferrocat, ethercrab and SOEM (pysoem) side by side, in one run, against the same release
# `ferrocat sim` serving 16 slaves on a veth pair in namespaces this script makes and removes:
# time from start to OP, the highest sustained rate of a one-frame LRW + FRMW cycle, and the
# master's CPU time per cycle. Needs root and scripts/test.sh's .venv (pysoem).
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH="${SECONDS_EACH:-3}"
cargo build -q --release -p ferrocat --example ethercrab_bench
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
id=$$; m=fcmm$id; s=fcms$id
cleanup() { ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true; }
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "fcm${id}a" type veth peer name "fcm${id}b"
ip link set "fcm${id}a" netns "$m"; ip link set "fcm${id}b" netns "$s"
ip -n "$m" link set "fcm${id}a" up; ip -n "$s" link set "fcm${id}b" up
devices=(--device EK1100)
for k in $(seq 1 15); do if (( k % 2 )); then devices+=(--device EL1004); else devices+=(--device EL2004); fi; done
run_sim() { ip netns exec "$s" "$bin" sim "${devices[@]}" --iface "fcm${id}b" >/dev/null 2>&1 & echo $!; }
for master in ferrocat ethercrab soem; do
  sim=$(run_sim); sleep 0.5
  case $master in
    ferrocat) ip netns exec "$m" "$bin" run --iface "fcm${id}a" --dc --max-rate --seconds "$SECONDS_EACH" 2>&1 \
                | grep -E "bring-up|cyclic rate" | tr '\n' ' '; echo ;;
    ethercrab) ip netns exec "$m" target/release/examples/ethercrab_bench "fcm${id}a" "$SECONDS_EACH" ;;
    soem) ip netns exec "$m" .venv/bin/python crates/cli/tests/python/soem_bench.py "fcm${id}a" "$SECONDS_EACH" ;;
  esac
  kill -TERM "$sim"; while kill -0 "$sim" 2>/dev/null; do sleep 0.1; done
done
