// strata — whole-graph fill-reducing orderings and the ordering dispatcher
// (see ordering.hpp).
//
// What: METIS_NodeND and SuiteSparse AMD applied to the whole graph, the natural and the
// user orderings, the dispatcher compute_ordering, and permutation helpers. strata's own
// nested dissection driver lives in nested_dissection.cpp.
//
// Why: nested dissection is the default because it keeps the separator tree the
// multi-GPU schedule needs; METIS_NodeND is the reference it is measured against (and a
// user choice), AMD is the best choice for small or very irregular problems, and the user
// ordering lets a caller reuse a permutation computed elsewhere.
//
// Conventions: every permutation here is "new to old", perm[k] is the original index of
// the k-th pivot (CHOLMOD's Perm). METIS_NodeND documents "row i of A' is row perm[i] of
// A", so its `perm` output is new-to-old and its `iperm` old-to-new; AMD's P is
// new-to-old ("row P[k] is the k-th pivot"). Both are checked by test_ordering.
//
// METIS 5.1 as packaged by Debian uses 32-bit idx_t: a graph whose order or number of
// directed edges does not fit is rejected with InvalidInput rather than truncated.
//
// Sources: Amestoy, Davis & Duff, "An approximate minimum degree ordering algorithm",
// SIAM J. Matrix Anal. Appl. 17 (1996); Karypis & Kumar, "A fast and high quality
// multilevel scheme for partitioning irregular graphs", SIAM J. Sci. Comput. 20 (1998);
// George, "Nested dissection of a regular finite element mesh", SIAM J. Numer. Anal. 10
// (1973).
#include <amd.h>
#include <metis.h>

#include <algorithm>
#include <limits>
#include <numeric>
#include <string>
#include <type_traits>

#include "base/default_init.hpp"
#include "ordering/ordering.hpp"
#include "strata/errors.hpp"

namespace strata::ordering {

namespace {

// AMD's core routine on g with index type Int: amd_2 (int) when the graph's lists and their
// elbow room fit 32-bit indices, which halves the bytes AMD works through, else amd_l2
// (SuiteSparse_long); the same algorithm, the same permutation. The graph is what amd_2
// takes (symmetric, no diagonal, no duplicates), so it is called directly rather than
// through amd_order, which would check the pattern and form A + Aᵀ again. amd_2 overwrites
// its copy of the lists and needs room after them: at least n entries (amd_order gives
// nz/5 + n, as here).
template <class Int>
void amd_core(const Graph& g, index_t* perm, AmdCounts* counts) {
  const Int n = static_cast<Int>(g.n);
  const Int nz = static_cast<Int>(g.n_edges_directed());
  const Int iwlen = nz + nz / 5 + n;
  // not value-initialized: amd_2 reads only the first nz entries before writing the rest
  UninitVector<Int> iw(static_cast<std::size_t>(iwlen));
  std::copy(g.adjncy.begin(), g.adjncy.end(), iw.begin());
  UninitVector<Int> pe(static_cast<std::size_t>(n)), len(static_cast<std::size_t>(n));
  for (Int v = 0; v < n; ++v) {
    pe[v] = static_cast<Int>(g.xadj[v]);
    len[v] = static_cast<Int>(g.xadj[v + 1] - g.xadj[v]);
  }
  std::vector<Int> nv(n), next(n), last(n), head(n), elen(n), degree(n), w(n);
  double control[AMD_CONTROL], info[AMD_INFO] = {};
  amd_defaults(control);
  if constexpr (sizeof(Int) == sizeof(int))
    amd_2(n, pe.data(), iw.data(), len.data(), iwlen, nz, nv.data(), next.data(), last.data(),
          head.data(), elen.data(), degree.data(), w.data(), control, info);
  else
    amd_l2(n, pe.data(), iw.data(), len.data(), iwlen, nz, nv.data(), next.data(), last.data(),
           head.data(), elen.data(), degree.data(), w.data(), control, info);
  std::copy(last.begin(), last.end(), perm);  // Last: the k-th pivot
  if (counts) {
    counts->nnz_l = info[AMD_LNZ] + static_cast<double>(n);
    counts->flops = info[AMD_NDIV] + 2 * info[AMD_NMULTSUBS_LDL];
  }
}

}  // namespace

std::vector<index_t> amd_ordering(const Graph& g, AmdCounts* counts) {
  const index_t n = g.n;
  if (n == 0) return {};
  std::vector<index_t> perm(n);
  if (g.n_edges_directed() == 0) {
    std::iota(perm.begin(), perm.end(), index_t{0});
    if (counts) *counts = {static_cast<double>(n), static_cast<double>(n)};
    return perm;
  }
  static_assert(sizeof(SuiteSparse_long) == sizeof(index_t), "AMD long index must be 64-bit");
  const index_t nz = g.n_edges_directed();
  if (nz + nz / 5 + n <= std::numeric_limits<int>::max())
    amd_core<int>(g, perm.data(), counts);
  else
    amd_core<SuiteSparse_long>(g, perm.data(), counts);
  return perm;
}

std::vector<index_t> amd_ordering(const Graph& g) { return amd_ordering(g, nullptr); }

bool amd_is_good_enough(const AmdCounts& counts, const Graph& g) {
  if (g.n == 0) return true;
  const double nnz_tril =
      static_cast<double>(g.n) + 0.5 * static_cast<double>(g.n_edges_directed());
  return counts.flops < 500 * counts.nnz_l || counts.nnz_l < 5 * nnz_tril;
}

std::vector<index_t> metis_ordering(const Graph& g, const std::vector<index_t>& vertex_weights) {
  const index_t n = g.n;
  if (n == 0) return {};
  std::vector<index_t> perm(n);
  if (g.n_edges_directed() == 0 || n <= 2) {  // every ordering has the same (zero) fill
    std::iota(perm.begin(), perm.end(), index_t{0});
    return perm;
  }
  constexpr index_t idx_max = std::numeric_limits<idx_t>::max();
  if (n > idx_max || g.n_edges_directed() > idx_max)
    throw InvalidInput("metis_ordering: the graph (" + std::to_string(n) + " vertices, " +
                       std::to_string(g.n_edges_directed()) + " directed edges) exceeds METIS's " +
                       std::to_string(IDXTYPEWIDTH) + "-bit index type");
  std::vector<idx_t> xadj(g.xadj.begin(), g.xadj.end());
  std::vector<idx_t> adjncy(g.adjncy.begin(), g.adjncy.end());
  std::vector<idx_t> vwgt;
  if (!vertex_weights.empty()) {
    if (static_cast<index_t>(vertex_weights.size()) != n)
      throw InvalidInput("metis_ordering: " + std::to_string(vertex_weights.size()) +
                         " vertex weights for " + std::to_string(n) + " vertices");
    index_t total = 0;
    for (const index_t w : vertex_weights) {
      if (w < 1) throw InvalidInput("metis_ordering: vertex weights must be positive");
      total += w;
    }
    if (total > idx_max)
      throw InvalidInput("metis_ordering: the total vertex weight exceeds METIS's " +
                         std::to_string(IDXTYPEWIDTH) + "-bit index type");
    vwgt.assign(vertex_weights.begin(), vertex_weights.end());
  }
  std::vector<idx_t> mperm(n), miperm(n);
  idx_t nv = static_cast<idx_t>(n);
  idx_t options[METIS_NOPTIONS];
  METIS_SetDefaultOptions(options);
  options[METIS_OPTION_NUMBERING] = 0;
  const int status =
      METIS_NodeND(&nv, xadj.data(), adjncy.data(), vwgt.empty() ? nullptr : vwgt.data(), options,
                   mperm.data(), miperm.data());
  if (status == METIS_ERROR_MEMORY) throw OutOfMemory(0, "METIS_NodeND");
  if (status != METIS_OK)
    throw InvalidInput("METIS_NodeND failed (status " + std::to_string(status) + ")");
  for (index_t k = 0; k < n; ++k) perm[k] = mperm[k];  // METIS perm: new -> old
  return perm;
}

NestedDissectionOptions nd_options(const Options& opts, int workers) {
  if (opts.nd_leaf_size < 1)
    throw InvalidInput("Options::nd_leaf_size must be at least 1 (got " +
                       std::to_string(opts.nd_leaf_size) + ")");
  if (opts.nd_separators < 0)
    throw InvalidInput("Options::nd_separators must be at least 0 (got " +
                       std::to_string(opts.nd_separators) + ")");
  NestedDissectionOptions nd;
  nd.leaf_size = opts.nd_leaf_size;
  nd.top_separators = opts.nd_top_separators;
  nd.separators = opts.nd_separators;
  if (opts.balance_by_work && workers > 1) {
    const long parts = static_cast<long>(workers) * std::max(1, opts.subtrees_per_gpu);
    while ((1L << nd.balance_levels) < parts) ++nd.balance_levels;  // ⌈log₂ parts⌉
  }
  return nd;
}

OrderingResult compute_ordering(const Graph& g, const Options& opts, int workers) {
  OrderingResult r;
  const index_t n = g.n;
  r.method = opts.ordering;
  switch (opts.ordering) {
    case OrderingMethod::nested_dissection:
      return nested_dissection(g, nd_options(opts, workers));
    case OrderingMethod::metis:
      r.perm = metis_ordering(g);
      return r;
    case OrderingMethod::amd:
      r.perm = amd_ordering(g);
      return r;
    case OrderingMethod::automatic: {
      // a tree split over several workers needs the separator tree
      AmdCounts counts;
      if (workers == 1) r.perm = amd_ordering(g, &counts);
      if (workers == 1 && amd_is_good_enough(counts, g)) {
        r.method = OrderingMethod::amd;
        return r;
      }
      return nested_dissection(g, nd_options(opts, workers));
    }
    case OrderingMethod::natural:
      r.perm.resize(n);
      std::iota(r.perm.begin(), r.perm.end(), index_t{0});
      return r;
    case OrderingMethod::user: {
      const auto& p = opts.user_permutation;
      if (static_cast<index_t>(p.size()) != n)
        throw InvalidInput("user_permutation has " + std::to_string(p.size()) +
                           " entries, expected " + std::to_string(n));
      std::vector<index_t> seen(n, -1);
      for (index_t k = 0; k < n; ++k) {
        const index_t v = p[k];
        if (v < 0 || v >= n)
          throw InvalidInput("user_permutation[" + std::to_string(k) + "] = " + std::to_string(v) +
                             " is out of range [0, " + std::to_string(n) + ")");
        if (seen[v] >= 0)
          throw InvalidInput("user_permutation[" + std::to_string(k) + "] = " + std::to_string(v) +
                             " repeats user_permutation[" + std::to_string(seen[v]) + "]");
        seen[v] = k;
      }
      r.perm = p;
      return r;
    }
  }
  throw InvalidInput("compute_ordering: unknown ordering method");
}

std::vector<index_t> invert_permutation(const std::vector<index_t>& perm) {
  const index_t n = static_cast<index_t>(perm.size());
  if (!is_permutation(perm, n)) throw InvalidInput("invert_permutation: not a permutation");
  std::vector<index_t> inv(n);
  for (index_t k = 0; k < n; ++k) inv[perm[k]] = k;
  return inv;
}

bool is_permutation(const std::vector<index_t>& perm, index_t n) {
  if (n < 0 || static_cast<index_t>(perm.size()) != n) return false;
  std::vector<char> seen(n, 0);
  for (const index_t v : perm) {
    if (v < 0 || v >= n || seen[v]) return false;
    seen[v] = 1;
  }
  return true;
}

}  // namespace strata::ordering
