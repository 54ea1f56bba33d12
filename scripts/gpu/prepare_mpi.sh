#!/usr/bin/env bash
# Stages what the distributed benchmark (scripts/gpu/run_mpi.sh) needs on a lent GPU
# machine that has no MPI: the Debian OpenMPI 4.1 runtime (mpirun, libmpi, its plugins and
# the libraries they load) with its /usr tree mirrored under .carry-mpi/usr, compressed to
# .carry-mpi/openmpi.tar.xz (about 6 MB), and bench_distributed built for sm_90 (after
# scripts/gpu/prepare.sh has built build-gpu). OpenMPI relocates with OPAL_PREFIX (its
# FAQ, "Can I install Open MPI in a different location"); run_mpi.sh sets it.
# Usage: bash scripts/gpu/prepare.sh && bash scripts/gpu/prepare_mpi.sh
#        then carry [".carry", ".carry-mpi"] and run "bash scripts/gpu/run_mpi.sh"
set -euo pipefail
cd "$(dirname "$0")/../.."
cmake --build build-gpu -j2 --target bench_distributed strata_cli
rm -rf .carry-mpi && mkdir -p .carry-mpi/bin .carry-mpi/stage
cp build-gpu/bench/bench_distributed .carry-mpi/bin/
pkgs="openmpi-bin libopenmpi3 openmpi-common libpmix2 libhwloc15 libhwloc-plugins
      libevent-core-2.1-7 libevent-pthreads-2.1-7 libfabric1 libucx0 libnl-3-200
      libnl-route-3-200 libibverbs1 libpsm2-2 libpsm-infinipath1 librdmacm1"
for p in $pkgs; do
  dpkg -L "$p" 2>/dev/null || true
done | grep -v -E '/share/(doc|man|lintian)/' | sort -u | while read -r f; do
  # files and file symlinks only, under their real directory (merged /usr: /lib is a
  # symlink to usr/lib, and dpkg lists both spellings)
  if [ -f "$f" ] || { [ -L "$f" ] && [ ! -d "$f" ]; }; then
    d=$(readlink -f "$(dirname "$f")")
    mkdir -p ".carry-mpi/stage$d"
    cp -a "$f" ".carry-mpi/stage$d/"
  fi
done
# the alternatives symlinks (mpirun -> /etc/alternatives/mpirun) point outside: replace
for b in mpirun mpiexec; do
  rm -f ".carry-mpi/stage/usr/bin/$b"
  ln -s orterun ".carry-mpi/stage/usr/bin/$b"
done
tar -C .carry-mpi/stage -cJf .carry-mpi/openmpi.tar.xz .
rm -rf .carry-mpi/stage
du -sh .carry-mpi
