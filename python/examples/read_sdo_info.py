"""Prints the object dictionary of every slave that gives SDO information: each object's
index, code, type and name, and each entry's type, size, access and name.

    python read_sdo_info.py [IFACE]

Without IFACE, an EK1100 and a CiA402 servo on a virtual segment.
"""
import sys

import ferrocat


def main(iface=None):
    if iface:
        m = ferrocat.Master.open(iface)
    else:
        m = ferrocat.Master.virtual(ferrocat.Segment(["EK1100", "SERVO"]))
    # PREOP: every slave's mailbox set up.
    for s in m.configure():
        if not s.has_coe:
            print(f"no SDO info for {s.name}")
            continue
        print(s.name)
        for index in m.od_list(s.position):
            o = m.object_info(s.position, index)
            print(f" Idx: {index:#06x}; Code: {o['object_code']}; Type: {o['data_type']}; Name: \"{o['name']}\"")
            for sub in range(o["max_subindex"] + 1):
                try:
                    e = m.entry_info(s.position, index, sub)
                except ferrocat.Error:
                    continue
                if e["data_type"] and e["bits"]:
                    print(
                        f"  Subindex {sub}; Type: {e['data_type']}; BitSize: {e['bits']}; "
                        f"Access: {e['access']:#x} Name: \"{e['name']}\""
                    )


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else None)
