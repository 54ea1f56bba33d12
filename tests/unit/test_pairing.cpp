// strata tests — Duff & Pralet's symmetric matching-based scaling and 2×2 pivot pairing
// (src/ordering/pairing.hpp), the orderings on the quotient graph of the pivot groups,
// and what the analysis makes of them: every group consecutive in the pivot order and
// in one front. The numerical outcome (no perturbed pivots, exact inertia) is checked
// here on hand-made matrices and in tests/integration/test_solver.cpp on random and
// shared KKT matrices.
//
// Source: I. S. Duff and S. Pralet, "Strategies for scaling and pivoting for sparse
// symmetric indefinite problems", SIAM J. Matrix Anal. Appl. 27(2), 2005.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>
#include <set>
#include <vector>

#include "analysis/analysis.hpp"
#include "ordering/graph.hpp"
#include "ordering/ordering.hpp"
#include "ordering/pairing.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using ordering::VertexGroups;

// Lower-stored canonical CSC of a dense symmetric n×n matrix (column-major); zeros are
// not stored.
SparseMatrix lower_from_dense(index_t n, const std::vector<double>& d) {
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.storage = Storage::lower;
  a.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {
    for (index_t i = j; i < n; ++i)
      if (d[i + j * n] != 0.0) {
        a.indices.push_back(i);
        a.values.push_back(d[i + j * n]);
      }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  return a;
}

// The groups of a pairing as sets of members, for order-independent comparisons.
std::set<std::vector<index_t>> group_sets(const VertexGroups& g) {
  std::set<std::vector<index_t>> out;
  for (index_t q = 0; q < g.n_groups(); ++q) {
    std::vector<index_t> m(g.members.begin() + g.ptr[q], g.members.begin() + g.ptr[q + 1]);
    std::sort(m.begin(), m.end());
    out.insert(m);
  }
  return out;
}

// Every group's members are consecutive in an.perm, in the group's order, and pivots of
// one front.
void expect_groups_in_one_front(const Analysis& an) {
  const auto& g = an.pivot_groups;
  for (index_t q = 0; q < g.n_groups(); ++q) {
    const index_t k0 = an.iperm[g.members[g.ptr[q]]];
    for (index_t p = g.ptr[q] + 1; p < g.ptr[q + 1]; ++p) {
      const index_t k = an.iperm[g.members[p]];
      EXPECT_EQ(k, k0 + (p - g.ptr[q])) << "group " << q << " is not consecutive";
      EXPECT_EQ(an.tree.front_of_column[k], an.tree.front_of_column[k0])
          << "group " << q << " is split across fronts";
    }
  }
}

Options indefinite(OrderingMethod m = OrderingMethod::nested_dissection, index_t block = 256) {
  Options o;
  o.type = MatrixType::symmetric_indefinite;
  o.ordering = m;
  o.max_block_size = block;
  return o;
}

// ---------------------------------------------------------------------------------------
// The pairing itself

TEST(Pairing, AntiDiagonalTwoByTwo) {
  // [[0, 1e6], [1e6, 0]]: one pair, scaled to [[0, 1], [1, 0]].
  const SparseMatrix a = lower_from_dense(2, {0, 1e6, 1e6, 0});
  const auto sp = ordering::symmetric_matching_pairing(a, 0.01);
  EXPECT_FALSE(sp.structurally_singular);
  ASSERT_EQ(sp.scaling.size(), 2u);
  EXPECT_NEAR(sp.scaling[0] * 1e6 * sp.scaling[1], 1.0, 1e-14);
  EXPECT_NEAR(sp.scaling[0], sp.scaling[1], 1e-14 * sp.scaling[0]);
  EXPECT_EQ(sp.scaled_diagonal, (std::vector<double>{0, 0}));
  ASSERT_EQ(sp.groups.n_groups(), 1);
  EXPECT_EQ(sp.groups.members, (std::vector<index_t>{0, 1}));

  for (MatrixType type : {MatrixType::symmetric_indefinite, MatrixType::automatic}) {
    Options o;
    o.type = type;
    Solver s(o);
    s.factorize(a);
    EXPECT_EQ(s.stats().analysis.type, MatrixType::symmetric_indefinite)
        << "a zero diagonal cannot be spd: resolved at analysis";
    EXPECT_EQ(s.stats().analysis.pairs, 1);
    const FactorStats& f = s.stats().factor;
    EXPECT_EQ(f.perturbed_pivots, 0);
    EXPECT_EQ(f.two_by_two_pivots, 1);
    EXPECT_EQ(f.inertia_positive, 1);
    EXPECT_EQ(f.inertia_negative, 1);
    EXPECT_NEAR(f.log_abs_determinant, 2 * std::log(1e6), 1e-12);
    EXPECT_EQ(f.determinant_sign, -1);
    const auto x = s.solve(std::vector<double>{2e6, 3e6});
    EXPECT_NEAR(x[0], 3.0, 1e-14);
    EXPECT_NEAR(x[1], 2.0, 1e-14);
  }
}

// D·A·D has entries ≤ 1 and matched entries of magnitude 1, for symmetric matrices of
// every kind, including badly scaled ones.
TEST(Pairing, ScalingBoundsAndMatchedEntries) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> expo(-6, 6);
  for (auto kind : {test::RandomKind::spd, test::RandomKind::symmetric_indefinite})
    for (index_t n : {1, 2, 7, 50, 400}) {
      SparseMatrix a = test::random_sparse(n, 3, kind, rng);
      std::vector<double> s(n);
      for (double& v : s) v = std::pow(10.0, expo(rng));
      for (index_t j = 0; j < n; ++j)
        for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
          a.values[p] *= s[a.indices[p]] * s[j];
      const auto sp = ordering::symmetric_matching_pairing(a, 0.01);
      ASSERT_EQ(static_cast<index_t>(sp.scaling.size()), n);
      const SparseMatrix full = expand_symmetric(a);
      std::map<std::pair<index_t, index_t>, double> scaled;
      for (index_t j = 0; j < n; ++j)
        for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p) {
          const index_t i = full.indices[p];
          const double v = std::abs(sp.scaling[i] * full.values[p] * sp.scaling[j]);
          EXPECT_LE(v, 1.0 + 1e-12) << "entry (" << i << ", " << j << ")";
          scaled[{i, j}] = v;
        }
      if (sp.structurally_singular) continue;
      for (index_t i = 0; i < n; ++i) {
        const auto it = scaled.find({i, sp.matching[i]});
        ASSERT_NE(it, scaled.end()) << "matched entry of row " << i << " is not an entry";
        EXPECT_NEAR(it->second, 1.0, 1e-10) << "matched entry of row " << i;
      }
      // groups: disjoint, sizes 2 or odd ≥ 3, consecutive members coupled by an entry,
      // and every pair holds a small scaled diagonal
      std::vector<int> seen(n, 0);
      for (index_t q = 0; q < sp.groups.n_groups(); ++q) {
        const index_t sz = sp.groups.size(q);
        ASSERT_GE(sz, 2);
        bool any_small = false;
        for (index_t p = sp.groups.ptr[q]; p < sp.groups.ptr[q + 1]; ++p) {
          const index_t v = sp.groups.members[p];
          EXPECT_EQ(seen[v]++, 0) << "vertex " << v << " in two groups";
          any_small |= sp.scaled_diagonal[v] < 0.01;
          if (p + 1 < sp.groups.ptr[q + 1])
            EXPECT_TRUE(scaled.count({sp.groups.members[p + 1], v}))
                << "members " << v << " and " << sp.groups.members[p + 1] << " not coupled";
        }
        EXPECT_TRUE(any_small) << "a group of large diagonals was kept";
        if (sz == 2)  // the smaller diagonal first
          EXPECT_LE(sp.scaled_diagonal[sp.groups.members[sp.groups.ptr[q]]],
                    sp.scaled_diagonal[sp.groups.members[sp.groups.ptr[q] + 1]]);
      }
    }
}

// A KKT matrix [[H, Bᵀ], [B, 0]] whose matching is forced: each constraint row (4, 5)
// can only be matched through B, and its largest B entry wins.
TEST(Pairing, KktPairsArePredictable) {
  const index_t n = 6;
  std::vector<double> d(n * n, 0.0);
  auto set = [&](index_t i, index_t j, double v) { d[i + j * n] = d[j + i * n] = v; };
  for (index_t i = 0; i < 4; ++i) set(i, i, 4.0);
  for (index_t i = 0; i + 1 < 4; ++i) set(i, i + 1, 0.5);
  set(4, 1, 3.0);  // constraint 4 couples variables 1 (strongly) and 2
  set(4, 2, 0.1);
  set(5, 3, 2.0);  // constraint 5 couples variables 3 (strongly) and 0
  set(5, 0, 0.2);
  const SparseMatrix a = lower_from_dense(n, d);
  const auto sp = ordering::symmetric_matching_pairing(a, 0.01);
  EXPECT_EQ(group_sets(sp.groups), (std::set<std::vector<index_t>>{{1, 4}, {3, 5}}));
  for (index_t q = 0; q < sp.groups.n_groups(); ++q)  // the constraint (zero diagonal) first
    EXPECT_GE(sp.groups.members[sp.groups.ptr[q]], 4);

  for (OrderingMethod m :
       {OrderingMethod::nested_dissection, OrderingMethod::metis, OrderingMethod::amd}) {
    for (index_t block : {1, 2, 256}) {
      SCOPED_TRACE("ordering " + std::string(to_string(m)) + " block " + std::to_string(block));
      const Options o = indefinite(m, block);
      const Analysis an = analyze_matrix(a, o);
      EXPECT_EQ(an.stats.pairs, 2);
      EXPECT_EQ(an.row_scaling, an.col_scaling);
      EXPECT_TRUE(an.matching_perm.empty()) << "no column permutation for symmetric types";
      expect_groups_in_one_front(an);
      Solver s(o);
      s.factorize(a);
      EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
      EXPECT_EQ(s.stats().factor.inertia_positive, 4);
      EXPECT_EQ(s.stats().factor.inertia_negative, 2);
      std::vector<double> b(n, 1.0);
      const auto x = s.solve(b);
      EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-15);
    }
  }
}

// A pair whose two scaled diagonals are large is split back into singletons, unless the
// threshold says otherwise; a threshold ≤ 0 keeps no pair but still scales.
TEST(Pairing, PairsOfLargeDiagonalsAreSplit) {
  // [[1 2]; [2 1]]: the off-diagonal wins the matching; scaled, the diagonal is 1/2.
  const SparseMatrix a = lower_from_dense(2, {1, 2, 2, 1});
  auto sp = ordering::symmetric_matching_pairing(a, 0.01);
  EXPECT_EQ(sp.matching, (std::vector<index_t>{1, 0}));
  EXPECT_NEAR(sp.scaled_diagonal[0], 0.5, 1e-15);
  EXPECT_EQ(sp.groups.n_groups(), 0);
  sp = ordering::symmetric_matching_pairing(a, 0.6);
  EXPECT_EQ(sp.groups.n_groups(), 1);

  Options o = indefinite();
  o.pairing_threshold = 0;
  const SparseMatrix z = lower_from_dense(2, {0, 1, 1, 0});
  const Analysis an = analyze_matrix(z, o);
  EXPECT_EQ(an.stats.pairs, 0);
  EXPECT_EQ(an.row_scaling.size(), 2u);
  o.matching_and_scaling = false;
  const Analysis off = analyze_matrix(z, o);
  EXPECT_TRUE(off.row_scaling.empty());
  EXPECT_EQ(off.pivot_groups.n_groups(), 0);
}

// A zero-diagonal odd cycle [[0 a b]; [a 0 c]; [b c 0]] (det 2abc) has no good singleton:
// it is kept whole, and its 3×3 block is factored without perturbation.
TEST(Pairing, ZeroDiagonalOddCycleIsKeptWhole) {
  const SparseMatrix a = lower_from_dense(3, {0, 1, 2, 1, 0, 3, 2, 3, 0});
  const auto sp = ordering::symmetric_matching_pairing(a, 0.01);
  ASSERT_EQ(sp.groups.n_groups(), 1);
  EXPECT_EQ(sp.groups.size(0), 3);
  const Options o = indefinite();
  const Analysis an = analyze_matrix(a, o);
  EXPECT_EQ(an.stats.odd_cycles, 1);
  expect_groups_in_one_front(an);
  Solver s(o);
  s.factorize(a);
  EXPECT_EQ(s.stats().factor.perturbed_pivots, 0);
  // trace 0, det 12 > 0: one positive and two negative eigenvalues
  EXPECT_EQ(s.stats().factor.inertia_positive, 1);
  EXPECT_EQ(s.stats().factor.inertia_negative, 2);
  EXPECT_NEAR(s.stats().factor.log_abs_determinant, std::log(12.0), 1e-13);
  EXPECT_EQ(s.stats().factor.determinant_sign, 1);

  // A 5-cycle with zero diagonal: the odd cycle 0-1-2-3-4-0 is the only perfect matching
  // structure (plus its reverse), det = 2·Π(edges).
  std::vector<double> d(25, 0.0);
  const double w[5] = {1.0, 2.0, 0.5, 3.0, 1.5};
  for (index_t i = 0; i < 5; ++i) {
    const index_t j = (i + 1) % 5;
    d[i + j * 5] = d[j + i * 5] = w[i];
  }
  const SparseMatrix c5 = lower_from_dense(5, d);
  Solver s5(o);
  s5.factorize(c5);
  EXPECT_EQ(s5.stats().analysis.odd_cycles, 1);
  EXPECT_EQ(s5.stats().factor.perturbed_pivots, 0);
  EXPECT_NEAR(s5.stats().factor.log_abs_determinant, std::log(2 * 1.0 * 2.0 * 0.5 * 3.0 * 1.5),
              1e-12);
}

// One odd cycle of 100001 zero-diagonal unknowns (the matching of an odd cycle graph is a
// rotation): too long to keep whole, it is split into 50000 pairs and a singleton, in
// time linear in its length (choosing among its 100001 splittings naively is quadratic).
TEST(Pairing, LongOddCycleIsSplitInLinearTime) {
  const index_t n = 100001;
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 2.0);
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.storage = Storage::lower;
  a.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {  // lower triangle of the cycle 0-1-...-(n-1)-0
    if (j + 1 < n) {
      a.indices.push_back(j + 1);
      a.values.push_back(u(rng));
    }
    if (j == 0) {
      a.indices.push_back(n - 1);
      a.values.push_back(u(rng));
    }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  const auto sp = ordering::symmetric_matching_pairing(a, 0.01);
  std::vector<char> seen(n, 0);
  index_t k = 0;
  for (index_t i = 0; !seen[i]; i = sp.matching[i]) seen[i] = 1, ++k;
  ASSERT_EQ(k, n) << "the matching is one cycle";
  EXPECT_EQ(sp.groups.n_groups(), (n - 1) / 2);
  for (index_t q = 0; q < sp.groups.n_groups(); ++q) EXPECT_EQ(sp.groups.size(q), 2);
}

// ---------------------------------------------------------------------------------------
// Groups and the orderings on the quotient graph

TEST(Pairing, CompleteGroupsAndQuotientGraph) {
  VertexGroups multi;
  multi.members = {4, 1, 5, 3, 0};
  multi.ptr = {0, 2, 5};
  const VertexGroups all = ordering::complete_groups(7, multi);
  // groups in increasing order of their smallest member, members in their given order
  EXPECT_EQ(all.members, (std::vector<index_t>{5, 3, 0, 4, 1, 2, 6}));
  EXPECT_EQ(all.ptr, (std::vector<index_t>{0, 3, 5, 6, 7}));
  VertexGroups bad = multi;
  bad.members = {4, 1, 5, 4, 0};
  EXPECT_THROW(ordering::complete_groups(7, bad), InvalidInput);

  // path 0-1-2-3-4-5-6; groups {5,3,0}, {4,1}, {2}, {6}
  ordering::Graph g;
  g.n = 7;
  g.xadj = {0, 1, 3, 5, 7, 9, 11, 12};
  g.adjncy = {1, 0, 2, 1, 3, 2, 4, 3, 5, 4, 6, 5};
  const ordering::Graph q = ordering::quotient_graph(g, all);
  EXPECT_EQ(q.n, 4);
  EXPECT_EQ(q.xadj, (std::vector<index_t>{0, 3, 5, 7, 8}));
  EXPECT_EQ(std::vector<index_t>(q.adjncy.begin(), q.adjncy.end()),
            (std::vector<index_t>{1, 2, 3, 0, 2, 0, 1, 0}));
}

// Every method keeps each group consecutive and in order; nested dissection's tree counts
// members; with singleton groups ND gives exactly the ungrouped ordering.
TEST(Pairing, GroupedOrderingsKeepGroupsConsecutive) {
  auto rng = test::fresh_rng();
  for (index_t n : {3, 40, 900}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const ordering::Graph g =
        ordering::graph_of(test::random_sparse(n, 3, test::RandomKind::spd, rng));
    // random groups of 1..3 vertices
    std::vector<index_t> order(n);
    std::iota(order.begin(), order.end(), index_t{0});
    std::shuffle(order.begin(), order.end(), rng);
    VertexGroups multi;
    std::uniform_int_distribution<index_t> size(1, 3);
    for (index_t p = 0; p < n;) {
      const index_t s = std::min(size(rng), n - p);
      if (s >= 2) {
        multi.members.insert(multi.members.end(), order.begin() + p, order.begin() + p + s);
        multi.ptr.push_back(static_cast<index_t>(multi.members.size()));
      }
      p += s;
    }
    const VertexGroups groups = ordering::complete_groups(n, multi);
    for (OrderingMethod m :
         {OrderingMethod::nested_dissection, OrderingMethod::metis, OrderingMethod::amd}) {
      SCOPED_TRACE(to_string(m));
      Options o;
      o.ordering = m;
      o.nd_leaf_size = 16;
      const ordering::OrderingResult r = ordering::compute_grouped_ordering(g, groups, o);
      ASSERT_TRUE(ordering::is_permutation(r.perm, n));
      const auto inv = ordering::invert_permutation(r.perm);
      for (index_t q = 0; q < groups.n_groups(); ++q)
        for (index_t p = groups.ptr[q] + 1; p < groups.ptr[q + 1]; ++p)
          ASSERT_EQ(inv[groups.members[p]], inv[groups.members[p - 1]] + 1) << "group " << q;
      if (m == OrderingMethod::nested_dissection) {
        // node ranges partition 0..n and no group straddles two nodes
        const auto& nodes = r.tree.nodes;
        ASSERT_FALSE(nodes.empty());
        EXPECT_EQ(nodes.back().end, n);
        EXPECT_EQ(nodes.back().subtree_begin, 0);
        std::vector<index_t> owner(n, -1);
        for (index_t v = 0; v < static_cast<index_t>(nodes.size()); ++v)
          for (index_t k = nodes[v].begin; k < nodes[v].end; ++k) {
            ASSERT_EQ(owner[k], -1);
            owner[k] = v;
          }
        for (index_t k = 0; k < n; ++k) ASSERT_GE(owner[k], 0);
        for (index_t q = 0; q < groups.n_groups(); ++q)
          for (index_t p = groups.ptr[q] + 1; p < groups.ptr[q + 1]; ++p)
            EXPECT_EQ(owner[inv[groups.members[p]]], owner[inv[groups.members[p - 1]]]);
      }
    }
    // natural and user ignore the groups
    Options nat;
    nat.ordering = OrderingMethod::natural;
    EXPECT_EQ(ordering::compute_grouped_ordering(g, groups, nat).perm,
              ordering::compute_ordering(g, nat).perm);
    // singleton groups: the weighted driver is the plain one
    const VertexGroups singles = ordering::complete_groups(n, VertexGroups{});
    ordering::NestedDissectionOptions nd;
    nd.leaf_size = 16;
    EXPECT_EQ(ordering::nested_dissection(g, nd, singles).perm,
              ordering::nested_dissection(g, nd).perm);
  }
}

// ---------------------------------------------------------------------------------------
// The analysis

// A random KKT matrix [[H, Bᵀ], [B, 0]] symmetrically permuted at random (constraints
// interleaved with variables): every group lands consecutive and in one front, for every
// ordering method and block size, including max_block_size 1 and 2.
TEST(Pairing, GroupsAreConsecutiveAndInOneFront) {
  auto rng = test::fresh_rng();
  for (index_t n : {5, 17, 733}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    std::vector<char> is_constraint;
    const SparseMatrix a = test::random_kkt(n, rng, 0, &is_constraint);
    for (OrderingMethod m :
         {OrderingMethod::nested_dissection, OrderingMethod::metis, OrderingMethod::amd})
      for (index_t block : {1, 2, 4, 256}) {
        SCOPED_TRACE(std::string(to_string(m)) + " block " + std::to_string(block));
        const Analysis an = analyze_matrix(a, indefinite(m, block));
        // a constraint is never a singleton: its row only couples variables, so its
        // cycle of the matching has a variable to pair it with
        std::vector<char> grouped(n, 0);
        for (const index_t v : an.pivot_groups.members) grouped[v] = 1;
        for (index_t i = 0; i < n; ++i)
          if (is_constraint[i]) EXPECT_TRUE(grouped[i]) << "constraint " << i;
        EXPECT_GE(an.stats.pairs + an.stats.odd_cycles, n / 3);
        expect_groups_in_one_front(an);
        for (index_t f = 0; f < an.tree.n_fronts(); ++f)
          EXPECT_LE(an.tree.n_pivots(f), std::max<index_t>(block, 2));
      }
  }
}

// analyze resolves `automatic` to symmetric_indefinite only when a diagonal entry is
// missing or ≤ 0; an SPD matrix keeps the Cholesky attempt.
TEST(Pairing, AutomaticTypeResolutionAtAnalysis) {
  auto rng = test::fresh_rng();
  const SparseMatrix spd = test::random_sparse(60, 3, test::RandomKind::spd, rng);
  Options o;
  EXPECT_EQ(analyze_matrix(spd, o).type, MatrixType::automatic);
  SparseMatrix neg = spd;
  neg.values[neg.offsets[7]] = -1.0;  // column 7's first stored entry is its diagonal
  ASSERT_EQ(neg.indices[neg.offsets[7]], 7);
  EXPECT_EQ(analyze_matrix(neg, o).type, MatrixType::symmetric_indefinite);
  const SparseMatrix kkt = test::random_kkt(60, rng);
  const Analysis an = analyze_matrix(kkt, o);
  EXPECT_EQ(an.type, MatrixType::symmetric_indefinite);
  EXPECT_GE(an.stats.pairs, 20);
  Solver s;
  s.factorize(kkt);
  EXPECT_EQ(s.matrix_type(), MatrixType::symmetric_indefinite);
}

// The scaling and the pairs are computed from the values at analysis and reused by every
// refactorization: refactorize equals a fresh factorization with the same analysis.
TEST(Pairing, RefactorizationReusesScalingAndPairs) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = test::random_kkt(300, rng);
  SparseMatrix a2 = a;
  std::uniform_real_distribution<double> u(0.5, 1.5);
  for (double& v : a2.values) v *= u(rng);
  const Options o = indefinite();
  Solver s1(o), s2(o);
  s1.analyze(a);
  s1.factorize(a);
  s1.refactorize(a2);
  s2.analyze(a);
  s2.factorize(a2);
  std::vector<double> b(300);
  for (double& v : b) v = u(rng);
  const auto x1 = s1.solve(b);
  const auto x2 = s2.solve(b);
  EXPECT_EQ(x1, x2);
  EXPECT_EQ(s1.stats().factor.perturbed_pivots, 0);
  EXPECT_LE(test::backward_error(a2, x1.data(), b.data()), 1e-14);
}

}  // namespace
}  // namespace strata
