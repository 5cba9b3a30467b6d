#!/usr/bin/env bash
# The cyclic loop beside clients: `ferrocat run --dc` against `ferrocat sim` (EK1100, EL2004,
# the built-in servo) on a veth pair between two network namespaces this script creates and
# removes, at 1 ms and 250 us, each cycle twice: alone, and with four clients at once (the
# `load` example of ferrocat-service): one hammering SDO uploads through the control socket, one
# reading the whole shared image at 10 kHz, one writing an output every cycle (and counting the
# cycles each write took to reach the wire), and one killed with SIGKILL in the middle of a
# write (the file locked, the sequence odd); and a third time with the mailbox gateway on and
# flooded (`load … gateway`: diagnosis uploads from station 0 back to back, one datagram in ten
# malformed). Prints per run: the wake-up p50/p99/max, overruns, frames lost,
# working-counter errors, slaves that left OP, the loop's CPU per cycle, what the clients
# measured, and the half-done writes the master dropped. Then the time of a fresh `ferrocat sdo
# read` beside the running master (median of 20). Needs root. SECONDS_EACH (default 60) sets
# each run's length, CYCLES the cycles (default 1000 250), CLIENTS the loads (default
# "none four gateway").
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release -p ferrocat
cargo build -q --release -p ferrocat-service --example load
bin=target/release/ferrocat
load=target/release/examples/load
secs=${SECONDS_EACH:-60}
cycles=${CYCLES:-1000 250}
loads=${CLIENTS:-none four gateway}
id=$$
m=fcbm$id; s=fcbs$id; ifm="fcb${id}a"; ifs="fcb${id}b"
work=$(mktemp -d)
export FERROCAT_RUN_DIR="$work/run"
pids=()
cleanup() {
  for p in "${pids[@]}" ${sim:-} ${run:-}; do kill -KILL "$p" 2>/dev/null || true; done
  ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "$ifm" type veth peer name "$ifs"
ip link set "$ifm" netns "$m"; ip link set "$ifs" netns "$s"
for ns_if in "$m $ifm" "$s $ifs"; do
  set -- $ns_if
  ip netns exec "$1" sysctl -qw "net.ipv6.conf.$2.disable_ipv6=1"
  ip -n "$1" link set "$2" up
done
# The mailbox gateway listens on the master's namespace's loopback.
ip -n "$m" link set lo up
printf "[[device]]\nbuiltin = 'EK1100'\n[[device]]\nbuiltin = 'EL2004'\n[[device]]\nbuiltin = 'SERVO'\n" > "$work/seg.toml"

echo "host: $(nproc) CPUs, $(uname -r), $(git rev-parse --short HEAD); $secs s a run"
printf '%-6s %-8s %8s %8s %9s %6s %6s %5s %5s %7s  %s\n' \
  cycle clients "wake50" "wake99" "wakemax" "over" "lost" "wkc" "left" "cpu us" "clients' figures"
for cycle in $cycles; do
  for clients in $loads; do
    ip netns exec "$s" "$bin" sim --config "$work/seg.toml" --iface "$ifs" 2>/dev/null &
    sim=$!
    sleep 0.5
    gw=(); [ "$clients" = gateway ] && gw=(--mailbox-gateway)
    ip netns exec "$m" "$bin" run --iface "$ifm" --dc --cycle-us "$cycle" --seconds "$secs" --json "${gw[@]}" \
      >"$work/run.json" 2>"$work/run.err" &
    run=$!
    # Ready once the socket answers.
    for _ in $(seq 100); do
      ip netns exec "$m" "$bin" stats --iface "$ifm" >/dev/null 2>&1 && break
      sleep 0.1
    done
    said=""
    if [ "$clients" = four ]; then
      : > "$work/clients"
      pids=()
      ip netns exec "$m" "$load" "$ifm" sdo >>"$work/clients" & pids+=($!)
      ip netns exec "$m" "$load" "$ifm" read 10000 >>"$work/clients" & pids+=($!)
      ip netns exec "$m" "$load" "$ifm" write "1:Output#1" >>"$work/clients" & pids+=($!)
      ip netns exec "$m" "$load" "$ifm" write-abandon "1:Output#2" >/dev/null & killed=$!
      sleep 1
      kill -KILL "$killed" 2>/dev/null || true
      wait "$killed" 2>/dev/null || true
    fi
    if [ "$clients" = gateway ]; then
      : > "$work/clients"
      ip netns exec "$m" "$load" 127.0.0.1:34980 gateway >>"$work/clients" & pids+=($!)
    fi
    # A fresh `sdo read` beside the master, 20 times (the command's whole run).
    if [ "$cycle" = 1000 ] && [ "$clients" = none ]; then
      for _ in $(seq 20); do
        t0=$(date +%s%N)
        ip netns exec "$m" "$bin" sdo read 2 0x1018:1 --iface "$ifm" >/dev/null 2>&1
        echo $(( ($(date +%s%N) - t0) / 1000 ))
      done | sort -n | sed -n '10p' > "$work/sdo_us"
    fi
    wait "$run" || true
    run=
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; wait "$p" 2>/dev/null || true; done
    pids=()
    kill -TERM "$sim"; wait "$sim" || true; sim=
    [ "$clients" != none ] && said=$(tr '\n' ';' < "$work/clients")
    python3 - "$cycle" "$clients" "$work/run.json" "$work/run.err" "$said" <<'PY'
import json, re, sys
cycle, clients, run, err, said = sys.argv[1:]
v = json.load(open(run)); e = open(err).read()
cpu = float(re.search(r"CPU time ([\d.]+) (?:us|µs) per cycle", e).group(1))
n = max(v["cycles"], 1)
w = v["wake_latency"]
img = (v.get("control") or {}).get("image") or {}
extra = said + (f" dropped half-done {img.get('writes_dropped_half_done', 0)}" if clients == "four" else "")
print(f"{cycle:<6} {clients:<8} {w['p50_us']:8.1f} {w['p99_us']:8.1f} {w['max_us']:9.1f} "
      f"{100 * v['overruns'] / n:5.2f}% {100 * v['frames_lost'] / n:5.3f}% {v['wkc_errors']:5d} "
      f"{v['slaves']['left_op']:5d} {cpu:7.1f}  {extra}")
PY
  done
done
[ -s "$work/sdo_us" ] && echo "a fresh 'ferrocat sdo read' beside the running master at 1 ms: median $(($(cat "$work/sdo_us") / 1000)) ms of 20 (the whole command, the process's start included)"
