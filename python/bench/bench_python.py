"""One measurement of scripts/bench-python.sh, printed as one JSON line.

    python bench_python.py rate ferrocat|ferrocat-ring|soem IFACE SECONDS
        cycles back to back from a Python loop (one LRW + FRMW frame each: DC on, no clock-sync
        method), as fast as they go
    python bench_python.py wake ferrocat|soem IFACE SECONDS quiet|busy|busy-rt
        1 ms cycles for SECONDS, with or without a Python thread burning CPU in pure Python
        beside them; the wake-up lateness of the cycles (p50, p99, max, µs) and the cycles run.
        ferrocat runs its cycles in a Rust thread (Master.start; with busy-rt at SCHED_FIFO 80);
        pysoem's are a Python thread's, as its users write them.
"""
import json
import sys
import threading
import time

what, master, iface, seconds = sys.argv[1], sys.argv[2], sys.argv[3], float(sys.argv[4])
load = sys.argv[5] if len(sys.argv) > 5 else "quiet"
busy = load.startswith("busy")


def burner(stop):
    x = 0
    while not stop.is_set():
        x += 1


def percentiles(late_ns):
    v = sorted(late_ns)
    at = lambda p: v[min(len(v) - 1, round(p / 100 * (len(v) - 1)))] / 1e3
    return {"p50_us": at(50), "p99_us": at(99), "max_us": at(100), "cycles": len(v)}


if master.startswith("ferrocat"):
    import ferrocat

    # ferrocat-ring: the packet ring, spinning for the answer (for a core of the master's own).
    m = ferrocat.Master.open(iface, io="ring" if master == "ferrocat-ring" else "auto")
    m.bring_up(cycle_us=1000, dc=True, sync="none")
    if what == "rate":
        t0, n = time.monotonic(), 0
        while time.monotonic() - t0 < seconds:
            m.exchange()
            n += 1
        print(json.dumps({"cycles_per_s": n / (time.monotonic() - t0)}))
    else:
        stop = threading.Event()
        t = threading.Thread(target=burner, args=(stop,))
        if busy:
            t.start()
        m.start(priority=80 if load == "busy-rt" else None)
        time.sleep(seconds)
        st = m.stop()
        stop.set()
        if busy:
            t.join()
        print(json.dumps({"p50_us": st["wake_late_p50_us"], "p99_us": st["wake_late_p99_us"],
                          "max_us": st["wake_late_max_us"], "cycles": st["cycles"]}))
else:
    import pysoem

    m = pysoem.Master()
    m.open(iface)
    m.config_init()
    m.config_map()
    m.config_dc()
    m.state = pysoem.OP_STATE
    m.write_state()
    while m.state_check(pysoem.OP_STATE, 1000) != pysoem.OP_STATE:
        m.send_processdata()
        m.receive_processdata(2000)
    if what == "rate":
        t0, n = time.monotonic(), 0
        while time.monotonic() - t0 < seconds:
            m.send_processdata()
            m.receive_processdata(2000)
            n += 1
        print(json.dumps({"cycles_per_s": n / (time.monotonic() - t0)}))
    else:
        stop = threading.Event()
        late = []

        def cycles():
            nxt = time.monotonic_ns()
            end = nxt + int(seconds * 1e9)
            while nxt < end:
                nxt += 1_000_000
                d = nxt - time.monotonic_ns()
                if d > 0:
                    time.sleep(d / 1e9)
                late.append(max(0, time.monotonic_ns() - nxt))
                m.send_processdata()
                m.receive_processdata(2000)

        b = threading.Thread(target=burner, args=(stop,))
        if busy:
            b.start()
        c = threading.Thread(target=cycles)
        c.start()
        c.join()
        stop.set()
        if busy:
            b.join()
        print(json.dumps(percentiles(late)))
    m.close()
