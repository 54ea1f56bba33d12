# Sourced (not run) by the scripts/gpu run scripts, from the repository's root: when a
# staged .carry/ is there (scripts/gpu/prepare.sh), unpacks its binaries and libraries,
# links .carry/matrices to the tree's data/matrices,
# reassembles cuDSS from the parts earlier calls left in build-cudss/ (all of them: the
# number in build-cudss/parts, see prepare.sh), puts both on
# LD_LIBRARY_PATH and sets STRATA_CARRIED=1, so that the results name the staged
# binaries' commit (.carry/COMMIT) rather than the machine's checkout. Sets BIN (the
# drivers' folder: $STRATA_BIN_DIR, else .carry/bin), S (the strata binary: $STRATA_BIN, else
# $BIN/strata) and RESULTS (where results go: $STRATA_RESULTS_DIR, which bench/run sets,
# else $OUT, else /tmp/strata-out).
if [ -d .carry/lib ] || [ -f .carry/staged.tar.xz ]; then
  bash scripts/gpu/unpack.sh .carry
  # the shared matrices (the build's STRATA_MATRIX_DIR) are the tree's own, not carried
  [ -e .carry/matrices ] || ln -sfn "$PWD/data/matrices" .carry/matrices
  if [ -f build-cudss/parts ] && [ ! -f build-cudss/libcudss.so.1 ] &&
    [ "$(ls build-cudss/part-* | wc -l)" -eq "$(cat build-cudss/parts)" ]; then
    cat build-cudss/part-* | xz -d -T8 >build-cudss/libcudss.so.1
  fi
  export LD_LIBRARY_PATH="$PWD/.carry/lib:$PWD/build-cudss:${LD_LIBRARY_PATH:-}"
  # the staged binaries run (not others named by STRATA_BIN_DIR): their commit
  if [ "${STRATA_BIN_DIR:-.carry/bin}" = .carry/bin ]; then export STRATA_CARRIED=1; fi
fi
BIN=${STRATA_BIN_DIR:-.carry/bin}
S=${STRATA_BIN:-$BIN/strata}
RESULTS=${STRATA_RESULTS_DIR:-${OUT:-/tmp/strata-out}}
