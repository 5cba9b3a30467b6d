#!/usr/bin/env bash
# What diagnosis in OP costs the cyclic loop: `ferrocat run` against `ferrocat sim` (an EK1100,
# I/O terminals and the built-in servo, 0.1 % of frames corrupted so that the error counters
# grow) on a veth pair between two network namespaces this script creates and removes, at 1 ms
# and 250 us, with diagnosis (error counters every second, a mailbox every cycle) and without,
# alternately. Prints each run's wake-up p99 and max, overruns, frames lost and what diagnosis
# read. Needs root. SECONDS_EACH (default 20) sets each run's length, ROUNDS (default 2) how
# often each pairing runs; DC=1 runs with --dc, so that diagnosis also reads the servo's
# sync-error flags (0x1C32:20 and 0x1C33:20).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
id=$$
m=fcdm$id; s=fcds$id
seg=$(mktemp --suffix=.toml)
cleanup() {
  [ -n "${sim:-}" ] && kill -TERM "$sim" 2>/dev/null || true
  ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true
  rm -f "$seg"
}
trap cleanup EXIT
cat > "$seg" <<'TOML'
seed = 5
corruption_probability = 0.001
[[device]]
builtin = 'EK1100'
[[device]]
builtin = 'EL2004'
[[device]]
builtin = 'EL1004'
[[device]]
builtin = 'SERVO'
TOML
ip netns add "$m"; ip netns add "$s"
ip link add "fcd${id}a" type veth peer name "fcd${id}b"
ip link set "fcd${id}a" netns "$m"; ip link set "fcd${id}b" netns "$s"
ip -n "$m" link set "fcd${id}a" up; ip -n "$s" link set "fcd${id}b" up
ip netns exec "$s" "$bin" sim --config "$seg" --iface "fcd${id}b" 2>/dev/null &
sim=$!
sleep 0.5
echo "host: $(nproc) CPUs, $(uname -r); ${SECONDS_EACH:-20} s a run"
printf '%-8s %-10s %10s %10s %9s %7s %9s %9s %6s\n' cycle diagnosis "wake p99" "wake max" overruns lost "counters" "polls" "flags"
for round in $(seq "${ROUNDS:-2}"); do
  for cycle in 1000 250; do
    for diag in on off; do
      flag=(); [ "$diag" = off ] && flag=(--no-diagnosis)
      [ "${DC:-0}" = 1 ] && flag+=(--dc)
      out=$(ip netns exec "$m" "$bin" run --iface "fcd${id}a" --cycle-us "$cycle" --seconds "${SECONDS_EACH:-20}" --json "${flag[@]}" 2>/dev/null)
      python3 - "$cycle" "$diag" "$out" <<'PY'
import json, sys
cycle, diag, v = sys.argv[1], sys.argv[2], json.loads(sys.argv[3])
d = v.get("diagnosis") or {}
w = v["wake_latency"]
print(f"{cycle+' us':<8} {diag:<10} {w['p99_us']:>8.1f}us {w['max_us']:>8.1f}us {v['overruns']:>9} {v['frames_lost']:>7} "
      f"{d.get('counter_reads', '-'):>9} {d.get('mailbox_polls', '-'):>9} {d.get('sync_flag_reads', '-'):>6}")
PY
    done
  done
done
