// strata tests — graphs of sparse patterns, fill-reducing orderings and the separator
// tree of nested dissection (src/ordering/graph.hpp, src/ordering/ordering.hpp).
//
// Fill is measured by a test-local symbolic factorization: the elimination tree (Liu's
// algorithm with path compression) and the row subtrees of L, which costs O(nnz(L)). It is
// itself checked against a brute-force dense elimination on small graphs.
//
// The tests DISABLED_ReportQuality and DISABLED_ReportLarge print the timings and ND / METIS_NodeND
// fill ratios on the large problems (run with --gtest_also_run_disabled_tests).
#include <gtest/gtest.h>
#include <tbb/task_arena.h>
#include <zlib.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <numeric>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include "analysis/analysis.hpp"
#include "ordering/graph.hpp"
#include "ordering/ordering.hpp"
#include "sparse/generators.hpp"
#include "strata/errors.hpp"
#include "support/test_support.hpp"

namespace strata::ordering {
namespace {

// ---------------------------------------------------------------------------------------
// helpers

// A graph from an explicit edge list (each undirected edge once, any order).
Graph graph_from_edges(index_t n, const std::vector<std::pair<index_t, index_t>>& edges) {
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.offsets.assign(n + 1, 0);
  for (const auto& [i, j] : edges) ++a.offsets[j + 1];
  for (index_t j = 0; j < n; ++j) a.offsets[j + 1] += a.offsets[j];
  a.indices.resize(edges.size());
  std::vector<index_t> next(a.offsets.begin(), a.offsets.end() - 1);
  for (const auto& [i, j] : edges) a.indices[next[j]++] = i;
  return graph_of(a);
}

Graph path_graph(index_t n) {
  std::vector<std::pair<index_t, index_t>> e;
  for (index_t i = 0; i + 1 < n; ++i) e.push_back({i, i + 1});
  return graph_from_edges(n, e);
}

Graph star_graph(index_t n, index_t center) {
  std::vector<std::pair<index_t, index_t>> e;
  for (index_t i = 0; i < n; ++i)
    if (i != center) e.push_back({i, center});
  return graph_from_edges(n, e);
}

Graph random_graph(index_t n, index_t per_column, std::mt19937_64& rng) {
  return graph_of(test::random_sparse(n, per_column, test::RandomKind::spd, rng));
}

// Several components: grids of different sizes, a path, a star and isolated vertices,
// with the vertex numbers shuffled so components interleave.
Graph disconnected_graph(std::mt19937_64& rng) {
  std::vector<std::pair<index_t, index_t>> e;
  index_t n = 0;
  auto add = [&](const Graph& g) {
    for (index_t v = 0; v < g.n; ++v)
      for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p)
        if (g.adjncy[p] > v) e.push_back({n + v, n + g.adjncy[p]});
    n += g.n;
  };
  add(graph_of(generators::laplacian_2d(30, 20)));
  add(graph_of(generators::laplacian_3d(7, 6, 5)));
  add(path_graph(300));
  add(star_graph(50, 7));
  for (int k = 0; k < 40; ++k) add(path_graph(k % 5 + 1));  // small pieces and isolated
  std::vector<index_t> shuffle(n);
  std::iota(shuffle.begin(), shuffle.end(), index_t{0});
  std::shuffle(shuffle.begin(), shuffle.end(), rng);
  for (auto& [i, j] : e) {
    i = shuffle[i];
    j = shuffle[j];
  }
  return graph_from_edges(n, e);
}

// nnz(L) (diagonal included) of the Cholesky factor of a matrix with graph g, ordered by
// perm (new to old): elimination tree, then each row's subtree of the etree.
index_t fill_nnz(const Graph& g, const std::vector<index_t>& perm) {
  const index_t n = g.n;
  const std::vector<index_t> inv = invert_permutation(perm);
  std::vector<index_t> parent(n, -1), ancestor(n, -1);
  for (index_t k = 0; k < n; ++k) {
    const index_t v = perm[k];
    for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p) {
      index_t i = inv[g.adjncy[p]];
      while (i != -1 && i < k) {
        const index_t next = ancestor[i];
        ancestor[i] = k;
        if (next == -1) parent[i] = k;
        i = next;
      }
    }
  }
  std::vector<index_t> flag(n, -1);
  index_t nnz = n;
  for (index_t k = 0; k < n; ++k) {
    flag[k] = k;
    const index_t v = perm[k];
    for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p)
      for (index_t i = inv[g.adjncy[p]]; i < k && flag[i] != k; i = parent[i]) {
        flag[i] = k;
        ++nnz;  // L(k, i) is nonzero
      }
  }
  return nnz;
}

// Brute-force nnz(L) by a dense boolean elimination (small n only).
index_t fill_nnz_dense(const Graph& g, const std::vector<index_t>& perm) {
  const index_t n = g.n;
  const std::vector<index_t> inv = invert_permutation(perm);
  std::vector<std::vector<char>> m(n, std::vector<char>(n, 0));
  for (index_t v = 0; v < n; ++v) {
    m[inv[v]][inv[v]] = 1;
    for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p) m[inv[v]][inv[g.adjncy[p]]] = 1;
  }
  index_t nnz = 0;
  for (index_t k = 0; k < n; ++k) {
    for (index_t i = k; i < n; ++i) nnz += m[i][k];
    for (index_t i = k + 1; i < n; ++i)
      if (m[i][k])
        for (index_t j = k + 1; j < n; ++j)
          if (m[j][k]) m[i][j] = 1;
  }
  return nnz;
}

// Checks every documented invariant of the separator tree of an ordering of g.
void check_tree(const Graph& g, const OrderingResult& r) {
  const index_t n = g.n;
  ASSERT_TRUE(is_permutation(r.perm, n));
  const auto& nodes = r.tree.nodes;
  if (n == 0) {
    EXPECT_TRUE(r.tree.empty());
    return;
  }
  ASSERT_FALSE(nodes.empty());
  const index_t nn = static_cast<index_t>(nodes.size());
  // The root is last, and it is the only node without a parent.
  EXPECT_EQ(nodes.back().parent, -1);
  std::vector<index_t> owner(n, -1);
  for (index_t v = 0; v < nn; ++v) {
    const auto& node = nodes[v];
    SCOPED_TRACE("node " + std::to_string(v));
    ASSERT_LE(0, node.begin);
    ASSERT_LE(node.begin, node.end);
    ASSERT_LE(node.end, n);
    ASSERT_LE(node.subtree_begin, node.begin);
    EXPECT_EQ(node.work, 0.0);
    if (v != nn - 1) {
      ASSERT_GT(node.parent, v) << "postorder: the parent comes after its children";
      ASSERT_LT(node.parent, nn);
      const auto& pc = nodes[node.parent].children;
      EXPECT_EQ(std::count(pc.begin(), pc.end(), v), 1);
    }
    for (index_t k = node.begin; k < node.end; ++k) {
      ASSERT_EQ(owner[k], -1) << "pivot " << k << " owned twice";
      owner[k] = v;
    }
    // Children: listed in pivot order, earlier in postorder, ranges contiguous and
    // covering the subtree exactly up to the node's own pivots.
    index_t expect = node.subtree_begin;
    for (const index_t c : node.children) {
      ASSERT_LT(c, v);
      ASSERT_EQ(nodes[c].parent, v);
      EXPECT_EQ(nodes[c].subtree_begin, expect) << "child " << c;
      expect = nodes[c].end;
    }
    EXPECT_EQ(expect, node.begin) << "the subtree range ends at the node's own range";
    if (node.children.empty()) EXPECT_EQ(node.subtree_begin, node.begin);
    // A node with an empty separator has at least two children (several components).
    if (node.begin == node.end && n > 0) EXPECT_GE(node.children.size(), 2u);
  }
  // Postorder: the subtree of v is exactly the nodes v - size(v) + 1 .. v.
  std::vector<index_t> size(nn, 1);
  for (index_t v = 0; v < nn; ++v)
    for (const index_t c : nodes[v].children) size[v] += size[c];
  for (index_t v = 0; v < nn; ++v)
    for (index_t u = v - size[v] + 1; u < v; ++u) {
      index_t a = u;
      while (a != -1 && a != v) a = nodes[a].parent;
      ASSERT_EQ(a, v) << "node " << u << " lies in the postorder range of " << v;
    }
  EXPECT_EQ(nodes.back().subtree_begin, 0);
  EXPECT_EQ(nodes.back().end, n);
  for (index_t k = 0; k < n; ++k) ASSERT_GE(owner[k], 0) << "pivot " << k << " owned by no node";
  // Separation: for every edge (u, v) with pivot(u) < pivot(v), the node owning v is an
  // ancestor of (or is) the node owning u. Equivalently, no edge joins the vertex sets of
  // two different child subtrees of a node.
  const std::vector<index_t> inv = invert_permutation(r.perm);
  index_t bad = 0;
  for (index_t u = 0; u < n; ++u)
    for (index_t p = g.xadj[u]; p < g.xadj[u + 1]; ++p) {
      const index_t a = inv[u], b = inv[g.adjncy[p]];
      if (a >= b) continue;
      const auto& nb = nodes[owner[b]];
      if (a < nb.subtree_begin || a >= nb.end) ++bad;
    }
  EXPECT_EQ(bad, 0) << "edges crossing between sibling subtrees";
}

Options with_method(OrderingMethod m) {
  Options o;
  o.ordering = m;
  return o;
}

const OrderingMethod kMethods[] = {OrderingMethod::nested_dissection, OrderingMethod::metis,
                                   OrderingMethod::amd, OrderingMethod::natural};

void check_all_methods(const Graph& g, const std::string& what) {
  SCOPED_TRACE(what);
  for (const OrderingMethod m : kMethods) {
    SCOPED_TRACE(std::string("method ") + std::to_string(static_cast<int>(m)));
    const OrderingResult r = compute_ordering(g, with_method(m));
    ASSERT_TRUE(is_permutation(r.perm, g.n));
    if (m == OrderingMethod::nested_dissection)
      check_tree(g, r);
    else
      EXPECT_TRUE(r.tree.empty());
  }
  // ND with small leaves exercises deep trees and tiny separators.
  for (const index_t leaf : {1, 2, 5, 16}) {
    SCOPED_TRACE("leaf size " + std::to_string(leaf));
    const OrderingResult r = nested_dissection(g, {leaf, 3});
    check_tree(g, r);
  }
}

// ---------------------------------------------------------------------------------------
// graph_of and induced_subgraph

void expect_well_formed(const Graph& g) {
  ASSERT_EQ(static_cast<index_t>(g.xadj.size()), g.n + 1);
  ASSERT_EQ(g.xadj[0], 0);
  ASSERT_EQ(g.n_edges_directed(), static_cast<index_t>(g.adjncy.size()));
  std::set<std::pair<index_t, index_t>> edges;
  for (index_t v = 0; v < g.n; ++v)
    for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p) {
      ASSERT_NE(g.adjncy[p], v) << "self loop";
      if (p > g.xadj[v]) ASSERT_LT(g.adjncy[p - 1], g.adjncy[p]) << "unsorted or repeated";
      edges.insert({v, g.adjncy[p]});
    }
  for (const auto& [u, v] : edges) EXPECT_TRUE(edges.count({v, u})) << u << "-" << v;
}

TEST(GraphOf, SameGraphForEveryLayoutAndStorage) {
  auto rng = test::fresh_rng();
  const SparseMatrix lower = test::random_sparse(60, 4, test::RandomKind::spd, rng);
  const SparseMatrix full = expand_symmetric(lower);
  const Graph ref = graph_of(full);
  expect_well_formed(ref);
  // Expected: off-diagonal pattern of the full matrix.
  index_t offdiag = 0;
  for (index_t j = 0; j < full.n_cols; ++j)
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p) offdiag += full.indices[p] != j;
  EXPECT_EQ(ref.n_edges_directed(), offdiag);

  SparseMatrix a = lower;  // lower CSC
  EXPECT_EQ(graph_of(a).adjncy, ref.adjncy);
  a.layout = Layout::csr;  // lower CSC read as CSR is the upper triangle
  a.storage = Storage::upper;
  EXPECT_EQ(graph_of(a).adjncy, ref.adjncy);
  a = full;
  a.layout = Layout::csr;
  EXPECT_EQ(graph_of(a).xadj, ref.xadj);
  EXPECT_EQ(graph_of(a).adjncy, ref.adjncy);
}

TEST(GraphOf, UnsymmetricPatternIsSymmetrized) {
  // A = [1 1 0; 0 1 0; 1 0 1] (CSC, duplicates and unsorted indices)
  SparseMatrix a;
  a.n_rows = a.n_cols = 3;
  a.offsets = {0, 3, 6, 7};
  a.indices = {2, 0, 2, 1, 0, 0, 2};
  const Graph g = graph_of(a);
  expect_well_formed(g);
  EXPECT_EQ(g.xadj, (std::vector<index_t>{0, 2, 3, 4}));
  EXPECT_EQ(std::vector<index_t>(g.adjncy.begin(), g.adjncy.end()),
            (std::vector<index_t>{1, 2, 0, 0}));
}

TEST(GraphOf, EmptyAndDiagonalOnly) {
  SparseMatrix a;
  EXPECT_EQ(graph_of(a).n, 0);
  a.n_rows = a.n_cols = 3;
  a.offsets = {0, 1, 2, 2};
  a.indices = {0, 1};
  const Graph g = graph_of(a);
  EXPECT_EQ(g.n, 3);
  EXPECT_EQ(g.n_edges_directed(), 0);
}

TEST(GraphOf, RejectsBadInput) {
  SparseMatrix a;
  a.n_rows = 2;
  a.n_cols = 3;
  a.offsets = {0, 0, 0, 0};
  EXPECT_THROW(graph_of(a), InvalidInput);
  a.n_rows = 3;
  a.offsets = {0, 1, 1, 1};
  a.indices = {3};
  EXPECT_THROW(graph_of(a), InvalidInput);
  a.offsets = {0, 1};
  EXPECT_THROW(graph_of(a), InvalidInput);
}

TEST(InducedSubgraph, KeepsInternalEdges) {
  const Graph g = graph_of(generators::laplacian_2d(4, 4));
  const std::vector<index_t> verts = {5, 1, 6, 15, 4};  // 1-5, 4-5, 5-6 inside
  const Graph s = induced_subgraph(g, verts);
  expect_well_formed(s);
  EXPECT_EQ(s.n, 5);
  EXPECT_EQ(s.n_edges_directed(), 6);
  EXPECT_EQ(s.xadj[4] - s.xadj[3], 0);  // vertex 15 is isolated here
  EXPECT_THROW(induced_subgraph(g, {1, 1}), InvalidInput);
  EXPECT_THROW(induced_subgraph(g, {16}), InvalidInput);
}

// ---------------------------------------------------------------------------------------
// permutations

TEST(Permutation, InvertAndCheck) {
  const std::vector<index_t> p = {2, 0, 3, 1};
  EXPECT_TRUE(is_permutation(p, 4));
  EXPECT_FALSE(is_permutation(p, 5));
  EXPECT_FALSE(is_permutation({0, 0}, 2));
  EXPECT_FALSE(is_permutation({0, 2}, 2));
  EXPECT_FALSE(is_permutation({-1, 0}, 2));
  EXPECT_TRUE(is_permutation({}, 0));
  const auto inv = invert_permutation(p);
  for (index_t k = 0; k < 4; ++k) EXPECT_EQ(inv[p[k]], k);
}

TEST(FillHelper, MatchesDenseElimination) {
  auto rng = test::fresh_rng();
  for (index_t n : {1, 2, 7, 40, 90}) {
    const Graph g = random_graph(n, 3, rng);
    std::vector<index_t> p(n);
    std::iota(p.begin(), p.end(), index_t{0});
    std::shuffle(p.begin(), p.end(), rng);
    EXPECT_EQ(fill_nnz(g, p), fill_nnz_dense(g, p)) << "n = " << n;
    const auto amd = amd_ordering(g);
    EXPECT_EQ(fill_nnz(g, amd), fill_nnz_dense(g, amd)) << "n = " << n;
  }
}

// ---------------------------------------------------------------------------------------
// every method returns a valid permutation

TEST(Orderings, TinyGraphs) {
  for (index_t n = 0; n <= 3; ++n) {
    check_all_methods(path_graph(n), "path " + std::to_string(n));
    check_all_methods(graph_from_edges(n, {}), "no edges " + std::to_string(n));
  }
  check_all_methods(graph_from_edges(3, {{0, 1}, {1, 2}, {0, 2}}), "triangle");
}

TEST(Orderings, RandomGraphs) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("rng seed " + std::to_string(seed));
  for (index_t n : {0, 1, 2, 3, 5, 733})
    for (index_t per : {1, 3, 8})
      check_all_methods(random_graph(n, per, rng), "random n=" + std::to_string(n));
}

TEST(Orderings, GridsPathStar) {
  check_all_methods(graph_of(generators::laplacian_2d(23, 17)), "grid 2D");
  check_all_methods(graph_of(generators::laplacian_3d(9, 8, 7)), "grid 3D");
  check_all_methods(graph_of(generators::elasticity_3d(5, 4, 4)), "elasticity");
  check_all_methods(path_graph(1000), "path");
  check_all_methods(star_graph(500, 123), "star");
  // A clique compresses to a single vertex; two cliques joined by a path compress to few.
  std::vector<std::pair<index_t, index_t>> e;
  for (index_t i = 0; i < 200; ++i)
    for (index_t j = i + 1; j < 200; ++j) e.push_back({i, j});
  check_all_methods(graph_from_edges(200, e), "clique");
  for (index_t i = 0; i < 200; ++i)
    for (index_t j = i + 1; j < 200; ++j) e.push_back({300 + i, 300 + j});
  for (index_t i = 199; i < 300; ++i) e.push_back({i, i + 1});
  check_all_methods(graph_from_edges(500, e), "two cliques and a path");
}

TEST(Orderings, IsolatedVerticesAndDisconnected) {
  auto rng = test::fresh_rng();
  // A grid with every third vertex's edges removed, leaving isolated vertices.
  const Graph grid = graph_of(generators::laplacian_2d(30, 30));
  std::vector<std::pair<index_t, index_t>> e;
  for (index_t v = 0; v < grid.n; ++v)
    for (index_t p = grid.xadj[v]; p < grid.xadj[v + 1]; ++p) {
      const index_t w = grid.adjncy[p];
      if (w > v && v % 3 != 0 && w % 3 != 0) e.push_back({v, w});
    }
  check_all_methods(graph_from_edges(grid.n, e), "isolated vertices");
  check_all_methods(graph_from_edges(500, {}), "no edges at all");
  const Graph d = disconnected_graph(rng);
  check_all_methods(d, "disconnected");
  // The root of a disconnected graph has an empty separator and one child per large
  // component (small components are packed into shared leaves).
  const OrderingResult r = nested_dissection(d, {});
  EXPECT_EQ(r.tree.nodes.back().begin, r.tree.nodes.back().end);
  EXPECT_GE(r.tree.nodes.back().children.size(), 4u);
}

// ---------------------------------------------------------------------------------------
// permutation semantics: new to old

// Column counts (off the diagonal) of the Cholesky factor of g's matrix ordered by perm,
// as fill_nnz walks them.
std::vector<index_t> column_counts(const Graph& g, const std::vector<index_t>& perm) {
  const index_t n = g.n;
  const std::vector<index_t> inv = invert_permutation(perm);
  std::vector<index_t> parent(n, -1), ancestor(n, -1), flag(n, -1), count(n, 0);
  for (index_t k = 0; k < n; ++k)
    for (index_t p = g.xadj[perm[k]]; p < g.xadj[perm[k] + 1]; ++p)
      for (index_t i = inv[g.adjncy[p]]; i != -1 && i < k;) {
        const index_t next = ancestor[i];
        ancestor[i] = k;
        if (next == -1) parent[i] = k;
        i = next;
      }
  for (index_t k = 0; k < n; ++k) {
    flag[k] = k;
    for (index_t p = g.xadj[perm[k]]; p < g.xadj[perm[k] + 1]; ++p)
      for (index_t i = inv[g.adjncy[p]]; i < k && flag[i] != k; i = parent[i]) {
        flag[i] = k;
        ++count[i];
      }
  }
  return count;
}

// OrderingMethod::automatic: AMD's own counts are those of its ordering (nnz(L), and the
// LDLᵀ flops Σ c(c + 2) over the columns' off-diagonal counts c) within 1 %; AMD is kept
// exactly when CHOLMOD's rule holds for them (a 2D grid, a random sparse graph, a path), nested
// dissection is taken otherwise (a 3D grid) and whenever several workers split the tree;
// the analysis reports the method used.
TEST(Orderings, AutomaticKeepsAmdWhenItsFactorIsCheap) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  struct Case {
    std::string name;
    Graph g;
  };
  std::vector<Case> cases;
  cases.push_back({"path 733", path_graph(733)});
  cases.push_back({"2D 40x30", graph_of(generators::laplacian_2d(40, 30))});
  cases.push_back({"random 733", random_graph(733, 3, rng)});
  cases.push_back({"3D 24^3", graph_of(generators::laplacian_3d(24, 24, 24))});
  int kept = 0, dissected = 0;
  for (const Case& c : cases) {
    SCOPED_TRACE(c.name);
    AmdCounts counts;
    const std::vector<index_t> amd = amd_ordering(c.g, &counts);
    EXPECT_EQ(amd, amd_ordering(c.g));
    const std::vector<index_t> cc = column_counts(c.g, amd);
    double lnz = static_cast<double>(c.g.n), flops = 0;
    for (const index_t x : cc) {
      lnz += static_cast<double>(x);
      flops += static_cast<double>(x) * static_cast<double>(x + 2);
    }
    // AMD's counts are those of its elimination, exact or (after aggressive absorption,
    // with its approximate degrees) slightly above
    EXPECT_EQ(lnz, static_cast<double>(fill_nnz(c.g, amd)));
    EXPECT_GE(counts.nnz_l, lnz);
    EXPECT_LE(counts.nnz_l, 1.01 * lnz);
    EXPECT_GE(counts.flops, flops);
    EXPECT_LE(counts.flops, 1.01 * flops);
    const double tril =
        static_cast<double>(c.g.n) + 0.5 * static_cast<double>(c.g.n_edges_directed());
    const bool cheap = counts.flops < 500 * counts.nnz_l || counts.nnz_l < 5 * tril;
    EXPECT_EQ(amd_is_good_enough(counts, c.g), cheap);
    const OrderingResult r = compute_ordering(c.g, with_method(OrderingMethod::automatic));
    if (cheap) {
      ++kept;
      EXPECT_EQ(r.method, OrderingMethod::amd);
      EXPECT_EQ(r.perm, amd);
      EXPECT_TRUE(r.tree.empty());
    } else {
      ++dissected;
      EXPECT_EQ(r.method, OrderingMethod::nested_dissection);
      EXPECT_EQ(r.perm, compute_ordering(c.g, with_method(OrderingMethod::nested_dissection)).perm);
      check_tree(c.g, r);
    }
    const OrderingResult split = compute_ordering(c.g, with_method(OrderingMethod::automatic), 2);
    EXPECT_EQ(split.method, OrderingMethod::nested_dissection);
    check_tree(c.g, split);
  }
  EXPECT_EQ(kept, 3) << "the path, the 2D grid and the random graph have cheap AMD factors";
  EXPECT_EQ(dissected, 1) << "the 3D grid's AMD factor is not cheap";
  // the analysis says which method it used
  Options o = with_method(OrderingMethod::automatic);
  EXPECT_EQ(analyze_matrix(generators::laplacian_2d(40, 30), o, 1).stats.ordering,
            OrderingMethod::amd);
  EXPECT_EQ(analyze_matrix(generators::laplacian_3d(24, 24, 24), o, 1).stats.ordering,
            OrderingMethod::nested_dissection);
}

TEST(Orderings, PermutationIsNewToOld) {
  // On a star, every fill-reducing ordering eliminates the centre last: perm.back() is
  // the centre in new-to-old form (an old-to-new array would hold n-1 at the centre).
  const index_t n = 300, center = 17;
  const Graph g = star_graph(n, center);
  EXPECT_EQ(metis_ordering(g).back(), center);
  EXPECT_EQ(amd_ordering(g).back(), center);
  EXPECT_EQ(nested_dissection(g, {}).perm.back(), center);
  EXPECT_EQ(nested_dissection(g, {4, 1}).perm.back(), center);
  EXPECT_EQ(fill_nnz(g, metis_ordering(g)), 2 * n - 1);
  // And the fill of METIS's result is that of a good ordering, not of its inverse.
  const Graph grid = graph_of(generators::laplacian_2d(40, 40));
  const auto p = metis_ordering(grid);
  EXPECT_LT(fill_nnz(grid, p), fill_nnz(grid, invert_permutation(p)));
}

// ---------------------------------------------------------------------------------------
// fill quality against METIS_NodeND

void expect_fill_close(const Graph& g, double bound, const std::string& what) {
  const index_t nd = fill_nnz(g, nested_dissection(g, {}).perm);
  const index_t metis = fill_nnz(g, metis_ordering(g));
  const index_t amd = fill_nnz(g, amd_ordering(g));
  const double ratio = static_cast<double>(nd) / static_cast<double>(metis);
  std::printf("  %-22s nnz(L): ND %lld, METIS_NodeND %lld (ratio %.3f), AMD %lld\n", what.c_str(),
              static_cast<long long>(nd), static_cast<long long>(metis), ratio,
              static_cast<long long>(amd));
  EXPECT_LE(ratio, bound) << what;
}

TEST(Quality, FillCloseToMetisNodeND) {
  expect_fill_close(graph_of(generators::laplacian_2d(100, 100)), 1.15, "2D 100x100");
  expect_fill_close(graph_of(generators::laplacian_3d(20, 20, 20)), 1.15, "3D 20^3");
  expect_fill_close(graph_of(generators::elasticity_3d(10, 10, 10)), 1.15, "elasticity 10^3");
}

TEST(Quality, FarBetterThanNatural) {
  const Graph g = graph_of(generators::laplacian_3d(15, 15, 15));
  std::vector<index_t> natural(g.n);
  std::iota(natural.begin(), natural.end(), index_t{0});
  EXPECT_LT(2 * fill_nnz(g, nested_dissection(g, {}).perm), fill_nnz(g, natural));
}

// ---------------------------------------------------------------------------------------
// determinism

TEST(NestedDissection, DeterministicForAFixedSeed) {
  for (const auto& g : {graph_of(generators::laplacian_3d(14, 14, 14)),
                        graph_of(generators::laplacian_3d(21, 11, 7)),
                        graph_of(generators::elasticity_3d(6, 6, 6))}) {
    for (const int seed : {1, 7}) {
      const OrderingResult a = nested_dissection(g, {64, seed});
      const OrderingResult b = nested_dissection(g, {64, seed});
      EXPECT_EQ(a.perm, b.perm);
      ASSERT_EQ(a.tree.nodes.size(), b.tree.nodes.size());
      for (std::size_t k = 0; k < a.tree.nodes.size(); ++k) {
        EXPECT_EQ(a.tree.nodes[k].begin, b.tree.nodes[k].begin);
        EXPECT_EQ(a.tree.nodes[k].end, b.tree.nodes[k].end);
        EXPECT_EQ(a.tree.nodes[k].parent, b.tree.nodes[k].parent);
      }
    }
  }
}

// Pieces dissected side by side over the arena's threads give the ordering of one thread:
// the same permutation and the same tree, with or without balance by work and vertex
// groups; and with several threads some pieces did run side by side (this test program
// links strata statically, so METIS's random numbers are per thread: metis_random.hpp).
TEST(NestedDissection, SameOrderingOnAnyThreadCount) {
  std::mt19937_64 rng(std::random_device{}());
  struct Case {
    Graph g;
    bool large;
  };
  std::vector<Case> cases;
  for (const index_t n : {1, 2, 3, 5}) cases.push_back({path_graph(n), false});
  cases.push_back({random_graph(733, 4, rng), false});
  cases.push_back({graph_of(generators::laplacian_3d(20, 20, 20)), true});
  cases.push_back({graph_of(generators::elasticity_3d(12, 12, 12)), true});
  cases.push_back({disconnected_graph(rng), false});
  for (const Case& c : cases) {
    const Graph& g = c.g;  // (a structured binding cannot be captured by clang's C++20)
    const bool large = c.large;
    for (const int balance_levels : {0, 2}) {
      NestedDissectionOptions o;
      o.leaf_size = 32;
      o.balance_levels = balance_levels;
      auto on = [&](int threads) {
        tbb::task_arena arena(threads);
        return arena.execute([&] { return nested_dissection(g, o); });
      };
      const OrderingResult one = on(1);
      check_tree(g, one);
      EXPECT_EQ(one.side_by_side, 0);
      for (const int threads : {2, 4}) {
        const OrderingResult r = on(threads);
        EXPECT_EQ(r.perm, one.perm) << g.n << " vertices, " << threads << " threads";
        ASSERT_EQ(r.tree.nodes.size(), one.tree.nodes.size());
        for (std::size_t k = 0; k < r.tree.nodes.size(); ++k) {
          EXPECT_EQ(r.tree.nodes[k].begin, one.tree.nodes[k].begin);
          EXPECT_EQ(r.tree.nodes[k].end, one.tree.nodes[k].end);
          EXPECT_EQ(r.tree.nodes[k].parent, one.tree.nodes[k].parent);
          EXPECT_EQ(r.tree.nodes[k].children, one.tree.nodes[k].children);
        }
        EXPECT_EQ(r.rebisections, one.rebisections);
        if (large) EXPECT_GT(r.side_by_side, 0) << g.n << " vertices, " << threads << " threads";
      }
    }
  }
}

// The compression of indistinguishable vertices compares sorted adjacency lists over the
// threads and falls back to marking closed neighbourhoods when a list is not sorted: a
// 3-dof mesh (three indistinguishable vertices per node) with its lists shuffled still gets
// a valid tree and the fill of the sorted graph's ordering within a few percent.
TEST(NestedDissection, CompressesAGraphWithUnsortedAdjacency) {
  std::mt19937_64 rng(std::random_device{}());
  const Graph sorted = graph_of(generators::elasticity_3d(11, 11, 11));
  Graph shuffled = sorted;
  for (index_t v = 0; v < shuffled.n; ++v)
    std::shuffle(shuffled.adjncy.begin() + shuffled.xadj[v],
                 shuffled.adjncy.begin() + shuffled.xadj[v + 1], rng);
  ASSERT_NE(shuffled.adjncy, sorted.adjncy);
  const NestedDissectionOptions o{64, 1};
  const OrderingResult a = nested_dissection(sorted, o), b = nested_dissection(shuffled, o);
  check_tree(sorted, a);
  check_tree(shuffled, b);
  const auto fa = static_cast<double>(fill_nnz(sorted, a.perm));
  const auto fb = static_cast<double>(fill_nnz(sorted, b.perm));
  EXPECT_LE(fb, 1.15 * fa);
  EXPECT_LE(fa, 1.15 * fb);
}

TEST(NestedDissection, LeafSizeIsRespected) {
  const Graph g = graph_of(generators::laplacian_2d(50, 50));
  for (const index_t leaf : {8, 128, 3000}) {
    const OrderingResult r = nested_dissection(g, {leaf, 1});
    check_tree(g, r);
    for (const auto& node : r.tree.nodes)
      if (node.children.empty()) EXPECT_LE(node.end - node.begin, leaf);
    if (leaf >= g.n) EXPECT_EQ(r.tree.nodes.size(), 1u);
  }
  EXPECT_THROW(nested_dissection(g, {0, 1}), InvalidInput);
  Options o;
  o.nd_leaf_size = 0;
  EXPECT_THROW(compute_ordering(g, o), InvalidInput);
}

// The separators per bisection below the top levels: by default METIS_NodeND's rule (2 on
// a graph that compresses, as a 3-dof mesh's does; 1 on one that does not), else the
// count asked for, which still gives a valid tree and fill close to METIS_NodeND's.
TEST(NestedDissection, SeparatorsPerBisection) {
  const Graph mesh = graph_of(generators::elasticity_3d(10, 10, 10));  // compresses 3x
  const Graph grid = graph_of(generators::laplacian_3d(14, 14, 14));   // does not
  auto with = [](int separators) {
    NestedDissectionOptions o;
    o.leaf_size = 64;
    o.separators = separators;
    return o;
  };
  EXPECT_EQ(nested_dissection(mesh, with(0)).perm, nested_dissection(mesh, with(2)).perm);
  EXPECT_NE(nested_dissection(mesh, with(0)).perm, nested_dissection(mesh, with(1)).perm);
  EXPECT_EQ(nested_dissection(grid, with(0)).perm, nested_dissection(grid, with(1)).perm);
  for (const Graph* g : {&mesh, &grid}) {
    const double rule = static_cast<double>(fill_nnz(*g, nested_dissection(*g, with(0)).perm));
    for (int separators : {1, 3}) {
      const OrderingResult r = nested_dissection(*g, with(separators));
      check_tree(*g, r);
      EXPECT_LE(static_cast<double>(fill_nnz(*g, r.perm)), 1.15 * rule)
          << separators << " separators";
    }
  }
  Options o;
  o.nd_leaf_size = 64;
  o.nd_separators = 1;
  EXPECT_EQ(compute_ordering(mesh, o).perm, nested_dissection(mesh, with(1)).perm);
  o.nd_separators = -1;
  EXPECT_THROW(compute_ordering(mesh, o), InvalidInput);
}

// ---------------------------------------------------------------------------------------
// user and natural orderings

TEST(ComputeOrdering, NaturalAndUser) {
  const Graph g = path_graph(5);
  const auto nat = compute_ordering(g, with_method(OrderingMethod::natural)).perm;
  EXPECT_EQ(nat, (std::vector<index_t>{0, 1, 2, 3, 4}));
  Options o = with_method(OrderingMethod::user);
  o.user_permutation = {4, 2, 0, 1, 3};
  EXPECT_EQ(compute_ordering(g, o).perm, o.user_permutation);
  EXPECT_TRUE(compute_ordering(g, o).tree.empty());
}

std::string user_error(const Graph& g, std::vector<index_t> p) {
  Options o = with_method(OrderingMethod::user);
  o.user_permutation = std::move(p);
  try {
    compute_ordering(g, o);
  } catch (const InvalidInput& e) {
    return e.what();
  }
  return "no exception";
}

TEST(ComputeOrdering, UserPermutationErrors) {
  const Graph g = path_graph(5);
  EXPECT_NE(user_error(g, {0, 1, 2}).find("3 entries, expected 5"), std::string::npos)
      << user_error(g, {0, 1, 2});
  const std::string range = user_error(g, {0, 1, 2, 5, 3});
  EXPECT_NE(range.find("user_permutation[3] = 5"), std::string::npos) << range;
  EXPECT_NE(range.find("out of range"), std::string::npos) << range;
  EXPECT_NE(user_error(g, {0, -1, 2, 3, 4}).find("user_permutation[1] = -1"), std::string::npos);
  const std::string rep = user_error(g, {0, 1, 2, 1, 4});
  EXPECT_NE(rep.find("user_permutation[3] = 1 repeats user_permutation[1]"), std::string::npos)
      << rep;
  EXPECT_EQ(user_error(graph_from_edges(0, {}), {}), "no exception");
}

// ---------------------------------------------------------------------------------------
// report on the large problems (not run by default)

// Pattern of a Matrix Market coordinate file (".gz"); a throwaway reader for this report
// only (strata's reader lives in src/sparse).
SparseMatrix read_pattern_gz(const std::string& path) {
  gzFile f = gzopen(path.c_str(), "rb");
  if (!f) throw std::runtime_error("cannot open " + path);
  std::vector<char> buf(1 << 16);
  auto next_line = [&](std::string& line) {
    line.clear();
    while (gzgets(f, buf.data(), static_cast<int>(buf.size()))) {
      line += buf.data();
      if (!line.empty() && line.back() == '\n') return true;
    }
    return !line.empty();
  };
  std::string line;
  do {
    if (!next_line(line)) throw std::runtime_error("truncated " + path);
  } while (line[0] == '%');
  std::istringstream hdr(line);
  long long m = 0, n = 0, nnz = 0;
  hdr >> m >> n >> nnz;
  std::vector<std::pair<index_t, index_t>> e;
  e.reserve(nnz);
  for (long long k = 0; k < nnz && next_line(line); ++k) {
    long long i = 0, j = 0;
    std::sscanf(line.c_str(), "%lld %lld", &i, &j);
    e.push_back({i - 1, j - 1});
  }
  gzclose(f);
  SparseMatrix a;
  a.n_rows = m;
  a.n_cols = n;
  a.offsets.assign(n + 1, 0);
  for (const auto& [i, j] : e) ++a.offsets[j + 1];
  for (index_t j = 0; j < n; ++j) a.offsets[j + 1] += a.offsets[j];
  a.indices.resize(e.size());
  std::vector<index_t> next(a.offsets.begin(), a.offsets.end() - 1);
  for (const auto& [i, j] : e) a.indices[next[j]++] = i;
  return a;
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Process CPU seconds (the orderings are single-threaded; the machine may be shared).
double cpu_seconds() { return static_cast<double>(std::clock()) / CLOCKS_PER_SEC; }

void report(const Graph& g, const std::string& what, bool with_amd = true) {
  double c0 = cpu_seconds();
  const OrderingResult nd = nested_dissection(g, {});
  const double t_nd = cpu_seconds() - c0;
  c0 = cpu_seconds();
  const auto metis = metis_ordering(g);
  const double t_metis = cpu_seconds() - c0;
  const index_t f_nd = fill_nnz(g, nd.perm), f_metis = fill_nnz(g, metis);
  index_t f_amd = 0;
  double t_amd = 0;
  if (with_amd) {
    c0 = cpu_seconds();
    const auto amd = amd_ordering(g);
    t_amd = cpu_seconds() - c0;
    f_amd = fill_nnz(g, amd);
  }
  std::printf(
      "%-18s n=%-8lld nnz(L): ND %-11lld NodeND %-11lld ratio %.3f  AMD %-11lld | CPU s ND "
      "%.2f NodeND %.2f AMD %.2f | tree nodes %zu\n",
      what.c_str(), static_cast<long long>(g.n), static_cast<long long>(f_nd),
      static_cast<long long>(f_metis), static_cast<double>(f_nd) / static_cast<double>(f_metis),
      static_cast<long long>(f_amd), t_nd, t_metis, t_amd, nd.tree.nodes.size());
  std::fflush(stdout);
}

TEST(Quality, DISABLED_ReportQuality) {
  report(graph_of(generators::laplacian_3d(60, 60, 60)), "7-point 60^3");
  report(graph_of(generators::elasticity_3d(30, 30, 30)), "elasticity 30^3");
  for (const char* name :
       {"bcsstk09", "bcsstk13", "bcsstk16", "ccx_cubef2f3_K", "ccx_segmenttet_K"}) {
    const std::string path = test::matrix_path(name);
    if (!std::filesystem::exists(path)) {
      std::printf("%s: not found\n", path.c_str());
      continue;
    }
    report(graph_of(read_pattern_gz(path)), name);
  }
}

TEST(Quality, DISABLED_ReportLarge) {
  const Graph big = graph_of(generators::laplacian_3d(100, 100, 100));
  const auto t0 = std::chrono::steady_clock::now();
  const double c0 = cpu_seconds();
  const OrderingResult r = nested_dissection(big, {});
  std::printf("7-point 100^3: ND %.2f s wall, %.2f s CPU, %zu tree nodes\n", seconds_since(t0),
              cpu_seconds() - c0, r.tree.nodes.size());
  std::fflush(stdout);
  check_tree(big, r);
  report(big, "7-point 100^3", false);
}

// analyze_with_matching on a general pattern that lost one matched entry A(j, q[j]) (its
// row and column keep others) is refused, naming the entry; on the pattern as analyzed it
// keeps the matching and scaling and orders the pattern as the analysis did.
TEST(AnalysisWithMatching, NeedsEveryMatchedEntry) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {1, 2, 3, 5, 733}) {
    SCOPED_TRACE("n = " + std::to_string(n));
    const SparseMatrix a = test::random_sparse(n, 3, test::RandomKind::general, rng);
    Options o;
    o.type = MatrixType::general;
    const Analysis an = analyze_matrix(a, o);
    const Analysis again = analyze_with_matching(a, an, o);
    EXPECT_TRUE(again.stats.matching_kept);
    EXPECT_FALSE(again.stats.order_kept);
    EXPECT_EQ(again.matching_perm, an.matching_perm);
    EXPECT_EQ(again.row_scaling, an.row_scaling);
    EXPECT_EQ(again.col_scaling, an.col_scaling);
    EXPECT_EQ(again.perm, an.perm);
    // a matched entry (j, q[j]) whose row and column hold other entries
    std::vector<index_t> row_count(n, 0);
    for (index_t i : a.indices) ++row_count[i];
    index_t j = 0;
    while (j < n && (row_count[j] < 2 ||
                     a.offsets[an.matching_perm[j] + 1] - a.offsets[an.matching_perm[j]] < 2))
      ++j;
    if (j == n) continue;  // none (a tiny matrix)
    const index_t col = an.matching_perm[j];
    SparseMatrix lost = a;
    const auto at = std::find(lost.indices.begin() + lost.offsets[col],
                              lost.indices.begin() + lost.offsets[col + 1], j);
    ASSERT_NE(at, lost.indices.begin() + lost.offsets[col + 1]);
    lost.values.erase(lost.values.begin() + (at - lost.indices.begin()));
    lost.indices.erase(at);
    for (index_t k = col + 1; k <= n; ++k) --lost.offsets[k];
    try {
      (void)analyze_with_matching(lost, an, o);
      ADD_FAILURE() << "a pattern without the matched entry was accepted";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find("matched entry (" + std::to_string(j) + ", " +
                                           std::to_string(col) + ")"),
                std::string::npos)
          << e.what();
    }
  }
}

}  // namespace
}  // namespace strata::ordering
