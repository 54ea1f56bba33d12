"""The README's performance table and the hand-written history, for bench/report.py.

The README carries a short table of the headline ratios (strata against CHOLMOD, MUMPS,
cuDSS, SuperLU), each the geometric mean over the problems of the newest untagged run
(and, on its own lines, of the newest cuDSS run tagged "mbd": the multibody Newton matrices),
with its machine, date and results file. bench/report.py computes the ratios (Report.
key_ratio) and this module writes them between two marker lines of README.md, leaving the
rest of the file as it is. bench/history.md (notes on what each change measured) is
copied to the end of REPORT.md. Standard library only.
"""
from __future__ import annotations

import os

from report_common import f_ratio

BEGIN = ("<!-- performance table: written by bench/report.py from bench/results; "
         "edits between these lines are lost -->")
END = "<!-- end of the performance table -->"

# the rows' order: by the start of their description
ORDER = ("factorization time, strata / CHOLMOD", "factorization time, strata / MUMPS",
         "analysis time", "nnz(L)", "GPU refactorization time, strata / cuDSS (each",
         "GPU refactorization time, strata / cuDSS (strata", "GPU solve time, strata / cuDSS (",
         "GPU refactorization time, strata / cuDSS, multibody Newton matrices (each",
         "GPU refactorization time, strata / cuDSS, multibody Newton matrices (strata",
         "GPU solve time, strata / cuDSS, multibody",
         "solve from Python, strata / scipy", "solve from Python, strata / CHOLMOD")


def _rank(what: str) -> int:
    for i, prefix in enumerate(ORDER):
        if what.startswith(prefix):
            return i
    return len(ORDER)


def _machine(machine: tuple) -> str:
    cpu, threads, gpu = machine
    return f"{gpu} ({threads} CPU threads)" if gpu else f"{cpu or 'CPU'}, {threads} threads"


def readme_table(key_ratios: list[dict], readme_dir: str) -> str:
    """The markdown table of the headline ratios; results files linked relative to
    readme_dir."""
    if not key_ratios:
        return ("No results yet: `bench/run cpu` measures this machine, then "
                "`python3 bench/report.py` fills this table.\n")
    rows = []
    for k in sorted(key_ratios, key=lambda k: (_rank(k["what"]), k["run"].date)):
        run = k["run"]
        link = os.path.relpath(run.path, readme_dir)
        rows.append([k["what"], f"**{f_ratio(k['ratio'])}**", str(k["problems"]),
                     _machine(run.machine), run.date[:10], f"[`{run.name}`]({link})"])
    head = ["ratio (below 1: strata faster or smaller)", "geometric mean", "problems",
            "machine", "date", "results"]
    lines = ["| " + " | ".join(head) + " |", "| --- | ---: | ---: | --- | --- | --- |"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return ("\n".join(lines) + "\n"
            + "\nEach ratio is the geometric mean over the problems of the newest run of "
              "its kind; every figure, plot and caveat is in "
              "[bench/REPORT.md](bench/REPORT.md).\n")


def update_readme(path: str, block: str) -> str | None:
    """Replaces the text between BEGIN and END in the file at path by block; returns an
    error message, or None when done."""
    try:
        with open(path, encoding="utf-8") as f:
            text = f.read()
    except OSError as e:
        return f"{path}: {e.strerror}"
    i, j = text.find(BEGIN), text.find(END)
    if i < 0 or j < i:
        return f"{path}: no performance table markers ({BEGIN!r} ... {END!r})"
    new = text[:i + len(BEGIN)] + "\n" + block + text[j:]
    if new != text:
        tmp = path + ".tmp"
        with open(tmp, "w", encoding="utf-8") as f:
            f.write(new)
        os.replace(tmp, path)
    return None


def history_section(path: str) -> str:
    """bench/history.md for the end of REPORT.md: its title dropped, its sections one
    level down under a heading of their own. "" when the file does not exist."""
    if not os.path.isfile(path):
        return ""
    with open(path, encoding="utf-8") as f:
        lines = f.read().splitlines()
    if lines and lines[0].startswith("# "):
        lines = lines[1:]
    while lines and not lines[0].strip():
        lines = lines[1:]
    out = ["## History (hand-written notes, `bench/history.md`)", ""]
    for line in lines:
        out.append("#" + line if line.startswith("## ") else line)
    return "\n".join(out).rstrip() + "\n"
