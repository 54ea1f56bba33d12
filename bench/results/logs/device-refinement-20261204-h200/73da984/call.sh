#!/usr/bin/env bash
# gpu tests at the test fix; the engine end to end on the default model and tracked:1000
timeout 300 bash scripts/gpu/run.sh > $OUT/run.log 2>&1; echo "run.sh rc=$?" >> $OUT/run.log
. scripts/gpu/carried.sh
timeout 200 python3 bench/e2e.py --strata .carry/bin/strata --device gpu --threads 16 --repeat 2 --models tracked:100:1.0,tracked:1000:0.02 --results-dir $OUT/e > $OUT/e2e.log 2>&1
cp $OUT/e/*.json $OUT/ 2>/dev/null; rm -rf $OUT/e/logs
ls $OUT $OUT/e
