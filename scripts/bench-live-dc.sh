#!/usr/bin/env bash
# Live clock sync on this host: `ferrocat run --dc` against `ferrocat sim` (EK1100, EL2004 and
# the built-in DC-synchronous servo) on a veth pair between two network namespaces this script
# creates and removes, every method at 1 ms and 250 us, on a short segment and on one whose
# master link makes the round trip about 60 % of the cycle. Prints the host's wake-up figures
# first (the wake_cost example), then per run: frames lost and overruns (% of cycles), slaves
# that left OP and what the simulator put each sync error down to, the lock at the end, when it
# first locked and how often it changed, the loop's CPU per cycle and its ratio to `none`'s,
# where the frames passed SYNC0, and the wake-up p99 and max. Then ferrocat's true error
# (median |master - reference|, from the simulator's clocks) by `lab live` with the probing
# budget its run chose. Needs root. SECONDS_EACH (default 60) sets each run's length; METHODS
# and CYCLES the runs (default every method, 1000 and 250).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
secs=${SECONDS_EACH:-60}
methods=${METHODS:-none conventional park2020 chen2016 pi ferrocat ferrocat-mfr}
cycles=${CYCLES:-1000 250}
id=$$
m=fclm$id; s=fcls$id
work=$(mktemp -d)
cleanup() {
  [ -n "${sim:-}" ] && kill -TERM "$sim" 2>/dev/null || true
  ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "fcl${id}a" type veth peer name "fcl${id}b"
ip link set "fcl${id}a" netns "$m"; ip link set "fcl${id}b" netns "$s"
for ns_if in "$m fcl${id}a" "$s fcl${id}b"; do
  set -- $ns_if
  ip netns exec "$1" sysctl -qw "net.ipv6.conf.$2.disable_ipv6=1"
  ip -n "$1" link set "$2" up
done

echo "host: $(nproc) CPUs, $(uname -r); $secs s a run"
cargo run -q --release -p ferrocat-link --example wake_cost 2>&1 | sed 's/^/  /'

segment() { # $1: master link in ns (0: the default)
  [ "$1" -gt 0 ] && echo "master_link_ns = $1"
  printf "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n"
}

printf '%-6s %-6s %-13s %7s %7s %4s %-22s %-9s %7s %5s %8s %5s %-9s %7s %7s\n' \
  segment cycle method "lost%" "over%" "left" "sim: side of errors" lock "locked" "chg" "cpu us" "x" "passage" "wake99" "wakemax"
budgets="$work/budgets"; : > "$budgets"
for cycle in $cycles; do
  for kind in short slow; do
    link=0; [ "$kind" = slow ] && link=$((cycle * 300))
    segment "$link" > "$work/seg.toml"
    none_cpu=""
    for method in $methods; do
      ip netns exec "$s" "$bin" sim --config "$work/seg.toml" --iface "fcl${id}b" --report "$work/sim.json" 2>/dev/null &
      sim=$!
      sleep 0.5
      ip netns exec "$m" "$bin" run --iface "fcl${id}a" --dc --sync "$method" --cycle-us "$cycle" --seconds "$secs" --json \
        > "$work/run.json" 2> "$work/run.err" || echo "  ($method failed: $(tail -1 "$work/run.err"))"
      kill -TERM "$sim"; wait "$sim" || true; sim=
      line=$(python3 - "$kind" "$cycle" "$method" "$work/run.json" "$work/run.err" "$work/sim.json" "${none_cpu:-0}" <<'PY'
import json, re, sys
kind, cycle, method, run, err, sim, none_cpu = sys.argv[1:]
v = json.load(open(run)); e = open(err).read(); s = json.load(open(sim))
cs = v.get("clock_sync") or {}
cpu = float(re.search(r"CPU time ([\d.]+) (?:us|µs) per cycle", e).group(1))
n = max(v["cycles"], 1)
# The simulator's sync errors by side (run steps the slaves down before its frames stop).
errs = [x["side"] for x in s.get("sync_errors", [])]
sides = ", ".join(f"{errs.count(k)} {k}" for k in ("no frames", "simulator", "phase") if errs.count(k)) or "none"
p = cs.get("passage_after_sync0") or {}
ratio = cpu / float(none_cpu) if float(none_cpu) > 0 else 1.0
after = cs.get("locked_after_s")
print(f"{kind:<6} {cycle:<6} {method:<13} {100*v['frames_lost']/n:7.3f} {100*v['overruns']/n:7.3f} "
      f"{v['slaves']['left_op']:4} {sides:<22} {cs.get('lock','-'):<9} {('%.2f s' % after) if after is not None else '-':>7} "
      f"{cs.get('lock_changes', 0):5} {cpu:8.1f} {ratio:5.2f} {p.get('min_us', 0):4.0f}-{p.get('max_us', 0):<4.0f} "
      f"{v['wake_latency']['p99_us']:7.0f} {v['wake_latency']['max_us']:7.0f}")
print(f"BUDGET {cs.get('probe_budget_us') or ''} CPU {cpu}")
PY
)
      echo "$line" | grep -v '^BUDGET'
      cpu=$(echo "$line" | sed -n 's/^BUDGET .* CPU //p')
      [ "$method" = none ] && none_cpu=$cpu
      budget=$(echo "$line" | sed -n 's/^BUDGET \([0-9.]*\) CPU.*/\1/p')
      [ "$method" = ferrocat ] && [ "$kind" = short ] && [ -n "$budget" ] && echo "$cycle $budget" >> "$budgets"
    done
  done
done

echo
echo "ferrocat's true error by lab live (2 slaves, the probe budget ferrocat's run chose; median |master - reference| in the ref |e|50 column):"
while read -r cycle budget; do
  b=${budget%.*}
  "$bin" lab live --method ferrocat --method ferrocat-mfr --cycle-us "$cycle" --seconds "$secs" --probe-budget-us "$b" 2>/dev/null \
    | sed -n '/^method/,$p' | sed "s/^/  $cycle us, budget $b us: /"
done < "$budgets"
