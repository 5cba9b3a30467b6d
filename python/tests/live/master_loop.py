"""On a real interface: the master brought up, its cycles run in a Rust thread (start) while
a Python thread burns CPU in pure Python, outputs set and SDOs asked between cycles. Prints
JSON for crates/cli/tests/python_live.rs.

    python master_loop.py IFACE
"""
import json
import sys
import threading
import time

import ferrocat

m = ferrocat.Master.open(sys.argv[1])
# One master per segment: a second is refused, naming the first.
try:
    ferrocat.Master.open(sys.argv[1])
    second = None
except ferrocat.Error as e:
    second = str(e)
m.bring_up(cycle_us=1000)
m.start()
stop = threading.Event()


def burn():
    # Pure Python, holding the GIL whenever it can.
    x = 0
    while not stop.is_set():
        x += 1


busy = threading.Thread(target=burn)
busy.start()
t0 = time.monotonic()
# Outputs 2 and 4 of the EL2004 (its entries share the name "Output": by index).
m.set(1, "0x7010:01", 1)
m.set(1, "0x7030:01", 1)
vendor = int.from_bytes(m.sdo_read(2, 0x1018, 1), "little")
m.sdo_write(2, 0x6083, 0, (4242).to_bytes(4, "little"))
readback = int.from_bytes(m.sdo_read(2, 0x6083, 0), "little")
try:
    m.sdo_read(2, 0x5FFF, 0)
    abort = None
except ferrocat.SdoAbort as e:
    abort = e.code
time.sleep(1.0)
stop.set()
busy.join()
during = m.loop_stats()
stats = m.stop()
elapsed = time.monotonic() - t0
outputs = m.get(1, "0x7010:01") + 2 * m.get(1, "0x7030:01")
running_after = m.running

print(
    json.dumps(
        {
            "elapsed_s": elapsed,
            "cycles": stats["cycles"],
            "short_wkc": stats["short_wkc"],
            "running_during": during is not None,
            "wake_late_p99_us": stats["wake_late_p99_us"],
            "vendor": vendor,
            "readback": readback,
            "abort": abort,
            "outputs": outputs,
            "running_after": running_after,
            "second": second,
        }
    )
)
