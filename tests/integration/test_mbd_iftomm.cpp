// strata::mbd — the IFToMM multibody benchmark problems bundled in models/iftomm/, each
// against a reference that does not come from strata's integrator: closed forms (the
// simple pendulum and the N-four-bar reduce to one pendulum equation, integrated here with
// classical Runge–Kutta), a second formulation of the same mechanism (Bricard with a
// cylindrical joint instead of the redundant revolute), and invariants (energy of
// conservative models, constraint residuals of accepted steps, dense output against runs
// that end at the output times). docs/formulation.md §7 lists what each test shows.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>

#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"

namespace strata::mbd {
namespace {

using json = nlohmann::json;

std::string model_path(const std::string& name) {
  return std::string(STRATA_MODELS_DIR) + "/iftomm/" + name + ".json";
}

// y'' = f(y) from (y0, 0 ... y0') over [0, T] by classical RK4 with step h: the
// reference of the one-degree-of-freedom problems (error ~ h^4, 1e-13 at h = 1e-4 here).
std::pair<double, double> rk4(const std::function<double(double)>& f, double y, double yd, double T,
                              double h) {
  const int steps = static_cast<int>(std::lround(T / h));
  for (int k = 0; k < steps; ++k) {
    const double k1y = yd, k1v = f(y);
    const double k2y = yd + 0.5 * h * k1v, k2v = f(y + 0.5 * h * k1y);
    const double k3y = yd + 0.5 * h * k2v, k3v = f(y + 0.5 * h * k2y);
    const double k4y = yd + h * k3v, k4v = f(y + h * k3y);
    y += h / 6 * (k1y + 2 * k2y + 2 * k3y + k4y);
    yd += h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v);
  }
  return {y, yd};
}

// Runs a model with its file's settings (the "documented settings"), keeping the rows.
SimulationResult run(const Model& m, SimulationHistory* h, IntegratorOptions* override = nullptr) {
  SimulationOptions o = simulation_options(m, RunSettings{});
  if (override) {
    override->t_end = override->t_end > 0 ? override->t_end : o.integrator.t_end;
    o.integrator = *override;
  }
  o.history = h;
  return simulate(m, o);
}

double max_energy_drift(const SimulationHistory& h) {
  const double e0 = h.steps.front().kinetic_energy + h.steps.front().potential_energy;
  double d = 0;
  for (const StepRecord& s : h.steps)
    d = std::max(d, std::abs(s.kinetic_energy + s.potential_energy - e0));
  return d;
}

TEST(Iftomm, SimplePendulumMatchesItsEquation) {
  const Model m = load_model(model_path("simple_pendulum"));
  SimulationHistory h;
  const SimulationResult r = run(m, &h);
  ASSERT_TRUE(r.complete) << r.message;
  // θ measured from +x, mass at (cos θ, sin θ): θ'' = −g cos θ, θ(0) = π
  const auto [th, thd] = rk4([](double y) { return -9.81 * std::cos(y); }, M_PI, 0, 10, 1e-4);
  const double* q = &h.positions[h.positions.size() - m.n];
  std::printf("A01 at t = 10 s: (%.12f, %.12f), reference (%.12f, %.12f)\n", q[0], q[1],
              std::cos(th), std::sin(th));
  EXPECT_NEAR(q[0], std::cos(th), 1e-6);
  EXPECT_NEAR(q[1], std::sin(th), 1e-6);
  EXPECT_LT(r.reference_error, 1e-6);  // the file's reference value is the same
}

TEST(Iftomm, NFourBarPassesItsSingularConfigurationsToTheReference) {
  const Model m = load_model(model_path("n_four_bar"));
  SimulationHistory h;
  const SimulationResult r = run(m, &h);
  ASSERT_TRUE(r.complete) << r.message;
  // parallelogram branch: T = 1.5 θ'², V = 3.5 g cos θ (θ the cranks' angle from the
  // vertical, clockwise), so 3 θ'' = 3.5 g sin θ; B0 = (sin θ, cos θ)
  const auto [th, thd] = rk4([](double y) { return 3.5 * 9.81 / 3 * std::sin(y); }, 0, 1, 10, 1e-4);
  const int k = m.find_body("crank0");
  const double* q = &h.positions[h.positions.size() - m.n];
  const Vec3<double> b0 = m.point_position(k, {{0.5, 0, 0}}, q);
  const double err = std::hypot(b0[0] - std::sin(th), b0[1] - std::cos(th));
  std::printf(
      "A02 at t = 10 s: B0 = (%.10f, %.10f), reference (%.10f, %.10f), error %.3e; "
      "%lld steps, stabilized from t = %.3f s\n",
      b0[0], b0[1], std::sin(th), std::cos(th), err, static_cast<long long>(r.stats.steps),
      r.stats.stabilized_since);
  EXPECT_LT(err, 1e-5);
  // the cranks passed the horizontal (all bars on one line) as often as the reference does
  const index_t phi = m.bodies[k].offset + 2;
  int passes = 0;
  for (std::size_t row = 1; row < h.time.size(); ++row)
    passes +=
        std::sin(h.positions[(row - 1) * m.n + phi]) * std::sin(h.positions[row * m.n + phi]) <= 0;
  EXPECT_EQ(passes, static_cast<int>(std::floor((th - M_PI / 2) / M_PI)) + 1);
  EXPECT_EQ(passes, 10);
  EXPECT_LT(max_energy_drift(h), 1e-4 * 35.835);
  EXPECT_NEAR(m.reference.points[0].position[0], std::sin(th), 1e-9);
  EXPECT_NEAR(m.reference.points[0].position[1], std::cos(th), 1e-9);
}

TEST(Iftomm, BricardWithSixRevoluteJointsConservesEnergy) {
  const Model m = load_model(model_path("bricard"));
  SimulationHistory h;
  const SimulationResult r = run(m, &h);
  ASSERT_TRUE(r.complete) << r.message;
  ASSERT_EQ(r.removed_constraints.size(), 1u);
  double kmax = 0;
  for (const StepRecord& s : h.steps) kmax = std::max(kmax, s.kinetic_energy);
  const double drift = max_energy_drift(h);
  std::printf(
      "A04 (6 revolute joints, default settings): energy drift %.3e J over 10 s, largest "
      "kinetic energy %.3f J; removed %s\n",
      drift, kmax, r.removed_constraints[0].c_str());
  EXPECT_GT(kmax, 1.0);  // it moves
  EXPECT_LT(drift, 1e-4);
  EXPECT_LT(r.max_position_violation, 1e-8);  // the removed equation holds too
}

TEST(Iftomm, BricardMatchesTheSameMechanismWithoutRedundancy) {
  // the 6R loop against the loop closed by a cylindrical joint at P5 (no redundant
  // equation, a different constraint Jacobian): the same motion, to the Newton tolerance
  json doc = load_model_document(model_path("bricard"));
  doc["simulation"] = {
      {"t_end", 2.0}, {"step", 2e-4}, {"order", 4}, {"newton_rtol", 1e-10}, {"newton_atol", 1e-12}};
  const Model six = build_model(doc, "bricard-6R");
  doc["joints"][5]["type"] = "cylindrical";
  const Model cyl = build_model(doc, "bricard-cylindrical");
  SimulationHistory h6, hc;
  const SimulationResult r6 = run(six, &h6), rc = run(cyl, &hc);
  ASSERT_TRUE(r6.complete) << r6.message;
  ASSERT_TRUE(rc.complete) << rc.message;
  EXPECT_EQ(r6.removed_constraints.size(), 1u);
  EXPECT_TRUE(rc.removed_constraints.empty());
  const int k = six.find_body("rod3");
  const Vec3<double> a =
      six.point_position(k, {{0, 0, 0.5}}, &h6.positions[h6.positions.size() - six.n]);
  const Vec3<double> b =
      cyl.point_position(k, {{0, 0, 0.5}}, &hc.positions[hc.positions.size() - cyl.n]);
  const double d = std::sqrt((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]) +
                             (a[2] - b[2]) * (a[2] - b[2]));
  std::printf("A04 P3 at t = 2 s: 6R (%.12f, %.12f, %.12f), cylindrical: %.3e apart\n", a[0], a[1],
              a[2], d);
  EXPECT_LT(d, 1e-8);
  EXPECT_GT(std::abs(a[1] + 1), 0.1);  // P3 has moved well away from its start
}

TEST(Iftomm, NoStepOffTheConstraintsIsAccepted) {
  // The four-bar near its singular configuration, with every 50th converged step attempt
  // pushed off the constraints by 1e-4 rad: each such attempt must be rejected (and redone
  // with a smaller step), and every accepted step must satisfy the constraints.
  const Model m = load_model(model_path("n_four_bar"));
  IntegratorOptions o = simulation_options(m, RunSettings{}).integrator;
  o.t_end = 1.0;
  o.step = 1e-3;
  o.order = 2;
  int calls = 0, perturbed = 0;
  const index_t phi = m.bodies[m.find_body("crank1")].offset + 2;
  o.perturb_converged = [&](double* q, double*) {
    if (++calls % 50 == 0) {
      q[phi] += 1e-4;
      ++perturbed;
    }
  };
  SimulationHistory h;
  const SimulationResult r = run(m, &h, &o);
  ASSERT_TRUE(r.complete) << r.message;
  EXPECT_GT(perturbed, 10);
  EXPECT_EQ(r.stats.residual_rejections, perturbed);
  double worst = 0;
  for (const StepRecord& s : h.steps) worst = std::max(worst, s.position_violation);
  EXPECT_LT(worst, 1e-9);
  EXPECT_GE(r.stats.stabilized_since, 0);  // it went through the horizontal position
}

TEST(Iftomm, PartitionedFormulationNeverAcceptsABadStep) {
  // The case: BDF5, h = 1e-4 with the partitioned formulation only (it cannot pass
  // the singular configuration reliably): no accepted step is off the constraints, and an
  // energy drift is reported.
  const Model m = load_model(model_path("n_four_bar"));
  IntegratorOptions o = simulation_options(m, RunSettings{}).integrator;
  o.t_end = 1.5;
  o.step = 1e-4;
  o.order = 5;
  o.formulation = FormulationChoice::partitioned;
  SimulationHistory h;
  const SimulationResult r = run(m, &h, &o);
  std::printf("partitioned only: %s at t = %.4f s (%s)\n", r.complete ? "complete" : "stopped",
              r.t_reached, r.message.c_str());
  double worst = 0, worst_v = 0;
  for (const StepRecord& s : h.steps) {
    worst = std::max(worst, s.position_violation);
    worst_v = std::max(worst_v, s.velocity_violation);
  }
  EXPECT_LT(worst, 1e-6);
  EXPECT_LT(worst_v, 1e-3);
  // Through the singular configuration the partitioned formulation may stop, or (its
  // Newton matrices solved without static pivots) pass onto another branch, gaining
  // energy: then the energy monitor must say so.
  if (!r.complete) EXPECT_NE(r.message.find("did not converge"), std::string::npos);
  if (max_energy_drift(h) > 1.0) {
    bool warned = false;
    for (const std::string& w : r.warnings) warned |= w.find("energy") != std::string::npos;
    EXPECT_TRUE(warned) << "energy drift " << max_energy_drift(h) << " J without a warning";
  }
}

TEST(Iftomm, DenseOutputEqualsRunsEndingAtTheOutputTimes) {
  // Rows every 0.1 s from the BDF interpolation polynomial against runs with the same
  // settings that end exactly there (their last step shortened): equal to about the local
  // error tolerance. A linear interpolation would be 1e3 times off here.
  const Model m = load_model(model_path("spatial_slider_crank"));
  IntegratorOptions o = simulation_options(m, RunSettings{}).integrator;
  o.variable_step = true;
  o.order = 5;
  o.rtol = 1e-7;
  o.atol = 1e-9;
  o.step = 1e-4;
  o.max_step = 0.01;
  o.t_end = 0.5;
  SimulationOptions so = simulation_options(m, RunSettings{});
  so.integrator = o;
  so.output_interval = 0.1;
  SimulationHistory dense;
  so.history = &dense;
  const SimulationResult r = simulate(m, so);
  ASSERT_TRUE(r.complete) << r.message;
  ASSERT_EQ(dense.time.size(), 6u);
  double worst = 0;
  for (int k = 1; k <= 5; ++k) {
    EXPECT_DOUBLE_EQ(dense.time[k], 0.1 * k);
    IntegratorOptions ok = o;
    ok.t_end = 0.1 * k;
    Integrator in(m, ok);
    in.initialize();
    while (!in.done()) in.advance();
    for (index_t i = 0; i < m.n; ++i)
      worst = std::max(worst, std::abs(dense.positions[k * m.n + i] - in.q()[i]) /
                                  (o.atol + o.rtol * std::abs(in.q()[i])));
  }
  std::printf("dense output against runs ending at 0.1 k s: largest weighted difference %.3f\n",
              worst);
  EXPECT_LT(worst, 10.0);
}

TEST(Iftomm, DefaultSettingsReachTheReferenceOrWarn) {
  for (const char* name : {"simple_pendulum", "n_four_bar", "andrews", "bricard",
                           "flyball_governor", "spatial_slider_crank"}) {
    SCOPED_TRACE(name);
    const Model m = load_model(model_path(name));
    ASSERT_GE(m.reference.time, 0) << "no reference in the model file";
    const SimulationResult r = run(m, nullptr);
    ASSERT_TRUE(r.complete) << r.message;
    ASSERT_GE(r.reference_error, 0);
    std::printf("%-22s default settings: deviation %.3e at t = %g s, %zu warning(s)\n", name,
                r.reference_error, m.reference.time, r.warnings.size());
    if (r.reference_error > m.reference.tolerance) EXPECT_FALSE(r.warnings.empty());
    EXPECT_LE(r.reference_error, 1e-3);  // (the bundled defaults are chosen to reach it)
  }
}

}  // namespace
}  // namespace strata::mbd
