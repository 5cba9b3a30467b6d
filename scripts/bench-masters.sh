#!/usr/bin/env bash
# ferrocat, ethercrab and SOEM (pysoem) side by side, in one run, against the same release
# `ferrocat sim` serving 16 slaves on a veth pair in namespaces this script makes and removes:
# time from start to OP, the highest sustained rate of a one-frame LRW + FRMW cycle, and the
# master's CPU time per cycle, and its system calls per cycle (perf's count of
# raw_syscalls:sys_enter over the run, bring-up included, divided by the cycles). The simulator
# is pinned to CPU 0 and every master to CPU 1, so that the three get the same conditions; they
# take turns for ROUNDS rounds (load on the machine changes over time) and medians are printed.
# Needs root and scripts/test.sh's .venv (pysoem); without perf the system-call column is "-".
# ferrocat runs twice: on a packet ring (`--io ring`, spinning for the answer: the path for a
# dedicated core) and on its default path (`--io auto`, io_uring, sleeping for the answer).
# SIM_IO (ring) chooses the simulator's frame path, the same for every master.
set -euo pipefail
cd "$(dirname "$0")/.."
SECONDS_EACH="${SECONDS_EACH:-3}"
ROUNDS="${ROUNDS:-5}"
SIM_IO="${SIM_IO:-ring}"   # how the simulator moves frames: ring, socket, uring or auto
cargo build -q --release -p ferrocat --example ethercrab_bench
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
id=$$; m=fcmm$id; s=fcms$id
out=$(mktemp)
perf=false
if command -v perf >/dev/null && perf stat -e raw_syscalls:sys_enter true >/dev/null 2>&1; then perf=true; fi
sim=""
rt_runtime=$(cat /proc/sys/kernel/sched_rt_runtime_us)
cleanup() {
  if [ -n "$sim" ]; then kill -TERM "$sim" 2>/dev/null || true; fi
  echo "$rt_runtime" > /proc/sys/kernel/sched_rt_runtime_us || true
  ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true; rm -f "$out" "$out.perf"
}
trap cleanup EXIT
# A simulator or master that spins for its frames (--io ring) runs SCHED_FIFO without a pause
# at these rates: the kernel's RT throttling (sched_rt_runtime_us) would stop it for ~50 ms
# each second, which the masters see as lost frames. Off for the run, restored on exit.
echo -1 > /proc/sys/kernel/sched_rt_runtime_us
ip netns add "$m"; ip netns add "$s"
ip link add "fcm${id}a" type veth peer name "fcm${id}b"
ip link set "fcm${id}a" netns "$m"; ip link set "fcm${id}b" netns "$s"
ip -n "$m" link set "fcm${id}a" up; ip -n "$s" link set "fcm${id}b" up
devices=(--device EK1100)
for k in $(seq 1 15); do if (( k % 2 )); then devices+=(--device EL1004); else devices+=(--device EL2004); fi; done
for round in $(seq 1 "$ROUNDS"); do
  for master in ferrocat-ring ferrocat ethercrab soem; do
    ip netns exec "$s" taskset -c 0 "$bin" sim "${devices[@]}" --iface "fcm${id}b" --io "$SIM_IO" >/dev/null 2>&1 &
    sim=$!
    sleep 0.5
    case $master in
      ferrocat-ring) cmd=("$bin" run --iface "fcm${id}a" --io ring --dc --sync none --dc-static-frames 0 --max-rate --seconds "$SECONDS_EACH") ;;
      ferrocat) cmd=("$bin" run --iface "fcm${id}a" --io auto --dc --sync none --dc-static-frames 0 --max-rate --seconds "$SECONDS_EACH") ;;
      ethercrab) cmd=(target/release/examples/ethercrab_bench "fcm${id}a" "$SECONDS_EACH") ;;
      soem) cmd=(.venv/bin/python crates/cli/tests/python/soem_bench.py "fcm${id}a" "$SECONDS_EACH") ;;
    esac
    if $perf; then
      line=$(ip netns exec "$m" perf stat -x, -e raw_syscalls:sys_enter -o "$out.perf" taskset -c 1 "${cmd[@]}" 2>&1 | tr '\n' ' ')
      calls=$(grep -E 'raw_syscalls:sys_enter' "$out.perf" | cut -d, -f1)
    else
      line=$(ip netns exec "$m" taskset -c 1 "${cmd[@]}" 2>&1 | tr '\n' ' ')
      calls=""
    fi
    kill -TERM "$sim"; while kill -0 "$sim" 2>/dev/null; do sleep 0.1; done
    op=$(grep -oE 'bring-up to OP:? [0-9.]+ ms' <<<"$line" | grep -oE '[0-9.]+' | head -1)
    rate=$(grep -oE '[0-9.]+ cycles/s' <<<"$line" | grep -oE '[0-9.]+' | head -1)
    cpu=$(grep -oE '[0-9.]+ (us|µs) per cycle' <<<"$line" | grep -oE '[0-9.]+' | head -1)
    per=$(python3 -c "import sys; c, r, s = sys.argv[1:]; print(f'{int(c) / (float(r) * float(s)):.2f}' if c and r else '-')" "${calls:-}" "${rate:-}" "$SECONDS_EACH")
    echo "round $round  $master  to-OP ${op} ms  ${rate} cycles/s  CPU ${cpu} us/cycle  ${per} syscalls/cycle"
    echo "$master $op $rate $cpu $per" >> "$out"
  done
done
echo
echo "medians over $ROUNDS rounds (16 slaves, one LRW + FRMW frame per cycle):"
for master in ferrocat-ring ferrocat ethercrab soem; do
  med() { grep "^$master " "$out" | awk -v c="$1" '{print $c}' | sort -g | awk '{a[NR]=$1} END {print a[int((NR+1)/2)]}'; }
  printf "  %-13s start to OP %8s ms   %8s cycles/s   %7s us CPU per cycle   %6s system calls per cycle\n" "$master" "$(med 2)" "$(med 3)" "$(med 4)" "$(med 5)"
done
