// strata — the start-up check of the host code's instruction-set level (base/cpu_level.hpp):
// the extensions it asks this CPU for against the kernel's /proc/cpuinfo (an independent
// source), and the list of missing extensions for CPUs that lack random subsets of them.
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "base/cpu_level.hpp"

namespace strata::detail {
namespace {

const std::vector<std::string> kV3 = {"avx", "avx2", "bmi", "bmi2", "fma", "popcnt"};
const std::vector<std::string> kV4Only = {"avx512f", "avx512bw", "avx512cd", "avx512dq",
                                          "avx512vl"};

// The CPU flags of the first processor in /proc/cpuinfo (Linux's names: bmi1 for bmi).
std::set<std::string> proc_cpuinfo_flags() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("flags", 0) == 0) {
      std::istringstream words(line.substr(line.find(':') + 1));
      std::set<std::string> flags;
      for (std::string w; words >> w;) flags.insert(w);
      return flags;
    }
  return {};
}

TEST(CpuLevel, ExtensionsAgreeWithProcCpuinfo) {
#if defined(__linux__) && defined(__x86_64__)
  const std::set<std::string> flags = proc_cpuinfo_flags();
  ASSERT_FALSE(flags.empty()) << "no flags line in /proc/cpuinfo";
  std::vector<std::string> all = kV3;
  all.insert(all.end(), kV4Only.begin(), kV4Only.end());
  for (const std::string& name : all) {
    const std::string linux_name = name == "bmi" ? "bmi1" : name;
    EXPECT_EQ(cpu_has_extension(name.c_str()), flags.count(linux_name) == 1) << name;
  }
  EXPECT_FALSE(cpu_has_extension("not-an-extension"));
  // the program runs, so the start-up check passed: the build's level is this CPU's
  EXPECT_TRUE(cpu_supports_build_level()) << build_cpu_arch();
#else
  GTEST_SKIP() << "not Linux on x86-64: no /proc/cpuinfo flags to compare with";
#endif
}

// A CPU that has exactly the extensions in `present`.
thread_local const std::set<std::string>* g_present = nullptr;
bool fake_has(const char* name) { return g_present->count(name) == 1; }

std::string missing_of(const char* level, std::size_t size = 128) {
  std::vector<char> out(size, 'x');
  missing_cpu_extensions(level, fake_has, out.data(), size);
  return std::string(out.data());
}

TEST(CpuLevel, MissingExtensionsOfRandomCpus) {
  std::mt19937 rng(std::random_device{}());
  std::vector<std::string> all = kV3;
  all.insert(all.end(), kV4Only.begin(), kV4Only.end());
  for (int trial = 0; trial < 200; ++trial) {
    std::set<std::string> present;
    for (const std::string& e : all)
      if (rng() % 3 != 0) present.insert(e);
    g_present = &present;
    std::string want3, want4;
    for (const std::string& e : all) {
      if (present.count(e)) continue;
      const bool v3 = std::find(kV3.begin(), kV3.end(), e) != kV3.end();
      if (v3) want3 += (want3.empty() ? "" : " ") + e;
      want4 += (want4.empty() ? "" : " ") + e;
    }
    EXPECT_EQ(missing_of("x86-64-v3"), want3);
    EXPECT_EQ(missing_of("x86-64-v4"), want4);
    // levels without a check need nothing
    EXPECT_EQ(missing_of("native"), "");
    EXPECT_EQ(missing_of(""), "");
    EXPECT_EQ(missing_of("x86-64-v2"), "");
    // a short buffer holds the list's beginning, terminated
    for (std::size_t size : {1, 2, 3, 5})
      EXPECT_EQ(missing_of("x86-64-v4", size), want4.substr(0, size - 1));
  }
  g_present = nullptr;
}

}  // namespace
}  // namespace strata::detail
