"""SOEM (pysoem) scan of a segment: identities and the delays SOEM computes. Prints JSON."""
import json
import struct
import sys

import pysoem

m = pysoem.Master()
m.open(sys.argv[1])
try:
    m.config_init()
    m.config_dc()
    out = []
    for s in m.slaves:
        (delay,) = struct.unpack("<I", s._fprd(0x0928, 4))
        out.append({"name": s.name, "vendor_id": s.man, "product_code": s.id, "revision": s.rev, "delay_ns": delay})
finally:
    m.close()
print(json.dumps(out))
