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
# a missing file is a usage error
check "missing file" 105 "" "$strata" solve "$tmp/none.mtx"
echo "$pass passed, $fail failed"
[[ $fail -eq 0 ]]
