#!/usr/bin/env bash
# Experiment 5: `strata simulate` on each mechanical model generator (src/mbd/generators.cpp:
# tracked:N — tracked vehicle, lattice:N — bushing lattice, flexible:NXxNYxNZ — flexible
# plate; docs/mbd-benchmarks.md), on the CUDA backend and on the CPU with 8 threads, for
# the time per step and the share of it spent in the solver. Runs on the lent GPU machine
# over a staged .carry/ (the CUDA build's strata binary in .carry/bin and its non-CUDA
# libraries in .carry/lib, as prepare.sh stages them), or on any machine with
# STRATA_BIN=path/to/strata (bench/run gpu sets it).
#
# Sizes: the figure is time per step, so the runs are short (a few to a few tens of steps);
# each is sized to end well within its timeout (TIMEOUT, 150 s) on the lent H100. At
# commit 0c7a928 tracked:1000 to t = 0.05 took 28.5 s on the GPU and hit the former 40 s
# timeout on the CPU, so it now runs to t = 0.02.
#
# Log: $OUT/mbd.log, or $STRATA_RESULTS_DIR/logs/mbd-gpu-<UTC time>.log when that is set
# (bench/run gpu sets it to its results folder): a header of '# key: value' lines, then
# one block per run opened by "=== NAME: strata simulate ARGS" and holding the summary
# `strata simulate` prints; bench/report_e2e.py parses the newest
# bench/results/logs/mbd-*.log.
#   Usage: bash scripts/gpu/run_mbd.sh [--quick]   (--quick: tiny models, a smoke run)
set -uo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/: unpacked, on LD_LIBRARY_PATH
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
S=${STRATA_BIN:-.carry/bin/strata}
[ -x "$S" ] || { echo "run_mbd: no strata binary at $S (set STRATA_BIN)"; exit 2; }
TIMEOUT=${TIMEOUT:-150}
THREADS=8  # CPU runs: 8 threads (stated in the log and the report)
quick=0
[ "${1:-}" = --quick ] && quick=1
stamp=$(date -u +%Y%m%dT%H%M%SZ)
log="$OUT/mbd.log"
# under bench/run: straight into its results folder's logs/, where the report reads it
if [ -n "${STRATA_RESULTS_DIR:-}" ]; then
  mkdir -p "$STRATA_RESULTS_DIR/logs"
  log="$STRATA_RESULTS_DIR/logs/mbd-gpu-$stamp.log"
fi
: >"$log"
# what bench/report.py shows as the machine, date and commit of this log (.carry/COMMIT is
# written by prepare.sh; the device tree has no .git)
commit=$(cat .carry/COMMIT 2>/dev/null || git rev-parse --short HEAD 2>/dev/null || echo unknown)
{
  echo "# date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "# gpu: $(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -n 1)"
  echo "# cpu: $(awk -F': ' '/^model name/ {print $2; exit}' /proc/cpuinfo), $(nproc) hardware threads"
  echo "# commit: $commit"
  echo "# cpu threads: $THREADS (--threads $THREADS on every CPU run)"
  echo "# timeout: $TIMEOUT s per run"
} >>"$log"
run() {  # name, args...
  local name=$1
  shift
  echo "=== $name: strata simulate $*" | tee -a "$log"
  timeout "$TIMEOUT" "$S" simulate --quiet --output "" "$@" 2>&1 | grep -v "^model read" | tee -a "$log"
  local rc=${PIPESTATUS[0]}
  [ "$rc" -eq 124 ] && echo "run_mbd: $name stopped by the $TIMEOUT s timeout" | tee -a "$log"
}
if ((quick)); then
  models=("lattice4|lattice:4|0.01" "tracked20|tracked:20|0.005" "flexible16|flexible:16x2x2|0.005")
else
  models=("lattice12|lattice:12|0.02" "tracked1000|tracked:1000|0.02" "flexible64|flexible:64x4x4|0.01")
fi
for m in "${models[@]}"; do
  IFS='|' read -r name spec tend <<<"$m"
  run "$name-gpu" --generate "$spec" --t-end "$tend" --device gpu
  run "$name-cpu" --generate "$spec" --t-end "$tend" --device cpu --threads "$THREADS"
done
# the default model over its whole second, with each way of handling the pivots its
# analysis's order cannot take (Options::pivoting; docs/formulation.md)
if ((!quick)); then
  for p in fixed automatic delayed; do
    run "default-gpu-$p" --device gpu --pivoting "$p"
  done
  run "default-cpu" --device cpu --threads "$THREADS"
fi
echo "run_mbd: log in $log"
exit 0
