// strata — the vector logarithm of base/vector_math.hpp against the scalar std::log (an
// independent implementation, glibc's libm): fresh random magnitudes over the whole
// double range (subnormal, tiny, huge, negative, zero) at the sizes the vector loop's
// remainder handling sees (1, 2, 3, 5, 733 and more), in place and out of place.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <vector>

#include "base/vector_math.hpp"

namespace strata::detail {
namespace {

// a random finite double: sign, zero (1 in 8), subnormal (1 in 8) or a normal number whose
// exponent is drawn over the whole range
double draw(std::mt19937_64& rng) {
  std::uniform_int_distribution<int> kind(0, 7);
  std::uniform_real_distribution<double> mant(1.0, 2.0);
  const double sign = rng() % 2 ? -1.0 : 1.0;
  switch (kind(rng)) {
    case 0:
      return 0.0 * sign;
    case 1:
      return sign * mant(rng) * std::numeric_limits<double>::denorm_min() *
             static_cast<double>(rng() % (std::uint64_t{1} << 51) + 1);
    default:
      return sign * std::ldexp(mant(rng), std::uniform_int_distribution<int>(-1021, 1022)(rng));
  }
}

// |x − y| within `ulps` units in the last place of y
bool within_ulps(double x, double y, double ulps) {
  if (x == y) return true;
  const double ulp =
      std::nextafter(std::abs(y), std::numeric_limits<double>::infinity()) - std::abs(y);
  return std::abs(x - y) <= ulps * ulp;
}

TEST(VectorMath, LogMagnitudesAgainstScalarLog) {
  std::mt19937_64 rng(std::random_device{}());
  for (index_t n : {0, 1, 2, 3, 5, 7, 8, 9, 16, 733, 10007}) {
    std::vector<double> a(static_cast<std::size_t>(n));
    for (double& x : a) x = draw(rng);
    std::vector<double> out(a.size(), -1.0);
    const index_t zeros = log_magnitudes(a.data(), out.data(), n);
    index_t expected_zeros = 0;
    for (index_t k = 0; k < n; ++k) {
      if (a[k] == 0.0) {
        ++expected_zeros;
        EXPECT_EQ(out[k], 0.0) << "n " << n << " k " << k;
        continue;
      }
      const double ref = std::log(std::abs(a[k]));
      EXPECT_TRUE(within_ulps(out[k], ref, 2.0)) << "n " << n << " k " << k << ": log|" << a[k]
                                                 << "| = " << out[k] << ", std::log " << ref;
    }
    EXPECT_EQ(zeros, expected_zeros) << "n " << n;
    // in place: the same results
    std::vector<double> in_place = a;
    EXPECT_EQ(log_magnitudes(in_place.data(), in_place.data(), n), zeros);
    EXPECT_EQ(in_place, out) << "n " << n;
  }
}

TEST(VectorMath, LogMagnitudesOfExactPowersAndOne) {
  // exact cases: log 1 = 0, and log 2^k = k log 2 to within the rounding of both sides
  std::vector<double> a = {1.0, -1.0, 2.0, 0.5, std::ldexp(1.0, 1000), std::ldexp(1.0, -1074)};
  std::vector<double> out(a.size());
  EXPECT_EQ(log_magnitudes(a.data(), out.data(), static_cast<index_t>(a.size())), 0);
  EXPECT_EQ(out[0], 0.0);
  EXPECT_EQ(out[1], 0.0);
  EXPECT_TRUE(within_ulps(out[2], std::log(2.0), 1.0));
  EXPECT_TRUE(within_ulps(out[3], -std::log(2.0), 1.0));
  EXPECT_TRUE(within_ulps(out[4], 1000 * std::log(2.0), 2.0));
  EXPECT_TRUE(within_ulps(out[5], -1074 * std::log(2.0), 2.0));
}

}  // namespace
}  // namespace strata::detail
