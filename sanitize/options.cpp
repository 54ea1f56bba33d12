// strata — default sanitizer options of the STRATA_SANITIZE / STRATA_FUZZ builds.
//
// What. The ASan and UBSan runtimes call these weak hooks at start-up and use the
// strings as their defaults (the ASAN_OPTIONS and UBSAN_OPTIONS environment variables are
// applied after them and win). CMake adds this file to every executable of a sanitizer
// build, so `ctest` in that build folder, a test binary run by hand and the fuzz targets
// all check the same way as CI (scripts/sanitize.sh).
//
// Why these values. halt_on_error: the first finding stops the process with a nonzero
// status, so it fails its test (the objects are also built with -fno-sanitize-recover=all).
// detect_leaks: a leak is a finding too. allocator_may_return_null: malloc returns NULL
// where the allocator cannot satisfy a request, as in a normal build (zlib, METIS and AMD
// report that as an error). ASan's operator new still aborts then instead of throwing
// std::bad_alloc, so the one test of that path (a Matrix Market file declaring 1e15
// columns) skips itself under ASan. No leak suppressions:
// the uninstrumented system libraries (OpenBLAS, oneTBB, METIS, SuiteSparse) raised none in the
// whole CPU suite, and a suppression naming libtbb would hide every leak of strata code that runs
// inside a TBB task (LSan matches a suppression against any frame of the allocation's stack).
// Source: the sanitizer runtime flags, https://github.com/google/sanitizers/wiki
// (AddressSanitizerFlags, SanitizerCommonFlags) and the clang UBSan documentation.

extern "C" {

// Read by the runtime before main: a string literal, nothing that allocates.
const char* __asan_default_options() {
  return "halt_on_error=1:detect_leaks=1:check_initialization_order=1:strict_init_order=1:"
         "allocator_may_return_null=1:print_summary=1";
}

const char* __ubsan_default_options() { return "halt_on_error=1:print_stacktrace=1"; }

}  // extern "C"
