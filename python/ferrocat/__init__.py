"""ferrocat: an EtherCAT master with distributed clocks, and a virtual EtherCAT segment to test
it against, from Python.

    import ferrocat
    seg = ferrocat.Segment(["EK1100", "EL2004", "SERVO"], seed=1)
    m = ferrocat.Master.virtual(seg)          # or Master.open("eth0"), Master.udp("host:port")
    for s in m.bring_up(cycle_us=1000, dc=True):
        print(s.position, s.name, s.state)
    m.set(1, "0x7000:01", 1)               # the EL2004's first output
    m.run(100)                                # 100 cycles, 0.1 s of the segment's time

The master's work runs in Rust with the GIL released. Errors are `ferrocat.Error` (an SDO
abort: `ferrocat.SdoAbort`, with its `code`).
"""
from ._native import (
    Axis,
    Client,
    Error,
    Master,
    SdoAbort,
    Segment,
    SegmentView,
    Slave,
    Variable,
    __version__,
)

__all__ = [
    "Axis",
    "Client",
    "Error",
    "Master",
    "SdoAbort",
    "Segment",
    "SegmentView",
    "Slave",
    "Variable",
    "__version__",
]
