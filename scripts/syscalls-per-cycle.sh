#!/usr/bin/env bash
# System calls per cycle of `ferrocat run` against `ferrocat sim` over a veth pair in two
# namespaces it makes and removes (root): strace -c of a 2 s run at 1 ms cycles and one back to
# back, for two builds side by side, two rounds. The counts include the bring-up.
#
#   scripts/syscalls-per-cycle.sh OLD_BINARY NEW_BINARY
set -euo pipefail
old="$1"; new="$2"
tmp=$(mktemp -d)
ip netns del fcsm 2>/dev/null || true; ip netns del fcss 2>/dev/null || true
ip netns add fcsm; ip netns add fcss
ip link add fcsa type veth peer name fcsb
ip link set fcsa netns fcsm; ip link set fcsb netns fcss
ip -n fcsm link set fcsa up; ip -n fcss link set fcsb up
ip netns exec fcss "$new" sim --device EK1100 --device EL2004 --device EL1004 --iface fcsb 2>/dev/null &
SIM=$!
sleep 1
for round in 1 2; do
for b in old new; do
  bin=$([ $b = old ] && echo "$old" || echo "$new")
  for mode in "--cycle-us 1000" "--max-rate"; do
    ip netns exec fcsm strace -f -c -o "$tmp/st.txt" "$bin" run --iface fcsa --seconds 2 $mode > "$tmp/out.txt" 2>/dev/null
    cycles=$(grep -oE "^[0-9]+ cycles" "$tmp/out.txt" | cut -d' ' -f1)
    for sc in sendto recvmsg setsockopt clock_nanosleep; do
      n=$(awk -v s=$sc '$NF==s {print $4}' "$tmp/st.txt"); echo "$round $b $mode $sc ${n:-0} cycles $cycles per-cycle $(python3 -c "print(round(${n:-0}/$cycles,3))")"
    done
  done
done
done
kill -TERM $SIM; sleep 0.5
ip netns del fcsm; ip netns del fcss
rm -rf "$tmp"
