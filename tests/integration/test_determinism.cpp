// Determinism of the CPU backend, on matrices whose top fronts are large enough for the
// multithreaded-BLAS path of the CPU executor (more than 2e7 flops: a 20³ Laplacian, 3D
// elasticity), in every factorization type, with Options::num_threads = 1, 2, 3 and 5
// (oversubscribed on a 2-core machine, which is allowed; 5 threads run the CPU plan's
// layer of subtrees, schedule/stack_plan.hpp, with large fronts on one BLAS thread each):
//  - Options::reproducible: bitwise the same factor and solution for every thread count;
//  - default: bitwise the same from one run to the next for a fixed thread count, and
//    between thread counts equal to the unit-roundoff level (multithreaded OpenBLAS on the
//    large fronts rounds differently for different thread counts).
// What is compared: the solution (after refinement) bit for bit, log|det A| (a sum over
// every pivot, so any change of any pivot shows), the inertia and the refinement steps.
// Why it holds: see docs/reliability.md, "Determinism".
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string>

#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

struct Outcome {
  std::vector<double> x;
  double logdet = 0;
  int sign = 0;
  index_t positive = 0, negative = 0, perturbed = 0;
  int refinement = 0;
};

Outcome run(const SparseMatrix& a, MatrixType type, int threads, const std::vector<double>& b,
            bool reproducible) {
  Options o;
  o.type = type;
  o.num_threads = threads;
  o.reproducible = reproducible;
  Solver s(o);
  s.analyze(a);
  s.factorize(a);
  Outcome r;
  r.x = s.solve(b);
  const FactorStats& f = s.stats().factor;
  r.logdet = f.log_abs_determinant;
  r.sign = f.determinant_sign;
  r.positive = f.inertia_positive;
  r.negative = f.inertia_negative;
  r.perturbed = f.perturbed_pivots;
  r.refinement = s.stats().solve.refinement_steps;
  return r;
}

bool bitwise_equal(const std::vector<double>& x, const std::vector<double>& y) {
  return x.size() == y.size() && std::memcmp(x.data(), y.data(), x.size() * sizeof(double)) == 0;
}

// A − σI (lower storage kept): indefinite for σ inside the spectrum.
SparseMatrix shifted(SparseMatrix a, double sigma) {
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      if (a.indices[p] == j) a.values[p] -= sigma;
  return a;
}

// An unsymmetric matrix on the same pattern: entries above the diagonal scaled.
SparseMatrix unsymmetric(const SparseMatrix& lower) {
  std::vector<index_t> ri, ci;
  std::vector<double> v;
  for (index_t j = 0; j < lower.n_cols; ++j)
    for (index_t p = lower.offsets[j]; p < lower.offsets[j + 1]; ++p) {
      const index_t i = lower.indices[p];
      ri.push_back(i), ci.push_back(j), v.push_back(lower.values[p]);
      if (i != j) ri.push_back(j), ci.push_back(i), v.push_back(0.7 * lower.values[p]);
    }
  SparseMatrix a;
  a.n_rows = a.n_cols = lower.n_rows;
  a.layout = Layout::csc;
  a.storage = Storage::full;
  a.offsets.assign(a.n_cols + 1, 0);
  for (index_t c : ci) ++a.offsets[c + 1];
  for (index_t j = 0; j < a.n_cols; ++j) a.offsets[j + 1] += a.offsets[j];
  a.indices.resize(ri.size());
  a.values.resize(ri.size());
  std::vector<index_t> next(a.offsets.begin(), a.offsets.end() - 1);
  for (std::size_t k = 0; k < ri.size(); ++k) {
    a.indices[next[ci[k]]] = ri[k];
    a.values[next[ci[k]]++] = v[k];
  }
  return a;
}

struct Case {
  std::string name;
  SparseMatrix a;
  MatrixType type;
  bool well_conditioned = true;  // forward errors comparable at roundoff level
};

std::vector<Case> cases() {
  const SparseMatrix lap = generators::laplacian_3d(20, 20, 20);
  return {{"lap3d 20^3 LLt", lap, MatrixType::spd},
          {"elasticity 10^3 LLt", generators::elasticity_3d(10, 10, 10), MatrixType::spd},
          // the shift lies inside the dense spectrum: badly conditioned
          {"lap3d 20^3 - 3I LDLt", shifted(lap, 3.0), MatrixType::symmetric_indefinite, false},
          {"lap3d 20^3 unsymmetric LU", unsymmetric(lap), MatrixType::general}};
}

std::vector<double> random_rhs(index_t n, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> b(n);
  for (double& v : b) v = u(rng);
  return b;
}

void expect_identical(const Outcome& r, const Outcome& ref) {
  EXPECT_TRUE(bitwise_equal(r.x, ref.x))
      << "solution differs; max relative difference " << test::relative_difference(r.x, ref.x);
  EXPECT_EQ(std::memcmp(&r.logdet, &ref.logdet, sizeof(double)), 0)
      << r.logdet << " vs " << ref.logdet;
  EXPECT_EQ(r.sign, ref.sign);
  EXPECT_EQ(r.positive, ref.positive);
  EXPECT_EQ(r.negative, ref.negative);
  EXPECT_EQ(r.perturbed, ref.perturbed);
  EXPECT_EQ(r.refinement, ref.refinement);
}

TEST(Determinism, ReproducibleIsBitwiseIdenticalForEveryThreadCount) {
  auto rng = test::fresh_rng();
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const std::vector<double> b = random_rhs(c.a.n_rows, rng);
    const Outcome ref = run(c.a, c.type, 1, b, true);
    EXPECT_LT(test::backward_error(c.a, ref.x.data(), b.data()), 1e-14);
    // the reproducible single-thread run is the default single-thread run
    expect_identical(run(c.a, c.type, 1, b, false), ref);
    for (int threads : {2, 3, 5}) {
      SCOPED_TRACE("threads " + std::to_string(threads));
      expect_identical(run(c.a, c.type, threads, b, true), ref);
    }
  }
}

TEST(Determinism, DefaultIsRepeatableAndAgreesToRoundoffAcrossThreadCounts) {
  auto rng = test::fresh_rng();
  for (const Case& c : cases()) {
    SCOPED_TRACE(c.name);
    const std::vector<double> b = random_rhs(c.a.n_rows, rng);
    const Outcome one = run(c.a, c.type, 1, b, false);
    for (int threads : {2, 3, 5}) {
      SCOPED_TRACE("threads " + std::to_string(threads));
      const Outcome first = run(c.a, c.type, threads, b, false);
      expect_identical(run(c.a, c.type, threads, b, false), first);  // run to run
      if (c.well_conditioned) EXPECT_LT(test::relative_difference(first.x, one.x), 1e-13);
      EXPECT_LT(std::abs(first.logdet - one.logdet), 1e-12 * std::abs(one.logdet));
      EXPECT_EQ(first.positive, one.positive);
      EXPECT_EQ(first.negative, one.negative);
      EXPECT_LT(test::backward_error(c.a, first.x.data(), b.data()), 1e-14);
    }
  }
}

}  // namespace
}  // namespace strata
