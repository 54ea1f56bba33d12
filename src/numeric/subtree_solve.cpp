// strata — the host solve by subtrees (see subtree_solve.hpp).
#include "numeric/subtree_solve.hpp"

#include <tbb/parallel_for.h>

#include <algorithm>
#include <numeric>
#include <string>

#include "base/blas.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

// Panel entries above which a top front's BLAS calls get more than one thread: below, the
// threads' start-up costs more than the memory traffic they share.
constexpr std::size_t kThreadedTopEntries = std::size_t{1} << 20;

}  // namespace

SubtreeSolvePlan plan_subtree_solve(const Analysis& an) {
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  const bool lu = !an.symmetric;
  SubtreeSolvePlan p;
  p.analysis_id = an.id;
  p.row_slot.assign(t.rows.size(), -1);
  if (nf == 0) return p;
  // work of each subtree (the panel entries the solve reads) and its first front
  std::vector<double> work(nf, 0.0);
  std::vector<index_t> first(nf);
  std::iota(first.begin(), first.end(), index_t{0});
  double total = 0;
  for (index_t f = 0; f < nf; ++f) {  // children come before their parent
    work[f] += static_cast<double>(panel_size(t, f, lu));
    total += static_cast<double>(panel_size(t, f, lu));
    const index_t q = t.parent[f];
    if (q >= 0) {
      work[q] += work[f];
      first[q] = std::min(first[q], first[f]);
    }
  }
  const double limit = total / kSolveSubtrees;
  std::vector<char> in_subtree(nf, 0);
  for (index_t f = 0; f < nf; ++f) {
    const index_t q = t.parent[f];
    if (work[f] <= limit && (q < 0 || work[q] > limit)) p.subtrees.emplace_back(first[f], f);
  }
  for (const auto& [lo, hi] : p.subtrees)
    std::fill(in_subtree.begin() + lo, in_subtree.begin() + hi + 1, 1);
  for (index_t f = 0; f < nf; ++f)
    if (!in_subtree[f]) p.top.push_back(f);
  // each subtree's rows outside it (its pivots are the contiguous range of its fronts')
  std::vector<index_t> slot_of(an.n, -1), stamp(an.n, -1);
  for (std::size_t s = 0; s < p.subtrees.size(); ++s) {
    const auto [lo, hi] = p.subtrees[s];
    const index_t r0 = t.first_pivot[lo], r1 = t.first_pivot[hi + 1];
    std::vector<index_t> outside;
    for (index_t f = lo; f <= hi; ++f) {
      const index_t* rows = t.rows_of(f);
      for (index_t i = t.n_pivots(f); i < t.n_rows(f); ++i) {
        const index_t r = rows[i];
        if (r >= r0 && r < r1) continue;
        if (stamp[r] != static_cast<index_t>(s)) {
          stamp[r] = static_cast<index_t>(s);
          outside.push_back(r);
        }
      }
    }
    std::sort(outside.begin(), outside.end());
    for (std::size_t j = 0; j < outside.size(); ++j) slot_of[outside[j]] = static_cast<index_t>(j);
    for (index_t f = lo; f <= hi; ++f) {
      const index_t* rows = t.rows_of(f);
      index_t* slot = p.row_slot.data() + t.row_offsets[f];
      for (index_t i = t.n_pivots(f); i < t.n_rows(f); ++i)
        if (rows[i] < r0 || rows[i] >= r1) slot[i] = slot_of[rows[i]];
    }
    p.slot_row.insert(p.slot_row.end(), outside.begin(), outside.end());
    p.slot_offsets.push_back(static_cast<index_t>(p.slot_row.size()));
  }
  return p;
}

void solve_by_subtrees(const Analysis& an, const NumericFactor& fac, const SubtreeSolvePlan& plan,
                       double* x, index_t nrhs, tbb::task_arena& arena, int top_blas_threads) {
  if (plan.analysis_id != an.id || plan.row_slot.size() != an.tree.rows.size())
    throw InternalError("solve_by_subtrees: the plan was made for another analysis");
  const auto& t = an.tree;
  const bool lu = fac.type == MatrixType::general;
  const index_t n = an.n;
  const int ns = static_cast<int>(plan.subtrees.size());
  const std::size_t slots = plan.slot_row.size();
  // per subtree, its slots' values for every right-hand side (ld: its slot count)
  std::vector<double> delta(slots * static_cast<std::size_t>(nrhs), 0.0);
  auto delta_of = [&](int s) {
    return delta.data() + static_cast<std::size_t>(plan.slot_offsets[s]) * nrhs;
  };
  openblas_set_num_threads(1);
  auto top_front = [&](index_t f, auto&& step) {
    const bool big = top_blas_threads > 1 && panel_size(t, f, lu) >= kThreadedTopEntries;
    if (big) openblas_set_num_threads(top_blas_threads);
    step(f);
    if (big) openblas_set_num_threads(1);
  };
  arena.execute([&] {
    tbb::parallel_for(0, ns, 1, [&](int s) {
      std::vector<double> w;
      const auto [lo, hi] = plan.subtrees[s];
      const index_t ld = plan.slot_offsets[s + 1] - plan.slot_offsets[s];
      for (index_t f = lo; f <= hi; ++f)
        forward_front(an, fac, f, x, nrhs, w, plan.row_slot.data() + t.row_offsets[f], delta_of(s),
                      ld);
    });
  });
  for (int s = 0; s < ns; ++s) {  // the subtrees' updates of the rows above them, in order
    const index_t b = plan.slot_offsets[s], ld = plan.slot_offsets[s + 1] - b;
    const double* d = delta_of(s);
    for (index_t r = 0; r < nrhs; ++r)
      for (index_t j = 0; j < ld; ++j) x[plan.slot_row[b + j] + r * n] += d[j + r * ld];
  }
  std::vector<double> w;
  for (const index_t f : plan.top)
    top_front(f, [&](index_t g) { forward_front(an, fac, g, x, nrhs, w); });
  if (fac.type == MatrixType::symmetric_indefinite)
    for (index_t f = 0; f < t.n_fronts(); ++f) diagonal_front(an, fac, f, x, nrhs);
  for (auto it = plan.top.rbegin(); it != plan.top.rend(); ++it)
    top_front(*it, [&](index_t g) { backward_front(an, fac, g, x, nrhs, w); });
  arena.execute([&] {
    tbb::parallel_for(0, ns, 1, [&](int s) {
      std::vector<double> wb;
      const auto [lo, hi] = plan.subtrees[s];
      for (index_t f = hi; f >= lo; --f) backward_front(an, fac, f, x, nrhs, wb);
    });
  });
}

}  // namespace strata::numeric
