// strata — partial factorization of one front with threshold pivoting and delayed pivots.
//
// The fixed-layout kernels of dense_front.hpp eliminate every fully summed pivot of a
// front, replacing a tiny one by a static pivot. Here a pivot that fails a relative
// threshold test is not taken: its row and column stay uneliminated and go to the parent
// front with the contribution block (delayed pivoting: Duff & Reid, "The multifrontal
// solution of indefinite sparse symmetric linear equations", ACM TOMS 9, 1983; MA57 and
// MUMPS, Amestoy, Duff, L'Excellent & Koster, SIAM J. Matrix Anal. Appl. 23, 2001). At the
// parent more rows are fully summed, so a good pivot is usually there; at a root every row
// is fully summed and the only pivots still refused are those of a numerically singular
// matrix, which are then replaced by static pivots (the last resort, counted).
//
// A front F is m×m, column-major (leading dimension ld); its first p rows and columns are
// fully summed (the candidates). LU eliminates column by column (right-looking within
// the p candidate columns): for the next candidate column j, the pivot is the largest
// entry among the remaining fully summed rows, taken when it is at least `threshold` times
// the largest entry of column j over all remaining rows, contribution-block rows included
// (so |L21| ≤ 1/threshold: the growth bound of threshold partial pivoting), and larger
// than `tiny`; otherwise column j is moved behind the remaining candidates and skipped.
// Rows and columns permute independently, so the delayed rows and the delayed columns may
// be different variables (MUMPS's unsymmetric fronts keep separate row and column lists
// for the same reason).
#pragma once

#include <tbb/task_arena.h>

#include "numeric/cpu/dense_front.hpp"
#include "strata/types.hpp"

namespace strata::numeric::cpu {

/// Threshold pivoting settings of a front.
struct DelayPolicy {
  double threshold = 0.01;  ///< relative threshold u in (0, 1] (MUMPS CNTL(1)'s default)
  double tiny = 0;        ///< a pivot of magnitude ≤ tiny is never taken while it may be delayed
  bool may_delay = true;  ///< false at a root: every candidate is eliminated
  double static_pivot = 0;  ///< with may_delay false: |pivot| < static_pivot becomes ±static_pivot
};

/// LU of the p fully summed columns of an m×m front with threshold partial pivoting and
/// delayed pivots (see the header above). Returns the number of pivots eliminated, npiv
/// (npiv = p when !policy.may_delay). On return, with the rows and columns of F permuted
/// within the first p by row_perm[0..p) and col_perm[0..p) (position i holds original
/// local row row_perm[i], column col_perm[i]; positions p..m unmoved):
///   F[0:npiv, 0:npiv]   L11 (unit lower, not stored) and U11,
///   F[npiv:m, 0:npiv]   L21 = F21 U11⁻¹,
///   F[0:npiv, npiv:m]   U12 = L11⁻¹ F12 (delayed columns first),
///   F[npiv:m, npiv:m]   the Schur complement; its first p − npiv rows and columns are the
///                       delayed ones.
/// stats counts the npiv pivots (sign and log|u_ii| of U11; the permutations' parity is
/// the caller's) and the static pivots. After each panel of pivots, the update of the
/// columns behind it (TRSM and GEMM) is made in blocks of 128 columns; with `arena` (of
/// more than one thread) the blocks run on its threads, each with the BLAS as the caller
/// set it (one thread, for a parallel update without the BLAS's own threads). The factor
/// is bitwise the same with or without an arena. Throws InvalidInput for inconsistent
/// sizes.
index_t factor_front_lu_delayed(double* f, index_t m, index_t p, index_t ld,
                                const DelayPolicy& policy, index_t* row_perm, index_t* col_perm,
                                PivotStats& stats, tbb::task_arena* arena = nullptr);

/// Throws InvalidInput, its message starting with `what`, unless 0 ≤ p ≤ m ≤ ld (ld ≥ 1) and
/// policy.threshold is in (0, 1]: the two front kernels' arguments.
void check_delayed_front(index_t m, index_t p, index_t ld, const DelayPolicy& policy,
                         const char* what);

/// A panel's pivots j0..k−1 (L's columns and U's rows in place, L unit lower) applied to the
/// columns k..m−1 of an m×m front F (leading dimension ld): their U rows F[j0:k, k:m] =
/// L11⁻¹·F[j0:k, k:m] by forward substitution (zeros skipped), then their Schur complement
/// F[k:m, k:m] −= F[k:m, j0:k]·F[j0:k, k:m] by GEMM, in blocks of 128 columns that run on
/// `arena`'s threads when one of more than one thread is given (the same bits either way).
/// The right-looking step of both delayed front kernels.
void update_behind_panel(double* f, index_t m, index_t ld, index_t j0, index_t k,
                         tbb::task_arena* arena);

/// The symmetric counterpart (delayed_front_sym.cpp): the m×m front of a symmetric
/// indefinite matrix, given whole (both triangles), eliminated with symmetric interchanges
/// only, by 1×1 and 2×2 pivots chosen by a threshold test (MA57's) over the p fully summed
/// columns, the candidates no pivot can take delayed together with their rows; at a root
/// (!policy.may_delay) by the Bunch–Kaufman rule, a pivot step under static_pivot replaced
/// by ±static_pivot. Returns npiv; the factor is left in factor_front_lu_delayed's layout
/// and permutations (an LU: a 2×2 pivot is two elimination steps whose two rows may be
/// interchanged, so row_perm and col_perm differ at most within 2×2 pivots; the delayed
/// positions npiv..p hold the same variables in both). stats: the inertia of the pivots
/// (positive, negative, zero; a 2×2 pivot by its determinant and trace), two_by_two, the
/// perturbed pivots, and the sign and log|·| of the elimination steps' pivots (det of the
/// pivot block up to the row list's parity, which the caller applies). Throws InvalidInput
/// for inconsistent sizes or a threshold outside (0, 1].
index_t factor_front_sym_delayed(double* f, index_t m, index_t p, index_t ld,
                                 const DelayPolicy& policy, index_t* row_perm, index_t* col_perm,
                                 PivotStats& stats, tbb::task_arena* arena = nullptr);

}  // namespace strata::numeric::cpu
