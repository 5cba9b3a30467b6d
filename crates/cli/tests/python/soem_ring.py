"""SOEM (through pysoem, unmodified) with cable redundancy: two interfaces, a ring.

Usage: soem_ring.py IFACE IFACE_RED SECONDS
Brings the ring to OP and runs process data for SECONDS, each cycle writing its count (mod 16)
to both nibbles of the first byte of every slave's outputs (SOEM packs 4-bit outputs two to a
byte, so that each slave sees it whichever nibble is its own); the segment breaks
the ring at a time it chose. Prints one JSON object on stdout: the working counters seen, the
last outputs written, each slave's DL status afterwards.
"""
import json
import struct
import sys
import time

import pysoem

iface, iface_red, seconds = sys.argv[1], sys.argv[2], float(sys.argv[3])
m = pysoem.Master()
m.open(iface, iface_red)
result = {}
try:
    result["found"] = m.config_init()
    m.config_map()
    result["has_dc"] = bool(m.config_dc())
    m.state = pysoem.SAFEOP_STATE
    m.write_state()
    m.state_check(pysoem.SAFEOP_STATE, 500_000)
    m.send_processdata()
    m.receive_processdata(2000)
    m.state = pysoem.OP_STATE
    m.write_state()
    for _ in range(100):
        m.send_processdata()
        m.receive_processdata(2000)
        if m.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
            break
    result["op"] = m.read_state() == pysoem.OP_STATE
    result["expected_wkc"] = m.expected_wkc
    wkcs = {}
    cycles = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        cycles += 1
        value = cycles & 0x0F
        for s in m.slaves:
            if len(s.output) > 0:
                s.output = bytes([value | value << 4]) + s.output[1:]
        m.send_processdata()
        wkc = m.receive_processdata(2000)
        wkcs[wkc] = wkcs.get(wkc, 0) + 1
        time.sleep(0.001)
    result["cycles"] = cycles
    result["last_output"] = cycles & 0x0F
    result["wkc_counts"] = {str(k): v for k, v in wkcs.items()}
    result["dl_status"] = [struct.unpack("<H", s._fprd(0x0110, 2))[0] for s in m.slaves]
    m.read_state()
    result["states"] = [s.state for s in m.slaves]
finally:
    m.close()
print(json.dumps(result))
