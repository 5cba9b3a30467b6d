"""SOEM (through pysoem, unmodified) writes files to a simulated slave by FoE and reads them back.

Usage: soem_foe.py IFACE SLAVE_POSITION PASSWORD
The slave is ferrocat's built-in servo, whose SII names FoE. In PREOP (after config_init) SOEM
writes files of several lengths — shorter than a packet, exactly a whole number of packets
(ended by an empty one), several packets and a bit — reads each back, reads a file that does
not exist and writes with a wrong password. Prints one JSON object on stdout.
"""
import json
import sys

import pysoem

iface, pos, password = sys.argv[1], int(sys.argv[2]), int(sys.argv[3], 0)
m = pysoem.Master()
m.open(iface)
result = {"files": []}
try:
    result["found"] = m.config_init()
    s = m.slaves[pos]
    result["name"] = s.name
    # The servo's mailboxes are 128 bytes: 116 bytes of file per packet.
    for n in [1, 100, 116, 348, 5000]:
        data = bytes((k * 7 + k // 251) & 0xFF for k in range(n))
        name = "file-%d.bin" % n
        w = s.foe_write(name, password, data)
        back = s.foe_read(name, password, 1 << 16)
        result["files"].append({"name": name, "bytes": n, "write": w, "same": back == data, "read": len(back)})
    for what, call in [
        ("missing", lambda: s.foe_read("none.bin", password, 1024)),
        ("wrong_password", lambda: s.foe_write("x.bin", password ^ 1, b"x")),
    ]:
        try:
            r = call()
            result[what] = {"ok": True, "result": repr(r)}
        except Exception as e:
            result[what] = {"ok": False, "error": str(e)}
finally:
    m.close()
print(json.dumps(result))
