// strata — analysis-phase integration tests: structural singularity is refused with a
// message naming the problem; the separator tree's work hook matches the column counts;
// the CPU factorization's memory estimate bounds what it allocates.
#include <gtest/gtest.h>
#include <malloc.h>

#include <tuple>

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
// AnalysisStats::analysis_bytes against what the analysis keeps, and
// AnalysisStats::cpu_factorization_bytes against what a CPU factorization allocates: the
// heap in use (glibc's mallinfo2, mmapped blocks included) grows from after the analysis
// to after the first factorization by the factor, the arena and the front workspaces the
// Solver keeps; the estimate bounds that growth and is not far above it (with one thread
// it counts a second workspace that may never be used).
TEST(Analysis, CpuFactorizationBytesBoundWhatTheFactorizationAllocates) {
#if STRATA_TEST_HAS_ASAN
  GTEST_SKIP() << "the heap statistics are the sanitizer's under ASan: test skipped";
#else
  for (const auto& [name, a, type] :
       {std::tuple{"lap3d 24", generators::laplacian_3d(24, 24, 24), MatrixType::spd},
        std::tuple{"elasticity 8", generators::elasticity_3d(8, 8, 8), MatrixType::spd}}) {
    SCOPED_TRACE(name);
    // the lower triangle, the analysis's canonical form: the Solver then keeps its copies
    // of the input at analysis, and the growth below is the factorization's alone
    SparseMatrix low;
    low.n_rows = low.n_cols = a.n_rows;
    low.storage = Storage::lower;
    low.offsets.assign(1, 0);
    for (index_t j = 0; j < a.n_cols; ++j) {
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        if (a.indices[p] >= j) {
          low.indices.push_back(a.indices[p]);
          low.values.push_back(a.values[p]);
        }
      low.offsets.push_back(static_cast<index_t>(low.indices.size()));
    }
    Options o;
    o.type = type;
    o.num_threads = 1;
    const auto in_use = [] {
      const struct mallinfo2 m = mallinfo2();
      return static_cast<double>(m.uordblks + m.hblkhd);
    };
    const double before_analysis = in_use();
    Solver s(o);
    s.analyze(low);
    // what the analysis keeps: its arrays (analysis_bytes), the Solver's copies of the
    // input's values and pattern and its statistics (a few arrays of nnz entries) — a loose
    // upper bound, and a lower one that fails when analysis_bytes counts what is not there
    const double kept = in_use() - before_analysis;
    const auto arrays = static_cast<double>(s.stats().analysis.analysis_bytes);
    const double input = 8.0 * static_cast<double>(low.indices.size() + low.n_cols + 1);
    EXPECT_GE(kept, 0.95 * arrays) << kept << " bytes kept, analysis_bytes " << arrays;
    EXPECT_LE(kept, arrays + 4 * input + (2 << 20)) << kept << " bytes kept, " << arrays;
    const double before = in_use();
    s.factorize(low);
    const double grown = in_use() - before;
    const auto estimate = static_cast<double>(s.stats().analysis.cpu_factorization_bytes);
    ASSERT_GT(estimate, 0);
    EXPECT_LE(grown, 1.02 * estimate + (1 << 20)) << grown << " bytes grown, " << estimate;
    EXPECT_GE(grown, 0.7 * estimate) << grown << " bytes grown, " << estimate;
  }
#endif
}

}  // namespace strata
