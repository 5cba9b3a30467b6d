"""Serves a virtual segment from Python on IFACE until stdin closes, then prints the serving
counters as JSON.

    python serve_segment.py IFACE DEVICE...
"""
import json
import sys

import ferrocat

seg = ferrocat.Segment(sys.argv[2:], seed=1)
seg.serve(sys.argv[1])
print("serving", flush=True)
sys.stdin.read()
print(json.dumps(seg.stop()), flush=True)
