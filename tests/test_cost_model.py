#!/usr/bin/env python3
"""Test of bench/cost_model.py's size-dependent rates and tiled top schedule.

    python3 tests/test_cost_model.py

  * fit_rate_curve on points drawn afresh from a known curve r(F) = r_inf / (1 + (F_half
    / F)^beta) (random parameters, flops over five decades, 1% noise) predicts their
    times within 3% over the range of the points;
  * tiled_top counts a depth's fronts as running at once (its slowest front), worked out
    by hand on a three-front tree;
  * predict_curves with a flat curve (F_half tiny, no fixed cost) gives predict()'s
    constant-rate figures for the current schedule, subtrees and top part alike.
"""
import math
import os
import random
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "bench"))
import cost_model as cm  # noqa: E402

from script_checks import check, finish  # noqa: E402


rng = random.Random()
seed = rng.randrange(1 << 30)
rng.seed(seed)
print("seed", seed)

# 1. the fit recovers a known curve
for trial in range(3):
    truth = {"r_inf": 10 ** rng.uniform(12.7, 13.7), "f_half": 10 ** rng.uniform(10, 12),
             "beta": rng.uniform(0.4, 1.0)}
    points = []
    for i in range(30):
        f = 10 ** rng.uniform(8, 13)
        points.append((f, f / cm.rate_of(truth, f) * (1 + rng.uniform(-0.01, 0.01))))
    fit = cm.fit_rate_curve(points)
    check(fit is not None, f"trial {trial}: no fit")
    lo, hi = (math.log10(g([f for f, _ in points])) for g in (min, max))
    worst = max(abs(cm.seconds_of(fit, f) / (f / cm.rate_of(truth, f)) - 1)
                for f in (10 ** (lo + (hi - lo) * k / 20) for k in range(21)))
    check(worst < 0.03, f"trial {trial}: {truth} fitted as {fit}: worst time error {worst:.3f}")
check(cm.fit_rate_curve([(1e9, 1e-3), (2e9, 2e-3)]) is None, "two points give no fit")

# 2. tiled_top: root (depth 0) over W = 2 GPUs, two children (depth 1) on one GPU each
fronts = [
    {"depth": 1, "pivots": 100, "cb": 50, "flops": 4e9, "children": []},
    {"depth": 1, "pivots": 100, "cb": 50, "flops": 6e9, "children": []},
    {"depth": 0, "pivots": 2048, "cb": 0, "flops": 8e9, "children": [0, 1]},
]
link = {"nvlink": 1e11, "ib_per_node": 4e11}
rate = 1e12
comp, comm = cm.tiled_top(fronts, [0, 1, 2], 2, link, 1.0, lambda flops: rate)
# depth 1: max(4e9, 6e9) / 1e12 = 6 ms, no communication (P = 1);
# depth 0: 8e9 / (2 · 1e12) = 4 ms; 8 · 2048² / √2 bytes at 1e11 B/s plus
# 2 tile columns · 2 log2(2) · 5 µs
expect_comp = 6e-3 + 4e-3
expect_comm = 8.0 * 2048 ** 2 / math.sqrt(2) / 1e11 + 2 * 2 * 1 * cm.ASSUMED["message_latency_s"]
check(abs(comp - expect_comp) < 1e-12, f"tiled compute {comp} != {expect_comp}")
check(abs(comm - expect_comm) < 1e-12, f"tiled communication {comm} != {expect_comm}")

# 3. a flat curve is predict()'s constant rate
tree, root = cm.problem_tree("lap3d-24")
flat_sub = {"r_inf": 3e12, "f_half": 1e-30, "beta": 1.0, "overhead_s": 0.0}
flat_top = {"r_inf": 7e12, "f_half": 1e-30, "beta": 1.0}
cal = {"subtree_rate": 3e12, "top_rate": 7e12, "pcie_bytes_per_s": 5e10, "host_seconds": 0.0}
nv = {"rank_bytes_per_s": 1.5e11, "via_host": False, "nvlink": 1.5e11, "ib_per_node": 5e10}
for R, G in ((1, 1), (4, 1), (8, 1)):
    a = cm.predict(tree, root, R, G, cal, nv, "current", 1.3)
    b = cm.predict_curves(tree, root, R, G, {"subtree": flat_sub, "top": flat_top}, nv,
                          "current", 1.3)
    for k in ("subtree_seconds", "top_seconds", "cb_seconds", "total_seconds"):
        check(abs(a[k] - b[k]) <= 1e-9 * max(1.0, a[k]), f"{R}x{G} {k}: {a[k]} != {b[k]}")

finish("cost_model: all checks passed")
