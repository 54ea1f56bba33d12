#!/usr/bin/env bash
# Builds strata for the lent GPU machine (sm_90) here and stages what the device run
# needs in .carry/ (ignored by git): the test and benchmark binaries, the shared
# libraries the device image lacks, compressed. The device runs Ubuntu 24.04 with the
# same CUDA 13.0 and a newer glibc, so binaries built here run there. The shared matrices
# are not copied: carried.sh links .carry/matrices to the tree's data/matrices there.
# A call carries about 22 MB beside the tree: name the binaries a call needs (their build
# paths' last parts, e.g. strata bench_cudss test_cuda_backend; only those are built);
# without names every test and benchmark binary is built and staged. They are packed into
# one archive, .carry/staged.tar.xz (pack.sh; another commit's binaries for an A/B run go
# into .carry/base/ and pack.sh is run again). A set for the next call can wait in
# .carry-b/ (ignored): `mv .carry .carry-b` after staging it, and that call carries
# .carry-b and begins `rm -rf .carry && mv .carry-b .carry`.
# Usage: scripts/gpu/prepare.sh [BINARY...]   then: device run with carry [".carry"] and
#        command "bash scripts/gpu/run.sh"
set -euo pipefail
cd "$(dirname "$0")/../.."
# NVIDIA cuDSS, the GPU anchor, from its PyPI wheel (bench_cudss links it; the library
# travels separately, see cudss_parts below)
if [ ! -f .whl/nvidia/cu13/lib/libcudss.so.1 ]; then
  python3 -m pip download --no-deps -d .whl nvidia-cudss-cu13 >/dev/null
  (cd .whl && python3 -m zipfile -e nvidia_cudss_cu13-*.whl .)
fi
cmake -S . -B build-gpu -G Ninja -DCMAKE_BUILD_TYPE=Release -DCMAKE_CUDA_ARCHITECTURES=90 \
  -DSTRATA_MATRIX_DIR=.carry/matrices -DSTRATA_CUDSS_DIR="$PWD/.whl/nvidia/cu13" >/dev/null
# only the named binaries (their targets) when names are given
if [ $# -gt 0 ]; then cmake --build build-gpu -j2 --target "$@"; else cmake --build build-gpu -j2; fi
rm -rf .carry && mkdir -p .carry/bin .carry/lib
# the commit the binaries were built from (logs on the device name it; it has no .git)
echo "$(git rev-parse --short HEAD)$(git diff --quiet HEAD -- . || echo ' with uncommitted changes')" >.carry/COMMIT
if [ $# -gt 0 ]; then
  for b in "$@"; do
    found=""
    for d in build-gpu build-gpu/tests build-gpu/bench; do
      if [ -f "$d/$b" ]; then found="$d/$b"; fi
    done
    [ -n "$found" ] || { echo "prepare.sh: no binary $b in build-gpu" >&2; exit 1; }
    cp "$found" .carry/bin/
  done
else
  cp build-gpu/strata build-gpu/tests/test_solver build-gpu/bench/bench_factor .carry/bin/
  # every gpu-labelled test binary (one per file in tests/gpu)
  for src in tests/gpu/*.cpp; do cp "build-gpu/tests/$(basename "$src" .cpp)" .carry/bin/; done
  for b in bench_gpu bench_gpu_memory bench_cudss bench_multigpu bench_analysis; do [ -f build-gpu/bench/$b ] && cp build-gpu/bench/$b .carry/bin/; done
fi
# the GPU timeline recorder (bench/tools/cupti_trace.cpp) and the CUPTI it loads:
# LD_LIBRARY_PATH=.carry/trace LD_PRELOAD=.carry/trace/libstrata_cupti_trace.so
if [ -f build-gpu/bench/libstrata_cupti_trace.so ]; then
  mkdir -p .carry/trace
  cp build-gpu/bench/libstrata_cupti_trace.so .carry/trace/
  cp -L "$(ldd build-gpu/bench/libstrata_cupti_trace.so | awk '/libcupti/ {print $3}')" .carry/trace/
fi
# every non-system, non-CUDA library the binaries load
for b in .carry/bin/*; do
  ldd "$b" | awk '/=>/ {print $3}'
done | sort -u | grep -v -E '/(libc|libm|libdl|libpthread|librt|libgcc_s|libstdc\+\+)\.so|cuda|libcu|libnv' |
  while read -r lib; do cp -L "$lib" .carry/lib/; done
# the binaries and libraries travel in one solid archive (pack.sh); the run scripts
# unpack it (unpack.sh)
bash scripts/gpu/pack.sh .carry
# cuDSS's library is 167 MB (143 MB compressed), over what one call carries: it travels
# in parts of 13 MiB, which leave room for the tracked tree (about 40 MB) within what a
# call carries, .cudss1, .cudss2, ..., one per call, each copied whole (its part and
# the file `parts`, their number) to build-cudss/ on the device (ignored paths there are
# kept while the machine stays warm); carried.sh joins them once all are there. Send the
# first part's call alone and the others only once it has run: after a start is refused,
# every call for the next minutes is refused too, each at a cost in device time.
if [ -f .whl/nvidia/cu13/lib/libcudss.so.1 ] && [ ! -f .cudss1/parts ]; then
  rm -rf .cudss[0-9]* .cudss-part-*
  xz -T2 -6 -c .whl/nvidia/cu13/lib/libcudss.so.1 | split -b 13M - .cudss-part-
  i=0
  for f in .cudss-part-*; do i=$((i + 1)); mkdir -p ".cudss$i" && mv "$f" ".cudss$i/${f#.cudss-}"; done
  for d in .cudss[0-9]*; do echo "$i" >"$d/parts"; done
  echo "cuDSS: $i parts (.cudss1..$i), carry one per call: mkdir -p build-cudss && cp .cudssK/* build-cudss/"
fi
