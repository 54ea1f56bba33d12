// strata — front factorization with threshold pivoting and delayed pivots (see
// delayed_front.hpp).
//
// LU, blocked. Pivots are taken in panels of kPanel: inside a panel left-looking (the next
// candidate column is brought up to date with the panel's earlier pivots, over all m rows,
// since the threshold test's column maximum must see the contribution-block rows as they
// are), after it right-looking (the U rows of every column behind the panel by forward
// substitution, then one GEMM for their Schur complement: BLAS-3, the delayed and
// contribution-block rows and columns among them). The up-to-date column is built in a
// copy: a refused column is swapped, as it was, with the last untried candidate, and gets
// the panel's pivots with every other column behind the panel. Whole rows are interchanged
// at once: the rows interchanged are both below the panel's earlier pivots, where every
// column behind the panel is still waiting for the same update.
#include "numeric/cpu/delayed_front.hpp"

#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "numeric/cpu/dense_blas.hpp"
#include "numeric/cpu/small_dense.hpp"
#include "strata/errors.hpp"

namespace strata::numeric::cpu {
namespace {

// Pivots per panel: the BLAS-2 work inside a panel is about m·kPanel per column, the rest
// goes to one TRSM and one GEMM per panel.
constexpr index_t kPanel = 32;

// Columns per block of a panel's update of the columns behind it: the blocks are the
// tasks when the update runs on an arena's threads (one-thread BLAS in each).
constexpr index_t kUpdateColumns = 128;

void count(double d, PivotStats& st) {
  if (d < 0) st.det_sign = -st.det_sign;
  if (d == 0) {
    ++st.zero;
    st.det_sign = 0;
  }
  st.log_abs_det += std::log(std::abs(d));
}

// B = L⁻¹·B for the panel's unit lower triangle L (np × np, np ≤ kPanel) and w columns
// of B, a column at a time (forward substitution by columns of L, skipping zeros): at these
// shapes TRSM's packing costs more than the arithmetic, and the delayed fronts' U rows are
// mostly zeros (contact pairs in the pattern that are not in contact).
void unit_lower_solve(index_t np, index_t w, const double* l, index_t ldl, double* b, index_t ldb) {
  for (index_t j = 0; j < w; ++j) {
    double* x = b + static_cast<std::size_t>(j) * ldb;
    for (index_t c = 0; c + 1 < np; ++c) {
      const double u = x[c];
      if (u == 0.0) continue;
      const double* lc = l + static_cast<std::size_t>(c) * ldl;
      for (index_t i = c + 1; i < np; ++i) x[i] -= lc[i] * u;
    }
  }
}

}  // namespace

void update_behind_panel(double* f, index_t m, index_t ld, index_t j0, index_t k,
                         tbb::task_arena* arena) {
  const index_t np = k - j0, nrest = m - k;
  if (np <= 0 || nrest <= 0) return;
  auto A = [&](index_t i, index_t j) -> double* { return f + i + j * ld; };
  // in blocks of kUpdateColumns columns, each independent of the others: the same calls,
  // so the same bits, whether the blocks run one after another or on an arena
  const index_t blocks = (nrest + kUpdateColumns - 1) / kUpdateColumns;
  auto update = [&](index_t b) {
    const index_t c0 = k + b * kUpdateColumns;
    const index_t w = std::min(kUpdateColumns, m - c0);
    unit_lower_solve(np, w, A(j0, j0), ld, A(j0, c0), ld);
    gemm('N', 'N', m - k, w, np, -1.0, A(k, j0), ld, A(j0, c0), ld, 1.0, A(k, c0), ld);
  };
  if (arena && blocks > 1 && arena->max_concurrency() > 1)
    // isolated: a thread waiting here takes no other front's task, whose work arrays
    // (per thread) this front is using
    arena->execute([&] {
      tbb::this_task_arena::isolate([&] { tbb::parallel_for(index_t{0}, blocks, update); });
    });
  else
    for (index_t b = 0; b < blocks; ++b) update(b);
}

void check_delayed_front(index_t m, index_t p, index_t ld, const DelayPolicy& policy,
                         const char* what) {
  if (m < 0 || p < 0 || p > m || ld < std::max<index_t>(m, 1))
    throw InvalidInput(std::string(what) + ": need 0 <= p <= m <= ld (m=" + std::to_string(m) +
                       ", p=" + std::to_string(p) + ", ld=" + std::to_string(ld) + ")");
  if (!(policy.threshold > 0 && policy.threshold <= 1))
    throw InvalidInput(std::string(what) + ": the pivot threshold must be in (0, 1]");
}

index_t factor_front_lu_delayed(double* f, index_t m, index_t p, index_t ld,
                                const DelayPolicy& policy, index_t* row_perm, index_t* col_perm,
                                PivotStats& st, tbb::task_arena* arena) {
  check_delayed_front(m, p, ld, policy, "delayed front");
  auto A = [&](index_t i, index_t j) -> double& { return f[i + j * ld]; };
  for (index_t i = 0; i < p; ++i) row_perm[i] = col_perm[i] = i;
  std::vector<double> col;  // the candidate column brought up to date with the panel
  index_t npiv = 0;
  index_t last = p;  // candidates are columns npiv..last-1; last..p-1 were refused
  while (npiv < last) {
    // one panel: up to kPanel pivots taken from the candidates, left-looking inside it
    const index_t j0 = npiv;
    while (npiv < last && npiv - j0 < kPanel) {
      const index_t j = npiv;
      // column j with the panel's earlier pivots applied (the earlier panels' are in it
      // already), in a copy: a refused column must stay without them, since the update
      // after the panel applies them to every column behind it
      col.assign(&A(j0, j), &A(j0, j) + (m - j0));
      const index_t q = j - j0;          // pivots already taken in this panel
      for (index_t c = 0; c < q; ++c) {  // unit lower solve on the panel's top rows
        const double u = col[c];
        if (u == 0.0) continue;
        const double* l = &A(j0, j0 + c);
        for (index_t i = c + 1; i < m - j0; ++i) col[i] -= l[i] * u;
      }
      // largest entry among the remaining fully summed rows (the first of them, j first,
      // on ties), and over all remaining rows: the maxima first, then where (a NaN on the
      // diagonal stays the pivot, as a comparison with it fails)
      index_t r = j;
      double best = std::abs(col[q]);
      if (!std::isnan(best)) {
        const double most = max_abs(col.data() + q + 1, p - j - 1);
        if (most > best) {
          best = most;
          r = j + 1;
          while (std::abs(col[r - j0]) != most) ++r;
        }
      }
      const double colmax = std::max(best, max_abs(col.data() + (p - j0), m - p));
      const bool good = best > policy.tiny && best >= policy.threshold * colmax;
      if (!good && policy.may_delay) {
        // refuse column j (as it was): behind the remaining candidates
        --last;
        if (j != last) {
          for (index_t i = 0; i < m; ++i) std::swap(A(i, j), A(i, last));
          std::swap(col_perm[j], col_perm[last]);
        }
        continue;
      }
      std::copy(col.begin(), col.end(), &A(j0, j));
      if (r != j) {  // whole rows: the panel's L, the pending columns, the block's columns
        for (index_t c = 0; c < m; ++c) std::swap(A(j, c), A(r, c));
        std::swap(row_perm[j], row_perm[r]);
      }
      double d = A(j, j);
      if (std::abs(d) < policy.static_pivot) {  // a root's last resort
        d = d < 0 ? -policy.static_pivot : policy.static_pivot;
        ++st.perturbed;
      }
      A(j, j) = d;
      count(d, st);
      const double inv = d != 0 ? 1.0 / d : 0.0;
      for (index_t i = j + 1; i < m; ++i) A(i, j) *= inv;
      ++npiv;
    }
    // the panel's pivots applied to every column behind it (the candidates left, the
    // refused ones and the contribution block's): their U rows, then their Schur complement
    update_behind_panel(f, m, ld, j0, npiv, arena);
  }
  return npiv;
}

}  // namespace strata::numeric::cpu
