#!/usr/bin/env bash
# Installs the dependencies, builds strata and runs the whole test suite; then the
# reliability checks of docs/reliability.md: the CPU suite again built with
# ASan+UBSan (scripts/sanitize.sh) and a short run of every fuzz target
# (scripts/fuzz.sh, STRATA_FUZZ_SECONDS each, default 60). STRATA_TEST_QUICK=1 skips
# those two (for a quick local run; CI runs everything).
# GPU tests (ctest label `gpu`) skip themselves with a message where no GPU is present.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
if ! nvidia-smi -L >/dev/null 2>&1; then
  echo "note: no NVIDIA GPU on this machine: the gpu-labelled tests will report Skipped" \
       "(they run on a lent GPU machine through scripts/gpu/run.sh)"
fi
ctest --test-dir build --output-on-failure -j2 --timeout 1200
if [ "${STRATA_TEST_QUICK:-0}" != 1 ]; then
  bash scripts/sanitize.sh
  bash scripts/fuzz.sh "${STRATA_FUZZ_SECONDS:-60}"
fi
