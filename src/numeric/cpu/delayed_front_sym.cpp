// strata — a symmetric front's partial factorization with 1×1 and 2×2 pivots and delayed
// pivots (see delayed_front.hpp).
//
// What: the front of a symmetric indefinite matrix, held whole (both triangles), is
// eliminated with symmetric interchanges only, so the pivots are diagonal entries (1×1) or
// diagonal 2×2 blocks and the inertia of the eliminated block is that of its pivots
// (Sylvester's law of inertia). A candidate that can neither be a 1×1 pivot nor form a 2×2
// pivot with another candidate is delayed: its row and column go to the parent front
// together, as in MA57 and MUMPS's symmetric fronts (Duff & Reid, "The multifrontal
// solution of indefinite sparse symmetric linear equations", ACM TOMS 9, 1983).
//
// How: the factor is stored as an LU (the layout of factor_front_lu_delayed), so the
// delayed factorization's solve serves both types: a 1×1 pivot d is one elimination step
// (the column over d gives L, the row is U's); a 2×2 pivot D is two elimination steps on its
// two columns with the two rows ordered so that the first step's pivot is the larger
// entry of D's first column (the rows of D may be interchanged, the columns are not: the
// row and column lists then differ in those two places, which LU's layout allows). The
// tests, on the up-to-date column j over all remaining rows (contribution-block rows
// included), with u the threshold:
//   1×1: |a_jj| > tiny and |a_jj| ≥ u·max_{i≠j} |a_ij|;
//   2×2 with the candidate r of the largest |a_rj|: both entries of |D⁻¹|·(γ_j, γ_r)ᵀ at
//   most 1/u, γ the columns' largest entries outside D (MA57's test; Duff, Gould, Reid,
//   Scott & Turner, IMA J. Numer. Anal. 11, 1991), both elimination steps' pivots > tiny.
// At a root nothing may be delayed and the Bunch–Kaufman rule chooses (Bunch & Kaufman,
// Math. Comp. 31, 1977; Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed.,
// §11.1.2): backward stable for any symmetric matrix; a pivot below static_pivot there is
// the last resort of a numerically singular matrix and is replaced by ±static_pivot.
// The candidates' columns (all rows) are updated after every pivot (right-looking over the
// p fully summed columns, as the tests need them current); the columns behind them, the
// contribution block's, get every pivot at the end at once (their U rows by a triangular
// solve, then one GEMM for their Schur complement), in blocks of columns that run on the
// arena's threads when one is given.
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>

#include "numeric/cpu/delayed_front.hpp"
#include "numeric/cpu/dense_blas.hpp"
#include "strata/errors.hpp"

namespace strata::numeric::cpu {
namespace {

// Columns per block of the final update of the columns behind the candidates.
constexpr index_t kUpdateColumns = 128;

// The Bunch–Kaufman constant (1 + √17)/8: it minimizes the bound on the growth of a
// 1×1 / 2×2 pivoting step.
const double kBunchKaufmanAlpha = (1.0 + std::sqrt(17.0)) / 8.0;

// det and log of one elimination step's pivot (the product of a 2×2 pivot's two steps'
// pivots is ±det D, the sign of the rows' order is in the row list's parity).
void count_step(double u, PivotStats& st) {
  if (u < 0) st.det_sign = -st.det_sign;
  if (u == 0) st.det_sign = 0;
  st.log_abs_det += std::log(std::abs(u));
}

}  // namespace

index_t factor_front_sym_delayed(double* f, index_t m, index_t p, index_t ld,
                                 const DelayPolicy& policy, index_t* row_perm, index_t* col_perm,
                                 PivotStats& st, tbb::task_arena* arena) {
  if (m < 0 || p < 0 || p > m || ld < std::max<index_t>(m, 1))
    throw InvalidInput("delayed symmetric front: need 0 <= p <= m <= ld (m=" + std::to_string(m) +
                       ", p=" + std::to_string(p) + ", ld=" + std::to_string(ld) + ")");
  if (!(policy.threshold > 0 && policy.threshold <= 1))
    throw InvalidInput("delayed symmetric front: the pivot threshold must be in (0, 1]");
  auto A = [&](index_t i, index_t j) -> double& { return f[i + j * ld]; };
  for (index_t i = 0; i < p; ++i) row_perm[i] = col_perm[i] = i;
  // positions a, b (both candidates at or after the next pivot) interchanged symmetrically:
  // whole rows (L's part, the pending columns) and whole candidate columns (U's part)
  auto sym_swap = [&](index_t a, index_t b) {
    if (a == b) return;
    for (index_t c = 0; c < m; ++c) std::swap(A(a, c), A(b, c));
    for (index_t i = 0; i < m; ++i) std::swap(A(i, a), A(i, b));
    std::swap(row_perm[a], row_perm[b]);
    std::swap(col_perm[a], col_perm[b]);
  };
  // the largest |entry| of column j over rows [s, m) outside rows x and y
  auto column_max = [&](index_t j, index_t s, index_t x, index_t y) {
    double g = 0;
    const double* col = &A(0, j);
    for (index_t i = s; i < m; ++i)
      if (i != x && i != y) g = std::max(g, std::abs(col[i]));
    return g;
  };
  // one elimination step at (s, s): L's column, then the candidates' columns behind it
  // (their rows below s); a root's pivot under static_pivot is replaced first
  auto eliminate = [&](index_t s) {
    double d = A(s, s);
    if (!policy.may_delay && std::abs(d) < policy.static_pivot) {
      d = d < 0 ? -policy.static_pivot : policy.static_pivot;
      A(s, s) = d;
      ++st.perturbed;
    }
    count_step(d, st);
    const double inv = d != 0 ? 1.0 / d : 0.0;
    double* l = &A(0, s);
    for (index_t i = s + 1; i < m; ++i) l[i] *= inv;
    for (index_t c = s + 1; c < p; ++c) {
      const double u = A(s, c);
      if (u == 0.0) continue;
      double* col = &A(0, c);
      for (index_t i = s + 1; i < m; ++i) col[i] -= l[i] * u;
    }
    return d;
  };
  auto count_inertia = [&](double d) {
    if (d > 0)
      ++st.positive;
    else if (d < 0)
      ++st.negative;
    else
      ++st.zero;
  };

  const double u = policy.threshold;
  index_t s = 0;
  index_t last = p;  // candidates are s..last-1; last..p-1 were refused (delayed)
  while (s < last) {
    const index_t j = s;
    const double gj = column_max(j, s, j, j);
    // the candidate partner of the largest |a_rj|
    index_t r = -1;
    double arj = 0;
    for (index_t i = s + 1; i < last; ++i)
      if (std::abs(A(i, j)) > arj) arj = std::abs(A(i, j)), r = i;
    const double ajj = std::abs(A(j, j));
    enum { none, one_j, one_r, two } choice = none;
    if (policy.may_delay) {
      if (ajj > policy.tiny && ajj >= u * gj) {
        choice = one_j;
      } else if (r >= 0) {
        const double gj2 = column_max(j, s, j, r), gr2 = column_max(r, s, j, r);
        const double det = A(j, j) * A(r, r) - A(r, j) * A(j, r);
        const double piv0 = std::max(ajj, arj), adet = std::abs(det);
        const double piv1 = piv0 > 0 ? adet / piv0 : 0.0;
        if (piv0 > policy.tiny && piv1 > policy.tiny &&
            std::abs(A(r, r)) * gj2 + std::abs(A(j, r)) * gr2 <= adet / u &&
            std::abs(A(r, j)) * gj2 + ajj * gr2 <= adet / u)
          choice = two;
      }
      if (choice == none) {  // refused: behind the remaining candidates, row and column
        --last;
        sym_swap(j, last);
        continue;
      }
    } else if (ajj >= kBunchKaufmanAlpha * gj || r < 0 || arj == 0) {
      choice = one_j;  // (a zero column: the static pivot below)
    } else {
      const double gr = column_max(r, s, r, r);
      if (ajj * gr >= kBunchKaufmanAlpha * gj * gj)
        choice = one_j;
      else if (std::abs(A(r, r)) >= kBunchKaufmanAlpha * gr)
        choice = one_r;
      else
        choice = two;
    }
    if (choice == one_j || choice == one_r) {
      if (choice == one_r) sym_swap(s, r);
      count_inertia(eliminate(s));
      ++s;
      continue;
    }
    // a 2×2 pivot at s, s+1: r beside j, then the larger of D's first column on top
    sym_swap(s + 1, r);
    const double det = A(s, s) * A(s + 1, s + 1) - A(s + 1, s) * A(s, s + 1);
    const double trace = A(s, s) + A(s + 1, s + 1);
    if (std::abs(A(s + 1, s)) > std::abs(A(s, s))) {
      for (index_t c = 0; c < m; ++c) std::swap(A(s, c), A(s + 1, c));
      std::swap(row_perm[s], row_perm[s + 1]);
    }
    const index_t perturbed = st.perturbed;
    eliminate(s);
    eliminate(s + 1);
    ++st.two_by_two;
    if (st.perturbed != perturbed) {  // a root's singular block: inertia not known
      st.zero += 2;
    } else if (det < 0) {
      ++st.positive;
      ++st.negative;
    } else if (det > 0) {
      (trace > 0 ? st.positive : st.negative) += 2;
    } else {
      st.zero += 2;
    }
    s += 2;
  }

  // every pivot applied to the columns behind the candidates: their U rows, then their
  // Schur complement (the delayed rows and the contribution block's)
  const index_t k = s, nrest = m - p;
  if (k > 0 && nrest > 0) {
    const index_t blocks = (nrest + kUpdateColumns - 1) / kUpdateColumns;
    auto update = [&](index_t b) {
      const index_t c0 = p + b * kUpdateColumns;
      const index_t w = std::min(kUpdateColumns, m - c0);
      trsm('L', 'L', 'N', 'U', k, w, &A(0, 0), ld, &A(0, c0), ld);
      gemm('N', 'N', m - k, w, k, -1.0, &A(k, 0), ld, &A(0, c0), ld, 1.0, &A(k, c0), ld);
    };
    if (arena && blocks > 1 && arena->max_concurrency() > 1)
      // isolated: a thread waiting here takes no other front's task (see the LU kernel)
      arena->execute([&] {
        tbb::this_task_arena::isolate([&] { tbb::parallel_for(index_t{0}, blocks, update); });
      });
    else
      for (index_t b = 0; b < blocks; ++b) update(b);
  }
  return k;
}

}  // namespace strata::numeric::cpu
