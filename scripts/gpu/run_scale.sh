#!/usr/bin/env bash
# A scale run of the engine on the lent GPU machine over a staged .carry/ (prepare.sh):
# `strata simulate --verbose` on one generated model, with the process's resident and
# virtual memory and the GPU's memory in use sampled every 5 s, and, when the kernel ends
# the process, the kernel log's last lines. Writes $OUT/scale-MODEL-STAMP.txt: a header
# line (command, commit, machine, date), strata's output without the per-iteration lines,
# its exit status, the largest RSS and VSZ and the last GPU samples.
# SCALE_LIMIT=S interrupts strata (SIGINT: it stops at the step and keeps what it has)
# after S seconds, so that a run longer than the device command still reports.
#   Usage: bash scripts/gpu/run_scale.sh MODEL T_END [more strata simulate arguments]
#   e.g.   bash scripts/gpu/run_scale.sh flexible:256x64x20 0.01 --device gpu
set -uo pipefail
cd "$(dirname "$0")/../.."
. scripts/gpu/carried.sh  # a staged .carry/: unpacked, on LD_LIBRARY_PATH
OUT="${OUT:-/tmp/strata-out}"
mkdir -p "$OUT"
model=${1:?usage: run_scale.sh MODEL T_END [ARGS...]}
t_end=${2:?usage: run_scale.sh MODEL T_END [ARGS...]}
shift 2
stamp=$(date -u +%Y%m%dT%H%M%SZ)
res="$OUT/scale-${model//:/-}-$stamp.txt"
work=$(mktemp -d)
cmd=("$S" simulate --generate "$model" --t-end "$t_end" --verbose --output "$work/o" "$@")
gpu=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1)
mem=$(awk '/MemTotal/ {printf "%.0f GB", $2 / 1048576}' /proc/meminfo)
echo "# strata simulate --generate $model --t-end $t_end --verbose $* (commit $(cat .carry/COMMIT 2>/dev/null || git rev-parse --short HEAD); ${gpu:-no GPU}, $(nproc) host threads, $mem host memory; $(date -u +%Y-%m-%dT%H:%MZ))" >"$res"
timeout --signal=INT "${SCALE_LIMIT:-0}" "${cmd[@]}" >"$work/log" 2>&1 &
pid=$!
peak_rss=0 peak_vsz=0
: >"$work/gpu"
while kill -0 "$pid" 2>/dev/null; do
  child=$(pgrep -P "$pid" | head -n 1)  # strata, under timeout
  read -r rss vsz < <(ps -o rss=,vsz= -p "${child:-$pid}" 2>/dev/null || echo "0 0")
  ((rss > peak_rss)) && peak_rss=$rss
  ((vsz > peak_vsz)) && peak_vsz=$vsz
  nvidia-smi --query-gpu=memory.used --format=csv,noheader >>"$work/gpu" 2>/dev/null
  sleep 5
done
wait "$pid"
rc=$?
grep -v " iteration " "$work/log" >>"$res"
{
  echo "exit $rc"
  echo "## largest RSS, VSZ (kB, sampled every 5 s)"
  echo "$peak_rss $peak_vsz"
  echo "## GPU memory used, last samples"
  tail -n 4 "$work/gpu"
  if ((rc >= 128)); then
    echo "## kernel log"
    dmesg 2>/dev/null | tail -n 5
  fi
} >>"$res"
rm -rf "$work"
tail -n 40 "$res"
exit $rc
