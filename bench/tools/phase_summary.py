#!/usr/bin/env python3
"""One line per problem of GPU benchmark results: strata's refactorization, its device time
and the device time of each phase of its last refactorization, and, for bench_cudss's
files, cuDSS's best refactorization and the ratio — the figures an A/B of two builds
compares (several files given: one run of each, in the order given).

Reads bench_gpu's results (gpu-*.json: the median refactorization is strata_gpu.seconds)
and bench_cudss's (cudss-*.json: strata_gpu.refactor_seconds; cuDSS's best of its default
order and strata's). Times in milliseconds. Phases: FactorStats's device phases
(large_fronts, small_fronts, assembly, store, host; the tiled phases when any is nonzero).

    python3 bench/tools/phase_summary.py results/gpu-profile-ab-*.json [--problems flexible]
"""

import argparse
import json
import os
import sys

PHASES = ["large_fronts", "small_fronts", "assembly", "store", "host"]


def rows_of(path):
    """(tag, problem, strata refactorization s, device s, phases {name: s}, cuDSS s or None)
    for each row of one results file."""
    with open(path) as f:
        d = json.load(f)
    out = []
    for r in d.get("rows", []):
        g = r.get("strata_gpu") or {}
        last = g.get("last_refactor") or {}
        refactor = g.get("refactor_seconds", g.get("seconds"))
        cudss = None
        if "cudss_default" in r:
            times = [r[k]["refactor_seconds"] for k in ("cudss_default", "cudss_strata_perm")
                     if isinstance(r.get(k), dict) and "refactor_seconds" in r[k]]
            cudss = min(times) if times else None
        out.append((d.get("tag") or os.path.basename(path), os.path.basename(str(r["problem"])),
                    refactor, last.get("device_seconds"), last.get("phases") or {}, cudss))
    return out


def ms(x):
    return "-" if x is None else f"{1e3 * x:.3f}"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("files", nargs="+")
    ap.add_argument("--problems", default="", help="only problems whose name contains this")
    a = ap.parse_args(argv)
    rows = [x for p in a.files for x in rows_of(p) if a.problems in x[1]]
    phases = PHASES + sorted({k for x in rows for k, v in x[4].items()
                              if k not in PHASES and v})
    print(" ".join(["tag".ljust(24), "problem".ljust(22), "refactor", "device"] +
                   [p[:12].rjust(12) for p in phases] + ["cuDSS", "ratio"]))
    for tag, name, rf, dev, ph, cu in rows:
        ratio = "-" if rf is None or not cu else f"{rf / cu:.3f}"
        print(" ".join([tag[:24].ljust(24), name[:22].ljust(22), ms(rf).rjust(8), ms(dev).rjust(6)] +
                       [ms(ph.get(p)).rjust(12) for p in phases] + [ms(cu).rjust(5), ratio]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
