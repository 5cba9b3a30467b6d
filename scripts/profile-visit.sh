#!/usr/bin/env bash
# Where an ESC visit's work goes: the benchmark workload (`ferrocat sim --bench`'s line of
# terminals, one LRW + FRMW frame per cycle) under callgrind, twice (CYCLES and 3 × CYCLES
# cycles), so that the set-up's cost cancels; prints instructions per ESC visit by part.
# Instruction counts do not move with the machine's load, unlike times. Needs valgrind.
# SLAVES (default 256), CYCLE_NS (100000) and CYCLES (1000) set the workload.
set -euo pipefail
cd "$(dirname "$0")/.."
slaves=${SLAVES:-256}; cycle_ns=${CYCLE_NS:-100000}; cycles=${CYCLES:-1000}
cargo build -q --profile profiling -p ferrocat-sim --example speed
work=$(mktemp -d); trap 'rm -rf "$work"' EXIT
for n in "$cycles" $((3 * cycles)); do
  valgrind --tool=callgrind --callgrind-out-file="$work/cg.$n" target/profiling/examples/speed "$slaves" "$cycle_ns" "$n" \
    > /dev/null 2>&1
  callgrind_annotate --inclusive=no --auto=no --show-percs=no "$work/cg.$n" | sed -n '/file:function/,$p' > "$work/self.$n"
done
python3 - "$work/self.$cycles" "$work/self.$((3 * cycles))" "$slaves" "$cycles" <<'PY'
import re, sys
# Each function's own instructions (callgrind's exclusive cost; what the compiler inlined
# counts where it was inlined), summed over the source files it has lines from.
def load(p):
    d = {}
    for line in open(p):
        m = re.match(r"^\s*([0-9,]+)\s+(.*)$", line)
        if not m or m[2].startswith("=>") or ":" not in m[2]:
            continue
        name = re.sub(r"\s*\[.*\]$", "", m[2]).split(":", 1)[1]
        d[name] = d.get(name, 0) + int(m[1].replace(",", ""))
    return d
a, b = load(sys.argv[1]), load(sys.argv[2])
visits = 2 * int(sys.argv[4]) * int(sys.argv[3])
per = {k: (b[k] - a.get(k, 0)) / visits for k in b}
# Which part of the visit each function is (by name; the rest is the frame's walk).
parts = [
    ("time control loop sample", ("tcl_sample", "RateTable::nearest", "scd_for", "set_scd")),
    ("clocks and SYNC units", ("advance_to", "fold_to", "local_at", "system_at", "next_event_ns", "SyncUnit")),
    ("receive-time latches", ("receptions", "latch_receive_times")),
    ("register and process-data bytes", ("read_byte", "write_byte", "refresh_tcl_registers", "refresh_registers", "SyncManager::parse")),
    ("application", ("DigitalIo", "take_fault", "sample_inputs", "outputs_written")),
    ("segment between ESCs", ("Segment::",)),
]
def part(name):
    return next((p for p, keys in parts if any(k in name for k in keys)), "datagram walk and end of frame")
total = sum(x for x in per.values() if x > 0)
sums = {}
for k, x in per.items():
    sums[part(k)] = sums.get(part(k), 0) + x
print(f"{sys.argv[3]} slaves, {2 * int(sys.argv[4])} cycles measured: {total:.0f} instructions per ESC visit")
for p, x in sorted(sums.items(), key=lambda kv: -kv[1]):
    if abs(x) >= 0.5:
        print(f"  {x:7.0f}  {100 * x / total:5.1f} %  {p}")
print("the functions (own instructions per visit):")
for k, x in sorted(per.items(), key=lambda kv: -kv[1])[:16]:
    print(f"  {x:7.1f}  {part(k):32} {k[-90:]}")
PY
