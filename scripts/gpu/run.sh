#!/usr/bin/env bash
# Runs on the lent GPU machine over the staged .carry/ (see prepare.sh): the gpu-labelled
# tests, then the GPU benchmark if present. Logs and results go to $OUT.
set -uo pipefail
for z in .carry/lib/*.xz; do [ -f "$z" ] && xz -d -f "$z"; done
export LD_LIBRARY_PATH="$PWD/.carry/lib:${LD_LIBRARY_PATH:-}"
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
rc=0
.carry/bin/test_cuda_backend 2>&1 | tee "$OUT/test_cuda_backend.log" || rc=1
if [ -x .carry/bin/test_cuda_faults ]; then
  .carry/bin/test_cuda_faults 2>&1 | tee "$OUT/test_cuda_faults.log" || rc=1
fi
if [ -x .carry/bin/bench_gpu ]; then
  .carry/bin/bench_gpu --results-dir "$OUT" "$@" 2>&1 | tee "$OUT/bench_gpu.log" || rc=1
fi
exit $rc
