"""Shared pieces of the strata benchmark report (bench/report.py, bench/report_gpu.py,
bench/report_e2e.py): reading results files and formatting numbers. Standard library only.
"""
from __future__ import annotations

import hashlib
import json
import math
import os

NOT_MEASURED = "**Not measured yet**"
# Result kinds whose figures live in lists other than "rows" (rows may then be absent).
OTHER_LISTS = {"gpu_memory": ("solvability", "block_size")}


# --------------------------------------------------------------------------- results


def short_problem_names(node) -> None:
    """Problems given to a driver as Matrix Market paths (the multibody Newton matrices
    written on the device) are named by their file's stem, as the drivers name them now."""
    if isinstance(node, dict):
        p = node.get("problem")
        if isinstance(p, str) and "/" in p:
            node["problem"] = os.path.basename(p).split(".mtx")[0]
        for v in node.values():
            short_problem_names(v)
    elif isinstance(node, list):
        for v in node:
            short_problem_names(v)


class Run:
    """One results file."""

    def __init__(self, path: str, data: dict):
        self.path = path
        self.name = os.path.basename(path)
        self.data = data
        short_problem_names(data)
        self.kind = data["benchmark"]
        self.tag = data.get("tag") or ""
        self.backend = data.get("backend") or "cpu"
        self.date = data["date"]
        self.rows = data.get("rows") or []
        m = data["machine"]
        self.machine = (str(m.get("cpu", "")), int(m.get("hardware_threads", 0) or 0),
                        str(m.get("gpu", "") or ""))

    def get(self, key, default=None):
        return self.data.get(key, default)


def load_runs(results_dir: str) -> tuple[list[Run], list[tuple[str, str]]]:
    """All well-formed results files in results_dir, and (file, reason) for the others."""
    runs, skipped = [], []
    if not os.path.isdir(results_dir):
        return runs, skipped
    for name in sorted(os.listdir(results_dir)):
        if not name.endswith(".json"):
            continue
        path = os.path.join(results_dir, name)
        try:
            with open(path, encoding="utf-8") as f:
                data = json.load(f)
        except (OSError, ValueError) as e:
            skipped.append((name, f"cannot be read as JSON ({e.__class__.__name__})"))
            continue
        if not isinstance(data, dict):
            skipped.append((name, "not a JSON object"))
            continue
        lists = ("rows",) + OTHER_LISTS.get(data.get("benchmark"), ())
        missing = [k for k in ("benchmark", "date", "command", "git_commit", "machine")
                   if k not in data]
        if not any(k in data for k in lists):
            missing.append(" or ".join(lists))
        if missing:
            skipped.append((name, "missing " + ", ".join(missing)))
            continue
        if not all(isinstance(data.get(k, []), list) for k in lists) or not isinstance(
                data["machine"], dict):
            skipped.append((name, "'rows' is not a list or 'machine' is not an object"))
            continue
        runs.append(Run(path, data))
    return runs, skipped


def newest_runs(runs: list[Run]) -> list[Run]:
    """The newest run per (kind, machine, tag, backend); ties broken by file name."""
    best: dict[tuple, Run] = {}
    for r in runs:
        key = (r.kind, r.machine, r.tag, r.backend)
        if key not in best or (r.date, r.name) > (best[key].date, best[key].name):
            best[key] = r
    return sorted(best.values(), key=lambda r: (r.kind, r.machine, r.backend, r.tag))


def machine_label(machine: tuple) -> str:
    cpu, threads, gpu = machine
    s = f"{cpu or 'unknown CPU'}, {threads} hardware threads"
    return s + (f", GPU {gpu}" if gpu else ", no GPU")


def machine_slug(machine: tuple) -> str:
    return hashlib.sha1(repr(machine).encode()).hexdigest()[:8]


def by_machine(runs: list[Run]) -> dict[tuple, list[Run]]:
    out: dict[tuple, list[Run]] = {}
    for r in runs:
        out.setdefault(r.machine, []).append(r)
    return out


# --------------------------------------------------------------------------- numbers


def num(x):
    """x as a float when it is a finite number, else None."""
    if isinstance(x, bool) or not isinstance(x, (int, float)):
        return None
    return float(x) if math.isfinite(x) else None


def dig(d, *keys):
    for k in keys:
        if not isinstance(d, dict) or k not in d:
            return None
        d = d[k]
    return d


def geomean(v: list[float]) -> float | None:
    v = [x for x in v if x is not None and x > 0]
    return math.exp(sum(math.log(x) for x in v) / len(v)) if v else None


def ratio(a, b):
    a, b = num(a), num(b)
    return a / b if a is not None and b is not None and b > 0 else None


def f_ratio(x) -> str:
    return "–" if x is None else f"{x:.3f}"


def f_sec(x) -> str:
    x = num(x)
    return "–" if x is None else f"{x:.4g}"


def f_int(x) -> str:
    x = num(x)
    return "–" if x is None else f"{int(round(x)):,}"


def f_g(x) -> str:
    x = num(x)
    return "–" if x is None else f"{x:.3g}"


def f_e(x) -> str:
    x = num(x)
    return "–" if x is None else f"{x:.1e}"


def f_pct(x) -> str:
    x = num(x)
    return "–" if x is None else f"{x:+.2f}%"


def table(header: list[str], rows: list[list[str]], right_from: int = 1) -> str:
    align = ["---" if i < right_from else "---:" for i in range(len(header))]
    lines = ["| " + " | ".join(header) + " |", "| " + " | ".join(align) + " |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines) + "\n"
