#!/usr/bin/env python3
"""Test of bench/report.py on the fixture results in tests/data/bench_results/.

    python3 tests/test_report.py [--keep DIR]

The fixtures are shaped exactly like bench_analysis and bench_factor output and were
made with round ratios, so the expected figures below are worked out by hand:
  analysis  nnz(L) strata/CHOLMOD+METIS 1.21 and 1.0  -> geometric mean 1.100
            time   strata/CHOLMOD+METIS 2.0 and 8.0   -> 4.000
  factor    strata/CHOLMOD 1, 2, 4                    -> 2.000 (behind on 2 of 3)
            strata/MUMPS   0.5, 0.5, 0.5              -> 0.500 (not behind)
  an older factor run (marker 777) must not be shown; a run with an unknown tag (marker
  654.321) must land in "Other results"; a truncated file must be listed as skipped;
  the GPU factorization (bench_gpu) has no results and must say "Not measured yet".
  gpu_memory  GPU block sweep 256/1024/2048: 2, 1, 0.8 s -> best 2048, 1024/best 1.250;
            solvability slowdown up to 5.0 at 10x, time over the PCIe floor 100-500x;
            DGEMM 50 TFLOP/s, best in-core 125 GFLOP/s -> 0.25% of the peak
  cudss     refactor strata/cuDSS default 20 and 10 -> 14.142, strata perm. 4 and 5 -> 4.472;
            1e12 flops / 2 s = 500 GFLOP/s = 1.00% of the peak; bcsstk16's flops come from
            the factor fixture (same nnz(L)): 1.41e8 / 0.01 s = 14.1 GFLOP/s
  multigpu  cuda: 8, 4.8, 4 s on 1, 2, 4 GPUs -> speedups 1.67, 2.00; ablation at 4 GPUs
            1.200, 1.500, 1.100; a cpu-backend run (marker 0.0987) only under its own heading
  mbd log   solver 20 ms/step on the GPU vs 50 on the CPU (8 threads) -> 2.50x; a failed
            run is listed
  new-format fixtures (synthetic, machine "Fixture GPU 141GB"; the files say so):
  bench_gpu GPU 0.8 s, CPU best 4 s at 16 threads (8 at 4), CHOLMOD best 6 s at 4 threads
            -> CPU/GPU 5.000, CHOLMOD/GPU 7.500; tag "large": CPU/GPU 0.750 (GPU slower);
            phases 0.2/0.1/0.3/0/0.05/0.15 of 0.8 s -> largest: large fronts (37%)
  cudss     refactor 0.8 vs 0.2 -> 4.000; first solve 0.06 vs 0.03 / 0.02 -> 2.000 / 3.000,
            full solve 0.3 -> 10.000 / 15.000; large fronts 0.3 s > cuDSS's 0.2 -> 1.500
  multigpu  refactor 1, 1.25, 1.6 s on 1, 2, 4 GPUs (slower with more), first 5, 6, 7;
            lap3d-s1: 4 subtrees per GPU 1.0 / 0.8 s, then a newer run with 1 per GPU
            0.9 / 0.5 s -> the default is the newer (speedup 1.80, other subtrees 1.600 [4]),
            its estimated speedup 1.90 beside it;
            an older file (marker 9.99) is superseded; ablation file 1.250, 0.750, 1.100;
            ablation-split file: top split off 2.4 s -> 1.500, the default's split
            2 layers / 6 parts / 25% / 15%
  distrib.  1x4, 2x2, 4x1: 1, 1.5, 2 s vs predicted 2, 2.5, 2.5 -> 0.500, 0.600, 0.800;
            bytes 400/800 MB vs 200/400 -> 2.000; the 1x4 row says gpus_per_rank 1 (the
            file's 4 counts)
  cudss mbd a run tagged mbd: flexible-64x4x4 refactor 0.5 vs 1 ms -> 0.500, and bcsstk16
            (0.4 vs 0.2 ms, a bundled matrix, not a Newton matrix) left out of its
            "multibody Newton matrices" lines -> 0.500 over 1 problem
  python    overhead 1.00% on the large matrix (goal 5%: met); strata/SuperLU 0.25 and
            1.0 -> 0.500, strata/CHOLMOD 2.0 and 0.5 -> 1.000
Exit status 1 with a list of failed checks if anything is off.
"""
import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
FIXTURES = os.path.join(HERE, "data", "bench_results")
sys.path.insert(0, os.path.join(REPO, "bench"))
from report_readme import BEGIN as README_BEGIN, END as README_END  # noqa: E402


def sections(text):
    """{'## heading': body} for every level-2 heading."""
    out, cur = {}, None
    for line in text.splitlines():
        if line.startswith("## "):
            cur = line
            out[cur] = ""
        elif cur:
            out[cur] += line + "\n"
    return out


def section(secs, prefix):
    hits = [body for head, body in secs.items() if head.startswith(prefix)]
    return hits[0] if len(hits) == 1 else None


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--keep", help="write the report into this folder and keep it")
    args = ap.parse_args()
    out = args.keep or tempfile.mkdtemp(prefix="strata-report-test-")
    # a README with the performance table's markers, and hand-written history notes
    readme = os.path.join(out, "README.md")
    rm_before, rm_after = "# project\n\ntext before\n", "\ntext after\n"
    with open(readme, "w", encoding="utf-8") as f:
        f.write(rm_before + README_BEGIN + "\nstale table\n" + README_END + rm_after)
    history = os.path.join(out, "history.md")
    with open(history, "w", encoding="utf-8") as f:
        f.write("# Benchmark history\n\nmarker 31337\n\n## A change\n\nit got faster\n")
    proc = subprocess.run([sys.executable, os.path.join(REPO, "bench", "report.py"),
                           "--results", FIXTURES, "--out", out, "--readme", readme,
                           "--history", history],
                          capture_output=True, text=True)
    failures = []

    def check(cond, what):
        if not cond:
            failures.append(what)

    check(proc.returncode == 0, f"report.py exit status {proc.returncode}: {proc.stderr}")
    path = os.path.join(out, "REPORT.md")
    if not os.path.exists(path):
        print("FAIL: no REPORT.md written\n" + proc.stdout + proc.stderr)
        return 1
    text = open(path, encoding="utf-8").read()
    secs = sections(text)

    # --- summary: the key ratios, computed from the fixtures' rows
    summ = section(secs, "## Summary") or ""
    check(summ, "no Summary section")
    for what, value in (("nnz(L) strata/CHOLMOD+METIS", "1.100"),
                        ("analysis time strata/CHOLMOD+METIS", "4.000"),
                        ("factorization time strata/CHOLMOD", "2.000"),
                        ("factorization time strata/MUMPS", "0.500")):
        m = re.search(r"Geometric mean of " + re.escape(what) + r"[^*]*\*\*([0-9.]+)\*\*", summ)
        check(m and m.group(1) == value,
              f"summary: {what} should be {value}, found {m.group(1) if m else 'nothing'}")
    behind = summ.split("**Where strata is behind an anchor", 1)
    check(len(behind) == 2, "summary: no 'where strata is behind' statement")
    if len(behind) == 2:
        b = behind[1].split("Not behind", 1)[0]
        check("strata/CHOLMOD (same permutation" in b and "behind on 2 of 3 problems" in b
              and "elast3d-10, 4.000" in b,
              "summary: behind CHOLMOD in factorization (2 of 3, worst elast3d-10 4.000) not stated")
        check("analysis time strata/CHOLMOD+METIS" in b and "behind on 2 of 2" in b,
              "summary: behind CHOLMOD+METIS in analysis time not stated")
        check("nnz(L) strata/CHOLMOD+METIS" in b and "bcsstk16, 1.210" in b,
              "summary: behind CHOLMOD+METIS in nnz(L) (worst bcsstk16 1.210) not stated")
        check("strata/MUMPS" not in b, "summary: claims strata is behind MUMPS (it is not)")
    check(re.search(r"Not behind[^\n]*strata/MUMPS", summ),
          "summary: 'not behind MUMPS' not stated")

    # --- experiment 1: the sweep table, CPU measured, GPU not
    s1 = section(secs, "## 1.") or ""
    check(s1, "no section 1")
    check(re.search(r"\| problem \| 32 \| 256 \| 2048 \| best \| CHOLMOD s \|", s1),
          "section 1: sweep table header wrong")
    check(re.search(r"\| lap3d-20 \| 0\.9 \| 0\.5 \| 0\.6 \| 256 \| 0\.25–0\.26 \|", s1),
          "section 1: lap3d-20 sweep row wrong")
    check(re.search(r"\| elast3d-10 \| 2\.4 \| 1\.6 \| 1\.2 \| 2048 \| 0\.4 \|", s1),
          "section 1: elast3d-10 sweep row wrong")
    gpu1 = s1.split("### GPU", 1)
    g1 = gpu1[1] if len(gpu1) == 2 else ""
    check(re.search(r"\| lap3d-20 \| 8,000 \| 2 \| 1 \| 0\.8 \| 2048 \| 125 \| 1\.250 \|", g1),
          "section 1: GPU block sweep row wrong")
    check("(the CPU's default) costs" in g1 and "4096 for Cholesky on the GPU" in g1
          and "gpu-memory-20250103T100000Z.json" in g1,
          "section 1: GPU part does not say which defaults the block sizes are, or no file")
    for mbs in (32, 256, 2048):
        check(f"factor-mbs-{mbs}-2025" in s1, f"section 1: results file of mbs-{mbs} not named")

    # --- experiment 2
    s2 = section(secs, "## 2.") or ""
    check(re.search(r"\| \*\*geometric mean\*\* \|(?: *\|){7} 2\.000 \| 0\.500 \|", s2),
          "section 2: factor table geometric mean row wrong")
    check(re.search(r"\| bcsstk16 \| 4,884 \| 147,631 \| 968,000 \| 800,000 \| 1\.210 \|", s2),
          "section 2: analysis row bcsstk16 wrong")
    check("factor-20250102T100000Z.json" in s2 and "analysis-20250102T090000Z.json" in s2,
          "section 2: results files not named")
    check("bench_factor --problems bcsstk16,lap3d-20,elast3d-10 --threads 2 --repeat 3" in s2,
          "section 2: command of the factor run not in the caption")
    check("commit f1x7e5a" in s2 and "2025-01-02T10:00:00Z" in s2,
          "section 2: commit or date not in the caption")
    gpu2 = s2.split("### GPU: strata's CUDA backend", 1)
    bg = gpu2[1].split("### GPU: strata vs NVIDIA")[0] if len(gpu2) == 2 else ""
    # bench_gpu (new fields): best CPU of the thread counts 4 and 16, first solve, phases
    check(re.search(r"\| lap3d-new \| spd \| 512,000 \| 80,000,000 \| 1e\+12 \| 0\.8 \| "
                    r"1\.25e\+03 \| 4 \(16 thr\.\) \| 6 \(4 thr\.\) \| 5\.000 \| 7\.500 \| "
                    r"0\.06 \| 0\.3 \| 2 \|", bg) and "thread counts measured: 4, 16" in bg,
          "bench_gpu: row with thread counts / first solve wrong")
    check(re.search(r"\| lap3d-huge \|.*\| 0\.750 \| 1\.500 \|", bg)
          and "**The GPU is slower than the CPU backend** on lap3d-huge" in bg
          and "gpu-large-20250104T100500Z.json" in bg,
          "bench_gpu: the tagged run (GPU slower than CPU) is not shown or not stated")
    check(re.search(r"\| lap3d-new \| 0\.8 \| 0\.7 \| 0\.2 \(25%\) \| 0\.1 \(12%\) \| "
                    r"0\.3 \(37%\) \| 0 \(0%\) \| 0\.05 \(6%\) \| 0\.15 \(19%\) \| 0\.8 \| "
                    r"large fronts \|", bg), "bench_gpu: phase table row wrong")
    check("GPU-only profile" in bg and "gpu-profile-20250104T101000Z.json" in bg
          and re.search(r"\| lap3d-new \| 0\.75 \|.*\| assembly \|", bg),
          "gpu-profile: not shown as a phase table")
    cu = s2.split("### GPU: strata vs NVIDIA cuDSS", 1)
    cu = cu[1] if len(cu) == 2 else ""
    check(re.search(r"\| lap3d-big \| 20\.000 \| 4\.000 \| 20\.000 \| 4\.000 \|", cu),
          "cuDSS: ratio row lap3d-big wrong")
    check(re.search(r"\| \*\*geometric mean\*\* \| 10\.000 \| 11\.547 \| 14\.142 \| 4\.472 \|", cu),
          "cuDSS: geometric mean row wrong")
    check(re.search(r"\| lap3d-big \|.*\| 1e\+12 \| 500 \| 1\.00% \|", cu)
          and re.search(r"\| bcsstk16 \|.*\| 1\.41e\+08 \| 14\.1 \| 0\.03% \|", cu),
          "cuDSS: GFLOP/s or fraction of the DGEMM peak wrong")
    check("**10.0–20.0× slower**" in cu and re.search(r"large problems[^\n]*\*\*not met\*\*", cu)
          and re.search(r"40% of the DGEMM peak[^\n]*\*\*not met\*\*", cu),
          "cuDSS: being behind or the targets not stated plainly")
    check("cudss-20250103T110000Z.json" in cu and "commit 9a1b2c3" in cu,
          "cuDSS: results file or commit not named")
    # cuDSS, new fields: first solve vs cuDSS solve, full solve apart, phases beside cuDSS
    check(re.search(r"\| lap3d-new \| 0\.06 \| 0\.3 \| 2 \| 0\.03 \| 0\.02 \| 2\.000 \| "
                    r"3\.000 \| 10\.000 \| 15\.000 \|", cu), "cuDSS: solve comparison row wrong")
    check("takes 2.00–2.00× cuDSS's solve (default reordering): **slower on 1 of 1 problems**"
          in cu, "cuDSS: first solve behind cuDSS not stated")
    check(re.search(r"\| lap3d-new \| 0\.8 \|.*\| large fronts \|.*\| 0\.2 \| 4\.000 \| "
                    r"1\.500 \|", cu) and "strata's last refactorization is **4.00× cuDSS's**" in cu
          and "large fronts (0.3 s) alone takes longer than cuDSS's whole refactorization" in cu,
          "cuDSS: phase breakdown beside cuDSS's refactorization wrong")
    check(re.search(r"\| lap3d-new \| 10\.000 \| 6\.000 \| 4\.000 \| 2\.000 \|", cu),
          "cuDSS: new-format ratio row wrong")
    check(re.search(r"Not measured yet\*\* in this run: solve time", s2),
          "section 2: missing solve time not reported as not measured")

    # --- experiment 3: GPU runs are the experiment, CPU-backend runs apart
    s3 = section(secs, "## 3.") or ""
    g3, _, c3 = s3.partition("### CPU backend")
    check(re.search(r"\| lap3d-20 \| 8,000 \| 4\.9e\+08 \| 8 \| 4\.8 \| 4 \| 1\.67 \| 2\.00 \| 83% \| 50% \|",
                    g3), "section 3: speedup row wrong")
    check(re.search(r"\| lap3d-20 \| 4 \| 4 \| 4 \| 4\.8 \(1\.200\) \| 6 \(1\.500\) \[1\] \| 4\.4 \(1\.100\) \|",
                    g3), "section 3: ablation row wrong")
    check(re.search(r"\| lap3d-20 \| 2 \| 1 \| 3 \| 2 \| 60% \|", g3), "section 3: per-GPU row wrong")
    check("0.0987" not in g3 and "0.0987" in c3 and "not the experiment" in c3,
          "section 3: the CPU-backend run is mixed into the GPU experiment or not labelled")
    # new-format multigpu (first factorization apart) on another machine; old file superseded
    check("9.99" not in s3 and "multigpu-20250104T115000Z.json" in g3
          and "superseded" in g3, "section 3: the superseded old-format file is shown or not named")
    check("**Caution: these results files are of the older format**" in g3,
          "section 3: old-format multigpu results not flagged")
    check(re.search(r"\| lap3d-new \| 512,000 \| 1\.25e\+12 \| 1 \| 1\.25 \| 1\.6 \| 0\.80 \| "
                    r"0\.62 \|", g3) and "lap3d-new on 4 GPUs takes 1.60× the 1-GPU time" in g3,
          "section 3: new scaling row or 'slower with more GPUs' wrong")
    # the default subtrees per GPU is the most in the problem's newest run: lap3d-s1's
    # newer run has 1 per GPU (0.9 / 0.5 s), an older one 4 (1.0 / 0.8 s)
    check(re.search(r"\| lap3d-s1 \| 512,000 \| 1\.25e\+12 \| 0\.9 \| 0\.5 \| – \| 1\.80 \|"
                    r".*\| 1\.90 \| – \|", g3) and "*estimate W*" in g3
          and re.search(r"\| lap3d-s1 \| 2 \| 1 \| 0\.5 \| – \| 0\.8 \(1\.600\) \[4\] \|", g3),
          "section 3: the newest run's subtrees per GPU is not the default, or its estimated "
          "speedup is not shown beside the measured one")
    check(re.search(r"\| lap3d-new \| 4 \| 7 \| 1\.6 \| 5\.4 \| 4\.375 \|", g3),
          "section 3: first factorization vs refactorization row wrong")
    check(re.search(r"\| lap3d-abl \| 4 \| 4 \| 1\.6 \| 2 \(1\.250\) \| 1\.2 \(0\.750\) \[1\] \| "
                    r"1\.76 \(1\.100\) \| 2\.4 \(1\.500\) \| 2 / 6 / 25% / 15% \|", g3),
          "section 3: ablation from the ablation files (top split on/off) wrong")
    # --- experiment 3b: distributed vs the cost model
    s3b = section(secs, "## 3b.") or ""
    check(re.search(r"\| lap3d-new \| 1 × 4 \| 5 \| 1 \| – \| 2 \| 0\.500 \| 0 \| 0 \| – \|", s3b)
          and re.search(r"\| lap3d-new \| 2 × 2 \| 6 \| 1\.5 \| 1\.5 \| 2\.5 \| 0\.600 \| 400 \| "
                        r"200 \| 2\.000 \|", s3b)
          and re.search(r"\| lap3d-new \| 4 × 1 \| 7 \| 2 \| 2 \| 2\.5 \| 0\.800 \| 800 \| 400 \| "
                        r"2\.000 \|", s3b),
          "section 3b: measured vs predicted rows wrong (1x4 must come from the file's "
          "gpus_per_rank, not the row's)")
    check("4 ranks × 1 GPU takes 2.00× the time of 1 rank × 4 GPUs (**slower**" in s3b
          and "**The cost model is off by more than 1.5×** on lap3d-new 1 × 4" in s3b
          and "predictions, nothing measured" in s3b and "0.4321" in s3b
          and "cost-model.json" in s3b and "distributed-2x2-20250104T130100Z.json" in s3b,
          "section 3b: slower than one process, model error, model-only table or files missing")
    summ3 = section(secs, "## Summary") or ""
    check("lap3d-new on 4 ranks × 1 GPU is 2.00× slower than 1 rank × 4 GPUs" in summ3
          and "lap3d-new on 4 GPUs 1.60× the 1-GPU time" in summ3
          and "lap3d-huge (CPU/GPU 0.750)" in summ3
          and re.search(r"first solve \(one application of the factor, no refinement\)/cuDSS "
                        r"solve \(default reordering\): \*\*2\.000\*\*", summ3),
          "summary: multi-GPU, distributed, GPU-vs-CPU or first-solve behind statements missing")
    # --- experiment 4
    s4 = section(secs, "## 4.") or ""
    check(re.search(r"\| lap3d-20 \| 10× \| 10 \| 0\.5 \| 256 \| 5 \| 5\.00 \| 0\.05 \| 100\.000 \|", s4),
          "section 4: solvability row at 10x wrong")
    check(re.search(r"\| lap3d-20 \| 10× \| 0\.5 \| 256 \| 5 \| 1 \| 0\.5 \| 1 \| 1\.5 \| 0\.5 \| 1 \| 0\.5 \|",
                    s4), "section 4: tiled phases row at 10x wrong")
    check("**5.0× slower than in core**" in s4 and "100–500× above the PCIe floor" in s4,
          "section 4: slowdown or distance to the PCIe floor not stated")
    check("host→device 50 GB/s, device→host 25 GB/s" in s4 and "**0.25% of the peak**" in s4,
          "section 4: device figures or fraction of the DGEMM peak wrong")
    # --- experiment 5: the mbd log
    s5 = section(secs, "## 5.") or ""
    check(re.search(r"\| lattice-gpu \| `--generate lattice:4 --t-end 0\.02` \| cuda \| 10 \|", s5)
          and "(2.50×: the GPU is faster)" in s5 and "broken-run" in s5
          and "| cpu (8 threads) |" in s5 and "on the CPU with 8 threads" in s5,
          "section 5: log table, CPU vs GPU ratio or failed run wrong")
    check("commit 9a1b2c3" in s5 and "mbd-gpu-20250103T130000Z.log" in s5,
          "section 5: the log's commit or name not in the caption")
    summ2 = section(secs, "## Summary") or ""
    check(re.search(r"refactorization time strata GPU/cuDSS \(default reordering\): \*\*14\.142\*\*",
                    summ2), "summary: cuDSS refactorization ratio missing")

    # --- the Python interface: overhead table, the goal, solver ratios
    sp_ = section(secs, "## Python interface") or ""
    check(re.search(r"\| lap3d-45 \| large \| 91,125 \| 10 \| 10\.1 \| \+1\.00% \| \+2\.00% \| "
                    r"\+0\.50% \| 10\.4 \|", sp_), "python: overhead row lap3d-45 wrong")
    check("Goal (Python layer under 5% on the large matrix, lap3d-45): met" in sp_,
          "python: the overhead goal is not judged on the large matrix")
    check(re.search(r"\| bcsstk16 \| 4,884 \| 1 \(2\.0e-16\) \| 4 \(3\.0e-16\) \| 8 \(3\.0e-16\) \| "
                    r"0\.5 \(1\.0e-16\) \| 0\.250 \| 2\.000 \|", sp_),
          "python: solvers row bcsstk16 wrong")
    check(re.search(r"\| lap3d-35 \| 42,875 \| .* \| not run \| .* \| 1\.000 \| 0\.500 \|", sp_),
          "python: solvers row lap3d-35 wrong (COLAMD not run)")
    check(re.search(r"\| \*\*geometric mean\*\* \|(?: *\|){5} 0\.500 \| 1\.000 \|", sp_),
          "python: geometric means of the solver ratios wrong")
    check("python-20250102T130000Z.json" in sp_, "python: results file not named")

    # --- newest run only, unknown tags kept, broken files listed
    check("777" not in text, "the older factor run (marker 777) is shown")
    other = section(secs, "## Other results") or ""
    check("654.321" in other and "threads-1" in other,
          "the run with tag threads-1 is not under 'Other results'")
    check("gpu-profile" not in other and "cost_model" not in other and "distributed" not in other,
          "a gpu-profile, cost-model or distributed file landed in 'Other results'")
    skipped = section(secs, "## Results files skipped") or ""
    check("broken-20250101T000000Z.json" in skipped, "the truncated file is not listed as skipped")

    # --- a cuDSS run tagged mbd: its headline ratios over the Newton matrices only
    mbd_rows = [ln for ln in open(readme, encoding="utf-8").read().splitlines()
                if "multibody Newton matrices (each its own ordering)" in ln
                and "cudss-mbd-20250105T110000Z.json" in ln]
    check(len(mbd_rows) == 1 and "| **0.500** | 1 |" in mbd_rows[0],
          f"README's mbd line should be 0.500 over 1 problem (bcsstk16 left out): {mbd_rows}")
    check("multibody Newton matrices: **0.500** over 1 problems" in text,
          "REPORT's mbd refactorization line should be 0.500 over 1 problem")

    # --- plots: every referenced PNG exists and is a PNG; each has a caption with a file
    plots = re.findall(r"!\[[^\]]*\]\((plots/[^)]+\.png)\)", text)
    check(len(plots) == 17, f"expected 17 plots (sweep CPU and GPU, analysis, factor, 3 cuDSS, "
          f"4 GPU phase plots, multigpu GPU (2 machines) and CPU, distributed, solvability, "
          f"simulate), found {len(plots)}")
    for p in plots:
        f = os.path.join(out, p)
        ok = os.path.exists(f) and open(f, "rb").read(8) == b"\x89PNG\r\n\x1a\n"
        check(ok, f"plot {p} missing or not a PNG")
        after = text.split(p, 1)[1][:3000]
        check("Measured with" in after and "results file" in after,
              f"plot {p} has no caption saying how it was measured")
    for link in re.findall(r"\]\(([^)]+\.(?:json|log))\)", text):
        check(os.path.exists(os.path.join(out, link)), f"link to results file {link} is broken")

    # --- the same input gives the same report (no clock, no randomness)
    out2 = tempfile.mkdtemp(prefix="strata-report-test-")
    subprocess.run([sys.executable, os.path.join(REPO, "bench", "report.py"),
                    "--results", FIXTURES, "--out", out2, "--history", history],
                   capture_output=True, check=False)
    again = os.path.join(out2, "REPORT.md")
    check(os.path.exists(again) and open(again, encoding="utf-8").read() == text,
          "two runs on the same results give different reports")

    # --- the README's performance table: the summary's ratios, between the markers only
    rd = open(readme, encoding="utf-8").read()
    check(rd.startswith(rm_before + README_BEGIN + "\n") and rd.endswith(README_END + rm_after)
          and "stale table" not in rd, "README: text outside the markers changed, or the "
          "old table is still there")
    for what, value, n in (("factorization time, strata / CHOLMOD (same ordering, CPU)",
                            "2.000", 3),
                           ("factorization time, strata / MUMPS (same ordering, CPU)",
                            "0.500", 3),
                           ("analysis time, strata / CHOLMOD+METIS", "4.000", 2),
                           ("nnz(L), strata / CHOLMOD+METIS", "1.100", 2)):
        m = re.search(r"^\| " + re.escape(what) + r" \| \*\*([0-9.]+)\*\* \| (\d+) \|", rd,
                      re.M)
        check(m and m.group(1) == value and int(m.group(2)) == n,
              f"README: row {what!r} should be {value} over {n}, found "
              f"{m.groups() if m else 'nothing'}")
    links = re.findall(r"\]\(([^)]+\.json)\)", rd)
    check(links and all(os.path.isfile(os.path.join(out, p)) for p in links),
          f"README: results files not linked, or linked wrongly: {links}")
    check("marker 777" not in rd and "654.321" not in rd,
          "README: an older or tagged run's figure in the table")
    # --- the history notes at the end of REPORT.md, one heading level down
    check(re.search(r"## History \(hand-written notes[^\n]*\n\nmarker 31337\n\n### A change\n"
                    r"\nit got faster\n$", text),
          "REPORT.md does not end with the history notes")
    # --- a README without the markers: exit 1, says so
    bad = os.path.join(out, "README-no-markers.md")
    with open(bad, "w", encoding="utf-8") as f:
        f.write("# no table here\n")
    r4 = subprocess.run([sys.executable, os.path.join(REPO, "bench", "report.py"),
                         "--results", FIXTURES, "--out", tempfile.mkdtemp(), "--readme", bad],
                        capture_output=True, text=True)
    check(r4.returncode == 1 and "no performance table markers" in r4.stderr,
          f"README without markers: exit {r4.returncode}, {r4.stderr!r}")

    # --- an empty results folder: everything not measured, nothing invented
    empty = tempfile.mkdtemp(prefix="strata-report-empty-")
    out3 = tempfile.mkdtemp(prefix="strata-report-test-")
    r3 = subprocess.run([sys.executable, os.path.join(REPO, "bench", "report.py"),
                         "--results", empty, "--out", out3], capture_output=True, text=True)
    check(r3.returncode == 0, f"report.py fails on an empty results folder: {r3.stderr}")
    e = open(os.path.join(out3, "REPORT.md"), encoding="utf-8").read() if r3.returncode == 0 else ""
    check(e.count("Not measured yet") >= 10 and "| ---" not in e and "![" not in e,
          "empty results: sections not all 'not measured', or a table/plot was written")

    for d in (out2, empty, out3):
        shutil.rmtree(d, ignore_errors=True)
    if failures:
        print(f"FAIL ({len(failures)} checks), report kept in {out}:")
        for f in failures:
            print("  - " + f)
        return 1
    if not args.keep:
        shutil.rmtree(out, ignore_errors=True)
    print("ok: report generator checks passed" + (f" (report in {out})" if args.keep else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
