// strata — static pivots corrected in the solve by a low-rank update
// (Options::pivoting = Pivoting::corrected; internal).
//
// A refactorization in the analysis's fixed order factors B = R·A(:,Q)·C (the matching's
// scaling times the refactorization's rescaling, in the analysis's pivot order) without
// delaying pivots. When the values have drifted from those the analysis saw, some pivot's
// fully summed column is tiny (a constraint row whose largest entry has moved elsewhere):
// static pivoting then replaces it by ±ε‖B‖₁, and since that pivot divides the rest of its
// column, the factor's entries grow by up to 1/ε and its solutions lose about half of their
// digits.
//
// Here (numeric/static_pivot.hpp) such a pivot p is shifted instead: p + sign(p)·c with
// c = kCorrectedPivotShift ≈ 1, of the size of B's largest entries. The pivot is then a
// regular one and the factor's entries stay bounded, and the factor is exactly (to one
// rounding per shift) that of B plus σ_l = sign(p)·c at each of the k pivots' entries
// (the row the front's threshold partial pivoting chose, the pivot's column; the later
// steps of the elimination are those of that matrix). In A's numbering, F = A + E with
//
//     E = U·Γ·Vᵀ,  U = [e_{i_1} … e_{i_k}],  V = [e_{j_1} … e_{j_k}],  Γ = diag(σ_l/(r_{i_l}
//     c_{j_l})),
//
// (i_l, j_l) those entries' row and column of A and r, c the total row and column
// scalings. The solve corrects the factor's solutions by the Sherman–Morrison–Woodbury
// formula (Golub & Van Loan, "Matrix Computations", 4th ed., §2.1.4; with static pivots:
// Arioli, Duff, Gratton & Pralet, SIAM J. Sci. Comput. 29 (2007), where GMRES with the
// perturbed factor converges in k + 1 steps):
//
//     A⁻¹ = F⁻¹ + F⁻¹U·(Γ⁻¹ − VᵀF⁻¹U)⁻¹·VᵀF⁻¹.
//
// At the factorization: W = F⁻¹·U·D_r⁻¹ (k solves with the factor, D_r = diag(r_{i_l})),
// S = D_c⁻¹·(Γ⁻¹ − VᵀF⁻¹U)·D_r⁻¹, i.e. S_lm = δ_lm/σ_l − W(j_l, m)/c_{j_l} (D_c =
// diag(c_{j_l})), a k×k matrix of order one whatever A's scaling, its rows equilibrated
// (D·S), and the LU of D·S with partial pivoting and its reciprocal condition number
// (LAPACK getrf, gecon). Per solve, after x = F⁻¹b: t_l = x(j_l)/c_{j_l},
// y = S⁻¹t = (D·S)⁻¹·D·t, x += W·y. S is singular exactly when A is
// (det A = det F · Π σ_l · det S); a D·S whose reciprocal condition is below 10⁻³ (its
// solves would lose more than three digits: A nearly singular, or F so ill-conditioned
// that S's entries come from cancellation) sends the factorization to delayed pivoting,
// which reports A's numerical singularity where there is one. The formula is not backward
// stable in general (Yip, SIAM J. Sci. Stat. Comput. 7 (1986)): its error grows with the
// conditioning of F and S, and F, the fixed order's factor of A + E, may grow where the
// analysis's stale matching leaves small pivots that are not static ones. So k is bounded
// (Options::max_corrected_pivots), the factorization's W-solve carries one more column, a
// probe b = A·x̂ whose corrected solution must reach the backward error of a checked
// solve within one refinement step (else delayed pivoting takes over), and every
// corrected solve is checked and refined.
#pragma once

#include <functional>
#include <limits>
#include <vector>

#include "strata/types.hpp"

namespace strata::detail {

struct SolverState;

/// The entry of a shifted pivot: its row and column (0-based, A's original numbering; not
/// necessarily an entry of A's pattern), the shift σ of B there, and the total row and
/// column scalings r_i, c_j of B = R·A(:,Q)·C at it.
struct CorrectedEntry {
  index_t row = 0, col = 0;
  double shift = 0;
  double row_scale = 1, col_scale = 1;
};

/// The low-rank correction of one factorization (see above).
struct PivotCorrection {
  std::vector<CorrectedEntry> entries;
  std::vector<double> w;            ///< n × k, column-major: F⁻¹·U·D_r⁻¹
  std::vector<double> s_row_scale;  ///< k: D, 1 / the largest entry of each row of S
  std::vector<double> s_lu;         ///< k × k, column-major: the LU of D·S (getrf)
  std::vector<int> ipiv;            ///< getrf's row interchanges (1-based)
  double log_abs_det = 0;           ///< log|det S|
  int det_sign = 1;                 ///< sign of det S
  bool active = false;              ///< the solve applies it (set once it is complete)
  /// the probe's backward error (correction_probe) when one ran for this factorization,
  /// kept or not; NaN otherwise
  double probe_backward_error = std::numeric_limits<double>::quiet_NaN();

  index_t k() const { return static_cast<index_t>(entries.size()); }
  void clear();
};

/// The entries where the last fixed-order factorization of `s`, made with a negative
/// static pivot (PivotPolicy), shifted pivots (NumericFactor::static_pivot_at of the
/// fronts that count perturbed pivots), into `out` (replaced). Returns false when they
/// cannot all be told (a front marks another number of pivots than it counts).
bool find_shifted_pivots(const SolverState& s, std::vector<CorrectedEntry>& out);

/// Completes c for its entries and the factor of A + E just made: W by one call of
/// `apply_factor` (x = F⁻¹b for n × nrhs columns, original numbering, no correction), S
/// and its LU. With `probe_b` (n entries, or null) the same call also solves with it, and
/// `probe_x` (n entries) receives the corrected solution A⁻¹·probe_b. Returns true and
/// sets c.active when D·S's reciprocal condition number is at least 10⁻³ (its solves lose
/// at most three digits), else false (probe_x then unspecified).
bool build_correction(
    PivotCorrection& c, index_t n,
    const std::function<void(const double* b, double* x, index_t nrhs)>& apply_factor,
    const double* probe_b = nullptr, double* probe_x = nullptr);

/// The probe solution x̂ of a correction's test (n entries, none zero, of one sign pattern
/// that no structure of A favours): x̂_i = (−1)^i·(1 + (i mod 3)/2). A correction is kept
/// only when its solve of A·x = A·x̂ reaches the backward error every checked solve must
/// reach (Options::refinement_tolerance, or the rounding floor) within one refinement
/// step: the rcond test of D·S bounds S's own error, not the growth in the fixed order's
/// factor of A + E.
void correction_probe(index_t n, double* x_hat);

/// x (n × nrhs, column-major, original numbering) = F⁻¹b on entry, A⁻¹b on return.
void apply_correction(const PivotCorrection& c, index_t n, double* x, index_t nrhs);

}  // namespace strata::detail
