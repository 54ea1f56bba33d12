#!/usr/bin/env bash
# Unpacks what scripts/gpu/pack.sh packed, on the lent GPU machine: DIR/staged.tar.xz (one
# solid archive of DIR's bin/, lib/, base/ and trace/) into DIR, and any single
# compressed file (*.xz) left in those folders. Does nothing when there is nothing packed.
# Run by carried.sh, bench/run --bin-dir and run_mpi.sh.
#   Usage: bash scripts/gpu/unpack.sh [DIR]   (default .carry)
set -euo pipefail
dir=${1:-.carry}
if [ -f "$dir/staged.tar.xz" ]; then
  xz -dc -T0 "$dir/staged.tar.xz" | tar -C "$dir" -xf -
  rm -f "$dir/staged.tar.xz"
fi
for z in "$dir"/lib/*.xz "$dir"/bin/*.xz "$dir"/base/*.xz "$dir"/trace/*.xz; do
  [ -f "$z" ] && xz -d -f "$z"
done
exit 0
