// strata tests — symbolic factorization: elimination tree, postorder, column counts
// (checked exactly against CHOLMOD's cholmod_l_analyze and a dense symbolic elimination),
// the assembly tree (supernodes and relaxed amalgamation, checked against CHOLMOD's
// supernodal analysis; separator blocking; row structures) and the level schedule.
#include <cholmod.h>
#include <gtest/gtest.h>
#include <metis.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cstdint>
#include <numeric>
#include <string>
#include <vector>

#include "analysis/analysis.hpp"
#include "base/timer.hpp"
#include "ordering/graph.hpp"
#include "ordering/ordering.hpp"
#include "sparse/generators.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"
#include "support/test_support.hpp"
#include "symbolic/symbolic.hpp"

namespace strata {
namespace {

using symbolic::AmalgamationOptions;
using symbolic::AssemblyTree;
using symbolic::SymbolicFactorization;

// ---------------------------------------------------------------------------------------
// Helpers
// ---------------------------------------------------------------------------------------

/// Full canonical pattern (no values) of a symmetric matrix, or of A + Aᵀ for a general one.
SparseMatrix symmetric_pattern(const SparseMatrix& a) {
  if (a.storage != Storage::full) {
    SparseMatrix f = expand_symmetric(a);
    f.values.clear();
    return f;
  }
  // A + Aᵀ: put every entry (i, j) at (max, min) of a lower-stored matrix, then expand.
  const SparseMatrix c = canonicalize(a);
  const index_t n = c.n_cols;
  SparseMatrix low;
  low.n_rows = low.n_cols = n;
  low.storage = Storage::lower;
  low.offsets.assign(n + 1, 0);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p)
      ++low.offsets[std::min(c.indices[p], j) + 1];
  for (index_t j = 0; j < n; ++j) low.offsets[j + 1] += low.offsets[j];
  low.indices.resize(low.offsets[n]);
  std::vector<index_t> next(low.offsets.begin(), low.offsets.end() - 1);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p)
      low.indices[next[std::min(c.indices[p], j)]++] = std::max(c.indices[p], j);
  return expand_symmetric(low);
}

std::vector<index_t> identity(index_t n) {
  std::vector<index_t> p(n);
  std::iota(p.begin(), p.end(), 0);
  return p;
}

/// METIS_NodeND fill-reducing permutation (new→old) of a full symmetric pattern.
std::vector<index_t> metis_order(const SparseMatrix& full) {
  const index_t n = full.n_cols;
  std::vector<idx_t> xadj(n + 1, 0), adj;
  for (index_t j = 0; j < n; ++j) {
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] != j) adj.push_back(static_cast<idx_t>(full.indices[p]));
    xadj[j + 1] = static_cast<idx_t>(adj.size());
  }
  if (n <= 2 || adj.empty()) return identity(n);
  idx_t nv = static_cast<idx_t>(n);
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  std::vector<idx_t> perm(n), iperm(n);
  const int rc =
      METIS_NodeND(&nv, xadj.data(), adj.data(), nullptr, options, perm.data(), iperm.data());
  EXPECT_EQ(rc, METIS_OK);
  return std::vector<index_t>(perm.begin(), perm.end());
}

std::vector<index_t> random_order(index_t n, std::mt19937_64& rng) {
  std::vector<index_t> p = identity(n);
  std::shuffle(p.begin(), p.end(), rng);
  return p;
}

/// CHOLMOD's column counts of L for a full symmetric pattern, in its own numbering
/// (natural ordering, no postorder), and CHOLMOD's nnz(L).
struct CholmodCounts {
  std::vector<index_t> colcount;
  double lnz = 0;
  double fl = 0;  ///< CHOLMOD's flop count of the factorization
};

CholmodCounts cholmod_counts(const SparseMatrix& full) {
  const index_t n = full.n_cols;
  CholmodCounts out;
  if (n == 0) return out;
  cholmod_common c;
  cholmod_l_start(&c);
  c.nmethods = 1;
  c.method[0].ordering = CHOLMOD_NATURAL;
  c.postorder = 0;
  c.supernodal = CHOLMOD_SIMPLICIAL;
  index_t nzl = 0;
  for (index_t j = 0; j < n; ++j)
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) ++nzl;
  cholmod_sparse* a =
      cholmod_l_allocate_sparse(n, n, std::max<index_t>(nzl, 1), 1, 1, -1, CHOLMOD_PATTERN, &c);
  auto* ap = static_cast<SuiteSparse_long*>(a->p);
  auto* ai = static_cast<SuiteSparse_long*>(a->i);
  index_t w = 0;
  for (index_t j = 0; j < n; ++j) {
    ap[j] = w;
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) ai[w++] = full.indices[p];
  }
  ap[n] = w;
  cholmod_factor* l = cholmod_l_analyze(a, &c);
  EXPECT_NE(l, nullptr) << "cholmod_l_analyze failed, status " << c.status;
  if (l) {
    auto* cc = static_cast<SuiteSparse_long*>(l->ColCount);
    out.colcount.assign(cc, cc + n);
    out.lnz = c.lnz;
    out.fl = c.fl;
    auto* perm = static_cast<SuiteSparse_long*>(l->Perm);
    for (index_t k = 0; k < n; ++k) EXPECT_EQ(perm[k], k) << "CHOLMOD permuted the matrix";
    cholmod_l_free_factor(&l, &c);
  }
  cholmod_l_free_sparse(&a, &c);
  cholmod_l_finish(&c);
  return out;
}

/// CHOLMOD's supernode partition (first column of each supernode, then n) of a full
/// symmetric pattern analysed in its natural order, with CHOLMOD's default relaxation.
std::vector<index_t> cholmod_supernodes(const SparseMatrix& full) {
  const index_t n = full.n_cols;
  cholmod_common c;
  cholmod_l_start(&c);
  c.nmethods = 1;
  c.method[0].ordering = CHOLMOD_NATURAL;
  c.postorder = 0;
  c.supernodal = CHOLMOD_SUPERNODAL;
  index_t nzl = 0;
  for (index_t j = 0; j < n; ++j)
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) ++nzl;
  cholmod_sparse* a =
      cholmod_l_allocate_sparse(n, n, std::max<index_t>(nzl, 1), 1, 1, -1, CHOLMOD_PATTERN, &c);
  auto* ap = static_cast<SuiteSparse_long*>(a->p);
  auto* ai = static_cast<SuiteSparse_long*>(a->i);
  index_t w = 0;
  for (index_t j = 0; j < n; ++j) {
    ap[j] = w;
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) ai[w++] = full.indices[p];
  }
  ap[n] = w;
  std::vector<index_t> out;
  cholmod_factor* l = cholmod_l_analyze(a, &c);
  EXPECT_NE(l, nullptr);
  if (l) {
    EXPECT_TRUE(l->is_super);
    auto* super = static_cast<SuiteSparse_long*>(l->super);
    out.assign(super, super + l->nsuper + 1);
    cholmod_l_free_factor(&l, &c);
  }
  cholmod_l_free_sparse(&a, &c);
  cholmod_l_finish(&c);
  return out;
}

/// With CHOLMOD's default relaxation and no blocking, the fronts are exactly CHOLMOD's
/// relaxed supernodes. CHOLMOD finds supernodes in the order it is given, so it gets the
/// pattern permuted by our postorder (its own postorder is off).
void expect_cholmod_supernodes(const SparseMatrix& b, const std::vector<index_t>& post) {
  AmalgamationOptions o;  // CHOLMOD's nrelax / zrelax defaults
  o.max_block_size = 0;
  const SparseMatrix bp = symbolic::permute_symmetric_pattern(b, post);
  const SymbolicFactorization sf = symbolic::analyze_pattern(bp, o);
  EXPECT_EQ(sf.post, identity(b.n_cols)) << "a postordered pattern is its own postorder";
  if (b.n_cols > 0) {
    const std::vector<index_t> cs = cholmod_supernodes(bp);
    EXPECT_EQ(sf.tree.first_pivot, cs);
  }
}

/// Reference symbolic factorization by dense (bitset) elimination: the structure of
/// L(:, j) is A(j+1:n, j) plus the structures of the columns whose first off-diagonal
/// row is j. O(n²/64) memory: for n up to a few thousand.
struct DenseSymbolic {
  std::vector<index_t> parent;
  std::vector<index_t> colcount;
  std::vector<std::vector<index_t>> below;  // rows of L(:, j) below the diagonal, sorted
};

DenseSymbolic dense_symbolic(const SparseMatrix& full) {
  const index_t n = full.n_cols;
  const index_t words = (n + 63) / 64;
  std::vector<std::uint64_t> bits(static_cast<std::size_t>(n * words), 0);
  auto col = [&](index_t j) { return bits.data() + j * words; };
  for (index_t j = 0; j < n; ++j)
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p) {
      const index_t i = full.indices[p];
      if (i > j) col(j)[i / 64] |= std::uint64_t{1} << (i % 64);
    }
  DenseSymbolic r;
  r.parent.assign(n, -1);
  r.colcount.assign(n, 1);
  r.below.resize(n);
  for (index_t j = 0; j < n; ++j) {
    std::uint64_t* cj = col(j);
    for (index_t w = j / 64; w < words; ++w)
      for (std::uint64_t b = cj[w]; b; b &= b - 1)
        r.below[j].push_back(w * 64 + __builtin_ctzll(b));
    r.colcount[j] += static_cast<index_t>(r.below[j].size());
    if (r.below[j].empty()) continue;
    const index_t p = r.below[j].front();
    r.parent[j] = p;
    std::uint64_t* cp = col(p);
    for (index_t w = j / 64; w < words; ++w) cp[w] |= cj[w];
    cp[p / 64] &= ~(std::uint64_t{1} << (p % 64));
  }
  return r;
}

/// Elimination tree the slow way: for every entry A(i, k), i < k, climb from i without
/// path compression to the root of its current subtree and hang it below k.
std::vector<index_t> naive_etree(const SparseMatrix& full) {
  const index_t n = full.n_cols;
  std::vector<index_t> parent(n, -1);
  for (index_t k = 0; k < n; ++k)
    for (index_t p = full.offsets[k]; p < full.offsets[k + 1]; ++p) {
      index_t r = full.indices[p];
      if (r >= k) continue;
      while (parent[r] != -1 && parent[r] != k) r = parent[r];
      if (parent[r] == -1) parent[r] = k;
    }
  return parent;
}

/// post is a postorder of parent: a permutation, children before parents, and every
/// subtree a contiguous range ending at its root.
void expect_valid_postorder(const std::vector<index_t>& parent, const std::vector<index_t>& post) {
  const index_t n = static_cast<index_t>(parent.size());
  ASSERT_EQ(static_cast<index_t>(post.size()), n);
  std::vector<index_t> ipost(n, -1);
  for (index_t k = 0; k < n; ++k) {
    ASSERT_GE(post[k], 0);
    ASSERT_LT(post[k], n);
    ASSERT_EQ(ipost[post[k]], -1) << "repeated node " << post[k];
    ipost[post[k]] = k;
  }
  std::vector<index_t> size(n, 1);
  for (index_t k = 0; k < n; ++k) {
    const index_t j = post[k];
    if (parent[j] != -1) size[parent[j]] += size[j];
  }
  for (index_t j = 0; j < n; ++j) {
    if (parent[j] == -1) continue;
    const index_t p = parent[j];
    EXPECT_LT(ipost[j], ipost[p]);
    // j's range [ipost[j]-size[j]+1, ipost[j]] lies inside p's range below p.
    EXPECT_GE(ipost[j] - size[j] + 1, ipost[p] - size[p] + 1);
  }
}

index_t front_l_entries(const AssemblyTree& t, index_t f) {
  const index_t np = t.n_pivots(f), nr = t.n_rows(f);
  return np * nr - np * (np - 1) / 2;
}

/// Every invariant of the assembly tree. `ref` (optional) is the dense symbolic
/// factorization of the same input pattern; `exact` asks for fronts without amalgamation
/// zeros (relaxation disabled).
void check_tree(const SparseMatrix& full, const SymbolicFactorization& sf,
                const AmalgamationOptions& opts, const DenseSymbolic* ref, bool exact) {
  const AssemblyTree& t = sf.tree;
  const index_t n = full.n_cols;
  const index_t nf = t.n_fronts();
  ASSERT_EQ(t.n, n);
  ASSERT_EQ(static_cast<index_t>(t.first_pivot.size()), nf + 1);
  ASSERT_EQ(static_cast<index_t>(t.row_offsets.size()), nf + 1);
  ASSERT_EQ(static_cast<index_t>(t.child_offsets.size()), nf + 1);
  ASSERT_EQ(static_cast<index_t>(t.front_of_column.size()), n);
  ASSERT_EQ(t.first_pivot.front(), 0);
  ASSERT_EQ(t.first_pivot.back(), n);
  ASSERT_EQ(t.row_offsets.back(), static_cast<index_t>(t.rows.size()));
  index_t l_entries = 0;
  for (index_t f = 0; f < nf; ++f) {
    ASSERT_GT(t.n_pivots(f), 0) << "front " << f;
    if (opts.max_block_size > 0) EXPECT_LE(t.n_pivots(f), opts.max_block_size);
    for (index_t j = t.first_pivot[f]; j < t.first_pivot[f + 1]; ++j)
      ASSERT_EQ(t.front_of_column[j], f);
    ASSERT_GE(t.n_rows(f), t.n_pivots(f));
    const index_t* r = t.rows_of(f);
    for (index_t k = 0; k < t.n_pivots(f); ++k) ASSERT_EQ(r[k], t.first_pivot[f] + k);
    for (index_t k = 1; k < t.n_rows(f); ++k) ASSERT_LT(r[k - 1], r[k]) << "front " << f;
    if (t.n_rows(f) > 0) ASSERT_LT(r[t.n_rows(f) - 1], n);
    ASSERT_TRUE(t.parent[f] == -1 || t.parent[f] > f) << "front " << f;
    if (t.parent[f] == -1) EXPECT_EQ(t.cb_size(f), 0) << "a root passes nothing up";
    l_entries += front_l_entries(t, f);
  }
  // Children lists mirror parent[], in increasing order.
  index_t nchildren = 0;
  for (index_t f = 0; f < nf; ++f) {
    for (index_t c = t.child_offsets[f]; c < t.child_offsets[f + 1]; ++c) {
      EXPECT_EQ(t.parent[t.children[c]], f);
      if (c > t.child_offsets[f]) EXPECT_LT(t.children[c - 1], t.children[c]);
    }
    nchildren += t.child_offsets[f + 1] - t.child_offsets[f];
  }
  index_t nonroots = 0;
  for (index_t f = 0; f < nf; ++f) nonroots += t.parent[f] != -1;
  EXPECT_EQ(nchildren, nonroots);
  // Fronts are numbered in postorder.
  expect_valid_postorder(t.parent, identity(nf));
  // A child's contribution rows lie in its parent's rows.
  std::vector<index_t> mark(n, -1);
  for (index_t f = 0; f < nf; ++f) {
    if (t.parent[f] == -1) continue;
    const index_t p = t.parent[f];
    for (index_t k = 0; k < t.n_rows(p); ++k) mark[t.rows_of(p)[k]] = f;
    for (index_t k = t.n_pivots(f); k < t.n_rows(f); ++k)
      ASSERT_EQ(mark[t.rows_of(f)[k]], f)
          << "row " << t.rows_of(f)[k] << " of front " << f << " missing from parent " << p;
  }
  // Exact counts: without amalgamation every pivot column of a front holds exactly the
  // rows of L's column.
  EXPECT_GE(l_entries, sf.nnz_l);
  if (exact) {
    EXPECT_EQ(l_entries, sf.nnz_l);
    double front_total = 0, column_total = 0;
    for (index_t f = 0; f < nf; ++f) front_total += symbolic::front_flops(t, f);
    for (index_t c : sf.colcount) column_total += static_cast<double>(c) * static_cast<double>(c);
    EXPECT_EQ(front_total, column_total);
    for (index_t f = 0; f < nf; ++f)
      for (index_t k = 0; k < t.n_pivots(f); ++k)
        ASSERT_EQ(sf.colcount[sf.post[t.first_pivot[f] + k]], t.n_rows(f) - k);
  }
  // The rows of each L(:, j) lie in the rows of j's front (tree numbering: column k of
  // the tree is input column post[k]).
  if (ref) {
    std::vector<index_t> ipost(n);
    for (index_t k = 0; k < n; ++k) ipost[sf.post[k]] = k;
    std::fill(mark.begin(), mark.end(), -1);
    for (index_t f = 0; f < nf; ++f) {
      for (index_t k = 0; k < t.n_rows(f); ++k) mark[t.rows_of(f)[k]] = f;
      for (index_t k = t.first_pivot[f]; k < t.first_pivot[f + 1]; ++k)
        for (index_t r : ref->below[sf.post[k]]) {
          ASSERT_GT(ipost[r], k);
          ASSERT_EQ(mark[ipost[r]], f) << "L(" << ipost[r] << ", " << k << ") not in front " << f;
        }
    }
  }
}

void check_schedule(const AssemblyTree& t, const symbolic::LevelSchedule& s) {
  const index_t nf = t.n_fronts();
  ASSERT_EQ(static_cast<index_t>(s.fronts.size()), nf);
  ASSERT_EQ(static_cast<index_t>(s.level_of.size()), nf);
  ASSERT_EQ(s.level_offsets.front(), 0);
  ASSERT_EQ(s.level_offsets.back(), nf);
  std::vector<int> seen(nf, 0);
  for (index_t l = 0; l < s.n_levels(); ++l) {
    EXPECT_LT(s.level_offsets[l], s.level_offsets[l + 1]) << "empty level " << l;
    for (index_t p = s.level_offsets[l]; p < s.level_offsets[l + 1]; ++p) {
      ASSERT_EQ(s.level_of[s.fronts[p]], l);
      ++seen[s.fronts[p]];
    }
  }
  for (index_t f = 0; f < nf; ++f) {
    EXPECT_EQ(seen[f], 1) << "front " << f;
    if (t.parent[f] != -1)
      EXPECT_LT(s.level_of[f], s.level_of[t.parent[f]]);
    else
      EXPECT_EQ(s.level_of[f], s.n_levels() - 1) << "roots have depth 0";
  }
  // Independence: no front of a level is an ancestor of another front of that level.
  // Every proper ancestor of f is on a strictly higher level, so it suffices that levels
  // strictly increase along parents, checked above; verify it directly on small trees.
  if (nf <= 2000)
    for (index_t f = 0; f < nf; ++f)
      for (index_t a = t.parent[f]; a != -1; a = t.parent[a])
        ASSERT_NE(s.level_of[a], s.level_of[f]);
}

/// Symbolic analysis of P·pattern·Pᵀ with every check: etree and postorder against
/// references, colcounts against CHOLMOD (and the dense reference when small), the tree
/// invariants for a few amalgamation settings, and the level schedule.
void check_all(const SparseMatrix& pattern, const std::vector<index_t>& perm,
               const std::string& what) {
  SCOPED_TRACE(what);
  const SparseMatrix b = symbolic::permute_symmetric_pattern(pattern, perm);
  const index_t n = b.n_cols;
  const std::vector<index_t> parent = symbolic::elimination_tree(b);
  EXPECT_EQ(parent, naive_etree(b));
  const std::vector<index_t> post = symbolic::postorder(parent);
  expect_valid_postorder(parent, post);
  const std::vector<index_t> cc = symbolic::column_counts(b, parent, post);

  DenseSymbolic ref;
  const bool small = n <= 4000;
  if (small) {
    ref = dense_symbolic(b);
    EXPECT_EQ(parent, ref.parent);
    EXPECT_EQ(cc, ref.colcount);
  }
  const CholmodCounts chol = cholmod_counts(b);
  EXPECT_EQ(cc, chol.colcount);
  const index_t nnz_l = std::accumulate(cc.begin(), cc.end(), index_t{0});
  EXPECT_EQ(static_cast<double>(nnz_l), chol.lnz);
  double flops = 0;  // the convention of front_flops: Σ_j c_j²
  for (index_t c : cc) flops += static_cast<double>(c) * static_cast<double>(c);
  EXPECT_EQ(flops, chol.fl);
  expect_cholmod_supernodes(b, post);

  AmalgamationOptions none;
  none.relax_small = 1;
  none.relax_zeros_1 = none.relax_zeros_2 = none.relax_zeros_3 = 0;
  none.max_block_size = 0;
  AmalgamationOptions defaults;
  struct Case {
    AmalgamationOptions o;
    bool exact;
  };
  std::vector<Case> cases{{none, true}, {defaults, false}};
  for (index_t mbs : {index_t{8}, index_t{32}, n + 1}) {
    AmalgamationOptions o = defaults;
    o.max_block_size = mbs;
    cases.push_back({o, false});
    o = none;
    o.max_block_size = mbs;
    cases.push_back({o, true});
  }
  // analyze_permuted_graph reads the unpermuted pattern through perm, with each column's
  // rows in any order: here reversed and rotated, so not sorted
  SparseMatrix shuffled = expand_symmetric(pattern);
  for (index_t j = 0; j < n; ++j) {
    const auto first = shuffled.indices.begin() + shuffled.offsets[j];
    const auto last = shuffled.indices.begin() + shuffled.offsets[j + 1];
    std::reverse(first, last);
    if (last - first > 2) std::rotate(first, first + 1, last);
  }
  for (const Case& c : cases) {
    SCOPED_TRACE("relax_small " + std::to_string(c.o.relax_small) + ", max_block_size " +
                 std::to_string(c.o.max_block_size));
    const SymbolicFactorization sf = symbolic::analyze_pattern(b, c.o);
    EXPECT_EQ(sf.parent, parent);
    EXPECT_EQ(sf.post, post);
    EXPECT_EQ(sf.colcount, cc);
    EXPECT_EQ(sf.nnz_l, nnz_l);
    check_tree(b, sf, c.o, small ? &ref : nullptr, c.exact);
    check_schedule(sf.tree, symbolic::level_schedule(sf.tree));
    const SymbolicFactorization g =
        symbolic::analyze_permuted_graph(n, shuffled.offsets, shuffled.indices.data(), perm, c.o);
    EXPECT_EQ(g.parent, sf.parent);
    EXPECT_EQ(g.post, sf.post);
    EXPECT_EQ(g.colcount, sf.colcount);
    EXPECT_EQ(g.nnz_l, sf.nnz_l);
    EXPECT_EQ(g.tree.first_pivot, sf.tree.first_pivot);
    EXPECT_EQ(g.tree.row_offsets, sf.tree.row_offsets);
    EXPECT_EQ(g.tree.rows, sf.tree.rows);
    EXPECT_EQ(g.tree.parent, sf.tree.parent);
    EXPECT_EQ(g.tree.child_offsets, sf.tree.child_offsets);
    EXPECT_EQ(g.tree.children, sf.tree.children);
    EXPECT_EQ(g.tree.front_of_column, sf.tree.front_of_column);
    if (::testing::Test::HasFatalFailure()) return;
  }
}

// ---------------------------------------------------------------------------------------
// Tests
// ---------------------------------------------------------------------------------------

TEST(Etree, EmptyAndTiny) {
  SparseMatrix empty;
  EXPECT_TRUE(symbolic::elimination_tree(empty).empty());
  EXPECT_TRUE(symbolic::postorder({}).empty());
  const SymbolicFactorization sf = symbolic::analyze_pattern(empty, {});
  EXPECT_EQ(sf.tree.n_fronts(), 0);
  EXPECT_EQ(sf.nnz_l, 0);
  EXPECT_EQ(symbolic::level_schedule(sf.tree).n_levels(), 0);
}

TEST(Etree, PostorderOfAForest) {
  // Two trees: 4 <- {0, 3}, 3 <- {1, 2}; 6 <- 5.
  const std::vector<index_t> parent{4, 3, 3, 4, -1, 6, -1};
  const std::vector<index_t> post = symbolic::postorder(parent);
  EXPECT_EQ(post, (std::vector<index_t>{0, 1, 2, 3, 4, 5, 6}));
  const std::vector<index_t> parent2{-1, 0, 0, 1};  // 0 <- {1, 2}, 1 <- 3
  EXPECT_EQ(symbolic::postorder(parent2), (std::vector<index_t>{3, 1, 2, 0}));
  EXPECT_THROW(symbolic::postorder({1, 0}), InvalidInput);
}

TEST(Symbolic, RandomPatterns) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {1, 2, 3, 5, 17, 733})
    for (test::RandomKind kind :
         {test::RandomKind::spd, test::RandomKind::symmetric_indefinite, test::RandomKind::general})
      for (index_t per : {1, 3}) {
        const SparseMatrix pattern = symmetric_pattern(test::random_sparse(n, per, kind, rng));
        const std::string what = "n " + std::to_string(n) + " kind " +
                                 std::to_string(static_cast<int>(kind)) + " per " +
                                 std::to_string(per);
        check_all(pattern, identity(n), what + " natural");
        check_all(pattern, random_order(n, rng), what + " random order");
        check_all(pattern, metis_order(pattern), what + " metis");
        if (HasFatalFailure()) return;
      }
}

TEST(Symbolic, AwkwardSizesAgainstCholmod) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {4, 63, 64, 65, 127, 1000, 2049})
    for (index_t per : {0, 1, 2, 5}) {
      const SparseMatrix pattern =
          symmetric_pattern(test::random_sparse(n, per, test::RandomKind::general, rng));
      check_all(pattern, metis_order(pattern),
                "n " + std::to_string(n) + " per " + std::to_string(per));
      if (HasFatalFailure()) return;
    }
}

TEST(Symbolic, Grids) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  struct Grid {
    std::string name;
    SparseMatrix a;
  };
  const std::vector<Grid> grids{
      {"2d 1x1", generators::laplacian_2d(1, 1)},
      {"2d 1x50", generators::laplacian_2d(1, 50)},
      {"2d 7x9", generators::laplacian_2d(7, 9)},
      {"2d 40x33", generators::laplacian_2d(40, 33)},
      {"2d 100x100", generators::laplacian_2d(100, 100)},
      {"3d 5x6x7", generators::laplacian_3d(5, 6, 7)},
      {"3d 15x15x15", generators::laplacian_3d(15, 15, 15)},
      {"3d 24x20x22", generators::laplacian_3d(24, 20, 22)},
      {"elasticity 3x3x3", generators::elasticity_3d(3, 3, 3)},
      {"elasticity 8x7x6", generators::elasticity_3d(8, 7, 6)},
  };
  for (const Grid& g : grids) {
    const SparseMatrix pattern = symmetric_pattern(g.a);
    const index_t n = pattern.n_cols;
    if (n <= 4000) check_all(pattern, identity(n), g.name + " natural");
    check_all(pattern, metis_order(pattern), g.name + " metis");
    if (n <= 1000) check_all(pattern, random_order(n, rng), g.name + " random order");
    if (HasFatalFailure()) return;
  }
}

TEST(Symbolic, FundamentalSupernodesAndRelaxation) {
  // Tridiagonal, natural order: the etree is a path; column counts 2, ..., 2, 1.
  const index_t n = 50;
  const SparseMatrix pattern = symmetric_pattern(generators::laplacian_2d(n, 1));
  AmalgamationOptions none;
  none.relax_small = 1;
  none.relax_zeros_1 = none.relax_zeros_2 = none.relax_zeros_3 = 0;
  none.max_block_size = 0;
  SymbolicFactorization sf = symbolic::analyze_pattern(pattern, none);
  // Only the last two columns form a fundamental supernode.
  EXPECT_EQ(sf.tree.n_fronts(), n - 1);
  EXPECT_EQ(sf.nnz_l, 2 * n - 1);
  EXPECT_EQ(symbolic::level_schedule(sf.tree).n_levels(), n - 1);
  // Merging everything: one front of n pivots and n rows.
  AmalgamationOptions all = none;
  all.relax_small = n;
  sf = symbolic::analyze_pattern(pattern, all);
  ASSERT_EQ(sf.tree.n_fronts(), 1);
  EXPECT_EQ(sf.tree.n_rows(0), n);
  // ... and blocked into a chain of 8-pivot fronts, the remainder on top.
  all.max_block_size = 8;
  sf = symbolic::analyze_pattern(pattern, all);
  ASSERT_EQ(sf.tree.n_fronts(), (n + 7) / 8);
  for (index_t f = 0; f + 1 < sf.tree.n_fronts(); ++f) {
    EXPECT_EQ(sf.tree.n_pivots(f), 8);
    EXPECT_EQ(sf.tree.parent[f], f + 1);
    // Rows are the union of the piece's structures, not the merged front's dense
    // suffix: the pivots plus the next column.
    EXPECT_EQ(sf.tree.n_rows(f), 9);
  }
  EXPECT_EQ(sf.tree.n_pivots(sf.tree.n_fronts() - 1), n % 8);
  // Default relaxation: far fewer fronts.
  sf = symbolic::analyze_pattern(pattern, AmalgamationOptions{});
  EXPECT_LT(sf.tree.n_fronts(), n / 4);
}

TEST(Symbolic, RelaxationRuleOnAStar) {
  // An arrow matrix: n-1 leaves all coupled to the last column only. Each leaf is a
  // fundamental supernode of 1 pivot and 2 rows; the root (n-1 children) has 1 pivot.
  // Only the last child of a front can merge into it (CHOLMOD's rule: the parent must
  // start right after the child, so pivots stay contiguous).
  const index_t n = 10;
  SparseMatrix low;
  low.n_rows = low.n_cols = n;
  low.storage = Storage::lower;
  low.offsets.assign(1, 0);
  for (index_t j = 0; j < n; ++j) {
    low.indices.push_back(j);
    if (j + 1 < n) low.indices.push_back(n - 1);
    low.offsets.push_back(static_cast<index_t>(low.indices.size()));
  }
  const SparseMatrix pattern = symmetric_pattern(low);
  // Relaxation off: the last leaf still merges, as [8, 9] is dense (no zeros added);
  // leaf 7 would add the zero L(8, 7).
  AmalgamationOptions none;
  none.relax_small = 1;
  none.relax_zeros_1 = none.relax_zeros_2 = none.relax_zeros_3 = 0;
  SymbolicFactorization sf = symbolic::analyze_pattern(pattern, none);
  ASSERT_EQ(sf.tree.n_fronts(), n - 1);
  const symbolic::LevelSchedule s = symbolic::level_schedule(sf.tree);
  ASSERT_EQ(s.n_levels(), 2);
  EXPECT_EQ(s.level_offsets[1] - s.level_offsets[0], n - 2);    // the leaves, in one level
  EXPECT_EQ(symbolic::front_flops(sf.tree, 0), 4.0);            // 1 pivot, 2 rows
  EXPECT_EQ(symbolic::front_flops(sf.tree, n - 2), 4.0 + 1.0);  // {8, 9}: rows 2, 1
  // relax_small 3 merges leaf 7 for its size ({7, 8, 9}, one true zero). With a zero
  // threshold of 0.25, leaf 6 then merges only because, as in CHOLMOD, the zero of the
  // size-only merge is not counted: 2 new zeros / 10 entries = 0.2 (3 / 10 counting
  // it). Leaf 5 would make 2 + 3 zeros of 15: 0.33, no merge.
  AmalgamationOptions small = none;
  small.relax_small = 3;
  small.relax_zeros_1 = small.relax_zeros_2 = small.relax_zeros_3 = 0.25;
  sf = symbolic::analyze_pattern(pattern, small);
  ASSERT_EQ(sf.tree.n_fronts(), n - 3);
  EXPECT_EQ(sf.tree.first_pivot[n - 4], 6);
  EXPECT_EQ(sf.tree.n_rows(n - 4), 4);
}

TEST(Symbolic, FrontFlops) {
  // 2 pivots, 5 rows: 5² + 4².
  const index_t n = 5;
  SparseMatrix low;
  low.n_rows = low.n_cols = n;
  low.storage = Storage::lower;
  for (index_t j = 0; j < n; ++j) {
    for (index_t i = j; i < n; ++i) low.indices.push_back(i);
    low.offsets.push_back(static_cast<index_t>(low.indices.size()));
  }
  AmalgamationOptions o;
  o.max_block_size = 2;
  const SymbolicFactorization sf = symbolic::analyze_pattern(symmetric_pattern(low), o);
  ASSERT_EQ(sf.tree.n_fronts(), 3);
  EXPECT_EQ(symbolic::front_flops(sf.tree, 0), 25.0 + 16.0);
  EXPECT_EQ(symbolic::front_flops(sf.tree, 1), 9.0 + 4.0);
  EXPECT_EQ(symbolic::front_flops(sf.tree, 2), 1.0);
}

TEST(Symbolic, PermuteSymmetricPattern) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const index_t n = 57;
  const SparseMatrix a = test::random_sparse(n, 3, test::RandomKind::spd, rng);
  const std::vector<index_t> perm = random_order(n, rng);
  const SparseMatrix b = symbolic::permute_symmetric_pattern(a, perm);  // lower is expanded
  const SparseMatrix full = symmetric_pattern(a);
  EXPECT_EQ(b.nnz(), full.nnz());
  EXPECT_EQ(b.storage, Storage::full);
  std::vector<char> dense(n * n, 0);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      dense[full.indices[p] + n * j] = 1;
  for (index_t c = 0; c < n; ++c)
    for (index_t p = b.offsets[c]; p < b.offsets[c + 1]; ++p) {
      if (p > b.offsets[c]) EXPECT_LT(b.indices[p - 1], b.indices[p]);
      EXPECT_TRUE(dense[perm[b.indices[p]] + n * perm[c]]);
    }
  EXPECT_THROW(symbolic::permute_symmetric_pattern(a, identity(n - 1)), InvalidInput);
  std::vector<index_t> bad = identity(n);
  bad[3] = 4;
  EXPECT_THROW(symbolic::permute_symmetric_pattern(a, bad), InvalidInput);
}

// The fronts' row structures are walked in ranges of rows over the arena's threads: the
// same tree and rows on 1, 2, 3 and 4 threads, for a grid in a random order (many short
// row subtrees) and in its nested-dissection order (long ones), with sizes that do not
// split evenly.
TEST(Symbolic, RowStructuresSameOnAnyThreadCount) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const SparseMatrix grid = symmetric_pattern(generators::laplacian_3d(29, 23, 31));
  const index_t n = grid.n_cols;
  Options o;
  o.ordering = OrderingMethod::nested_dissection;
  const std::vector<index_t> nd = compute_ordering(ordering::graph_of(grid), o).perm;
  for (const auto& perm : {random_order(n, rng), nd}) {
    const SparseMatrix b = symbolic::permute_symmetric_pattern(grid, perm);
    auto on = [&](int threads) {
      tbb::task_arena arena(threads);
      return arena.execute([&] { return symbolic::analyze_pattern(b, {}); });
    };
    const symbolic::SymbolicFactorization one = on(1);
    for (const int threads : {2, 3, 4}) {
      const symbolic::SymbolicFactorization r = on(threads);
      EXPECT_EQ(r.tree.first_pivot, one.tree.first_pivot) << threads << " threads";
      EXPECT_EQ(r.tree.parent, one.tree.parent);
      EXPECT_EQ(r.tree.row_offsets, one.tree.row_offsets);
      EXPECT_EQ(r.tree.rows, one.tree.rows);
      EXPECT_EQ(r.nnz_l, one.nnz_l);
    }
  }
}

TEST(Symbolic, RejectsUnsymmetricPattern) {
  // A(2, 0) without A(0, 2): the upper triangle says column 2 is a root of its own.
  SparseMatrix a;
  a.n_rows = a.n_cols = 3;
  a.offsets = {0, 2, 3, 4};
  a.indices = {0, 2, 1, 2};
  EXPECT_THROW(symbolic::analyze_pattern(a, {}), InvalidInput);
}

// AmalgamationOptions::keep_with_next (2×2 pivot pairs of symmetric indefinite matrices,
// Duff & Pralet 2005): a flagged column j of the input has j+1 as its etree parent, comes
// right before it in the postorder and shares its front, whatever the relaxation and the
// block size; the tree keeps every invariant.
TEST(Symbolic, KeepWithNextHoldsPairsInOneFront) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {2, 9, 60, 700}) {
    SCOPED_TRACE("n=" + std::to_string(n));
    const SparseMatrix pattern =
        symmetric_pattern(test::random_sparse(n, 3, test::RandomKind::spd, rng));
    const SparseMatrix b = symbolic::permute_symmetric_pattern(pattern, random_order(n, rng));
    // flag about half of the columns j with an entry (j+1, j); `chains` allows flags on
    // consecutive columns (groups of 3 and more)
    auto has_entry = [&](index_t i, index_t j) {
      return std::binary_search(b.indices.begin() + b.offsets[j],
                                b.indices.begin() + b.offsets[j + 1], i);
    };
    for (bool chains : {false, true}) {
      std::vector<char> keep(n, 0);
      std::bernoulli_distribution coin(0.5);
      index_t flagged = 0;
      for (index_t j = 0; j + 1 < n; ++j)
        if (has_entry(j + 1, j) && coin(rng) && (chains || j == 0 || !keep[j - 1])) {
          keep[j] = 1;
          ++flagged;
        }
      // the coin can flag none of the few candidates of a small order (n = 60 has about
      // six after the random permutation): flag the first candidate then, so that every
      // order with a candidate exercises the pairing
      for (index_t j = 0; flagged == 0 && j + 1 < n; ++j)
        if (has_entry(j + 1, j)) {
          keep[j] = 1;
          ++flagged;
        }
      if (n >= 700) EXPECT_GT(flagged, 0);
      AmalgamationOptions none;
      none.relax_small = 1;
      none.relax_zeros_1 = none.relax_zeros_2 = none.relax_zeros_3 = 0;
      none.max_block_size = 0;
      for (index_t mbs : {index_t{0}, index_t{1}, index_t{2}, index_t{3}, index_t{8}}) {
        for (bool relax : {false, true}) {
          SCOPED_TRACE("chains " + std::to_string(chains) + " max_block_size " +
                       std::to_string(mbs) + " relax " + std::to_string(relax));
          AmalgamationOptions o = relax ? AmalgamationOptions{} : none;
          o.max_block_size = mbs;
          const SymbolicFactorization plain = symbolic::analyze_pattern(b, o);
          o.keep_with_next = keep;
          const SymbolicFactorization sf = symbolic::analyze_pattern(b, o);
          EXPECT_EQ(sf.parent, plain.parent);
          EXPECT_EQ(sf.post, plain.post);
          EXPECT_EQ(sf.nnz_l, plain.nnz_l);
          std::vector<index_t> ipost(n);
          for (index_t k = 0; k < n; ++k) ipost[sf.post[k]] = k;
          index_t longest_chain = 1, run = 1;
          for (index_t j = 0; j + 1 < n; ++j) {
            run = keep[j] ? run + 1 : 1;
            longest_chain = std::max(longest_chain, run);
            if (!keep[j]) continue;
            ASSERT_EQ(sf.parent[j], j + 1);
            ASSERT_EQ(ipost[j + 1], ipost[j] + 1);
            EXPECT_EQ(sf.tree.front_of_column[ipost[j]], sf.tree.front_of_column[ipost[j + 1]])
                << "pair (" << j << ", " << j + 1 << ") split across fronts";
          }
          // check_tree asserts n_pivots ≤ max_block_size: pieces may only exceed it to
          // hold a chain longer than max_block_size
          AmalgamationOptions bound = o;
          if (mbs > 0) bound.max_block_size = std::max(mbs, longest_chain);
          check_tree(b, sf, bound, nullptr, false);
          check_schedule(sf.tree, symbolic::level_schedule(sf.tree));
          if (!relax && mbs == 0) EXPECT_LE(sf.tree.n_fronts(), plain.tree.n_fronts());
          if (HasFatalFailure()) return;
        }
      }
    }
  }
  // A flag on a column whose parent is not the next column is rejected.
  SparseMatrix diag;
  diag.n_rows = diag.n_cols = 3;
  diag.offsets = {0, 1, 2, 3};
  diag.indices = {0, 1, 2};
  AmalgamationOptions o;
  o.keep_with_next = {1, 0, 0};
  EXPECT_THROW(symbolic::analyze_pattern(diag, o), InvalidInput);
  o.keep_with_next = {0, 0};
  EXPECT_THROW(symbolic::analyze_pattern(diag, o), InvalidInput);
}

TEST(Symbolic, SharedMatricesAgainstCholmod) {
  const std::vector<std::string> names = test::shared_matrix_names();
  ASSERT_FALSE(names.empty());
  for (const std::string& name : names) {
    const MMMatrix m = read_matrix_market(test::matrix_path(name));
    const SparseMatrix pattern = symmetric_pattern(m.matrix);
    const std::vector<index_t> perm = metis_order(pattern);
    check_all(pattern, perm, name);
    const SymbolicFactorization sf = symbolic::analyze_pattern(
        symbolic::permute_symmetric_pattern(pattern, perm), AmalgamationOptions{});
    std::printf("  %-24s n %7lld  nnz(A+A') %8lld  nnz(L) %9lld  fronts %6lld\n", name.c_str(),
                static_cast<long long>(pattern.n_cols), static_cast<long long>(pattern.nnz()),
                static_cast<long long>(sf.nnz_l), static_cast<long long>(sf.tree.n_fronts()));
    if (HasFatalFailure()) return;
  }
}

// Timing of the whole symbolic phase on the 7-point Laplacian of a 100³ grid
// (1,000,000 columns) ordered by METIS. Disabled by default (METIS alone takes a while
// on a shared machine); run with --gtest_also_run_disabled_tests.
void time_grid(index_t k) {
  const SparseMatrix pattern = symmetric_pattern(generators::laplacian_3d(k, k, k));
  Timer timer;
  const std::vector<index_t> perm = metis_order(pattern);
  const double t_metis = timer.seconds();
  timer.reset();
  const SparseMatrix b = symbolic::permute_symmetric_pattern(pattern, perm);
  const double t_perm = timer.seconds();
  timer.reset();
  const std::vector<index_t> parent = symbolic::elimination_tree(b);
  const double t_etree = timer.seconds();
  timer.reset();
  const std::vector<index_t> post = symbolic::postorder(parent);
  const double t_post = timer.seconds();
  timer.reset();
  const std::vector<index_t> cc = symbolic::column_counts(b, parent, post);
  const double t_counts = timer.seconds();
  timer.reset();
  const SymbolicFactorization sf = symbolic::analyze_pattern(b, AmalgamationOptions{});
  const double t_analyze = timer.seconds();
  timer.reset();
  const symbolic::LevelSchedule s = symbolic::level_schedule(sf.tree);
  const double t_levels = timer.seconds();
  double flops = 0;
  index_t max_rows = 0;
  for (index_t f = 0; f < sf.tree.n_fronts(); ++f) {
    flops += symbolic::front_flops(sf.tree, f);
    max_rows = std::max(max_rows, sf.tree.n_rows(f));
  }
  std::printf(
      "%lld^3 grid: n %lld, nnz(A) %lld, nnz(L) %lld, fronts %lld, largest front %lld rows, "
      "levels %lld, flops %.3g\n  METIS %.2f s; permute %.3f s; etree %.3f s; postorder "
      "%.3f s; column counts %.3f s; analyze_pattern (all of the symbolic phase) %.3f s; "
      "level schedule %.4f s\n",
      static_cast<long long>(k), static_cast<long long>(b.n_cols), static_cast<long long>(b.nnz()),
      static_cast<long long>(sf.nnz_l), static_cast<long long>(sf.tree.n_fronts()),
      static_cast<long long>(max_rows), static_cast<long long>(s.n_levels()), flops, t_metis,
      t_perm, t_etree, t_post, t_counts, t_analyze, t_levels);
  EXPECT_EQ(sf.colcount, cc);
  timer.reset();
  const CholmodCounts chol = cholmod_counts(b);
  std::printf("  cholmod_l_analyze (natural order, simplicial, for comparison) %.3f s\n",
              timer.seconds());
  EXPECT_EQ(cc, chol.colcount);
  EXPECT_EQ(static_cast<double>(sf.nnz_l), chol.lnz);
}

TEST(Symbolic, Timing40Cubed) { time_grid(40); }

// Options::max_block_size 0 resolves by backend and type: 4096 for Cholesky on the CUDA
// backend (its analysis needs no GPU), 1024 otherwise; a value given is used as is, and
// a negative one is refused. A 3-D Laplacian 40³ has a top separator of about 1,600
// pivots: split into chains at 1024, whole at 4096.
TEST(Symbolic, MaxBlockSizeByBackendAndType) {
  const SparseMatrix a = generators::laplacian_3d(40, 40, 40);
  struct Case {
    Backend backend;
    MatrixType type;
    index_t asked, used;
  };
  for (const Case& c :
       {Case{Backend::cpu, MatrixType::spd, 0, 1024}, Case{Backend::cuda, MatrixType::spd, 0, 4096},
        Case{Backend::cuda, MatrixType::general, 0, 1024},
        Case{Backend::cuda, MatrixType::symmetric_indefinite, 0, 1024},
        Case{Backend::cuda, MatrixType::spd, 512, 512},
        Case{Backend::cpu, MatrixType::spd, 3000, 3000}}) {
    SCOPED_TRACE("backend " + std::to_string(static_cast<int>(c.backend)) + " type " +
                 std::to_string(static_cast<int>(c.type)) + " asked " + std::to_string(c.asked));
    Options o;
    o.backend = c.backend;
    o.type = c.type;
    o.max_block_size = c.asked;
    o.num_gpus = 1;  // whatever the machine has
    const Analysis an = analyze_matrix(a, o);
    EXPECT_EQ(an.stats.max_block_size, c.used);
    EXPECT_LE(an.stats.largest_front_pivots, c.used);
    EXPECT_GT(an.stats.largest_front_pivots, std::min<index_t>(c.used, 1024) / 2);
    if (c.used > 1024) EXPECT_GT(an.stats.largest_front_pivots, 1024);
  }
  Options bad;
  bad.max_block_size = -1;
  EXPECT_THROW(analyze_matrix(a, bad), InvalidInput);
}
TEST(Symbolic, DISABLED_Timing100Cubed) { time_grid(100); }

// The extend-add map (symbolic::child_row_map, kept as Analysis::child_rows): every
// contribution row of a front is found at the position the map gives in its parent's rows
// (checked by searching the parent's list), positions increasing; LU (the pattern of
// A+Aᵀ) and Cholesky trees, sizes 1 to 733.
TEST(Symbolic, ChildRowMapPlacesEveryContributionRowInItsParent) {
  auto rng = test::fresh_rng();
  for (index_t n : {1, 2, 3, 5, 733}) {
    for (MatrixType type : {MatrixType::spd, MatrixType::general}) {
      SCOPED_TRACE("n=" + std::to_string(n) + " type " + std::to_string(static_cast<int>(type)));
      const SparseMatrix a = test::random_sparse(
          n, 4, type == MatrixType::spd ? test::RandomKind::spd : test::RandomKind::general, rng);
      Options o;
      o.type = type;
      const Analysis an = analyze_matrix(a, o);
      const auto& t = an.tree;
      const symbolic::ChildRowMap& map = an.child_rows;
      ASSERT_EQ(map.offsets.size(), static_cast<std::size_t>(t.n_fronts() + 1));
      for (index_t c = 0; c < t.n_fronts(); ++c) {
        ASSERT_EQ(map.offsets[c + 1] - map.offsets[c], t.cb_size(c));
        const index_t p = t.parent[c];
        if (p < 0) continue;
        const index_t* prow = t.rows_of(p);
        const index_t* crow = t.rows_of(c) + t.n_pivots(c);
        for (index_t i = 0; i < t.cb_size(c); ++i) {
          const index_t expect = std::find(prow, prow + t.n_rows(p), crow[i]) - prow;
          ASSERT_LT(expect, t.n_rows(p)) << "row " << crow[i] << " not in the parent";
          EXPECT_EQ(map.of(c)[i], expect);
          if (i > 0) EXPECT_LT(map.of(c)[i - 1], map.of(c)[i]);
        }
      }
    }
  }
}

}  // namespace
}  // namespace strata
