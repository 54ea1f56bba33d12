// strata::mbd — the Newton matrix condensed by its rows of two entries (condensed_solver):
// the condensed solve against a dense LU of the full system (LAPACK), on random systems
// of the shape the eliminations need (pivot rows of two nonzeros and explicit zeros,
// partners that are eliminated in turn) drawn afresh, sizes 1, 2, 3, 5 and 733; the same
// through the LinearSolver wrapper around strata's LU and the dense LU; the engine's own
// Newton matrices in both formulations; the engine with and without condensation; and the
// errors of a list that does not fit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "mbd/condensed_solver.hpp"
#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/linear_solver.hpp"
#include "mbd/model_io.hpp"
#include "strata/errors.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

struct Condensable {
  SparseMatrix a;  // full CSC with sorted rows, explicit zeros kept
  std::vector<RowElimination> eliminations;
};

// A random nonsingular-in-practice system of order n with about n/3 eliminations: a
// general random matrix whose pivot rows are replaced by β x_d − x_c (β random), some of
// their other entries kept as explicit zeros; a third of the partners are columns that
// another elimination removes later in the given list or earlier (chains of two).
Condensable random_condensable(index_t n, std::mt19937_64& rng) {
  const SparseMatrix g = strata::test::random_sparse(n, 4, strata::test::RandomKind::general, rng);
  std::vector<double> d = strata::test::to_dense(g);  // column-major
  std::vector<char> structural(static_cast<std::size_t>(n) * n, 0);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = g.offsets[j]; p < g.offsets[j + 1]; ++p) structural[g.indices[p] + j * n] = 1;
  for (index_t i = 0; i < n; ++i) {  // a strong diagonal keeps the full system well posed
    d[i + i * n] += 4.0 * (i % 2 ? 1 : -1);
    structural[i + i * n] = 1;
  }
  std::vector<index_t> perm(n);
  for (index_t i = 0; i < n; ++i) perm[i] = i;
  std::shuffle(perm.begin(), perm.end(), rng);
  std::uniform_real_distribution<double> u(0.5, 2.0);
  Condensable out;
  // pivots on the diagonal (row = column = perm[k]); partners other columns, sometimes the
  // column of another elimination (never one whose partner chain leads back)
  const index_t ne = n >= 2 ? n / 3 + (n == 2) : 0;
  std::vector<char> eliminated(n, 0);
  for (index_t k = 0; k < ne; ++k) eliminated[perm[k]] = 1;
  for (index_t k = 0; k < ne; ++k) {
    const index_t c = perm[k];
    index_t partner;
    if (k + 1 < ne && rng() % 3 == 0)
      partner = perm[k + 1];  // chain: c → perm[k+1] → … (acyclic: increasing k)
    else
      partner = perm[ne + rng() % (n - ne)];  // a column that stays
    for (index_t j = 0; j < n; ++j) {         // row c: explicit zeros where it had entries
      d[c + j * n] = 0.0;
      if (rng() % 2 == 0) structural[c + j * n] = 0;
    }
    d[c + c * n] = -u(rng);
    d[c + partner * n] = u(rng) * (rng() % 2 ? 1 : -1);
    structural[c + c * n] = structural[c + partner * n] = 1;
    out.eliminations.push_back({c, c, partner});
  }
  std::shuffle(out.eliminations.begin(), out.eliminations.end(), rng);  // any order given
  SparseMatrix& a = out.a;
  a.n_rows = a.n_cols = n;
  a.offsets.assign(n + 1, 0);
  for (index_t j = 0; j < n; ++j) {
    for (index_t i = 0; i < n; ++i)
      if (structural[i + j * n]) {
        a.indices.push_back(i);
        a.values.push_back(d[i + j * n]);
      }
    a.offsets[j + 1] = static_cast<index_t>(a.indices.size());
  }
  return out;
}

std::vector<double> random_vector(index_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::vector<double> b(n);
  for (double& v : b) v = u(rng);
  return b;
}

std::vector<double> dense_solution(const SparseMatrix& a, const std::vector<double>& b) {
  std::vector<double> x = b;
  EXPECT_TRUE(strata::test::dense_solve(strata::test::to_dense(a), a.n_rows, x, 1));
  return x;
}

// The tolerance of a solve of a: a multiple of κ∞(a)·u.
double tolerance(const SparseMatrix& a) {
  return std::max(1e-13, 64 * a.n_rows * strata::test::condition_inf(a) * 1.1e-16);
}

TEST(MbdCondensed, RandomSystemsEqualADenseSolve) {
  unsigned long long seed = 0;
  auto rng = strata::test::fresh_rng(&seed);
  RecordProperty("seed", std::to_string(seed));
  for (index_t n : {1, 2, 3, 5, 733}) {
    SCOPED_TRACE("n = " + std::to_string(n));
    Condensable s = random_condensable(n, rng);
    CondensedSystem cs;
    SparseMatrix r;
    cs.build(s.a, s.eliminations, r);
    ASSERT_EQ(r.n_rows, n - static_cast<index_t>(s.eliminations.size()));
    EXPECT_EQ(cs.eliminations(), s.eliminations);
    EXPECT_NO_THROW(validate(r));
    for (int round = 0; round < 2; ++round) {  // new values of the same pattern
      if (round == 1)
        for (index_t p = 0; p < s.a.nnz(); ++p)
          if (s.a.values[p] != 0.0 && s.a.values[p] != -1.0) s.a.values[p] *= 1.5;
      {  // what the solve needs is kept: the values given may go away (the engine's
         // Jacobian is rewritten between the factorization and later solves)
        std::vector<double> given = s.a.values;
        cs.values(given, r.values);
        std::fill(given.begin(), given.end(), std::nan(""));
      }
      // a right-hand side with zeros on the pivot rows too (Newton's updates after the
      // first: the relations hold)
      std::vector<double> b0 = random_vector(n, rng);
      for (const RowElimination& e : s.eliminations) b0[e.row] = 0.0;
      std::vector<double> b1 = b0;  // and with one relation's right-hand side not 0
      if (!s.eliminations.empty()) b1[s.eliminations.front().row] = 0.5;
      for (const std::vector<double>& b : {random_vector(n, rng), b0, b1}) {
        std::vector<double> rb(r.n_rows), x(n);
        cs.reduce_rhs(b.data(), rb.data());
        const std::vector<double> rx = r.n_rows > 0 ? dense_solution(r, rb) : std::vector<double>{};
        cs.expand(rx.data(), x.data());
        const std::vector<double> ref = dense_solution(s.a, b);
        EXPECT_LE(strata::test::relative_difference(x, ref), tolerance(s.a)) << "round " << round;
      }
    }
  }
}

TEST(MbdCondensed, SolverWrapperEqualsTheFullSolve) {
  unsigned long long seed = 0;
  auto rng = strata::test::fresh_rng(&seed);
  RecordProperty("seed", std::to_string(seed));
  for (index_t n : {2, 3, 5, 733}) {
    SCOPED_TRACE("n = " + std::to_string(n));
    Condensable s = random_condensable(n, rng);
    const auto list = s.eliminations;
    Options o = engine_solver_options();
    o.backend = Backend::cpu;
    for (bool dense : {true, false}) {
      SCOPED_TRACE(dense ? "dense LU inside" : "strata LU inside");
      auto solver = make_condensed_solver(dense ? make_dense_solver() : make_strata_solver(o),
                                          [list] { return list; });
      solver->analyze(s.a);
      solver->factorize(s.a);
      const std::vector<double> b = random_vector(n, rng);
      std::vector<double> x(n);
      solver->solve(b.data(), x.data());
      EXPECT_LE(strata::test::relative_difference(x, dense_solution(s.a, b)), tolerance(s.a));
      // the values alone change: the pattern's map is kept
      for (double& v : s.a.values)
        if (v != 0.0 && v != -1.0) v *= 0.75;
      solver->factorize_analyzed_pattern(s.a);
      solver->solve(b.data(), x.data());
      EXPECT_LE(strata::test::relative_difference(x, dense_solution(s.a, b)), tolerance(s.a));
      EXPECT_NE(solver->describe().find("condensed"), std::string::npos);
    }
  }
}

// The engine's integrator of `model` with `io`, run to io.t_end.
std::unique_ptr<Integrator> integrated(const Model& model, const IntegratorOptions& io) {
  auto in = std::make_unique<Integrator>(model, io);
  in->initialize();
  while (!in->done()) in->advance();
  return in;
}

// The engine's Newton matrix after a few steps of a model, both formulations: the
// condensed solve (strata's LU on the host) against the dense LU of the full matrix.
TEST(MbdCondensed, NewtonMatricesOfBothFormulations) {
  auto rng = strata::test::fresh_rng();
  for (const char* spec : {"tracked:20", "flexible:8x2x2", "lattice:2"}) {
    for (FormulationChoice f : {FormulationChoice::partitioned, FormulationChoice::stabilized}) {
      SCOPED_TRACE(std::string(spec) + (f == FormulationChoice::stabilized ? " stabilized" : ""));
      Model model = build_model(generate(spec), spec);
      IntegratorOptions io;
      io.t_end = 0.003;
      io.formulation = f;
      io.solver.backend = Backend::cpu;
      const std::unique_ptr<Integrator> in = integrated(model, io);
      const NewtonSystem& sys = in->system();
      const SparseMatrix& a = sys.matrix();
      const std::vector<RowElimination> list = sys.bdf_eliminations();
      EXPECT_FALSE(list.empty());
      auto solver = make_condensed_solver(make_strata_solver(io.solver), [&] { return list; });
      solver->analyze(a);
      solver->factorize(a);
      const std::vector<double> b = random_vector(a.n_rows, rng);
      std::vector<double> x(a.n_rows);
      solver->solve(b.data(), x.data());
      EXPECT_LE(strata::test::relative_difference(x, dense_solution(a, b)), tolerance(a));
    }
  }
}

// A banded system of order n (entries |i − j| ≤ 2, a strong diagonal) with every third
// row a pivot row β x_d − x_c whose partner d is the next column (itself eliminated at
// times: chains), its other band entries explicit zeros: large enough for the condensed
// passes to run over threads, with little fill for a sparse reference.
Condensable banded_condensable(index_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.5, 2.0);
  Condensable out;
  std::vector<char> pivot(n, 0);
  for (index_t c = 0; c + 1 < n; c += 3) pivot[c] = 1;
  for (index_t c = 1; c + 1 < n; c += 30) pivot[c] = 1;  // c−1 → c → c+1: a chain
  SparseMatrix& a = out.a;
  a.n_rows = a.n_cols = n;
  a.offsets.assign(n + 1, 0);
  for (index_t j = 0; j < n; ++j) {
    for (index_t i = std::max<index_t>(0, j - 2); i <= std::min(n - 1, j + 2); ++i) {
      double v = i == j ? 8.0 * (j % 2 ? 1 : -1) : u(rng) - 1.25;
      if (pivot[i]) v = i == j ? -u(rng) : (j == i + 1 ? u(rng) : 0.0);
      a.indices.push_back(i);
      a.values.push_back(v);
    }
    a.offsets[j + 1] = static_cast<index_t>(a.indices.size());
  }
  for (index_t c = 0; c + 1 < n; ++c)
    if (pivot[c]) out.eliminations.push_back({c, c, c + 1});
  return out;
}

// The condensed solve against the full system's, both by strata's LU, on a system large
// enough for the passes over threads (R's values, the reduced right-hand side by row).
TEST(MbdCondensed, LargeSystemsOverThreads) {
  auto rng = strata::test::fresh_rng();
  const index_t n = 120000;
  const Condensable s = banded_condensable(n, rng);
  const auto list = s.eliminations;
  Options o = engine_solver_options();
  o.backend = Backend::cpu;
  auto full = make_strata_solver(o);
  auto condensed = make_condensed_solver(make_strata_solver(o), [list] { return list; });
  EXPECT_GT(condensed->system_order(s.a), 70000);
  std::vector<double> b = random_vector(n, rng), b1 = b;
  for (const RowElimination& e : list) b1[e.row] = 0.0;
  b1[list[7].row] = 1.0;  // few relations with a right-hand side: by elimination
  for (LinearSolver* ls : {full.get(), condensed.get()}) {
    ls->analyze(s.a);
    ls->factorize(s.a);
  }
  for (const std::vector<double>& rhs : {b, b1}) {
    std::vector<double> x(n), y(n);
    full->solve(rhs.data(), x.data());
    condensed->solve(rhs.data(), y.data());
    EXPECT_LE(strata::test::relative_difference(y, x), 1e-12);
  }
}

// Without eliminations the wrapper hands the inner solver the matrix as it is: the
// solution is the inner solver's own, bit for bit. The engine condenses only where a third
// of the rows or more go.
TEST(MbdCondensed, NoEliminationIsTheInnerSolver) {
  auto rng = strata::test::fresh_rng();
  const Condensable s = random_condensable(733, rng);
  Options o = engine_solver_options();
  o.backend = Backend::cpu;
  auto plain = make_strata_solver(o);
  auto wrapped =
      make_condensed_solver(make_strata_solver(o), [] { return std::vector<RowElimination>{}; });
  const std::vector<double> b = random_vector(733, rng);
  std::vector<double> x(733), y(733);
  for (LinearSolver* ls : {plain.get(), wrapped.get()}) {
    ls->analyze(s.a);
    ls->factorize(s.a);
    ls->factorize_analyzed_pattern(s.a);
  }
  plain->solve(b.data(), x.data());
  wrapped->solve(b.data(), y.data());
  EXPECT_EQ(x, y);
  EXPECT_EQ(wrapped->describe(), plain->describe());
  EXPECT_EQ(wrapped->system_order(s.a), 733);
  EXPECT_TRUE(worth_condensing(3, 1));
  EXPECT_FALSE(worth_condensing(100, 33));
  EXPECT_TRUE(worth_condensing(14728, 9600));  // flexible:64x4x4
  EXPECT_FALSE(worth_condensing(7069, 1505));  // the default model, stabilized
}

// IntegratorOptions::condensation: a flexible body integrated with the condensed Newton
// matrix and with the full one reaches the same positions (the same Newton iterations on
// the same system, solved two ways: they differ by rounding); the condensation's host
// time is counted only where it condensed.
TEST(MbdCondensed, TheEngineWithAndWithoutCondensation) {
  const char* spec = "flexible:8x2x2";
  Model model = build_model(generate(spec), spec);
  std::vector<double> q[2];
  for (bool condense : {true, false}) {
    SCOPED_TRACE(condense ? "condensed" : "full");
    IntegratorOptions io;
    io.t_end = 0.004;
    io.condensation = condense;
    io.solver.backend = Backend::cpu;
    const std::unique_ptr<Integrator> in = integrated(model, io);
    q[condense ? 0 : 1] = in->q();
    const IntegratorStats& st = in->stats();
    EXPECT_EQ(st.solver.find("condensed") != std::string::npos, condense) << st.solver;
    if (condense)
      EXPECT_GT(st.condensation_seconds, 0.0);
    else
      EXPECT_EQ(st.condensation_seconds, 0.0);
  }
  ASSERT_EQ(q[0].size(), q[1].size());
  for (std::size_t i = 0; i < q[0].size(); ++i)
    EXPECT_NEAR(q[0][i], q[1][i], 1e-8 * std::max(1.0, std::abs(q[1][i]))) << "coordinate " << i;
}

TEST(MbdCondensed, ListsThatDoNotFitAreRefused) {
  // [[-1, 2, 0], [0, 3, 1], [1, 0, 2]] with an explicit zero at (0, 2)
  SparseMatrix a;
  a.n_rows = a.n_cols = 3;
  a.offsets = {0, 2, 4, 7};
  a.indices = {0, 2, 0, 1, 0, 1, 2};
  a.values = {-1, 1, 2, 3, 0, 1, 2};
  CondensedSystem cs;
  SparseMatrix r;
  EXPECT_THROW(cs.build(a, {{0, 0, 3}}, r), InvalidInput);             // out of range
  EXPECT_THROW(cs.build(a, {{0, 0, 0}}, r), InvalidInput);             // partner = column
  EXPECT_THROW(cs.build(a, {{0, 0, 1}, {0, 1, 2}}, r), InvalidInput);  // row named twice
  EXPECT_THROW(cs.build(a, {{1, 0, 1}}, r), InvalidInput);             // (1, 0) not an entry
  EXPECT_THROW(cs.build(a, {{0, 0, 1}, {1, 1, 0}}, r), InvalidInput);  // a cycle
  cs.build(a, {{0, 0, 1}}, r);                                         // x0 = (b0 − 2 x1) / −1
  EXPECT_EQ(r.n_rows, 2);
  std::vector<double> v = a.values;
  cs.values(v, r.values);
  v[0] = 0.0;  // the pivot
  EXPECT_THROW(cs.values(v, r.values), InvalidInput);
  v = a.values;
  v[4] = 1e-300;  // the explicit zero of the pivot row
  EXPECT_THROW(cs.values(v, r.values), InternalError);
  std::vector<double> rb(2);
  CondensedSystem fresh;
  EXPECT_THROW(fresh.reduce_rhs(v.data(), rb.data()), InvalidState);
}

}  // namespace
}  // namespace strata::mbd
