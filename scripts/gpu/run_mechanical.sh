#!/usr/bin/env bash
# Experiment 3c: the multi-GPU factorization on the multibody generators' mechanical models
# (issue 6: "the mechanical models from the multibody generators"). Each model's Newton
# matrix of step 1 is written by `strata simulate --dump-matrix` (on the GPU, one step),
# then bench_multigpu factors it on 1, 2 and 4 GPUs (as many as are visible; with none,
# host executors stand in for 2, a smoke run) with the defaults — an LU with matching and scaling, the type `strata simulate` uses.
# The matrices are generated here, on the device, not carried (hundreds of MB of text).
#
# Models: lattice:N (bushing lattice, 3D: nested dissection with large separators) and
# flexible:NXxNYxNZ (flexible plate, a thin 3D mesh). tracked:N is a chain, whose tree
# has no width to spread over GPUs; it is left out.
#
#   Usage: bash scripts/gpu/run_mechanical.sh [--quick]
# Runs over a staged .carry/ (scripts/gpu/prepare.sh) or with STRATA_BIN_DIR=<folder of the
# bench_multigpu binary> and STRATA_BIN=<the strata binary>; results go to $STRATA_RESULTS_DIR (bench/run sets it)
# or $OUT, as multigpu-mechanical-*.json.
set -euo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/ unpacked; BIN, S, RESULTS
WORK=${TMPDIR:-/tmp}/strata-mechanical
mkdir -p "$RESULTS" "$WORK"
quick=0
[ "${1:-}" = --quick ] && quick=1
if ((quick)); then
  models=("lattice-4|lattice:4" "flexible-16x2x2|flexible:16x2x2")
else
  models=("lattice-20|lattice:20" "flexible-128x32x4|flexible:128x32x4")
fi
n=$( (nvidia-smi -L 2>/dev/null || true) | wc -l)
workers=1
((n >= 2)) && workers=1,2
((n >= 4)) && workers=1,2,4
backend=cuda
if ((n == 0)); then  # no GPU (a smoke run): host executors stand in for 2 GPUs
  backend=cpu
  workers=1,2
fi
list=$(bash scripts/gpu/mechanical_matrices.sh "$S" "$WORK" "${models[@]}" | tail -n 1)
"$BIN/bench_multigpu" --backend "$backend" --workers "$workers" --subtrees 1 --balance off \
  --stealing on --repeat 2 --tag mechanical --problems "$list" --results-dir "$RESULTS"
rm -rf "$WORK"
