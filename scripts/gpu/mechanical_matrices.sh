#!/usr/bin/env bash
# The multibody Newton matrices the GPU benchmarks factor: for each NAME|SPEC argument,
# `strata simulate --generate SPEC` runs one step of 1 ms (on the GPU when there is one)
# and its first Newton iteration's Jacobian is written to DIR/NAME/NAME.mtx. Prints the
# comma-separated list of the files on its last line. Generated on the device, not
# carried (hundreds of MB of text).
#   Usage: bash scripts/gpu/mechanical_matrices.sh STRATA_BINARY DIR NAME|SPEC...
set -euo pipefail
S=$1
WORK=$2
shift 2
files=()
for m in "$@"; do
  IFS='|' read -r name spec <<<"$m"
  dir="$WORK/$name"
  rm -rf "$dir"
  "$S" simulate --generate "$spec" --step 1e-3 --t-end 1e-3 --device auto --quiet \
    --output "" --dump-matrix "$dir" | grep -E "^(model|strata \[ms\]|Newton matrix)" >&2 || true
  [ -f "$dir/jacobian_step1.mtx" ] || { echo "mechanical_matrices: no matrix for $spec" >&2; exit 1; }
  mv "$dir/jacobian_step1.mtx" "$dir/$name.mtx"
  files+=("$dir/$name.mtx")
done
(IFS=,; echo "${files[*]}")
