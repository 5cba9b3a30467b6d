"""SOEM (through pysoem, unmodified) stalls for 10 ms while a simulated drive runs DC-synchronous.

Usage: soem_sync_error.py IFACE DRIVE_POSITION
SOEM configures DC with SYNC0 at 1 ms and takes the segment to OP; after a second of process
data it sends nothing for 10 ms, then goes on as SOEM's examples do (ecatcheck): a short
working counter makes it read the states, acknowledge a slave in SAFE_OP + ERROR and ask for
OP again. Prints one JSON object on stdout: what the drive showed after the stall, and whether
it came back.
"""
import json
import sys
import time

import pysoem

from soem_states import to_op

iface, pos = sys.argv[1], int(sys.argv[2])
m = pysoem.Master()
m.open(iface)
result = {}


def cycle():
    m.send_processdata()
    wkc = m.receive_processdata(2000)
    time.sleep(0.001)
    return wkc


try:
    result["found"] = m.config_init()
    m.config_map()
    m.config_dc()
    d = m.slaves[pos]
    d.dc_sync(True, 1_000_000)
    result["op_before"] = to_op(m, cycle)
    for _ in range(1000):
        cycle()
    time.sleep(0.010)
    # SOEM's ecatcheck: on a short working counter, and until every slave is back in OP.
    seen, short, back, check = None, 0, False, False
    for _ in range(3000):
        wkc = cycle()
        if wkc < m.expected_wkc:
            short += 1
        if not (wkc < m.expected_wkc or check):
            continue
        check = False
        m.read_state()
        if d.state == pysoem.SAFEOP_STATE + pysoem.STATE_ERROR:
            if seen is None:
                seen = {"state": d.state, "al_status": d.al_status}
            d.state = pysoem.SAFEOP_STATE + pysoem.STATE_ACK
            d.write_state()
            check = True
        elif d.state == pysoem.SAFEOP_STATE:
            d.state = pysoem.OP_STATE
            d.write_state()
            check = True
        elif d.state == pysoem.OP_STATE and seen is not None:
            back = True
            break
    result["after_stall"] = seen
    result["short_cycles"] = short
    result["back_in_op"] = back
finally:
    m.close()
print(json.dumps(result))
