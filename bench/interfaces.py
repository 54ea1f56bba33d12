#!/usr/bin/env python3
"""Overhead of the Python interface, and strata from Python next to scipy's SuperLU.

For each matrix: wall time in Python of strata.Solver(A) (conversion to int64/float64
arrays + copy + analysis + factorization), of solve(b), and of refactorize(A), against
the times the C++ phases report themselves (stats: seconds.total, factor.seconds,
solve.seconds); the difference is the cost of the interface. scipy.sparse.linalg.splu
(SuperLU, COLAMD) is timed on the same matrix as a reference point, not as a tuned
competitor. Best of --repeat runs.

    PYTHONPATH=build/python /usr/bin/python3 bench/interfaces.py [--repeat 3] [--json OUT]
        [--matrix-dir data/matrices] [--threads 0]

Prints a table; --json writes every figure (with machine and git commit) to OUT. Not part
of bench/run or bench/REPORT.md: bench/python_vs_scipy.py is the benchmark in the report
(Python against the command line, strata against SuperLU and CHOLMOD).
"""

import argparse
import json
import os
import platform
import subprocess
import time

import numpy as np
import scipy.io
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import strata


def laplacian_2d(k):
    t = sp.diags([-1, 2, -1], [-1, 0, 1], shape=(k, k))
    i = sp.eye(k)
    return (sp.kron(t, i) + sp.kron(i, t)).tocsc()


def laplacian_3d(k):
    t = sp.diags([-1, 2, -1], [-1, 0, 1], shape=(k, k))
    i = sp.eye(k)
    return (sp.kron(sp.kron(t, i), i) + sp.kron(sp.kron(i, t), i) + sp.kron(sp.kron(i, i), t)).tocsc()


def best(f, repeat, inner=None):
    """Best wall time of f over `repeat` runs, with f's result and, when given, inner(result)
    measured right after that same run."""
    best_t, best_out, best_inner = None, None, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        t = time.perf_counter() - t0
        if best_t is None or t < best_t:
            best_t, best_out = t, out
            best_inner = inner(out) if inner else None
    return (best_t, best_out, best_inner) if inner else (best_t, best_out)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json", default="")
    ap.add_argument("--threads", type=int, default=0)
    ap.add_argument("--matrix-dir", default=os.environ.get(
        "STRATA_MATRIX_DIR", os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))),
                                          "data", "matrices")))
    args = ap.parse_args()

    problems = [("lap2d-200", laplacian_2d(200)), ("lap3d-25", laplacian_3d(25))]
    for name in ("bcsstk16", "bayer10"):
        path = os.path.join(args.matrix_dir, name + ".mtx.gz")
        if args.matrix_dir and os.path.exists(path):
            problems.append((name, sp.csc_matrix(scipy.io.mmread(path))))

    rows = []
    for name, A in problems:
        n = A.shape[0]
        b = np.ones(n)
        t_build, s, inner_build = best(
            lambda: strata.Solver(A, device="cpu", num_threads=args.threads), args.repeat,
            lambda s: s.stats["seconds"]["total"] + s.stats["factor"]["seconds"])
        st = s.stats
        t_solve, x, (inner_solve, berr) = best(
            lambda: s.solve(b), args.repeat,
            lambda _: (s.stats["solve"]["seconds"], s.stats["solve"]["backward_error"]))
        t_refac, _, inner_refac = best(lambda: s.refactorize(A), args.repeat,
                                       lambda _: s.stats["factor"]["seconds"])
        t_splu, lu = best(lambda: spla.splu(A), 1)
        t_splu_solve, _ = best(lambda: lu.solve(b), args.repeat)
        r = {
            "matrix": name, "n": n, "nnz": int(A.nnz), "type": st["factor"]["type"],
            "solver_wall_s": t_build, "analysis_plus_factor_s": inner_build,
            "solve_wall_s": t_solve, "solve_inner_s": inner_solve,
            "refactorize_wall_s": t_refac, "refactorize_inner_s": inner_refac,
            "backward_error": berr,
            "scipy_splu_s": t_splu, "scipy_splu_solve_s": t_splu_solve,
        }
        rows.append(r)

    hdr = (f"{'matrix':<12} {'n':>8} {'type':<8} {'Solver() s':>11} {'C++ s':>9} {'ovh %':>6} "
           f"{'solve s':>9} {'C++ s':>9} {'refac s':>9} {'C++ s':>9} {'splu s':>9}")
    print(hdr)
    for r in rows:
        ovh = 100.0 * (r["solver_wall_s"] - r["analysis_plus_factor_s"]) / r["solver_wall_s"]
        print(f"{r['matrix']:<12} {r['n']:>8} {r['type'][:8]:<8} {r['solver_wall_s']:>11.4f} "
              f"{r['analysis_plus_factor_s']:>9.4f} {ovh:>6.1f} {r['solve_wall_s']:>9.4f} "
              f"{r['solve_inner_s']:>9.4f} {r['refactorize_wall_s']:>9.4f} "
              f"{r['refactorize_inner_s']:>9.4f} {r['scipy_splu_s']:>9.4f}")
    if args.json:
        try:
            commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True,
                                    cwd=os.path.dirname(os.path.abspath(__file__))).stdout.strip()
        except OSError:
            commit = ""
        out = {"benchmark": "interfaces", "machine": platform.node(), "cpu": platform.processor(),
               "cores": os.cpu_count(), "date": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
               "git_commit": commit, "command": "bench/interfaces.py", "rows": rows}
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
        print("wrote", args.json)


if __name__ == "__main__":
    main()
