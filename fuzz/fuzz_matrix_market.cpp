// strata fuzz target — the Matrix Market reader on arbitrary bytes.
//
// What. Each input is written to a scratch file and read with read_matrix_market (plain
// text, or gzip data: zlib's gzread recognises the gzip header whatever the file is
// called) and, when small, with read_dense_matrix_market; mm_checks.hpp says what a read
// must satisfy. Seeds: fuzz/corpus/matrix_market (small SuiteSparse files, plain and
// gzip, and hand-made files of every banner). Run by scripts/fuzz.sh.
#include <cstddef>
#include <cstdint>

#include "fuzz_common.hpp"
#include "mm_checks.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static strata::fuzz::ScratchFile input(".mtx"), scratch(".out.mtx");
  strata::fuzz::check_file(input.write(data, size), scratch.path());
  return 0;
}
