#!/usr/bin/env bash
# ferrocat's Python package against SOEM through pysoem, from Python, on the veth set-up of
# scripts/bench-masters.sh (a release `ferrocat sim` of 16 slaves pinned to CPU 0, the master
# on CPU 1, in namespaces this script makes and removes), ROUNDS rounds taking turns, medians:
# - the highest cycle rate from a Python loop (Master.exchange against send_processdata +
#   receive_processdata, one LRW + FRMW frame a cycle), ferrocat on its default path
#   (io_uring, sleeping for the answer) and on a packet ring (io="ring", spinning for it);
# - the wake-up lateness of 1 ms cycles (p50, p99), quiet and with a Python thread burning CPU
#   in pure Python beside them (ferrocat's cycles in its Rust thread, pysoem's in a Python
#   thread, as its users write them), normal scheduling for both, and ferrocat's thread at
#   SCHED_FIFO 80 beside the busy thread.
# Needs root and scripts/test.sh's .venv (pysoem and ferrocat's package). Prints the host's
# wake_cost figures first.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH="${SECONDS_EACH:-3}"
ROUNDS="${ROUNDS:-3}"
py=.venv/bin/python
cargo build -q --release -p ferrocat
cargo build -q --release -p ferrocat-link --example wake_cost
bin=target/release/ferrocat
echo "host ($(nproc) CPUs): $(target/release/examples/wake_cost 2>&1 | tr '\n' ' ')"
id=$$; m=fcpm$id; s=fcps$id
out=$(mktemp)
sim=""
cleanup() {
  if [ -n "$sim" ]; then kill -TERM "$sim" 2>/dev/null || true; fi
  ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true; rm -f "$out"
}
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "fcp${id}a" type veth peer name "fcp${id}b"
ip link set "fcp${id}a" netns "$m"; ip link set "fcp${id}b" netns "$s"
ip -n "$m" link set "fcp${id}a" up; ip -n "$s" link set "fcp${id}b" up
devices=(--device EK1100)
for k in $(seq 1 15); do if (( k % 2 )); then devices+=(--device EL1004); else devices+=(--device EL2004); fi; done
# one WHAT MASTER [busy]: a fresh simulator, one measurement, its JSON line.
one() {
  ip netns exec "$s" taskset -c 0 "$bin" sim "${devices[@]}" --iface "fcp${id}b" >/dev/null 2>&1 &
  sim=$!
  sleep 0.5
  ip netns exec "$m" taskset -c 1 "$py" python/bench/bench_python.py "$1" "$2" "fcp${id}a" "$SECONDS_EACH" "${3:-quiet}" \
    | tail -n 1 || true
  kill -TERM "$sim"; while kill -0 "$sim" 2>/dev/null; do sleep 0.1; done
  sim=""
}
field() { python3 -c 'import json,sys; v=json.loads(sys.argv[1]).get(sys.argv[2]); print("-" if v is None else v)' "$1" "$2" 2>/dev/null || echo -; }
for round in $(seq 1 "$ROUNDS"); do
  for master in ferrocat ferrocat-ring soem; do
    r=$(one rate "$master")
    echo "round $round  $master  rate: $r"
    echo "rate-$master $(field "$r" cycles_per_s)" >> "$out"
    [ "$master" = ferrocat-ring ] && continue
    loads=(quiet busy); [ "$master" = ferrocat ] && loads+=(busy-rt)
    for load in "${loads[@]}"; do
      w=$(one wake "$master" "$load")
      echo "round $round  $master  1 ms cycles, $load: $w"
      echo "wake-$master-$load $(field "$w" p50_us) $(field "$w" p99_us) $(field "$w" cycles)" >> "$out"
    done
  done
done
med() { grep "^$1 " "$out" | awk -v c="$2" '{print $c}' | grep -v '^-$' | sort -g | awk '{a[NR]=$1} END {if (NR) print a[int((NR+1)/2)]; else print "-"}'; }
echo
echo "medians over $ROUNDS rounds (16 slaves):"
printf "  %-13s %8s cycles/s from a Python loop\n" ferrocat-ring "$(med rate-ferrocat-ring 2)"
for master in ferrocat soem; do
  printf "  %-13s %8s cycles/s from a Python loop\n" "$master" "$(med "rate-$master" 2)"
done
n=$(python3 -c "print(int(float('$SECONDS_EACH') * 1000))")
echo "1 ms cycles for ${SECONDS_EACH} s ($n planned), wake-ups late p50 / p99 µs, cycles run:"
for row in ferrocat-quiet ferrocat-busy ferrocat-busy-rt soem-quiet soem-busy; do
  printf "  %-18s %9s / %9s µs   %6s cycles\n" "$row" "$(med "wake-$row" 2)" "$(med "wake-$row" 3)" "$(med "wake-$row" 4)"
done
