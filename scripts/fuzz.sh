#!/usr/bin/env bash
# Builds the libFuzzer targets (fuzz/; clang with ASan+UBSan, in ./build-sanitize) and
# runs each for SECONDS (default 60, the CI setting; run longer by hand, e.g.
# `scripts/fuzz.sh 3600 fuzz_solver`). Usage: scripts/fuzz.sh [SECONDS] [TARGET...]
#
# Each target starts from its tracked seeds (fuzz/corpus/NAME) and a working corpus in
# build-sanitize/fuzz-corpus/NAME that grows across runs. A crash, sanitizer report,
# hang (> 10 s on one input) or leak stops that target and fails the script; the input
# is saved as build-sanitize/fuzz-artifacts/NAME-crash-... and the command to replay it
# is printed (turn it into a regression test in tests/, then fix the code).
# STRATA_FUZZ_PARALLEL (default: the number of cores) targets run at a time.
set -euo pipefail
cd "$(dirname "$0")/.."
seconds=${1:-60}
shift || true
targets=("$@")
((${#targets[@]})) || targets=(fuzz_matrix_market fuzz_matrix_market_gz fuzz_model_json fuzz_solver)
dir=${STRATA_SANITIZE_BUILD:-build-sanitize}
# the shared test matrices where the main build (./build) finds them
matrix_dir=$(sed -n 's/^STRATA_MATRIX_DIR:PATH=//p' build/CMakeCache.txt 2>/dev/null || true)
cmake -S . -B "$dir" -G Ninja -DCMAKE_BUILD_TYPE=RelWithDebInfo \
  -DCMAKE_C_COMPILER=clang -DCMAKE_CXX_COMPILER=clang++ \
  -DSTRATA_FUZZ=ON -DSTRATA_BUILD_BENCH=OFF ${matrix_dir:+"-DSTRATA_MATRIX_DIR=$matrix_dir"} >/dev/null
cmake --build "$dir" --target "${targets[@]}"

# seeds, dictionary and largest input of each target
declare -A seeds=([fuzz_matrix_market]=matrix_market [fuzz_matrix_market_gz]=matrix_market_gz
                  [fuzz_model_json]=model_json [fuzz_solver]=solver)
declare -A dicts=([fuzz_matrix_market]=matrix_market [fuzz_matrix_market_gz]=matrix_market
                  [fuzz_model_json]=model_json [fuzz_solver]=matrix_market)
declare -A maxlen=([fuzz_matrix_market]=8192 [fuzz_matrix_market_gz]=8192
                   [fuzz_model_json]=16384 [fuzz_solver]=4096)

mkdir -p "$dir/fuzz-artifacts" "$dir/fuzz-logs"
run_one() {
  local t=$1
  local corpus="$dir/fuzz-corpus/$t"
  mkdir -p "$corpus"
  "$dir/fuzz/$t" -max_total_time="$seconds" -timeout=10 -rss_limit_mb=2048 \
    -max_len="${maxlen[$t]}" -dict="fuzz/${dicts[$t]}.dict" -print_final_stats=1 \
    -artifact_prefix="$dir/fuzz-artifacts/$t-" "$corpus" "fuzz/corpus/${seeds[$t]}" \
    >"$dir/fuzz-logs/$t.log" 2>&1
}

# A single allocation above 1.8 GB fails (std::bad_alloc, which strata reports as
# OutOfMemory: a defined outcome) before libFuzzer's 2 GB malloc limit calls it a crash.
export ASAN_OPTIONS=${ASAN_OPTIONS:-max_allocation_size_mb=1800}
parallel=${STRATA_FUZZ_PARALLEL:-$(nproc)}
declare -A pids
failed=()
for t in "${targets[@]}"; do
  while (($(jobs -rp | wc -l) >= parallel)); do wait -n || true; done
  echo "fuzz: $t for $seconds s"
  run_one "$t" &
  pids[$t]=$!
done
for t in "${targets[@]}"; do
  if wait "${pids[$t]}"; then
    runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$dir/fuzz-logs/$t.log" | grep -o '[0-9]*$' || echo "?")
    cov=$(grep -o 'cov: [0-9]*' "$dir/fuzz-logs/$t.log" | tail -1 || true)
    echo "fuzz: $t clean: $runs inputs, $cov"
  else
    failed+=("$t")
    echo "fuzz: $t FAILED — log $dir/fuzz-logs/$t.log:"
    tail -n 60 "$dir/fuzz-logs/$t.log"
    grep -o "Test unit written to .*" "$dir/fuzz-logs/$t.log" | sed "s|Test unit written to |replay: $dir/fuzz/$t |" || true
  fi
done
((${#failed[@]} == 0)) || { echo "fuzz: findings in ${failed[*]}"; exit 1; }
