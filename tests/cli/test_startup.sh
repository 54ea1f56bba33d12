#!/usr/bin/env bash
# strata — the command line starts without NVIDIA cuBLAS and cuSOLVER: the CUDA build opens
# them on the CUDA backend's first use (src/numeric/cuda/cuda_libraries.cpp), so that a
# process that never uses a GPU does not pay cuBLASLt's start-up. Checked on the
# binary's dynamic section and on the libraries the loader opens (LD_DEBUG=files) for
# `--version` and for a solve on the CPU backend; also that the start-up check itself
# sees a library that is loaded (libstdc++, which every run loads).
#   Usage: bash tests/cli/test_startup.sh STRATA_BINARY MATRIX
set -uo pipefail
S=$1
M=$2
fail=0
loaded() {  # the shared objects the loader opened for the command "$@", one per line
  LD_DEBUG=files "$@" 2>&1 >/dev/null | grep -oE "file=[^ ]+ " | sed 's/^file=//' | sort -u
}
if readelf -d "$S" | grep NEEDED | grep -qE "libcublas|libcusolver"; then
  echo "FAIL: $S has cuBLAS or cuSOLVER among its needed libraries:"
  readelf -d "$S" | grep NEEDED
  fail=1
fi
version=$(loaded "$S" --version)
if ! grep -q "libstdc++" <<<"$version"; then
  echo "FAIL: the loader's list of opened libraries is empty or unreadable (LD_DEBUG=files)"
  fail=1
fi
if grep -E "libcublas|libcusolver" <<<"$version"; then
  echo "FAIL: strata --version loaded the libraries above"
  fail=1
fi
solve=$(loaded "$S" solve "$M" --device cpu)
if grep -E "libcublas|libcusolver" <<<"$solve"; then
  echo "FAIL: strata solve --device cpu loaded the libraries above"
  fail=1
fi
[ $fail -eq 0 ] && echo "test_startup: no cuBLAS or cuSOLVER at start-up or on the CPU backend"
exit $fail
