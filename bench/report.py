#!/usr/bin/env python3
"""strata benchmark report: turns every bench/results/*.json into bench/REPORT.md.

    python3 bench/report.py [--results DIR] [--out DIR] [--readme FILE] [--history FILE]

Reads every results file the benchmark drivers wrote (bench_analysis, bench_factor, and
the GPU drivers to come), keeps the newest run per (benchmark kind, machine, tag), and
writes OUT/REPORT.md with tables and OUT/plots/*.png (matplotlib, Agg backend). Every
table and plot is captioned with the command, machine, date and git commit of the run it
shows and the name of its results file; every number in the report is either copied from
a results file or computed from one (ratios, geometric means: the caption says which).
Sections whose results do not exist say so instead of showing numbers. The headline
ratios also go into the performance table of README.md (between its marker lines), and
the hand-written notes of bench/history.md are copied to the end (bench/report_readme.py).

What a results file must hold (bench/bench_common.cpp writes it): "benchmark" (the kind),
"date" (ISO 8601 UTC), "command", "git_commit", "machine" {"cpu", "hardware_threads",
"gpu", "host"}, "rows" (a list of objects), and optionally "tag" (default "") and
"backend" (default "cpu"; GPU drivers must write "cuda").

How results map to the five experiments of the benchmark issue:
  1. max block size sweep   benchmark "factor", tag "mbs-N" (one run per block size N);
                            backend "cpu" -> CPU part, any other backend -> GPU part
  2. other solvers          benchmark "analysis" (vs CHOLMOD+METIS) and "factor", tag ""
                            (vs CHOLMOD and MUMPS with the same permutation; a row's
                            "cudss" object, from a GPU driver, becomes a cuDSS column)
                            (bench_gpu: rows with "strata_gpu", GPU vs CPU backend);
                            benchmark "cudss" (bench_cudss: strata's GPU vs NVIDIA cuDSS;
                            "last_refactor" phases, "first_solve_seconds");
                            benchmark "gpu-profile" (bench_gpu --gpu-only): phases only
  3. GPU count 1, 2, 4      benchmark "multigpu" (backend cuda; cpu runs shown apart;
                            rows with "first_factor_seconds" supersede older files)
  3b. MPI ranks             benchmark "distributed" (bench_distributed via
                            scripts/gpu/run_mpi.sh) beside the newest "cost_model"
                            prediction (cost-model.json of bench/cost_model.py)
  4. solvability            benchmark "gpu_memory" (its "solvability" and "device_figures";
                            its "block_size" list is the GPU part of experiment 1)
  5. end to end simulate    benchmark "simulate", else the newest results/logs/*mbd*.log
                            (scripts/gpu/run_mbd.sh; see bench/report_e2e.py)
and, outside the five experiments, the IFToMM multibody benchmarks (bench/iftomm.py,
benchmark "iftomm"; bench/report_iftomm.py) and the Python interface (bench/python_vs_scipy.py):
benchmark "python", tag "" (overhead against the command line; strata against scipy's
spsolve and scikit-sparse's CHOLMOD).
Results of any other kind or tag are shown as plain tables under "Other results", so
nothing measured is dropped silently.

Only the Python standard library and matplotlib are used.
"""
from __future__ import annotations

import argparse
import os
import re
import sys

from report_common import (NOT_MEASURED, Run, by_machine, dig, f_e, f_g, f_int, f_pct,
                           f_ratio, f_sec, geomean, load_runs, machine_label,
                           machine_slug, newest_runs, num, ratio, table)
from report_e2e import EndToEnd
from report_dist import Distributed
from report_gpu import GpuSections, is_bench_gpu
from report_readme import history_section, readme_table, update_readme
from report_iftomm import IftommSection

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SWEEP_TAG = re.compile(r"^mbs-(\d+)$")


# --------------------------------------------------------------------------- report


def bundled_matrix(problem) -> bool:
    """True for a matrix bundled in data/matrices (bcsstk16, ...): a cuDSS run tagged mbd may
    name one beside the multibody Newton matrices, which are generated and not bundled."""
    here = os.path.dirname(os.path.abspath(__file__))
    return os.path.exists(os.path.join(here, "..", "data", "matrices", f"{problem}.mtx.gz"))


def headline_rows(run: Run) -> list:
    """The rows a run's headline ratios are taken over: for a cuDSS run tagged mbd only the
    multibody Newton matrices (its lines say so), every row otherwise."""
    if run.kind == "cudss" and run.tag == "mbd":
        return [row for row in run.rows if not bundled_matrix(row.get("problem"))]
    return run.rows


def mbd_label(run: Run) -> str:
    """ ", multibody Newton matrices" for a cuDSS run tagged mbd (run_cudss_mbd.sh)."""
    return ", multibody Newton matrices" if run.kind == "cudss" and run.tag == "mbd" else ""


class Report(GpuSections, Distributed, EndToEnd, IftommSection):
    def __init__(self, results_dir: str, out_dir: str, history: str | None = None):
        self.results_dir = os.path.abspath(results_dir)
        self.history = history
        self.out_dir = os.path.abspath(out_dir)
        self.plot_dir = os.path.join(self.out_dir, "plots")
        self.parts: list[str] = []
        self.plots: list[str] = []
        self.key_ratios: list[dict] = []
        self.used: set[str] = set()
        import matplotlib  # noqa: PLC0415 (imported here so --help works without it)

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt  # noqa: PLC0415

        self.plt = plt

    # ---- helpers

    def key_ratio(self, what: str, g, per_problem: list, run: Run) -> None:
        """Remembers a headline ratio (geometric mean g over the problems of a run, untagged
        runs only, and cuDSS runs tagged "mbd": the multibody Newton matrices' own line)
        for the README's performance table (report_readme.py)."""
        if g is not None and (not run.tag or (run.kind == "cudss" and run.tag == "mbd")):
            n = sum(1 for _, x in per_problem if x is not None)
            self.key_ratios.append({"what": what, "ratio": g, "problems": n, "run": run})

    def w(self, text: str = "") -> None:
        self.parts.append(text + "\n")

    def rel(self, path: str) -> str:
        return os.path.relpath(path, self.out_dir)

    def source(self, run: Run) -> str:
        """The caption line: how it was measured and where the numbers are."""
        self.used.add(run.path)
        commit = str(run.get("git_commit") or "unknown")
        if run.get("git_dirty"):
            commit += " (with uncommitted changes)"
        host = dig(run.data, "machine", "host")
        host = f" (host {host})" if host else ""
        return (f"`{run.get('command')}` on {machine_label(run.machine)}{host}, "
                f"{run.date}, commit {commit}; results file "
                f"[`{run.name}`]({self.rel(run.path)})")

    def caption(self, what: str, runs: list[Run]) -> None:
        if len(runs) == 1:
            self.w(f"*{what} Measured with {self.source(runs[0])}.*")
        else:
            self.w(f"*{what} Measured with:*")
            self.w()
            for r in runs:
                self.w(f"- {self.source(r)}")
        self.w()

    def savefig(self, fig, stem: str, alt: str, what: str, runs: list[Run]) -> None:
        os.makedirs(self.plot_dir, exist_ok=True)
        name = stem + ".png"
        fig.tight_layout()
        fig.savefig(os.path.join(self.plot_dir, name), dpi=100, metadata={"Software": None})
        self.plt.close(fig)
        self.plots.append(name)
        self.w(f"![{alt}](plots/{name})")
        self.w()
        self.caption(what, runs)

    # ---- the report

    def build(self) -> str:
        all_runs, skipped = load_runs(self.results_dir)
        runs = newest_runs(all_runs)
        self.all_runs = all_runs
        self.consumed: set[str] = set()
        self.behind_notes: list[str] = []  # sections add "strata is behind" statements
        body_start = len(self.parts)
        self.sweep(runs)
        self.comparison(runs)
        self.multigpu_section(runs)
        self.distributed_section(runs)
        self.solvability_section(runs)
        self.e2e_section(runs)
        self.iftomm_section(runs)
        self.python_section(runs)
        self.others(runs)
        if skipped:
            self.w("## Results files skipped")
            self.w()
            for name, why in skipped:
                self.w(f"- `{name}`: {why}")
            self.w()
        body = self.parts[body_start:]
        self.parts = self.parts[:body_start]
        self.header(all_runs, runs)
        self.summary(runs)
        self.parts += body
        if self.history:
            self.parts.append(history_section(self.history))
        return "".join(self.parts)

    def header(self, all_runs: list[Run], runs: list[Run]) -> None:
        self.w("# strata benchmark report")
        self.w()
        self.w(f"Generated by `bench/report.py` from the results files in "
               f"`{self.rel(self.results_dir)}/` ({len(all_runs)} files read; the newest run "
               f"per benchmark kind, machine and tag is shown, {len(runs)} runs). Do not edit "
               f"by hand. To measure on this machine and regenerate: `bench/run cpu`. To "
               f"regenerate from the stored results only: `python3 bench/report.py`. The GPU "
               f"sections are regenerated from results files that came back from lent GPU "
               f"machines (`bench/run gpu`, `bench/run multigpu`) into `bench/results/`.")
        self.w()
        self.w("Every number below is copied from a results file or computed from one "
               "(ratios and geometric means, as the captions say). Lower is better for every "
               "ratio: a ratio above 1 means strata is behind the anchor.")
        self.w()

    # ---- summary

    def summary(self, runs: list[Run]) -> None:
        self.w("## Summary")
        self.w()
        lines, behind, ahead = [], [], []

        def judge(label: str, machine: tuple, per_problem: list[tuple[str, float]]):
            per_problem = [(p, x) for p, x in per_problem if x is not None]
            g = geomean([x for _, x in per_problem])
            if g is None:
                return None
            worse = [(p, x) for p, x in per_problem if x > 1]
            where = f"on {machine_label(machine)}"
            if g > 1:
                worst = max(worse, key=lambda t: t[1])
                behind.append(f"{label} {where}: geometric mean {f_ratio(g)}, behind on "
                              f"{len(worse)} of {len(per_problem)} problems (worst: "
                              f"{worst[0]}, {f_ratio(worst[1])})")
            elif worse:
                behind.append(f"{label} {where}: ahead in geometric mean ({f_ratio(g)}) but "
                              f"behind on {len(worse)} of {len(per_problem)} problems: "
                              + ", ".join(f"{p} ({f_ratio(x)})" for p, x in worse))
            else:
                ahead.append(f"{label} {where} (geometric mean {f_ratio(g)}, "
                             f"{len(per_problem)} problems)")
            return g

        for r in runs:
            if r.kind == "factor" and r.tag == "":
                for key, name in (("cholmod", "CHOLMOD"), ("mumps", "MUMPS"), ("cudss", "cuDSS")):
                    pp = [(row.get("problem"), self.factor_ratio(row, key)) for row in r.rows]
                    label = f"factorization time strata/{name} (same permutation, {r.backend})"
                    g = judge(label, r.machine, pp)
                    self.key_ratio(f"factorization time, strata / {name} (same ordering, "
                                   f"{r.backend.upper()})", g, pp, r)
                    if g is not None:
                        lines.append(f"- Geometric mean of {label}: **{f_ratio(g)}** "
                                     f"over {sum(1 for _, x in pp if x is not None)} problems "
                                     f"on {machine_label(r.machine)} "
                                     f"([`{r.name}`]({self.rel(r.path)})).")
            if r.kind == "cudss" and not r.get("solver_options"):
                # cuDSS's REFACTORIZATION alone has the values on the device already, so also
                # against cuDSS with their copy from the host first; newer runs time strata
                # from values in GPU memory (refactor_seconds) and from page-locked host
                # memory (refactor_host_seconds, against cuDSS with the copy); older ones
                # from host values only (refactor_seconds, against both)
                for what, theirs, k, name in (
                        ("refactor_seconds", "refactor_seconds", "cudss_default",
                         "refactorization time strata GPU/cuDSS (default reordering)"),
                        ("refactor_seconds", "refactor_seconds", "cudss_strata_perm",
                         "refactorization time strata GPU/cuDSS (strata's permutation)"),
                        ("refactor_seconds", "refactor_with_upload_seconds", "cudss_default",
                         "refactorization time strata GPU/cuDSS with its values copied from "
                         "page-locked host memory first (default reordering)")):
                    def ours(row):
                        host = dig(row, "strata_gpu", "refactor_host_seconds")
                        if theirs != what and host is not None:
                            return host
                        return dig(row, "strata_gpu", what)
                    pp = [(row.get("problem"), ratio(ours(row), dig(row, k, theirs)))
                          for row in headline_rows(r)]
                    g = judge(name, r.machine, pp)
                    self.key_ratio("GPU refactorization time, strata / cuDSS"
                                   + (", multibody Newton matrices" if r.tag == "mbd" else "")
                                   + " (" + ("each its own ordering" if k == "cudss_default"
                                             else "strata's ordering")
                                   + (", both from values in host memory"
                                      if theirs != what else "") + ")", g, pp, r)
                    if g is not None:
                        lines.append(f"- Geometric mean of {name}{mbd_label(r)}: "
                                     f"**{f_ratio(g)}** over "
                                     f"{sum(1 for _, x in pp if x is not None)} problems on "
                                     f"{machine_label(r.machine)} "
                                     f"([`{r.name}`]({self.rel(r.path)})).")
            # the first solve from host arrays, from arrays in GPU memory where the run
            # measured it (-1 or absent: not measured), and the default checked solve,
            # against cuDSS's (GPU arrays)
            for field, what, label in (
                    ("first_solve_seconds", "(one application of the factor, no refinement)",
                     "one right-hand side, no refinement"),
                    ("first_solve_gpu_arrays_seconds", "with b and x in GPU memory",
                     "b and x in GPU memory for both, no refinement"),
                    ("solve_seconds", "checked (residual, refinement to 1e-15), from host arrays",
                     "strata's default checked solve against cuDSS's unchecked one")):
                if r.kind != "cudss" or r.get("solver_options"):
                    break

                def strata_s(row, field=field):
                    v = num(dig(row, "strata_gpu", field))
                    return v if v is not None and v > 0 else None
                pp = [(row.get("problem"), ratio(strata_s(row), dig(row, "cudss_default",
                                                                     "solve_seconds")))
                      for row in headline_rows(r)]
                if all(x is None for _, x in pp):
                    continue
                name = (f"solve time strata GPU first solve {what}/cuDSS solve "
                        "(default reordering)")
                g = judge(name, r.machine, pp)
                self.key_ratio("GPU solve time, strata / cuDSS"
                               + (", multibody Newton matrices" if r.tag == "mbd" else "")
                               + f" ({label})", g, pp, r)
                if g is not None:
                    lines.append(f"- Geometric mean of {name}{mbd_label(r)}: "
                                 f"**{f_ratio(g)}** over "
                                 f"{sum(1 for _, x in pp if x is not None)} problems on "
                                 f"{machine_label(r.machine)} "
                                 f"([`{r.name}`]({self.rel(r.path)})).")
            if r.kind == "analysis" and r.tag == "":
                for key, what in (("nnz_l", "nnz(L) strata/CHOLMOD+METIS"),
                                  ("seconds", "analysis time strata/CHOLMOD+METIS")):
                    pp = [(row.get("problem"),
                           ratio(dig(row, "strata", key), dig(row, "cholmod_metis", key)))
                          for row in r.rows]
                    g = judge(what, r.machine, pp)
                    self.key_ratio(what.replace(" strata/", ", strata / "), g, pp, r)
                    if g is not None:
                        lines.append(f"- Geometric mean of {what}: **{f_ratio(g)}** over "
                                     f"{sum(1 for _, x in pp if x is not None)} problems on "
                                     f"{machine_label(r.machine)} "
                                     f"([`{r.name}`]({self.rel(r.path)})).")
        behind += getattr(self, "behind_notes", [])
        if not lines:
            self.w(f"{NOT_MEASURED}: no analysis or factorization results exist "
                   f"(run `bench/run cpu`).")
            self.w()
            return
        self.w("Key ratios (strata / anchor, each the geometric mean over the problems of "
               "the newest run; computed by this generator from the rows of the results "
               "file named):")
        self.w()
        for line in lines:
            self.w(line)
        self.w()
        if behind:
            self.w("**Where strata is behind an anchor (ratio > 1):**")
            self.w()
            for b in behind:
                self.w(f"- {b}.")
            self.w()
        else:
            self.w("In these measurements strata is not behind any anchor on any problem.")
            self.w()
        if ahead:
            self.w("Not behind (ratio ≤ 1 on every problem): " + "; ".join(ahead) + ".")
            self.w()
        self.w("Not yet compared at all: everything marked *not measured yet* below.")
        self.w()

    @staticmethod
    def factor_ratio(row: dict, anchor: str):
        a = row.get(anchor)
        if not isinstance(a, dict) or a.get("ok") is False:
            return None
        return ratio(dig(row, "strata", "seconds"), a.get("seconds"))

    # ---- 1. block size sweep

    def sweep(self, runs: list[Run]) -> None:
        self.w("## 1. Maximum block size sweep")
        self.w()
        self.w("strata's factorization time as `max_block_size` (the widest pivot block a "
               "separator front is split into) goes from 32 to 2048. Each block size is one "
               "`bench_factor --max-block-size N --tag mbs-N` run; the CHOLMOD column is the "
               "supernodal CHOLMOD factorization with the same permutation, measured in each "
               "of those runs (its spread shows the run-to-run noise of the machine).")
        self.w()
        sweep_runs = [r for r in runs if r.kind == "factor" and SWEEP_TAG.match(r.tag)]
        for part, pick in (("CPU", lambda r: r.backend == "cpu"),
                           ("GPU", lambda r: r.backend != "cpu")):
            self.w(f"### {part}")
            self.w()
            chosen = [r for r in sweep_runs if pick(r)]
            gm = ([r for r in runs if r.kind == "gpu_memory" and r.get("block_size")]
                  if part == "GPU" else [])
            for r in gm:
                self.gpu_block_sweep(r)
            if not chosen and gm:
                continue
            if not chosen:
                need = ("run `bench/run cpu`" if part == "CPU"
                        else "needs a lent GPU machine: `bench/run gpu`")
                self.w(f"{NOT_MEASURED}: no {part} block size sweep results ({need}).")
                self.w()
                continue
            for machine, mruns in by_machine(chosen).items():
                self.sweep_machine(part, machine, mruns)

    def sweep_machine(self, part: str, machine: tuple, mruns: list[Run]) -> None:
        self.consumed.update(r.path for r in mruns)

        def block(r: Run) -> int:
            v = num(r.get("max_block_size"))
            return int(v) if v is not None else int(SWEEP_TAG.match(r.tag).group(1))

        mruns = sorted(mruns, key=block)
        sizes = [block(r) for r in mruns]
        problems: list[str] = []
        for r in mruns:
            for row in r.rows:
                if row.get("problem") not in problems:
                    problems.append(row.get("problem"))
        cell = {(block(r), row.get("problem")): row for r in mruns for row in r.rows}
        rows = []
        for p in problems:
            times = {b: num(dig(cell.get((b, p)), "strata", "seconds")) for b in sizes}
            known = {b: t for b, t in times.items() if t is not None}
            best = min(known, key=known.get) if known else None
            chol = [num(dig(cell.get((b, p)), "cholmod", "seconds")) for b in sizes]
            chol = [c for c in chol if c is not None]
            chol_s = ("–" if not chol else f_sec(chol[0]) if min(chol) == max(chol)
                      else f"{f_sec(min(chol))}–{f_sec(max(chol))}")
            rows.append([p] + [f_sec(times[b]) for b in sizes] +
                        [str(best) if best is not None else "–", chol_s])
        self.w(f"Factorization time in seconds (median of the run's repeats) on "
               f"{machine_label(machine)}; *best* is the block size with the lowest time.")
        self.w()
        self.w(table(["problem"] + [f"{b}" for b in sizes] + ["best", "CHOLMOD s"], rows))
        fig, ax = self.plt.subplots(figsize=(7, 4.5))
        colors = self.plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for i, p in enumerate(problems):
            pts = [(b, num(dig(cell.get((b, p)), "strata", "seconds"))) for b in sizes]
            pts = [(b, t) for b, t in pts if t is not None]
            c = colors[i % len(colors)]
            if pts:
                ax.plot([b for b, _ in pts], [t for _, t in pts], "o-", color=c, label=p)
            cpts = [(b, num(dig(cell.get((b, p)), "cholmod", "seconds"))) for b in sizes]
            cpts = [(b, t) for b, t in cpts if t is not None]
            if cpts:
                ax.plot([b for b, _ in cpts], [t for _, t in cpts], ":", color=c, alpha=0.7)
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(sizes)
        ax.set_xticklabels([str(b) for b in sizes])
        ax.set_xlabel("max_block_size")
        ax.set_ylabel("factorization time [s]")
        ax.set_title(f"strata factorization time vs max_block_size ({part})\n"
                     f"solid: strata, dotted: CHOLMOD same permutation", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        self.savefig(fig, f"block-size-sweep-{part.lower()}-{machine_slug(machine)}",
                     f"factorization time vs max_block_size, {part}",
                     "Table and plot: one run per block size, each the median of its repeats.",
                     mruns)

    # ---- 2. against other solvers

    def comparison(self, runs: list[Run]) -> None:
        self.w("## 2. Against other solvers")
        self.w()
        self.w("### Analysis: strata vs CHOLMOD with METIS")
        self.w()
        an = [r for r in runs if r.kind == "analysis" and r.tag == ""]
        if not an:
            self.w(f"{NOT_MEASURED}: no analysis results (run `bench/run cpu`).")
            self.w()
        for r in an:
            self.analysis_run(r)
        self.w("### Factorization: strata vs CHOLMOD and MUMPS (same permutation)")
        self.w()
        fa = [r for r in runs if r.kind == "factor" and r.tag == ""]
        cpu = [r for r in fa if r.backend == "cpu"]
        # bench_gpu runs of any tag (bench/run gpu splits them: "" and "large")
        gpu = [r for r in runs if r.kind == "factor" and r.backend != "cpu"
               and (r.tag == "" or is_bench_gpu(r))]
        if not cpu:
            self.w(f"{NOT_MEASURED}: no CPU factorization results (run `bench/run cpu`).")
            self.w()
        for r in cpu:
            self.factor_run(r)
        self.w("### GPU: strata's CUDA backend vs its CPU backend and CHOLMOD")
        self.w()
        if not gpu:
            self.w(f"{NOT_MEASURED}: no GPU factorization results "
                   f"(needs a lent GPU machine: `bench/run gpu`).")
            self.w()
        for r in gpu:
            if is_bench_gpu(r):
                self.gpu_vs_cpu_run(r)
            else:
                self.factor_run(r)
        self.gpu_profile_section(runs)
        self.cudss_section(runs)

    def analysis_run(self, r: Run) -> None:
        self.consumed.add(r.path)
        rows, nr, tr = [], [], []
        for row in r.rows:
            s, c = row.get("strata", {}), row.get("cholmod_metis", {})
            n_r, t_r = ratio(dig(s, "nnz_l"), dig(c, "nnz_l")), ratio(dig(s, "seconds"),
                                                                        dig(c, "seconds"))
            nr.append((row.get("problem"), n_r))
            tr.append((row.get("problem"), t_r))
            rows.append([str(row.get("problem")), f_int(row.get("n")), f_int(row.get("nnz_a")),
                         f_int(dig(s, "nnz_l")), f_int(dig(c, "nnz_l")), f_ratio(n_r),
                         f_g(dig(s, "flops")), f_g(dig(c, "flops")), f_sec(dig(s, "seconds")),
                         f_sec(dig(c, "seconds")), f_ratio(t_r)])
        rows.append(["**geometric mean**"] + [""] * 4 + [f_ratio(geomean([x for _, x in nr]))]
                    + [""] * 4 + [f_ratio(geomean([x for _, x in tr]))])
        self.w(f"On {machine_label(r.machine)}. nnz(L) and flops as each analysis predicts "
               f"them; time: median of the run's repeats, in seconds. Ratios are strata / "
               f"CHOLMOD.")
        self.w()
        self.w(table(["problem", "n", "nnz(A)", "nnz(L) strata", "nnz(L) CHOLMOD",
                      "nnz(L) ratio", "flops strata", "flops CHOLMOD", "time strata",
                      "time CHOLMOD", "time ratio"], rows))
        rss = num(r.get("peak_rss_bytes"))
        if rss is not None:
            self.w(f"Peak resident memory of the whole run (both solvers, all problems): "
                   f"{rss / 2**20:.1f} MiB.")
            self.w()
        fig, axes = self.plt.subplots(1, 2, figsize=(10, 4.2))
        for ax, data, title in ((axes[0], nr, "nnz(L) strata / CHOLMOD+METIS"),
                                (axes[1], tr, "analysis time strata / CHOLMOD+METIS")):
            pts = [(p, x) for p, x in data if x is not None]
            ax.bar(range(len(pts)), [x for _, x in pts],
                   color=["tab:red" if x > 1 else "tab:green" for _, x in pts])
            ax.axhline(1.0, color="black", lw=0.8)
            ax.set_xticks(range(len(pts)))
            ax.set_xticklabels([p for p, _ in pts], rotation=45, ha="right", fontsize=8)
            ax.set_title(title + " (lower is better)", fontsize=10)
            ax.grid(True, axis="y", alpha=0.3)
        self.savefig(fig, f"analysis-vs-cholmod-{r.backend}-{machine_slug(r.machine)}",
                     "analysis ratios strata / CHOLMOD+METIS",
                     "Table and plot: ratios computed by this generator from the rows.", [r])

    def factor_run(self, r: Run) -> None:
        self.consumed.add(r.path)
        anchors = [(k, n) for k, n in (("cholmod", "CHOLMOD"), ("mumps", "MUMPS"),
                                       ("cudss", "cuDSS"))
                   if any(isinstance(row.get(k), dict) for row in r.rows)]
        header = ["problem", "n", "nnz(L)", "flops", "strata s", "GFLOP/s"]
        header += [f"{n} s" for _, n in anchors] + [f"strata/{n}" for _, n in anchors]
        header += ["berr strata"] + [f"berr {n}" for _, n in anchors] + ["refinement steps"]
        memory = any(num(dig(row, "strata", "peak_rss_bytes")) is not None for row in r.rows)
        if memory:
            header += ["peak RSS strata MB", "peak RSS strata/CHOLMOD",
                       "above input strata/CHOLMOD", "RSS / reported peak"]
        rows, ratios = [], {k: [] for k, _ in anchors}
        rss_ratios = []
        for row in r.rows:
            s = row.get("strata", {})
            line = [str(row.get("problem")), f_int(row.get("n")), f_int(row.get("nnz_l")),
                    f_g(row.get("factor_flops")), f_sec(s.get("seconds")), f_g(s.get("gflops"))]
            for k, _ in anchors:
                a = row.get(k)
                failed = isinstance(a, dict) and a.get("ok") is False
                line.append("failed" if failed else f_sec(dig(a, "seconds")))
            for k, _ in anchors:
                x = self.factor_ratio(row, k)
                ratios[k].append((row.get("problem"), x))
                line.append(f_ratio(x))
            line.append(f_e(s.get("backward_error")))
            line += [f_e(dig(row.get(k), "backward_error")) for k, _ in anchors]
            line.append(f_int(s.get("refinement_steps")))
            if memory:
                rss = num(s.get("peak_rss_bytes"))
                x = ratio(rss, dig(row, "cholmod", "peak_rss_bytes"))
                rss_ratios.append((row.get("problem"), x))
                line += [f_g(rss * 1e-6) if rss is not None else "–", f_ratio(x),
                         f_ratio(ratio(s.get("rss_above_input_bytes"),
                                       dig(row, "cholmod", "rss_above_input_bytes"))),
                         f_ratio(ratio(rss, s.get("reported_peak_bytes")))]
            rows.append(line)
        gm = ["**geometric mean**"] + [""] * (5 + len(anchors))
        gm += [f_ratio(geomean([x for _, x in ratios[k]])) for k, _ in anchors]
        gm += [""] * (2 + len(anchors))
        if memory:
            gm += ["", f_ratio(geomean([x for _, x in rss_ratios])), "", ""]
        rows.append(gm)
        threads = r.get("threads")
        mbs = r.get("max_block_size")
        self.w(f"On {machine_label(r.machine)}, backend {r.backend}"
               + (f", {threads} threads for every solver" if threads is not None else "")
               + (f", strata max_block_size {mbs}" if mbs is not None else "")
               + ". Times: median of the run's refactorizations, in seconds; nnz(L) and "
               "flops are strata's; berr is the backward error ‖b−Ax‖∞/(‖A‖∞‖x‖∞+‖b‖∞) of "
               "each solver's solution of A x = A·1 (strata with iterative refinement)."
               + (" Peak RSS: the peak resident set of each solver's analysis and first "
                  "factorization, each in a fresh process with the same input ('above "
                  "input': the peak less what the process held with the input loaded); "
                  "'reported peak' is what the analysis says its own arrays and a CPU "
                  "factorization hold (analysis_bytes + cpu_factorization_bytes; results "
                  "written before analysis_bytes existed count the factorization only) plus "
                  "that input."
                  if memory else ""))
        self.w()
        self.w(table(header, rows))
        chol_nnz = [(row.get("problem"), ratio(row.get("nnz_l"), dig(row, "cholmod", "nnz_l")))
                    for row in r.rows]
        if any(x is not None for _, x in chol_nnz):
            self.w("nnz(L) strata / CHOLMOD with the same permutation (relaxed amalgamation "
                   "adds explicit zeros in both): "
                   + ", ".join(f"{p} {f_ratio(x)}" for p, x in chol_nnz if x is not None) + ".")
            self.w()
        missing = []
        if not any(num(dig(row, "strata", "solve_seconds")) is not None for row in r.rows):
            missing.append("solve time")
        if not any(num(dig(row, "strata", "total_seconds")) is not None for row in r.rows):
            missing.append("total (analysis + factorization + solve) time")
        if not memory:
            missing.append("memory")
        if missing:
            self.w(f"{NOT_MEASURED} in this run: " + ", ".join(missing)
                   + " (the driver does not record them).")
            self.w()
        fig, ax = self.plt.subplots(figsize=(max(6, 1.1 * len(r.rows) + 2), 4.5))
        series = [("strata", lambda row: dig(row, "strata", "seconds"))]
        series += [(n, (lambda k: lambda row: None if self.factor_ratio(row, k) is None
                        else dig(row, k, "seconds"))(k)) for k, n in anchors]
        width = 0.8 / len(series)
        for i, (label, get) in enumerate(series):
            xs, ys = [], []
            for j, row in enumerate(r.rows):
                y = num(get(row))
                if y is not None and y > 0:
                    xs.append(j + (i - (len(series) - 1) / 2) * width)
                    ys.append(y)
            ax.bar(xs, ys, width, label=label)
        ax.set_yscale("log")
        ax.set_xticks(range(len(r.rows)))
        ax.set_xticklabels([str(row.get("problem")) for row in r.rows], rotation=45,
                           ha="right", fontsize=8)
        ax.set_ylabel("factorization time [s]")
        ax.set_title("factorization time, same permutation (lower is better)", fontsize=10)
        ax.grid(True, axis="y", which="both", alpha=0.3)
        ax.legend(fontsize=8)
        self.savefig(fig, f"factor-vs-anchors-{r.backend}-{machine_slug(r.machine)}",
                     "factorization time per problem and solver",
                     "Table and plot: ratios computed by this generator from the rows.", [r])

    # ---- 3-5 and the rest

    def simple_section(self, runs, title, kind, what, need) -> None:
        self.w(f"## {title}")
        self.w()
        self.w(f"Measures {what}.")
        self.w()
        chosen = [r for r in runs if r.kind == kind]
        if not chosen:
            self.w(f"{NOT_MEASURED}: no `{kind}` results in the results folder; {need}.")
            self.w()
            return
        for r in chosen:
            self.generic_run(r)

    def python_section(self, runs: list[Run]) -> None:
        self.w("## Python interface: overhead, scipy and CHOLMOD")
        self.w()
        self.w("Measures the cost of the Python layer (strata.Solver + solve against `strata "
               "solve` on the same matrix; goal: under 5% on the large one) and a complete "
               "solve from Python (analysis, factorization, one right-hand side) by strata, "
               "scipy's spsolve (SuperLU) and scikit-sparse's CHOLMOD on SPD matrices.")
        self.w()
        chosen = [r for r in runs if r.kind == "python" and not r.tag]
        if not chosen:
            self.w(f"{NOT_MEASURED}: no `python` results in the results folder; run "
                   "`PYTHONPATH=build/python /usr/bin/python3 bench/python_vs_scipy.py`.")
            self.w()
            return
        for r in chosen:
            self.consumed.add(r.path)
            self.python_run(r)

    def python_run(self, r: Run) -> None:
        over = [row for row in r.rows if row.get("part") == "overhead"]
        goal = num(r.get("overhead_goal_percent"))
        if over:
            self.w(f"### Python layer vs the command line ({machine_label(r.machine)})")
            self.w()
            rows = []
            for row in over:
                rows.append([str(row.get("problem")), str(row.get("size", "")),
                             f_int(row.get("n")), f_sec(dig(row, "cli", "total_seconds")),
                             f_sec(dig(row, "python", "total_seconds")),
                             f_pct(row.get("overhead_vs_cli_percent")),
                             f_pct(row.get("overhead_vs_cli_median_percent")),
                             f_pct(row.get("outside_phases_percent")),
                             f_sec(dig(row, "python", "full_storage_total_seconds"))])
            self.w(table(["problem", "size", "n", "CLI s", "Python s", "Python vs CLI",
                          "same, medians", "outside the C++ phases",
                          "Python, full storage s"], rows, 2))
            large = [row for row in over if row.get("size") == "large"]
            if goal is not None and large:
                for row in large:
                    o = num(row.get("overhead_vs_cli_percent"))
                    if o is None:
                        continue
                    verdict = "met" if o < goal else "**not met**"
                    self.w(f"Goal (Python layer under {goal:g}% on the large matrix, "
                           f"{row.get('problem')}): {verdict} ({f_pct(o)} against the "
                           f"command line, {f_pct(row.get('outside_phases_percent'))} outside "
                           f"the C++ phases of the same call).")
                    self.w()
            load = r.get("load_average")
            if isinstance(load, dict) and num(load.get("start")) is not None:
                self.w(f"Load average of the machine (1 minute) at the start and end of the "
                       f"run: {num(load['start']):.1f} and {num(load.get('end')) or 0:.1f} on "
                       f"{r.machine[1]} hardware threads: other work on the machine makes the "
                       f"two processes' times differ by chance; the column \"outside the C++ "
                       f"phases\" (Python time over the phase times strata reports in the same "
                       f"call) does not depend on that.")
                self.w()
            self.caption("Table: copied from the rows (CLI and Python: analysis + "
                         "factorization + one solve, best of the repeats, and the ratio of "
                         "the medians; percentages as stored).", [r])
        solv = [row for row in r.rows if row.get("part") == "solvers"]
        if solv:
            self.w(f"### strata, SuperLU and CHOLMOD from Python ({machine_label(r.machine)})")
            self.w()
            keys = [("strata", "strata"), ("scipy_spsolve", "SuperLU (MMD on A+Aᵀ)"),
                    ("scipy_spsolve_colamd", "SuperLU (COLAMD)"), ("cholmod", "CHOLMOD")]

            def cell(row, k):
                d = row.get(k) or {}
                if "seconds" in d:
                    return f"{f_sec(d['seconds'])} ({f_e(d.get('backward_error'))})"
                return str(d.get("status", "–")).split(" (")[0]

            rows, ratios_lu, ratios_ch = [], [], []
            for row in solv:
                r_lu = ratio(dig(row, "strata", "seconds"), dig(row, "scipy_spsolve", "seconds"))
                r_ch = ratio(dig(row, "strata", "seconds"), dig(row, "cholmod", "seconds"))
                ratios_lu.append(r_lu)
                ratios_ch.append(r_ch)
                rows.append([str(row.get("problem")), f_int(row.get("n"))]
                            + [cell(row, k) for k, _ in keys] + [f_ratio(r_lu), f_ratio(r_ch)])
            rows.append(["**geometric mean**", ""] + [""] * len(keys)
                        + [f_ratio(geomean(ratios_lu)), f_ratio(geomean(ratios_ch))])
            probs = [row.get("problem") for row in solv]
            self.key_ratio("solve from Python, strata / scipy's SuperLU", geomean(ratios_lu),
                           list(zip(probs, ratios_lu)), r)
            self.key_ratio("solve from Python, strata / CHOLMOD (scikit-sparse)",
                           geomean(ratios_ch), list(zip(probs, ratios_ch)), r)
            self.w(table(["problem", "n"] + [f"{n} s (backward error)" for _, n in keys]
                         + ["strata/SuperLU", "strata/CHOLMOD"], rows))
            missing = sorted({str(dig(row, "cholmod", "status")) for row in solv
                              if dig(row, "cholmod", "status")})
            if missing:
                self.w(f"CHOLMOD: {', '.join(missing)} (scikit-sparse; scripts/setup.sh "
                       f"tries to install it with pip).")
                self.w()
            self.caption("Table: times and backward errors copied from the rows; ratios "
                         "(time of strata / time of the other solver, below 1: strata is "
                         "faster) and their geometric means computed by this generator.", [r])

    def others(self, runs: list[Run]) -> None:
        rest = [r for r in runs if r.path not in self.consumed]
        if not rest:
            return
        self.w("## Other results")
        self.w()
        self.w("Results that none of the sections above shows (other kinds or tags), as "
               "stored; this generator has no plot for them.")
        self.w()
        for r in rest:
            self.w(f"### `{r.kind}`" + (f", tag `{r.tag}`" if r.tag else "")
                   + f", backend {r.backend}")
            self.w()
            self.generic_run(r)

    def generic_run(self, r: Run) -> None:
        self.consumed.add(r.path)

        def flat(d, prefix=""):
            out = {}
            for k, v in d.items():
                if isinstance(v, dict):
                    out.update(flat(v, f"{prefix}{k}."))
                elif isinstance(v, (str, int, float, bool)) or v is None:
                    out[prefix + k] = v
            return out

        rows = [flat(row) for row in r.rows if isinstance(row, dict)]
        cols: list[str] = ["problem"] if any("problem" in row for row in rows) else []
        for row in rows:
            cols += [k for k in row if k not in cols]

        def fmt(v):
            if isinstance(v, bool) or v is None or isinstance(v, str):
                return "–" if v is None else str(v).replace("|", "\\|")
            return f"{v:.6g}" if isinstance(v, float) else str(v)

        if rows:
            self.w(table(cols, [[fmt(row.get(c)) for c in cols] for row in rows]))
        else:
            self.w("The run holds no rows.")
            self.w()
        self.caption("Table: the rows as stored.", [r])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--results", default=os.path.join(REPO, "bench", "results"),
                    help="folder of results files (default: bench/results)")
    ap.add_argument("--out", default=os.path.join(REPO, "bench"),
                    help="folder to write REPORT.md and plots/ into (default: bench)")
    ap.add_argument("--readme", default=None,
                    help="README whose performance table to rewrite (between its marker "
                         "lines); default: the repository's README.md when --out is the "
                         "default, else none")
    ap.add_argument("--history", default=os.path.join(REPO, "bench", "history.md"),
                    help="hand-written notes copied to the end of REPORT.md "
                         "(default: bench/history.md)")
    args = ap.parse_args(argv)
    default_out = os.path.abspath(args.out) == os.path.join(REPO, "bench")
    readme = args.readme or (os.path.join(REPO, "README.md") if default_out else None)
    try:
        rep = Report(args.results, args.out, args.history)
    except ImportError:
        print("report.py: matplotlib is missing; run scripts/setup.sh (Debian "
              "python3-matplotlib, importable by /usr/bin/python3)", file=sys.stderr)
        return 2
    os.makedirs(args.out, exist_ok=True)
    # The plots folder belongs to the generator: stale plots of earlier runs go.
    if os.path.isdir(rep.plot_dir):
        for name in os.listdir(rep.plot_dir):
            if name.endswith(".png"):
                os.remove(os.path.join(rep.plot_dir, name))
    text = rep.build()
    path = os.path.join(args.out, "REPORT.md")
    tmp = path + ".tmp"
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
    os.replace(tmp, path)
    print(f"report: {path} ({len(rep.used)} results files, {len(rep.plots)} plots)")
    if readme:
        block = readme_table(rep.key_ratios, os.path.dirname(os.path.abspath(readme)))
        err = update_readme(readme, block)
        if err:
            print(f"report.py: {err}", file=sys.stderr)
            return 1
        print(f"report: performance table of {readme} ({len(rep.key_ratios)} ratios)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
