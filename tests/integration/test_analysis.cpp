// strata — analysis-phase integration tests: structural singularity is refused with a
// message naming the problem; the separator tree's work hook matches the column counts.
#include <gtest/gtest.h>

#include "analysis/analysis.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

SparseMatrix from_triplets(index_t n, Storage st,
                           std::vector<std::tuple<index_t, index_t, double>> t) {
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.storage = st;
  a.offsets.assign(n + 1, 0);
  std::sort(t.begin(), t.end(), [](auto& x, auto& y) {
    return std::get<1>(x) != std::get<1>(y) ? std::get<1>(x) < std::get<1>(y)
                                            : std::get<0>(x) < std::get<0>(y);
  });
  for (auto& [i, j, v] : t) {
    a.indices.push_back(i);
    a.values.push_back(v);
    ++a.offsets[j + 1];
  }
  for (index_t j = 0; j < n; ++j) a.offsets[j + 1] += a.offsets[j];
  return a;
}

TEST(Analysis, StructurallySingularMatricesAreRefused) {
  // empty row 2
  SparseMatrix g = from_triplets(3, Storage::full, {{0, 0, 1.0}, {1, 1, 1.0}, {0, 2, 1.0}});
  for (MatrixType t : {MatrixType::general, MatrixType::automatic}) {
    Options o;
    o.type = t;
    Solver s(o);
    try {
      s.analyze(g);
      FAIL() << "expected InvalidInput";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("structurally singular"), std::string::npos) << e.what();
    }
  }
  // no empty line, but columns 1 and 2 both have their only entry in row 0
  SparseMatrix h = from_triplets(3, Storage::full,
                                 {{0, 0, 1.0}, {1, 0, 1.0}, {2, 0, 1.0}, {0, 1, 2.0}, {0, 2, 3.0}});
  Options o;
  o.type = MatrixType::general;
  Solver s(o);
  EXPECT_THROW(s.analyze(h), InvalidInput);
  // symmetric with an empty row/column
  SparseMatrix y = from_triplets(3, Storage::lower, {{0, 0, 1.0}, {2, 2, 1.0}, {2, 0, 0.5}});
  Solver sy;
  EXPECT_THROW(sy.analyze(y), InvalidInput);
}

TEST(Analysis, SeparatorTreeWorkIsSubtreeFlops) {
  SparseMatrix a = generators::laplacian_3d(12, 12, 12);
  Options o;
  o.type = MatrixType::spd;
  Analysis an = analyze_matrix(a, o);
  const auto& tree = an.separator_tree;
  ASSERT_FALSE(tree.empty());
  double own_total = 0;
  for (const auto& node : tree.nodes) {
    double children = 0;
    for (index_t c : node.children) children += tree.nodes[c].work;
    EXPECT_GE(node.work, children);  // a node's subtree contains its children's
    EXPECT_GT(node.work, 0.0);
    own_total += node.work - children;
  }
  // the root's work is the whole factorization's Σ colcount², the exact flop count the
  // fronts carry without amalgamation padding: no more than the fronts' count
  EXPECT_NEAR(own_total, tree.nodes.back().work, 1e-6 * own_total);
  EXPECT_LE(tree.nodes.back().work, an.stats.factor_flops * (1 + 1e-12));
  EXPECT_GT(tree.nodes.back().work, 0.5 * an.stats.factor_flops);
}

}  // namespace
}  // namespace strata
