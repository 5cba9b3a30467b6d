"""A master dropped while its loop runs takes the loop with it: the threads of this process
before the loop, with it, and after the master's Python object is gone. Prints JSON.

    python loop_drop.py IFACE
"""
import gc
import json
import os
import sys
import time

import ferrocat


def threads():
    return len(os.listdir("/proc/self/task"))


m = ferrocat.Master.open(sys.argv[1])
m.bring_up(cycle_us=1000)
idle = threads()
m.start()
time.sleep(0.1)
with_loop = threads()
del m
gc.collect()
time.sleep(0.3)
print(json.dumps({"threads": [idle, with_loop, threads()]}))
