#!/usr/bin/env bash
# Installs the dependencies, builds strata and runs the whole test suite.
# GPU tests (ctest label `gpu`) skip themselves with a message where no GPU is present.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
bash scripts/build.sh
ctest --test-dir build --output-on-failure -j2 --timeout 1200
