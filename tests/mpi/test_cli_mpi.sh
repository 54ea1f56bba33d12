#!/usr/bin/env bash
# strata tests — `mpirun -n R strata solve`: the same solution (to 1e-7 relative; the backward error at the roundoff) as the
# one-process run, for an spd, a symmetric indefinite and an unsymmetric shared matrix,
# written by rank 0 only, with the per-rank figures in the JSON report; a missing file
# fails on every rank with one message. Usage: test_cli_mpi.sh STRATA MPIEXEC MATRIX_DIR
set -euo pipefail
strata=$1 mpiexec=$2 dir=$3
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
# (matrix, allowed relative difference of the solutions: κ(A)·1e-16 with room;
#  κ = 4.9e9, 8.8e10, 9.2e5, 1.4e11 by numpy.linalg.cond)
for case in bcsstk16:1e-5 hangGlider_2:1e-4 rajat11:1e-8 watt_2:1e-4; do
  m=${case%%:*} tol=${case#*:}
  "$strata" solve "$dir/$m.mtx.gz" --threads 1 --out "$tmp/x1.mtx" >/dev/null
  for r in 2 3; do
    "$mpiexec" -n $r --oversubscribe "$strata" solve "$dir/$m.mtx.gz" --threads 1 \
      --out "$tmp/x$r.mtx" --json >"$tmp/report$r.json"
    /usr/bin/python3 - "$tmp/x1.mtx" "$tmp/x$r.mtx" "$tmp/report$r.json" "$r" "$tol" <<'PY'
import json, sys
import numpy as np
from scipy.io import mmread
x1, xr = np.asarray(mmread(sys.argv[1])).ravel(), np.asarray(mmread(sys.argv[2])).ravel()
rep = json.load(open(sys.argv[3]))
d = rep["distributed"]
assert d["ranks"] == int(sys.argv[4]) and len(d["per_rank"]) == d["ranks"], d
assert sum(r["subtrees"] for r in d["per_rank"]) == rep["subtrees"], d
assert rep["solve"]["backward_error"] < 1e-14, rep["solve"]
diff = np.abs(x1 - xr).max() / np.abs(x1).max()
assert diff < float(sys.argv[5]), f"solutions differ by {diff}"
PY
  done
done
# a malformed matrix file (read on rank 0 only): exit 1 on every rank, one message
printf '%%%%MatrixMarket matrix coordinate real general\n3 3 1\n1 9 1.0\n' >"$tmp/bad.mtx"
if "$mpiexec" -n 2 --oversubscribe "$strata" solve "$tmp/bad.mtx" 2>"$tmp/err"; then
  echo "a malformed file did not fail" >&2
  exit 1
fi
[ "$(grep -c 'strata: error' "$tmp/err")" = 1 ] || { cat "$tmp/err" >&2; exit 1; }
echo "cli mpi: ok"
