#!/usr/bin/env bash
# The multibody Newton matrices against NVIDIA cuDSS (issue: the main job's own matrices on
# the GPU): scripts/gpu/mechanical_matrices.sh writes each model's Newton matrix of step 1
# (generated here, on the device: hundreds of MB of text), then bench_cudss factors them,
# tagged "mbd" (the report's and the README's own line, apart from the synthetic problems).
#   Usage: bash scripts/gpu/run_cudss_mbd.sh [--quick] [bench_cudss arguments, e.g. --repeat 5]
# Runs over a staged .carry/ with cuDSS in build-cudss/ (scripts/gpu/prepare.sh, run.sh), or
# with STRATA_BIN_DIR=<folder of bench_cudss> and STRATA_BIN=<the strata binary>; results
# go to $STRATA_RESULTS_DIR (bench/run sets it) or $OUT.
set -euo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/ unpacked; BIN, S, RESULTS
WORK=${TMPDIR:-/tmp}/strata-cudss-mbd
mkdir -p "$RESULTS" "$WORK"
models=("tracked-100|tracked:100" "tracked-1000|tracked:1000" "flexible-64x4x4|flexible:64x4x4"
  "lattice-12|lattice:12" "tracked-3000|tracked:3000" "flexible-128x32x4|flexible:128x32x4")
if [ "${1:-}" = --quick ]; then
  shift
  models=("tracked-20|tracked:20" "lattice-3|lattice:3")
fi
if [ ! -x "$BIN/bench_cudss" ] || ldd "$BIN/bench_cudss" | grep -q "not found"; then
  echo "run_cudss_mbd: skipped: no loadable $BIN/bench_cudss (configure with STRATA_CUDSS_DIR;" \
    "on a lent machine carry .cudss1, .cudss2, ..., see scripts/gpu/prepare.sh)"
  exit 0
fi
list=$(bash scripts/gpu/mechanical_matrices.sh "$S" "$WORK" "${models[@]}" | tail -n 1)
"$BIN/bench_cudss" --tag mbd --problems "$list" --results-dir "$RESULTS" "$@"
rm -rf "$WORK"
