"""Prints the first 128 bytes of the first slave's EEPROM (SII), two bytes (one word) a line.

    python read_eeprom.py [IFACE]

Without IFACE, an EK1100 on a virtual segment.
"""
import sys

import ferrocat


def main(iface=None):
    m = ferrocat.Master.open(iface) if iface else ferrocat.Master.virtual(ferrocat.Segment(["EK1100"]))
    if not m.scan():
        raise SystemExit("no slave")
    sii = m.sii_read(0)
    for at in range(0, 0x80, 2):
        print(f"{at:04x}:" + "|".join(f"{b:02x}" for b in sii[at : at + 2]))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
