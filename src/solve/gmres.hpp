// strata — restarted GMRES, right-preconditioned by the sparse factorization.
//
// When static pivoting perturbed pivots, the factor M is that of a nearby matrix and
// A M⁻¹ = I + (a perturbation of rank ≈ the number of perturbed pivots); iterative
// refinement may then stall, while GMRES converges in about that many iterations.
// (Arioli, Duff, Gratton & Pralet, "A note on GMRES preconditioned by a perturbed LDLᵀ
// decomposition with static pivoting", SIAM J. Sci. Comput. 29(5), 2007; Saad & Schultz
// 1986 for GMRES.)
#pragma once

#include <functional>

#include "strata/types.hpp"

namespace strata::solve {

/// y = op(x) for vectors of length n.
using Operator = std::function<void(const double* x, double* y)>;

/// Normwise backward error ‖b − A x‖∞ / (norm_a·‖x‖∞ + ‖b‖∞) of x, with r = b − A x
/// (length n) left in `r`. +inf when x or the residual is not finite (an overflow in
/// A x, or a NaN): never NaN, and never small because of a NaN that max() skipped.
double backward_error(index_t n, const Operator& a, double norm_a, const double* b, const double* x,
                      double* r);

/// The same backward error from the three maxima r_max = ‖b − A x‖∞, x_max = ‖x‖∞ and
/// b_max = ‖b‖∞ (computed elsewhere, e.g. on a GPU): +inf when r_max or x_max is not
/// finite (a NaN's magnitude included).
double backward_error_of(double r_max, double x_max, double b_max, double norm_a);

struct GmresResult {
  int iterations = 0;
  double backward_error = 0;  ///< normwise, of the returned x (true residual)
};

/// Solves A x = b for one right-hand side by flexible GMRES(restart) with preconditioner
/// M⁻¹, starting from the given x, until the normwise backward error
/// ‖b − A x‖∞ / (norm_a·‖x‖∞ + ‖b‖∞) ≤ tolerance or max_iterations iterations.
/// x has n entries and is overwritten; never returns an iterate worse than the start.
GmresResult gmres(index_t n, const Operator& a, const Operator& m_inv, double norm_a,
                  const double* b, double* x, int restart, int max_iterations, double tolerance);

}  // namespace strata::solve
