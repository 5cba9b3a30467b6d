"""Two CiA402 drives with distributed clocks: to OP, clock sync locked, both enabled, moved
by one revolution's worth of increments (65 536) along a cosine profile, disabled.

    python two_drives_csp.py [IFACE AXIS0 AXIS1]

Without arguments, an EK1100 and two servos on a virtual segment in virtual time.
"""
import sys

import ferrocat

MOVE = 1 << 16


def main(args):
    if args:
        iface, positions = args[0], [int(p) for p in args[1:3]]
        m = ferrocat.Master.open(iface)
    else:
        positions = [1, 2]
        m = ferrocat.Master.virtual(ferrocat.Segment(["EK1100", "SERVO", "SERVO"], seed=1))
    m.bring_up(cycle_us=1000, dc=True, csp=positions)
    axes = [m.axis(p) for p in positions]
    for a in axes:
        a.enable()
    print("clock sync:", m.clock_sync())
    for a in axes:
        start = a.actual_position
        end = a.move_to(start + MOVE, seconds=1.0)
        print(f"slave {a.position}: moved {end - start} increments, {a.state}")
    for a in axes:
        a.disable()
    m.shut_down()


if __name__ == "__main__":
    main(sys.argv[1:])
