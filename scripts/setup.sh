#!/usr/bin/env bash
# Installs every dependency strata needs from Debian packages. Idempotent; needs root
# (or sudo). `--nccl` also installs NCCL (for the STRATA_NCCL build option). The CUDA toolkit is not installed here: CMake enables the CUDA backend
# only when nvcc is found.
set -euo pipefail
pkgs=(
  build-essential cmake ninja-build pkg-config
  libopenblas-dev liblapack-dev libmetis-dev libsuitesparse-dev
  libcli11-dev nlohmann-json3-dev libfmt-dev zlib1g-dev libtbb-dev
  libgtest-dev libgmock-dev libbenchmark-dev libmumps-seq-dev
  python3-matplotlib python3-dev python3-pybind11 python3-numpy python3-scipy python3-pytest
  python3-pip
  # the Python package as pip builds it (pyproject.toml, test python_wheel_venv): venv,
  # python -m build; meshio reads the ParaView series in tests/python/test_outputs.py
  python3-venv python3-build python3-meshio
  # the distributed solver (STRATA_MPI, docs/distributed.md): OpenMPI, and mpi4py built for
  # it (strata.Solver(..., comm=) and its test)
  openmpi-bin libopenmpi-dev python3-mpi4py
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
# scikit-build-core (the build backend of pyproject.toml) has no Debian 12 package: pip
# installs it from PyPI for /usr/bin/python3, so that `python3 -m build --no-isolation` and
# the test python_wheel_venv build offline; `pip install .` with build isolation fetches
# its own copy.
if ! /usr/bin/python3 -c "import scikit_build_core" 2>/dev/null; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO=sudo
  $SUDO /usr/bin/python3 -m pip install -q --timeout 30 --retries 2 --break-system-packages \
    --no-warn-script-location "scikit-build-core>=0.10"
  echo "setup: scikit-build-core installed (pip)"
fi
# scikit-sparse (CHOLMOD from Python) is only a reference in bench/python_vs_scipy.py and
# has no Debian package: pip builds it against Debian's SuiteSparse (0.4.16 is the last
# release that builds with SuiteSparse 5; it needs the network). Optional: when the build
# fails, setup still succeeds and the benchmark says "not installed".
if ! /usr/bin/python3 -c "import sksparse.cholmod" 2>/dev/null; then
  SUDO=""
  [ "$(id -u)" -eq 0 ] || SUDO=sudo
  if $SUDO env SUITESPARSE_INCLUDE_DIR=/usr/include/suitesparse /usr/bin/python3 -m pip install \
       -q --timeout 30 --retries 1 --break-system-packages --no-warn-script-location \
       "scikit-sparse==0.4.16" >/tmp/strata-setup-sksparse.log 2>&1; then
    echo "setup: scikit-sparse installed (pip)"
  else
    echo "setup: note: scikit-sparse could not be installed (see /tmp/strata-setup-sksparse.log);" \
         "bench/python_vs_scipy.py will report CHOLMOD from Python as not installed"
  fi
fi
# NCCL for STRATA_NCCL (GPU-to-GPU contribution blocks between ranks), only when asked:
# `bash scripts/setup.sh --nccl`. The CUDA toolkit may ship it (nccl.h beside cuda.h);
# otherwise NVIDIA's pip wheel nvidia-nccl-cu13 (what PyTorch uses; CMake finds it through
# `import nvidia.nccl`).
if [ "${1:-}" = "--nccl" ]; then
  if ls /usr/local/cuda*/include/nccl.h >/dev/null 2>&1 || [ -e /usr/include/nccl.h ] ||
     /usr/bin/python3 -c "import nvidia.nccl" 2>/dev/null; then
    echo "setup: NCCL present"
  else
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO=sudo
    $SUDO /usr/bin/python3 -m pip install -q --break-system-packages --no-warn-script-location \
      nvidia-nccl-cu13
    echo "setup: NCCL installed (pip nvidia-nccl-cu13)"
  fi
fi
echo "setup: all dependencies present"
