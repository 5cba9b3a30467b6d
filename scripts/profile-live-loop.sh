#!/usr/bin/env bash
# Where the cyclic loop's CPU goes live: `ferrocat run --dc --sync METHOD` against `ferrocat
# sim` (EK1100, EL2004, SERVO) on a veth pair between two namespaces this script makes and
# removes, under `perf record` (software clock samples: a VM without hardware counters has
# them too). Prints the master's samples by where they were taken: its own code, the send
# system call (and, inside it, the kernel delivering the frame to the simulator's socket on
# the veth peer and waking it), the wait for the reply, the receive, the sleep to the next
# cycle. Not in CI. Needs root and perf (Debian's linux-perf).
#   METHOD (default none), SECONDS_RUN (default 5), CYCLE_US (default 1000).
set -euo pipefail
cd "$(dirname "$0")/.."
command -v perf >/dev/null || { echo "needs perf (apt-get install linux-perf)" >&2; exit 1; }
method=${METHOD:-none}; secs=${SECONDS_RUN:-5}; cycle_us=${CYCLE_US:-1000}
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
id=$$; m=fcpm$id; s=fcps$id
work=$(mktemp -d)
cleanup() {
  [ -n "${sim:-}" ] && kill -TERM "$sim" 2>/dev/null || true
  ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true
  rm -rf "$work"
}
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "fcp${id}a" type veth peer name "fcp${id}b"
ip link set "fcp${id}a" netns "$m"; ip link set "fcp${id}b" netns "$s"
for ns_if in "$m fcp${id}a" "$s fcp${id}b"; do
  set -- $ns_if
  ip netns exec "$1" sysctl -qw "net.ipv6.conf.$2.disable_ipv6=1"
  ip -n "$1" link set "$2" up
done
ip netns exec "$s" "$bin" sim --device EK1100 --device EL2004 --device SERVO --iface "fcp${id}b" \
  2>"$work/sim.err" &
sim=$!
for _ in $(seq 100); do grep -q " on " "$work/sim.err" 2>/dev/null && break; sleep 0.05; done
ip netns exec "$m" perf record -q -e cpu-clock -F 20000 -g -o "$work/perf.data" \
  "$bin" run --dc --sync "$method" --cycle-us "$cycle_us" --seconds "$secs" --iface "fcp${id}a" \
  >/dev/null 2>"$work/run.err"
grep -E "^host:|master CPU time" "$work/run.err" | sed 's/^/  /'
perf report -i "$work/perf.data" --children --sort sym --stdio -g none 2>/dev/null >"$work/children"
perf report -i "$work/perf.data" --no-children --sort dso --stdio -g none 2>/dev/null >"$work/dso"
python3 - "$work/children" "$work/dso" <<'PY'
import re, sys
def pct(path, name):
    for line in open(path):
        m = re.match(r"^\s*([0-9.]+)%\s+(?:([0-9.]+)%\s+)?(.*)$", line)
        if m and m[3].strip().endswith(name):
            return float(m[1])
    return 0.0
kernel = pct(sys.argv[2], "[kernel.kallsyms]")
rows = [
    ("the master's own code and libraries (not the kernel)", 100.0 - kernel),
    ("sending (packet_sendmsg), in all", pct(sys.argv[1], "packet_sendmsg")),
    ("  of it: the frame delivered to the simulator's socket and its thread woken (sock_def_readable)", pct(sys.argv[1], "sock_def_readable")),
    ("waiting for the reply (io_uring's wait: the switch out and back)", pct(sys.argv[1], "io_cqring_wait")),
    ("receiving (packet_recvmsg)", pct(sys.argv[1], "packet_recvmsg")),
    ("sleeping to the next cycle (do_nanosleep)", pct(sys.argv[1], "do_nanosleep")),
]
print("  share of the master's CPU samples (inclusive; the rows overlap where one path calls another)")
for name, p in rows:
    print(f"  {p:6.1f} %  {name}")
PY
