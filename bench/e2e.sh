#!/usr/bin/env bash
# bench/run's end-to-end part: bench/e2e.py with the strata binary bench/run uses
# (STRATA_BIN) and, when STRATA_BASELINE names another build's strata, that one side by
# side; results into STRATA_RESULTS_DIR. Arguments go to bench/e2e.py.
set -euo pipefail
cd "$(dirname "$0")/.."
py=/usr/bin/python3
[ -x "$py" ] || py=python3
args=(--strata "${STRATA_BIN:-build/strata}" --results-dir "${STRATA_RESULTS_DIR:-bench/results}")
[ -n "${STRATA_BASELINE:-}" ] && args+=(--baseline "$STRATA_BASELINE")
exec "$py" bench/e2e.py "${args[@]}" "$@"
