// strata programs — see blas_kernels.hpp.
#include "blas_kernels.hpp"

#include <unistd.h>

#include <cstdlib>
#include <string_view>

extern "C" {
// OpenBLAS's own queries (cblas.h): a static string each, valid for the process's life.
char* openblas_get_config(void);
char* openblas_get_corename(void);
}

namespace strata::app {

std::string blas_description() {
  // openblas_get_config(): "OpenBLAS 0.3.21 DYNAMIC_ARCH NO_AFFINITY SkylakeX MAX_THREADS=64"
  const std::string_view config = openblas_get_config();
  std::string name(config.substr(0, config.find(' ', config.find(' ') + 1)));
  return name + ", " + openblas_get_corename() + " kernels";
}

std::string openblas_core_for_cpu() {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512cd") &&
      __builtin_cpu_supports("avx512bw") && __builtin_cpu_supports("avx512dq") &&
      __builtin_cpu_supports("avx512vl"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
#endif
  return "";
}

void use_fitting_blas_kernels(char** argv) {
  if (std::getenv("OPENBLAS_CORETYPE")) return;  // the user's choice
  if (std::string_view(openblas_get_corename()) != "Prescott") return;
  const std::string core = openblas_core_for_cpu();
  if (core.empty()) return;
  if (setenv("OPENBLAS_CORETYPE", core.c_str(), 1) != 0) return;
  execv("/proc/self/exe", argv);
  unsetenv("OPENBLAS_CORETYPE");  // the execution failed: go on as we were
}

}  // namespace strata::app
