// strata — see cpu_level.hpp. This file is compiled for the base x86-64 level (CMake
// sets its own -march), and calls only C library functions: an inline C++ function
// (std::string's, say) would be instantiated in other objects too, compiled for the
// build's level, and the linker may keep that copy for this file's calls as well.
#include "base/cpu_level.hpp"

#include <cstdio>
#include <cstdlib>
#include <cstring>

#ifndef STRATA_CPU_LEVEL  // the level checked: "x86-64-v3", "x86-64-v4" or ""
#define STRATA_CPU_LEVEL ""
#endif
#ifndef STRATA_CPU_ARCH  // the -march given, or ""
#define STRATA_CPU_ARCH ""
#endif

namespace strata::detail {

bool cpu_has_extension(const char* name) noexcept {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  __builtin_cpu_init();
  // (__builtin_cpu_supports takes string literals only)
  struct Query {
    const char* name;
    bool present;
  };
  const Query queries[] = {{"avx", __builtin_cpu_supports("avx") != 0},
                           {"avx2", __builtin_cpu_supports("avx2") != 0},
                           {"bmi", __builtin_cpu_supports("bmi") != 0},
                           {"bmi2", __builtin_cpu_supports("bmi2") != 0},
                           {"fma", __builtin_cpu_supports("fma") != 0},
                           {"popcnt", __builtin_cpu_supports("popcnt") != 0},
                           {"avx512f", __builtin_cpu_supports("avx512f") != 0},
                           {"avx512bw", __builtin_cpu_supports("avx512bw") != 0},
                           {"avx512cd", __builtin_cpu_supports("avx512cd") != 0},
                           {"avx512dq", __builtin_cpu_supports("avx512dq") != 0},
                           {"avx512vl", __builtin_cpu_supports("avx512vl") != 0}};
  for (const Query& q : queries)
    if (std::strcmp(q.name, name) == 0) return q.present;
#else
  (void)name;
#endif
  return false;
}

namespace {

bool check_once() {
  char missing[128];
  missing_cpu_extensions(STRATA_CPU_LEVEL, cpu_has_extension, missing, sizeof missing);
  return missing[0] == '\0';
}

// Before the program's other static initializers (priority 101, the first one not reserved
// for the implementation): they may already run code of the build's level.
[[gnu::constructor(101)]] void check_at_start_up() {
  char missing[128];
  missing_cpu_extensions(STRATA_CPU_LEVEL, cpu_has_extension, missing, sizeof missing);
  if (missing[0] == '\0') return;
  std::fprintf(stderr,
               "strata: error: this build of strata is compiled for %s, and this CPU lacks "
               "%s; rebuild it for this machine with cmake -DSTRATA_CPU_ARCH=native (or "
               "-DSTRATA_CPU_ARCH=none for the base x86-64 level)\n",
               STRATA_CPU_LEVEL, missing);
  std::_Exit(1);
}

}  // namespace

void missing_cpu_extensions(const char* level, bool (*has)(const char* name), char* out,
                            std::size_t size) noexcept {
  if (size == 0) return;
  out[0] = '\0';
  // the level's extensions beyond the one below it, as the x86-64 psABI lists them (v4
  // includes v3's), less F16C, LZCNT and MOVBE, which every CPU with AVX2, BMI2 and FMA
  // has and not every compiler's __builtin_cpu_supports names
  static const char* const kExtensions[] = {"avx",      "avx2",     "bmi",     "bmi2",
                                            "fma",      "popcnt",   "avx512f", "avx512bw",
                                            "avx512cd", "avx512dq", "avx512vl"};
  const bool v3 = std::strcmp(level, "x86-64-v3") == 0;
  const bool v4 = std::strcmp(level, "x86-64-v4") == 0;
  const int needed = v4 ? 11 : v3 ? 6 : 0;  // the first six are v3's
  for (int i = 0; i < needed; ++i) {
    if (has(kExtensions[i])) continue;
    if (out[0] != '\0') std::strncat(out, " ", size - std::strlen(out) - 1);
    std::strncat(out, kExtensions[i], size - std::strlen(out) - 1);
  }
}

bool cpu_supports_build_level() noexcept {
  static const bool supported = check_once();
  return supported;
}

const char* build_cpu_arch() noexcept {
  return STRATA_CPU_ARCH[0] != '\0' ? STRATA_CPU_ARCH : "the compiler's default target";
}

}  // namespace strata::detail
