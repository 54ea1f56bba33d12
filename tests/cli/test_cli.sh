#!/usr/bin/env bash
# strata — command-line tests: bad input gives a clear message, exit status 1 and no
# output file; good input gives exit 0 and a complete output file.
# Usage: test_cli.sh PATH/TO/strata   (prints "N passed, M failed")
set -u
strata=$1
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
pass=0 fail=0
check() {  # name, expected exit status, message substring, command...
  local name=$1 want=$2 msg=$3
  shift 3
  local out rc
  out=$("$@" 2>&1)
  rc=$?
  if [[ $rc -eq $want && $out == *"$msg"* ]]; then
    pass=$((pass + 1))
  else
    fail=$((fail + 1))
    echo "FAIL $name: exit $rc (want $want), output: $out"
  fi
}
no_file() {  # name, path
  if [[ -e $2 ]]; then fail=$((fail + 1)); echo "FAIL $1: $2 exists"; else pass=$((pass + 1)); fi
}

# an indefinite symmetric matrix declared spd
cat > "$tmp/indef.mtx" <<'M'
%%MatrixMarket matrix coordinate real symmetric
3 3 4
1 1 2.0
2 1 1.0
2 2 -3.0
3 3 1.0
M
check "not spd" 1 "not positive definite" "$strata" solve "$tmp/indef.mtx" --type spd --out "$tmp/x1.mtx"
no_file "not spd: no output" "$tmp/x1.mtx"
check "indefinite solves as auto" 0 "symmetric_indefinite" "$strata" solve "$tmp/indef.mtx"

# structurally singular: row 2 (1-based 3) empty
cat > "$tmp/sing.mtx" <<'M'
%%MatrixMarket matrix coordinate real general
3 3 3
1 1 1.0
2 2 1.0
1 3 1.0
M
check "structurally singular" 1 "structurally singular" "$strata" solve "$tmp/sing.mtx" --out "$tmp/x2.mtx"
no_file "singular: no output" "$tmp/x2.mtx"

# right-hand side of the wrong length
cat > "$tmp/good.mtx" <<'M'
%%MatrixMarket matrix coordinate real general
3 3 5
1 1 4.0
2 2 5.0
3 3 6.0
1 2 1.0
3 1 -1.0
M
cat > "$tmp/b2.mtx" <<'M'
%%MatrixMarket matrix array real general
2 1
1.0
2.0
M
check "rhs length" 1 "right-hand side has 2 rows" "$strata" solve "$tmp/good.mtx" --rhs "$tmp/b2.mtx" --out "$tmp/x3.mtx"
no_file "rhs length: no output" "$tmp/x3.mtx"

# a NaN value: the parse error names file and line
sed 's/^2 2 5.0$/2 2 nan/' "$tmp/good.mtx" > "$tmp/nan.mtx"
check "nan" 1 "nan.mtx:4" "$strata" solve "$tmp/nan.mtx" --out "$tmp/x4.mtx"
no_file "nan: no output" "$tmp/x4.mtx"

# a good solve writes a complete solution (x = 1 for b = A·1)
check "good solve" 0 "backward error" "$strata" solve "$tmp/good.mtx" --out "$tmp/x5.mtx"
if [[ -f $tmp/x5.mtx ]] && [[ $(grep -c '^1$\|^0\.99999999999999\|^1\.0000000000000' "$tmp/x5.mtx") -eq 3 ]]; then
  pass=$((pass + 1))
else
  fail=$((fail + 1)); echo "FAIL good solve output:"; cat "$tmp/x5.mtx" 2>/dev/null
fi
# --json is valid JSON with the figures
if "$strata" analyze "$tmp/good.mtx" --json | python3 -c 'import json,sys; j=json.load(sys.stdin); assert j["n"] == 3 and j["nnz_l"] >= 3' 2>/dev/null; then
  pass=$((pass + 1))
else
  fail=$((fail + 1)); echo "FAIL analyze --json"
fi
# usage errors: exit 2 and "strata: error:" (the exit-status table is in --help)
check "missing file" 2 "strata: error:" "$strata" solve "$tmp/none.mtx"
check "directory as file" 2 "strata: error:" "$strata" solve "$tmp"
check "missing rhs" 2 "strata: error:" "$strata" solve "$tmp/good.mtx" --rhs "$tmp/none.mtx"
check "threads abc" 2 "strata: error: --threads: must be a whole number of at least 1, got 'abc'" "$strata" solve "$tmp/good.mtx" --threads abc
check "threads -1" 2 "got '-1'" "$strata" solve "$tmp/good.mtx" --threads -1
check "threads 0" 2 "got '0'" "$strata" solve "$tmp/good.mtx" --threads 0
check "simulate threads 0" 2 "got '0'" "$strata" simulate --threads 0
check "negative step" 2 "--step: must be a number greater than 0" "$strata" simulate --step -1
check "unknown option" 2 "strata: error:" "$strata" solve "$tmp/good.mtx" --bogus
# the names of the solver's options: the vocabulary shared with the C API, Python and
# the engine (strata::parse), aliases included
check "unknown ordering" 2 "ordering must be 'nd', 'metis', 'amd', 'natural' or 'auto' (aliases: nested_dissection = nd, automatic = auto), got 'rcm'" "$strata" solve "$tmp/good.mtx" --ordering rcm
check "unknown type" 2 "type must be 'auto', 'spd', 'symmetric_indefinite' or 'general'" "$strata" solve "$tmp/good.mtx" --type cholesky
check "unknown pivoting" 2 "pivoting must be 'fixed', 'automatic', 'delayed' or 'corrected'" "$strata" simulate --pivoting partial
# any solver option of a simulation by its name (set_option's vocabulary)
check "unknown solver option" 2 "unknown option 'bogus'" "$strata" simulate --solver-option bogus=1
check "bad solver option value" 2 "option pivot_threshold must be a finite number, got 'x'" "$strata" simulate --solver-option pivot_threshold=x
check "solver option without value" 2 "--solver-option takes NAME=VALUE, got 'ordering'" "$strata" simulate --solver-option ordering
check "solver option out of range" 1 "Options::pivot_threshold must be in (0, 1]" "$strata" simulate --generate chain2d:2 --t-end 0.001 --quiet --output "$tmp/s_opt" --solver-option pivot_threshold=2
check "solver options" 0 "complete" "$strata" simulate --generate chain2d:2 --t-end 0.002 --quiet --output "$tmp/s_opt" --solver-option ordering=amd --solver-option pivoting=delayed
check "type alias lu" 0 "general on cpu" "$strata" solve "$tmp/good.mtx" --type lu --device cpu
check "no file" 2 "strata: error:" "$strata" solve
check "no command" 2 "strata: error:" "$strata"
check "help lists exit status" 0 "130 SIGINT, 143 SIGTERM" "$strata" solve --help

# a pivot in a message is readable (%.3e, not std::to_string's "-0.000000")
check "pivot format" 1 "pivot -3.500e+00 at column 1" "$strata" solve "$tmp/indef.mtx" --type spd

# --out: never replace what is not a regular file; follow a symbolic link; check first
mkfifo "$tmp/fifo"
(timeout 60 cat "$tmp/fifo" > "$tmp/from_fifo") &
reader=$!
check "out to a FIFO" 0 "solution written to" timeout 60 "$strata" solve "$tmp/good.mtx" --out "$tmp/fifo"
wait $reader
if [[ -p $tmp/fifo ]] && grep -q '^3 1$' "$tmp/from_fifo"; then pass=$((pass + 1)); else fail=$((fail + 1)); echo "FAIL out to a FIFO: not a FIFO any more, or the reader got no solution"; fi
echo "old contents" > "$tmp/target.mtx"
ln -s target.mtx "$tmp/link.mtx"
check "out to a symlink" 0 "solution written to" "$strata" solve "$tmp/good.mtx" --out "$tmp/link.mtx"
if [[ -L $tmp/link.mtx ]] && grep -q '^3 1$' "$tmp/target.mtx"; then pass=$((pass + 1)); else fail=$((fail + 1)); echo "FAIL out to a symlink: the link was replaced or its target not written"; fi
if find "$tmp" -name '*.tmp.*' | grep -q .; then fail=$((fail + 1)); echo "FAIL out to a symlink: temporaries left"; else pass=$((pass + 1)); fi
check "out to a folder" 1 "is a directory" "$strata" solve "$tmp/good.mtx" --out "$tmp"
check "out into a missing folder" 1 "does not exist" "$strata" solve "$tmp/good.mtx" --out "$tmp/no/such/x.mtx"
if [[ -c /dev/full ]]; then
  check "out to /dev/full" 1 "No space left on device" "$strata" solve "$tmp/good.mtx" --out /dev/full
  [[ -c /dev/full ]] && pass=$((pass + 1)) || { fail=$((fail + 1)); echo "FAIL: /dev/full is no longer a device"; }
fi

# a 76-byte file declaring a 2e8 x 2e8 matrix: refused at once (no O(n) allocation)
printf '%%%%MatrixMarket matrix coordinate real general\n200000000 200000000 1\n1 1 1.0\n' > "$tmp/huge.mtx"
check "huge declared size" 1 "huge.mtx: matrix is structurally singular: column 2 (1-based) has no entries" timeout 20 "$strata" solve "$tmp/huge.mtx"
check "huge declared size (analyze)" 1 "huge.mtx: matrix is structurally singular" timeout 20 "$strata" analyze "$tmp/huge.mtx"
# the file is named in the analysis's structural messages too
printf '%%%%MatrixMarket matrix coordinate real general\n2 3 2\n1 1 1.0\n2 2 1.0\n' > "$tmp/rect.mtx"
check "not square (solve)" 1 "rect.mtx: matrix is 2x3, not square" "$strata" solve "$tmp/rect.mtx"
check "not square (analyze)" 1 "rect.mtx: matrix is 2x3, not square" "$strata" analyze "$tmp/rect.mtx"
printf '%%%%MatrixMarket matrix coordinate real general\n3 3 5\n1 1 1.0\n2 1 1.0\n3 1 1.0\n1 2 1.0\n1 3 1.0\n' > "$tmp/unmatched.mtx"
check "structurally singular (matching, solve)" 1 "unmatched.mtx: the matrix is structurally singular" "$strata" solve "$tmp/unmatched.mtx"
check "structurally singular (matching, analyze)" 1 "unmatched.mtx: the matrix is structurally singular" "$strata" analyze "$tmp/unmatched.mtx"

# trailing data after a gzip stream is an error naming the file
gzip -c "$tmp/good.mtx" > "$tmp/trail.mtx.gz"
printf 'garbage' >> "$tmp/trail.mtx.gz"
check "gzip trailing data" 1 "trail.mtx.gz:0: trailing data after the end of the compressed stream" "$strata" solve "$tmp/trail.mtx.gz"
gzip -c "$tmp/good.mtx" > "$tmp/two.mtx.gz"
check "gzip: one member" 0 "backward error" "$strata" solve "$tmp/two.mtx.gz"

# a failed solve leaves an existing output file as it was (written via temporary + rename)
cp "$tmp/x5.mtx" "$tmp/keep.mtx"
check "failed solve keeps old output" 1 "not positive definite" "$strata" solve "$tmp/indef.mtx" --type spd --out "$tmp/keep.mtx"
if cmp -s "$tmp/x5.mtx" "$tmp/keep.mtx"; then pass=$((pass + 1)); else fail=$((fail + 1)); echo "FAIL: old output changed"; fi

# --- simulate: partial results, interruption, checkpoint and restart -----------------------
same_histories() {  # name, dir1, dir2: positions/velocities/accelerations/reactions bitwise,
  local name=$1 a=$2 b=$3 f ok=1  # steps.csv without its two timing columns
  for f in positions velocities accelerations reactions; do
    cmp -s "$a/$f.csv" "$b/$f.csv" || { ok=0; echo "FAIL $name: $f.csv differs"; }
  done
  cmp -s <(cut -d, -f1-7,10- "$a/steps.csv") <(cut -d, -f1-7,10- "$b/steps.csv") ||
    { ok=0; echo "FAIL $name: steps.csv differs"; }
  [[ -s $a/positions.csv ]] || { ok=0; echo "FAIL $name: $a/positions.csv missing or empty"; }
  if [[ $ok -eq 1 ]]; then pass=$((pass + 1)); else fail=$((fail + 1)); fi
}
has() {  # name, file, substring
  if grep -qF -- "$3" "$2" 2>/dev/null; then pass=$((pass + 1)); else fail=$((fail + 1)); echo "FAIL $1: no '$3' in $2"; cat "$2" 2>/dev/null; fi
}
no_tmp() {  # name, dir: no temporary file left behind
  if find "$2" -name '*.tmp.*' | grep -q .; then fail=$((fail + 1)); echo "FAIL $1: temporaries left in $2"; else pass=$((pass + 1)); fi
}
sim=("$strata" simulate --generate andrews --step 1e-4 --quiet)
# run to T; run to T/2 with checkpoints, resume to T: the same histories, bit for bit
check "sim full" 0 "complete" "${sim[@]}" --t-end 0.02 --output "$tmp/s_full"
check "sim half" 0 "checkpoint            step 90" "${sim[@]}" --t-end 0.01 --output "$tmp/s_half" --checkpoint-every 30
check "sim resume" 0 "resumed from" "$strata" simulate --resume "$tmp/s_half/checkpoint" --t-end 0.02 --output "$tmp/s_res" --quiet
same_histories "resume = uninterrupted" "$tmp/s_full" "$tmp/s_res"
has "complete status" "$tmp/s_res/status.json" '"complete": true'
no_tmp "no temporaries" "$tmp/s_res"
no_file "complete run: no partial file" "$tmp/s_res/positions.partial.csv"
# the options of a resumed run are those of the checkpoint
check "resume before the checkpoint" 1 "is not after the checkpoint's time" "$strata" simulate --resume "$tmp/s_half/checkpoint" --t-end 0.001 --output "$tmp/s_bad"
check "resume with --solver-option" 1 "--solver-option cannot be changed" "$strata" simulate --resume "$tmp/s_half/checkpoint" --solver-option ordering=amd --output "$tmp/s_bad"
check "resume with --step" 1 "--step cannot be changed" "$strata" simulate --resume "$tmp/s_half/checkpoint" --step 1e-3 --output "$tmp/s_bad"
mkdir -p "$tmp/bad_ck" && printf 'garbage' > "$tmp/bad_ck/checkpoint.cbor"
check "corrupt checkpoint" 1 "not a readable strata checkpoint" "$strata" simulate --resume "$tmp/bad_ck" --output "$tmp/s_bad"

# SIGINT mid-run: exit 130, histories named partial, status "interrupted" with the step,
# a checkpoint from which the run ends exactly as an uninterrupted one
long=("$strata" simulate --generate andrews --step 2e-5 --t-end 0.2 --quiet)
"${long[@]}" --output "$tmp/i_run" --checkpoint-every 100000 > "$tmp/i_run.log" 2>&1 &
pid=$!
for _ in $(seq 600); do
  [[ -f $tmp/i_run/steps.partial.csv && $(wc -l < "$tmp/i_run/steps.partial.csv") -gt 100 ]] && break
  sleep 0.05
done
kill -INT $pid
wait $pid
rc=$?
if [[ $rc -eq 130 ]]; then pass=$((pass + 1)); else fail=$((fail + 1)); echo "FAIL SIGINT: exit $rc (want 130)"; cat "$tmp/i_run.log"; fi
has "SIGINT status" "$tmp/i_run/status.json" '"state": "interrupted"'
has "SIGINT status partial" "$tmp/i_run/status.json" '"partial": true'
has "SIGINT reason" "$tmp/i_run/status.json" 'SIGINT'
no_file "SIGINT: no whole-run name" "$tmp/i_run/positions.csv"
[[ -s $tmp/i_run/positions.partial.csv ]] && pass=$((pass + 1)) || { fail=$((fail + 1)); echo "FAIL SIGINT: no partial positions"; }
no_tmp "SIGINT: no temporaries" "$tmp/i_run"
check "SIGINT resume" 0 "complete" "$strata" simulate --resume "$tmp/i_run/checkpoint" --output "$tmp/i_res" --quiet
check "long full" 0 "complete" "${long[@]}" --output "$tmp/i_full"
same_histories "SIGINT + resume = uninterrupted" "$tmp/i_full" "$tmp/i_res"

# SIGTERM: exit 143, partial
"${long[@]}" --output "$tmp/t_run" > "$tmp/t_run.log" 2>&1 &
pid=$!
for _ in $(seq 600); do
  [[ -f $tmp/t_run/steps.partial.csv && $(wc -l < "$tmp/t_run/steps.partial.csv") -gt 10 ]] && break
  sleep 0.05
done
kill -TERM $pid
wait $pid
rc=$?
if [[ $rc -eq 143 ]]; then pass=$((pass + 1)); else fail=$((fail + 1)); echo "FAIL SIGTERM: exit $rc (want 143)"; fi
has "SIGTERM status" "$tmp/t_run/status.json" 'SIGTERM'

# a Newton failure mid-run (a slider pushed beyond the reach of crank + rod): exit 1,
# partial histories, status "failed" with the reason
cat > "$tmp/slider.json" <<'J'
{"type": "planar", "bodies": [
  {"name": "crank", "mass": 1, "inertia": 0.1, "position": [0, 0], "angle": 0.9272952180016122},
  {"name": "slider", "mass": 1, "inertia": 0.1, "position": [2.0, 0]}],
 "joints": [
  {"name": "pivot", "type": "revolute", "body_i": "ground", "body_j": "crank", "point": [0, 0]},
  {"name": "guide", "type": "translational", "body_i": "ground", "body_j": "slider", "point": [2.0, 0], "axis": [1, 0]},
  {"name": "rod", "type": "distance", "body_i": "crank", "body_j": "slider", "point_i": [1, 0], "point_j": [0, 0], "length": 1.5},
  {"name": "push", "type": "translation_driver", "body_i": "ground", "body_j": "slider", "point": [2.0, 0], "axis": [1, 0],
   "motion": {"polynomial": [0, 1]}}]}
J
check "Newton failure" 1 "did not converge" "$strata" simulate "$tmp/slider.json" --t-end 1 --step 0.01 --output "$tmp/f_run" --quiet
has "failure status" "$tmp/f_run/status.json" '"state": "failed"'
has "failure reason" "$tmp/f_run/status.json" 'did not converge'
no_file "failure: no whole-run name" "$tmp/f_run/positions.csv"
[[ $(wc -l < "$tmp/f_run/positions.partial.csv") -gt 20 ]] && pass=$((pass + 1)) || { fail=$((fail + 1)); echo "FAIL failure: partial rows missing"; }
# a run that fails before its first step marks the folder: no earlier results, status failed
check "sim before failed start" 0 "complete" "${sim[@]}" --t-end 0.001 --output "$tmp/m_run" --vtk
printf '{"type": "planar", "bodies": [' > "$tmp/broken.json"
check "broken model" 1 "broken.json:1:" "$strata" simulate "$tmp/broken.json" --output "$tmp/m_run"
has "broken model status" "$tmp/m_run/status.json" '"state": "failed"'
has "broken model reason" "$tmp/m_run/status.json" 'invalid JSON'
for f in positions.csv steps.csv reactions.csv vtk/series.pvd; do no_file "broken model: $f of the earlier run" "$tmp/m_run/$f"; done
check "output folder not writable" 1 "cannot write" "$strata" simulate --generate andrews --output "$tmp/good.mtx/sub" --quiet
# a later complete run in the same folder replaces the partial files
check "complete after failure" 0 "complete" "${sim[@]}" --t-end 0.001 --output "$tmp/f_run"
no_file "stale partial removed" "$tmp/f_run/positions.partial.csv"

# OpenBLAS's kernels (apps/common/blas_kernels.hpp): a user's OPENBLAS_CORETYPE is kept;
# without one, a CPU with AVX2 and FMA never runs the Prescott fallback. The reference is
# the CPU's flags as the kernel lists them, not the compiler's CPU checks.
if [[ $(uname -m) == x86_64 ]]; then  # Prescott is an x86-64 core type
  check "user's OPENBLAS_CORETYPE kept" 0 "Prescott kernels" env OPENBLAS_CORETYPE=Prescott "$strata" --version
fi
cpu_flags=" $(grep -m1 '^flags' /proc/cpuinfo 2>/dev/null | cut -d: -f2) "
if [[ $cpu_flags == *" avx2 "* && $cpu_flags == *" fma "* ]]; then
  out=$(env -u OPENBLAS_CORETYPE "$strata" --version 2>&1)
  if [[ $out == *"OpenBLAS"*" kernels"* && $out != *"Prescott kernels"* ]]; then
    pass=$((pass + 1))
  else
    fail=$((fail + 1))
    echo "FAIL BLAS kernels on an AVX2 CPU: $out"
  fi
else
  echo "BLAS kernels on an AVX2 CPU: skipped (the CPU has no AVX2 and FMA)"
fi
echo "$pass passed, $fail failed"
[[ $fail -eq 0 ]]
