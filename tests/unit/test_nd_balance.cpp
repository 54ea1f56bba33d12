// strata tests — nested dissection balanced by work (NestedDissectionOptions::
// balance_levels): the result is a valid ordering with a valid separator tree, and the
// work of the two sides of the top bisection — computed here independently, from the
// analysis' own column counts (AnalysisStats / separator-tree work) — is never less
// balanced than METIS's vertex-balanced bisection, and better where the grid allows.
#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "analysis/analysis.hpp"
#include "core/solver_internal.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

// |w_a − w_b| / (w_a + w_b) of the two largest subtrees under the separator-tree root
// (the two sides of the top bisection), and the tree's consistency.
double root_imbalance(const Analysis& an) {
  const auto& tree = an.separator_tree;
  EXPECT_FALSE(tree.empty());
  const auto& root = tree.nodes.back();
  EXPECT_EQ(root.end, an.n);
  EXPECT_EQ(root.subtree_begin, 0);
  std::vector<double> w;
  for (index_t c : root.children) {
    EXPECT_EQ(tree.nodes[c].parent, static_cast<index_t>(tree.nodes.size()) - 1);
    w.push_back(tree.nodes[c].work);
  }
  EXPECT_EQ(w.size(), 2u) << "the top node is a bisection";
  if (w.size() != 2) return 0;
  return std::abs(w[0] - w[1]) / (w[0] + w[1]);
}

Analysis analyze(const SparseMatrix& a, MatrixType type, bool balance) {
  Options o;
  o.type = type;
  o.balance_by_work = balance;
  o.subtrees_per_gpu = 1;  // 2 workers × 1: one balanced level, the root bisection
  return analyze_matrix(a, o, 2);
}

TEST(NdBalance, RootBisectionNoLessBalancedAndValid) {
  struct Case {
    std::string name;
    SparseMatrix a;
    MatrixType type;
    bool must_improve;
  };
  std::vector<Case> cases;
  // the root bisection of lap3d-30 leaves 8.9% more work on one side (measured); a
  // plane may move by one, so balancing can fix it
  cases.push_back({"lap3d 30", generators::laplacian_3d(30, 30, 30), MatrixType::spd, true});
  cases.push_back(
      {"elasticity 9x10x11", generators::elasticity_3d(9, 10, 11), MatrixType::spd, false});
  auto rng = test::fresh_rng();
  cases.push_back({"random kkt 3000", test::random_kkt(3000, rng), MatrixType::symmetric_indefinite,
                   false});  // pivot pairs: the grouped (quotient graph) driver
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    const Analysis plain = analyze(c.a, c.type, false);
    const Analysis bal = analyze(c.a, c.type, true);
    EXPECT_TRUE(ordering::is_permutation(bal.perm, bal.n));
    EXPECT_EQ(plain.stats.nd_rebisections, 0);
    const double before = root_imbalance(plain), after = root_imbalance(bal);
    EXPECT_LE(after, before + 1e-12);
    if (c.must_improve) {
      EXPECT_GT(bal.stats.nd_rebisections, 0);
      EXPECT_LT(after, 0.5 * before);
    }
    // the factorization of the balanced ordering is right (2 workers, as analyzed above)
    std::vector<double> b(c.a.n_rows, 1.0);
    Options o;
    o.type = c.type;
    o.balance_by_work = true;
    o.subtrees_per_gpu = 1;
    Solver s(o);
    detail::SolverAccess::use_host_workers(s, 2, 1);
    s.factorize(c.a);
    EXPECT_GT(s.stats().analysis.nd_rebisections, c.must_improve ? 0 : -1);
    const auto x = s.solve(b);
    EXPECT_LE(test::backward_error(c.a, x.data(), b.data()), 1e-14);
  }
}

}  // namespace
}  // namespace strata
