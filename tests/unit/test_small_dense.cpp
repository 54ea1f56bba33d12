// The small dense kernels of the front solves (numeric/cpu/small_dense.hpp) against the
// definitions computed one column at a time in long double: y − A·x, the forward
// substitution with a unit lower triangle and the back substitution with an upper one
// (a zero diagonal entry giving 0 for its unknown), on random shapes including 1, 2, 3, 5
// and 733 rows or columns, a leading dimension larger than the rows, and zero groups of x.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "numeric/cpu/small_dense.hpp"
#include "support/test_support.hpp"

namespace strata::numeric::cpu {
namespace {

const index_t kSizes[] = {1, 2, 3, 4, 5, 7, 8, 9, 733};

// max |a − b| / max(1, max |b|)
double rel_diff(const std::vector<double>& a, const std::vector<long double>& b) {
  long double d = 0, s = 1;
  for (std::size_t i = 0; i < b.size(); ++i) {
    d = std::max(d, std::abs(static_cast<long double>(a[i]) - b[i]));
    s = std::max(s, std::abs(b[i]));
  }
  return static_cast<double>(d / s);
}

TEST(SmallDense, GemvSubtractIsYMinusAx) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t rows : kSizes)
    for (index_t cols : kSizes) {
      if (rows * cols > 100000) continue;
      SCOPED_TRACE(std::to_string(rows) + "x" + std::to_string(cols));
      const index_t lda = rows + 3;
      std::vector<double> a(static_cast<std::size_t>(lda) * cols), x(cols), y(rows);
      for (double& v : a) v = u(rng);
      for (double& v : x) v = u(rng);
      for (double& v : y) v = u(rng);
      // a group of four zeros (skipped) and a lone zero
      for (index_t j = 4; j < std::min<index_t>(cols, 8); ++j) x[j] = 0.0;
      if (cols > 2) x[cols - 1] = 0.0;
      std::vector<long double> ref(y.begin(), y.end());
      for (index_t j = 0; j < cols; ++j)
        for (index_t i = 0; i < rows; ++i)
          ref[i] -= static_cast<long double>(a[i + j * lda]) * x[j];
      gemv_subtract(rows, cols, a.data(), lda, x.data(), y.data());
      EXPECT_LE(rel_diff(y, ref), 4 * cols * 1.2e-16);
    }
}

// A well-conditioned triangle: off-diagonal entries scaled by 1/k, diagonal ±(1..2).
std::vector<double> triangle(index_t k, index_t ld, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> t(static_cast<std::size_t>(ld) * k);
  for (double& v : t) v = u(rng) / static_cast<double>(k);
  for (index_t j = 0; j < k; ++j) t[j + j * ld] = (u(rng) < 0 ? -1 : 1) * (1 + std::abs(u(rng)));
  return t;
}

TEST(SmallDense, UnitLowerSolveIsForwardSubstitution) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t k : kSizes) {
    SCOPED_TRACE("k=" + std::to_string(k));
    const index_t ld = k + 2;
    const std::vector<double> l = triangle(k, ld, rng);
    std::vector<double> w(k);
    for (double& v : w) v = u(rng);
    std::vector<long double> ref(w.begin(), w.end());
    for (index_t j = 0; j < k; ++j)  // the diagonal and the upper part are not read
      for (index_t i = j + 1; i < k; ++i)
        ref[i] -= static_cast<long double>(l[i + j * ld]) * ref[j];
    unit_lower_solve(k, l.data(), ld, w.data());
    EXPECT_LE(rel_diff(w, ref), 64 * k * 1.2e-16);
  }
}

TEST(SmallDense, UpperSolveIsBackSubstitutionWithZeroForAZeroPivot) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (index_t k : kSizes)
    for (bool zero_pivot : {false, true}) {
      SCOPED_TRACE("k=" + std::to_string(k) + (zero_pivot ? " with a zero pivot" : ""));
      const index_t ld = k + 1;
      std::vector<double> t = triangle(k, ld, rng);
      const index_t z = k / 2;
      if (zero_pivot) t[z + z * ld] = 0.0;
      std::vector<double> w(k);
      for (double& v : w) v = u(rng);
      std::vector<long double> ref(w.begin(), w.end());
      for (index_t j = k - 1; j >= 0; --j) {
        const double d = t[j + j * ld];
        ref[j] = d != 0.0 ? ref[j] / d : 0.0L;
        for (index_t i = 0; i < j; ++i) ref[i] -= static_cast<long double>(t[i + j * ld]) * ref[j];
      }
      upper_solve(k, t.data(), ld, w.data());
      for (double v : w) ASSERT_TRUE(std::isfinite(v));
      if (zero_pivot) EXPECT_EQ(w[z], 0.0);
      EXPECT_LE(rel_diff(w, ref), 64 * k * 1.2e-16);
    }
}

}  // namespace
}  // namespace strata::numeric::cpu
