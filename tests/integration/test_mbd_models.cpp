// strata::mbd — every bundled model file loads and integrates a few steps, and the
// generators' models agree with their files; --dump-matrix output is a valid Matrix
// Market pair of the Newton system's size.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"
#include "strata/matrix_market.hpp"
#include "support/mbd_test_support.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

TEST(MbdModels, BundledModelsRunAFewSteps) {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(STRATA_MODELS_DIR)) {
    if (entry.path().extension() != ".json") continue;
    SCOPED_TRACE(entry.path().string());
    const Model m = load_model(entry.path().string());
    SimulationOptions o;
    o.integrator.t_end = 5 * m.step;
    o.integrator.step = m.step;
    o.integrator.order = m.order;
    const SimulationResult r = simulate(m, o);
    EXPECT_TRUE(r.complete) << r.message;
    EXPECT_LT(r.max_position_violation, 1e-6);
    ++count;
  }
  EXPECT_GE(count, 5);
}

// Contact pairs with a margin (track links against wheels): a pair that leaves keeps its
// entries in the Newton matrix's pattern (only values change), one that comes back into
// the pattern changes nothing either; after prune_pattern the pattern is smaller, and the
// pair's return grows it back to a superset of the pruned one (the solver then analyzes it
// keeping its order).
TEST(MbdModels, ContactPairsThatLeaveStayInThePattern) {
  test::InitializedModel t("tracked:100");
  const Model& m = t.model;
  NewtonSystem& sys = t.in.system();
  std::vector<double> q = t.in.q(), away = q;
  sys.update_candidates(q.data());
  sys.prune_pattern();  // as the first analysis does
  const SparseMatrix start = sys.matrix();
  std::size_t pair = m.forces.size();
  for (std::size_t e = 0; e < m.forces.size() && pair == m.forces.size(); ++e)
    if (m.forces[e]->margin > 0 && sys.candidates()[e]) pair = e;
  ASSERT_LT(pair, m.forces.size()) << "no contact pair with a margin in the matrix";
  for (int i = 0; i < 3; ++i) away[m.forces[pair]->dofs[i]] += 100.0;  // one body far off
  auto same_pattern = [](const SparseMatrix& a, const SparseMatrix& b) {
    return a.offsets == b.offsets && a.indices == b.indices;
  };
  EXPECT_EQ(sys.update_candidates(away.data()), 1);
  EXPECT_FALSE(sys.candidates()[pair]);
  EXPECT_TRUE(sys.pattern_forces()[pair]);
  EXPECT_TRUE(same_pattern(sys.matrix(), start));
  EXPECT_EQ(sys.update_candidates(q.data()), 1);
  EXPECT_TRUE(same_pattern(sys.matrix(), start));
  EXPECT_EQ(sys.update_candidates(away.data()), 1);
  EXPECT_TRUE(sys.prune_pattern());
  EXPECT_FALSE(sys.pattern_forces()[pair]);
  const SparseMatrix pruned = sys.matrix();
  EXPECT_LT(pruned.nnz(), start.nnz());
  EXPECT_EQ(sys.update_candidates(q.data()), 2);
  EXPECT_TRUE(same_pattern(sys.matrix(), start));
  // every entry of the pruned pattern is in the grown one (the kept order's requirement)
  const SparseMatrix& grown = sys.matrix();
  for (index_t j = 0; j < pruned.n_cols; ++j)
    for (index_t p = pruned.offsets[j]; p < pruned.offsets[j + 1]; ++p)
      EXPECT_TRUE(std::binary_search(grown.indices.begin() + grown.offsets[j],
                                     grown.indices.begin() + grown.offsets[j + 1],
                                     pruned.indices[p]));
}

// check_candidates against its definition, evaluated here pair by pair: 2 when a pair
// outside the candidate set penetrates, 1 when one is within half its margin, else 0 — the
// same on any number of threads (the elements are checked in parallel).
TEST(MbdModels, CandidateCheckMatchesItsDefinitionOnAnyThreads) {
  test::InitializedModel t("tracked:100");
  const Model& m = t.model;
  NewtonSystem& sys = t.in.system();
  const std::vector<double> q = t.in.q();
  std::vector<double> away = q;
  for (std::size_t i = 0; i < away.size(); ++i) away[i] += 100.0 * static_cast<double>(i % 7);
  sys.update_candidates(away.data());  // most pairs out of the set
  auto expected = [&](const std::vector<double>& at) {
    int status = 0;
    std::vector<double> lq;
    for (std::size_t e = 0; e < m.forces.size(); ++e) {
      const Force& f = *m.forces[e];
      if (f.margin <= 0 || sys.candidates()[e]) continue;
      lq.clear();
      for (index_t d : f.dofs) lq.push_back(at[d]);
      const double p = f.proximity(lq.data());
      status = std::max(status, p < 0 ? 2 : p < 0.5 * f.margin ? 1 : 0);
    }
    return status;
  };
  const int at_q = expected(q);
  EXPECT_GE(at_q, 1) << "no pair outside the set comes near at the initial positions";
  for (int threads : {1, 2, 3, 5}) {
    sys.set_threads(threads);
    EXPECT_EQ(sys.check_candidates(q.data()), at_q) << threads << " threads";
    EXPECT_EQ(sys.check_candidates(away.data()), expected(away)) << threads << " threads";
  }
}

// The loop that analyzes once per pattern (refactorizations with the first values' matching
// and scaling, delayed pivots, kept-order analyses when contact pairs enter) follows the
// trajectory of a loop that analyzes afresh at every step: positions equal to 1e-8 at
// every step, for every bundled model and the default one (contacts). The Newton
// tolerance is tight (1e-10) so that the two runs' converged states differ by far less.
TEST(MbdModels, TrajectoriesEqualAFreshAnalysisAtEveryStep) {
  std::vector<std::pair<std::string, Model>> models;
  for (const auto& entry : std::filesystem::directory_iterator(STRATA_MODELS_DIR))
    if (entry.path().extension() == ".json")
      models.emplace_back(entry.path().filename().string(), load_model(entry.path().string()));
  models.emplace_back("tracked:100", build_model(generate("tracked:100"), "tracked:100"));
  ASSERT_GE(models.size(), 6u);
  for (const auto& [name, m] : models) {
    SCOPED_TRACE(name);
    IntegratorOptions o;
    o.step = m.step;
    o.order = m.order;
    o.t_end = 30 * m.step;
    o.newton_rtol = 1e-10;
    o.newton_atol = 1e-12;
    IntegratorOptions fresh = o;
    fresh.analyze_every_step = true;
    Integrator reused(m, o), reference(m, fresh);
    double worst = 0;
    const int steps = test::step_side_by_side(reused, reference, 1e-8, &worst);
    EXPECT_GE(reference.stats().analyses, steps);
    EXPECT_LT(reused.stats().analyses, reference.stats().analyses);
    EXPECT_EQ(reused.stats().perturbed_pivots, 0);
    RecordProperty(name + " largest position difference", test::scientific(worst));
  }
}

// An integrator restored from `state` (saved from `straight`, options o) and `straight`
// itself, both run to the end: the same time, positions and analyses, bit for bit.
void expect_resumed_run_equal(const Model& m, const IntegratorOptions& o, Integrator& straight,
                              const nlohmann::json& state) {
  Integrator resumed(m, o);
  resumed.restore_state(state);
  while (!straight.done()) straight.advance();
  while (!resumed.done()) resumed.advance();
  EXPECT_EQ(resumed.t(), straight.t());
  EXPECT_EQ(resumed.q(), straight.q());
  EXPECT_EQ(resumed.stats().analyses, straight.stats().analyses);
}

// When contact pairs entering the pattern make the kept order fill too much, the loop with
// reorder_keeping_matching orders the pattern anew keeping the analysis's matching and
// scaling: the default model
// through its first such change (t ≈ 0.39 s) follows, to 1e-8 at every step, the loop that
// analyzes afresh there (a new matching from the values), with no perturbed pivot; and an
// integrator restored from a state saved after that change continues it bit for bit (the
// state replays the analysis, the new order and the kept order).
TEST(MbdModels, ContactChangesOrderAnewKeepingTheMatching) {
  const Model m = build_model(generate("tracked:100"), "tracked:100");
  IntegratorOptions o;
  o.t_end = 0.4;
  o.newton_rtol = 1e-10;  // tight, as above: the two runs' converged states differ by little
  o.newton_atol = 1e-12;
  o.reorder_keeping_matching = true;
  IntegratorOptions afresh = o;
  afresh.reorder_keeping_matching = false;
  Integrator reordered(m, o), reference(m, afresh);
  double worst = 0;
  test::step_side_by_side(reordered, reference, 1e-8, &worst);
  EXPECT_GE(reordered.stats().matching_kept_analyses, 1);
  EXPECT_EQ(reference.stats().matching_kept_analyses, 0);
  EXPECT_EQ(reordered.stats().contact_analyses, reference.stats().contact_analyses);
  EXPECT_EQ(reordered.stats().perturbed_pivots, 0);
  RecordProperty("largest position difference", test::scientific(worst));

  IntegratorOptions longer = o;
  longer.t_end = 0.41;
  Integrator straight(m, longer);
  straight.initialize();
  while (straight.stats().matching_kept_analyses == 0 && !straight.done()) straight.advance();
  ASSERT_FALSE(straight.done()) << "no new order keeping the matching before t = 0.41";
  straight.advance();  // a step after it, so that the state holds its factor too
  expect_resumed_run_equal(m, longer, straight, straight.save_state());
}

// A new analysis starts its matching from the last analysis's (Solver::analyze(a, start)):
// in the default model the first contact-set change that needs one (t ≈ 0.39 s) analyzes
// with a start, and an integrator restored from a state saved after it (the state keeps
// the start, and the restore replays that analysis) continues it bit for bit.
TEST(MbdModels, ResumedAfterAnAnalysisFromTheLastMatching) {
  const Model m = build_model(generate("tracked:100"), "tracked:100");
  IntegratorOptions o;
  o.t_end = 0.41;
  Integrator straight(m, o);
  straight.initialize();
  while (straight.stats().analyses < 2 && !straight.done()) straight.advance();
  ASSERT_FALSE(straight.done()) << "no second analysis before t = 0.41";
  const nlohmann::json state = straight.save_state();
  ASSERT_FALSE(state.at("analysis_start").at("row_scaling").empty());
  expect_resumed_run_equal(m, o, straight, state);
  // a start of another order in the state is refused by name
  nlohmann::json bad = state;
  bad["analysis_start"]["row_scaling"].push_back(1.0);
  Integrator refused(m, o);
  EXPECT_THROW(refused.restore_state(bad), InvalidInput);
}

// The acceleration analysis solves the symmetric [M Φ_qᵀ; Φ_q 0] by strata's L D Lᵀ (LU
// only after static pivots); the reference is the same system by LAPACK's dense LU with
// partial pivoting (IntegratorOptions::dense_solver). Models with constraints, contacts and
// a flexible body.
TEST(MbdModels, InitialAccelerationsEqualADenseSolve) {
  for (const std::string spec :
       {"andrews", "tracked:20", "lattice:3", "flexible:6x2x2", "chain:7"}) {
    SCOPED_TRACE(spec);
    const Model m = build_model(generate(spec), spec);
    IntegratorOptions o;
    o.t_end = m.step;
    IntegratorOptions dense = o;
    dense.dense_solver = true;
    Integrator sparse(m, o), reference(m, dense);
    sparse.initialize();
    reference.initialize();
    ASSERT_EQ(sparse.a().size(), reference.a().size());
    ASSERT_EQ(sparse.lambda().size(), reference.lambda().size());
    const auto largest = [](const std::vector<double>& v) {
      double x = 0;
      for (double e : v) x = std::max(x, std::abs(e));
      return x;
    };
    // both solutions are backward stable; these models' matrices are far from singular
    const double a_scale = std::max(1.0, largest(reference.a()));
    const double l_scale = std::max(1.0, largest(reference.lambda()));
    for (std::size_t i = 0; i < sparse.a().size(); ++i)
      ASSERT_NEAR(sparse.a()[i], reference.a()[i], 1e-8 * a_scale) << "acceleration " << i;
    for (std::size_t i = 0; i < sparse.lambda().size(); ++i)
      ASSERT_NEAR(sparse.lambda()[i], reference.lambda()[i], 1e-8 * l_scale) << "multiplier " << i;
  }
}

TEST(MbdModels, DumpMatrixWritesTheNewtonSystem) {
  const Model m = build_model(generate("lattice:2"), "lattice");
  SimulationOptions o;
  o.integrator.t_end = 3 * m.step;
  o.integrator.step = m.step;
  o.integrator.dump_step = 2;
  o.integrator.dump_dir = strata::test::unique_temp_path("strata_mbd_dump");
  std::filesystem::remove_all(o.integrator.dump_dir);
  const SimulationResult r = simulate(m, o);
  ASSERT_TRUE(r.complete) << r.message;
  const MMMatrix a = read_matrix_market(o.integrator.dump_dir + "/jacobian_step2.mtx");
  index_t rows = 0, cols = 0;
  const auto b = read_dense_matrix_market(o.integrator.dump_dir + "/rhs_step2.mtx", &rows, &cols);
  const index_t size = 3 * m.n + m.n_constraints();
  EXPECT_EQ(a.matrix.n_rows, size);
  EXPECT_EQ(a.matrix.n_cols, size);
  EXPECT_EQ(rows, size);
  EXPECT_EQ(cols, 1);
  EXPECT_EQ(a.matrix.nnz(), r.stats.jacobian_nnz);
  std::filesystem::remove_all(o.integrator.dump_dir);
  // The system the sparse solver factors, written beside it: its solution is the full
  // system's without the unknowns the BDF relations eliminate (the rest in their order).
  Integrator in(m, o.integrator);
  in.initialize();
  while (!in.done()) in.advance();
  const std::string dir = o.integrator.dump_dir;
  const MMMatrix full = read_matrix_market(dir + "/jacobian_step2.mtx");
  const MMMatrix c = read_matrix_market(dir + "/jacobian_condensed_step2.mtx");
  std::vector<double> x = read_dense_matrix_market(dir + "/rhs_step2.mtx", &rows, &cols);
  std::vector<double> xc = read_dense_matrix_market(dir + "/rhs_condensed_step2.mtx", &rows, &cols);
  const std::vector<RowElimination> list = in.system().bdf_eliminations();
  ASSERT_FALSE(list.empty());
  EXPECT_EQ(c.matrix.n_rows, size - static_cast<index_t>(list.size()));
  EXPECT_EQ(rows, c.matrix.n_rows);
  ASSERT_TRUE(strata::test::dense_solve(strata::test::to_dense(full.matrix), size, x, 1));
  ASSERT_TRUE(strata::test::dense_solve(strata::test::to_dense(c.matrix), c.matrix.n_rows, xc, 1));
  std::vector<char> eliminated(size, 0);
  for (const RowElimination& e : list) eliminated[e.column] = 1;
  std::vector<double> kept;
  for (index_t j = 0; j < size; ++j)
    if (!eliminated[j]) kept.push_back(x[j]);
  EXPECT_LE(strata::test::relative_difference(xc, kept),
            1e-13 * strata::test::condition_inf(full.matrix));
  std::filesystem::remove_all(o.integrator.dump_dir);
}

// The engine carries a whole strata::Options: options set for a run reach the solver
// (the analysis's ordering, the factorization's pivoting), a checkpoint keeps every one of
// them, and a type other than general is refused (the Newton matrix is unsymmetric).
TEST(MbdModels, SolverOptionsReachTheSolverAndTheCheckpoint) {
  const Model m = build_model(generate("lattice:2"), "lattice");
  SimulationOptions o;
  o.integrator.t_end = 4 * m.step;
  o.integrator.step = m.step;
  set_option(o.integrator.solver, "ordering", "natural");
  set_option(o.integrator.solver, "pivoting", "fixed");
  set_option(o.integrator.solver, "pivot_threshold", "0.125");
  set_option(o.integrator.solver, "num_threads", "1");
  o.checkpoint_every = 2;
  o.checkpoint_dir = strata::test::unique_temp_path("strata_mbd_solver_options");
  std::filesystem::remove_all(o.checkpoint_dir);
  const SimulationResult natural = simulate(m, o);
  ASSERT_TRUE(natural.complete) << natural.message;
  EXPECT_EQ(natural.stats.delayed_factorizations, 0);  // pivoting fixed: never delayed
  const IntegratorOptions kept = checkpoint_integrator_options(read_checkpoint(o.checkpoint_dir));
  for (const std::string& name : option_fields())
    EXPECT_EQ(get_option(kept.solver, name), get_option(o.integrator.solver, name)) << name;
  std::filesystem::remove_all(o.checkpoint_dir);

  SimulationOptions nd = o;
  nd.checkpoint_every = 0;
  nd.integrator.solver = engine_solver_options();
  const SimulationResult by_nd = simulate(m, nd);
  ASSERT_TRUE(by_nd.complete) << by_nd.message;
  EXPECT_NE(natural.stats.factor_nnz, by_nd.stats.factor_nnz);  // the ordering was used

  Options spd = engine_solver_options();
  spd.type = MatrixType::spd;
  EXPECT_THROW(make_strata_solver(spd), InvalidInput);
  Options bad = engine_solver_options();
  bad.pivot_threshold = 0;
  EXPECT_THROW(make_strata_solver(bad), InvalidInput);
}

// The engine's symmetric solver (the set-up's saddle-point systems) takes the run's
// pivoting as the library does: Pivoting::delayed factors a KKT matrix with delayed 1×1
// and 2×2 pivots (no static pivot, the inertia known), fixed keeps the analysis's order.
TEST(MbdModels, SymmetricSolverTakesTheRunsPivoting) {
  unsigned long long seed = 0;
  auto rng = strata::test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const strata::test::StaleKkt k = strata::test::stale_kkt(300, rng);
  // both triangles, as the engine gives its symmetric systems
  const SparseMatrix whole = expand_symmetric(k.kkt);
  std::vector<double> b(300, 1.0), x(300);
  for (Pivoting p : {Pivoting::delayed, Pivoting::fixed}) {
    Options o = engine_solver_options();
    o.type = MatrixType::automatic;  // the symmetric solver's own type
    o.backend = Backend::cpu;
    o.pivoting = p;
    const std::unique_ptr<LinearSolver> s = make_strata_symmetric_solver(o);
    s->analyze(whole);
    s->factorize(whole);
    ASSERT_NE(s->stats(), nullptr);
    const FactorStats& f = s->stats()->factor;
    EXPECT_EQ(f.delayed_pivoting, p == Pivoting::delayed);
    if (p == Pivoting::delayed) {
      EXPECT_EQ(f.perturbed_pivots, 0);
      EXPECT_TRUE(f.inertia_valid);
      EXPECT_EQ(f.inertia_negative, k.constraints);
    }
    s->solve(b.data(), x.data());
    EXPECT_LE(strata::test::backward_error(whole, x.data(), b.data()), 1e-13);
  }
}

}  // namespace
}  // namespace strata::mbd
