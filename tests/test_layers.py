#!/usr/bin/env python3
"""The layering of src/ (ctest `source_layers`): the folders of src/ are listed in
docs/architecture.md's folder table from the ground up, and a file of src/ includes only
headers of its own folder, of folders listed before it, and the public headers
(include/strata). Every folder of src/ must be in the table. Exit status 1 with the list
of includes that run back up (file:line, the folder included).
"""
import os
import re
import sys

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"')


def layer_order():
    text = open(os.path.join(REPO, "docs", "architecture.md"), encoding="utf-8").read()
    return re.findall(r"^\| `src/([a-z_]+)/` \|", text, flags=re.M)


def main():
    order = layer_order()
    src = os.path.join(REPO, "src")
    problems = []
    folders = sorted(d for d in os.listdir(src) if os.path.isdir(os.path.join(src, d)))
    for d in folders:
        if d not in order:
            problems.append(f"src/{d}/ is not in docs/architecture.md's folder table")
    if problems:
        print("\n".join(problems))
        return 1
    up = 0
    for d in folders:
        for root, _, names in os.walk(os.path.join(src, d)):
            for name in sorted(names):
                path = os.path.join(root, name)
                with open(path, encoding="utf-8", errors="replace") as f:
                    for number, line in enumerate(f, 1):
                        m = INCLUDE.match(line)
                        if not m or "/" not in m.group(1):
                            continue
                        target = m.group(1).split("/")[0]
                        if target in order and order.index(target) > order.index(d):
                            up += 1
                            problems.append(f"{os.path.relpath(path, REPO)}:{number}: includes "
                                            f"{m.group(1)} (src/{target}/ is above src/{d}/)")
    if problems:
        print("\n".join(problems))
        print(f"{up} includes run back up; layer order: {', '.join(order)}")
        return 1
    print(f"no include runs back up; layer order: {', '.join(order)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
