"""SOEM (through pysoem, unmodified) against a segment: what slaveinfo prints, then OP and outputs.

Usage: soem_slaveinfo.py IFACE SLAVE OUTPUT_HEX
Writes OUTPUT_HEX (its bytes) to slave SLAVE's outputs (0-based; SOEM's IOmap may pack a
slave's bits with its neighbours'). Prints one JSON object on stdout.
"""
import json
import struct
import sys
import time

import pysoem

from wire_delays import DelayWrites, soem_delay

iface, out_slave, out_bytes = sys.argv[1], int(sys.argv[2]), bytes.fromhex(sys.argv[3])
m = pysoem.Master()
m.open(iface)
result = {"slaves": []}
try:
    n = m.config_init()
    result["found"] = n
    m.config_map()
    wire = DelayWrites(iface)
    result["has_dc"] = bool(m.config_dc())
    delays = wire.stop()
    for i, s in enumerate(m.slaves):
        station = 0x1001 + i
        info = {"name": s.name, "man": s.man, "id": s.id, "rev": s.rev, "station": station}
        sm = []
        for k in range(8):
            try:
                raw = s._fprd(0x0800 + 8 * k, 8)
            except pysoem.WkcError:
                break  # the ESC has no more SyncManagers
            start, length, ctl, status, act, pdi = struct.unpack("<HHBBBB", raw)
            if start:
                sm.append({"start": start, "length": length, "control": ctl, "activate": act})
        info["sm"] = sm
        fm = []
        for k in range(8):
            try:
                raw = s._fprd(0x0600 + 16 * k, 16)
            except pysoem.WkcError:
                break  # the ESC has no more FMMUs
            ls, ll, lsb, leb, ps, psb, ty, act = struct.unpack("<IHBBHBBB3x", raw)
            if act:
                fm.append({"ls": ls, "ll": ll, "lsb": lsb, "leb": leb, "ps": ps, "psb": psb, "type": ty})
        info["fmmu"] = fm
        (dl,) = struct.unpack("<H", s._fprd(0x0110, 2))
        info["active_ports"] = [int(bool(dl & (1 << (9 + 2 * p))) and not dl & (1 << (8 + 2 * p))) for p in range(4)]
        # What SOEM computed and wrote (a terminal with receive times only does not take it).
        info["delay_ns"] = soem_delay(s, station, delays)
        try:
            s._fprd(0x0928, 4)
            info["system_time"] = True
        except pysoem.WkcError:
            info["system_time"] = False
        result["slaves"].append(info)
    m.state = pysoem.SAFEOP_STATE
    m.write_state()
    m.state_check(pysoem.SAFEOP_STATE, 500_000)
    m.slaves[out_slave].output = out_bytes
    m.send_processdata()
    m.receive_processdata(2000)
    m.state = pysoem.OP_STATE
    m.write_state()
    wkc = 0
    for i in range(200):
        m.send_processdata()
        wkc = m.receive_processdata(2000)
        time.sleep(0.001)
        # Without device emulation AL control is a mailbox: a write before the firmware read
        # the last one is refused (the real LAN9252 refused a BWR 26 us after another), and
        # SAFEOP was just written again. Write OP again while it is not reached, as IgH does.
        if i % 50 == 49 and m.read_state() != pysoem.OP_STATE:
            m.state = pysoem.OP_STATE
            m.write_state()
    result["wkc"] = wkc
    result["expected_wkc"] = m.expected_wkc
    result["op"] = m.state_check(pysoem.OP_STATE, 500_000) == pysoem.OP_STATE
    m.read_state()
    result["states"] = [s.state for s in m.slaves]
    result["al_status_codes"] = [s.al_status for s in m.slaves]
finally:
    m.close()
print(json.dumps(result))
