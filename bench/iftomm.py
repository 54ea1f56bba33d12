#!/usr/bin/env python3
"""strata on the IFToMM multibody benchmark problems (models/iftomm/): error and time.

    python3 bench/iftomm.py [--cli build/strata] [--results-dir bench/results] [--quick]

Runs `strata simulate` on every bundled IFToMM model with the model file's settings and a
few others per problem (fixed steps of several orders and sizes, variable steps), and
writes one results file, bench/results/iftomm-<UTC time>.json (benchmark "iftomm"), that
bench/report.py turns into the "IFToMM multibody benchmarks" section of bench/REPORT.md.
Each row: the problem, the settings (the command line arguments), whether the run
completed, the deviation from the model file's reference values at its reference time
(status.json "reference_error"; the model descriptions say where each reference comes
from), the energy drift and warnings, steps, and the times the summary prints (total wall
time and its solver/assembly parts). The machine is whatever runs this (2 shared cores in
development): the times are reported, never tested.

Only the Python standard library is used.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time

from run_metadata import metadata

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# (model, extra arguments); "" is the model file's own settings
SETTINGS = {
    "simple_pendulum": ["", "--order 2 --step 1e-3", "--variable-step --rtol 1e-6 --atol 1e-8"],
    "n_four_bar": ["", "--order 2 --step 1e-3", "--order 2 --step 2e-4", "--order 3 --step 5e-4",
                   "--order 4 --step 2e-4", "--order 4 --step 1e-4", "--order 5 --step 2e-4",
                   "--variable-step", "--variable-step --rtol 1e-6 --atol 1e-8",
                   "--order 5 --step 1e-4 --formulation partitioned"],
    "andrews": ["", "--order 2 --step 2.5e-6 --newton-tol 1e-10",
                "--order 4 --step 5e-6 --newton-tol 1e-10",
                "--variable-step --order 4 --rtol 1e-8 --atol 1e-10 --step 1e-7"],
    "bricard": ["", "--order 4 --step 1e-4", "--variable-step --rtol 1e-6 --atol 1e-8"],
    "flyball_governor": ["", "--order 4 --step 1e-3", "--variable-step --rtol 1e-6 --atol 1e-8"],
    "spatial_slider_crank": ["", "--order 2 --step 2e-4", "--order 4 --step 1e-4",
                             "--variable-step --rtol 1e-6 --atol 1e-8"],
}
QUICK = {name: [""] for name in SETTINGS}

SUMMARY = {
    "steps": re.compile(r"^steps\s+(\d+) accepted, (\d+) rejected"),
    "time": re.compile(r"^time \[s\]\s+total ([\d.]+): solver ([\d.]+) .*assembly ([\d.]+)"),
    "energy": re.compile(r"^energy \[J\]\s+initial (\S+), final (\S+)"),
    "stabilized": re.compile(r"^formulation\s+partitioned, stabilized from t = (\S+) s"),
    "removed": re.compile(r"^redundant equations\s+(\d+) switched off"),
}


def run_one(cli, model, args, out):
    cmd = [cli, "simulate", model, "--quiet", "--output", out] + shlex.split(args)
    proc = subprocess.run(cmd, capture_output=True, text=True)
    row = {"settings": args or "(model file)", "exit_status": proc.returncode}
    for line in proc.stdout.splitlines():
        for key, rx in SUMMARY.items():
            m = rx.match(line)
            if m:
                row[key] = [float(x) for x in m.groups()]
    try:
        with open(os.path.join(out, "status.json"), encoding="utf-8") as f:
            status = json.load(f)
    except (OSError, ValueError):
        status = {}
    row["complete"] = bool(status.get("complete"))
    row["t_reached"] = status.get("t_reached")
    row["reference_error"] = status.get("reference_error")
    row["warnings"] = status.get("warnings", [])
    row["message"] = status.get("message", proc.stderr.strip()[-300:])
    if "time" in row:
        row["wall_seconds"], row["solver_seconds"], row["assembly_seconds"] = row.pop("time")
    if "steps" in row:
        row["steps"], row["rejected"] = (int(x) for x in row["steps"])
    if "energy" in row:
        e0, e1 = row.pop("energy")
        row["energy_change"] = e1 - e0
    if "stabilized" in row:
        row["stabilized_from"] = row.pop("stabilized")[0]
    if "removed" in row:
        row["removed_equations"] = int(row.pop("removed")[0])
    return row


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cli", default=os.path.join(REPO, "build", "strata"))
    ap.add_argument("--results-dir", default=os.path.join(REPO, "bench", "results"))
    ap.add_argument("--quick", action="store_true", help="the model files' settings only")
    args = ap.parse_args(argv)
    data = {"benchmark": "iftomm",
            **metadata([sys.argv[0]] + (argv if argv is not None else sys.argv[1:]))}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for name, settings in (QUICK if args.quick else SETTINGS).items():
            model = os.path.join(REPO, "models", "iftomm", name + ".json")
            with open(model, encoding="utf-8") as f:
                doc = json.load(f)
            ref = doc.get("reference", {})
            for s in settings:
                row = {"problem": name, "reference_time": ref.get("time"),
                       "reference_tolerance": ref.get("tolerance", 1e-3),
                       "reference_source": ref.get("source", "")}
                row.update(run_one(args.cli, model, s, os.path.join(tmp, name)))
                print(f"{name:22s} {row['settings']:48s} complete={row['complete']} "
                      f"error={row['reference_error']} wall={row.get('wall_seconds')}",
                      flush=True)
                rows.append(row)
    data["rows"] = rows
    os.makedirs(args.results_dir, exist_ok=True)
    path = os.path.join(args.results_dir,
                        "iftomm-" + time.strftime("%Y%m%dT%H%M%SZ", time.gmtime()) + ".json")
    with open(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
    print(f"results: {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
