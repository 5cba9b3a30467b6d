"""SOEM (through pysoem, unmodified) brings a simulated CiA402 drive to OPERATION ENABLED.

Usage: soem_cia402.py IFACE DRIVE_POSITION
The drive is ferrocat's built-in servo (RxPDO: controlword, target position, target velocity,
target torque, mode; TxPDO: statusword, position, velocity, torque, following error, mode
display). SOEM configures DC with SYNC0 at 1 ms, goes to OP, then walks the drive's state
machine in cyclic synchronous position, holding the target on the actual position.
Prints one JSON object on stdout.
"""
import json
import struct
import sys
import time

import pysoem

iface, pos = sys.argv[1], int(sys.argv[2])
m = pysoem.Master()
m.open(iface)
result = {"states": []}
try:
    result["found"] = m.config_init()
    m.config_map()
    result["has_dc"] = bool(m.config_dc())
    d = m.slaves[pos]
    result["name"] = d.name
    d.dc_sync(True, 1_000_000)
    # Python on a shared machine can stall for three cycles, which the drive's SM-synchronisation
    # supervision takes as a sync error (0x001A): as integrators on a stock kernel do, turn its
    # reaction off (0x10F1:02, sync error counter limit), and read back what SOEM wrote.
    d.sdo_write(0x10F1, 2, struct.pack("<H", 0))
    result["sync_error_limit"] = struct.unpack("<H", d.sdo_read(0x10F1, 2))[0]
    result["bytes"] = [len(d.output), len(d.input)]
    if not d.input:
        result["assign"] = [d.sdo_read(0x1C12, 0).hex(), d.sdo_read(0x1C12, 1).hex(), d.sdo_read(0x1C13, 1).hex(), d.sdo_read(0x1A00, 0).hex()]
        print(json.dumps(result))
        sys.exit(1)
    m.state = pysoem.SAFEOP_STATE
    m.write_state()
    m.state_check(pysoem.SAFEOP_STATE, 500_000)
    m.state = pysoem.OP_STATE
    m.write_state()
    # As SOEM's simple_test does: exchange process data and repeat the request until OP.
    for _ in range(300):
        m.send_processdata()
        m.receive_processdata(2000)
        if m.state_check(pysoem.OP_STATE, 1000) == pysoem.OP_STATE:
            break
        m.state = pysoem.OP_STATE
        m.write_state()
        time.sleep(0.001)
    result["op"] = m.read_state() == pysoem.OP_STATE
    result["al"] = [[s.state, s.al_status] for s in m.slaves]

    def decode(sw):
        # The profile's statusword patterns (bits 0-3, 5, 6).
        for mask, value, name in [
            (0x4F, 0x00, "not ready to switch on"),
            (0x4F, 0x40, "switch on disabled"),
            (0x6F, 0x21, "ready to switch on"),
            (0x6F, 0x23, "switched on"),
            (0x6F, 0x27, "operation enabled"),
            (0x6F, 0x07, "quick stop active"),
            (0x4F, 0x0F, "fault reaction active"),
            (0x4F, 0x08, "fault"),
        ]:
            if sw & mask == value:
                return name
        return "?"

    cw = 0
    for _ in range(3000):
        inp = d.input
        sw, actual = struct.unpack_from("<Hi", inp, 0)
        mode_display = struct.unpack_from("<b", inp, 16)[0]
        state = decode(sw)
        if not result["states"] or result["states"][-1] != state:
            result["states"].append(state)
        if state == "operation enabled" and mode_display == 8:
            break
        cw = {
            "switch on disabled": 0x06,
            "ready to switch on": 0x07,
            "switched on": 0x0F,
            "fault": 0x80 if cw != 0x80 else 0x00,
        }.get(state, cw)
        # Controlword, target position = actual (no jump), velocity 0, torque 0, mode 8 (CSP).
        d.output = struct.pack("<HiihbB", cw, actual, 0, 0, 8, 0)
        m.send_processdata()
        m.receive_processdata(2000)
        time.sleep(0.001)
    # Hold for a while in OPERATION ENABLED: the drive stays where it stood.
    first = None
    for _ in range(200):
        d.output = struct.pack("<HiihbB", 0x0F, actual, 0, 0, 8, 0)
        m.send_processdata()
        m.receive_processdata(2000)
        sw, actual_now = struct.unpack_from("<Hi", d.input, 0)
        first = actual_now if first is None else first
        time.sleep(0.001)
    result["final_state"] = decode(sw)
    result["mode_display"] = struct.unpack_from("<b", d.input, 16)[0]
    result["moved"] = actual_now - first
finally:
    m.state = pysoem.INIT_STATE
    m.write_state()
    m.close()
print(json.dumps(result))
