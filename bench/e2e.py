#!/usr/bin/env python3
"""End-to-end `strata simulate` benchmark: time per step split into set-up (initial
conditions and coordinate partitioning), analysis, factorization, solve and assembly,
the analyses by cause, the static pivots left, and the real-time factor (wall time over
simulated time), for each model, with the binary under test and, when --baseline names
another build (an older commit's, say), with that one too in the same run, models
alternating, so the ratio is measured and not remembered.

    python3 bench/e2e.py [--strata build/strata] [--baseline OLD/strata] [--device cpu]
                         [--baseline-args=ARGS] [--threads N] [--models SPEC:T_END,...]
                         [--repeat R]

--baseline-args gives the baseline's runs more arguments: with --baseline the binary under
test, `--baseline-args=--no-condensation` measures the condensation by the BDF relations
against the full Newton matrix in one run.

Writes bench/results/e2e-<UTC time>.json (machine, date, commit, command, every figure,
the ratios current / baseline) and prints a table. Each figure is the one the summary of
`strata simulate` prints; with --repeat R the run with the least wall time is kept.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import time

from run_metadata import REPO, metadata

DEFAULT_MODELS = "tracked:100:1.0,tracked:1000:0.02,flexible:64x4x4:0.01,lattice:6:0.02"

# lines of the summary of `strata simulate` and the figures read from them
PATTERNS = {
    "steps": (r"^steps\s+(\d+) accepted", int),
    "newton_iterations": (r"^Newton iterations\s+(\d+)", int),
    "factorizations": (r"^factorizations\s+(\d+)", int),
    "analyses": (r"analyses (\d+):", int),
    "analyses_perturbed": (r"perturbed pivots (\d+)[,;]", int),
    "analyses_contacts": (r"contact-set changes (\d+)", int),
    "analyses_matching_kept": (r"\(matching kept in (\d+)\)", int),
    "analyses_order_kept": (r"order kept for (\d+)", int),
    "static_pivots_left": (r"static pivots left (\d+)", int),
    "delayed_factorizations": (r"delayed pivoting in (\d+) factorizations", int),
    "corrected_factorizations": (r"static pivots corrected in (\d+) factorizations", int),
    "rows": (r"^Newton matrix\s+(\d+) x", int),
    "total_s": (r"^time \[s\]\s+total ([\d.]+)", float),
    "solver_s": (r"solver ([\d.]+) \(", float),
    "analysis_s": (r"of which analysis ([\d.]+)\)", float),
    "assembly_s": (r"assembly ([\d.]+) \(", float),
    "initial_conditions_s": (r"initial conditions ([\d.]+)", float),
    "partitioning_s": (r"partitioning ([\d.]+)", float),
    "factorization_ms": (r"factorization ([\d.]+) each", float),
    "solve_ms": (r"solve ([\d.]+) each", float),
    "device_solves": (r"\((\d+) on the GPU", int),
    "device_solve_ms": (r"on the GPU, ([\d.]+) each", float),
    # the host's share of the condensation by the BDF relations (factorizations and solves)
    "condensation_ms": (r"condensation on the host ([\d.]+) in all", float),
    # strata's own split of a factorization (the line "factorization [ms]", printed when
    # a GPU ran or values were equilibrated again)
    "value_input_ms": (r"value input ([\d.]+) each", float),
    "gpu_factorization_ms": (r"GPU ([\d.]+) each", float),
    "values_on_device_factorizations": (r"values scaled on the GPU in (\d+) of", int),
    # (binaries before 2026-11-28 print "equilibrated again on the host in N")
    "rescaled_factorizations": (r"equilibrated again (?:on the host )?in (\d+)", int),
}


def parse(text: str) -> dict:
    row = {}
    for line in text.splitlines():
        for key, (rx, conv) in PATTERNS.items():
            if key in row:
                continue
            m = re.search(rx, line)
            if m:
                row[key] = conv(m.group(1))
    return row


def run(binary: str, spec: str, t_end: float, device: str, threads: int,
        extra: list[str]) -> dict:
    cmd = [binary, "simulate", "--generate", spec, "--t-end", str(t_end), "--quiet", "--output",
           "", "--device", device] + extra
    if threads > 0:
        cmd += ["--threads", str(threads)]
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True)
    row = parse(proc.stdout)
    row.update(wall_s=time.perf_counter() - t0, exit_status=proc.returncode, t_end=t_end)
    if proc.returncode != 0:
        row["error"] = (proc.stderr.strip().splitlines() or [""])[-1]
    steps = max(row.get("steps", 0), 1)
    # the initial conditions' time includes their coordinate partitioning (which the
    # summary's partitioning figure also counts, with the checks during the run)
    row["setup_s"] = row.get("initial_conditions_s", 0)
    for key in ("solver_s", "analysis_s", "assembly_s"):
        row[key.replace("_s", "_ms_per_step")] = 1e3 * row.get(key, 0) / steps
    row["real_time_factor"] = row["wall_s"] / t_end
    return row


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--strata", default=os.path.join(REPO, "build", "strata"))
    ap.add_argument("--baseline", help="another strata binary, run side by side")
    ap.add_argument("--baseline-label", default="",
                    help="what the baseline is (its commit), recorded in the results")
    ap.add_argument("--baseline-args", default="",
                    help="more simulate arguments for the baseline's runs (one string, split "
                         "as a shell would), e.g. --baseline-args=--no-condensation with "
                         "--baseline the same binary")
    ap.add_argument("--device", default="cpu", choices=["cpu", "gpu", "auto"])
    ap.add_argument("--threads", type=int, default=0, help="host threads (0: all)")
    ap.add_argument("--models", default=DEFAULT_MODELS,
                    help="comma-separated SPEC:T_END (SPEC as --generate takes it)")
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--results-dir", default=os.path.join(REPO, "bench", "results"))
    args = ap.parse_args(argv)
    data = {"benchmark": "e2e", **metadata([sys.argv[0]] + (argv if argv is not None
                                                              else sys.argv[1:]))}
    data.update(device=args.device, threads=args.threads, baseline=args.baseline or "",
                baseline_label=args.baseline_label,
                baseline_args=args.baseline_args, rows=[])
    binaries = [("current", args.strata, [])] + (
        [("baseline", args.baseline, shlex.split(args.baseline_args))] if args.baseline else [])
    # Both binaries run the same OpenBLAS kernels: those the binary under test chooses (it
    # replaces OpenBLAS's Prescott fallback, apps/common/blas_kernels.hpp; an older baseline
    # may not), unless OPENBLAS_CORETYPE is set already.
    if "OPENBLAS_CORETYPE" not in os.environ:
        version = subprocess.run([args.strata, "--version"], capture_output=True, text=True)
        m = re.search(r", (\w+) kernels\)", version.stdout)
        if m:
            os.environ["OPENBLAS_CORETYPE"] = m.group(1)
    data["openblas_coretype"] = os.environ.get("OPENBLAS_CORETYPE", "")
    models = []
    for item in args.models.split(","):
        # SPEC:T_END; every generated model but andrews has an argument (tracked:100), so
        # "tracked:100" alone would read as the model tracked to t = 100 s: refused
        spec, _, t_end = item.rpartition(":")
        if not spec or (":" not in spec and spec != "andrews"):
            ap.error(f"--models: {item!r} is not SPEC:T_END (e.g. tracked:100:1.0)")
        try:
            models.append((spec, float(t_end)))
        except ValueError:
            ap.error(f"--models: the end time of {item!r} is not a number")
    for spec, t_end in models:
        best = {}
        for _ in range(max(args.repeat, 1)):
            for name, binary, extra in binaries:  # alternating: both see the same machine
                r = run(binary, spec, t_end, args.device, args.threads, extra)
                if name not in best or r["wall_s"] < best[name]["wall_s"]:
                    best[name] = r
        row = {"model": spec, **{name: best[name] for name, _, _ in binaries}}
        if args.baseline:
            row["ratio"] = {k: best["current"][k] / best["baseline"][k]
                            for k in ("wall_s", "solver_s", "assembly_s", "factorization_ms",
                                      "solve_ms") if best["baseline"].get(k)}
        data["rows"].append(row)
        cur = best["current"]
        print(f"{spec:18s} wall {cur['wall_s']:8.2f} s  solver {cur['solver_ms_per_step']:7.2f} "
              f"ms/step  analyses {cur.get('analyses', '?')} (perturbed "
              f"{cur.get('analyses_perturbed', '?')})  static left "
              f"{cur.get('static_pivots_left', '?')}"
              + (f"  wall ratio {row['ratio'].get('wall_s', float('nan')):.2f}"
                 if args.baseline else ""))
    os.makedirs(args.results_dir, exist_ok=True)
    path = os.path.join(args.results_dir,
                        "e2e-" + time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + ".json")
    with open(path + ".tmp", "w") as f:
        json.dump(data, f, indent=1)
    os.replace(path + ".tmp", path)
    print("results:", path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
