#!/usr/bin/env python3
"""strata — cost model of the distributed factorization (docs/distributed.md §4).

What: predicts the factorization time of a 3D grid problem (7-point Laplacian, or 3D
elasticity with 3 unknowns per node) on R ranks × G GPUs, from

  * the fronts of geometric nested dissection of the grid: a box is cut by the plane
    across its longest side; the separator's front has the plane's unknowns as pivots and
    the box's faces that border earlier separators as its contribution block (the classic
    picture: separators ~ n^(2/3) unknowns; George 1973, Liu 1992 §3);
  * rates and bandwidths measured on one machine (the files below), and link figures
    for several machines that are assumptions, stated in ASSUMED;
  * the split of the tree that strata makes: ~4 subtrees per worker, the separators above
    them the top part.

Two schedules are modelled:
  current  — what strata does now: subtrees on every GPU, their roots' contribution blocks
             to rank 0 (host buffers through MPI, or NCCL), the whole top part on rank
             0's first GPU;
  tiled    — the design of docs/distributed.md §1: the top separators' fronts split into
             1024×1024 tiles over the GPUs of the subtree below them (subtree-to-subcube
             mapping), 2D block-cyclic, panels broadcast along the grid rows and columns.

Calibration (cite: bench/results/…):
  multigpu-20261121T215148Z.json (4 H200, lap3d-80 and elast3d-40, 1/2/4 GPUs): per-GPU
    rate on subtrees (flops / busy seconds of workers 1-3), rate of the top part on GPU 0,
    the host-side time of a factorization outside the numeric driver, the subtree-root
    contribution-block bytes;
  gpu-memory-20261121T213929Z.json (H100): pinned PCIe 54.9 GB/s, DGEMM 64.5 TFLOP/s;
  strata's analysis (cudss-20261121T213723Z.json, H100): lap3d-100 and elast3d-50 factor flops.
With --measured runs of scripts/gpu/run_mpi.sh on a two-GPU machine, also:
  the 2-GPU benchmark calibrated on its own 1 x 1 / 1 x 2 / 2 x 1 runs (calibrate_two_gpu);
  one GPU's rate as a function of the size of its work, fitted on every part of the
    1 x 2 runs (calibrate_rate_curves), and the 8/64/512-GPU predictions made with it.

Usage: python3 bench/cost_model.py [--json OUT.json] [--measured RUN.json ...]
(--measured: JSON files of scripts/gpu/run_mpi.sh; each measurement is printed next to
its prediction.)
"""
import argparse
import functools
import heapq
import json
import math
import os
import sys

HERE = os.path.dirname(os.path.abspath(__file__))
RESULTS = os.path.join(HERE, "results")

# Link figures not measured here: stated assumptions (docs/distributed.md §4).
ASSUMED = {
    "nvlink_bytes_per_s": 150e9,  # H100/H200 NVLink 4, effective GPU-to-GPU (900 GB/s peak bidirectional)
    "mpi_shm_bytes_per_s": 8e9,  # OpenMPI shared-memory single-copy (CMA) between processes
    "ib_bytes_per_s_per_node": 50e9,  # one NDR 400 Gb/s port per node
    "message_latency_s": 5e-6,  # per message, inter-node
    "gpus_per_node": 8,
    "tile": 1024,  # tile order of the distributed top fronts (= max_block_size)
    "subtrees_per_worker": 4,
}


def load(name):
    with open(os.path.join(RESULTS, name)) as f:
        return json.load(f)


def calibrate():
    """Rates and overheads from the measured single-machine files."""
    mg = load("multigpu-20261121T215148Z.json")
    mem = load("gpu-memory-20261121T213929Z.json")
    cal = {"pcie_bytes_per_s": mem["device_figures"]["h2d_bytes_per_second"],
           "dgemm_flops_per_s": mem["device_figures"]["dgemm_flops_per_second"],
           "problems": {}}
    for prob in ("lap3d-80", "elast3d-40"):
        rows = {r["workers"]: r for r in mg["rows"] if r["problem"] == prob}
        one, four = rows[1], rows[4]
        devs = four["devices"]
        # workers 1..3 ran subtrees only: their rate is the subtree rate
        sub_rate = sum(d["flops"] for d in devs[1:]) / sum(d["busy_seconds"] for d in devs[1:])
        top_flops = four["top_flops_fraction"] * four["flops"]
        w0_sub_flops = devs[0]["flops"] - top_flops
        top_seconds = max(devs[0]["busy_seconds"] - w0_sub_flops / sub_rate, 1e-3)
        wall = devs[0]["busy_seconds"] + devs[0]["idle_seconds"]
        cal["problems"][prob] = {
            "flops": one["flops"],
            "one_gpu_seconds": one["factor_seconds"],
            "subtree_rate": sub_rate,
            "top_rate": top_flops / top_seconds,
            # factorization time outside the multi-worker driver (scaling, set-up)
            "host_seconds": four["factor_seconds"] - wall,
            "four_gpu_seconds": four["factor_seconds"],
            "subtree_cb_bytes_w4": sum(d["bytes_transferred"] for d in devs) / 2,
            "top_fraction_w4": four["top_flops_fraction"],
            "balance_w4": four["subtree_balance"],
            # entries of the lower triangle: 7-point (4 per row) / 27-point × 3×3 (41 per row)
            "nnz_lower": one["n"] * (4 if prob.startswith("lap") else 41),
            # pivots of the top part at 4 workers, from the geometric tree: the share of the
            # entries (about the same per pivot on a grid) that stays on rank 0
            "top_pivot_fraction_w4": top_pivot_fraction(prob, 4),
        }
    return cal


def top_pivot_fraction(prob, workers):
    """Pivots in the top part of strata's split of the geometric ND tree of `prob`, as a
    fraction of n."""
    fronts, root = problem_tree(prob)
    _, top = split(fronts, root, workers, ASSUMED["subtrees_per_worker"])
    n = sum(f["pivots"] for f in fronts)
    return sum(fronts[f]["pivots"] for f in top) / n


# ---- geometric nested dissection ------------------------------------------------------

def front_flops(k, m):
    """strata's count: sum over the k pivots of (rows at and below the pivot)^2."""
    s = lambda t: t * (t + 1) * (2 * t + 1) / 6.0
    return s(m) - s(m - k)


def nd_tree(nx, ny, nz, dof, leaf=64):
    """Fronts of geometric ND of an nx×ny×nz grid: list of dicts (depth, pivots, cb,
    flops, subtree_flops), and the tree as children lists. Box faces: 1 when the face
    borders an earlier separator (its nodes are rows of the fronts inside)."""
    fronts = []

    def box(dims, faces, depth):
        a, b, c = dims
        area = (b * c, b * c, a * c, a * c, a * b, a * b)
        cb = dof * sum(ar for ar, f in zip(area, faces) if f)
        nodes = a * b * c
        if nodes <= leaf or max(dims) < 3:
            k = dof * nodes
            fl = front_flops(k, k + cb)
            fronts.append({"depth": depth, "pivots": k, "cb": cb, "flops": fl,
                           "subtree_flops": fl, "children": []})
            return len(fronts) - 1
        axis = max(range(3), key=lambda i: dims[i])
        h = dims[axis] // 2
        left, right = list(dims), list(dims)
        left[axis], right[axis] = h, dims[axis] - h - 1
        fl_faces, fr_faces = list(faces), list(faces)
        fl_faces[2 * axis + 1] = 1
        fr_faces[2 * axis] = 1
        kids = [box(tuple(left), fl_faces, depth + 1), box(tuple(right), fr_faces, depth + 1)]
        k = dof * nodes // dims[axis]
        fl = front_flops(k, k + cb)
        fronts.append({"depth": depth, "pivots": k, "cb": cb, "flops": fl,
                       "subtree_flops": fl + sum(fronts[i]["subtree_flops"] for i in kids),
                       "children": kids})
        return len(fronts) - 1

    root = box((nx, ny, nz), (0, 0, 0, 0, 0, 0), 0)
    return fronts, root


_SPLITS = {}  # split()'s results by (tree, root, workers, per_worker, max_steps)


def split(fronts, root, workers, per_worker, max_steps=4096):
    """The split below, made once per tree and worker count (the trees of problem_tree are
    made once per name, and the 8-512-GPU tables ask for each split several times)."""
    key = (id(fronts), root, workers, per_worker, max_steps)
    if key not in _SPLITS:
        _SPLITS[key] = (fronts, _split(fronts, root, workers, per_worker, max_steps))
    subs, top = _SPLITS[key][1]
    return list(subs), list(top)


def _split(fronts, root, workers, per_worker, max_steps):
    """strata's split (schedule/tree_partition.cpp, Geist & Ng 1989): split the heaviest
    subtree into its children, score every state by LPT makespan + top work, keep the
    best state with at least workers × per_worker subtrees. Returns (subtree roots,
    top fronts). The heaviest subtree comes from a heap (ties: the earliest in the list,
    as max() over it would take), the top work is a running sum, and a state whose lower
    bound (its largest subtree or its mean load, + top work) cannot beat the best kept
    states is not scheduled — the same result as scoring every state."""
    subs, top = [root], []
    seq = 0
    heap = [(-fronts[root]["subtree_flops"], seq, root)]
    top_work = 0.0
    sub_total = fronts[root]["subtree_flops"]
    best_enough = best_any = None
    for step in range(max_steps):
        enough = len(subs) >= workers * per_worker
        if enough or step % 32 == 0:  # (states short of enough: sampled, for speed)
            bound = max(-heap[0][0], sub_total / workers) * (1 - 1e-12) + top_work
            beats_any = best_any is None or bound < best_any[0]
            beats_enough = enough and (best_enough is None or bound < best_enough[0])
            if beats_any or beats_enough:
                load = lpt_makespan([fronts[f]["subtree_flops"] for f in subs], workers)
                score = load + top_work
                state = None
                if best_any is None or score < best_any[0]:
                    state = (score, list(subs), list(top))
                    best_any = state
                if enough and (best_enough is None or score < best_enough[0]):
                    best_enough = state or (score, list(subs), list(top))
        f = heap[0][2]
        if not fronts[f]["children"]:
            break
        heapq.heappop(heap)
        subs.remove(f)
        top.append(f)
        top_work += fronts[f]["flops"]
        sub_total -= fronts[f]["subtree_flops"]
        for c in fronts[f]["children"]:
            subs.append(c)
            seq += 1
            heapq.heappush(heap, (-fronts[c]["subtree_flops"], seq, c))
            sub_total += fronts[c]["subtree_flops"]
    best = best_enough or best_any
    return best[1], best[2]


def lpt_makespan(works, workers):
    """Largest load of the LPT assignment (Graham 1969), with a heap."""
    heap = [0.0] * workers
    for w in sorted(works, reverse=True):
        heapq.heapreplace(heap, heap[0] + w)
    return max(heap)


def lpt(works, workers):
    load = [0.0] * workers
    owner = []
    for w in sorted(range(len(works)), key=lambda i: -works[i]):
        j = min(range(workers), key=lambda q: load[q])
        load[j] += works[w]
        owner.append((w, j))
    return load, dict(owner)


# ---- time of one factorization ---------------------------------------------------------

def tiled_top(fronts, top, W, link, flops_scale, rate_for):
    """Seconds of the top fronts in the tiled schedule (docs/distributed.md §1.5): a front at
    depth d gets the P = W / 2^d GPUs of its subcube, its tiles 2D block-cyclic, so it
    takes flops / (P · rate_for(flops)) plus 8 m²/√P bytes per GPU over NVLink (P ≤ 8) or
    the node's InfiniBand share, plus 2 log₂P latencies per tile column. The fronts of one
    depth run at once on disjoint subcubes, so a depth costs its slowest front and the
    depths add up. Returns (compute s, communication s)."""
    by_depth = {}
    for f in top:
        fr = fronts[f]
        P = max(1, W >> fr["depth"])
        flops = fr["flops"] * flops_scale
        compute = flops / (P * rate_for(flops))
        m = fr["pivots"] + fr["cb"]
        per_gpu = 8.0 * m * m / math.sqrt(P) if P > 1 else 0.0
        bw = link["nvlink"] if P <= ASSUMED["gpus_per_node"] else \
            link["ib_per_node"] / ASSUMED["gpus_per_node"]
        steps = math.ceil(fr["pivots"] / ASSUMED["tile"])
        lat = steps * 2 * math.log2(P) * ASSUMED["message_latency_s"] if P > 1 else 0
        c, t = by_depth.get(fr["depth"], (0.0, 0.0))
        by_depth[fr["depth"]] = (max(c, compute), max(t, per_gpu / bw + lat))
    return (sum(c for c, _ in by_depth.values()), sum(t for _, t in by_depth.values()))


def predict(fronts, root, ranks, gpus, cal, link, schedule="current", flops_scale=1.0):
    """Seconds of one factorization on ranks × gpus, with the parts that add up to it.
    link: bytes/s between two ranks (ingress of rank 0), transfers through host
    memory when link is the MPI path (then two PCIe crossings are added)."""
    W = ranks * gpus
    subs, top = split(fronts, root, W, ASSUMED["subtrees_per_worker"])
    sub_flops = [fronts[s]["subtree_flops"] * flops_scale for s in subs]
    load, owner = lpt(sub_flops, W)
    t_sub = max(load) / cal["subtree_rate"]
    top_flops = sum(fronts[f]["flops"] for f in top) * flops_scale
    # contribution blocks of subtree roots that leave their rank (rank of worker w: w // gpus)
    remote = sum(8.0 * fronts[subs[i]]["cb"] ** 2 for i in range(len(subs))
                 if owner[i] // gpus != 0)
    local = sum(8.0 * fronts[subs[i]]["cb"] ** 2 for i in range(len(subs))
                if owner[i] // gpus == 0)
    pcie = cal["pcie_bytes_per_s"]
    t_cb = remote / link["rank_bytes_per_s"] + (2 * remote / pcie if link["via_host"] else 0)
    t_cb += 2 * local / pcie if gpus > 1 else 0  # within rank 0: through host, as measured
    if schedule == "current":
        t_top = top_flops / cal["top_rate"]
        t_top_comm = 0.0
    else:
        # subtree-to-subcube: a top front at depth d gets W / 2^d GPUs, tiles 2D cyclic
        t_top, t_top_comm = tiled_top(fronts, top, W, link, flops_scale,
                                      lambda flops: cal["top_rate"])
    return {
        "ranks": ranks, "gpus_per_rank": gpus, "schedule": schedule,
        "subtrees": len(subs), "top_flops_fraction": top_flops / (top_flops + sum(sub_flops)),
        "subtree_seconds": t_sub, "cb_bytes_between_ranks": remote, "cb_seconds": t_cb,
        "top_seconds": t_top, "top_comm_seconds": t_top_comm,
        "host_seconds": cal["host_seconds"],
        "total_seconds": cal["host_seconds"] + t_sub + t_cb + t_top + t_top_comm,
    }


def predict_benchmark(c, ranks, gpus, pcie):
    """The 4-GPU benchmark, from the measured 4-worker split (same tree and subtrees for
    1×4, 2×2, 4×1: the analysis is made for 4 workers): subtrees at the measured subtree
    rate and balance, the top part at the measured top rate on rank 0's GPU, the subtree
    roots' blocks of the other ranks' workers ((R−1)/R of them, by LPT's even spread)
    through host memory and MPI (two PCIe crossings plus the shared-memory copy), the
    scaled values scattered (each rank r > 0 is sent the entries its subtrees' fronts
    assemble: the subtrees' share of the lower triangle, (R−1)/R of it off rank 0), and
    the rest ("host") calibrated so that 1 × 4 is the measured 4-GPU time of
    multigpu-20261121T215148Z.json."""
    W = ranks * gpus
    f = c["top_fraction_w4"]
    t_sub = (1 - f) * c["flops"] / W * c["balance_w4"] / c["subtree_rate"]
    t_top = f * c["flops"] / c["top_rate"]
    cb = c["subtree_cb_bytes_w4"]
    remote = cb * (ranks - 1) / ranks
    t_cb = remote / ASSUMED["mpi_shm_bytes_per_s"] + 2 * remote / pcie + 2 * (cb - remote) / pcie
    values = 8.0 * c["nnz_lower"] * (1 - c["top_pivot_fraction_w4"]) * (ranks - 1) / ranks
    t_values = values / ASSUMED["mpi_shm_bytes_per_s"]
    # everything the parts above leave out (scaling, set-up, host buffers, threads) is
    # taken from the 1 × 4 measurement, and assumed the same for 2 × 2 and 4 × 1
    base = t_sub + t_top + 2 * cb / pcie
    other = c["four_gpu_seconds"] - base
    return {"ranks": ranks, "gpus_per_rank": gpus, "top_flops_fraction": f,
            "subtree_seconds": t_sub, "top_seconds": t_top, "cb_bytes_between_ranks": remote,
            "cb_seconds": t_cb, "values_bytes": values, "values_seconds": t_values,
            "bytes_between_ranks": remote + values,
            "host_seconds": other,
            "total_seconds": other + t_sub + t_top + t_cb + t_values}


def calibrate_two_gpu(rows):
    """Rates from one run of scripts/gpu/run_mpi.sh on a two-GPU machine (rows of its 1 × 1,
    1 × 2 and 2 × 1 files, one problem): the subtree rate of GPU 1 in 1 × 2 (subtrees
    only), the top-part rate of GPU 0 there, the host-side time of 1 × 2 outside GPU 0's
    parts, and the links of 2 × 1 as its ranks measured them — the contribution blocks
    (RankStats::blocks_seconds, packing and NCCL included) and the scaled values
    (values_seconds, MPI from host memory). None when a configuration or figure is missing."""
    by = {(r.get("ranks"), r.get("gpus_per_rank")): r for r in rows}
    one, two, dist = by.get((1, 1)), by.get((1, 2)), by.get((2, 1))
    if not (one and two and dist) or len(two.get("devices", [])) < 2 or not dist.get("per_rank"):
        return None
    g0, g1 = two["devices"][0], two["devices"][1]
    top = [p for p in g0["parts"] if p["kind"] == "top"]
    if not top or "blocks_seconds" not in dist["per_rank"][0]:
        return None
    top_seconds = sum(p["end_seconds"] - p["start_seconds"] for p in top)
    rank0 = dist["per_rank"][0]
    values = dist["values_bytes_between_ranks"]
    return {
        "flops": one["flops"],
        "one_gpu_seconds": one["factor_seconds"],
        "top_flops_fraction": two["top_flops_fraction"],
        "subtree_rate": g1["flops"] / g1["busy_seconds"],
        "top_rate": sum(p["flops"] for p in top) / top_seconds,
        "host_seconds": two["factor_seconds"] - max(p["end_seconds"] for p in g0["parts"]),
        "blocks_bytes_per_s": (dist["bytes_between_ranks"] - values) / rank0["blocks_seconds"],
        "values_bytes_per_s": values / rank0["values_seconds"] if rank0["values_seconds"] else 0,
        "per_rank_flops": [r["factor_flops"] for r in dist["per_rank"]],
        "blocks_bytes": dist["bytes_between_ranks"] - values,
        "values_bytes": values,
    }


def predict_two_gpu(c, ranks, gpus):
    """1 × 2 or 2 × 1 from calibrate_two_gpu's figures (the current schedule): the host
    time, then (2 × 1) the values sent before any subtree starts, the busiest worker's
    subtrees at the subtree rate, (2 × 1) the blocks to rank 0, and the top part on one
    GPU at the top rate. Within one process the blocks go GPU to GPU beside the work
    (counted in the top part's measured rate), so 1 × 2 has no transfer term."""
    top = c["top_flops_fraction"] * c["flops"]
    sub = [f - (top if i == 0 else 0.0) for i, f in enumerate(c["per_rank_flops"])]
    t_sub = max(sub) / c["subtree_rate"]
    t_values = c["values_bytes"] / c["values_bytes_per_s"] if ranks > 1 and c["values_bytes_per_s"] else 0.0
    t_cb = c["blocks_bytes"] / c["blocks_bytes_per_s"] if ranks > 1 else 0.0
    t_top = top / c["top_rate"]
    return {"ranks": ranks, "gpus_per_rank": gpus, "host_seconds": c["host_seconds"],
            "values_seconds": t_values, "subtree_seconds": t_sub, "cb_seconds": t_cb,
            "top_seconds": t_top,
            "total_seconds": c["host_seconds"] + t_values + t_sub + t_cb + t_top}


# ---- rates that depend on the size of the work -------------------------------------------

def rate_of(curve, flops):
    """Flop rate of one GPU on a piece of `flops` flops by a fitted curve:
    r(F) = r_inf / (1 + (F_half / F)^beta) — a saturating form after Hockney's r_inf and
    n_1/2 (Hockney & Jesshope, "Parallel Computers 2", 1988, §1.3.3), with an exponent
    because the pieces here are subtrees and top parts whose largest fronts, not their
    count, grow with their flops."""
    if flops <= 0:
        return curve["r_inf"]
    return curve["r_inf"] / (1.0 + (curve["f_half"] / flops) ** curve["beta"])


def seconds_of(curve, flops):
    return curve.get("overhead_s", 0.0) + (flops / rate_of(curve, flops) if flops > 0 else 0.0)


def fit_rate_curve(points):
    """(r_inf, F_half, beta) minimizing the squared log error of the predicted seconds over
    points (flops, seconds): log t = log F − log r_inf + log(1 + (F_half/F)^beta), so for a
    given (F_half, beta) the best log r_inf is the mean of the residuals, in closed form;
    (F_half, beta) by a grid search refined around the best six times (no external solver;
    tens of points)."""
    pts = [(math.log(f), math.log(t), f) for f, t in points if f > 0 and t > 0]
    if len(pts) < 3:
        return None

    def best_for(lh, b):  # (error, log r_inf) for F_half = e^lh, beta = b
        g = [lf + math.log1p(math.exp(b * (lh - lf))) - lt for lf, lt, _ in pts]
        lr = sum(g) / len(g)
        return sum((x - lr) ** 2 for x in g), lr

    lh, b = math.log(1e11), 0.6
    e, lr = best_for(lh, b)
    best = (e, lr, lh, b)
    span = (8.0, 0.6)
    for _ in range(6):
        _, _, lh0, b0 = best
        for j in range(-8, 9):
            for k in range(-8, 9):
                cand_h, cand_b = lh0 + span[0] * j / 8, b0 + span[1] * k / 8
                if cand_b <= 0.05:
                    continue
                e, lr = best_for(cand_h, cand_b)
                if e < best[0]:
                    best = (e, lr, cand_h, cand_b)
        span = (span[0] / 4, span[1] / 4)
    e, lr, lh, b = best
    return {"r_inf": math.exp(lr), "f_half": math.exp(lh), "beta": b,
            "rms_log_error": math.sqrt(e / len(pts)), "points": len(pts)}


def calibrate_rate_curves(rows):
    """One GPU's rate as a function of the size of its work, from the 1 × 2 rows of runs
    of scripts/gpu/run_mpi.sh (several problems and sizes): each subtree part (flops,
    end − start) of either GPU for the subtree curve, each top part for the top curve; a
    subtree part of under 1e6 flops is no rate but the fixed cost of a part (median of
    their times), added to every subtree. None without 1 × 2 rows."""
    sub, top, tiny = [], [], []
    for r in rows:
        if (r.get("ranks"), r.get("gpus_per_rank")) != (1, 2):
            continue
        for d in r.get("devices", []):
            for p in d.get("parts", []):
                t = p["end_seconds"] - p["start_seconds"]
                if p["kind"] == "subtree":
                    (tiny if p["flops"] < 1e6 else sub).append((p["flops"], t))
                elif p["kind"] == "top":
                    top.append((p["flops"], t))
    s, t = fit_rate_curve(sub), fit_rate_curve(top)
    if not s or not t:
        return None
    tiny_t = sorted(x for _, x in tiny)
    s["overhead_s"] = tiny_t[len(tiny_t) // 2] if tiny_t else 0.0
    return {"subtree": s, "top": t,
            "subtree_points": sub, "top_points": top, "small_part_seconds": tiny_t}


def predict_curves(fronts, root, ranks, gpus, curves, link, schedule, flops_scale):
    """predict() with the size-dependent rates of calibrate_rate_curves: each worker's
    subtrees (LPT by flops) at the subtree curve's rate for each subtree's flops, plus
    the fixed cost of a part per subtree; the top part at the top curve's rate for its
    flops (current schedule), or each top front's share of its P GPUs at the rate of the
    whole front (tiled). The transfers as in predict(), over NCCL."""
    W = ranks * gpus
    subs, top = split(fronts, root, W, ASSUMED["subtrees_per_worker"])
    sub_flops = [fronts[s]["subtree_flops"] * flops_scale for s in subs]
    _, owner = lpt(sub_flops, W)
    busy = [0.0] * W
    for i, f in enumerate(sub_flops):
        busy[owner[i]] += seconds_of(curves["subtree"], f)
    t_sub = max(busy)
    top_flops = sum(fronts[f]["flops"] for f in top) * flops_scale
    remote = sum(8.0 * fronts[subs[i]]["cb"] ** 2 for i in range(len(subs))
                 if owner[i] // gpus != 0)
    t_cb = remote / link["rank_bytes_per_s"]
    t_top_comm = 0.0
    if schedule == "current":
        t_top = top_flops / rate_of(curves["top"], top_flops)
    else:
        # each GPU's share of a front's tiles at the rate of the whole front (tiles of a
        # fixed order run as fast as the front's own updates, not slower for being fewer
        # per GPU)
        t_top, t_top_comm = tiled_top(fronts, top, W, link, flops_scale,
                                      lambda flops: rate_of(curves["top"], flops))
    return {
        "ranks": ranks, "gpus_per_rank": gpus, "schedule": schedule, "rates": "size-dependent",
        "subtrees": len(subs), "top_flops_fraction": top_flops / (top_flops + sum(sub_flops)),
        "subtree_seconds": t_sub, "cb_bytes_between_ranks": remote, "cb_seconds": t_cb,
        "top_seconds": t_top, "top_comm_seconds": t_top_comm, "host_seconds": 0.0,
        "total_seconds": t_sub + t_cb + t_top + t_top_comm,
    }


def scaling_rows(prob, one, rows, predict_at):
    """The 8/64/512-GPU rows of one problem: predict_at(R, G, schedule) for each number of
    GPUs (8 per node) and both schedules, with the speed-up against `one` (the one-GPU
    numeric seconds); appended to `rows` and printed."""
    for W in (8, 64, 512):
        R, G = max(1, W // ASSUMED["gpus_per_node"]), min(W, ASSUMED["gpus_per_node"])
        for sched in ("current", "tiled"):
            p = predict_at(R, G, sched)
            p["problem"] = prob
            p["gpus"] = W
            p["one_gpu_numeric_seconds"] = one
            num = p["total_seconds"]
            p["speedup_vs_one_gpu"] = one / num
            rows.append(p)
            print(f"{prob:<12} {W:>5} {sched:<8} {100 * p['top_flops_fraction']:>5.1f}% "
                  f"{p['subtree_seconds']:>9.4f} {p['cb_bytes_between_ranks'] / 1e9:>7.2f} "
                  f"{p['cb_seconds']:>6.3f} {p['top_seconds']:>7.3f} "
                  f"{p['top_comm_seconds']:>10.3f} {num:>9.3f} {one / num:>8.1f}")


@functools.lru_cache(maxsize=None)
def problem_tree(name):
    """The geometric tree of a lap3d-N / elast3d-N problem (made once per name; callers
    read it and do not change it)."""
    kind, k = name.rsplit("-", 1)
    k = int(k)
    dof = 3 if kind.startswith("elast") else 1
    return nd_tree(k, k, k, dof)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--json", help="write every prediction here")
    ap.add_argument("--measured", nargs="*", default=[],
                    help="JSON of scripts/gpu/run_mpi.sh: print measurements beside predictions")
    args = ap.parse_args()
    cal = calibrate()
    import datetime
    out = {"benchmark": "cost_model", "tag": "prediction",
           "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%M:%SZ"),
           "machine": {"cpu": "model", "hardware_threads": 0, "gpu": ""},
           "command": " ".join(sys.argv), "rows": [],
           "assumed": ASSUMED, "calibration": cal, "benchmark_4gpu": [], "scaling": []}
    measured = []
    machines = []
    for path in args.measured:
        with open(path) as f:
            run = json.load(f)
        machines.append(run.get("machine", {}))
        for row in run.get("rows", []):
            # the configuration the driver ran with is the file's (a 1-rank row's own
            # gpus_per_rank has read 1 for 1 x 4)
            for k in ("ranks", "gpus_per_rank"):
                if k in run:
                    row[k] = run[k]
            measured.append(row)
    gpus = sorted({str(m["gpu"]) for m in machines if m.get("gpu")})

    print(f"# The 4-GPU benchmark (one machine: {', '.join(gpus) or 'GPU not recorded'}; "
          "MPI through host memory between ranks)")
    print(f"{'problem':<11} {'R x G':<6} {'top %':>6} {'subtree s':>9} {'CB MB':>8} "
          f"{'CB s':>6} {'vals s':>6} {'top s':>6} {'host s':>6} {'pred s':>7} {'meas s':>7} "
          f"{'pred MB':>8} {'meas MB':>8}")
    for prob in ("lap3d-80", "elast3d-40"):
        c = cal["problems"][prob]
        for R, G in ((1, 4), (2, 2), (4, 1)):
            p = predict_benchmark(c, R, G, cal["pcie_bytes_per_s"])
            p["problem"] = prob
            m = next((r for r in measured if r.get("problem") == prob and r.get("ranks") == R
                      and r.get("gpus_per_rank") == G), None)
            p["measured_seconds"] = m.get("factor_seconds") if m else None
            p["measured_bytes_between_ranks"] = m.get("bytes_between_ranks") if m else None
            out["benchmark_4gpu"].append(p)
            ms = f"{p['measured_seconds']:.3f}" if p["measured_seconds"] else "-"
            mb = (f"{p['measured_bytes_between_ranks'] / 1e6:.1f}"
                  if p["measured_bytes_between_ranks"] is not None else "-")
            print(f"{prob:<11} {R}x{G:<4} {100 * p['top_flops_fraction']:>5.1f}% "
                  f"{p['subtree_seconds']:>9.3f} {p['cb_bytes_between_ranks'] / 1e6:>8.1f} "
                  f"{p['cb_seconds']:>6.3f} {p['values_seconds']:>6.3f} {p['top_seconds']:>6.3f} "
                  f"{p['host_seconds']:>6.2f} {p['total_seconds']:>7.3f} {ms:>7} "
                  f"{p['bytes_between_ranks'] / 1e6:>8.1f} {mb:>8}")

    # the two-GPU benchmark, where the measured files have 1 × 1, 1 × 2 and 2 × 1 of a problem
    two_gpu = {}
    for row in measured:
        two_gpu.setdefault(row.get("problem"), []).append(row)
    header = False
    for prob, rows in sorted(two_gpu.items()):
        c = calibrate_two_gpu(rows)
        if not c:
            continue
        if not header:
            print("\n# The 2-GPU benchmark, calibrated on its own 1 x 1 and 1 x 2 runs and the "
                  "2 x 1 run's links")
            print(f"{'problem':<11} {'R x G':<6} {'host s':>6} {'vals s':>6} {'subtree s':>9} "
                  f"{'CB s':>6} {'top s':>6} {'pred s':>7} {'meas s':>7}")
            header = True
        out.setdefault("calibration_2gpu", {})[prob] = c
        for R, G in ((1, 2), (2, 1)):
            p = predict_two_gpu(c, R, G)
            p["problem"] = prob
            m = next((r for r in rows if r.get("ranks") == R and r.get("gpus_per_rank") == G), None)
            p["measured_seconds"] = m.get("factor_seconds") if m else None
            out.setdefault("benchmark_2gpu", []).append(p)
            ms = f"{p['measured_seconds']:.3f}" if p["measured_seconds"] else "-"
            print(f"{prob:<11} {R}x{G:<4} {p['host_seconds']:>6.3f} {p['values_seconds']:>6.3f} "
                  f"{p['subtree_seconds']:>9.3f} {p['cb_seconds']:>6.3f} {p['top_seconds']:>6.3f} "
                  f"{p['total_seconds']:>7.3f} {ms:>7}")

    # 8-512 GPUs with rates that depend on the size of the work, when the measured files
    # have 1 x 2 runs (of several sizes) to fit them on
    curves = calibrate_rate_curves(measured)
    if curves:
        out["rate_curves"] = curves
        print("\n# One GPU's rate against the size of its work, fitted on the 1 x 2 runs' parts "
              "(r(F) = r_inf / (1 + (F_half / F)^beta))")
        for k in ("subtree", "top"):
            c = curves[k]
            print(f"{k:<8} r_inf {c['r_inf'] / 1e12:6.1f} TFLOP/s  F_half {c['f_half']:.3g} flops  "
                  f"beta {c['beta']:.2f}  rms log error {c['rms_log_error']:.2f} "
                  f"({c['points']} parts)" +
                  (f"; fixed cost of a part {1e3 * c['overhead_s']:.2f} ms" if k == "subtree" else ""))
        nv = {"rank_bytes_per_s": ASSUMED["nvlink_bytes_per_s"], "via_host": False,
              "nvlink": ASSUMED["nvlink_bytes_per_s"],
              "ib_per_node": ASSUMED["ib_bytes_per_s_per_node"]}
        print("\n# 8, 64, 512 GPUs with the size-dependent rates (NCCL; 8 GPUs and one rank "
              "per node; the flop count of the measured 1 x 1 run where there is one)")
        print(f"{'problem':<12} {'GPUs':>5} {'schedule':<8} {'top %':>6} {'subtree s':>9} "
              f"{'CB GB':>7} {'CB s':>6} {'top s':>7} {'top comm s':>10} {'numeric s':>9} "
              f"{'speed-up':>8}")
        for prob in ("lap3d-100", "elast3d-50", "lap3d-200", "elast3d-100"):
            fronts, root = problem_tree(prob)
            model_flops = fronts[root]["subtree_flops"]
            one_row = next((r for r in measured if r.get("problem") == prob
                            and (r.get("ranks"), r.get("gpus_per_rank")) == (1, 1)), None)
            scale = one_row["flops"] / model_flops if one_row else 1.0
            if not one_row:  # the measured scale of the same kind's smaller problem
                base = "lap3d-100" if prob.startswith("lap") else "elast3d-50"
                b_row = next((r for r in measured if r.get("problem") == base
                              and (r.get("ranks"), r.get("gpus_per_rank")) == (1, 1)), None)
                if b_row:
                    bf, br = problem_tree(base)
                    scale = b_row["flops"] / bf[br]["subtree_flops"]
            # one GPU: the same model on one worker (its subtrees, then the top part)
            one = predict_curves(fronts, root, 1, 1, curves, nv, "current", scale)["total_seconds"]
            scaling_rows(prob, one, out.setdefault("scaling_size_dependent", []),
                         lambda R, G, sched: predict_curves(fronts, root, R, G, curves, nv,
                                                            sched, scale))

    print("\n# 8, 64, 512 GPUs (8 GPUs and one rank per node; inter-node "
          f"{ASSUMED['ib_bytes_per_s_per_node'] / 1e9:.0f} GB/s per node, NCCL)")
    ib = {"rank_bytes_per_s": ASSUMED["ib_bytes_per_s_per_node"], "via_host": False,
          "nvlink": ASSUMED["nvlink_bytes_per_s"],
          "ib_per_node": ASSUMED["ib_bytes_per_s_per_node"]}
    print(f"{'problem':<12} {'GPUs':>5} {'schedule':<8} {'top %':>6} {'subtree s':>9} "
          f"{'CB GB':>7} {'CB s':>6} {'top s':>7} {'top comm s':>10} {'numeric s':>9} "
          f"{'speed-up':>8}")
    for prob, base in (("lap3d-100", "lap3d-80"), ("elast3d-50", "elast3d-40"),
                       ("lap3d-200", "lap3d-80"), ("elast3d-100", "elast3d-40")):
        c = dict(cal["problems"][base])
        c["pcie_bytes_per_s"] = cal["pcie_bytes_per_s"]
        c["host_seconds"] = 0.0  # numeric part only: the host time is per machine, not per GPU
        fronts, root = problem_tree(prob)
        bf, br = problem_tree(base)
        scale = c["flops"] / bf[br]["subtree_flops"]
        one = fronts[root]["subtree_flops"] * scale / c["subtree_rate"]
        scaling_rows(prob, one, out["scaling"],
                     lambda R, G, sched: predict(fronts, root, R, G, c, ib, sched, scale))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)
        print(f"\nwritten: {args.json}")


if __name__ == "__main__":
    sys.exit(main())
