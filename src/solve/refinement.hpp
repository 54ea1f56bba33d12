// strata — the checked solve: iterative refinement with the factorization, and flexible
// GMRES preconditioned by it where refinement stalls (solve/gmres.hpp).
//
// Given x = M⁻¹ b from one application of the factor M ≈ A, each right-hand side's
// normwise backward error ‖b − A x‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) is computed; while it is above
// the tolerance and falls by at least half per step, x += M⁻¹ (b − A x) (Wilkinson;
// Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed., §12.1: one step in
// working precision makes the solve componentwise stable when M is a good enough factor).
// A step that makes it worse is undone. The steps are written once over a RefinementSpace,
// the vectors where they live (host arrays here, a GPU's memory in the solve phase, so that
// the residuals of a factor resident on a GPU need no copy of x). Columns that stall above
// max(tolerance, floor) go
// to GMRES (Arioli, Duff, Gratton & Pralet 2007: after static pivoting A M⁻¹ is the
// identity plus a low-rank perturbation, which GMRES resolves in a few iterations). The
// floor is the rounding level of the residual, (m+1)·u for m the most entries in a row of
// A (Higham §3.5): below it a backward error cannot be told from zero.
#pragma once

#include <functional>
#include <vector>

#include "solve/gmres.hpp"
#include "strata/types.hpp"

namespace strata::solve {

/// x = M⁻¹ b for nrhs columns of length n (column-major, leading dimension n).
using BlockOperator = std::function<void(const double* b, double* x, index_t nrhs)>;

struct RefinementSettings {
  int max_steps = 10;              ///< refinement steps at most (0: none)
  double tolerance = 1e-15;        ///< backward error at which a column is done
  double floor = 0;                ///< the residual's rounding level (see above)
  int gmres_max_iterations = 200;  ///< per column, restarted every 50 (0: no GMRES)
};

struct RefinementResult {
  int steps = 0;                       ///< refinement steps taken (over all columns)
  int gmres_iterations = 0;            ///< total over the columns
  std::vector<double> backward_error;  ///< per column, of the returned x
};

/// The vectors of a refinement of nrhs columns (b, x, the residual r, the correction d and
/// a kept copy of x), wherever they live.
class RefinementSpace {
 public:
  virtual ~RefinementSpace() = default;
  /// r = b − A x and each column's normwise backward error into berr (nrhs; +inf for a
  /// column whose residual or x is not finite), for every column, or for the columns c
  /// with active[c] where `active` is given (the others may be left as they were).
  virtual void residual(double* berr, const char* active) = 0;
  /// d = M⁻¹ r for every column.
  virtual void correct() = 0;
  /// Keeps column c of x, then x(:, c) += d(:, c).
  virtual void step(index_t c) = 0;
  /// x(:, c) = the copy the last step(c) kept.
  virtual void undo(index_t c) = 0;
};

/// The refinement steps alone over `space` (x = M⁻¹ b on entry): at most max_steps, while
/// a column's backward error is above `tolerance` and halves per step; a step that made a
/// column worse undone. Returns the steps taken and each column's backward error.
RefinementResult refine_steps(RefinementSpace& space, index_t nrhs, int max_steps,
                              double tolerance);

/// Refines x (n × nrhs, column-major, x = m_inv(b) on entry) towards A x = b; `a` applies
/// A to one column, norm_a is ‖A‖∞. Never returns a column worse than it came in.
RefinementResult refine(index_t n, index_t nrhs, const Operator& a, const BlockOperator& m_inv,
                        double norm_a, const double* b, double* x, const RefinementSettings& s);

}  // namespace strata::solve
