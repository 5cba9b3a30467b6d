#!/usr/bin/env bash
# Live round trip through `ferrocat sim` on a veth pair between two network namespaces that
# this script creates and removes: a 6-slave LRW + FRMW frame, sent and timed by `ferrocat rtt`.
# Prints the client's round trip and the simulator's own time per frame. Needs root.
set -euo pipefail
cd "$(dirname "$0")/.."
cargo build -q --release -p ferrocat
bin=target/release/ferrocat
id=$$
m=fcbm$id; s=fcbs$id
cleanup() { ip netns del "$m" 2>/dev/null || true; ip netns del "$s" 2>/dev/null || true; }
trap cleanup EXIT
ip netns add "$m"; ip netns add "$s"
ip link add "fcb${id}a" type veth peer name "fcb${id}b"
ip link set "fcb${id}a" netns "$m"; ip link set "fcb${id}b" netns "$s"
ip -n "$m" link set "fcb${id}a" up; ip -n "$s" link set "fcb${id}b" up
ip netns exec "$s" "$bin" sim --device EK1100 --device EL1004 --device EL2004 --device EL1004 --device EL2004 --device EL1004 \
  --iface "fcb${id}b" 2> "/tmp/fcb$id.log" &
sim=$!
sleep 0.5
ip netns exec "$m" "$bin" rtt --iface "fcb${id}a" --frames "${FRAMES:-5000}"
kill -TERM $sim; wait $sim
grep "time per frame" "/tmp/fcb$id.log"
rm -f "/tmp/fcb$id.log"
