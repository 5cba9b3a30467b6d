"""The benchmark of docs/benchmarks.md for SOEM through pysoem: start to OP, then LRW + FRMW
cycles (send_processdata with DC configured) back to back, with CPU time per cycle."""
import resource
import sys
import time

import pysoem

iface, seconds = sys.argv[1], float(sys.argv[2])
m = pysoem.Master()
m.open(iface)
start = time.monotonic()
n = m.config_init()
m.config_map()
m.config_dc()
m.state = pysoem.OP_STATE
m.write_state()
while m.state_check(pysoem.OP_STATE, 1000) != pysoem.OP_STATE:
    m.send_processdata()
    m.receive_processdata(2000)
to_op = time.monotonic() - start
cpu = lambda: sum(resource.getrusage(resource.RUSAGE_SELF)[:2])
c0, t0, cycles = cpu(), time.monotonic(), 0
while time.monotonic() - t0 < seconds:
    m.send_processdata()
    m.receive_processdata(2000)
    cycles += 1
wall, used = time.monotonic() - t0, cpu() - c0
m.close()
print(f"SOEM (pysoem): {n} slaves; bring-up to OP {to_op * 1e3:.1f} ms; {cycles / wall:.0f} cycles/s; CPU {used * 1e6 / cycles:.2f} us per cycle")
