"""SOEM (through pysoem, unmodified) through a slave's power cycle, and writing its alias.

Usage: soem_recovery.py IFACE POSITION ALIAS
The segment powers the slave at POSITION (1-based as SOEM counts) off and on twice, at times
it chose. Phase 1: process data runs and the slave is supervised as SOEM's simple_test does
(acknowledge, SAFEOP to OP, reconfigure, recover a lost slave) until the slave is back in OP
after the first power cycle and 200 more cycles have passed. Phase 2: ALIAS is written into
the slave's EEPROM as SOEM's eepromtool writes one (word 4, then the checksum word 7); process
data runs on until the second power cycle has passed; then the segment is configured again
and the slave's alias register read. Prints one JSON object on stdout.
"""
import json
import struct
import sys
import time

import pysoem

from soem_states import to_op

iface, position, alias = sys.argv[1], int(sys.argv[2]), int(sys.argv[3], 0)


def crc8(data):
    """The SII header checksum: CRC-8, polynomial x^8+x^2+x+1, initial 0xFF (ETG.1000.6)."""
    crc = 0xFF
    for b in data:
        crc ^= b
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    return crc


def supervise(m, log):
    """One pass over the slaves, in simple_test's order. Returns whether a slave is not in
    OP (simple_test's docheckstate: look again next cycle)."""
    m.read_state()
    again = False
    for i, s in enumerate(m.slaves):
        if s.state != pysoem.OP_STATE:
            again = True
            if s.state == pysoem.SAFEOP_STATE + pysoem.STATE_ERROR:
                s.state = pysoem.SAFEOP_STATE + pysoem.STATE_ACK
                s.write_state()
                log.append((i, "ack"))
            elif s.state == pysoem.SAFEOP_STATE:
                s.state = pysoem.OP_STATE
                s.write_state()
                log.append((i, "to op"))
            elif s.state > pysoem.NONE_STATE:
                if s.reconfig(500_000):
                    s.is_lost = False
                    log.append((i, "reconfigured"))
            elif not s.is_lost:
                s.state_check(pysoem.OP_STATE, 1000)
                if s.state == pysoem.NONE_STATE:
                    s.is_lost = True
                    log.append((i, "lost"))
        if s.is_lost:
            if s.state == pysoem.NONE_STATE:
                if s.recover(1000):
                    s.is_lost = False
                    log.append((i, "recovered"))
            else:
                s.is_lost = False
                log.append((i, "found"))
    return again


def cycle(m, count):
    s = m.slaves[position - 1]
    if len(s.output) > 0:
        s.output = bytes([count & 0x0F]) + s.output[1:]
    m.send_processdata()
    wkc = m.receive_processdata(2000)
    time.sleep(0.001)
    return wkc


m = pysoem.Master()
m.open(iface)
result = {"log": []}
try:
    result["found"] = m.config_init()
    m.config_map()
    result["op"] = to_op(m, lambda: (m.send_processdata(), m.receive_processdata(2000)))
    # The working counter of a whole cycle, as it comes back in OP (this pysoem's
    # expected_wkc reads 0 here).
    expected = max(cycle(m, k) for k in range(10))
    result["expected_wkc"] = expected
    target = m.slaves[position - 1]
    # Phase 1: run until the slave has come back to OP, then 200 good cycles more.
    short, good_after, count, check, back = 0, 0, 0, False, False
    end = time.monotonic() + 20
    while time.monotonic() < end and good_after < 200:
        count += 1
        wkc = cycle(m, count)
        short += wkc < expected
        if wkc < expected or check:
            check = supervise(m, result["log"])
            back = short > 0 and not check
        elif back:
            good_after += 1
    result["short_cycles"] = short
    result["back_in_op"] = back
    result["good_cycles_after"] = good_after
    # Phase 2: the alias into the EEPROM, then the second power cycle.
    header = b"".join(target.eeprom_read(w, 20_000) for w in (0, 2, 4, 6))[:14]
    header = header[:8] + struct.pack("<H", alias) + header[10:]
    target.eeprom_write(4, struct.pack("<H", alias), 20_000)
    target.eeprom_write(7, bytes([crc8(header), 0]), 20_000)
    # Until the slave has dropped out, and 1 s more (it is powered on again meanwhile). The
    # slave is off for 300 ms: it has dropped out when the cycles have come back short for
    # 150 ms on end. A short cycle or a few are the host stalling the script or the segment
    # for some milliseconds, which a loaded machine does; taking one of those for the power
    # cycle configured the segment again before the slave had been off.
    lost_at, short_since = None, None
    end = time.monotonic() + 20
    while time.monotonic() < end and (lost_at is None or time.monotonic() < lost_at + 1.0):
        count += 1
        now = time.monotonic()
        if cycle(m, count) >= expected:
            short_since = None
        elif short_since is None:
            short_since = now
        elif lost_at is None and now - short_since >= 0.150:
            lost_at = short_since
    result["second_cycle_seen"] = lost_at is not None
    # A new configuration: the slave's alias register, as its ESC loaded it at power-on.
    m.close()
    m = pysoem.Master()
    m.open(iface)
    result["found_again"] = m.config_init()
    result["alias_register"] = struct.unpack("<H", m.slaves[position - 1]._fprd(0x0012, 2))[0]
finally:
    m.close()
print(json.dumps(result))
