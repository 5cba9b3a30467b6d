"""A client of a running `ferrocat run`: hello, slaves, an SDO, the shared image's variables,
an output written and seen in a later cycle. Prints JSON.

    python client.py SOCKET
"""
import json
import sys
import time

import ferrocat

c = ferrocat.Client(socket=sys.argv[1])
hello = c.hello()
slaves = c.slaves()
vendor = int.from_bytes(c.sdo_read(2, 0x1018, 1), "little")
names = c.variables()
seq = c.write({"1:Output#2": 1})
seen = None
t0 = time.monotonic()
while time.monotonic() - t0 < 10:
    snap = c.read(["1:Output#2", "1:Output#1"])
    if snap["values"]["1:Output#2"] == 1:
        seen = snap
        break
    time.sleep(0.01)
print(
    json.dumps(
        {
            "hello": hello,
            "states": [s["state"] for s in slaves],
            "vendor": vendor,
            "variables": names,
            "seq": seq,
            "seen": seen,
        }
    )
)
