// strata::mbd — validation: Andrews' squeezer mechanism (Hairer & Wanner, Solving ODEs II,
// §VII.7; Test Set for IVP Solvers, problem "andrews"), modelled in absolute planar
// coordinates with joints, against the test set's reference solution at t = 0.03 s.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"

namespace strata::mbd {
namespace {

// Reference solution at t = 0.03 (test set, relative-angle coordinates).
constexpr double kReference[7] = {15.81077119629904,  -15.75637105984298, 0.04082224013073101,
                                  -0.5347301163226948, 0.5244099658805304, 0.5347301163226948,
                                  1.048080741042263};

// Max over components of |q − ref| / max(|ref|, 1e-2·‖ref‖∞)... reported as the test
// set does: the relative error of each component against the reference.
double run(double h, int order, bool dense, std::array<double, 7>* angles = nullptr) {
  Model model = build_model(andrews_squeezer(), "andrews");
  IntegratorOptions o;
  o.t_end = 0.03;
  o.step = h;
  o.order = order;
  o.newton_rtol = 1e-11;
  o.newton_atol = 1e-13;
  o.dense_solver = dense;
  o.backend = Backend::cpu;
  o.threads = 1;
  Integrator integ(model, o);
  integ.initialize();
  while (!integ.done()) integ.advance();
  EXPECT_NEAR(integ.t(), 0.03, 1e-15);
  const auto rel = andrews_relative_angles(integ.q().data());
  if (angles) *angles = rel;
  double err = 0;
  for (int i = 0; i < 7; ++i)
    err = std::max(err, std::abs(rel[i] - kReference[i]) / std::abs(kReference[i]));
  return err;
}

TEST(Andrews, MatchesReferenceSolution) {
  std::array<double, 7> q;
  const double err = run(2.5e-6, 2, false, &q);
  for (int i = 0; i < 7; ++i) std::printf("  q%d = %.15g (ref %.15g)\n", i, q[i], kReference[i]);
  std::printf("max relative error %.3e\n", err);
  EXPECT_LT(err, 1e-5);
}

}  // namespace
}  // namespace strata::mbd
