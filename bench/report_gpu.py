"""GPU sections of the strata benchmark report (used by bench/report.py).

What each results kind holds and how it becomes a section:
  gpu_memory  bench/bench_gpu_memory.cpp: "device_figures" (pinned host<->device bandwidth,
              cuBLAS DGEMM rate), "solvability" (per problem the factorization in core and
              under a device budget of factor bytes / ratio) -> experiment 4; "block_size"
              (in-core GPU factorization per max_block_size) -> experiment 1, GPU part.
  factor, backend cuda, rows with "strata_gpu"  bench/bench_gpu.cpp: the CUDA backend
              against the CPU backend and CHOLMOD -> experiment 2, GPU vs CPU.
  cudss       bench/bench_cudss.cpp: strata's CUDA backend against NVIDIA cuDSS (default
              reordering, and strata's permutation) -> experiment 2, GPU part.
  multigpu    bench/bench_multigpu.cpp: factorization with 1, 2, 4 workers and the
              ablation -> experiment 3 (backend cuda only; backend cpu is shown apart).
  simulate    a JSON of that kind if a driver ever writes one; otherwise the newest
              bench/results/logs/*mbd*.log written by scripts/gpu/run_mbd.sh (the text
              summary `strata simulate` prints) -> experiment 5.
Every number is copied from those files or computed from them (ratios, rates, geometric
means), as the captions say.
"""
from __future__ import annotations

from report_common import (NOT_MEASURED, Run, dig, f_e, f_g, f_int, f_ratio,
                           f_sec, geomean, machine_label, machine_slug, num, ratio, table)

# Problems with at least this many entries in L count as "large" for the cuDSS target
# (the issue names no size; this is the generator's choice and the report says so).
LARGE_NNZ_L = 5e7
PEAK_TARGET = 0.40  # the target: at least 40% of the DGEMM peak
DEFAULT_BLOCK = 1024  # the CPU's (and LU's, LDLᵀ's) block size, chosen from the CPU sweep
# Options::max_block_size 0 (the default since 7be8df6) is 4096 for Cholesky on the GPU
GPU_CHOLESKY_BLOCK = 4096


def is_bench_gpu(r: Run) -> bool:
    """A bench_gpu run (CUDA backend vs CPU backend and CHOLMOD)."""
    return r.kind == "factor" and any(isinstance(row.get("strata_gpu"), dict) for row in r.rows)


def ratio_label(x) -> str:
    x = num(x)
    return "in-core" if not x else f"{x:g}×"


class GpuSections:
    """Mixin of Report: the sections fed by the GPU drivers."""

    # ---- shared look-ups

    def device_figures(self, machine: tuple) -> tuple[dict | None, Run | None]:
        """The newest gpu_memory device figures measured on the same GPU model."""
        best = None
        for r in self.all_runs:
            if r.kind == "gpu_memory" and r.machine[2] == machine[2] and machine[2]:
                if isinstance(r.get("device_figures"), dict):
                    if best is None or (r.date, r.name) > (best.date, best.name):
                        best = r
        return (best.get("device_figures"), best) if best else (None, None)

    def flops_for(self, problem: str, nnz_l) -> tuple[float | None, Run | None]:
        """strata's factor flop count for (problem, nnz(L)) from any results file whose
        row has the same problem and the same nnz(L) (so the same analysis)."""
        nnz_l = num(nnz_l)
        if nnz_l is None:
            return None, None
        for r in sorted(self.all_runs, key=lambda r: (r.date, r.name), reverse=True):
            for row in r.rows:
                if not isinstance(row, dict) or row.get("problem") != problem:
                    continue
                for nz, fl in ((row.get("nnz_l"), row.get("factor_flops")),
                               (row.get("nnz_l"), row.get("flops")),
                               (dig(row, "strata", "nnz_l"), dig(row, "strata", "flops"))):
                    if num(nz) == nnz_l and num(fl) is not None:
                        return num(fl), r
        return None, None

    # ---- experiment 1, GPU part

    def gpu_block_sweep(self, r: Run) -> None:
        self.consumed.add(r.path)
        probs = [p for p in r.get("block_size") or [] if isinstance(p, dict)]
        sizes = sorted({int(num(x.get("max_block_size")))
                        for p in probs for x in p.get("runs", [])
                        if num(x.get("max_block_size")) is not None})
        rows, verdicts = [], []
        for p in probs:
            t = {int(num(x["max_block_size"])): num(x.get("factor_seconds"))
                 for x in p.get("runs", []) if num(x.get("max_block_size")) is not None}
            g = {int(num(x["max_block_size"])): num(x.get("gflops")) for x in p.get("runs", [])
                 if num(x.get("max_block_size")) is not None}
            known = {b: v for b, v in t.items() if v is not None}
            best = min(known, key=known.get) if known else None
            d_over_b = ratio(known.get(DEFAULT_BLOCK), known.get(best)) if best else None
            rows.append([str(p.get("problem")), f_int(p.get("n"))]
                        + [f_sec(t.get(b)) for b in sizes]
                        + [str(best) if best else "–", f_g(g.get(best)) if best else "–",
                           f_ratio(d_over_b)])
            if best is not None:
                verdicts.append((p.get("problem"), best, d_over_b))
        self.w(f"In-core factorization on the GPU ({machine_label(r.machine)}), seconds "
               f"(median of the run's repeats) per `max_block_size`; *best* is the fastest "
               f"block size, *GFLOP/s* its rate as the driver stores it, *{DEFAULT_BLOCK}/best* "
               f"the time at the default block size over the best time.")
        self.w()
        self.w(table(["problem", "n"] + [str(b) for b in sizes]
                     + ["best", "GFLOP/s at best", f"{DEFAULT_BLOCK}/best"], rows, 1))
        if verdicts:
            bests = sorted({b for _, b, _ in verdicts})
            self.w("Best block size on the GPU: "
                   + ", ".join(f"{p} {b}" for p, b, _ in verdicts) + ". "
                   + (f"The largest block size tried ({max(sizes)}) is best on "
                      f"{sum(1 for _, b, _ in verdicts if b == max(sizes))} of "
                      f"{len(verdicts)} problems. " if sizes else "")
                   + f"Block size {DEFAULT_BLOCK} (the CPU's default) costs "
                   + ", ".join(f"{p} {f_ratio(x)}×" for p, _, x in verdicts if x is not None)
                   + f" of the best time; since 7be8df6 the default (max_block_size 0) is "
                   f"{GPU_CHOLESKY_BLOCK} for Cholesky on the GPU and {DEFAULT_BLOCK} otherwise "
                   f"(include/strata/options.hpp). Size 0 in a table is that default.")
            self.w()
        if not r.get("solvability"):  # its own section shows a solvability run's figures
            self.device_table(r)
        fig, ax = self.plt.subplots(figsize=(7, 4.5))
        for p in probs:
            pts = [(num(x.get("max_block_size")), num(x.get("factor_seconds")))
                   for x in p.get("runs", [])]
            pts = sorted((b, v) for b, v in pts if b is not None and v is not None)
            if pts:
                ax.plot([b for b, _ in pts], [v for _, v in pts], "o-", label=p.get("problem"))
        ax.axvline(DEFAULT_BLOCK, color="grey", ls="--", lw=0.8, label=f"default {DEFAULT_BLOCK}")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        if sizes:
            ax.set_xticks(sizes)
            ax.set_xticklabels([str(b) for b in sizes])
        ax.set_xlabel("max_block_size")
        ax.set_ylabel("factorization time [s]")
        ax.set_title("strata GPU factorization time vs max_block_size (in core)", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8)
        self.savefig(fig, f"block-size-sweep-gpu-{machine_slug(r.machine)}",
                     "GPU factorization time vs max_block_size",
                     "Table and plot: copied from the run's `block_size` rows; ratios computed "
                     "by this generator.", [r])

    # ---- experiment 2: bench_gpu (GPU vs CPU)

    def gpu_vs_cpu_run(self, r: Run) -> None:
        self.consumed.add(r.path)
        rows, counts = [], set()
        new_solve = any(num(dig(row, "strata_gpu", "first_solve_seconds")) is not None
                        for row in r.rows)
        for row in r.rows:
            g = row.get("strata_gpu") or {}
            cpu = [c for c in row.get("cpu", []) if isinstance(c, dict)]
            counts.update(int(num(c.get("threads"))) for c in cpu
                          if num(c.get("threads")) is not None)
            chol = [(num(c.get("cholmod_seconds")), c.get("threads")) for c in cpu]
            chol = min([c for c in chol if c[0] is not None], default=(None, None))
            best = num(row.get("best_cpu_seconds"))
            line = [str(row.get("problem")), str(row.get("type", "")), f_int(row.get("n")),
                    f_int(row.get("nnz_l")), f_g(row.get("factor_flops")),
                    f_sec(g.get("seconds")), f_g(g.get("gflops")),
                    f_sec(best) + (f" ({row.get('best_cpu_threads')} thr.)"
                                   if row.get("best_cpu_threads") else ""),
                    f_sec(chol[0]) + (f" ({chol[1]} thr.)" if chol[1] is not None and
                                      chol[0] is not None else ""),
                    f_ratio(ratio(best, g.get("seconds"))),
                    f_ratio(ratio(chol[0], g.get("seconds")))]
            if new_solve:
                line += [f_sec(g.get("first_solve_seconds")), f_sec(g.get("solve_seconds")),
                         f_int(g.get("refinement_steps"))]
            line.append(f_e(g.get("backward_error")))
            rows.append(line)
        tag = f" (tag `{r.tag}`)" if r.tag else ""
        self.w(f"strata's CUDA backend against its CPU backend and CHOLMOD (same permutation) "
               f"on {machine_label(r.machine)}{tag}. Seconds: median of the run's "
               f"refactorizations; *CPU/GPU* is the best CPU time over the GPU time (above 1: "
               f"the GPU is faster; below 1: **the GPU is slower**). "
               + (f"CPU thread counts measured: {', '.join(str(c) for c in sorted(counts))}; "
                  f"each CPU column is the best of them (the count in brackets)"
                  f" — more threads are not always faster, notably for CHOLMOD's OpenBLAS. "
                  if counts else "")
               + ("*first solve*: one application of the factor (no refinement); *solve*: "
                  "the full solve with iterative refinement. " if new_solve else "")
               + (str(r.get("note")) if r.get("note") else ""))
        self.w()
        if r.get("partial"):
            self.w("**This run was cut off** (the driver's partial file): only the problems "
                   "below were measured.")
            self.w()
        self.w(table(["problem", "type", "n", "nnz(L)", "flops", "GPU s", "GPU GFLOP/s",
                      "best CPU s", "CHOLMOD s", "CPU/GPU", "CHOLMOD/GPU"]
                     + (["first solve s", "solve s", "refinement steps"] if new_solve else [])
                     + ["berr GPU"], rows, 2))
        slower = [(str(row.get("problem")), x) for row in r.rows
                  for x in [ratio(row.get("best_cpu_seconds"), dig(row, "strata_gpu", "seconds"))]
                  if x is not None and x < 1]
        if slower:
            self.behind_notes.append(
                f"strata's GPU backend slower than its CPU backend on {machine_label(r.machine)}: "
                + ", ".join(f"{p} (CPU/GPU {f_ratio(x)})" for p, x in slower))
            self.w("**The GPU is slower than the CPU backend** on "
                   + ", ".join(f"{p} (CPU/GPU {f_ratio(x)})" for p, x in slower) + ".")
            self.w()
        self.caption("Table: copied from the rows (`strata_gpu`, `cpu`); ratios computed by "
                     "this generator.", [r])
        self.phase_table(r, [(str(row.get("problem")), dig(row, "strata_gpu", "last_refactor"),
                              None) for row in r.rows], "bench_gpu")

    # ---- where the GPU refactorization time goes (last_refactor.phases)

    PHASES = (("assembly", "assembly"), ("small_fronts", "small fronts"),
              ("large_fronts", "large fronts"), ("tiled_fronts", "tiled fronts"),
              ("store", "store"), ("host", "host"))

    def phase_table(self, r: Run, items, what: str) -> None:
        """items: (problem, last_refactor dict or None, cuDSS refactor seconds or None).
        Writes nothing when no item has phases (results files of older drivers)."""
        items = [(p, lr, c) for p, lr, c in items
                 if isinstance(lr, dict) and isinstance(lr.get("phases"), dict)]
        if not items:
            return
        anchor = any(c is not None for _, _, c in items)
        rows, behind = [], []
        for p, lr, c in items:
            ph = lr["phases"]
            tot = num(lr.get("seconds"))
            vals = [(k, num(ph.get(k))) for k, _ in self.PHASES]
            cells = []
            for _, v in vals:
                share = ratio(v, tot)
                cells.append("–" if v is None else f_sec(v) + (f" ({share:.0%})"
                                                               if share is not None else ""))
            known = [(k, v) for k, v in vals if v is not None]
            big = max(known, key=lambda t: t[1]) if known else None
            line = [p, f_sec(tot), f_sec(lr.get("device_seconds"))] + cells
            line.append(f_sec(sum(v for _, v in known)) if known else "–")
            line.append(dict(self.PHASES)[big[0]] if big else "–")
            line += [f_g(lr.get("gflops")),
                     f_g(num(lr.get("bytes_to_device")) and lr["bytes_to_device"] / 1e6),
                     f_int(lr.get("device_batches")), f_int(lr.get("tiled_fronts"))]
            if anchor:
                line += [f_sec(c), f_ratio(ratio(tot, c)),
                         f_ratio(ratio(big[1], c)) if big else "–"]
                if big and c and ratio(tot, c) and ratio(tot, c) > 1:
                    behind.append((p, tot / c, dict(self.PHASES)[big[0]], big[1], c,
                                   [(dict(self.PHASES)[k], v) for k, v in known if v > c]))
            rows.append(line)
        self.w(f"Where strata's GPU refactorization time goes ({what}, "
               f"{machine_label(r.machine)}): the phases of the **last** refactorization of "
               f"the run as the driver stores them (`last_refactor.phases`, GPU time per "
               f"phase in seconds; in brackets the share of that refactorization's time)"
               + ("; beside it cuDSS's refactorization (default reordering, median)"
                  if anchor else "") + ".")
        self.w()
        self.w(table(["problem", "last refactor s", "device s"] + [n for _, n in self.PHASES]
                     + ["sum of phases", "largest phase", "GFLOP/s", "MB to device",
                        "batches", "fronts tiled (count)"]
                     + (["cuDSS refactor s", "strata/cuDSS", "largest phase/cuDSS"]
                        if anchor else []), rows, 1))
        for p, x, name, v, c, over in behind:
            self.w(f"{p}: strata's last refactorization is **{x:.2f}× cuDSS's**; its largest "
                   f"phase, {name}, takes {f_sec(v)} s"
                   + (f" — {', '.join(f'{n} ({f_sec(t)} s)' for n, t in over)} alone "
                      f"{'takes' if len(over) == 1 else 'take'} longer than cuDSS's whole "
                      f"refactorization ({f_sec(c)} s)" if over else
                      f" (cuDSS's whole refactorization: {f_sec(c)} s)") + ".")
            self.w()
        fig, ax = self.plt.subplots(figsize=(max(6, 1.3 * len(items) + 3), 4.5))
        bottom = [0.0] * len(items)
        w = 0.4 if anchor else 0.6
        xs = [i - (w / 2 if anchor else 0) for i in range(len(items))]
        for k, name in self.PHASES:
            ys = [num(lr["phases"].get(k)) or 0.0 for _, lr, _ in items]
            if any(ys):
                ax.bar(xs, ys, w, bottom=bottom, label=f"strata: {name}")
                bottom = [b + y for b, y in zip(bottom, ys)]
        if anchor:
            ax.bar([i + w / 2 for i in range(len(items))], [c or 0 for _, _, c in items], w,
                   color="black", alpha=0.6, label="cuDSS refactorization")
        ax.set_xticks(range(len(items)))
        ax.set_xticklabels([p for p, _, _ in items], rotation=30, ha="right", fontsize=8)
        ax.set_ylabel("seconds")
        ax.set_title("GPU refactorization by phase (last refactorization; lower is better)",
                     fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(fontsize=7)
        self.savefig(fig, f"gpu-phases-{what.replace('_', '-')}-{r.tag or 'main'}-"
                     f"{machine_slug(r.machine)}", "GPU refactorization time by phase",
                     "Table and plot: phases copied from `last_refactor` of each row; shares "
                     "and ratios computed by this generator.", [r])

    def gpu_profile_section(self, runs: list[Run]) -> None:
        """bench_gpu --gpu-only (benchmark "gpu-profile"): only its phase table."""
        for r in [r for r in runs if r.kind == "gpu-profile"]:
            self.consumed.add(r.path)
            med = ", ".join(f"{row.get('problem')} {f_sec(dig(row, 'strata_gpu', 'seconds'))} s"
                            for row in r.rows)
            self.w(f"GPU-only profile (`bench_gpu --gpu-only`: no CPU columns), median "
                   f"refactorization: {med}.")
            self.w()
            self.phase_table(r, [(str(row.get("problem")),
                                  dig(row, "strata_gpu", "last_refactor"), None)
                                 for row in r.rows], "gpu_profile")

    # ---- experiment 2: cuDSS

    def cudss_section(self, runs: list[Run]) -> None:
        self.w("### GPU: strata vs NVIDIA cuDSS")
        self.w()
        chosen = [r for r in runs if r.kind == "cudss" and not r.get("solver_options")]
        if not chosen:
            self.w(f"{NOT_MEASURED}: no `cudss` results (bench_cudss on a lent GPU machine: "
                   f"`scripts/gpu/run.sh --cudss-bench ...`).")
            self.w()
        for r in chosen:
            self.cudss_run(r)
        self.cudss_option_runs([r for r in runs if r.kind == "cudss" and r.get("solver_options")])

    def cudss_option_runs(self, runs: list[Run]) -> None:
        """bench_cudss runs with strata options set (--solver-option): one line each."""
        if not runs:
            return
        self.w("#### strata options tried against cuDSS")
        self.w()
        self.w("Runs of `bench_cudss --solver-option NAME=VALUE`: refactorization time strata / "
               "the better of cuDSS's two orderings, per problem, one line per run.")
        self.w()
        problems = []
        for r in runs:
            for row in r.rows:
                if row.get("problem") not in problems:
                    problems.append(row.get("problem"))
        self.w("| options | machine | " + " | ".join(str(p) for p in problems) + " | file |")
        self.w("| --- | --- | " + " | ".join("---:" for _ in problems) + " | --- |")
        for r in sorted(runs, key=lambda r: (" ".join(r.get("solver_options")), r.date)):
            self.consumed.add(r.path)
            cells = []
            for p in problems:
                row = next((x for x in r.rows if x.get("problem") == p), None)
                best = None
                for k in ("cudss_default", "cudss_strata_perm"):
                    v = num(dig(row, k, "refactor_seconds")) if row else None
                    if v is not None and (best is None or v < best):
                        best = v
                cells.append(f_ratio(ratio(num(dig(row, "strata_gpu", "refactor_seconds")),
                                           best)) if row else "")
            self.w(f"| `{' '.join(r.get('solver_options'))}` | {machine_label(r.machine)} | "
                   + " | ".join(cells) + f" | [`{r.name}`]({self.rel(r.path)}) |")
        self.w()

    def cudss_run(self, r: Run) -> None:
        self.consumed.add(r.path)
        figs, fig_run = self.device_figures(r.machine)
        peak = num(dig(figs, "dgemm_flops_per_second"))
        keys = (("strata_gpu", "strata"), ("cudss_default", "cuDSS default"),
                ("cudss_strata_perm", "cuDSS strata perm."))

        def ok(row, k):
            d = row.get(k)
            return isinstance(d, dict) and d.get("ok") is not False and "error" not in d

        def sec(row, k, what):
            return num(dig(row, k, what)) if ok(row, k) else None

        times, ratios_rows, nnz_rows = [], [], []
        col = {c: [] for c in ("fd", "fp", "rd", "rp", "sd", "sp", "ad", "ap")}
        flop_src: set[str] = set()
        rates = []
        for row in r.rows:
            p = str(row.get("problem"))
            line = [p, str(row.get("type", "")), f_int(row.get("n"))]
            for what in ("analysis_seconds", "factor_seconds", "refactor_seconds",
                         "solve_seconds"):
                line += [f_sec(sec(row, k, what)) if ok(row, k) else "failed" for k, _ in keys]
            times.append(line)
            rl = [p]
            for c, what, k in (("fd", "factor_seconds", "cudss_default"),
                               ("fp", "factor_seconds", "cudss_strata_perm"),
                               ("rd", "refactor_seconds", "cudss_default"),
                               ("rp", "refactor_seconds", "cudss_strata_perm"),
                               ("sd", "solve_seconds", "cudss_default"),
                               ("sp", "solve_seconds", "cudss_strata_perm"),
                               ("ad", "analysis_seconds", "cudss_default"),
                               ("ap", "analysis_seconds", "cudss_strata_perm")):
                x = ratio(sec(row, "strata_gpu", what), sec(row, k, what))
                col[c].append((p, x))
                rl.append(f_ratio(x))
            ratios_rows.append(rl)
            flops = num(row.get("factor_flops"))
            src = "its own factor_flops" if flops is not None else None
            if flops is None:
                flops, fr = self.flops_for(p, row.get("nnz_l"))
                if fr is not None:
                    src = fr.name
                    self.used.add(fr.path)
            if flops is not None and row.get("type") == "general":
                flops *= 2  # LU: twice the Cholesky count of the same pattern (as bench_gpu)
            if src:
                flop_src.add(src)
            rf = sec(row, "strata_gpu", "refactor_seconds")
            rate = flops / rf if flops is not None and rf else None
            cd = sec(row, "cudss_default", "refactor_seconds")
            rate_c = flops / cd if flops is not None and cd else None
            rates.append((p, num(row.get("nnz_l")), rate))
            nnz_rows.append([p, f_int(row.get("nnz_l")),
                             f_int(dig(row, "cudss_default", "lu_nnz")),
                             f_int(dig(row, "cudss_strata_perm", "lu_nnz")),
                             f_ratio(ratio(row.get("nnz_l"), dig(row, "cudss_default", "lu_nnz"))),
                             f_e(dig(row, "strata_gpu", "backward_error")),
                             f_e(dig(row, "cudss_default", "backward_error")),
                             f_e(dig(row, "cudss_strata_perm", "backward_error")),
                             f_g(flops), f_g(rate * 1e-9) if rate else "–",
                             (f"{100 * rate / peak:.2f}%" if rate and peak else "–"),
                             f_g(rate_c * 1e-9) if rate_c else "–"])
        n_gm = ["**geometric mean**"] + [f_ratio(geomean([x for _, x in col[c]])) for c in col]
        ratios_rows.append(n_gm)
        version = r.get("cudss_version", "(version not recorded)")
        self.w(f"On {machine_label(r.machine)}, cuDSS {version}. strata: analysis, first factorization, median of the "
               f"refactorizations, one solve with refinement (CUDA backend). cuDSS, with its "
               f"default reordering (*default*) and with strata's permutation as "
               f"CUDSS_DATA_USER_PERM (*strata perm.*): analysis, factorization, median of "
               f"the REFACTORIZATION phase, solve. Seconds.")
        self.w()
        if r.get("note"):
            self.w(f"**Note on this run:** {r.get('note')}")
            self.w()
        hdr = ["problem", "type", "n"]
        for what in ("analysis", "factor", "refactor", "solve"):
            hdr += [f"{what} {n}" for _, n in keys]
        self.w(table(hdr, times, 2))
        self.w("Ratios strata / cuDSS (above 1: strata is slower; *def.*: cuDSS default "
               "reordering, *perm.*: cuDSS with strata's permutation):")
        self.w()
        self.w(table(["problem", "factor/def.", "factor/perm.", "refactor/def.",
                      "refactor/perm.", "solve/def.", "solve/perm.", "analysis/def.",
                      "analysis/perm."], ratios_rows))
        general = any(row.get("type") == "general" for row in r.rows)
        self.w("Fill and accuracy: strata's nnz(L) (of L alone, also for LU) against cuDSS's "
               "LU_NNZ" + ("; for the general (LU) problems LU_NNZ is about twice strata's "
                           "nnz(L), so it evidently counts L and U and that ratio is not like "
                           "for like" if general else "") + ". berr: "
               "‖b−Ax‖∞/(‖A‖∞‖x‖∞+‖b‖∞) for b = A·1. *GFLOP/s*: strata's factor flop count "
               "(LU: twice the Cholesky count of the pattern, as bench_gpu counts it) over "
               "the refactorization time; *cuDSS-equiv.* is the same flop count over cuDSS's "
               "default refactorization time (cuDSS's own count with its ordering differs).")
        self.w()
        self.w(table(["problem", "nnz(L) strata", "LU_NNZ def.", "LU_NNZ perm.",
                      "nnz(L)/LU_NNZ def.", "berr strata", "berr def.", "berr perm.",
                      "flops", "strata GFLOP/s", "% of DGEMM peak", "cuDSS-equiv. GFLOP/s"],
                     nnz_rows))
        srcs = sorted(flop_src)
        self.w("Flop counts from: " + (", ".join(s if s.startswith("its own") else f"`{s}`"
                                                for s in srcs) if srcs else
                                       "nowhere (not computable: no results file holds "
                                       "strata's flops for these analyses)")
               + " (a row of the same problem with the same nnz(L), i.e. the same analysis). "
               + (f"DGEMM peak: cuBLAS DGEMM n = {f_int(dig(figs, 'dgemm_n'))}, "
                  f"{peak * 1e-12:.1f} TFLOP/s, measured on the same GPU model in "
                  f"[`{fig_run.name}`]({self.rel(fig_run.path)})." if peak else
                  "DGEMM peak: not measured on this GPU model (no gpu_memory results), so the "
                  "fraction of peak is not computable."))
        self.w()
        if fig_run is not None:
            self.used.add(fig_run.path)
        solve = self.cudss_solve(r, sec)
        self.cudss_targets(r, col, rates, peak, solve)
        self.cudss_plot(r, keys)
        self.phase_table(r, [(str(row.get("problem")), dig(row, "strata_gpu", "last_refactor"),
                              sec(row, "cudss_default", "refactor_seconds"))
                             for row in r.rows], "bench_cudss")

    def cudss_solve(self, r: Run, sec) -> list:
        """The solve comparison: strata's first application of the factor (no refinement,
        like cuDSS's SOLVE phase) and its full solve with refinement, against cuDSS's solve.
        Returns [(problem, first/def., full/def.)]; [] for runs without first_solve_seconds."""
        if not any(num(dig(row, "strata_gpu", "first_solve_seconds")) is not None
                   for row in r.rows):
            return []
        rows, out = [], []
        for row in r.rows:
            p = str(row.get("problem"))
            first = sec(row, "strata_gpu", "first_solve_seconds")
            full = sec(row, "strata_gpu", "solve_seconds")
            d, q = sec(row, "cudss_default", "solve_seconds"), sec(row, "cudss_strata_perm",
                                                                  "solve_seconds")
            out.append((p, ratio(first, d), ratio(full, d)))
            rows.append([p, f_sec(first), f_sec(full),
                         f_int(dig(row, "strata_gpu", "refinement_steps")), f_sec(d), f_sec(q),
                         f_ratio(ratio(first, d)), f_ratio(ratio(first, q)),
                         f_ratio(ratio(full, d)), f_ratio(ratio(full, q))])
        rows.append(["**geometric mean**", "", "", "", "", ""]
                    + [f_ratio(geomean([x for x in col if x is not None]))
                       for col in zip(*[(ratio(sec(row, "strata_gpu", "first_solve_seconds"),
                                              sec(row, "cudss_default", "solve_seconds")),
                                        ratio(sec(row, "strata_gpu", "first_solve_seconds"),
                                              sec(row, "cudss_strata_perm", "solve_seconds")),
                                        ratio(sec(row, "strata_gpu", "solve_seconds"),
                                              sec(row, "cudss_default", "solve_seconds")),
                                        ratio(sec(row, "strata_gpu", "solve_seconds"),
                                              sec(row, "cudss_strata_perm", "solve_seconds")))
                                       for row in r.rows])])
        self.w("Solve, like for like: strata's *first solve* is one application of the factor "
               "(forward and backward substitution, no refinement: what cuDSS's SOLVE phase "
               "does); strata's *full solve* adds iterative refinement (its steps counted) and "
               "is what `Solver::solve` returns. cuDSS: its SOLVE phase. Seconds; ratios "
               "strata / cuDSS (above 1: strata is slower).")
        self.w()
        self.w(table(["problem", "strata first solve s", "strata full solve s",
                      "refinement steps", "cuDSS def. solve s", "cuDSS perm. solve s",
                      "first/def.", "first/perm.", "full/def.", "full/perm."], rows, 1))
        return out

    def cudss_targets(self, r, col, rates, peak, solve=()) -> None:
        rd = [(p, x) for p, x in col["rd"] if x is not None]
        rp = [(p, x) for p, x in col["rp"] if x is not None]
        fd = [(p, x) for p, x in col["fd"] if x is not None]
        nnz = {p: n for p, n, _ in rates}
        large = [p for p, n in nnz.items() if n is not None and n >= LARGE_NNZ_L]
        lines = []
        if rd:
            lo, hi = min(x for _, x in rd), max(x for _, x in rd)
            lines.append(f"strata's GPU refactorization is **{lo:.1f}–{hi:.1f}× slower** than "
                         f"cuDSS's with its default reordering (geometric mean "
                         f"{f_ratio(geomean([x for _, x in rd]))}; slowest: "
                         f"{max(rd, key=lambda t: t[1])[0]}) and "
                         + (f"{min(x for _, x in rp):.1f}–{max(x for _, x in rp):.1f}× slower "
                            f"than cuDSS's with strata's own permutation" if rp else
                            "not compared with strata's permutation") + ".")
        fs = [(p, x) for p, x, _ in solve if x is not None]
        if fs:
            slow = [(p, x) for p, x in fs if x > 1]
            lines.append(("One application of strata's factor (first solve, no refinement) "
                          f"takes {min(x for _, x in fs):.2f}–{max(x for _, x in fs):.2f}× "
                          f"cuDSS's solve (default reordering)"
                          + (f": **slower on {len(slow)} of {len(fs)} problems**" if slow
                             else ": not slower on any problem") + "; the full solve with "
                          "refinement: " + ", ".join(f"{p} {f_ratio(x)}×" for p, _, x in solve
                                                     if x is not None) + "."))
        if fd:
            lines.append(f"First factorization: {min(x for _, x in fd):.1f}–{max(x for _, x in fd):.1f}× "
                         f"cuDSS's.")
        if large:
            lr = [(p, x) for p, x in rd if p in large]
            lf = [(p, x) for p, x in fd if p in large]
            met = all(x <= 1 for _, x in lr) and all(x <= 1 for _, x in lf) and lr
            lines.append(f"Target (issue): factorization ≤ 1.0× cuDSS on the large problems "
                         f"(here: nnz(L) ≥ {LARGE_NNZ_L:.0e}, this generator's threshold: "
                         f"{', '.join(large)}): **{'met' if met else 'not met'}** "
                         f"(refactorization " + ", ".join(f"{p} {x:.1f}×" for p, x in lr)
                         + ").")
        good = [(p, x) for p, _, x in rates if x is not None]
        if good and peak:
            bp, bx = max(good, key=lambda t: t[1])
            lines.append(f"Target (issue): ≥ {PEAK_TARGET:.0%} of the DGEMM peak "
                         f"({peak * 1e-12:.1f} TFLOP/s): **"
                         f"{'met' if bx >= PEAK_TARGET * peak else 'not met'}**; the best "
                         f"strata refactorization reaches {bx * 1e-9:.0f} GFLOP/s ({bp}), "
                         f"{100 * bx / peak:.2f}% of the peak.")
        elif good:
            lines.append(f"Target (issue): ≥ {PEAK_TARGET:.0%} of the DGEMM peak: not "
                         f"computable (no DGEMM peak measured on this GPU model).")
        else:
            lines.append(f"Target (issue): ≥ {PEAK_TARGET:.0%} of the DGEMM peak: not "
                         f"computable (no flop counts for these analyses).")
        self.w("**Where strata is behind cuDSS:**")
        self.w()
        for line in lines:
            self.w(f"- {line}")
        self.w()

    def cudss_plot(self, r: Run, keys) -> None:
        probs = [str(row.get("problem")) for row in r.rows]
        fig, axes = self.plt.subplots(1, 2, figsize=(max(9, 1.4 * len(probs) + 3), 4.5))
        for ax, what, title in ((axes[0], "factor_seconds", "first factorization"),
                                (axes[1], "refactor_seconds", "refactorization")):
            width = 0.8 / len(keys)
            for i, (k, name) in enumerate(keys):
                xs, ys = [], []
                for j, row in enumerate(r.rows):
                    y = num(dig(row, k, what))
                    if y is not None and y > 0:
                        xs.append(j + (i - (len(keys) - 1) / 2) * width)
                        ys.append(y)
                ax.bar(xs, ys, width, label=name)
            ax.set_yscale("log")
            ax.set_xticks(range(len(probs)))
            ax.set_xticklabels(probs, rotation=45, ha="right", fontsize=8)
            ax.set_ylabel("seconds")
            ax.set_title(f"{title} (lower is better)", fontsize=10)
            ax.grid(True, axis="y", which="both", alpha=0.3)
            ax.legend(fontsize=8)
        self.savefig(fig, f"cudss-{machine_slug(r.machine)}",
                     "strata vs cuDSS factorization and refactorization time",
                     "Tables and plot: times copied from the rows; ratios, rates and the "
                     "fraction of peak computed by this generator.", [r])

    # ---- experiment 3

    def multigpu_section(self, runs: list[Run]) -> None:
        self.w("## 3. GPU count 1, 2, 4 (with ablation)")
        self.w()
        self.w("Factorization time with 1, 2 and 4 GPUs (bench_multigpu: the tree split into "
               "subtrees per GPU, a top part shared), the speedup over 1 GPU, and the "
               "ablation: the *default* configuration (the most subtrees per GPU in the "
               "problem's newest run: 1 since 6403d1a, 4 before; "
               "work stealing on, balance by work off — off by default because it did not "
               "balance the subtrees the GPUs get, docs/multigpu.md) against the same with one "
               "feature changed: balance by work on, another subtrees_per_gpu, no "
               "stealing.")
        self.w()
        mg = [r for r in runs if r.kind == "multigpu"]
        groups: dict[tuple, list[Run]] = {}
        for r in mg:
            groups.setdefault((r.backend, r.machine), []).append(r)
        gpu = {k: v for k, v in groups.items() if k[0] != "cpu"}
        cpu = {k: v for k, v in groups.items() if k[0] == "cpu"}
        if not gpu:
            self.w(f"{NOT_MEASURED}: no GPU (backend cuda) `multigpu` results; needs a lent "
                   f"2- or 4-GPU machine (`bench/run multigpu`, or `scripts/gpu/run.sh "
                   f"--multigpu-bench --workers 1,2,4 --subtrees 1,4 --balance on,off "
                   f"--stealing on,off`).")
            self.w()
        for (_, machine), rs in gpu.items():
            rs = self.multigpu_current(rs)
            self.multigpu_group(rs, machine, "GPU")
        if cpu:
            self.w("### CPU backend (host executors standing in for GPUs; not the experiment)")
            self.w()
            self.w("The same driver with `--backend cpu`: N host executors stand in for N "
                   "GPUs. These runs test the multi-worker path; their times say nothing "
                   "about GPUs and do not count as experiment 3.")
            self.w()
            for (_, machine), rs in cpu.items():
                self.multigpu_group(rs, machine, "CPU worker")

    @staticmethod
    def is_new_multigpu(r: Run) -> bool:
        """Rows with first_factor_seconds: factor_seconds is the median of the
        refactorizations after the first (set-up excluded). Older files' factor_seconds is
        the median over all factorizations, the first (which sets the executors up)
        included."""
        return any(isinstance(row, dict) and "first_factor_seconds" in row for row in r.rows)

    def multigpu_current(self, rs: list[Run]) -> list[Run]:
        """Of one machine's runs: the new-format ones when there are any (older files are
        named as superseded), else the older ones with a warning."""
        new = [r for r in rs if self.is_new_multigpu(r)]
        old = [r for r in rs if not self.is_new_multigpu(r)]
        if new and old:
            self.consumed.update(r.path for r in old)
            self.w("Older results on this machine, superseded by the files below and not "
                   "shown: " + ", ".join(f"[`{r.name}`]({self.rel(r.path)})" for r in old)
                   + " (their factor times include the first factorization, which sets the "
                   "executors up).")
            self.w()
            return new
        if old:
            self.w("**Caution: these results files are of the older format**: their *factor "
                   "s* is the median over all of the run's factorizations, the first included "
                   "— and the first sets the executors up — so set-up cost is mixed into every "
                   "time below, more so with more GPUs. Newer runs (`bench/run multigpu`) "
                   "report the first factorization apart.")
            self.w()
        return rs

    # Options::distributed_front_min_rows and distributed_front_block_size, the library's
    # defaults (include/strata/options.hpp)
    DIST_DEFAULT = (1024, 512)

    def multigpu_group(self, rs: list[Run], machine: tuple, unit: str) -> None:
        self.consumed.update(r.path for r in rs)
        cfg: dict[tuple, dict] = {}
        budget: dict[tuple, dict] = {}  # rows under a device budget (--budget-share), apart
        # rows with large fronts' updates split over idle GPUs (--split-fronts > 0), apart,
        # each with the row of the same run, problem and GPUs without the split
        split_rows: dict[tuple, tuple] = {}
        # rows of several GPUs whose distributed-front setting is not the library's
        # (Options::distributed_front_min_rows / _block_size, on since this session's
        # measurements: 1024 / 512), apart, with the run they came from; rows without the
        # key predate the option and ran with it off, which was then the default
        dist_rows: dict[tuple, tuple] = {}
        newest_s: dict = {}  # problem → the most subtrees per worker in its newest run
        # the solve: (problem, workers) → {"parts" | "host": (row, run)}; runs with
        # gpu_solve_parts=false give the host solve and are kept out of the factor tables
        solves: dict[tuple, dict] = {}
        for r in sorted(rs, key=lambda r: (r.date, r.name)):
            host = "gpu_solve_parts=false" in (r.get("solver_options") or [])
            for row in r.rows:
                if isinstance(row, dict) and num(row.get("first_solve_seconds")) is not None:
                    solves.setdefault((row.get("problem"), int(num(row.get("workers")) or 0)),
                                      {})["host" if host else "parts"] = (row, r)
        rs = [r for r in rs if not r.get("solver_options")]
        for r in sorted(rs, key=lambda r: (r.date, r.name)):  # newer runs override
            run_s: dict = {}
            for row in r.rows:
                if (isinstance(row, dict) and (num(row.get("workers")) or 0) > 1
                        and not (num(row.get("split_front_min_cb")) or 0) > 0
                        and not (num(row.get("budget_share_ratio")) or 0) > 0):
                    x = int(num(row.get("subtrees_per_worker")) or 0)
                    run_s[row.get("problem")] = max(run_s.get(row.get("problem"), 0), x)
            newest_s.update(run_s)
            for row in r.rows:
                if (isinstance(row, dict) and "distributed_front_min_rows" in row
                        and (num(row.get("workers")) or 0) > 1
                        and (num(row.get("split_front_min_cb")) or 0) == 0
                        and not (num(row.get("budget_share_ratio")) or 0) > 0):
                    key = (int(num(row.get("distributed_front_min_rows")) or 0),
                           int(num(row.get("distributed_front_block_size")) or 512))  # fixed at 512 before the option
                    dist_rows[(row.get("problem"), int(num(row.get("workers")) or 0), key,
                               r.date)] = (row, r)
                    if key != self.DIST_DEFAULT:
                        continue
                if isinstance(row, dict) and (num(row.get("split_front_min_cb")) or 0) > 0:
                    off = next((x for x in r.rows if isinstance(x, dict)
                                and (num(x.get("split_front_min_cb")) or 0) == 0
                                and x.get("problem") == row.get("problem")
                                and x.get("workers") == row.get("workers")), None)
                    split_rows[(row.get("problem"), int(num(row.get("workers")) or 0),
                                int(num(row.get("split_front_min_cb"))))] = (row, off, r)
                    continue
                if isinstance(row, dict) and (num(row.get("budget_share_ratio")) or 0) > 0:
                    budget[(row.get("problem"), int(num(row.get("workers")) or 0),
                            num(row.get("budget_share_ratio")))] = row
                    continue
                if isinstance(row, dict) and num(row.get("workers")) is not None:
                    # rows without split_top predate the top split: they ran the
                    # defaults of their time and count as the default here
                    cfg[(row.get("problem"), int(row["workers"]),
                         int(num(row.get("subtrees_per_worker")) or 0),
                         bool(row.get("balance_by_work")), bool(row.get("work_stealing")),
                         bool(row.get("split_top", True)))] = row
        problems = list(dict.fromkeys(k[0] for k in cfg))
        workers = sorted({k[1] for k in cfg})
        s_max = {p: max(k[2] for k in cfg if k[0] == p) for p in problems}
        # the default subtrees per worker: the most in the newest run of the problem (a
        # run's default is the most it has: an ablation adds fewer; the library's default
        # was 4 until 6403d1a, 1 since, so an older run's 4 must not stand for a newer 1)
        s_def = {p: newest_s.get(p, s_max[p]) for p in problems}

        def t(p, w, s, bal, stl, split=True):
            return num(dig(cfg.get((p, w, s, bal, stl, split)), "factor_seconds"))

        speed_rows, abl_rows, dev_rows, curves, est_cells = [], [], [], {}, []
        first_rows, phase_rows = [], []
        for p in problems:
            s = s_def[p]
            s_alt = s_max[p] if s_max[p] != s else 1  # the ablation's other count
            base = t(p, 1, s, False, True)
            if base is None:  # one worker has no top part to split: either row will do
                base = t(p, 1, s, False, True, False)
            any_row = next(v for k, v in cfg.items() if k[0] == p)
            line = [str(p), f_int(any_row.get("n")), f_g(any_row.get("flops"))]
            line += [f_sec(t(p, w, s, False, True)) for w in workers]
            sp = [(w, ratio(base, t(p, w, s, False, True))) for w in workers]
            line += [f"{x:.2f}" if x is not None else "–" for w, x in sp if w > 1]
            line += [f"{x / w:.0%}" if x is not None else "–" for w, x in sp if w > 1]
            curves[p] = [(w, x) for w, x in sp if x is not None]
            # the split's own estimate (flops only, AnalysisStats::estimated_speedup; rows
            # since 5721ec8), beside the measured speedup
            est_cells.append([num(dig(cfg.get((p, w, s, False, True, True)), "estimated_speedup"))
                              for w in workers if w > 1])
            speed_rows.append(line)
            for w in workers:
                row = cfg.get((p, w, s, False, True, True)) or {}
                ff, rf = num(row.get("first_factor_seconds")), num(row.get("factor_seconds"))
                if ff is not None:
                    first_rows.append([str(p), str(w), f_sec(ff), f_sec(rf),
                                       f_sec(ff - rf) if rf is not None else "–",
                                       f_ratio(ratio(ff, rf))])
                ph = row.get("factor_phases")
                if isinstance(ph, dict):
                    phase_rows.append([str(p), str(w)] + [f_sec(ph.get(k)) for k, _ in
                                                          self.PHASES])
            for w in workers:
                on = t(p, w, s, False, True)
                cells = [str(p), str(w), str(s), f_sec(on)]
                for alt in ((s, True, True, True), (s_alt, False, True, True),
                            (s, False, False, True), (s, False, True, False)):
                    x = t(p, w, *alt) if alt != (s, False, True, True) else None
                    cells.append("–" if x is None else
                                 f"{f_sec(x)} ({f_ratio(ratio(x, on))})"
                                 + (f" [{s_alt}]" if alt[0] != s else ""))
                row = cfg.get((p, w, s, False, True, True)) or {}
                layers = num(row.get("upper_layers"))
                cells.append("–" if layers is None else
                             f"{int(layers)} / {f_int(row.get('upper_parts'))} / "
                             f"{num(row.get('upper_flops_fraction')) or 0:.0%} / "
                             f"{num(row.get('top_flops_fraction')) or 0:.0%}")
                abl_rows.append(cells)
                for i, d in enumerate(row.get("devices") or []):
                    busy, idle = num(d.get("busy_seconds")), num(d.get("idle_seconds"))
                    share = ratio(busy, (busy or 0) + (idle or 0))
                    dev_rows.append([str(p), str(w), str(i), f_sec(busy), f_sec(idle),
                                     f"{share:.0%}" if share is not None else "–",
                                     f_int(d.get("subtrees_run")), f_int(d.get("subtrees_stolen")),
                                     f_int(d.get("upper_parts_run")),
                                     f_int(d.get("bytes_transferred")), f_g(d.get("flops"))])
        self.w(f"On {machine_label(machine)}; seconds: median of the run's factorizations "
               f"with the default configuration (the most subtrees per {unit} in the problem's "
               f"newest run — 1 since 6403d1a, 4 before; work "
               f"stealing on, work-balanced bisection off — Options' defaults); speedup: time with 1 {unit} over time with W; "
               f"efficiency: speedup / W.")
        self.w()
        est_head = []
        if any(x is not None for cells in est_cells for x in cells):
            est_head = [f"estimate {w}" for w in workers if w > 1]
            for line, cells in zip(speed_rows, est_cells):
                line += [f"{x:.2f}" if x is not None else "–" for x in cells]
        self.w(table(["problem", "n", "flops"] + [f"{w} {unit} s" for w in workers]
                     + [f"speedup {w}" for w in workers if w > 1]
                     + [f"efficiency {w}" for w in workers if w > 1] + est_head,
                     speed_rows))
        if est_head:
            self.w("*estimate W*: the speedup the tree split allows by flops alone "
                   "(`AnalysisStats::estimated_speedup`: total flops over the list schedule's "
                   "end + the top part's work; transfers and batching not counted), where the "
                   "run recorded it.")
            self.w()
        slower = [(p, w, x) for p, c in curves.items() for w, x in c if w > 1 and x < 1]
        if slower and unit == "GPU":
            self.behind_notes.append(
                f"multi-GPU factorization on {machine_label(machine)}: slower with more GPUs "
                f"than with one — " + ", ".join(f"{p} on {w} GPUs {1 / x:.2f}× the 1-GPU time"
                                                for p, w, x in slower))
        if slower:
            self.w(f"**Slower with more {unit}s than with one:** " + ", ".join(
                f"{p} on {w} {unit}s takes {1 / x:.2f}× the 1-{unit} time" for p, w, x in slower)
                + ".")
            self.w()
        behind = [(p, w, x) for p, c in curves.items() for w, x in c if w > 1 and x < 0.8 * w]
        if behind:
            self.w("Below 80% parallel efficiency: " + ", ".join(
                f"{p} with {w} ({x:.2f}× of the ideal {w}×)" for p, w, x in behind) + ".")
            self.w()
        if first_rows:
            self.w(f"First factorization (which sets the executors up) against the "
                   f"refactorizations after it (the times above), default configuration:")
            self.w()
            self.w(table(["problem", unit + "s", "first factorization s",
                          "refactorization s", "set-up (difference) s", "first/refactor"],
                         first_rows, 1))
        if solves:
            srows = []
            for (p, w), d in sorted(solves.items(), key=lambda kv: (str(kv[0][0]), kv[0][1])):
                on, host = d.get("parts"), d.get("host")
                one = solves.get((p, 1), {}).get("parts")
                t_on = num(on[0].get("first_solve_seconds")) if on else None
                t_host = num(host[0].get("first_solve_seconds")) if host else None
                t_one = num(one[0].get("first_solve_seconds")) if one and w > 1 else None
                where = ("–" if not on else "GPUs" if on[0].get("solve_on_device") else "host")
                srows.append([str(p), str(w), f_sec(t_on), where, f_sec(t_host),
                              f_ratio(ratio(t_host, t_on)), f_ratio(ratio(t_on, t_one)),
                              ", ".join(sorted({f"[`{x[1].name}`]({self.rel(x[1].path)})"
                                                for x in (on, host) if x}))])
            self.w(f"Solve: one application of the factor (`first_solve_seconds`, median of "
                   f"the run's solves, no refinement), seconds — with each part solved on the "
                   f"{unit} that holds it (`gpu_solve_parts`, the default; *where*: where it "
                   f"ran), and with the panels fetched to the host and solved there "
                   f"(`--solver-option gpu_solve_parts=false`, a run of its own); *host / parts*: "
                   f"over the parts' time; *over 1 {unit}*: the parts' time over the one-{unit} "
                   f"solve (a resident factor):")
            self.w()
            self.w(table(["problem", unit + "s", "parts s", "where", "host s", "host / parts",
                          f"over 1 {unit}", "files"], srows, 1))
        if phase_rows:
            self.w("GPU time per phase of the last refactorization (`factor_phases`, seconds, "
                   "as the driver stores them), default configuration:")
            self.w()
            self.w(table(["problem", unit + "s"] + [n for _, n in self.PHASES], phase_rows, 1))
        self.w("Ablation: time of the defaults (*default*: subtrees per GPU as in the speedup "
               "table; *other subtrees*: the run's other count, in square brackets, "
               "stealing on, balance by work off, top split into upper layers on) and with one "
               "feature changed, seconds (in brackets: over *default*; below 1, the change "
               "helps). – where the run did not include that configuration (the driver runs the "
               "product of its `--subtrees`, `--balance`, `--stealing` and `--split-top` "
               "lists). Rows of files without `split_top` predate the top split and count as "
               "the default. *Top split* of the default: upper layers / their parts / share of "
               "the flops in them / share left in the top part.")
        self.w()
        self.w(table(["problem", "workers", "subtrees per worker", "default s",
                      "balance by work on", "other subtrees", "no stealing", "no top split",
                      "top split"], abl_rows, 2))
        if budget:
            brows = []
            for (p, w, share), row in sorted(budget.items(), key=lambda kv: (str(kv[0][0]),
                                                                            kv[0][1], kv[0][2])):
                s = int(num(row.get("subtrees_per_worker")) or 0)
                in_core = t(p, w, s, False, True) if p in s_max else None
                fb = num(row.get("factor_bytes"))
                brows.append([str(p), str(w), f"{share:g}",
                              f_g(fb / w * 1e-6) if fb is not None else "–",
                              f_g((num(row.get("device_memory_limit")) or 0) * 1e-6),
                              f_sec(row.get("factor_seconds")), f_sec(in_core),
                              f_ratio(ratio(num(row.get("factor_seconds")), in_core)),
                              f_int(row.get("tiled_fronts")),
                              "yes" if row.get("contribution_blocks_on_host") else "no",
                              f_g((num(row.get("bytes_to_device")) or 0) * 1e-6),
                              f_g((num(row.get("bytes_to_host")) or 0) * 1e-6),
                              f_g(row.get("backward_error"))])
            self.w(f"Under a device memory budget far below each {unit}'s share of the factor "
                   f"(`--budget-share R`: budget = factor bytes / {unit}s / R): the "
                   f"factorization completes; seconds against the same configuration in "
                   f"core from the table above (– where the run had none), fronts factored "
                   f"tile by tile, contribution blocks spilled to the host, megabytes moved "
                   f"each way, backward error.")
            self.w()
            self.w(table(["problem", unit + "s", "share / budget", f"factor MB per {unit}",
                          "budget MB", "factor s", "in core s", "slowdown", "tiled fronts",
                          "CBs spilled", "MB to device", "MB to host", "berr"], brows, 2))
        if dist_rows:
            drows = []
            for (p, w, key, _), (row, r) in sorted(dist_rows.items(),
                                                   key=lambda kv: (str(kv[0][0]), kv[0][1],
                                                                   kv[0][3], kv[0][2])):
                devs = row.get("devices") or []
                off = next((x for x in r.rows if isinstance(x, dict)
                            and x.get("problem") == p and x.get("workers") == row.get("workers")
                            and int(num(x.get("distributed_front_min_rows")) or 0) == 0
                            and (num(x.get("split_front_min_cb")) or 0) == 0), None)
                top = [pr for d in devs for pr in (d.get("parts") or [])
                       if isinstance(pr, dict) and pr.get("kind") == "top"]
                top_s = (num(top[0].get("end_seconds")) - num(top[0].get("start_seconds"))
                         if top else None)
                on_s = num(row.get("factor_seconds"))
                drows.append([str(p), str(w), f"{key[0]} / {key[1]}", f_sec(on_s),
                              f_ratio(ratio(on_s, num(dig(off, "factor_seconds"))))
                              if key[0] > 0 else "–",
                              f_sec(top_s),
                              f_int(sum(int(num(d.get("fronts_distributed")) or 0) for d in devs)),
                              f"[`{r.name}`]({self.rel(r.path)})"])
            self.w(f"Top fronts factored whole over all {unit}s, columns in blocks dealt out "
                   f"cyclically (`Options::distributed_front_min_rows` / "
                   f"`distributed_front_block_size`, `--distributed-fronts` / "
                   f"`--distributed-block`; 0 rows: off; default {self.DIST_DEFAULT[0]} / "
                   f"{self.DIST_DEFAULT[1]}): seconds, the ratio to the row of the same run with "
                   f"it off (below 1, it helps), the top part's seconds from the part log, and "
                   f"the fronts distributed in the last factorization.")
            self.w()
            self.w(table(["problem", unit + "s", "min rows / block", "factor s", "vs off",
                          "top part s", "fronts distributed", "run"], drows, 3))
        if split_rows:
            srows = []
            for (p, w, cb), (row, off, r) in sorted(split_rows.items(),
                                                     key=lambda kv: (str(kv[0][0]), kv[0][1],
                                                                     kv[0][2])):
                devs = row.get("devices") or []
                on_s = num(row.get("factor_seconds"))
                off_s = num(dig(off, "factor_seconds"))
                srows.append([str(p), str(w), str(cb), f_sec(on_s), f_sec(off_s),
                              f_ratio(ratio(on_s, off_s)),
                              f_int(sum(int(num(d.get("fronts_split")) or 0) for d in devs)),
                              f_int(sum(int(num(d.get("strips_helped")) or 0) for d in devs)),
                              f"[`{r.name}`]({self.rel(r.path)})"])
            self.w(f"Large fronts' updates split by column strips over the {unit}s idle while "
                   f"they are factored (`Options::split_front_min_cb`, `--split-fronts`: fronts "
                   f"whose contribution block has at least that many rows; 0, the default, "
                   f"splits none): seconds with the split and without it in the same run (in "
                   f"brackets: with over without; below 1, the split helps), fronts split and "
                   f"strips computed by helpers in the last factorization.")
            self.w()
            self.w(table(["problem", unit + "s", "min CB rows", "split s", "not split s",
                          "ratio", "fronts split", "strips by helpers", "run"], srows, 3))
        if dev_rows:
            self.w(f"Per {unit} (default configuration, last factorization of the run): busy and idle "
                   f"seconds, busy share, subtrees run and stolen, upper-layer parts run, bytes "
                   f"moved, flops.")
            self.w()
            self.w(table(["problem", "workers", unit, "busy s", "idle s", "busy share",
                          "subtrees run", "stolen", "upper parts", "bytes moved", "flops"],
                         dev_rows, 3))
        fig, ax = self.plt.subplots(figsize=(6.5, 4.5))
        for p, c in curves.items():
            if c:
                ax.plot([w for w, _ in c], [x for _, x in c], "o-", label=p)
        ax.plot(workers, workers, "k:", lw=0.8, label="ideal")
        ax.set_xticks(workers)
        ax.set_xlabel(f"{unit}s")
        ax.set_ylabel(f"speedup over 1 {unit}")
        ax.set_title(f"factorization speedup, default configuration ({unit}s)", fontsize=10)
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
        self.savefig(fig, f"multigpu-{unit.split()[0].lower()}-{machine_slug(machine)}",
                     f"speedup over 1 {unit}",
                     "Tables and plot: times copied from the rows (newest run wins where runs "
                     "overlap); speedups and ratios computed by this generator.",
                     sorted(rs, key=lambda r: r.name))

    # ---- experiment 4

    def solvability_section(self, runs: list[Run]) -> None:
        self.w("## 4. Solvability: time vs factor size / device budget")
        self.w()
        self.w("The GPU factorization as the device memory budget shrinks below the size of "
               "the factor: in core (no budget) and with the budget set to factor bytes / "
               "ratio. The anchor is the PCIe floor: the time the transfers alone need at the "
               "measured pinned bandwidth (the larger of bytes to the device / H2D and bytes "
               "to the host / D2H).")
        self.w()
        chosen = [r for r in runs if r.kind == "gpu_memory" and r.get("solvability")]
        if not chosen:
            self.w(f"{NOT_MEASURED}: no `gpu_memory` results with a solvability part "
                   f"(bench_gpu_memory on a lent GPU machine: `scripts/gpu/run.sh "
                   f"--memory-bench`).")
            self.w()
        for r in chosen:
            self.solvability_run(r)
        kernels = [r for r in runs if r.kind == "gpu_memory" and r.get("front_kernels")]
        if kernels:
            # the single-front table from the run with the most shapes (newest on ties), the
            # concurrent one from the newest run that has it
            # (runs with strata's own panel kernels first)
            def has_ours(r):
                return any("panel_kernels_flops_per_second" in x
                           for x in r.get("front_kernels").get("rows") or [])
            full = max(kernels, key=lambda r: (has_ours(r),
                                               len(r.get("front_kernels").get("rows") or []),
                                               r.date, r.name))
            conc = [r for r in kernels if r.get("front_kernels").get("concurrent")]
            self.front_kernels_table(full, max(conc, key=lambda r: (r.date, r.name))
                                     if conc else None)
            batched = [r for r in kernels if r.get("front_kernels").get("batched_panels")]
            if batched:
                self.batched_panels_table(max(batched, key=lambda r: (r.date, r.name)))
        sweeps = [r for r in runs if r.kind == "gpu_memory" and r.get("panel_kernels")]
        if sweeps:
            def values(r):
                return len({x.get("gpu_panel_kernel_max_pivots")
                            for p in r.get("panel_kernels") for x in p.get("runs", [])})
            full = max(sweeps, key=lambda r: (values(r), r.date, r.name))
            self.panel_sweep_table(full)
            self.panel_progress_table([r for r in sweeps if r is not full])
        blocked = [r for r in runs if r.kind == "gpu_memory" and r.get("potrf_block")]
        blocked_kernels = [r for r in kernels if any(
            "blocked_256_potrf_trsm_flops_per_second" in x
            for x in r.get("front_kernels").get("rows") or [])]
        if blocked or blocked_kernels:
            self.potrf_block_tables(
                max(blocked, key=lambda r: (r.date, r.name)) if blocked else None,
                sorted(blocked_kernels, key=lambda r: (r.date, r.name)))
        lu_strips = [r for r in runs if r.kind == "gpu_memory" and r.get("lu_panel_kernels")]
        if lu_strips:
            self.w("### LU fronts by strips of batched kernels")
            self.w()
            for r in sorted(lu_strips, key=lambda r: (r.date, r.name)):
                self.lu_strip_table(r)
        recursive = [r for r in runs if r.kind == "gpu_memory" and r.get("recursive_panel")]
        if recursive:
            self.w("### Cholesky pivot block and panel by recursion")
            self.w()
            for r in sorted(recursive, key=lambda r: (r.date, r.name)):
                self.recursive_panel_table(r)

    def lu_strip_table(self, r: Run) -> None:
        """Options::gpu_lu_strip_pivots sweep on LU problems (0: GETRF + TRSMs)."""
        self.consumed.add(r.path)
        values = sorted({int(num(x.get("gpu_lu_strip_pivots")))
                         for p in r.get("lu_panel_kernels") for x in p.get("runs", [])})
        rows = []
        for p in r.get("lu_panel_kernels"):
            by = {int(num(x.get("gpu_lu_strip_pivots"))): x for x in p.get("runs", [])}
            secs = {v: num(x.get("factor_seconds")) for v, x in by.items()}
            best = min((v for v in values if v > 0 and v in secs), key=lambda v: secs[v],
                       default=None)
            at = by.get(best) or {}
            rows.append([p.get("problem")] + [f_sec(secs.get(v)) for v in values] +
                        [f_ratio(ratio(secs.get(best), secs.get(0))),
                         f"{at.get('lu_large_fronts', '–')} / {at.get('lu_large_fronts_pivoted', '–')}"])
        self.w("`Options::gpu_lu_strip_pivots` (src/numeric/cuda/lu_fronts.cu, default 256): "
               "large LU fronts eliminated without interchanges in strips of that many pivots, "
               "each strip's pivot block and panels by the batched kernels of "
               "kernels_lu_panel.cu for all fronts of a chunk, the rest by cuBLAS GEMMs; 0 is "
               "the path before (cuSOLVER GETRF + two cuBLAS TRSMs per front). In-core "
               "refactorization, seconds (median of the repeats), the best strip against 0, "
               "and at that strip the large fronts and those factored again with GETRF "
               f"({machine_label(r.machine)}, {r.date}, commit {r.get('git_commit') or '?'}; "
               f"`{r.get('command')}`; the note in the JSON says what the tree held).")
        self.w()
        self.w(table(["problem"] + [f"{v}" for v in values] +
                     ["best / 0", "large fronts / redone"], rows, 0))
        self.w()

    def recursive_panel_table(self, r: Run) -> None:
        """Options::gpu_recursive_panel off and on, whole problems."""
        self.consumed.add(r.path)
        rows = []
        for p in r.get("recursive_panel"):
            by = {int(num(x.get("gpu_recursive_panel"))): num(x.get("factor_seconds"))
                  for x in p.get("runs", [])}
            rows.append([p.get("problem"), f_sec(by.get(0)), f_sec(by.get(1)),
                         f_ratio(ratio(by.get(1), by.get(0)))])
        self.w("`Options::gpu_recursive_panel` (src/numeric/cuda/llt_recursive.cu, on by "
               "default): fronts with more pivots than `gpu_panel_kernel_max_pivots` get their "
               "pivot block and panel by recursion on the pivot columns (64-column base cases, "
               "one cuBLAS GEMM per level) instead of cuSOLVER POTRF + cuBLAS TRSM. In-core "
               "refactorization, seconds (median of the repeats) "
               f"({machine_label(r.machine)}, {r.date}, commit {r.get('git_commit') or '?'}; "
               f"`{r.get('command')}`; the note in the JSON says what the tree held).")
        self.w()
        self.w(table(["problem", "off (POTRF + TRSM)", "on (recursion)", "on / off"], rows, 0))
        self.w()

    def potrf_block_tables(self, sweep: Run | None, kerns: list[Run]) -> None:
        """Options::gpu_potrf_block_size: single fronts (kernel table) and whole problems."""
        self.w("### Cholesky pivot block and panel in column blocks")
        self.w()
        self.w("`Options::gpu_potrf_block_size` (src/numeric/cuda/llt_blocked.cu): a large "
               "front's pivot block and panel by POTRF of each nb-wide diagonal block, TRSM "
               "of the rows below it and SYRK + GEMM of the remaining pivot columns, instead "
               "of one cuSOLVER POTRF and one cuBLAS TRSM of all k pivots (0).")
        self.w()
        for kern in kerns:
            self.consumed.add(kern.path)
            rows = []
            for x in kern.get("front_kernels").get("rows") or []:
                def tf(key):
                    v = num(x.get(key))
                    return "–" if v is None else f"{v * 1e-12:.1f}"
                rows.append([f_int(x.get("m")), f_int(x.get("k")), tf("potrf_flops_per_second"),
                             tf("potrf_trsm_flops_per_second")] +
                            [tf(f"blocked_{nb}_potrf_trsm_flops_per_second")
                             for nb in (128, 256, 512)] +
                            [tf("recursive_potrf_trsm_flops_per_second"),
                             tf("getrf_flops_per_second"), tf("getrf_nopiv_flops_per_second")])
            self.w("One front, TFLOP/s of POTRF + TRSM's work (k³/3 + (m−k)·k² flops), best of "
                   "3; beside it cuSOLVER GETRF of the k×k pivot block (2k³/3 flops) with "
                   "partial pivoting and without (what an LU front's pivot block costs: large "
                   "LU fronts run GETRF without pivoting first, CudaExecutor::lu_large_fronts) "
                   f"({machine_label(kern.machine)}, {kern.date}, commit "
                   f"{kern.get('git_commit') or '?'}; `{kern.get('command')}`):")
            self.w()
            self.w(table(["m", "k", "POTRF k×k alone", "POTRF + TRSM", "blocks of 128",
                          "blocks of 256", "blocks of 512", "recursion (llt_recursive.cu)",
                          "GETRF k×k", "GETRF unpivoted"], rows, 0))
            self.w()
        if sweep is not None:
            self.consumed.add(sweep.path)
            data = sweep.get("potrf_block")
            values = sorted({int(num(x.get("gpu_potrf_block_size")))
                             for p in data for x in p.get("runs", [])})
            rows = []
            for p in data:
                by = {int(num(x.get("gpu_potrf_block_size"))): num(x.get("factor_seconds"))
                      for x in p.get("runs", [])}
                best = min((v for v in by.values() if v), default=None)
                rows.append([p.get("problem")] + [
                    "–" if by.get(v) is None else
                    (f"**{by[v]:.4f}**" if by[v] == best else f"{by[v]:.4f}") for v in values])
            self.w("In-core refactorization, seconds (median of the repeats), per "
                   "`gpu_potrf_block_size` (0: one POTRF + TRSM per front); best in bold "
                   f"({machine_label(sweep.machine)}, {sweep.date}, commit "
                   f"{sweep.get('git_commit') or '?'}; `{sweep.get('command')}`).")
            self.w()
            self.w(table(["problem"] + [str(v) for v in values], rows, 0))
            self.w()

    def batched_panels_table(self, r: Run) -> None:
        """Pivot blocks and panels of many fronts: library on 8 streams vs strata's kernels."""
        self.consumed.add(r.path)
        rows = [[f_int(x.get("m")), f_int(x.get("k")), f_int(x.get("fronts")),
                 f_g(num(x.get("library_flops_per_second")) and
                     x["library_flops_per_second"] * 1e-12),
                 f_g(num(x.get("ours_flops_per_second")) and x["ours_flops_per_second"] * 1e-12)]
                for x in r.get("front_kernels").get("batched_panels")]
        self.w("The pivot blocks and panels (POTRF + TRSM's work, k³/3 + (m−k)·k² flops each) "
               "of many fronts of one shape: cuSOLVER POTRF + cuBLAS TRSM per front on 8 "
               "streams, against strata's panel kernels (kernels_panel.cu: all fronts in one "
               "go, 64 pivot columns per step); aggregate TFLOP/s "
               f"({machine_label(r.machine)}, {r.date}, commit {r.get('git_commit') or '?'}; "
               f"`{r.get('command')}`).")
        self.w()
        self.w(table(["m", "k", "fronts", "library", "panel kernels"], rows, 0))

    def panel_progress_table(self, rs: list[Run]) -> None:
        """Later runs of the panel part at one setting: the in-core time commit by commit."""
        if not rs:
            return
        rs = sorted(rs, key=lambda r: (r.date, r.name))
        problems = list(dict.fromkeys(p.get("problem") for r in rs
                                      for p in r.get("panel_kernels")))
        rows = []
        for r in rs:
            self.consumed.add(r.path)
            by = {}
            for p in r.get("panel_kernels"):
                for x in p.get("runs", []):
                    by[p.get("problem")] = (num(x.get("factor_seconds")),
                                            x.get("gpu_panel_kernel_max_pivots"))
            rows.append([r.date, r.get("git_commit") or "?", r.get("tag") or ""] + [
                "–" if by.get(q) is None or by[q][0] is None else
                f"{by[q][0]:.4f} (≤ {by[q][1]})" for q in problems])
        self.w("The same in-core refactorization in later runs, one setting each (the note in "
               "each JSON says what the tree held; "
               f"{machine_label(rs[-1].machine)}):")
        self.w()
        self.w(table(["date", "commit", "tag"] + problems, rows, 0))

    def panel_sweep_table(self, r: Run) -> None:
        """In-core Cholesky refactorization per Options::gpu_panel_kernel_max_pivots."""
        self.consumed.add(r.path)
        sweep = r.get("panel_kernels")
        values = sorted({int(num(x.get("gpu_panel_kernel_max_pivots")))
                         for p in sweep for x in p.get("runs", [])})
        rows = []
        for p in sweep:
            by = {int(num(x.get("gpu_panel_kernel_max_pivots"))): num(x.get("factor_seconds"))
                  for x in p.get("runs", [])}
            best = min((v for v in by.values() if v), default=None)
            rows.append([p.get("problem")] + [
                "–" if by.get(v) is None else
                (f"**{by[v]:.4f}**" if by[v] == best else f"{by[v]:.4f}") for v in values])
        self.w("### Which Cholesky fronts get the panel kernels")
        self.w()
        self.w("In-core refactorization time in seconds (median of the repeats) for each value "
               "of `Options::gpu_panel_kernel_max_pivots`: fronts over 256 rows with at most "
               "that many pivots get strata's pivot-block and panel kernels, the others "
               "cuSOLVER POTRF + cuBLAS TRSM (0: all of them); the SYRK stays cuBLAS's. Best "
               f"in bold ({machine_label(r.machine)}, {r.date}, commit "
               f"{r.get('git_commit') or '?'}; `{r.get('command')}`).")
        self.w()
        self.w(table(["problem"] + [f"≤ {v}" for v in values], rows, 0))

    def front_kernels_table(self, r: Run, rc: Run | None) -> None:
        """The dense kernels of a large front, by shape (bench_gpu_memory --parts kernels):
        where the factorization's rate is lost against the DGEMM peak; and (from rc) the
        large-front sequence on many fronts over several streams."""
        self.consumed.add(r.path)
        fk = r.get("front_kernels")
        peak = num(fk.get("dgemm_flops_per_second"))
        keys = [("potrf", "POTRF k×k"), ("trsm", "TRSM (m−k)×k"),
                ("potrf_trsm", "POTRF + TRSM"), ("panel_kernels", "ours: panel kernels"),
                ("trtri", "TRTRI k×k"),
                ("trsm_by_inverse", "TRSM as TRTRI + GEMM"), ("syrk", "SYRK rank k"),
                ("gemm_blocked_512", "GEMMs, 512-column blocks"),
                ("gemm_blocked_1024", "GEMMs, 1024"), ("gemm_blocked_2048", "GEMMs, 2048"),
                ("gemm_full", "one GEMM, full square")]
        rows = []
        for row in fk.get("rows") or []:
            cells = [f_int(row.get("m")), f_int(row.get("k"))]
            for k, _ in keys:
                x = num(row.get(k + "_flops_per_second"))
                cells.append("–" if x is None else
                             f"{x * 1e-12:.1f}" + (f" ({x / peak:.0%})" if peak else ""))
            rows.append(cells)
        self.w("### Dense kernels at the shapes of large fronts")
        self.w()
        self.w(f"TFLOP/s (in brackets: of the DGEMM peak, {f_g(peak and peak * 1e-12)} TFLOP/s) "
               f"that cuBLAS / cuSOLVER reach on one front of m rows and k pivots, each kernel "
               f"alone, best of 3; *TRSM as TRTRI + GEMM*: L11 copied, inverted by cuSOLVER "
               f"Xtrtri, the panel multiplied by the inverse into a buffer and copied back, "
               f"credited with TRSM's flops; *ours*: strata's pivot-block and panel kernels "
               f"(kernels_panel.cu) on the same front, credited with POTRF + TRSM's flops "
               f"({machine_label(r.machine)}, {r.date}, commit "
               f"{r.get('git_commit') or '?'}; `{r.get('command')}`): the factorization of "
               f"the pivot block and the panel below it, then the rank-k update of the "
               f"contribution block by DSYRK and by GEMMs over column blocks (credited with "
               f"the update's (m−k)²·k flops) and by one GEMM of the full square (its own "
               f"2·(m−k)²·k).")
        self.w()
        self.w(table(["m", "k"] + [n for _, n in keys], rows, 0))
        conc = (rc.get("front_kernels").get("concurrent") or []) if rc else []
        if conc:
            self.consumed.add(rc.path)
            shapes = list(dict.fromkeys((c.get("m"), c.get("k")) for c in conc))
            streams = sorted({int(num(c.get("streams")) or 0) for c in conc})
            crow = []
            for m, k in shapes:
                by = {int(num(c.get("streams")) or 0): num(c.get("flops_per_second"))
                      for c in conc if (c.get("m"), c.get("k")) == (m, k)}
                crow.append([f_int(m), f_int(k)] + [
                    "–" if by.get(s) is None else f"{by[s] * 1e-12:.1f}" for s in streams])
            self.w("The same sequence (POTRF, TRSM, SYRK) on 32 fronts of one shape side by "
                   "side on S streams, each with its own handles: aggregate TFLOP/s (the "
                   "executor runs a chunk's large fronts on 8 such lanes; "
                   f"{machine_label(rc.machine)}, {rc.date}, commit "
                   f"{rc.get('git_commit') or '?'}; `{rc.get('command')}`).")
            self.w()
            self.w(table(["m", "k"] + [f"S = {s}" for s in streams], crow, 0))

    def device_table(self, r: Run) -> None:
        f = r.get("device_figures")
        if not isinstance(f, dict):
            return
        self.w(f"Device figures ({machine_label(r.machine)}): pinned host→device "
               f"{f_g(num(f.get('h2d_bytes_per_second')) and f['h2d_bytes_per_second'] * 1e-9)} "
               f"GB/s, device→host "
               f"{f_g(num(f.get('d2h_bytes_per_second')) and f['d2h_bytes_per_second'] * 1e-9)} "
               f"GB/s (median of 5 copies of 256 MiB); cuBLAS DGEMM "
               f"(n = {f_int(f.get('dgemm_n'))}, best of 5) "
               f"{f_g(num(f.get('dgemm_flops_per_second')) and f['dgemm_flops_per_second'] * 1e-12)}"
               f" TFLOP/s.")
        self.w()
        peak = num(f.get("dgemm_flops_per_second"))
        bs = [(p.get("problem"), num(x.get("gflops")), x.get("max_block_size"))
              for p in r.get("block_size") or [] for x in p.get("runs", [])]
        bs = [b for b in bs if b[1] is not None]
        if peak and bs:
            p, g, b = max(bs, key=lambda t: t[1])
            bl = f"0, i.e. {GPU_CHOLESKY_BLOCK} for Cholesky" if num(b) == 0 else b
            self.w(f"Fraction of the DGEMM peak: the fastest in-core factorization of this "
                   f"run ({p}, max_block_size {bl}) reaches {g:.0f} GFLOP/s, "
                   f"**{100 * g * 1e9 / peak:.2f}% of the peak** (target ≥ "
                   f"{PEAK_TARGET:.0%}: **{'met' if g * 1e9 >= PEAK_TARGET * peak else 'not met'}**).")
            self.w()

    @staticmethod
    def tiled_variant(x: dict) -> tuple[str, str]:
        """A budgeted run's pool share and streamed-piece width (+prefetch) cells; – when
        the run did not record them (or ran in core)."""
        if not num(x.get("ratio")):
            return "–", "–"
        share = num(x.get("tiled_pool_share"))
        cols = x.get("tiled_stream_columns")
        return (f"{share:g}" if share is not None else "–",
                (f_int(cols) + (" +prefetch" if x.get("tiled_prefetch") else ""))
                if cols is not None else "–")

    def solvability_phases(self, probs: list) -> None:
        """Where a budgeted run's time went (FactorStats::device_phases), when it tiled."""
        rows = []
        for p in probs:
            for x in p.get("runs", []):
                ph = x.get("factor_phases") or {}
                if not num(x.get("ratio")) or not num(ph.get("tiled_fronts")):
                    continue
                chunks = sum(num(ph.get(k)) or 0
                             for k in ("assembly", "small_fronts", "large_fronts", "store"))
                split = ("tiled_pivot_columns" in ph)
                rows.append([str(p.get("problem")), ratio_label(x.get("ratio")),
                             *self.tiled_variant(x),
                             f_sec(num(x.get("factor_seconds"))), f_sec(chunks),
                             f_sec(num(ph.get("host"))), f_sec(num(ph.get("tiled_assembly"))),
                             f_sec(num(ph.get("tiled_slabs"))),
                             f_sec(num(ph.get("tiled_pivot_columns"))) if split else "–",
                             f_sec(num(ph.get("tiled_cb_update"))) if split else "–",
                             f_sec(num(ph.get("tiled_store")))])
        if not rows:
            return
        self.w("Where the budgeted runs' time went (`FactorStats::device_phases`, seconds): the "
               "launch groups of the fronts that fit (assembly, small and large fronts, stores; "
               "GPU time), the host's part after each group, and the tiled fronts' wall time — "
               "assembly on the host, slabs (for Cholesky since e45b480 split into the pivot "
               "columns and the contribution block's update; – where the run predates the "
               "split), the stores.")
        self.w()
        self.w(table(["problem", "factor/budget", "pool share", "stream cols", "factor s",
                      "groups s", "host s", "tiled assembly s", "tiled slabs s", "pivot columns s", "CB update s",
                      "tiled stores s"], rows, 2))

    def solvability_run(self, r: Run) -> None:
        self.consumed.add(r.path)
        self.device_table(r)
        probs = [p for p in r.get("solvability") or [] if isinstance(p, dict)]
        rows, worst = [], []
        for p in probs:
            for x in p.get("runs", []):
                fl = num(x.get("transfer_floor_seconds"))
                ft = num(x.get("factor_seconds"))
                rows.append([str(p.get("problem")), ratio_label(x.get("ratio")),
                             f_g(num(x.get("budget_bytes")) and x["budget_bytes"] / 1e6)
                             if num(x.get("ratio")) else "–",
                             *self.tiled_variant(x),
                             f_sec(ft), f"{num(x.get('slowdown_vs_in_core')) or 0:.2f}",
                             f_sec(fl), f_ratio(ratio(ft, fl)),
                             f_g(num(x.get("bytes_to_device")) and x["bytes_to_device"] / 1e6),
                             f_g(num(x.get("bytes_to_host")) and x["bytes_to_host"] / 1e6),
                             f_int(x.get("device_batches")), f_int(x.get("tiled_fronts")),
                             "yes" if x.get("contribution_blocks_on_host") else "no",
                             "yes" if x.get("factor_resident") else "no",
                             f_sec(x.get("solve_seconds")), f_e(x.get("backward_error"))])
                if num(x.get("ratio")):
                    worst.append((p.get("problem"), x.get("ratio"),
                                  num(x.get("slowdown_vs_in_core")), ratio(ft, fl)))
        self.w("Per problem (factor bytes in MB: "
               + ", ".join(f"{p.get('problem')} {f_g(num(p.get('factor_bytes')) and p['factor_bytes'] / 1e6)}"
                           for p in probs)
               + "): the budget, the device pool's share of it that the run asked for "
               "(`gpu_tiled_pool_share`; 0 or – : the plan's own pool) and the width of the "
               "pieces streamed through a tiled Cholesky front (`gpu_tiled_stream_columns`; "
               "0 or –: a third of the pool; +prefetch: `gpu_tiled_prefetch` on), the "
               "factorization time (median of the run's repeats), the "
               "slowdown against in core, the PCIe floor and the time over it, megabytes "
               "moved each way, device batches, fronts tiled because they do not fit, "
               "whether contribution blocks were spilled to the host, whether the factor "
               "stayed on the device, the solve time and the backward error.")
        self.w()
        self.w(table(["problem", "factor/budget", "budget MB", "pool share", "stream cols",
                      "factor s", "slowdown",
                      "PCIe floor s", "time/floor", "MB to device", "MB to host", "batches",
                      "tiled fronts", "CBs spilled", "factor on device", "solve s", "berr"],
                     rows, 2))
        berrs = [num(x.get("backward_error")) for p in probs for x in p.get("runs", [])]
        solved = bool(berrs) and all(b is not None and b <= 1e-12 for b in berrs)
        if worst:
            p, rt, sl, tf = max(worst, key=lambda t: t[2] or 0)
            self.w(("Every budget was solved (backward error ≤ 1e-12 in every run). "
                    if solved else "**Not every budget was solved to a backward error of "
                    "1e-12** (see the table). ") + "The cost: up to "
                   f"**{sl:.1f}× slower than in core** ({p} at {ratio_label(rt)}), and the "
                   f"time stays {min(t for *_, t in worst if t):.0f}–"
                   f"{max(t for *_, t in worst if t):.0f}× above the PCIe floor: the bytes moved, "
                   f"at the measured pinned bandwidth, are not what bounds the time.")
            self.w()
        self.solvability_phases(probs)
        fig, ax = self.plt.subplots(figsize=(7.5, 4.8))
        colors = self.plt.rcParams["axes.prop_cycle"].by_key()["color"]
        for i, p in enumerate(probs):
            c = colors[i % len(colors)]
            budgeted = [x for x in p.get("runs", []) if num(x.get("ratio"))]
            variants = sorted({self.tiled_variant(x) for x in budgeted})
            for si, v in enumerate(variants):  # one line per variant of the tiled fronts
                pts = sorted((num(x.get("ratio")), num(x.get("factor_seconds")),
                              num(x.get("transfer_floor_seconds"))) for x in budgeted
                             if self.tiled_variant(x) == v)
                tag = f" pool {v[0]}, pieces {v[1]}" if len(variants) > 1 else ""
                style = ["o-", "s--", "^-."][si % 3]
                ax.plot([a for a, _, _ in pts], [b for _, b, _ in pts], style, color=c,
                        label=f"{p.get('problem')}{tag}")
                ax.plot([a for a, _, _ in pts], [f for _, _, f in pts], "x:", color=c,
                        label=f"{p.get('problem')}{tag} PCIe floor")
            core = [num(x.get("factor_seconds")) for x in p.get("runs", [])
                    if not num(x.get("ratio"))]
            if core and core[0]:
                ax.axhline(core[0], color=c, ls="--", lw=0.8, alpha=0.7)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ticks = sorted({num(x.get("ratio")) for p in probs for x in p.get("runs", [])
                        if num(x.get("ratio"))})
        if ticks:
            ax.set_xticks(ticks)
            ax.set_xticklabels([f"{t:g}×" for t in ticks])
        ax.set_xlabel("factor bytes / device budget")
        ax.set_ylabel("seconds")
        ax.set_title("GPU factorization time under a device budget\nsolid: factorization, "
                     "dotted: PCIe floor, dashed: in core", fontsize=10)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7, ncol=2)
        self.savefig(fig, f"solvability-{machine_slug(r.machine)}",
                     "factorization time vs factor bytes / device budget",
                     "Table and plot: copied from the run's `solvability` rows; time/floor "
                     "computed by this generator.", [r])
