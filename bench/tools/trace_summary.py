#!/usr/bin/env python3
"""Sums a GPU timeline written by bench/tools/cupti_trace.cpp (CSV: kind, device, stream,
start_ns, end_ns, bytes, detail; the host's CUDA runtime calls are kind "api", device -1,
stream the calling thread).

The timeline is cut into windows: runs of activity separated by an idle gap of at least
--gap milliseconds on every device (a benchmark's factorizations and solves are separated
by host work). Without --window it lists the windows (start, length, activities, kernels'
busy time per device); with --window K (0-based, negative from the end) it sums window K:
per device the busy time (the union of its activities' intervals), per kernel name and per
copy kind the count and the summed time, copy bytes and rate, the largest idle gaps inside
the window, and with --timeline N its first N activities in order. With --api MS it also
lists the host's runtime calls (recorded with STRATA_CUPTI_API=1) of at least MS milliseconds from --lead milliseconds before
the window to its end, and sums the calls by thread and name.

    python3 bench/tools/trace_summary.py trace.csv
    python3 bench/tools/trace_summary.py trace.csv --window -1 --top 25
"""

import argparse
import csv
import re
import sys
from collections import defaultdict


def load(path):
    rows = []
    with open(path, newline="") as f:
        for r in csv.DictReader(f):
            rows.append(
                {
                    "kind": r["kind"],
                    "device": int(r["device"]),
                    "stream": int(r["stream"]),
                    "start": int(r["start_ns"]),
                    "end": int(r["end_ns"]),
                    "bytes": int(r["bytes"]),
                    "detail": r["detail"],
                }
            )
    rows.sort(key=lambda r: r["start"])
    return rows


def windows(rows, gap_ns):
    """Runs of activity with no idle gap of gap_ns or more between them (all devices)."""
    out, cur, end = [], [], None
    for r in rows:
        if cur and r["start"] - end >= gap_ns:
            out.append(cur)
            cur = []
        if not cur:
            end = r["end"]
        cur.append(r)
        end = max(end, r["end"])
    if cur:
        out.append(cur)
    return out


def union_ns(intervals):
    """Total length of the union of [start, end) intervals."""
    total, last = 0, None
    for s, e in sorted(intervals):
        if last is None or s > last:
            total += e - s
            last = e
        elif e > last:
            total += e - last
            last = e
    return total


def short_name(detail):
    """A kernel's name without its template arguments, parameters and launch shape."""
    name = detail.split(" grid=")[0]
    name = re.sub(r"\(.*", "", name)
    depth, out = 0, []
    for c in name:
        if c == "<":
            depth += 1
        elif c == ">":
            depth -= 1
        elif depth == 0:
            out.append(c)
    return "".join(out).strip() or name


def list_windows(ws):
    print(f"{'window':>6} {'start ms':>10} {'length ms':>10} {'activities':>10}  busy ms per device")
    t0 = ws[0][0]["start"] if ws else 0
    for i, w in enumerate(ws):
        length = max(r["end"] for r in w) - w[0]["start"]
        busy = defaultdict(list)
        for r in w:
            busy[r["device"]].append((r["start"], r["end"]))
        per = ", ".join(f"{d}: {union_ns(v) / 1e6:.3f}" for d, v in sorted(busy.items()))
        print(f"{i:>6} {(w[0]['start'] - t0) / 1e6:>10.3f} {length / 1e6:>10.3f} {len(w):>10}  {per}")


def host_calls(api, t0, t1, lead_ns, min_ns):
    """The runtime calls that start in [t0 - lead, t1]: the long ones, and sums by thread."""
    calls = [r for r in api if t0 - lead_ns <= r["start"] <= t1]
    if not calls:
        return
    print(f"\nhost runtime calls from {lead_ns / 1e6:.1f} ms before the window (ms from its start):")
    by = defaultdict(lambda: [0, 0])
    for r in calls:
        v = by[(r["stream"], r["detail"])]
        v[0] += 1
        v[1] += r["end"] - r["start"]
    for (thread, name), (n, ns) in sorted(by.items(), key=lambda kv: -kv[1][1])[:15]:
        print(f"  thread {thread:>10} {name:<40} {n:>6} calls {ns / 1e6:>9.3f} ms")
    for r in calls:
        if r["end"] - r["start"] >= min_ns:
            print(
                f"  {(r['start'] - t0) / 1e6:>9.3f} {(r['end'] - r['start']) / 1e6:>8.3f} "
                f"thread {r['stream']:>10} {r['detail']}"
            )


def summarize(w, top, timeline):
    t0 = w[0]["start"]
    t1 = max(r["end"] for r in w)
    print(f"window: {(t1 - t0) / 1e6:.3f} ms, {len(w)} activities")
    devices = sorted({r["device"] for r in w})
    for d in devices:
        mine = [r for r in w if r["device"] == d]
        kern = [(r["start"], r["end"]) for r in mine if r["kind"] == "kernel"]
        copy = [(r["start"], r["end"]) for r in mine if r["kind"] != "kernel"]
        allv = kern + copy
        first = min(s for s, _ in allv)
        last = max(e for _, e in allv)
        print(
            f"device {d}: active {(first - t0) / 1e6:.3f}..{(last - t0) / 1e6:.3f} ms, busy "
            f"{union_ns(allv) / 1e6:.3f} ms (kernels {union_ns(kern) / 1e6:.3f}, copies and "
            f"memsets {union_ns(copy) / 1e6:.3f}), streams {len({r['stream'] for r in mine})}"
        )
        gaps, last_end = [], None
        for s, e in sorted(allv):
            if last_end is not None and s > last_end:
                gaps.append((s - last_end, last_end))
            last_end = e if last_end is None else max(last_end, e)
        gaps.sort(reverse=True)
        if gaps:
            print(
                "  largest idle gaps (ms at): "
                + ", ".join(f"{g / 1e6:.3f} @ {(at - t0) / 1e6:.3f}" for g, at in gaps[:6])
                + f"; {len(gaps)} gaps, {sum(g for g, _ in gaps) / 1e6:.3f} ms in all"
            )
    by = defaultdict(lambda: [0, 0, 0])  # count, ns, bytes
    for r in w:
        key = (r["device"], r["kind"], short_name(r["detail"]) if r["kind"] == "kernel" else r["detail"])
        v = by[key]
        v[0] += 1
        v[1] += r["end"] - r["start"]
        v[2] += r["bytes"]
    print(f"\n{'dev':>3} {'kind':<10} {'count':>6} {'ms':>9} {'GB':>7} {'GB/s':>7}  name")
    for (d, kind, name), (n, ns, b) in sorted(by.items(), key=lambda kv: -kv[1][1])[:top]:
        rate = f"{b / ns:7.1f}" if b and ns else ""
        gb = f"{b / 1e9:7.3f}" if b else ""
        print(f"{d:>3} {kind:<10} {n:>6} {ns / 1e6:>9.3f} {gb:>7} {rate:>7}  {name[:90]}")
    if timeline:
        print(f"\n{'start ms':>9} {'ms':>8} dev str kind       detail")
        for r in w[:timeline]:
            print(
                f"{(r['start'] - t0) / 1e6:>9.3f} {(r['end'] - r['start']) / 1e6:>8.3f} {r['device']:>3} "
                f"{r['stream']:>3} {r['kind']:<10} {r['detail'][:100]} {r['bytes'] or ''}"
            )


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("trace")
    ap.add_argument("--gap", type=float, default=2.0, help="idle milliseconds that end a window")
    ap.add_argument("--window", type=int, help="the window to sum (negative: from the end)")
    ap.add_argument("--top", type=int, default=20, help="rows of the per-name table")
    ap.add_argument("--timeline", type=int, default=0, help="print the window's first N activities")
    ap.add_argument("--api", type=float, help="list the host's runtime calls of at least this many ms")
    ap.add_argument("--lead", type=float, default=5.0, help="ms before the window whose calls --api lists")
    a = ap.parse_args()
    rows = load(a.trace)
    api = [r for r in rows if r["kind"] == "api"]
    rows = [r for r in rows if r["kind"] != "api"]
    if not rows:
        sys.exit(f"{a.trace}: no activities")
    ws = windows(rows, int(a.gap * 1e6))
    if a.window is None:
        list_windows(ws)
    else:
        w = ws[a.window]
        summarize(w, a.top, a.timeline)
        if a.api is not None:
            host_calls(api, w[0]["start"], max(r["end"] for r in w), int(a.lead * 1e6), int(a.api * 1e6))


if __name__ == "__main__":
    main()
