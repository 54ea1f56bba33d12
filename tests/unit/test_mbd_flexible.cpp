// strata::mbd — the St. Venant–Kirchhoff hexahedron against closed forms: its mass, zero
// elastic force under rigid motion, the face load of a homogeneous stretch
// (P = F S, S = λ tr(E) I + 2μE), its forces as the gradient of its strain energy, and its
// closed-form tangent as the exact derivative of its forces.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "mbd/linalg.hpp"
#include "mbd/model_io.hpp"

namespace strata::mbd {
namespace {

using json = nlohmann::json;

constexpr double kE = 2e6, kNu = 0.3, kRho = 1000;

Model unit_cube(double gz = 0) {
  json j = {{"type", "spatial"}, {"gravity", {0, 0, gz}}};
  j["flexible_bodies"] = {
      {{"name", "cube"},
       {"material", {{"density", kRho}, {"young", kE}, {"poisson", kNu}}},
       {"nodes",
        {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}, {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}}},
       {"elements", {{0, 1, 2, 3, 4, 5, 6, 7}}}}};
  return build_model(j, "cube");
}

// Elastic nodal forces (a = v = 0, no gravity) at positions x.
std::vector<double> forces(const Model& m, const std::vector<double>& x) {
  ForceEval e;
  std::vector<double> zero(24, 0.0);
  m.forces[0]->evaluate(x.data(), zero.data(), zero.data(), 0, false, e);
  return e.g;
}

TEST(MbdFlexible, MassMatrixHasTheBodyMass) {
  const Model m = unit_cube(-9.81);
  ForceEval e;
  std::vector<double> zero(24, 0.0), a(24, 0.0);
  for (int n = 0; n < 8; ++n) a[3 * n] = 1.0;  // unit acceleration in x
  m.forces[0]->evaluate(m.q0.data(), zero.data(), a.data(), 0, false, e);
  double fx = 0, fz = 0;
  for (int n = 0; n < 8; ++n) fx += e.g[3 * n], fz += e.g[3 * n + 2];
  EXPECT_NEAR(fx, kRho * 1.0, 1e-9);   // Σ M a = m
  EXPECT_NEAR(fz, kRho * 9.81, 1e-9);  // gravity: −(−m g)
  // the mass matrix alone (the initial acceleration analysis's) is ∂g/∂a of the evaluation
  // with Jacobians, and its entries add up to the mass in each direction
  std::vector<double> da;
  m.forces[0]->mass_matrix(m.q0.data(), zero.data(), 0, da);
  m.forces[0]->evaluate(m.q0.data(), zero.data(), a.data(), 0, true, e);
  EXPECT_EQ(da, e.da);
  double total = 0;
  for (double v : da) total += v;
  EXPECT_NEAR(total, 3 * kRho * 1.0, 1e-9);
}

TEST(MbdFlexible, RigidMotionGivesNoElasticForce) {
  const Model m = unit_cube();
  const Mat3<double> R = rot3(axis_angle({{1, 2, 3}}, 0.9));
  std::vector<double> x(24);
  for (int n = 0; n < 8; ++n) {
    const Vec3<double> X{{m.q0[3 * n], m.q0[3 * n + 1], m.q0[3 * n + 2]}};
    const Vec3<double> y = R * X;
    for (int i = 0; i < 3; ++i) x[3 * n + i] = y[i] + 0.3 * (i + 1);
  }
  for (double f : forces(m, x)) EXPECT_NEAR(f, 0.0, 1e-7);
}

TEST(MbdFlexible, HomogeneousStretchGivesTheAnalyticFaceLoad) {
  const Model m = unit_cube();
  const double s = 1.1;  // x = diag(s, 1, 1) X
  std::vector<double> x = m.q0;
  for (int n = 0; n < 8; ++n) x[3 * n] *= s;
  const auto f = forces(m, x);
  const double lam = kE * kNu / ((1 + kNu) * (1 - 2 * kNu)), mu = kE / (2 * (1 + kNu));
  const double E11 = 0.5 * (s * s - 1);
  const double P11 = s * (lam + 2 * mu) * E11, P22 = lam * E11;
  double fx = 0, fy = 0;  // nodes on the faces X = 1 and Y = 1
  for (int n = 0; n < 8; ++n) {
    if (m.q0[3 * n] == 1.0) fx += f[3 * n];
    if (m.q0[3 * n + 1] == 1.0) fy += f[3 * n + 1];
  }
  EXPECT_NEAR(fx, P11, 1e-9 * P11);
  EXPECT_NEAR(fy, P22, 1e-9 * std::abs(P22));
}

TEST(MbdFlexible, ForcesAreTheGradientOfTheStrainEnergy) {
  const Model m = unit_cube();
  std::vector<double> x = m.q0;
  for (int i = 0; i < 24; ++i) x[i] += 0.05 * std::sin(1.7 * i);
  const auto f = forces(m, x);
  const double eps = 1e-6;
  for (int i = 0; i < 24; ++i) {
    auto xp = x, xm = x;
    xp[i] += eps;
    xm[i] -= eps;
    const double dW = (m.forces[0]->potential_energy(xp.data(), 0) -
                       m.forces[0]->potential_energy(xm.data(), 0)) /
                      (2 * eps);
    EXPECT_NEAR(f[i], dW, 1e-5 * (1 + std::abs(dW))) << "coordinate " << i;
  }
}

// A distorted, damped hexahedron at a random strained state: the closed-form Jacobians
// (∂g/∂q with the damping's second-derivative term, ∂g/∂v = β K) against differences of
// the residual that are exact for its polynomial dependence: g is cubic in q (Richardson's
// extrapolation of central differences, (4 D(h) − D(2h))/3, removes the h² term, the only
// one) and linear in v (a central difference is exact). What remains is rounding.
TEST(MbdFlexible, TangentIsTheExactDerivativeOfTheForces) {
  const unsigned seed = std::random_device{}();
  SCOPED_TRACE("seed " + std::to_string(seed));
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const double damping : {0.0, 0.02}) {
    SCOPED_TRACE("damping " + std::to_string(damping));
    json nodes = json::array();
    const int corner[8][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0},
                              {0, 0, 1}, {1, 0, 1}, {1, 1, 1}, {0, 1, 1}};
    for (const auto& c : corner)  // a hexahedron of 0.5 × 0.8 × 1.2 with its nodes moved
      nodes.push_back(
          {0.5 * c[0] + 0.08 * u(rng), 0.8 * c[1] + 0.08 * u(rng), 1.2 * c[2] + 0.08 * u(rng)});
    json j = {{"type", "spatial"}, {"gravity", {0, 0, -9.81}}};
    j["flexible_bodies"] = {
        {{"name", "block"},
         {"material", {{"density", kRho}, {"young", kE}, {"poisson", kNu}, {"damping", damping}}},
         {"nodes", nodes},
         {"elements", {{0, 1, 2, 3, 4, 5, 6, 7}}}}};
    const Model m = build_model(j, "block");
    const Force& f = *m.forces[0];
    std::vector<double> q = m.q0, v(24), a(24);
    for (int i = 0; i < 24; ++i) {
      q[i] += 0.1 * u(rng);  // strains of about ten percent
      v[i] = u(rng);
      a[i] = u(rng);
    }
    ForceEval e, p, n;
    f.evaluate(q.data(), v.data(), a.data(), 0, true, e);
    auto difference = [&](std::vector<double>& x, int k, double h, int i) {
      const double x0 = x[k];
      x[k] = x0 + h;
      f.evaluate(q.data(), v.data(), a.data(), 0, false, p);
      x[k] = x0 - h;
      f.evaluate(q.data(), v.data(), a.data(), 0, false, n);
      x[k] = x0;
      return (p.g[i] - n.g[i]) / (2 * h);
    };
    double kmax = 0;
    for (double x : e.dq) kmax = std::max(kmax, std::abs(x));
    ASSERT_GT(kmax, 0.0);
    double worst_q = 0, worst_v = 0, dvmax = 0;
    const double h = 1e-3;
    for (int k = 0; k < 24; ++k)
      for (int i = 0; i < 24; ++i) {
        const double dq = (4 * difference(q, k, h, i) - difference(q, k, 2 * h, i)) / 3;
        worst_q = std::max(worst_q, std::abs(e.dq[i * 24 + k] - dq));
        const double dv = difference(v, k, h, i);
        worst_v = std::max(worst_v, std::abs(e.dv[i * 24 + k] - dv));
        dvmax = std::max(dvmax, std::abs(dv));
      }
    EXPECT_LE(worst_q, 1e-9 * kmax) << "dg/dq, largest entry " << kmax;
    EXPECT_LE(worst_v, 1e-9 * kmax) << "dg/dv";
    if (damping == 0) EXPECT_EQ(dvmax, 0.0);
    if (damping > 0) EXPECT_GT(dvmax, 1e-3 * damping * kmax);
  }
}

}  // namespace
}  // namespace strata::mbd
