"""Experiment 3b of the strata benchmark report (used by bench/report.py): the distributed
factorization over MPI ranks (issue 11), measured against the cost model's prediction.

Inputs:
  distributed  bench/bench_distributed.cpp, one file per configuration (run by
               scripts/gpu/run_mpi.sh: 1 rank × 4 GPUs, 2 × 2, 4 × 1; tags "RxG"). The
               configuration is read from the file's top-level "ranks" and "gpus_per_rank"
               (the command line the driver ran with), not from the rows.
  cost_model   bench/cost_model.py --json (cost-model.json, written by run_mpi.sh next to
               the measurements): "benchmark_4gpu" holds per (problem, ranks, gpus_per_rank)
               the predicted seconds, its parts and the bytes between ranks; "scaling" the
               model-only predictions for 8-512 GPUs. Without such a file the prediction is
               computed here with bench/cost_model.py's own functions (calibrate,
               predict_benchmark), and the report says so.
Every number is copied from those files or computed from them, as the captions say.
"""
from __future__ import annotations

import os
import sys

from report_common import (NOT_MEASURED, Run, f_e, f_g, f_int, f_ratio, f_sec,
                           machine_label, machine_slug, num, ratio, table)

HERE = os.path.dirname(os.path.abspath(__file__))


def config_of(r: Run, row: dict) -> tuple[int, int]:
    """(ranks, GPUs per rank) of a distributed row: the file's, else the row's."""
    rk = num(r.get("ranks"))
    g = num(r.get("gpus_per_rank"))
    rk = rk if rk is not None else num(row.get("ranks"))
    g = g if g is not None else num(row.get("gpus_per_rank"))
    return int(rk or 0), int(g or 0)


def model_predictions(problems: set[str]) -> tuple[dict, str]:
    """Predictions from bench/cost_model.py's functions when no cost-model file exists:
    ({(problem, R, G): prediction}, where-from text); ({}, reason) if it cannot run."""
    try:
        sys.path.insert(0, HERE)
        import cost_model  # noqa: PLC0415

        cal = cost_model.calibrate()
    except Exception as e:  # noqa: BLE001 (any failure: the report says why)
        return {}, f"bench/cost_model.py could not be run ({e.__class__.__name__}: {e})"
    out = {}
    for p in problems:
        c = cal["problems"].get(p)
        if c is None:
            continue
        for rk, g in ((1, 4), (2, 2), (4, 1)):
            out[(p, rk, g)] = cost_model.predict_benchmark(c, rk, g, cal["pcie_bytes_per_s"])
    return out, ("computed by this generator with bench/cost_model.py's calibrate() and "
                 "predict_benchmark() (no cost-model results file in the folder)")


class Distributed:
    """Mixin of Report: experiment 3b."""

    def distributed_section(self, runs: list[Run]) -> None:
        self.w("## 3b. Beyond one process: MPI ranks")
        self.w()
        self.w("The same 4 GPUs of one machine driven as 1 rank × 4 GPUs, 2 ranks × 2 GPUs "
               "and 4 ranks × 1 GPU (bench_distributed under mpirun, scripts/gpu/run_mpi.sh): "
               "factorization time and bytes sent between ranks, beside the prediction of "
               "the cost model (bench/cost_model.py, docs/distributed.md §4).")
        self.w()
        dist = [r for r in runs if r.kind == "distributed"]
        models = sorted([r for r in self.all_runs if r.kind == "cost_model"],
                        key=lambda r: (r.date, r.name))
        if not dist:
            self.consumed.update(r.path for r in models)
            self.w(f"{NOT_MEASURED}: no `distributed` results; on a lent 4-GPU machine "
                   f"`bench/run multigpu --only mpi` (or `bash scripts/gpu/run_mpi.sh`), then "
                   f"copy its distributed-*.json and cost-model.json to bench/results/.")
            self.w()
            return
        self.consumed.update(r.path for r in dist)
        by_machine: dict[tuple, list[Run]] = {}
        for r in dist:
            by_machine.setdefault(r.machine, []).append(r)
        for machine, rs in by_machine.items():
            self.distributed_machine(machine, rs, models)

    def distributed_machine(self, machine: tuple, rs: list[Run], models: list[Run]) -> None:
        meas: dict[tuple, tuple[Run, dict]] = {}
        for r in sorted(rs, key=lambda r: (r.date, r.name)):  # newer runs override
            for row in r.rows:
                if isinstance(row, dict):
                    meas[(str(row.get("problem")),) + config_of(r, row)] = (r, row)
        problems = list(dict.fromkeys(k[0] for k in meas))
        model = models[-1] if models else None
        pred, where = {}, ""
        if model is not None:
            self.consumed.add(model.path)
            for p in model.get("benchmark_4gpu") or []:
                if isinstance(p, dict) and num(p.get("ranks")) is not None:
                    pred[(str(p.get("problem")), int(p["ranks"]),
                          int(num(p.get("gpus_per_rank")) or 0))] = p
            where = f"the newest cost-model file, {self.source(model)}"
        else:
            pred, where = model_predictions(set(problems))
        keys = sorted(meas, key=lambda k: (problems.index(k[0]), -k[2], k[1]))
        rows, parts, sp, plot = [], [], [], []
        for k in keys:
            r, row = meas[k]
            p, rk, g = k
            pr = pred.get(k) or {}
            t, tp = num(row.get("factor_seconds")), num(pr.get("total_seconds"))
            b, bp = num(row.get("bytes_between_ranks")), num(pr.get("bytes_between_ranks"))
            per = [x for x in row.get("per_rank") or [] if isinstance(x, dict)]
            slow = [num(x.get("factor_seconds")) for x in per]
            slow = max([x for x in slow if x is not None], default=None)
            rows.append([p, f"{rk} × {g}", f_sec(row.get("first_factor_seconds")), f_sec(t),
                         f_sec(slow), f_sec(tp), f_ratio(ratio(t, tp)),
                         f_g(b / 1e6) if b is not None else "–",
                         f_g(bp / 1e6) if bp is not None else "–", f_ratio(ratio(b, bp)),
                         f_sec(row.get("solve_seconds")), f_e(row.get("backward_error"))])
            if pr:
                parts.append([p, f"{rk} × {g}", f_sec(pr.get("subtree_seconds")),
                              f_sec(pr.get("top_seconds")), f_sec(pr.get("cb_seconds")),
                              f_sec(pr.get("values_seconds")), f_sec(pr.get("host_seconds")),
                              f_sec(tp)])
            plot.append((f"{p}\n{rk}×{g}", t, tp, b, bp))
            one = meas.get((p, 1, rk * g))
            base = num(one[1].get("factor_seconds")) if one else None
            if rk > 1 and base and t:
                sp.append((p, rk, g, t / base, rk * g))
        self.w(f"On {machine_label(machine)}. *first*: the first factorization (it sets the "
               f"executors up); *factor*: the driver's `factor_seconds`, the median of the "
               f"refactorizations after the first (files from 3da3a5a on; earlier files "
               f"counted the first in that median); *slowest rank*: the largest per-rank "
               f"factorization time. Transport: NCCL where the file says so, else MPI through "
               f"host memory. "
               f"Configuration R × G from the file's `ranks` and `gpus_per_rank`. Bytes: "
               f"sent between ranks during the factorization (contribution blocks and values). "
               f"Predicted: {where or 'no prediction available'}.")
        self.w()
        self.w(table(["problem", "ranks × GPUs", "first s", "factor s", "slowest rank s",
                      "predicted s", "measured/predicted", "MB between ranks", "predicted MB",
                      "measured/predicted MB", "solve s", "berr"], rows, 2))
        for p, rk, g, x, w in sp:
            verdict = "**slower**" if x > 1 else "faster"
            self.w(f"{p}: {rk} ranks × {g} GPU{'s' if g > 1 else ''} takes {x:.2f}× the time "
                   f"of 1 rank × {w} GPUs ({verdict} than one process driving the same GPUs).")
            self.w()
            if x > 1:
                self.behind_notes.append(
                    f"distributed factorization on {machine_label(machine)}: {p} on {rk} "
                    f"ranks × {g} GPU{'s' if g > 1 else ''} is {x:.2f}× slower than 1 rank × {w} GPUs")
        off = [(k, ratio(num(meas[k][1].get("factor_seconds")),
                         num((pred.get(k) or {}).get("total_seconds")))) for k in keys]
        off = [(k, x) for k, x in off if x is not None and (x > 1.5 or x < 1 / 1.5)]
        if off:
            self.w("**The cost model is off by more than 1.5×** on " + ", ".join(
                f"{k[0]} {k[1]} × {k[2]} (measured/predicted {f_ratio(x)})" for k, x in off)
                + ": its predictions are not confirmed by these measurements.")
            self.w()
        slow_solve = [(k, num(meas[k][1].get("solve_seconds")),
                       num(meas[k][1].get("factor_seconds"))) for k in keys]
        slow_solve = [(k, s, f) for k, s, f in slow_solve if s and f and s > 5 * f]
        if slow_solve:
            self.w("**Solves slower than 5 factorizations** (a solve should cost a small "
                   "fraction of one): " + ", ".join(f"{k[0]} {k[1]} × {k[2]} ({f_sec(s)} s)"
                                                   for k, s, _ in slow_solve) + ".")
            self.w()
        if parts:
            self.w("The prediction's parts (seconds): subtrees (at the calibrated subtree "
                   "rate and balance), the top part on rank 0's GPU, contribution blocks "
                   "between ranks and through host memory, the values sent to the ranks, "
                   "and *host*, everything else, calibrated from a single-process 4-GPU time "
                   "(bench/cost_model.py). Model output, not measurements.")
            self.w()
            self.w(table(["problem", "ranks × GPUs", "subtrees", "top", "blocks", "values",
                          "host", "total"], parts, 2))
        if plot:
            fig, axes = self.plt.subplots(1, 2, figsize=(max(9, 1.2 * len(plot) + 4), 4.5))
            xs = range(len(plot))
            for ax, i, unit, title in ((axes[0], 1, 1, "factorization time [s]"),
                                       (axes[1], 3, 1e6, "MB between ranks")):
                ax.bar([x - 0.2 for x in xs], [(v[i] or 0) / unit for v in plot], 0.4,
                       label="measured")
                ax.bar([x + 0.2 for x in xs], [(v[i + 1] or 0) / unit for v in plot], 0.4,
                       label="predicted")
                ax.set_xticks(list(xs))
                ax.set_xticklabels([v[0] for v in plot], fontsize=7)
                ax.set_title(title + ": measured vs cost model", fontsize=10)
                ax.grid(True, axis="y", alpha=0.3)
                ax.legend(fontsize=8)
            self.savefig(fig, f"distributed-{machine_slug(machine)}",
                         "distributed factorization: measured vs predicted",
                         "Tables and plot: measurements copied from the rows (newest file per "
                         "configuration), predictions from the cost model as stated above; "
                         "ratios computed by this generator.",
                         sorted({meas[k][0].path: meas[k][0] for k in keys}.values(),
                                key=lambda r: r.name)
                         + ([model] if model is not None else []))
        scal = [p for p in (model.get("scaling") or [])] if model is not None else []
        scal = [p for p in scal if isinstance(p, dict)]
        if scal:
            self.w("The model alone (**predictions, nothing measured**) for more GPUs than a "
                   "lent machine has (8 GPUs per node, one rank per node): the numeric "
                   "factorization with the current schedule (the whole top part on one GPU) "
                   "and with the tiled top fronts of docs/distributed.md §1, and the speedup "
                   "over one GPU.")
            self.w()
            self.w(table(["problem", "GPUs", "schedule", "top flops share", "predicted s",
                          "predicted speedup"],
                         [[str(p.get("problem")), f_int(p.get("gpus")), str(p.get("schedule")),
                           f"{num(p.get('top_flops_fraction')) or 0:.1%}",
                           f_sec(p.get("total_seconds")),
                           f_g(p.get("speedup_vs_one_gpu"))] for p in scal], 1))
            self.caption("Table: copied from the cost model's `scaling` list.", [model])
