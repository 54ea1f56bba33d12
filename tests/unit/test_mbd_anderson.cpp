// strata::mbd — Anderson acceleration (mbd/anderson.hpp) on linear fixed-point maps
// g(x) = M x + b, against the fixed point x* = (I − M)⁻¹ b from dense LAPACK (dgesv).
// On a linear map Anderson acceleration of depth m ≥ d (d the dimension) is GMRES in
// disguise (Walker & Ni 2011, Theorem 2.2): it reaches x* after at most d + 1 maps.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "base/blas.hpp"
#include "mbd/anderson.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

struct LinearMap {
  index_t n;
  std::vector<double> m, b;  // M column-major n×n
  void apply(const double* x, double* g) const {
    for (index_t i = 0; i < n; ++i) g[i] = b[i];
    for (index_t j = 0; j < n; ++j)
      for (index_t i = 0; i < n; ++i) g[i] += m[i + j * n] * x[j];
  }
  std::vector<double> fixed_point() const {  // (I − M) x = b by dense LU
    std::vector<double> a(n * n), x = b;
    for (index_t k = 0; k < n * n; ++k) a[k] = -m[k];
    for (index_t i = 0; i < n; ++i) a[i + i * n] += 1;
    std::vector<int> piv(n);
    const int ni = static_cast<int>(n), one = 1;
    int info = 0;
    dgesv_(&ni, &one, a.data(), &ni, piv.data(), x.data(), &ni, &info);
    EXPECT_EQ(info, 0);
    return x;
  }
};

// M with ‖M‖₂ ≤ rho: a random matrix scaled by its Frobenius norm (an upper bound).
LinearMap random_map(index_t n, double rho, std::mt19937_64& rng) {
  std::normal_distribution<double> g(0, 1);
  LinearMap f{n, std::vector<double>(n * n), std::vector<double>(n)};
  double fro = 0;
  for (double& v : f.m) fro += (v = g(rng)) * v;
  for (double& v : f.m) v *= rho / std::sqrt(fro);
  for (double& v : f.b) v = g(rng);
  return f;
}

double max_rel_error(const std::vector<double>& x, const std::vector<double>& ref) {
  double e = 0, s = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    e = std::max(e, std::abs(x[i] - ref[i]));
    s = std::max(s, std::abs(ref[i]));
  }
  return e / s;
}

// Iterates x ← AA(x, g(x) − x) from x = 0 for `maps` maps; returns x.
std::vector<double> iterate(const LinearMap& f, AndersonMixing& aa, const std::vector<double>& w,
                            int maps) {
  std::vector<double> x(f.n, 0.0), g(f.n), d(f.n);
  for (int k = 0; k < maps; ++k) {
    f.apply(x.data(), g.data());
    for (index_t i = 0; i < f.n; ++i) d[i] = g[i] - x[i];
    aa.step(x.data(), d.data(), w.data(), f.n);
  }
  return x;
}

TEST(Anderson, DepthAtLeastTheDimensionReachesTheFixedPoint) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 2.0);
  for (index_t n : {1, 2, 3, 5}) {
    // contraction 0.9: the plain iteration is still 0.9^(n+1) away after n + 1 maps
    const LinearMap f = random_map(n, 0.9, rng);
    const std::vector<double> ref = f.fixed_point();
    std::vector<double> w(n);
    for (double& v : w) v = u(rng);  // the weighted norm changes the fit, not the limit
    AndersonMixing aa(static_cast<int>(n));
    const std::vector<double> x = iterate(f, aa, w, static_cast<int>(n) + 2);
    EXPECT_LT(max_rel_error(x, ref), 1e-9) << "n = " << n;
  }
}

TEST(Anderson, DepthZeroIsThePlainIteration) {
  auto rng = test::fresh_rng();
  const LinearMap f = random_map(5, 0.5, rng);
  std::vector<double> w(5, 1.0), x(5, 0.0), g(5);
  AndersonMixing aa(0);
  const std::vector<double> y = iterate(f, aa, w, 4);
  for (int k = 0; k < 4; ++k) {  // x + (g(x) − x): the update as the mixing receives it
    f.apply(x.data(), g.data());
    for (int i = 0; i < 5; ++i) x[i] += g[i] - x[i];
  }
  for (int i = 0; i < 5; ++i) EXPECT_EQ(y[i], x[i]);
}

// M = U diag(λ) Uᵀ, U a random Householder reflector: three slow modes (λ = 0.95, 0.9,
// −0.9), the rest |λ| ≤ 0.2 — what a stale Jacobian leaves when a few stiff modes changed.
LinearMap few_slow_modes(index_t n, std::mt19937_64& rng) {
  std::normal_distribution<double> g(0, 1);
  std::uniform_real_distribution<double> u(-0.2, 0.2);
  std::vector<double> v(n), lam(n);
  double vv = 0;
  for (double& x : v) vv += (x = g(rng)) * x;
  for (double& l : lam) l = u(rng);
  lam[0] = 0.95, lam[1] = 0.9, lam[2] = -0.9;
  LinearMap f{n, std::vector<double>(n * n), std::vector<double>(n)};
  std::vector<double> uu(n * n);  // U = I − 2 v vᵀ / vᵀv
  for (index_t j = 0; j < n; ++j)
    for (index_t i = 0; i < n; ++i) uu[i + j * n] = (i == j) - 2 * v[i] * v[j] / vv;
  for (index_t j = 0; j < n; ++j)
    for (index_t k = 0; k < n; ++k) {
      const double c = lam[k] * uu[j + k * n];  // λ_k U(j, k)
      for (index_t i = 0; i < n; ++i) f.m[i + j * n] += uu[i + k * n] * c;
    }
  for (double& x : f.b) x = g(rng);
  return f;
}

TEST(Anderson, ShallowDepthOutrunsThePlainIterationOnALargeMap) {
  // n = 733: the plain iteration is held back by the slow modes (0.95^60 ≈ 0.05 of their
  // error left after 60 maps); depth 3 fits them away and converges at the fast modes' rate
  auto rng = test::fresh_rng();
  const index_t n = 733;
  const LinearMap f = few_slow_modes(n, rng);
  const std::vector<double> ref = f.fixed_point();
  std::vector<double> w(n, 1.0);
  AndersonMixing plain(0), aa(3);
  const std::vector<double> xp = iterate(f, plain, w, 60), xa = iterate(f, aa, w, 60);
  EXPECT_GT(max_rel_error(xp, ref), 1e-4);
  // depth 3's error after 60 maps is limited by the rounding of its least-squares fits, which
  // spreads up to about 1e-10 over fresh draws: five orders below the plain iteration's
  EXPECT_LT(max_rel_error(xa, ref), 1e-9);
}

TEST(Anderson, StalledIteratesStayFinite) {
  // the same update twice (a stalled iteration) makes a zero difference: it is dropped,
  // the step stays the plain update and finite; reset() forgets the history
  std::vector<double> x{1.0, 2.0, 3.0}, f{0.5, -0.25, 0.0}, w{1.0, 1.0, 0.0};
  AndersonMixing aa(3);
  aa.step(x.data(), f.data(), w.data(), 3);
  std::vector<double> y = x;
  aa.step(y.data(), f.data(), w.data(), 3);  // f_k − f_{k−1} = 0
  for (int i = 0; i < 3; ++i) {
    EXPECT_TRUE(std::isfinite(y[i]));
    EXPECT_DOUBLE_EQ(y[i], x[i] + f[i]);
  }
  aa.reset();
  std::vector<double> z = y;
  EXPECT_EQ(aa.step(z.data(), f.data(), w.data(), 3), 0);
  for (int i = 0; i < 3; ++i) EXPECT_DOUBLE_EQ(z[i], y[i] + f[i]);
}

}  // namespace
}  // namespace strata::mbd
