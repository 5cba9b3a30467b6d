"""Two simulated CiA402 drives brought to OP with DC, enabled and moved together in cyclic
synchronous position, in virtual time."""
import time

import ferrocat

MOVE = 1 << 16


def test_two_drives_with_dc_are_enabled_and_moved():
    t0 = time.perf_counter()
    m = ferrocat.Master.virtual(ferrocat.Segment(["EK1100", "SERVO", "SERVO"], seed=3))
    m.bring_up(cycle_us=1000, dc=True, csp=[1, 2])
    axes = [m.axis(1), m.axis(2)]
    for a in axes:
        a.enable(timeout_s=2.0)
        assert a.state == "OperationEnabled" and a.feedback()["ready"]
    start = [a.actual_position for a in axes]
    # One drive's move runs the cycles; the other holds its target meanwhile, then moves.
    ends = [a.move_to(s + MOVE, seconds=0.5) for a, s in zip(axes, start)]
    for end, s in zip(ends, start):
        assert abs(end - (s + MOVE)) <= 16, f"moved to {end}, wanted {s + MOVE}"
    assert m.clock_sync()["lock"] == "locked"
    assert m.stats()["wkc_errors"] == 0
    for a in axes:
        a.disable()
        assert a.state == "SwitchOnDisabled"
    wall = time.perf_counter() - t0
    # The target is under 2 s; the figure is printed (pytest -s), not asserted: CI
    # hosts differ.
    print(f"two drives to OP with DC, enabled, moved and disabled: {wall:.2f} s of wall time")
