#!/usr/bin/env bash
# Installs the dependencies, builds strata and runs the whole test suite.
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
