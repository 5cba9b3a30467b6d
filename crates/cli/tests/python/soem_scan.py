"""SOEM (pysoem) scan of a segment: identities and the delays SOEM computes. Prints JSON."""
import json
import sys

import pysoem

from wire_delays import DelayWrites, soem_delay

m = pysoem.Master()
m.open(sys.argv[1])
try:
    m.config_init()
    wire = DelayWrites(sys.argv[1])
    m.config_dc()
    delays = wire.stop()
    out = []
    for i, s in enumerate(m.slaves):
        # What SOEM computed and wrote to 0x0928 (stations 0x1001, 0x1002, … by position).
        delay = soem_delay(s, 0x1001 + i, delays)
        out.append({"name": s.name, "vendor_id": s.man, "product_code": s.id, "revision": s.rev, "delay_ns": delay})
finally:
    m.close()
print(json.dumps(out))
