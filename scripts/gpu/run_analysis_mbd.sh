#!/usr/bin/env bash
# The analysis of the multibody Newton matrices on this machine's cores (bench/run cpu) or
# a lent machine's host (bench/run gpu, or by hand after prepare.sh), next to
# UMFPACK's symbolic phase (bench_analysis --matching --umfpack, tagged
# mbd-umfpack-t<threads>, as on the development machine: the report tells machines apart), at each thread count given; scripts/gpu/mechanical_matrices.sh
# writes the matrices here (generated on the device, not carried). When a baseline build's
# strata is staged in .carry/base/ (an older commit's, for the ratio), both binaries'
# `strata analyze --json` are alternated three times per matrix and thread count and the
# lines go to analysis-baseline.txt.
#   Usage: bash scripts/gpu/run_analysis_mbd.sh [--quick] [THREADS...]   (default 1 16)
# Runs over a staged .carry/ (scripts/gpu/prepare.sh), or with STRATA_BIN_DIR and
# STRATA_BIN; results go to $STRATA_RESULTS_DIR (bench/run sets it) or $OUT.
set -euo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/ unpacked; BIN, S, RESULTS
WORK=${TMPDIR:-/tmp}/strata-analysis-mbd
mkdir -p "$RESULTS" "$WORK"
models=("tracked-1000|tracked:1000" "flexible-64x4x4|flexible:64x4x4" "lattice-12|lattice:12"
  "flexible-128x32x4|flexible:128x32x4")
if [ "${1:-}" = --quick ]; then
  shift
  models=("tracked-20|tracked:20" "lattice-3|lattice:3")
fi
threads=("$@")
[ ${#threads[@]} -gt 0 ] || threads=(1 16)
list=$(bash scripts/gpu/mechanical_matrices.sh "$S" "$WORK" "${models[@]}" | tail -n 1)
for t in "${threads[@]}"; do
  "$BIN/bench_analysis" --matching --umfpack --no-cholmod --threads "$t" --repeat 3 \
    --tag "mbd-umfpack-t$t" --problems "$list" --results-dir "$RESULTS"
done
if [ -x .carry/base/strata ]; then
  for m in ${list//,/ }; do
    for t in "${threads[@]}"; do
      for r in 1 2 3; do
        for b in .carry/base/strata "$S"; do
          printf '%s %s t=%s ' "$b" "$(basename "$m")" "$t"
          "$b" analyze "$m" --threads "$t" --json | python3 -c \
            'import json,sys; a=json.load(sys.stdin); a=a.get("analysis",a); s=a["seconds"]; print("total %.4f ordering %.4f symbolic %.4f plan %.4f nnz_l %d" % (s["total"], s["ordering"], s["symbolic"], s["plan"], a["nnz_l"]))'
        done
      done
    done
  done | tee "$RESULTS/analysis-baseline.txt"
fi
rm -rf "$WORK"
