"""SOEM (through pysoem, unmodified) with its overlapping IO map (ecx_config_overlap_map).

Usage: soem_overlap.py IFACE SECONDS
Outputs and inputs share the logical image: a slave with both has its output FMMU and its input
FMMU on the same logical bytes, so one LRW carries its outputs out and its inputs back in their
place — the slave must take the outputs before it puts its inputs there. The segment has an
output terminal and the built-in servo (RxPDO controlword, target position, velocity, torque,
mode; TxPDO statusword, position, …): the servo is walked to OPERATION ENABLED by controlword
through the overlapped bytes, then process data runs for SECONDS, each cycle writing its count
(mod 16) to the terminal. Prints one JSON object on stdout.
"""
import json
import struct
import sys
import time

import pysoem

from soem_states import to_op

iface, seconds = sys.argv[1], float(sys.argv[2])
m = pysoem.Master()
m.open(iface)
result = {"states": []}


def exchange():
    m.send_overlap_processdata()
    wkc = m.receive_processdata(2000)
    time.sleep(0.001)
    return wkc


try:
    result["found"] = m.config_init()
    result["map_bytes"] = m.config_overlap_map()
    fmmus = []
    for s in m.slaves:
        mine = []
        for k in range(2):
            try:
                raw = s._fprd(0x0600 + 16 * k, 16)
            except pysoem.WkcError:
                break
            ls, ll, lsb, leb, ps, psb, ty, act = struct.unpack("<IHBBHBBB3x", raw)
            if act:
                mine.append({"logical": ls, "length": ll, "type": ty})
        fmmus.append(mine)
    result["fmmus"] = fmmus
    result["acks"] = []
    to_op(m, exchange, log=result["acks"])
    result["op"] = m.read_state() == pysoem.OP_STATE
    terminal = next(s for s in m.slaves if len(s.output) > 0 and len(s.input) == 0)
    drive = next(s for s in m.slaves if len(s.output) > 0 and len(s.input) > 0)
    # The drive's state machine by controlword, its statusword read from the same bytes.
    cw = 0
    for _ in range(2000):
        sw, actual = struct.unpack_from("<Hi", drive.input, 0)
        state = {0x40: "switch on disabled", 0x21: "ready to switch on", 0x23: "switched on", 0x27: "operation enabled"}.get(
            sw & (0x4F if sw & 0x4F == 0x40 else 0x6F), "other"
        )
        if not result["states"] or result["states"][-1] != state:
            result["states"].append(state)
        if state == "operation enabled":
            break
        cw = {"switch on disabled": 0x06, "ready to switch on": 0x07, "switched on": 0x0F}.get(state, cw)
        # Controlword, target position = actual (no jump), velocity 0, torque 0, mode 8 (CSP).
        drive.output = struct.pack("<HiihbB", cw, actual, 0, 0, 8, 0)
        exchange()
    wkcs = {}
    cycles = 0
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        cycles += 1
        terminal.output = bytes([cycles & 0x0F]) + terminal.output[1:]
        sw, actual = struct.unpack_from("<Hi", drive.input, 0)
        drive.output = struct.pack("<HiihbB", 0x0F, actual, 0, 0, 8, 0)
        wkc = exchange()
        wkcs[wkc] = wkcs.get(wkc, 0) + 1
    result["final_statusword"] = struct.unpack_from("<H", drive.input, 0)[0]
    result["cycles"] = cycles
    result["last_output"] = cycles & 0x0F
    result["wkc_counts"] = {str(k): v for k, v in wkcs.items()}
finally:
    m.close()
print(json.dumps(result))
