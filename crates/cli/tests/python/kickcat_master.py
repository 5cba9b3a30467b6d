"""KickCAT's master (the `kickcat` package from PyPI) on a segment: bring-up to OP, process
data both ways, and an SDO upload from every CoE slave. Prints one JSON object.

    kickcat_master.py IFACE OUTPUT_SLAVE INPUT_SLAVE SDO_SLAVE
(slave positions count from 0; OUTPUT_SLAVE gets 0x0F on its outputs, INPUT_SLAVE's inputs are
reported, SDO_SLAVE's device name 0x1008 is read)
"""
import json
import sys
import time

import kickcat


def error_handler(*_):
    # A datagram that came back short: counted, the cycle goes on (as KickCAT's examples do).
    global errors
    errors += 1


errors = 0
iface, out_pos, in_pos, sdo_pos = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4])
link = kickcat.create_link(iface, "")
# How long KickCAT waits for a frame (s), and for each step of its bring-up (s). With no
# redundant interface ("" above) KickCAT's link pairs the real socket with a null one whose
# writes report success: every blocking exchange (`Link::writeThenRead`, used for its
# broadcasts and EEPROM access) sends the frame, gets the reply, then waits a full frame
# timeout on the real socket for the copy "sent" on the null one. About 200 such waits per
# bring-up follow from KickCAT's design, not from the segment (the capture shows each reply
# 80 µs after its frame); on real hardware it is the same. 10 ms made Bus::init time out on a
# CI machine busy with the suite beside it, so 50 ms.
link.set_timeout(0.05)
bus = kickcat.Bus(link)
bus.init(1.0)
slaves = bus.slaves()
bus.create_mapping()

name = bus.read_sdo(slaves[sdo_pos], 0x1008, 0, kickcat.Access.PARTIAL, 64, 1.0)

bus.request_state(kickcat.State.SAFE_OP)
bus.wait_for_state(kickcat.State.SAFE_OP, 1.0)
out = slaves[out_pos]
out.set_output_bytes(bytes([0x0F] * out.output_size))


def cycle():
    bus.send_logical_read(error_handler)
    bus.send_logical_write(error_handler)
    bus.finalize_datagrams()
    bus.process_awaiting_frames()


bus.request_state(kickcat.State.OPERATIONAL)
bus.wait_for_state(kickcat.State.OPERATIONAL, 1.0, cycle)
cycles = 0
t0 = time.monotonic()
while time.monotonic() - t0 < 0.3:
    cycle()
    cycles += 1
    time.sleep(0.001)
states = [str(bus.get_state(s)) for s in slaves]
print(json.dumps({
    "slaves": [s.address for s in slaves],
    "states": states,
    "cycles": cycles,
    "cycle_errors": errors,
    "output_size": [s.output_size for s in slaves],
    "input_size": [s.input_size for s in slaves],
    "inputs": slaves[in_pos].input_data.hex(),
    "device_name": name.rstrip(b"\0").decode("latin-1")
}))
