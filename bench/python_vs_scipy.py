#!/usr/bin/env python3
"""strata from Python: the cost of the Python layer against the C++ command line, and
strata against scipy's spsolve (SuperLU) and scikit-sparse's CHOLMOD on SPD matrices.

    PYTHONPATH=build/python /usr/bin/python3 bench/python_vs_scipy.py
        [--cli build/strata] [--repeat 3] [--overhead-repeat 7] [--threads 0]
        [--results-dir bench/results]
        [--matrix-dir data/matrices] [--splu-limit 60] [--quick]

Part 1, overhead (goal of issue 10: under 5% on the large matrix). The same matrix, in
the same form (lower triangle, CSC: what `strata solve` reads from a symmetric Matrix
Market file), is solved (analysis + factorization + one solve, b = A·1) by
`strata solve FILE --json`, whose own timer around the three phases excludes reading
the file, and by strata.Solver(A_lower, storage="lower").solve(b) timed in Python
around both calls (array conversion and copy included). Overhead = Python time / CLI
time − 1, each the best of --overhead-repeat runs, the two alternated (also given with
the medians, and every run's time). Also given: the part of
the Python time outside the C++ phases of that same call (the phase times the solver
reports), which does not depend on run-to-run noise between processes, and the time of
strata.Solver on the full (both triangles) scipy matrix, the form users usually have.

Part 2, other solvers on SPD matrices (shared SuiteSparse/CalculiX matrices and
generated Laplacians, small and large): wall time in Python of a complete solve of one
right-hand side (analysis, factorization, solve) — strata.solve(A, b),
scipy.sparse.linalg.spsolve(A, b) (SuperLU; permc_spec MMD_AT_PLUS_A, the symmetric
ordering, and on the smaller matrices also scipy's default COLAMD), and
sksparse.cholmod.cholesky(A)(b) (supernodal CHOLMOD with its default ordering) — with the
normwise backward error ‖b − A x‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) of each solution. Best of --repeat
runs (SuperLU: once above SPLU_ONCE_ABOVE unknowns, each run in a child process stopped
after --splu-limit seconds, recorded as "timed out"). When scikit-sparse is not
installed (scripts/setup.sh tries pip), its column says "not installed".

Writes bench/results/python-<UTC date-time>.json (machine, date, git commit, the exact
command, every figure); bench/report.py shows it in bench/REPORT.md. --quick: tiny
problems, one repeat, results to a temporary folder (a smoke run).
"""

import argparse
import json
import multiprocessing
import os
import platform
import subprocess
import sys
import tempfile
import time

from run_metadata import metadata

import numpy as np
import scipy
import scipy.io
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import strata

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# SuperLU is run once (not --repeat times) above this n; every SuperLU solve runs in a
# child process stopped after --splu-limit seconds (with COLAMD, scipy's default, a
# 20³ Laplacian already takes minutes on two cores)
SPLU_ONCE_ABOVE = 30000

try:
    import sksparse
    from sksparse.cholmod import cholesky as _cholmod_cholesky
    SKSPARSE = getattr(sksparse, "__version__", None) or "installed"
except ImportError:
    _cholmod_cholesky = None
    SKSPARSE = None


# ------------------------------------------------------------------------------ problems


def laplacian_2d(k):
    t = sp.diags([-1, 2, -1], [-1, 0, 1], shape=(k, k))
    i = sp.eye(k)
    return (sp.kron(t, i) + sp.kron(i, t)).tocsc()


def laplacian_3d(k):
    t = sp.diags([-1, 2, -1], [-1, 0, 1], shape=(k, k))
    i = sp.eye(k)
    return (sp.kron(sp.kron(t, i), i) + sp.kron(sp.kron(i, t), i)
            + sp.kron(sp.kron(i, i), t)).tocsc()


def load(name, matrix_dir):
    """(full symmetric CSC matrix, where it came from) for a generated or shared name."""
    kind, _, size = name.partition("-")
    if kind == "lap2d":
        return laplacian_2d(int(size)), f"generated: 5-point Laplacian {size}x{size}"
    if kind == "lap3d":
        return laplacian_3d(int(size)), f"generated: 7-point Laplacian {size}^3"
    path = os.path.join(matrix_dir, name + ".mtx.gz")
    if not os.path.exists(path):
        sys.exit(f"python_vs_scipy.py: {path} does not exist: pass --matrix-dir (or set "
                 f"STRATA_MATRIX_DIR) to the folder of the shared matrices")
    A = sp.csc_matrix(scipy.io.mmread(path))
    return A, os.path.relpath(path, REPO) if path.startswith(REPO) else path


# ------------------------------------------------------------------------------ helpers


def backward_error(A, x, b):
    r = b - A @ x
    anorm = abs(A).sum(axis=1).max()
    return float(np.abs(r).max() / (anorm * np.abs(x).max() + np.abs(b).max()))


def timed(f):
    t0 = time.perf_counter()
    out = f()
    return time.perf_counter() - t0, out


def best_of(f, repeat):
    """(best wall time, result of that run)."""
    best = None
    for _ in range(max(1, repeat)):
        t, out = timed(f)
        if best is None or t < best[0]:
            best = (t, out)
    return best


def limited(f, limit):
    """(wall time, result) of f() run in a forked child process, or None when it takes
    longer than `limit` seconds (the child is then killed)."""
    ctx = multiprocessing.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)

    def child():
        send.send(timed(f))

    proc = ctx.Process(target=child)
    proc.start()
    try:
        if recv.poll(limit):
            return recv.recv()
        return None
    finally:
        if proc.is_alive():
            proc.kill()
        proc.join()


# ------------------------------------------------------------------------------ part 1


def cli_solve(cli, path, threads):
    proc = subprocess.run([cli, "solve", path, "--json", "--threads", str(threads)],
                          capture_output=True, text=True)
    if proc.returncode != 0:
        raise RuntimeError(f"{cli} solve {path}: {proc.stderr.strip()}")
    return json.loads(proc.stdout)


def overhead_row(name, size, A, cli, threads, repeat, tmp):
    """Python (strata.Solver + solve) against `strata solve` on the same lower triangle."""
    path = os.path.join(tmp, name + ".mtx")
    A_lower = sp.tril(A).tocsc()
    scipy.io.mmwrite(path, A_lower, symmetry="symmetric")
    A_lower = sp.csc_matrix(scipy.io.mmread(path))  # exactly the values the CLI reads
    A_lower = sp.tril(A_lower).tocsc()
    A_full = (A_lower + sp.tril(A_lower, -1).T).tocsc()
    b = A_full @ np.ones(A.shape[0])

    def python_once():
        t0 = time.perf_counter()
        s = strata.Solver(A_lower, storage="lower", num_threads=threads)
        t1 = time.perf_counter()
        x = s.solve(b)
        t2 = time.perf_counter()
        st = s.stats
        inner = st["seconds"]["total"] + st["factor"]["seconds"] + st["solve"]["seconds"]
        return {"total": t2 - t0, "solver": t1 - t0, "solve": t2 - t1, "inner": inner,
                "x": x, "stats": st}

    best_py, best_cli = None, None
    cli_runs, py_runs = [], []
    for _ in range(max(1, repeat)):  # alternate, so that slow phases of the machine hit both
        c = cli_solve(cli, path, threads)
        cli_runs.append(c["total_seconds"])
        if best_cli is None or c["total_seconds"] < best_cli["total_seconds"]:
            best_cli = c
        p = python_once()
        py_runs.append(p["total"])
        if best_py is None or p["total"] < best_py["total"]:
            best_py = p
    t_full, _ = best_of(lambda: strata.Solver(A_full, num_threads=threads).solve(b),
                        min(repeat, 3))
    cli_total = best_cli["total_seconds"]
    cs = best_cli["seconds"]
    return {
        "problem": name, "size": size, "n": int(A.shape[0]), "nnz_a": int(A.nnz),
        "type": best_py["stats"]["factor"]["type"], "nnz_l": int(best_py["stats"]["nnz_l"]),
        "cli": {"total_seconds": cli_total, "analysis_seconds": cs["total"],
                "factor_seconds": best_cli["factor"]["seconds"],
                "solve_seconds": best_cli["solve"]["seconds"],
                "backward_error": best_cli["solve"]["backward_error"]},
        "python": {"total_seconds": best_py["total"], "solver_seconds": best_py["solver"],
                   "solve_seconds": best_py["solve"],
                   "phases_seconds": best_py["inner"],
                   "analysis_seconds": best_py["stats"]["seconds"]["total"],
                   "factor_seconds": best_py["stats"]["factor"]["seconds"],
                   "solve_phase_seconds": best_py["stats"]["solve"]["seconds"],
                   "backward_error": backward_error(A_full, best_py["x"], b),
                   "full_storage_total_seconds": t_full},
        "runs": {"cli_total_seconds": cli_runs, "python_total_seconds": py_runs},
        "overhead_vs_cli_percent": 100.0 * (best_py["total"] / cli_total - 1.0),
        "overhead_vs_cli_median_percent":
            100.0 * (float(np.median(py_runs)) / float(np.median(cli_runs)) - 1.0),
        "outside_phases_percent": 100.0 * (best_py["total"] / best_py["inner"] - 1.0),
    }


# ------------------------------------------------------------------------------ part 2


def solvers_row(name, size, A, source, threads, repeat, splu_limit):
    n = A.shape[0]
    rng = np.random.default_rng()
    b = A @ rng.standard_normal(n)
    row = {"problem": name, "size": size, "source": source, "n": int(n), "nnz_a": int(A.nnz)}

    t, (x, st) = best_of(lambda: (lambda s: (s.solve(b), s.stats))(
        strata.Solver(A, type="spd", num_threads=threads)), repeat)
    row["strata"] = {"seconds": t, "backward_error": backward_error(A, x, b),
                     "nnz_l": int(st["nnz_l"]), "analysis_seconds": st["seconds"]["total"],
                     "factor_seconds": st["factor"]["seconds"],
                     "solve_seconds": st["solve"]["seconds"]}

    A_csc = A.tocsc()
    splu_repeat = 1 if n > SPLU_ONCE_ABOVE else repeat
    for key, permc in (("scipy_spsolve", "MMD_AT_PLUS_A"), ("scipy_spsolve_colamd", "COLAMD")):
        best = None
        for _ in range(splu_repeat):
            got = limited(lambda: spla.spsolve(A_csc, b, permc_spec=permc, use_umfpack=False),
                          splu_limit)
            if got is None:
                break
            if best is None or got[0] < best[0]:
                best = got
        if best is None:
            row[key] = {"status": f"timed out (> {splu_limit:g} s)", "permc_spec": permc}
        else:
            row[key] = {"seconds": best[0], "backward_error": backward_error(A, best[1], b),
                        "permc_spec": permc, "runs": splu_repeat}

    if _cholmod_cholesky is None:
        row["cholmod"] = {"status": "not installed"}
    else:
        def chol():
            f = _cholmod_cholesky(A_csc)
            return f(b), f
        t, (x, f) = best_of(chol, repeat)
        row["cholmod"] = {"seconds": t, "backward_error": backward_error(A, x, b),
                          "nnz_l": int(f.L().nnz)}
    return row


# ------------------------------------------------------------------------------ main


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--cli", default=os.path.join(REPO, "build", "strata"),
                    help="the strata command (default: build/strata)")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--overhead-repeat", type=int, default=7,
                    help="runs of each side in part 1 (default 7: other work on a small "
                         "machine makes single runs vary by tens of percent)")
    ap.add_argument("--threads", type=int, default=0, help="strata threads (0: all)")
    ap.add_argument("--splu-limit", type=float, default=60.0,
                    help="seconds after which one SuperLU solve is stopped (default 60)")
    ap.add_argument("--results-dir", default=os.path.join(REPO, "bench", "results"))
    ap.add_argument("--matrix-dir", default=os.environ.get(
        "STRATA_MATRIX_DIR", os.path.join(REPO, "data", "matrices")))
    ap.add_argument("--quick", action="store_true",
                    help="tiny problems, one repeat, results to a temporary folder")
    args = ap.parse_args(argv)
    pythonpath = os.environ.get("PYTHONPATH")
    meta = metadata(([f"PYTHONPATH={pythonpath}"] if pythonpath else []) + [sys.executable]
                    + sys.argv[:1] + (argv if argv is not None else sys.argv[1:]))
    if args.quick:
        args.repeat = args.overhead_repeat = 1
        args.results_dir = tempfile.mkdtemp(prefix="strata-python-bench-")
        overhead = [("lap2d-30", "small"), ("lap3d-12", "large")]
        solvers = [("lap2d-30", "small"), ("lap3d-10", "large")]
    else:
        overhead = [("bcsstk16", "small"), ("lap3d-45", "large")]
        solvers = [("bcsstk16", "small"), ("ccx_segmenttet_K", "small"),
                   ("ccx_cubef2f3_K", "small"), ("lap2d-100", "small"), ("lap3d-15", "small"),
                   ("lap2d-300", "large"), ("lap3d-35", "large")]
    if not os.access(args.cli, os.X_OK):
        ap.error(f"{args.cli} is not an executable: build it (scripts/build.sh) or pass --cli")

    load_start = os.getloadavg()[0]
    rows = []
    cache = {}

    def get(name):
        if name not in cache:
            cache[name] = load(name, args.matrix_dir)
        return cache[name]

    with tempfile.TemporaryDirectory(prefix="strata-python-bench-") as tmp:
        for name, size in overhead:
            A, _ = get(name)
            r = overhead_row(name, size, A, args.cli, args.threads, args.overhead_repeat, tmp)
            r["part"] = "overhead"
            rows.append(r)
            print(f"overhead {name:<18} n={r['n']:>8}  CLI {r['cli']['total_seconds']:8.3f} s  "
                  f"Python {r['python']['total_seconds']:8.3f} s  "
                  f"{r['overhead_vs_cli_percent']:+6.2f}% vs CLI, "
                  f"{r['outside_phases_percent']:5.2f}% outside the phases", flush=True)
    for name, size in solvers:
        A, source = get(name)
        r = solvers_row(name, size, A, source, args.threads, args.repeat, args.splu_limit)
        r["part"] = "solvers"
        rows.append(r)

        def f(k):
            d = r[k]
            return (f"{d['seconds']:8.3f} s ({d['backward_error']:.1e})" if "seconds" in d
                    else f"{d['status'][:22]:>22}")
        print(f"solvers  {name:<18} n={r['n']:>8}  strata {f('strata')}  "
              f"spsolve {f('scipy_spsolve')}  colamd {f('scipy_spsolve_colamd')}  "
              f"cholmod {f('cholmod')}", flush=True)

    out = {"benchmark": "python", "tag": "quick" if args.quick else "", **meta,
           # other work on the machine stretches the times: the 1-minute load average
           # before and after the run
           "load_average": {"start": load_start, "end": os.getloadavg()[0]},
           "threads": args.threads, "repeat": args.repeat,
           "overhead_repeat": args.overhead_repeat,
           "overhead_goal_percent": 5.0,
           "versions": {"python": platform.python_version(), "numpy": np.__version__,
                        "scipy": scipy.__version__,
                        "scikit_sparse": SKSPARSE or "not installed",
                        "strata": strata.__version__},
           "rows": rows}
    os.makedirs(args.results_dir, exist_ok=True)
    path = os.path.join(args.results_dir,
                        "python-" + time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + ".json")
    with open(path + ".tmp", "w") as f:
        json.dump(out, f, indent=2)
        f.write("\n")
    os.replace(path + ".tmp", path)
    print("wrote", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
