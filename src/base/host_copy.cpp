// strata — copies between large host buffers on the host's threads (see host_copy.hpp).
#include "base/host_copy.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cstring>

namespace strata {
namespace {
constexpr std::size_t kChunk = std::size_t{1} << 17;  // doubles: 1 MiB per task at least
}

void parallel_copy(double* dst, const double* src, std::size_t n) {
  if (n <= kChunk) {
    if (n) std::memcpy(dst, src, sizeof(double) * n);
    return;
  }
  const std::size_t chunks = (n + kChunk - 1) / kChunk;
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, chunks), [&](const auto& r) {
    const std::size_t b = r.begin() * kChunk, e = std::min(n, r.end() * kChunk);
    std::memcpy(dst + b, src + b, sizeof(double) * (e - b));
  });
}

void parallel_copy_2d(double* dst, std::size_t ld_dst, const double* src, std::size_t ld_src,
                      std::size_t rows, std::size_t cols) {
  if (rows == 0 || cols == 0) return;
  if (rows == ld_dst && rows == ld_src) return parallel_copy(dst, src, rows * cols);
  const std::size_t grain = std::max<std::size_t>(1, kChunk / rows);  // columns per task
  tbb::parallel_for(tbb::blocked_range<std::size_t>(0, cols, grain), [&](const auto& r) {
    for (std::size_t j = r.begin(); j < r.end(); ++j)
      std::memcpy(dst + j * ld_dst, src + j * ld_src, sizeof(double) * rows);
  });
}

}  // namespace strata
