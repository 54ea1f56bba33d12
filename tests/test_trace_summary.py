#!/usr/bin/env python3
"""Test of bench/tools/trace_summary.py, the sums of a GPU timeline.

    python3 tests/test_trace_summary.py

  * union_ns against a brute-force count over a nanosecond grid, on intervals drawn
    afresh (overlapping, nested, touching, disjoint);
  * windows: a gap of at least the limit on every device ends a window, a shorter one
    does not, and an activity that ends late keeps the window open (worked by hand);
  * short_name drops template arguments, parameters and the launch shape;
  * the command line on a small CSV written here: the window list and a window's sums
    (busy time per device, the largest gap), and a host call listed with --api but in no
    window, worked by hand.
"""
import os
import random
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.join(HERE, "..", "bench", "tools"))
import trace_summary as ts  # noqa: E402

from script_checks import check, finish  # noqa: E402


rng = random.Random()
for trial in range(200):
    n = rng.randint(0, 8)
    iv = []
    for _ in range(n):
        s = rng.randint(0, 60)
        iv.append((s, s + rng.randint(0, 15)))
    covered = set()
    for s, e in iv:
        covered.update(range(s, e))
    check(ts.union_ns(iv) == len(covered), f"union_ns {iv}: {ts.union_ns(iv)} != {len(covered)}")


def act(device, start, end, kind="kernel", detail="k grid=1.1.1 block=32.1.1", nbytes=0):
    return {"kind": kind, "device": device, "stream": 7, "start": start, "end": end,
            "bytes": nbytes, "detail": detail}


# gap limit 10: [0,5] and [3,30] overlap; 30 -> 38 is a gap of 8 (same window); a long
# activity on device 1 [35, 100] keeps the window open past [38, 40]; 100 -> 111 ends it
rows = [act(0, 0, 5), act(0, 3, 30), act(0, 38, 40), act(1, 35, 100), act(0, 111, 112),
        act(1, 130, 131)]
ws = ts.windows(sorted(rows, key=lambda r: r["start"]), 10)
check([len(w) for w in ws] == [4, 1, 1], f"windows {[len(w) for w in ws]} != [4, 1, 1]")

check(ts.short_name("void ns::f<int, (char)1>(double*, long) grid=1.1.1 block=2.1.1") == "void ns::f",
      "short_name of a template kernel")
check(ts.short_name("plain grid=3.1.1 block=64.1.1") == "plain", "short_name of a plain name")

with tempfile.TemporaryDirectory() as d:
    path = os.path.join(d, "t.csv")
    with open(path, "w") as f:
        f.write("kind,device,stream,start_ns,end_ns,bytes,detail\n")
        # window 0 (ms): device 0 kernels 1..2 and 1.8..2.6, a copy 2.5..3.0; device 1 1.5..2.2
        f.write('kernel,0,7,1000000,2000000,0,"a grid=1.1.1 block=32.1.1"\n')
        f.write('kernel,1,9,1500000,2200000,0,"b grid=1.1.1 block=32.1.1"\n')
        f.write('kernel,0,8,1800000,2600000,0,"a grid=1.1.1 block=32.1.1"\n')
        f.write('memcpy,0,7,2500000,3000000,1000000,"HtoD"\n')
        # window 1: device 0 9.0..9.5, a gap of 0.3, 9.8..10.0
        f.write('kernel,0,7,9000000,9500000,0,"c grid=1.1.1 block=32.1.1"\n')
        f.write('memcpy_p2p,0,7,9800000,10000000,2000000,"PtoP 1->0"\n')
        # a host call 0.5 ms before window 1 (not device activity: no window of its own)
        f.write('api,-1,4242,8500000,8900000,0,"cudaFree_v3020"\n')
    script = os.path.join(HERE, "..", "bench", "tools", "trace_summary.py")
    out = subprocess.run([sys.executable, script, path], capture_output=True, text=True).stdout
    check("0: 2.000, 1: 0.700" in out, f"window 0's busy figures in:\n{out}")
    check("0: 0.700" in out, f"window 1's busy figure in:\n{out}")
    out = subprocess.run([sys.executable, script, path, "--window", "-1"], capture_output=True,
                         text=True).stdout
    check("busy 0.700 ms" in out and "0.300 @ 0.500" in out, f"window 1's sums in:\n{out}")
    check(out.count("window:") == 1 and "cudaFree" not in out, f"a host call outside --api:\n{out}")
    out = subprocess.run([sys.executable, script, path, "--window", "1", "--api", "0.1"],
                         capture_output=True, text=True).stdout
    check("-0.500    0.400 thread       4242 cudaFree_v3020" in out, f"the host call listed in:\n{out}")

finish("trace_summary: all checks passed")
