#!/usr/bin/env python3
"""Test of bench/tools/phase_summary.py, the per-problem lines of GPU benchmark results.

    python3 tests/test_phase_summary.py

On two small results files written here, one as bench_gpu writes them and one as
bench_cudss does, with times drawn afresh: each line's refactorization, device time and
phases in milliseconds, cuDSS's best of its two orders and the ratio (worked from the
drawn values), a phase that is zero everywhere left out and a nonzero extra one shown,
and --problems keeping only the matching problems.
"""
import json
import os
import random
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
TOOL = os.path.join(HERE, "..", "bench", "tools", "phase_summary.py")
from script_checks import check, finish  # noqa: E402

rng = random.Random()


def draw():
    return rng.uniform(1e-4, 2e-2)


phases = {"large_fronts": draw(), "small_fronts": draw(), "assembly": draw(), "store": draw(),
          "host": draw(), "tiled_fronts": 0.0, "setup": draw()}
gpu = {"tag": "ab-one", "rows": [
    {"problem": "/tmp/mbd/flexible-64x4x4/flexible-64x4x4.mtx",
     "strata_gpu": {"seconds": draw(), "last_refactor": {"device_seconds": draw(), "phases": phases}}},
    {"problem": "bcsstk16",
     "strata_gpu": {"seconds": draw(), "last_refactor": {"device_seconds": draw(), "phases": phases}}}]}
cu_default, cu_perm = draw(), draw()
cudss = {"tag": "mbd", "rows": [
    {"problem": "tracked-1000",
     "strata_gpu": {"refactor_seconds": draw(), "seconds": 1.0,
                    "last_refactor": {"device_seconds": draw(), "phases": phases}},
     "cudss_default": {"refactor_seconds": cu_default},
     "cudss_strata_perm": {"refactor_seconds": cu_perm}}]}

with tempfile.TemporaryDirectory() as d:
    paths = []
    for name, content in (("gpu-profile-ab-one.json", gpu), ("cudss-mbd.json", cudss)):
        paths.append(os.path.join(d, name))
        with open(paths[-1], "w") as f:
            json.dump(content, f)
    out = subprocess.run([sys.executable, TOOL] + paths, capture_output=True, text=True,
                         check=True).stdout.splitlines()
    head = out[0].split()
    check(head[:4] == ["tag", "problem", "refactor", "device"], f"header {head}")
    check("tiled_fronts" not in head, "a phase zero everywhere is left out")
    check("setup" in head, "a nonzero phase beyond the usual ones is shown")
    check(len(out) == 4, f"one line per problem: {len(out) - 1}")
    col = {name: i for i, name in enumerate(head)}

    def expect(line, row, key, cudss_s):
        f = line.split()
        g = row["strata_gpu"]
        rf = g[key]
        check(f[1] == os.path.basename(row["problem"]), f"problem {f[1]}")
        check(f[2] == f"{1e3 * rf:.3f}", f"refactorization {f[2]} against {1e3 * rf:.3f}")
        check(f[3] == f"{1e3 * g['last_refactor']['device_seconds']:.3f}", f"device {f[3]}")
        for p in ("large_fronts", "small_fronts", "assembly", "store", "host", "setup"):
            want = f"{1e3 * phases[p]:.3f}"
            check(f[col[p[:12]]] == want, f"{p} {f[col[p[:12]]]} against {want}")
        if cudss_s is None:
            check(f[-2:] == ["-", "-"], f"no cuDSS in a bench_gpu file: {f[-2:]}")
        else:
            check(f[-2] == f"{1e3 * cudss_s:.3f}", f"cuDSS {f[-2]} against {1e3 * cudss_s:.3f}")
            check(f[-1] == f"{rf / cudss_s:.3f}", f"ratio {f[-1]} against {rf / cudss_s:.3f}")

    expect(out[1], gpu["rows"][0], "seconds", None)
    expect(out[2], gpu["rows"][1], "seconds", None)
    expect(out[3], cudss["rows"][0], "refactor_seconds", min(cu_default, cu_perm))
    only = subprocess.run([sys.executable, TOOL, "--problems", "flexible"] + paths,
                          capture_output=True, text=True, check=True).stdout.splitlines()
    check(len(only) == 2 and "flexible-64x4x4.mtx" in only[1], f"--problems: {only}")

finish("phase_summary: lines, phases, cuDSS ratio and the filter as worked out")
