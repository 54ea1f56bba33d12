// strata::mbd — physics checks against analytic facts: energy conservation of a
// conservative chain at the integrator's order, a body at rest stays at rest, constraint
// violations at Newton tolerance, driving constraints reproduce their motion, and the
// BDF order on Andrews' squeezer.
#include <gtest/gtest.h>

#include <cmath>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"

namespace strata::mbd {
namespace {

using json = nlohmann::json;

IntegratorOptions options(double t_end, double h, int order) {
  IntegratorOptions o;
  o.t_end = t_end;
  o.step = h;
  o.order = order;
  o.newton_rtol = 1e-10;
  o.newton_atol = 1e-12;
  return o;
}

// |E(T) − E(0)| for the spatial chain of 3 links with spherical joints.
double energy_drift(double h, int order, double* max_violation = nullptr) {
  const Model m = build_model(pendulum_chain(3, true), "chain");
  Integrator in(m, options(1.0, h, order));
  in.initialize();
  double k0, p0, k, p;
  in.system().energy(in.q().data(), in.v().data(), 0, &k0, &p0);
  double worst = 0;
  while (!in.done()) {
    in.advance();
    double pv, vv;
    in.constraint_violation(&pv, &vv);
    worst = std::max(worst, pv);
  }
  in.system().energy(in.q().data(), in.v().data(), in.t(), &k, &p);
  if (max_violation) *max_violation = worst;
  return std::abs(k + p - k0 - p0);
}

TEST(MbdPhysics, ConservativeChainConservesEnergyToTheOrder) {
  for (int order : {1, 2}) {
    const double e1 = energy_drift(4e-3, order), e2 = energy_drift(2e-3, order),
                 e3 = energy_drift(1e-3, order);
    std::printf("BDF%d energy drift over 1 s: h=4e-3 %.3e, 2e-3 %.3e, 1e-3 %.3e\n", order, e1, e2,
                e3);
    const double observed = std::log2(e2 / e3);
    EXPECT_NEAR(observed, order, 0.35) << "observed order " << observed;
    EXPECT_LT(e3, e2);
  }
}

TEST(MbdPhysics, ConstraintViolationStaysAtNewtonTolerance) {
  double violation = 0;
  energy_drift(2e-3, 2, &violation);
  EXPECT_LT(violation, 1e-9);
}

TEST(MbdPhysics, BodyAtRestOnTheGroundStaysAtRest) {
  // a box on four contact spheres, started at its static equilibrium
  const double m = 10, k = 1e6, g = 9.81, onset = 1e-4;
  // elastic force e(δ) = kδ²/(2·onset) below the onset depth, k(δ − onset/2) beyond
  const double f = m * g / 4;
  const double delta = f / k >= onset / 2 ? f / k + onset / 2 : std::sqrt(2 * onset * f / k);
  json j = {{"type", "spatial"}, {"gravity", {0, 0, -g}}};
  j["bodies"] = {{{"name", "box"},
                  {"mass", m},
                  {"inertia", {0.2, 0.2, 0.3}},
                  {"position", {0.3, -0.2, 0.1 - delta}}}};
  for (double x : {-0.2, 0.2})
    for (double y : {-0.2, 0.2})
      j["forces"].push_back({{"type", "contact"},
                             {"body", "box"},
                             {"point", {x, y, -0.09}},
                             {"radius", 0.01},
                             {"stiffness", k},
                             {"damping", 2e3},
                             {"friction", 0.6}});
  const Model model = build_model(j, "box");
  Integrator in(model, options(1.0, 1e-3, 2));
  in.initialize();
  while (!in.done()) in.advance();
  const auto& q = in.q();
  EXPECT_NEAR(q[0], 0.3, 1e-12);
  EXPECT_NEAR(q[1], -0.2, 1e-12);
  EXPECT_NEAR(q[2], 0.1 - delta, 1e-9);
  for (double v : in.v()) EXPECT_LT(std::abs(v), 1e-9);
  EXPECT_NEAR(q[3], 1.0, 1e-12);  // no rotation
}

TEST(MbdPhysics, DrivingConstraintReproducesItsMotion) {
  // a planar crank under gravity whose angle is prescribed by a rotation driver:
  // θ(t) = θ0 + 0.5 sin(3t + 0.1) − 0.5 sin 0.1
  const double th0 = 0.3;
  json j = {{"type", "planar"}, {"gravity", {0, -9.81}}};
  j["bodies"] = {{{"name", "crank"},
                  {"mass", 2},
                  {"inertia", 0.1},
                  {"position", {0.25 * std::cos(th0), 0.25 * std::sin(th0)}},
                  {"angle", th0}}};
  j["joints"] = {
      {{"type", "revolute"}, {"body_i", "ground"}, {"body_j", "crank"}, {"point", {0, 0}}},
      {{"name", "drive"},
       {"type", "rotation_driver"},
       {"body_i", "ground"},
       {"body_j", "crank"},
       {"point", {0, 0}},
       {"motion",
        {{"harmonic",
          {{"amplitude", 0.5}, {"omega", 3}, {"phase", 0.1}, {"offset", -0.5 * std::sin(0.1)}}}}}}};
  const Model model = build_model(j, "crank");
  Integrator in(model, options(2.0, 1e-3, 2));
  in.initialize();
  double worst = 0, worst_v = 0, worst_a = 0;
  while (!in.done()) {
    in.advance();
    const double t = in.t();
    const double th = th0 + 0.5 * std::sin(3 * t + 0.1) - 0.5 * std::sin(0.1);
    const double thd = 1.5 * std::cos(3 * t + 0.1), thdd = -4.5 * std::sin(3 * t + 0.1);
    worst = std::max(worst, std::abs(in.q()[2] - th));
    worst_v = std::max(worst_v, std::abs(in.v()[2] - thd));
    worst_a = std::max(worst_a, std::abs(in.a()[2] - thdd));
  }
  EXPECT_LT(worst, 1e-10);
  EXPECT_LT(worst_v, 1e-8);
  EXPECT_LT(worst_a, 1e-6);
}

TEST(MbdPhysics, AndrewsErrorShowsTheBdfOrder) {
  auto beta_error = [](double h, int order) {
    const Model m = build_model(andrews_squeezer(), "andrews");
    Integrator in(m, options(0.03, h, order));
    in.initialize();
    while (!in.done()) in.advance();
    return std::abs(andrews_relative_angles(in.q().data())[0] - 15.81077119629904);
  };
  for (int order : {1, 2}) {
    const double e1 = beta_error(1e-5, order), e2 = beta_error(5e-6, order);
    const double observed = std::log2(e1 / e2);
    std::printf("Andrews BDF%d: error of beta %.3e (h=1e-5), %.3e (h=5e-6): order %.2f\n", order,
                e1, e2, observed);
    EXPECT_NEAR(observed, order, 0.3);
  }
}

}  // namespace
}  // namespace strata::mbd
