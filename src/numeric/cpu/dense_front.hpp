// strata — dense partial factorization of one front on the CPU (BLAS/LAPACK).
//
// A front F is an m×m dense column-major matrix (leading dimension ld ≥ m) whose first
// k rows/columns are fully summed (the pivot block). A partial factorization eliminates
// those k pivots and leaves the Schur complement (the contribution block, update matrix)
// in F[k:m, k:m]:
//
//   LLᵀ:  F = [F11 F21ᵀ; F21 F22] (lower triangle referenced)
//         → L11 (lower, F[0:k,0:k]), L21 = F21 L11⁻ᵀ (F[k:m,0:k]),
//           S = F22 − L21 L21ᵀ (lower triangle of F[k:m,k:m]).
//   LDLᵀ: P F11 Pᵀ = L11 D L11ᵀ with Bunch–Kaufman 1×1/2×2 pivots chosen only among the k
//         fully summed columns (restricted pivoting); L11 unit lower in F[0:k,0:k] below
//         the diagonal, D on the diagonal (2×2 blocks use F(j+1,j) as off-diagonal),
//         L21 = F21 Pᵀ L11⁻ᵀ D⁻¹ in F[k:m,0:k], S = F22 − L21 D L21ᵀ (lower triangle).
//   LU:   P F11 = L11 U11 with partial pivoting among the k fully summed rows; F full.
//         L11 unit lower and U11 upper in F[0:k,0:k], U12 = L11⁻¹ P F12 in F[0:k,k:m],
//         L21 = F21 U11⁻¹ in F[k:m,0:k], S = F22 − L21 U12 in F[k:m,k:m].
//
// Static pivoting (LDLᵀ, LU): a pivot with |p| < static_pivot is replaced by
// sign(p)·static_pivot (sign(0) taken as +) and counted; no pivot is ever delayed
// (Duff & Pralet 2007; Li & Demmel 1998, SuperLU_DIST's GESP).
//
// Sources: Bunch & Kaufman 1977; Golub & Van Loan, "Matrix Computations", 4th ed., §4.4
// (blocked LDLᵀ) and §3.4 (blocked LU).
#pragma once

#include "base/lower_panels.hpp"
#include "numeric/pivot_stats.hpp"
#include "strata/types.hpp"

namespace strata::numeric::cpu {

/// LLᵀ partial factorization (dpotrf, dtrsm, dsyrk). Returns -1 on success, or the local
/// index (0..k-1) of the first pivot that is not positive (F is then partly overwritten).
index_t factor_front_llt(double* f, index_t m, index_t k, index_t ld, PivotStats& stats);

/// The same LLᵀ partial factorization with the front in two pieces: `panel` holds the
/// first k columns (m × k, leading dimension ld ≥ m: L11 and L21 on return) and `cb` the
/// lower triangle of F22 (order m − k, in column panels: base/lower_panels.hpp; S on
/// return). Lets the CPU executor form the panel in the factor's storage and the
/// contribution block on its stack, in about half a square, with no m × m workspace.
/// Returns as above; throws InternalError when cb's order is not m − k.
index_t factor_front_llt(double* panel, index_t m, index_t k, index_t ld, const LowerPanels& cb,
                         PivotStats& stats);

/// LDLᵀ partial factorization with restricted Bunch–Kaufman pivoting (α = (1+√17)/8) and
/// static pivoting. On return local_perm[0..k) gives the symmetric permutation applied to
/// the pivot block: position i now holds original local index local_perm[i]; and
/// pivot_size[i] is 1 for a 1×1 pivot, 2 for both columns of a 2×2 pivot.
void factor_front_ldlt(double* f, index_t m, index_t k, index_t ld, double static_pivot,
                       index_t* local_perm, int* pivot_size, PivotStats& stats);

/// The LDLᵀ statistics of k pivots from D alone, in the factor's layout (by pivot
/// position: d_diag, d_off and pivot_size 1, or 2 then 0 for a 2×2 pivot): inertia,
/// two_by_two, log_abs_det, det_sign, computed exactly as factor_front_ldlt computes them
/// while it factors (so the two agree bitwise). `perturbed` is left alone: D does not show
/// which pivots were replaced. Used by executors whose kernels return D but no statistics
/// (the CUDA backend).
void ldlt_stats_from_d(index_t k, const double* d_diag, const double* d_off, const int* pivot_size,
                       PivotStats& stats);

/// LU partial factorization of the m×m front f (column-major, leading dimension ld ≥ m)
/// in its k fully summed rows and columns, with threshold partial pivoting restricted to
/// the fully summed rows (Duff, Erisman & Reid, "Direct Methods for Sparse Matrices", 2nd
/// ed., §5.4): column j keeps its diagonal pivot when |a_jj| ≥ threshold·max_{j≤i<k}
/// |a_ij|, else takes the largest of those entries, the first on ties (threshold = 1:
/// partial pivoting); then static pivoting (|pivot| < static_pivot → ±static_pivot). On
/// return local_perm[0..k) gives the row permutation of the pivot block: row i now holds
/// original local row local_perm[i] (rows k..m are not moved). threshold in (0, 1].
void factor_front_lu(double* f, index_t m, index_t k, index_t ld, double static_pivot,
                     double threshold, index_t* local_perm, PivotStats& stats);

}  // namespace strata::numeric::cpu
