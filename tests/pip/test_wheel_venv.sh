#!/usr/bin/env bash
# The Python package as a user gets it: build a wheel from the source tree with
# `python -m build --wheel` (scikit-build-core, pyproject.toml), install it into a fresh
# venv with pip, and run tests/python against the installed copy and the installed
# `strata` command, not build/python.
#
#   test_wheel_venv.sh PYTHON WORKDIR SOURCE_DIR
#
# Offline and quick enough for CI: the venv sees the system's site-packages (numpy, scipy,
# pytest, matplotlib, meshio, and scikit-build-core and pybind11 for the build, all from
# scripts/setup.sh), the build is not isolated and pip uses no index; the CMake build
# folder WORKDIR/pip-build is kept between runs; the CUDA backend is left out
# (STRATA_ENABLE_CUDA=OFF: this tests the packaging, and nvcc on two cores is slow).
# A plain `pip install .` builds the CUDA backend when nvcc is found.
set -euo pipefail
py=$1 work=$2 src=$3
mkdir -p "$work"
work=$(cd "$work" && pwd)
for mod in venv build scikit_build_core pybind11 pytest numpy scipy; do
  "$py" -c "import $mod" 2>/dev/null ||
    { echo "FAIL: $py cannot import $mod (scripts/setup.sh installs it)"; exit 1; }
done
venv=$work/venv
rm -rf "$venv" "$work/dist"
"$py" -m venv --system-site-packages "$venv"
vpy=$venv/bin/python
start=$(date +%s)
CMAKE_BUILD_PARALLEL_LEVEL=${CMAKE_BUILD_PARALLEL_LEVEL:-2} \
  "$vpy" -m build --wheel --no-isolation --outdir "$work/dist" \
  -C build-dir="$work/pip-build" -C cmake.define.STRATA_ENABLE_CUDA=OFF "$src" \
  >"$work/build.log" 2>&1 || { tail -40 "$work/build.log"; echo "FAIL: wheel build"; exit 1; }
wheel=$(ls "$work"/dist/strata-*.whl)
echo "wheel: $(basename "$wheel") ($(($(date +%s) - start)) s)"
"$vpy" -m pip install -q --no-index --no-deps "$wheel"

# the installed copy: in the venv's site-packages, same version everywhere
cd "$work"  # not the source tree, whose python/ must not be what gets imported
unset PYTHONPATH
"$vpy" - "$venv" <<'EOF'
import importlib.metadata, os, subprocess, sys
import strata
venv = os.path.realpath(sys.argv[1])
where = os.path.realpath(strata.__file__)
assert where.startswith(venv + os.sep), f"strata imported from {where}, not the venv"
cli = os.path.join(venv, "bin", "strata")
out = subprocess.run([cli, "--version"], capture_output=True, text=True, check=True).stdout
meta = importlib.metadata.version("strata")
assert out.startswith(f"strata {strata.__version__} (") and meta == strata.__version__, \
    (out, strata.__version__, meta)
print(f"installed: {where}, version {meta}, command {cli}")
EOF
STRATA_CLI=$venv/bin/strata "$vpy" -m pytest -q -p no:cacheprovider "$src/tests/python"
