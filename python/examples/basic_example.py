"""Checks the segment's layout (EK1100, EL2004, EL1004), brings it to OP and toggles the
EL2004's first output every 0.1 s for a second, counting cycles with a short working counter.

    python basic_example.py [IFACE]

Without IFACE, on a virtual segment of those three terminals in virtual time. With IFACE, the
cycles run in a Rust thread (Master.start) while this script toggles the output between them.
"""
import sys
import time

import ferrocat

BECKHOFF = 0x2
LAYOUT = [("EK1100", 0x044C2C52), ("EL2004", 0x07D43052), ("EL1004", 0x03EC3052)]


def main(iface=None):
    if iface:
        m = ferrocat.Master.open(iface)
    else:
        m = ferrocat.Master.virtual(ferrocat.Segment([name for name, _ in LAYOUT], seed=1))
    slaves = m.scan()
    if len(slaves) != len(LAYOUT):
        raise SystemExit(f"found {len(slaves)} slaves, expected {len(LAYOUT)}")
    for s, (name, product) in zip(slaves, LAYOUT):
        if (s.vendor_id, s.product_code) != (BECKHOFF, product):
            raise SystemExit(f"slave {s.position} is {s.name} ({s.vendor_id:#x}:{s.product_code:#x}), expected {name}")
    m.bring_up(cycle_us=1000)
    print("all slaves in OP:", ", ".join(s.name for s in m.slaves))
    short = 0
    if iface:
        m.start()
        for k in range(10):
            m.set(1, "0x7000:01", k % 2)
            time.sleep(0.1)
        st = m.stop()
        short = st["short_wkc"]
        print(f"{st['cycles']} cycles in a Rust thread; wake-ups late by {st['wake_late_p99_us']:.1f} µs at p99")
    else:
        for k in range(10):
            m.set(1, "0x7000:01", k % 2)
            short += m.run(100)
        print(f"{m.stats()['cycles']} cycles in virtual time")
    print(f"cycles with a short working counter: {short}")
    m.shut_down()
    print("basic_example done")


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
