#!/usr/bin/env bash
# A soak run (not in CI): ferrocat run, live and in real time, against `ferrocat sim` serving
# EK1100 + EL2004 + EL1004 + SERVO on a veth pair in namespaces this script makes and removes,
# the simulator losing 1 % of frames. Reports cycles, frames lost, slaves that left OP and came
# back, and the master's resident memory early in the run and at its end. Nothing may be lost
# for good (every slave in OP at the end) and memory must not grow.
#   SOAK_SECONDS (default 600), LOSS (default 0.01), CYCLE_US (default 1000). Needs root.
set -euo pipefail
cd "$(dirname "$0")/.."
SOAK_SECONDS="${SOAK_SECONDS:-600}"
LOSS="${LOSS:-0.01}"
CYCLE_US="${CYCLE_US:-1000}"
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
id=$$; m=fcsm$id; s=fcss$id
work=$(mktemp -d)
cleanup() { ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true; rm -rf "$work"; }
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "fsk${id}a" type veth peer name "fsk${id}b"
ip link set "fsk${id}a" netns "$m"; ip link set "fsk${id}b" netns "$s"
ip -n "$m" link set "fsk${id}a" up; ip -n "$s" link set "fsk${id}b" up
cat > "$work/seg.toml" <<TOML
seed = 1
loss_probability = $LOSS
[[device]]
builtin = "EK1100"
[[device]]
builtin = "EL2004"
[[device]]
builtin = "EL1004"
[[device]]
builtin = "SERVO"
TOML
ip netns exec "$s" "$bin" sim --config "$work/seg.toml" --iface "fsk${id}b" >"$work/sim.log" 2>&1 &
sim=$!
sleep 0.5
ip netns exec "$m" "$bin" run --iface "fsk${id}a" --dc --cycle-us "$CYCLE_US" --seconds "$SOAK_SECONDS" --json \
  >"$work/run.json" 2>"$work/run.log" &
run=$!
rss() { awk '/^VmRSS/ {print $2}' "/proc/$1/status" 2>/dev/null || echo 0; }
sleep 10
rss_start=$(rss "$run")
while kill -0 "$run" 2>/dev/null; do
  rss_end=$(rss "$run"); [ "$rss_end" != 0 ] && last=$rss_end
  sleep 1
done
wait "$run" || { echo "ferrocat run failed:"; tail -20 "$work/run.log"; exit 1; }
# What the slaves did, by kind of event (the run's stderr has one line each).
echo "events by slave and kind (most frequent first):"
grep -oE 's  .*' "$work/run.log" | sed -E 's/^s  //; s/ at [0-9.]+ s//' | cut -c1-100 | sort | uniq -c | sort -rn | head -8 || true
kill -TERM "$sim"; wait "$sim" 2>/dev/null || true
python3 - "$work/run.json" "$rss_start" "${last:-0}" "$SOAK_SECONDS" "$LOSS" <<'PY'
import json, sys
r = json.load(open(sys.argv[1])); start, end = int(sys.argv[2]), int(sys.argv[3])
s = r["slaves"]
print(f"soak: {sys.argv[4]} s at {r['cycle_us']} us, the simulator losing {float(sys.argv[5]) * 100:g} % of frames")
print(f"  cycles {r['cycles']} (skipped after stalls {r['cycles_skipped']}), frames lost {r['frames_lost']}, overruns {r['overruns']}, working-counter errors {r['wkc_errors']}")
print(f"  slaves: left OP {s['left_op']}, stopped answering {s['lost']}, brought back {s['recovered']}, in OP at the end {s['in_op_at_end']}/{s['count']}")
cs = r.get("clock_sync") or {}
print(f"  clock sync {cs.get('method')}: {cs.get('lock')}, offset {cs.get('offset_ns')} ns")
print(f"  resident memory: {start} KiB after 10 s, {end} KiB at the end ({end - start:+d} KiB)")
# The allocator's own noise is a few pages; anything the run keeps per cycle or per event shows
# as hundreds of KiB over ten minutes.
grew = end - start > 64
ok = s["in_op_at_end"] == s["count"] and not grew
print("  PASS" if ok else "  FAIL: " + ("a slave not in OP at the end; " if s["in_op_at_end"] != s["count"] else "") + ("memory grew by more than 64 KiB" if grew else ""))
sys.exit(0 if ok else 1)
PY
