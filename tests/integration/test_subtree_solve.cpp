// The host solve by subtrees (numeric/subtree_solve.hpp): its plan covers the tree once
// with whole subtrees under a closed top, and its solutions equal the sequential
// multifrontal solve's to rounding, a dense LU's to the backward error of a stable solve,
// and each other bitwise for every thread count.
#include <gtest/gtest.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "analysis/analysis.hpp"
#include "numeric/factor.hpp"
#include "numeric/subtree_solve.hpp"
#include "sparse/generators.hpp"
#include "strata/solver.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

struct Problem {
  std::string name;
  SparseMatrix a;
  MatrixType type;
  Options options() const {  // the CPU backend, the problem's type
    Options o;
    o.type = type;
    o.backend = Backend::cpu;
    return o;
  }
};

std::vector<Problem> problems(std::mt19937_64& rng) {
  std::vector<Problem> ps;
  for (const index_t n : {1, 2, 3, 5, 733}) {
    ps.push_back({"spd " + std::to_string(n), test::random_sparse(n, 3, test::RandomKind::spd, rng),
                  MatrixType::spd});
    ps.push_back({"indefinite " + std::to_string(n),
                  test::random_sparse(n, 3, test::RandomKind::symmetric_indefinite, rng),
                  MatrixType::symmetric_indefinite});
    ps.push_back({"general " + std::to_string(n),
                  test::random_sparse(n, 3, test::RandomKind::general, rng), MatrixType::general});
  }
  ps.push_back({"lap3d 14", generators::laplacian_3d(14, 14, 14), MatrixType::spd});
  return ps;
}

// Every front in exactly one subtree or the top; a subtree is a whole subtree (its
// fronts' parents inside it but for its root's); the top holds every ancestor; each
// slot is a row outside its subtree, listed once, and the row map points at it.
TEST(SubtreeSolve, PlanCoversTheTreeOnce) {
  auto rng = test::fresh_rng();
  for (const Problem& pr : problems(rng)) {
    SCOPED_TRACE(pr.name);
    const Options o = pr.options();
    const Analysis an = analyze_matrix(pr.a, o);
    const auto& t = an.tree;
    const numeric::SubtreeSolvePlan p = numeric::plan_subtree_solve(an);
    ASSERT_EQ(p.analysis_id, an.id);
    ASSERT_EQ(p.row_slot.size(), t.rows.size());
    ASSERT_EQ(p.slot_offsets.size(), p.subtrees.size() + 1);
    std::vector<int> seen(t.n_fronts(), 0);
    std::vector<char> top(t.n_fronts(), 0);
    for (index_t f : p.top) {
      ++seen[f];
      top[f] = 1;
    }
    for (index_t f : p.top)
      if (t.parent[f] >= 0) EXPECT_TRUE(top[t.parent[f]]) << "top not closed at " << f;
    for (std::size_t s = 0; s < p.subtrees.size(); ++s) {
      const auto [lo, hi] = p.subtrees[s];
      ASSERT_LE(lo, hi);
      EXPECT_TRUE(t.parent[hi] < 0 || top[t.parent[hi]]) << "subtree root " << hi;
      const index_t r0 = t.first_pivot[lo], r1 = t.first_pivot[hi + 1];
      for (index_t f = lo; f <= hi; ++f) {
        ++seen[f];
        if (f < hi) {
          EXPECT_GT(t.parent[f], f);
          EXPECT_LE(t.parent[f], hi) << "front " << f << " leaves subtree " << s;
        }
        for (index_t i = 0; i < t.n_rows(f); ++i) {
          const index_t r = t.rows_of(f)[i];
          const index_t slot = p.row_slot[t.row_offsets[f] + i];
          if (r >= r0 && r < r1) {
            EXPECT_EQ(slot, -1);
          } else {
            ASSERT_GE(slot, 0);
            ASSERT_LT(slot, p.slot_offsets[s + 1] - p.slot_offsets[s]);
            EXPECT_EQ(p.slot_row[p.slot_offsets[s] + slot], r);
          }
        }
      }
      for (index_t j = p.slot_offsets[s]; j + 1 < p.slot_offsets[s + 1]; ++j)
        EXPECT_LT(p.slot_row[j], p.slot_row[j + 1]);
    }
    for (index_t f = 0; f < t.n_fronts(); ++f) EXPECT_EQ(seen[f], 1) << "front " << f;
    if (pr.name == "lap3d 14") EXPECT_GT(p.subtrees.size(), 8u);
  }
}

// The factor of the CPU executor solved by subtrees on 1, 2, 3 and 8 threads (top fronts
// with 1 and 3 BLAS threads), three right-hand sides: bitwise one result, equal to the
// sequential solve to rounding; through the Solver (a draw that dense LU finds singular
// skipped), the solution of A x = b has a backward error at rounding level.
TEST(SubtreeSolve, MatchesSequentialForEveryThreadCount) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  for (const Problem& pr : problems(rng)) {
    SCOPED_TRACE(pr.name);
    const Options o = pr.options();
    const Analysis an = analyze_matrix(pr.a, o);
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
    const auto exec = numeric::make_cpu_executor(1);
    numeric::NumericFactor fac;
    std::vector<double> arena;
    numeric::factorize(an, v, pr.type, pivot, *exec, fac, arena);
    const index_t n = an.n, nrhs = 3;
    std::vector<double> b(static_cast<std::size_t>(n) * nrhs);
    for (double& x : b) x = u(rng);
    std::vector<double> seq = b;
    numeric::solve_in_place(an, fac, seq.data(), nrhs);
    const numeric::SubtreeSolvePlan plan = numeric::plan_subtree_solve(an);
    std::vector<double> first;
    for (const int threads : {1, 2, 3, 8})
      for (const int blas : {1, 3}) {
        tbb::task_arena ta(threads);
        std::vector<double> x = b;
        numeric::solve_by_subtrees(an, fac, plan, x.data(), nrhs, ta, blas);
        if (first.empty()) {
          first = x;
          // the same solve with the updates of rows above a subtree summed apart first
          EXPECT_LT(test::relative_difference(x, seq), 1e-8);
        } else {
          EXPECT_EQ(x, first) << threads << " threads, " << blas << " BLAS threads";
        }
      }
    // the whole solve through the Solver (its driver's solve by subtrees), reproducible:
    // a backward error of rounding size, and for LLᵀ and LDLᵀ bitwise one solution for
    // every thread count
    std::vector<double> rhs(b.begin(), b.begin() + n), dense = rhs;
    if (!test::dense_solve(test::to_dense(pr.a), n, dense, 1)) continue;  // a singular draw
    std::vector<double> x1;
    for (const int threads : {1, 3, 8}) {
      Options so = o;
      so.num_threads = threads;
      so.reproducible = true;
      Solver s(so);
      s.analyze(pr.a);
      s.factorize(pr.a);
      std::vector<double> x(n);
      s.solve(rhs.data(), x.data(), 1);
      EXPECT_LT(test::backward_error(pr.a, x.data(), rhs.data()), 1e-12) << threads << " threads";
      if (x1.empty())
        x1 = x;
      else if (pr.type != MatrixType::general)  // LU may take the delayed path, solved apart
        EXPECT_EQ(x, x1) << threads << " threads";
    }
  }
}

// A front with more than a thousand pivots solved with several BLAS threads (the top of the
// solve by subtrees): its triangular solves go by column blocks (TRSV of each diagonal
// block, GEMV on every thread for the rest), and the solution equals the sequential
// solve's (one BLAS thread, DTRSV) to the rounding of a reordered sum. Dense random
// matrices of 1300 unknowns (1300 = 5 blocks of 256 and a partial one), one front each,
// for LLᵀ, LDLᵀ and LU.
TEST(SubtreeSolve, LargePivotBlocksByColumnBlocksMatchTrsv) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  const index_t n = 1300;
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::general, MatrixType::general}}) {
    SCOPED_TRACE(to_string(type));
    const SparseMatrix a = test::random_sparse(n, n, kind, rng);
    Options o;
    o.type = type;
    o.backend = Backend::cpu;
    o.max_block_size = 2048;  // the whole matrix one front
    const Analysis an = analyze_matrix(a, o);
    index_t largest = 0;
    for (index_t f = 0; f < an.tree.n_fronts(); ++f)
      largest = std::max(largest, an.tree.n_pivots(f));
    ASSERT_GE(largest, 1024);  // the blocked form's threshold
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, a, &pivot);
    const auto exec = numeric::make_cpu_executor(1);
    numeric::NumericFactor fac;
    std::vector<double> arena;
    numeric::factorize(an, v, type, pivot, *exec, fac, arena);
    std::vector<double> b(n);
    for (double& x : b) x = u(rng);
    std::vector<double> seq = b;
    numeric::solve_in_place(an, fac, seq.data(), 1);
    tbb::task_arena ta(2);
    std::vector<double> x = b;
    numeric::solve_by_subtrees(an, fac, numeric::plan_subtree_solve(an), x.data(), 1, ta, 3);
    // both solve the same scaled system; the difference is the rounding of the reordered
    // sums, amplified at most by the condition of the factors' triangles
    EXPECT_LT(test::relative_difference(x, seq), 1e-9);
    EXPECT_GT(test::relative_difference(x, b), 1e-3);  // something was solved
  }
}

TEST(SubtreeSolve, RefusesThePlanOfAnotherAnalysis) {
  const SparseMatrix a = generators::laplacian_3d(6, 6, 6);
  Options o;
  o.backend = Backend::cpu;
  const Analysis an = analyze_matrix(a, o), other = analyze_matrix(a, o);
  double pivot = 0;
  const std::vector<double> v = test::scaled_values(an, a, &pivot);
  const auto exec = numeric::make_cpu_executor(1);
  numeric::NumericFactor fac;
  std::vector<double> arena;
  numeric::factorize(an, v, MatrixType::spd, pivot, *exec, fac, arena);
  std::vector<double> x(an.n, 1.0);
  tbb::task_arena ta(2);
  EXPECT_THROW(
      numeric::solve_by_subtrees(an, fac, numeric::plan_subtree_solve(other), x.data(), 1, ta, 1),
      InternalError);
}

}  // namespace
}  // namespace strata
