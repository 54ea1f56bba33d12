#!/usr/bin/env bash
# LU on one GPU: the large LU fronts in strips by strata's batched kernels (lu_fronts.cu)
# against the library path (cuSOLVER GETRF + cuBLAS TRSMs), as a sweep of
# Options::gpu_lu_strip_pivots (0: every front to the library) in one run, on
# the generated unsymmetric elasticity problems and on the Newton matrices of two
# multibody models (scripts/gpu/mechanical_matrices.sh; `strata simulate` factors them as
# LU with matching and scaling). Runs over a staged .carry/ (scripts/gpu/prepare.sh);
# results go to $OUT as gpu-memory-lu-panel-*.json, the log to $OUT/lu-panel.log.
#   Usage: bash scripts/gpu/run_lu.sh [VALUES [PROBLEMS]]
#   (defaults: VALUES 0,64,128,256,512; PROBLEMS uelast3d-20,uelast3d-30 and the two models)
set -uo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/: unpacked, on LD_LIBRARY_PATH
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
values=${1:-0,64,128,256,512}
problems=${2:-}
if [ -z "$problems" ]; then
  list=$(bash scripts/gpu/mechanical_matrices.sh .carry/bin/strata "${TMPDIR:-/tmp}/strata-lu" \
    "lattice-20|lattice:20" "flexible-128x32x4|flexible:128x32x4" | tail -n 1)
  problems="uelast3d-20,uelast3d-30,$list"
fi
.carry/bin/bench_gpu_memory --parts lu-panel --lu-panel-problems "$problems" \
  --lu-strip-pivots "$values" --repeat 5 --tag lu-panel --results-dir "$OUT" 2>&1 |
  tee "$OUT/lu-panel.log"
