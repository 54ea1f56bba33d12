#!/usr/bin/env bash
# Builds strata for the lent GPU machine (sm_90) here and stages what the device run
# needs in .carry/ (ignored by git): the test and benchmark binaries, the shared
# libraries the device image lacks, and the shared matrices. The device runs Ubuntu
# 24.04 with the same CUDA 13.0 and a newer glibc, so binaries built here run there.
# Usage: scripts/gpu/prepare.sh   then: device run with carry [".carry"] and
#        command "bash scripts/gpu/run.sh"
set -euo pipefail
cd "$(dirname "$0")/../.."
cmake -S . -B build-gpu -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CUDA_ARCHITECTURES=90 \
  -DSTRATA_MATRIX_DIR=.carry/matrices >/dev/null
cmake --build build-gpu -j2
rm -rf .carry && mkdir -p .carry/bin .carry/lib .carry/matrices
cp build-gpu/strata build-gpu/tests/test_cuda_backend build-gpu/tests/test_cuda_faults \
   build-gpu/tests/test_solver \
   build-gpu/bench/bench_factor .carry/bin/ 2>/dev/null || true
[ -f build-gpu/bench/bench_gpu ] && cp build-gpu/bench/bench_gpu .carry/bin/
cp ../shared/matrices/*.mtx.gz .carry/matrices/ 2>/dev/null || cp /work/shared/matrices/*.mtx.gz .carry/matrices/
# every non-system, non-CUDA library the binaries load
for b in .carry/bin/*; do
  ldd "$b" | awk '/=>/ {print $3}'
done | sort -u | grep -v -E '/(libc|libm|libdl|libpthread|librt|libgcc_s|libstdc\+\+)\.so|cuda|libcu|libnv' |
  while read -r lib; do cp -L "$lib" .carry/lib/; done
# the large BLAS/LAPACK travel compressed (the tree that travels is limited to 64 MiB)
xz -T2 -6 .carry/lib/libopenblas.so.0 .carry/lib/liblapack.so.3
du -sh .carry
