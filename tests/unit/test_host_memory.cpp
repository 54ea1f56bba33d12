// strata — the host memory the GPU plan counts on (base/host_memory.hpp), against the
// physical memory sysconf reports (an independent source); the vectors whose resize does
// not zero (base/default_init.hpp), against std::vector.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "base/default_init.hpp"
#include "base/host_memory.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

TEST(HostMemory, AvailableIsPositiveAndWithinThePhysicalMemory) {
#ifdef __linux__
  const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
  ASSERT_GT(pages, 0);
  ASSERT_GT(page, 0);
  const std::size_t physical = static_cast<std::size_t>(pages) * static_cast<std::size_t>(page);
  const std::size_t avail = available_host_memory();
  EXPECT_GT(avail, 0u);  // MemAvailable is there on every kernel since 3.14
  EXPECT_LE(avail, physical);
#else
  GTEST_SKIP() << "not Linux: available_host_memory() reports 0 (no host limit)";
#endif
}

// UninitVector differs from std::vector only in what resize(n) puts in new elements: every
// construction with a value (resize(n, x), push_back, insert, copies) gives std::vector's
// contents, values written after a growth read back, a class type is still constructed
// (std::string: empty), and growing keeps the old elements. Fresh random values, sizes 0,
// 1, 2, 3, 5, 733.
TEST(UninitVector, ConstructsAsStdVectorExceptTheDefaultElements) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::uniform_real_distribution<double> u(-1, 1);
  for (std::size_t n : {0, 1, 2, 3, 5, 733}) {
    SCOPED_TRACE("n " + std::to_string(n));
    const double x = u(rng);
    UninitVector<double> a(n, x);
    std::vector<double> b(n, x);
    EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin(), b.end()));
    for (std::size_t i = 0; i < n; ++i) {
      const double v = u(rng);
      a.push_back(v);
      b.push_back(v);
    }
    EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin(), b.end()));
    const UninitVector<double> c = a;
    EXPECT_TRUE(std::equal(c.begin(), c.end(), b.begin(), b.end()));
    const std::size_t old = a.size();
    a.resize(2 * old + 3);  // the old elements stay; the new ones are written, then read
    EXPECT_TRUE(
        std::equal(a.begin(), a.begin() + static_cast<std::ptrdiff_t>(old), b.begin(), b.end()));
    for (std::size_t i = old; i < a.size(); ++i) a[i] = static_cast<double>(i);
    for (std::size_t i = old; i < a.size(); ++i) EXPECT_EQ(a[i], static_cast<double>(i));
    a.resize(n, x);
    b.resize(n, x);
    EXPECT_TRUE(std::equal(a.begin(), a.end(), b.begin(), b.end()));
    UninitVector<std::string> s;
    s.resize(n);
    for (const std::string& e : s) EXPECT_TRUE(e.empty());
    s.resize(n + 2, "strata");
    if (n > 0) EXPECT_TRUE(s.front().empty());
    EXPECT_EQ(s.back(), "strata");
  }
}

}  // namespace
}  // namespace strata
