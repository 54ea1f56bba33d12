// strata — the host memory the GPU plan counts on (base/host_memory.hpp), against the
// physical memory sysconf reports (an independent source).
#include <gtest/gtest.h>
#include <unistd.h>

#include "base/host_memory.hpp"

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

}  // namespace
}  // namespace strata
