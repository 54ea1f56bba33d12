#!/usr/bin/env bash
# The distributed benchmark on a lent multi-GPU machine (docs/distributed.md §5): on
# lap3d-80, elast3d-40 (the cost model's calibrated problems), lap3d-100 and elast3d-50,
# the factorization on 1 rank × 1 GPU, then for G visible GPUs
# (2, 4 or 8) 1 rank × G GPUs, 2 ranks × G/2 GPUs and G ranks × 1 GPU (8 GPUs: also
# 4 × 2), each rank's time and bytes moved between ranks, then the cost model's
# prediction beside each measurement.
# Results (distributed-*.json, cost-model.json, run_mpi.log) go to $OUT (default
# bench/results). With test_distributed_mpi staged beside bench_distributed, the
# distributed tests run first on one rank per GPU (their GPU ranks' case included).
# Needs mpirun: the machine's, or the OpenMPI staged by
# scripts/gpu/prepare_mpi.sh in .carry-mpi/ (carried with .carry/).
# Usage: bash scripts/gpu/run_mpi.sh [PROBLEMS] (default lap3d-80,elast3d-40,lap3d-100,elast3d-50);
# STRATA_MPI_CONFIGS="1x2 2x1" runs only those ranks × GPUs configurations; STRATA_MPI_ENV
# names more environment variables to pass to every rank.
set -uo pipefail
cd "$(dirname "$0")/../.."
OUT=${OUT:-bench/results}
mkdir -p "$OUT"
problems=${1:-lap3d-80,elast3d-40,lap3d-100,elast3d-50}
log="$OUT/run_mpi.log"
# under bench/run (STRATA_RESULTS_DIR set) the console output is logged by bench/run
[ -n "${STRATA_RESULTS_DIR:-}" ] && log=/dev/null
exec > >(tee -a "$log") 2>&1
bash scripts/gpu/unpack.sh .carry
export LD_LIBRARY_PATH="$PWD/.carry/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
# NCCL (for a STRATA_NCCL build) from PyTorch's nvidia-nccl wheel when present
nccl_lib=$(python3 -c 'import nvidia.nccl, os; print(os.path.join(os.path.dirname(nvidia.nccl.__file__), "lib"))' 2>/dev/null || true)
[ -n "$nccl_lib" ] && export LD_LIBRARY_PATH="$nccl_lib:$LD_LIBRARY_PATH"
# A machine with its own OpenMPI: use its libraries with its mpirun (its MCA components
# match them, not the Debian copies prepare.sh put in .carry/lib next to our libraries)
if command -v mpirun >/dev/null 2>&1; then
  mkdir -p .carry/lib-sysmpi
  for l in .carry/lib/*; do
    case "$(basename "$l")" in
      libmpi*|libopen-rte*|libopen-pal*|libpmix*|libhwloc*|libevent*|libfabric*|libuc[pmst]*|libpsm*|libibverbs*|librdmacm*|libnl-*|libefa*|libmunge*) ;;
      *) ln -sf "$PWD/$l" .carry/lib-sysmpi/ ;;
    esac
  done
  export LD_LIBRARY_PATH="$PWD/.carry/lib-sysmpi${nccl_lib:+:$nccl_lib}"
  echo "run_mpi: using this machine's mpirun and OpenMPI libraries"
fi
if ! command -v mpirun >/dev/null 2>&1; then
  if [ -f .carry-mpi/openmpi.tar.xz ]; then
    root="$PWD/.carry-mpi/root"
    mkdir -p "$root" && tar -C "$root" -xJf .carry-mpi/openmpi.tar.xz
    export OPAL_PREFIX="$root/usr" PATH="$root/usr/bin:$PATH"
    export LD_LIBRARY_PATH="$root/usr/lib/x86_64-linux-gnu:$root/usr/lib/x86_64-linux-gnu/openmpi/lib:$LD_LIBRARY_PATH"
    export PMIX_INSTALL_PREFIX="$root/usr" OMPI_MCA_mca_base_component_show_load_errors=0
    echo "run_mpi: using the OpenMPI staged in .carry-mpi ($root)"
  else
    echo "run_mpi: NO MPIRUN ON THIS MACHINE and no staged OpenMPI (.carry-mpi/openmpi.tar.xz):"
    echo "run_mpi: run scripts/gpu/prepare_mpi.sh on the build machine and carry .carry-mpi"
    exit 2
  fi
fi
bench=.carry-mpi/bin/bench_distributed
[ -n "${STRATA_BIN_DIR:-}" ] && [ -x "$STRATA_BIN_DIR/bench_distributed" ] && [ ! -x "$bench" ] &&
  bench=$STRATA_BIN_DIR/bench_distributed
[ -x "$bench" ] || bench=.carry/bin/bench_distributed
[ -x "$bench" ] || bench=build/bench/bench_distributed
[ -x "$bench" ] || { echo "run_mpi: no bench_distributed binary"; exit 2; }
export OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1
# NVLink multicast stays off (the lent machines' rule: it can take the host's GPUs out of
# service); passed to every rank explicitly
export NCCL_NVLS_ENABLE=0
nvidia-smi -L || true
mpirun --version | head -1
status=0
started=$(mktemp)
ngpu=$( (nvidia-smi -L 2>/dev/null || true) | wc -l)
case $ngpu in
  0 | 1) configs="1x1" ;;
  2 | 3) configs="1x1 1x2 2x1" ;;
  4 | 5 | 6 | 7) configs="1x1 1x4 2x2 4x1" ;;
  *) configs="1x1 1x8 2x4 4x2 8x1" ;;
esac
# STRATA_MPI_CONFIGS="2x1 1x2": only these ranks × GPUs (e.g. to fit a call's time limit)
configs=${STRATA_MPI_CONFIGS:-$configs}
# STRATA_MPI_ENV="NCCL_P2P_NVL_CHUNKSIZE NCCL_MAX_NCHANNELS": more variables of this
# environment passed to every rank (e.g. NCCL settings to compare)
extra_env=()
for v in ${STRATA_MPI_ENV:-}; do extra_env+=(-x "$v"); done
# the distributed tests with GPU ranks, one rank per GPU (tests/mpi/test_distributed_mpi.cpp;
# its GPU case runs where GPUs are visible), when that binary is staged beside the benchmark
tests=$(dirname "$bench")/test_distributed_mpi
if [ -x "$tests" ] && [ "$ngpu" -ge 2 ]; then
  echo "=== test_distributed_mpi on $ngpu ranks"
  OPENBLAS_NUM_THREADS=1 mpirun -n "$ngpu" --bind-to none --oversubscribe -x LD_LIBRARY_PATH \
    -x PATH -x OPENBLAS_NUM_THREADS -x NCCL_NVLS_ENABLE "$tests" || status=1
fi
for cfg in $configs; do
  r=${cfg%x*} g=${cfg#*x}
  echo "=== $r rank(s) x $g GPU(s): $problems"
  # --bind-to none: each rank drives its GPUs from several host threads
  mpirun -n "$r" --bind-to none --oversubscribe -x LD_LIBRARY_PATH -x PATH -x NCCL_NVLS_ENABLE \
    "${extra_env[@]}" "$bench" --backend cuda --gpus-per-rank "$g" --problems "$problems" --repeat 3 \
    --tag "${r}x${g}" --results-dir "$OUT" || status=1
done
# the prediction beside this session's measurements (files newer than the start of this script)
measured=$(find "$OUT" -maxdepth 1 -name 'distributed-*.json' -newer "$started" | sort)
python3 bench/cost_model.py --json "$OUT/cost-model.json" --measured $measured || status=1
rm -f "$started"
exit $status
