#!/usr/bin/env bash
# Installs every dependency strata needs from Debian packages. Idempotent; needs root
# (or sudo). The CUDA toolkit is not installed here: CMake enables the CUDA backend
# only when nvcc is found.
set -euo pipefail
pkgs=(
  build-essential cmake ninja-build pkg-config
  libopenblas-dev liblapack-dev libmetis-dev libsuitesparse-dev
  libcli11-dev nlohmann-json3-dev libfmt-dev zlib1g-dev libtbb-dev
  libgtest-dev libgmock-dev libbenchmark-dev libmumps-seq-dev
  python3-matplotlib python3-dev python3-pybind11 python3-numpy python3-scipy python3-pytest
  # the sanitizer and fuzz builds (scripts/sanitize.sh, scripts/fuzz.sh): Debian's clang,
  # its runtime libraries (ASan, UBSan, libFuzzer) and llvm-symbolizer for the reports
  clang libclang-rt-dev llvm
)
missing=()
for p in "${pkgs[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if ((${#missing[@]})); then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO=sudo
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq --no-install-recommends "${missing[@]}"
fi
echo "setup: all dependencies present"
