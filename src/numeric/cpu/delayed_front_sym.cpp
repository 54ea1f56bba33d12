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
// Blocked as the LU kernel is: pivots are taken in panels of about kPanel, inside a panel
// left-looking (the candidate column tested, and for a 2×2 test its partner's, brought up
// to date with the panel's earlier pivots over all m rows, in a copy), after it
// right-looking (the U rows of every column behind the panel by a triangular solve, then
// one GEMM for their Schur complement), in blocks of columns that run on the arena's
// threads when one is given. A symmetric interchange moves whole rows and whole columns:
// both rows lie below the panel's earlier pivots and both columns behind them, where every
// entry still waits for the same update.
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "numeric/cpu/delayed_front.hpp"
#include "strata/errors.hpp"

namespace strata::numeric::cpu {
namespace {

// Pivots per panel (a 2×2 pivot may end a panel one past it).
constexpr index_t kPanel = 32;

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
  check_delayed_front(m, p, ld, policy, "delayed symmetric front");
  auto A = [&](index_t i, index_t j) -> double& { return f[i + j * ld]; };
  for (index_t i = 0; i < p; ++i) row_perm[i] = col_perm[i] = i;
  // positions a, b (candidates behind the panel's pivots) interchanged symmetrically
  auto sym_swap = [&](index_t a, index_t b) {
    if (a == b) return;
    for (index_t c = 0; c < m; ++c) std::swap(A(a, c), A(b, c));
    for (index_t i = 0; i < m; ++i) std::swap(A(i, a), A(i, b));
    std::swap(row_perm[a], row_perm[b]);
    std::swap(col_perm[a], col_perm[b]);
  };
  index_t j0 = 0;  // the panel's first pivot
  index_t s = 0;   // the next pivot position
  // column j brought up to date with the panel's pivots j0..s-1, rows j0..m-1 into col
  // (its first s − j0 entries are its U rows)
  auto current = [&](index_t j, std::vector<double>& col) {
    col.assign(&A(j0, j), &A(j0, j) + (m - j0));
    for (index_t c = 0; c < s - j0; ++c) {
      const double u = col[c];
      if (u == 0.0) continue;
      const double* l = &A(j0, j0 + c);
      for (index_t i = c + 1; i < m - j0; ++i) col[i] -= l[i] * u;
    }
  };
  // the largest |entry| of an up-to-date column over rows s..m-1 outside rows x and y
  auto column_max = [&](const std::vector<double>& col, index_t x, index_t y) {
    double g = 0;
    for (index_t i = s; i < m; ++i)
      if (i != x && i != y) g = std::max(g, std::abs(col[i - j0]));
    return g;
  };
  // L's column at position t (its up-to-date values in place): a root's pivot under
  // static_pivot replaced first
  auto scale_column = [&](index_t t) {
    double d = A(t, t);
    if (!policy.may_delay && std::abs(d) < policy.static_pivot) {
      d = d < 0 ? -policy.static_pivot : policy.static_pivot;
      A(t, t) = d;
      ++st.perturbed;
    }
    count_step(d, st);
    const double inv = d != 0 ? 1.0 / d : 0.0;
    for (index_t i = t + 1; i < m; ++i) A(i, t) *= inv;
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
  std::vector<double> cs, cr;  // the up-to-date candidate column and its partner's
  index_t last = p;            // candidates are s..last-1; last..p-1 were refused (delayed)
  while (s < last) {
    j0 = s;
    while (s < last && s - j0 < kPanel) {
      current(s, cs);
      const double gj = column_max(cs, s, s);
      const double ajj = std::abs(cs[s - j0]);
      index_t r = -1;  // the candidate partner of the largest |a_rs|
      double ars = 0;
      for (index_t i = s + 1; i < last; ++i)
        if (std::abs(cs[i - j0]) > ars) ars = std::abs(cs[i - j0]), r = i;
      enum { none, one_s, one_r, two } choice = none;
      if (policy.may_delay) {
        if (ajj > policy.tiny && ajj >= u * gj) {
          choice = one_s;
        } else if (r >= 0) {
          current(r, cr);
          const double gs2 = column_max(cs, s, r), gr2 = column_max(cr, s, r);
          const double arr = std::abs(cr[r - j0]), asr = std::abs(cr[s - j0]);
          const double det = cs[s - j0] * cr[r - j0] - cs[r - j0] * cr[s - j0];
          const double piv0 = std::max(ajj, ars), adet = std::abs(det);
          const double piv1 = piv0 > 0 ? adet / piv0 : 0.0;
          if (piv0 > policy.tiny && piv1 > policy.tiny && arr * gs2 + asr * gr2 <= adet / u &&
              ars * gs2 + ajj * gr2 <= adet / u)
            choice = two;
        }
        if (choice == none) {  // refused: behind the remaining candidates, row and column
          --last;
          sym_swap(s, last);
          continue;
        }
      } else if (ajj >= kBunchKaufmanAlpha * gj || r < 0 || ars == 0) {
        choice = one_s;  // (a zero column: the static pivot)
      } else {
        current(r, cr);
        const double gr = column_max(cr, r, r);
        if (ajj * gr >= kBunchKaufmanAlpha * gj * gj)
          choice = one_s;
        else if (std::abs(cr[r - j0]) >= kBunchKaufmanAlpha * gr)
          choice = one_r;
        else
          choice = two;
      }
      // the chosen columns' up-to-date copies follow the interchange of rows: position t
      // of `col` was row t before sym_swap(a, b) moved rows a and b
      auto swap_rows_of = [&](std::vector<double>& col, index_t a, index_t b) {
        std::swap(col[a - j0], col[b - j0]);
      };
      if (choice == one_s || choice == one_r) {
        if (choice == one_r) {
          sym_swap(s, r);
          swap_rows_of(cr, s, r);
        }
        const std::vector<double>& col = choice == one_r ? cr : cs;
        std::copy(col.begin(), col.end(), &A(j0, s));
        count_inertia(scale_column(s));
        ++s;
        continue;
      }
      // a 2×2 pivot at s, s+1: the partner r beside s, then the larger entry of D's first
      // column on top, then two elimination steps on the two columns
      sym_swap(s + 1, r);
      swap_rows_of(cs, s + 1, r);
      swap_rows_of(cr, s + 1, r);
      std::copy(cs.begin(), cs.end(), &A(j0, s));
      std::copy(cr.begin(), cr.end(), &A(j0, s + 1));
      const double det = A(s, s) * A(s + 1, s + 1) - A(s + 1, s) * A(s, s + 1);
      const double trace = A(s, s) + A(s + 1, s + 1);
      if (std::abs(A(s + 1, s)) > std::abs(A(s, s))) {
        for (index_t c = 0; c < m; ++c) std::swap(A(s, c), A(s + 1, c));
        std::swap(row_perm[s], row_perm[s + 1]);
      }
      const index_t perturbed = st.perturbed;
      scale_column(s);
      const double u01 = A(s, s + 1);
      if (u01 != 0.0)
        for (index_t i = s + 1; i < m; ++i) A(i, s + 1) -= A(i, s) * u01;
      scale_column(s + 1);
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
    // the panel's pivots applied to every column behind it (the candidates left, the
    // refused ones and the contribution block's)
    update_behind_panel(f, m, ld, j0, s, arena);
  }
  return s;
}

}  // namespace strata::numeric::cpu
