#!/usr/bin/env bash
# gpu tests, then bench_cudss on the MBD matrices: the checked solve with A's copy kept on
# the device by the value pass (default) and with host residuals
ls build-cudss | wc -l > $OUT/parts.txt
timeout 300 bash scripts/gpu/run.sh > $OUT/run.log 2>&1; echo "run.sh rc=$?" >> $OUT/run.log
. scripts/gpu/carried.sh
ls -la build-cudss/libcudss.so.1 >> $OUT/parts.txt 2>&1
list=$(bash scripts/gpu/mechanical_matrices.sh .carry/bin/strata /tmp/mbd "tracked-100|tracked:100" "tracked-1000|tracked:1000" "flexible-64x4x4|flexible:64x4x4" "lattice-12|lattice:12" 2>$OUT/matrices.log | tail -n1)
echo "$list" >> $OUT/matrices.log
timeout 200 .carry/bin/bench_cudss --tag mbd --repeat 5 --analysis-repeat 3 --problems "$list",bcsstk16 --results-dir $OUT > $OUT/bench_cudss.log 2>&1
timeout 120 .carry/bin/bench_cudss --tag mbd-host-residuals --repeat 5 --analysis-repeat 1 --solver-option gpu_refinement=false --problems "$list",bcsstk16 --results-dir $OUT > $OUT/bench_cudss_host.log 2>&1
ls $OUT
