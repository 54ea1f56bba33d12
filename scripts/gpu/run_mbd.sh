#!/usr/bin/env bash
# Runs `strata simulate` on the lent GPU machine over a staged .carry/ (the CUDA build's
# strata binary in .carry/bin and its non-CUDA libraries in .carry/lib, as prepare.sh
# stages them): the benchmark models on the CUDA backend and, for comparison, on the CPU.
# Logs go to $OUT (mbd.log: a header of '# key: value' lines, then one summary per run;
# bench/report.py parses it for experiment 5 once copied to bench/results/logs/mbd-*.log).
set -uo pipefail
for z in .carry/lib/*.xz; do [ -f "$z" ] && xz -d -f "$z"; done
export LD_LIBRARY_PATH="$PWD/.carry/lib:${LD_LIBRARY_PATH:-}"
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
S=.carry/bin/strata
nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv | tee "$OUT/gpu.txt"
# what bench/report.py shows as the machine, date and commit of this log (.carry/COMMIT is
# written by prepare.sh; the device tree has no .git)
{
  echo "# date: $(date -u +%Y-%m-%dT%H:%M:%SZ)"
  echo "# gpu: $(nvidia-smi --query-gpu=name --format=csv,noheader | head -n 1)"
  echo "# cpu: $(awk -F': ' '/^model name/ {print $2; exit}' /proc/cpuinfo), $(nproc) hardware threads"
  echo "# commit: $(cat .carry/COMMIT 2>/dev/null || echo unknown)"
} >>"$OUT/mbd.log"
run() {  # name, args...
  local name=$1
  shift
  echo "=== $name: strata simulate $*" | tee -a "$OUT/mbd.log"
  timeout 40 $S simulate --quiet --output "" "$@" 2>&1 | grep -v "^model read" | tee -a "$OUT/mbd.log"
}
run lattice12-gpu --generate lattice:12 --t-end 0.02 --device gpu
run lattice12-cpu --generate lattice:12 --t-end 0.02 --device cpu --threads 8
run tracked1000-gpu --generate tracked:1000 --t-end 0.05 --device gpu
run tracked1000-cpu --generate tracked:1000 --t-end 0.05 --device cpu --threads 8
exit 0
