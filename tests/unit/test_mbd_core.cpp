// strata::mbd — building blocks against closed forms: BDF coefficients (classical
// constant-step values, exactness on polynomials, equal steps' nodes), Euler-parameter kinematics,
// the automatic derivatives of the Taylor-series types, and coordinate partitioning.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "mbd/autodiff.hpp"
#include "mbd/integrator.hpp"
#include "mbd/linalg.hpp"
#include "mbd/partition.hpp"

namespace strata::mbd {
namespace {

TEST(MbdCore, BdfCoefficientsOnAUniformGrid) {
  const double h = 0.1;
  // BDF2: (3/2 y_n − 2 y_{n−1} + 1/2 y_{n−2}) / h;  BDF3: (11/6, −3, 3/2, −1/3) / h
  auto a2 = bdf_coefficients({1.0, 1.0 - h, 1.0 - 2 * h});
  EXPECT_NEAR(a2[0] * h, 1.5, 1e-12);
  EXPECT_NEAR(a2[1] * h, -2.0, 1e-12);
  EXPECT_NEAR(a2[2] * h, 0.5, 1e-12);
  auto a3 = bdf_coefficients({1.0, 1.0 - h, 1.0 - 2 * h, 1.0 - 3 * h});
  const double c3[4] = {11.0 / 6, -3.0, 1.5, -1.0 / 3};
  for (int j = 0; j < 4; ++j) EXPECT_NEAR(a3[j] * h, c3[j], 1e-12);
}

TEST(MbdCore, BdfCoefficientsDifferentiatePolynomialsExactly) {
  // uneven points: the order-p formula is exact for polynomials of degree p
  const std::vector<double> t = {2.0, 1.9, 1.75, 1.7, 1.4};
  for (int p = 1; p <= 4; ++p) {
    std::vector<double> T(t.begin(), t.begin() + p + 1);
    const auto a = bdf_coefficients(T);
    double d = 0;
    for (int j = 0; j <= p; ++j) d += a[j] * std::pow(T[j], p);
    EXPECT_NEAR(d, p * std::pow(t[0], p - 1), 1e-9) << "order " << p;
  }
}

// Times accumulated step by step (t += h, as the integrator does) drift from multiples of
// h by rounding: bdf_nodes gives every step of equal size the same coefficients bit for
// bit (the raw time differences do not), unequal steps keep their own, and the nodes
// still differentiate polynomials exactly.
TEST(MbdCore, BdfNodesOfEqualStepsGiveTheSameCoefficients) {
  for (const double h : {1e-3, 1e-4, 0.1}) {
    SCOPED_TRACE("h = " + std::to_string(h));
    std::vector<double> t = {0.0};  // newest last
    for (int i = 0; i < 3000; ++i) t.push_back(t.back() + h);
    const std::vector<double> first = bdf_coefficients(bdf_nodes(t[3] + h, {t[3], t[2], t[1]}, h));
    int raw_differ = 0;
    for (std::size_t i = 3; i + 1 < t.size(); ++i) {
      const double tn = t[i] + h;
      const std::vector<double> past = {t[i], t[i - 1], t[i - 2]};
      ASSERT_EQ(bdf_coefficients(bdf_nodes(tn, past, h)), first) << "step " << i;
      raw_differ += bdf_coefficients({tn, t[i], t[i - 1], t[i - 2]})[0] !=
                    bdf_coefficients({t[4], t[3], t[2], t[1]})[0];
    }
    EXPECT_GT(raw_differ, 0);  // what the nodes are for
    const double c3[4] = {11.0 / 6, -3.0, 1.5, -1.0 / 3};
    for (int j = 0; j < 4; ++j) EXPECT_NEAR(first[j] * h, c3[j], 1e-12);
  }
  // unequal steps (h, h/2, h): the gaps are their own
  const double h = 0.01;
  const std::vector<double> T = bdf_nodes(1.0 + h, {1.0, 1.0 - h / 2, 1.0 - 1.5 * h}, h);
  EXPECT_NEAR(T[2], -1.5 * h, 1e-15);
  EXPECT_NEAR(T[3], -2.5 * h, 1e-15);
  const auto a = bdf_coefficients(T);
  double d = 0;
  for (int j = 0; j < 4; ++j) d += a[j] * std::pow(T[j] - 0.3, 3);
  EXPECT_NEAR(d, 3 * 0.09, 1e-9);
}

TEST(MbdCore, EulerParametersGiveRotationsAndAngularVelocity) {
  const Vec3<double> axis{{1, -2, 0.5}};
  const Vec4<double> p = axis_angle(axis, 0.7);
  const Mat3<double> A = rot3(p);
  const Mat3<double> I = A * transpose(A);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) EXPECT_NEAR(I(i, j), i == j ? 1.0 : 0.0, 1e-14);
  const Vec4<double> back = euler_parameters(A);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(back[i], p[i], 1e-14);
  // ṗ = ½ Gᵀ ω′ and ω′ = 2 G ṗ are inverse for a unit p
  const Vec3<double> w{{0.3, -0.2, 1.1}};
  const Vec4<double> pd = GT_times(p, w) * 0.5;
  const Vec3<double> w2 = G_times(p, pd) * 2.0;
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(w2[i], w[i], 1e-14);
}

TEST(MbdCore, TaylorSeriesGiveTimeDerivatives) {
  // f(q) = sin(q)·√q / q along q(s) = q + v s + a s²/2: c1 = ḟ, 2 c2 = f̈
  const double q = 0.8, v = -1.3, a = 2.1;
  Jet2<double> z(q, v, 0.5 * a);
  const Jet2<double> f = sin(z) * sqrt(z) / z;
  auto F = [](double x) { return std::sin(x) * std::sqrt(x) / x; };
  const double e = 1e-4;
  auto path = [&](double s) { return F(q + v * s + 0.5 * a * s * s); };
  EXPECT_NEAR(f.c0, F(q), 1e-15);
  EXPECT_NEAR(f.c1, (path(e) - path(-e)) / (2 * e), 1e-7);
  EXPECT_NEAR(2 * f.c2, (path(e) - 2 * path(0) + path(-e)) / (e * e), 1e-5);
  // nested duals give the Hessian of x²y + sin(y)
  using D1 = Dual<double, 2>;
  using D2 = Dual<D1, 2>;
  D2 x, y;
  x.v = D1(1.5, 0);
  x.d[0] = D1(1.0);
  y.v = D1(0.4, 1);
  y.d[1] = D1(1.0);
  const D2 g = x * x * y + sin(y);
  EXPECT_NEAR(g.d[0].d[0], 2 * 0.4, 1e-15);         // ∂²/∂x²
  EXPECT_NEAR(g.d[0].d[1], 2 * 1.5, 1e-15);         // ∂²/∂x∂y
  EXPECT_NEAR(g.d[1].d[1], -std::sin(0.4), 1e-15);  // ∂²/∂y²
}

TEST(MbdCore, PartitioningChoosesANonsingularDependentSet) {
  // Φ_q of a planar pendulum pinned at the origin, link angle 0.3: 2 × 3
  SparseRows j;
  j.n_cols = 3;
  const double s = std::sin(0.3), c = std::cos(0.3);
  j.cols = {0, 2, 1, 2};
  j.vals = {1.0, 0.5 * s, 1.0, -0.5 * c};
  j.ptr = {0, 2, 4};
  const Partition p = partition_coordinates(j, 0.25, 1e-9, [](index_t r) { return "row"; });
  EXPECT_EQ(p.dependent.size(), 2u);
  ASSERT_EQ(p.independent.size(), 1u);
  EXPECT_EQ(p.independent[0], 2);  // x and y depend on the angle
  EXPECT_GT(p.quality, 0.5);
  EXPECT_NEAR(partition_quality(j, p.dependent), p.quality, 1e-15);
  // forcing the angle as dependent for the first row is poorer
  EXPECT_LT(partition_quality(j, {2, 1}), 0.5);
}

}  // namespace
}  // namespace strata::mbd
