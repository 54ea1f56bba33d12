#!/usr/bin/env bash
# Runs on the lent GPU machine over the staged .carry/ (see prepare.sh): the gpu-labelled
# tests staged (those staged for another call are named and skipped), then the GPU
# benchmarks asked for (--bench ARGS, --memory-bench ARGS, --cudss-bench ARGS,
# --multigpu-bench ARGS). Logs and
# results go to $OUT.
set -uo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # the staged .carry/ unpacked, cuDSS's parts joined, on LD_LIBRARY_PATH
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
# what the machine offers for the distributed runs (MPI, NCCL), recorded with the GPUs
{ echo "mpirun: $(command -v mpirun || echo none)  mpiexec: $(command -v mpiexec || echo none)"
  python3 -c 'import nvidia.nccl, os; print("nccl wheel:", os.path.dirname(nvidia.nccl.__file__ or list(nvidia.nccl.__path__)[0]))' 2>&1 | tail -1
  ls /usr/lib/x86_64-linux-gnu 2>/dev/null | grep -E "libmpi|libnccl" | head -5; } >>"$OUT/gpu.txt" 2>&1
rc=0
# the gpu-labelled tests (every binary built from tests/gpu)
for t in $(ls tests/gpu/*.cpp | xargs -n1 basename | sed 's/\.cpp$//'); do
  if [ ! -x .carry/bin/$t ]; then  # staged in another call (prepare.sh BINARY...)
    echo "=== $t: not staged in this call" | tee -a "$OUT/gpu-tests.log"
    continue
  fi
  echo "=== $t" | tee -a "$OUT/gpu-tests.log"
  .carry/bin/$t 2>&1 | tail -n 60 | tee -a "$OUT/gpu-tests.log"
  [ "${PIPESTATUS[0]}" -eq 0 ] || rc=1
done
# the benchmarks, when asked for: run.sh [--bench ARGS...] [--memory-bench ARGS...]
while [ $# -gt 0 ]; do
  case "$1" in
    --bench) shift; args=(); while [ $# -gt 0 ] && [[ "$1" != --*-bench && "$1" != --bench ]]; do args+=("$1"); shift; done
      .carry/bin/bench_gpu --results-dir "$OUT" "${args[@]}" 2>&1 | tee "$OUT/bench_gpu.log" || rc=1 ;;
    --memory-bench) shift; args=(); while [ $# -gt 0 ] && [[ "$1" != --*-bench && "$1" != --bench ]]; do args+=("$1"); shift; done
      .carry/bin/bench_gpu_memory --results-dir "$OUT" "${args[@]}" 2>&1 | tee "$OUT/bench_gpu_memory.log" || rc=1 ;;
    --multigpu-bench) shift; args=(); while [ $# -gt 0 ] && [[ "$1" != --*-bench && "$1" != --bench ]]; do args+=("$1"); shift; done
      .carry/bin/bench_multigpu --backend cuda --results-dir "$OUT" "${args[@]}" 2>&1 | tee "$OUT/bench_multigpu.log" || rc=1 ;;
    --cudss-bench) shift; args=(); while [ $# -gt 0 ] && [[ "$1" != --*-bench && "$1" != --bench ]]; do args+=("$1"); shift; done
      .carry/bin/bench_cudss --results-dir "$OUT" "${args[@]}" 2>&1 | tee "$OUT/bench_cudss.log" || rc=1 ;;
    *) echo "run.sh: unknown argument $1"; exit 2 ;;
  esac
done
exit $rc
