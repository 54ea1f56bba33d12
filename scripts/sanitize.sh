#!/usr/bin/env bash
# Builds strata with AddressSanitizer + UndefinedBehaviorSanitizer (clang, in
# ./build-sanitize, which also holds the fuzz targets of scripts/fuzz.sh) and runs the
# whole CPU test suite there (ctest -LE gpu). Any sanitizer report stops its test with
# a nonzero status (halt_on_error; the defaults are compiled into every executable,
# sanitize/options.cpp), so the run fails. Extra arguments go to cmake.
# See docs/reliability.md ("Fuzzing and sanitizers").
set -euo pipefail
cd "$(dirname "$0")/.."
dir=${STRATA_SANITIZE_BUILD:-build-sanitize}
# the shared test matrices where the main build (./build) finds them
matrix_dir=$(sed -n 's/^STRATA_MATRIX_DIR:PATH=//p' build/CMakeCache.txt 2>/dev/null || true)
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DSTRATA_FUZZ=ON -DSTRATA_BUILD_BENCH=OFF ${matrix_dir:+"-DSTRATA_MATRIX_DIR=$matrix_dir"} "$@" >/dev/null
cmake --build "$dir"
start=$(date +%s)
ctest --test-dir "$dir" -LE gpu --output-on-failure -j"$(nproc)" --timeout 1800
echo "sanitize: CPU test suite clean under ASan+UBSan ($(($(date +%s) - start)) s)"
