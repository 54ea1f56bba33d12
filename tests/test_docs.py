#!/usr/bin/env python3
"""Checks of the user documentation (ctest `docs_links`):
  - README.md is under 200 lines and opens with the two commands of the project's rules
    (set up, build and simulate the default model; set up, build and test);
  - every link of README.md, docs/*.md and bench/history.md resolves to a file or folder
    inside the repository, and README.md links nothing outside it (no URL, nothing above
    the repository's root).
Exit status 1 with the list of problems.
"""
import os
import re
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
LINK = re.compile(r"\]\(([^)\s]+)\)")


def main():
    problems = []
    readme = os.path.join(REPO, "README.md")
    text = open(readme, encoding="utf-8").read()
    lines = text.splitlines()
    if len(lines) >= 200:
        problems.append(f"README.md has {len(lines)} lines (at most 199)")
    commands = [ln.strip() for ln in lines if ln.startswith("    ")]
    want = ["bash scripts/setup.sh && bash scripts/build.sh && ./build/strata simulate",
            "bash scripts/test.sh"]
    if commands[:2] != want:
        problems.append(f"README.md's first two commands are {commands[:2]}, not {want}")
    files = [readme, os.path.join(REPO, "bench", "history.md")]
    docs = os.path.join(REPO, "docs")
    files += [os.path.join(docs, n) for n in sorted(os.listdir(docs)) if n.endswith(".md")]
    for path in files:
        body = open(path, encoding="utf-8").read()
        for target in LINK.findall(body):
            name = os.path.relpath(path, REPO)
            if re.match(r"[a-z]+:", target):
                if path == readme:
                    problems.append(f"{name}: link leaves the repository: {target}")
                continue
            dest = os.path.normpath(os.path.join(os.path.dirname(path), target.split("#")[0]))
            if not dest.startswith(REPO + os.sep):
                problems.append(f"{name}: link leaves the repository: {target}")
            elif not os.path.exists(dest):
                problems.append(f"{name}: broken link: {target}")
    for p in problems:
        print("FAIL: " + p)
    if not problems:
        print(f"ok: {len(files)} files, README.md {len(lines)} lines")
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
