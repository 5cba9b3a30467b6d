"""SOEM (through pysoem, unmodified) writes and reads an object of a simulated drive many times
over a segment that loses frames.

Usage: soem_sdo_loss.py IFACE SLAVE_POSITION COUNT
Each round writes 0x607A:00 (a 32-bit target position) and reads it back. Prints one JSON
object on stdout: how many rounds read back what was written, how many failed and why.
"""
import json
import struct
import sys

import pysoem

iface, pos, count = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
m = pysoem.Master()
m.open(iface)
result = {"same": 0, "different": 0, "errors": []}
try:
    result["found"] = m.config_init()
    s = m.slaves[pos]
    for k in range(count):
        step = "write"
        try:
            s.sdo_write(0x607A, 0, struct.pack("<i", k))
            step = "read"
            back = struct.unpack("<i", s.sdo_read(0x607A, 0, 4))[0]
            result["same" if back == k else "different"] += 1
        except Exception as e:
            result["errors"].append("round %d, %s: %s %r" % (k, step, type(e).__name__, e))
finally:
    m.close()
print(json.dumps(result))
