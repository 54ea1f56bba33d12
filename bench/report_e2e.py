"""Experiment 5 of the strata benchmark report (used by bench/report.py): `strata simulate`
end to end on the CPU and on the GPU.

`strata simulate` prints a text summary and has no JSON output, so the figures come from
the newest bench/results/logs/*mbd*.log that scripts/gpu/run_mbd.sh writes: one block per
run, opened by "=== NAME: strata simulate ARGS" and holding the summary lines ("linear
solver ... on cuda", "time [s] total T: solver S (P%, ...)", "per step [ms] solver A,
assembly B", "strata [ms] analysis X each, factorization Y each, solve Z each", ...). Lines
"# key: value" before the first block (run_mbd.sh writes date, gpu, cpu and commit there)
describe the machine. A results JSON of kind "simulate", if a driver ever writes one, is
shown as a plain table instead.
"""
from __future__ import annotations

import os
import re

from report_common import NOT_MEASURED, Run, machine_slug, table

FIELDS = {
    "device": re.compile(r"^linear solver\s+.* on (\w+)\s*$"),
    "steps": re.compile(r"^steps\s+(\d+) accepted, (\d+) rejected"),
    "matrix": re.compile(r"^Newton matrix\s+(\d+) x \d+, nnz (\d+), nnz\(L\) (\d+)"),
    "time": re.compile(r"^time \[s\]\s+total ([\d.]+): solver ([\d.]+) \((\d+)%"),
    "assembly": re.compile(r"assembly ([\d.]+) \((\d+)%\)"),
    "per_step": re.compile(r"^per step \[ms\]\s+solver ([\d.]+), assembly ([\d.]+)"),
    "strata": re.compile(r"^strata \[ms\]\s+analysis ([\d.]+) each, factorization ([\d.]+) "
                         r"each, solve ([\d.]+) each"),
    "result": re.compile(r"^result\s+(.*)$"),
}


def parse_mbd_log(text: str) -> tuple[dict, list[dict]]:
    """(header {key: value}, runs [{name, args, device, ...}]) of a run_mbd.sh log."""
    header, runs, cur = {}, [], None
    for line in text.splitlines():
        m = re.match(r"^=== ([^:]+): strata simulate (.*)$", line)
        if m:
            cur = {"name": m.group(1), "args": m.group(2).strip()}
            runs.append(cur)
            continue
        if cur is None:
            h = re.match(r"^# ([\w ]+): (.*)$", line)
            if h:
                header[h.group(1).strip()] = h.group(2).strip()
            continue
        for key, rx in FIELDS.items():
            m = rx.search(line) if key == "assembly" else rx.match(line)
            if m and (key != "assembly" or line.startswith("time")):
                cur[key] = m.groups()
    return header, runs


def model_of(args: str) -> str:
    """The run's arguments without --device: runs with equal models are compared."""
    return re.sub(r"\s*--(device|threads) \S+", "", args).strip()


class EndToEnd:
    """Mixin of Report: experiment 5."""

    def e2e_section(self, runs: list[Run]) -> None:
        self.w("## 5. End to end: `strata simulate`, CPU vs GPU")
        self.w()
        self.w("Wall time of a multibody simulation (analysis when needed, a factorization "
               "and solves per Newton step) with strata on the CPU and on a GPU: time per "
               "step and the share of it spent in the solver.")
        self.w()
        js = [r for r in runs if r.kind == "simulate"]
        for r in js:
            self.generic_run(r)
        logs_dir = os.path.join(self.results_dir, "logs")
        # run_mbd.sh's logs (mbd-*.log), newest by the UTC time stamp in the name
        logs = sorted((n for n in os.listdir(logs_dir)
                       if n.startswith("mbd") and n.endswith(".log")),
                      key=lambda n: (re.findall(r"\d{8}T\d{4,6}Z?", n) or [""])[-1] + n
                      ) if os.path.isdir(logs_dir) else []
        if not logs and not js:
            self.w(f"{NOT_MEASURED}: no `simulate` results and no `logs/*mbd*.log`; on a lent "
                   f"GPU machine, `scripts/gpu/prepare.sh` here, then `bash "
                   f"scripts/gpu/run_mbd.sh` there (with `.carry`), and copy its "
                   f"`$OUT/mbd.log` to `bench/results/logs/mbd-gpu-<UTC time>.log`.")
            self.w()
            return
        if logs:
            self.e2e_log(os.path.join(logs_dir, logs[-1]))

    def e2e_log(self, path: str) -> None:
        name = os.path.basename(path)
        with open(path, encoding="utf-8", errors="replace") as f:
            header, all_rs = parse_mbd_log(f.read())
        rs = [r for r in all_rs if "time" in r]
        bad = [r["name"] for r in all_rs if "time" not in r]
        link = f"[`logs/{name}`]({self.rel(path)})"
        if bad:
            self.w(f"Runs in the log without a complete summary (failed or cut off, not "
                   f"shown): {', '.join(bad)}.")
            self.w()
        if not rs:
            self.w(f"{NOT_MEASURED}: {link} holds no complete `strata simulate` summary.")
            self.w()
            return
        rows = []
        for r in rs:
            n, nnz, nnzl = r.get("matrix", ("–",) * 3)
            tot, sol, share = r["time"]
            asm = r.get("assembly", ("–", "–"))
            ps = r.get("per_step", ("–", "–"))
            st = r.get("strata", ("–",) * 3)
            thr = re.search(r"--threads (\d+)", r["args"])
            dev = r.get("device", ("?",))[0]
            rows.append([r["name"], f"`{model_of(r['args'])}`",
                         dev + (f" ({thr.group(1)} threads)" if thr and dev == "cpu" else ""),
                         r.get("steps", ("–",))[0], f"{int(n):,}" if n != "–" else n,
                         f"{int(nnzl):,}" if nnzl != "–" else nnzl, tot, f"{sol} ({share}%)",
                         f"{asm[0]} ({asm[1]}%)", ps[0], ps[1], " / ".join(st),
                         r.get("result", ("–",))[0]])
        self.w(f"From {link}, the text summaries of `strata simulate --quiet --output \"\"` "
               f"(scripts/gpu/run_mbd.sh), parsed by this generator. *ran on*: the device "
               f"strata reports (`--device auto` picks it), with the CPU runs' thread "
               f"count; per step: averages over the "
               f"accepted steps, start-up included; strata: milliseconds per call.")
        self.w()
        self.w(table(["run", "model and arguments", "ran on", "steps", "Newton matrix n",
                      "nnz(L)", "total s", "solver s (share)", "assembly s (share)",
                      "solver ms/step", "assembly ms/step",
                      "strata analysis / factorization / solve ms", "result"], rows, 3))
        by_model: dict[str, dict[str, dict]] = {}
        for r in rs:
            by_model.setdefault(model_of(r["args"]), {})[r.get("device", ("?",))[0]] = r
        pairs = [(m, d["cpu"], d["cuda"]) for m, d in by_model.items()
                 if "cpu" in d and "cuda" in d]
        for m, c, g in pairs:
            sc, sg = float(c["per_step"][0]), float(g["per_step"][0])
            fc, fg = float(c["strata"][1]), float(g["strata"][1])
            verdict = ("faster" if sg < sc else "**slower**")
            thr = re.search(r"--threads (\d+)", c["args"])
            thr = f" with {thr.group(1)} threads" if thr else ""
            self.w(f"`{m}`: the solver takes {sg:g} ms per step on the GPU against {sc:g} on "
                   f"the CPU{thr} ({sc / sg:.2f}×: the GPU is {verdict}); one factorization "
                   f"{fg:g} ms against {fc:g} ms ({fc / fg:.2f}×); whole run "
                   f"{g['time'][0]} s against {c['time'][0]} s.")
            self.w()
        if not pairs:
            self.w("No model was run on both the CPU and the GPU in this log, so there is no "
                   "CPU vs GPU comparison.")
            self.w()
        fig, ax = self.plt.subplots(figsize=(max(6, 1.2 * len(rs) + 2), 4.5))
        labels = [f"{r['name']}\n({r.get('device', ('?',))[0]})" for r in rs]
        solver = [float(r["per_step"][0]) if "per_step" in r else 0 for r in rs]
        assembly = [float(r["per_step"][1]) if "per_step" in r else 0 for r in rs]
        ax.bar(range(len(rs)), solver, label="solver")
        ax.bar(range(len(rs)), assembly, bottom=solver, label="assembly")
        ax.set_xticks(range(len(rs)))
        ax.set_xticklabels(labels, fontsize=8)
        ax.set_ylabel("ms per step")
        ax.set_title("strata simulate: time per step", fontsize=10)
        ax.grid(True, axis="y", alpha=0.3)
        ax.legend(fontsize=8)
        self.savefig_log(fig, f"simulate-{machine_slug((name,))}", "time per step", path,
                         header)

    def savefig_log(self, fig, stem: str, alt: str, path: str, header: dict) -> None:
        """Like savefig, captioned from a log's header (or the same session's results)."""
        os.makedirs(self.plot_dir, exist_ok=True)
        fig.tight_layout()
        fig.savefig(os.path.join(self.plot_dir, stem + ".png"), dpi=100,
                    metadata={"Software": None})
        self.plt.close(fig)
        self.plots.append(stem + ".png")
        self.w(f"![{alt}](plots/{stem}.png)")
        self.w()
        name = os.path.basename(path)
        link = f"results file [`logs/{name}`]({self.rel(path)})"
        if header:
            what = ", ".join(f"{k} {v}" for k, v in header.items())
            self.w(f"*Table and plot: parsed from the log. Measured with "
                   f"`scripts/gpu/run_mbd.sh` ({what}); {link}.*")
        else:
            stamp = re.search(r"(\d{8}T\d{6}Z)", name)
            same = [r for r in self.all_runs if stamp and stamp.group(1) in r.name]
            if same:
                self.w(f"*Table and plot: parsed from the log. Measured with "
                       f"`scripts/gpu/run_mbd.sh`; the log records no machine, date or commit: "
                       f"those of the results file with the same time stamp, from the same "
                       f"session on the lent machine, are {self.source(same[0])}. Log: "
                       f"{link}.*")
            else:
                self.w(f"*Table and plot: parsed from the log. Measured with "
                       f"`scripts/gpu/run_mbd.sh`; the log records no machine, date or "
                       f"commit. Log: {link}.*")
        self.w()
