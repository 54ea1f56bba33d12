#!/usr/bin/env bash
# The end-to-end benchmark (bench/e2e.py: strata simulate per model, time per step by
# phase, analyses by cause, real-time factor) on the lent GPU machine over a staged
# .carry/ (prepare.sh): the CUDA build's strata, and, when .carry/base/strata is there
# (another commit's build, staged by hand with its commit in .carry/base/COMMIT), that one
# side by side in the same run. Results (e2e-*.json) and the log go to $OUT.
#   Usage: bash scripts/gpu/run_e2e.sh [bench/e2e.py arguments, e.g. --device gpu --models ...]
set -uo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/: unpacked, on LD_LIBRARY_PATH
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
args=(--strata .carry/bin/strata --results-dir "$OUT")
if [ -x .carry/base/strata ]; then
  args+=(--baseline .carry/base/strata --baseline-label "$(cat .carry/base/COMMIT 2>/dev/null)")
fi
PYTHONUNBUFFERED=1 python3 bench/e2e.py "${args[@]}" "$@" 2>&1 |
  tee -a "$OUT/e2e-$(date -u +%Y%m%dT%H%M%SZ).log"
