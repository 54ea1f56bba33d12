// strata — restarted flexible GMRES (FGMRES) with modified Gram–Schmidt and Givens
// rotations (Saad, "Iterative Methods for Sparse Linear Systems", 2nd ed., Alg. 9.6).
// The preconditioned vectors z_j = M⁻¹ v_j are kept and the update is x += Z y: with a
// preconditioner that is applied inexactly — a factorization with perturbed pivots has a
// large ‖M⁻¹‖ — this variant stays backward stable where right-preconditioned GMRES
// (x += M⁻¹ V y) stalls (Arioli & Duff, "Using FGMRES to obtain backward stability in
// mixed precision", ETNA 33, 2009). Measured on nnc1374: GMRES stalled at 3.7e-13.
// See gmres.hpp for why the solver uses it.
#include "solve/gmres.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace strata::solve {
namespace {

double norm2(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x * x;
  return std::sqrt(s);
}

}  // namespace

double backward_error(index_t n, const Operator& a, double norm_a, const double* b, const double* x,
                      double* r) {
  a(x, r);
  double rn = 0, xn = 0, bn = 0;
  bool finite = true;
  for (index_t i = 0; i < n; ++i) {
    r[i] = b[i] - r[i];
    finite = finite && std::isfinite(r[i]) && std::isfinite(x[i]);
    rn = std::max(rn, std::abs(r[i]));
    xn = std::max(xn, std::abs(x[i]));
    bn = std::max(bn, std::abs(b[i]));
  }
  if (!finite) return std::numeric_limits<double>::infinity();
  return backward_error_of(rn, xn, bn, norm_a);
}

double backward_error_of(double rn, double xn, double bn, double norm_a) {
  if (!std::isfinite(rn) || !std::isfinite(xn)) return std::numeric_limits<double>::infinity();
  const double den = norm_a * xn + bn;
  // norm_a·‖x‖∞ past DBL_MAX (both finite): ‖b‖∞ is negligible beside it
  if (!std::isfinite(den)) return rn / xn / norm_a;
  return den > 0 ? rn / den : rn;
}

GmresResult gmres(index_t n, const Operator& a, const Operator& m_inv, double norm_a,
                  const double* b, double* x, int restart, int max_iterations, double tolerance) {
  GmresResult res;
  restart = std::max(1, restart);
  std::vector<double> r(n), w(n), z(n);
  std::vector<double> best(x, x + n);
  double berr = backward_error(n, a, norm_a, b, x, r.data());
  double best_berr = berr;
  std::vector<std::vector<double>> v(restart + 1, std::vector<double>(n));
  std::vector<std::vector<double>> zs(restart, std::vector<double>(n));
  std::vector<double> h((restart + 1) * restart), cs(restart), sn(restart), g(restart + 1);
  int stagnant = 0;
  while (berr > tolerance && res.iterations < max_iterations) {
    const double beta = norm2(r);
    if (beta == 0) break;
    // residual target in the 2-norm: ‖r‖∞ ≤ ‖r‖₂, so aim at the ∞-norm threshold
    double xn = 0, bn = 0;
    for (index_t i = 0; i < n; ++i) {
      xn = std::max(xn, std::abs(x[i]));
      bn = std::max(bn, std::abs(b[i]));
    }
    const double target = 0.5 * tolerance * (norm_a * xn + bn);
    for (index_t i = 0; i < n; ++i) v[0][i] = r[i] / beta;
    std::fill(g.begin(), g.end(), 0.0);
    g[0] = beta;
    int k = 0;
    for (; k < restart && res.iterations < max_iterations; ++k) {
      ++res.iterations;
      m_inv(v[k].data(), zs[k].data());
      a(zs[k].data(), w.data());
      for (int i = 0; i <= k; ++i) {  // modified Gram–Schmidt
        double d = 0;
        for (index_t t = 0; t < n; ++t) d += w[t] * v[i][t];
        h[i + k * (restart + 1)] = d;
        for (index_t t = 0; t < n; ++t) w[t] -= d * v[i][t];
      }
      const double hn = norm2(w);
      h[k + 1 + k * (restart + 1)] = hn;
      if (hn > 0)
        for (index_t t = 0; t < n; ++t) v[k + 1][t] = w[t] / hn;
      for (int i = 0; i < k; ++i) {  // apply previous rotations to column k
        double& h0 = h[i + k * (restart + 1)];
        double& h1 = h[i + 1 + k * (restart + 1)];
        const double t0 = cs[i] * h0 + sn[i] * h1;
        h1 = -sn[i] * h0 + cs[i] * h1;
        h0 = t0;
      }
      double& hk = h[k + k * (restart + 1)];
      double& hk1 = h[k + 1 + k * (restart + 1)];
      const double den = std::hypot(hk, hk1);
      cs[k] = den > 0 ? hk / den : 1.0;
      sn[k] = den > 0 ? hk1 / den : 0.0;
      hk = den;
      hk1 = 0;
      g[k + 1] = -sn[k] * g[k];
      g[k] = cs[k] * g[k];
      if (std::abs(g[k + 1]) <= target || hn == 0) {
        ++k;
        break;
      }
    }
    // y = H⁻¹ g (upper triangular k×k), x += M⁻¹ V y
    std::vector<double> y(k);
    for (int i = k - 1; i >= 0; --i) {
      double s = g[i];
      for (int j = i + 1; j < k; ++j) s -= h[i + j * (restart + 1)] * y[j];
      y[i] = h[i + i * (restart + 1)] != 0 ? s / h[i + i * (restart + 1)] : 0.0;
    }
    for (int j = 0; j < k; ++j)
      for (index_t t = 0; t < n; ++t) x[t] += y[j] * zs[j][t];
    const double previous = berr;
    berr = backward_error(n, a, norm_a, b, x, r.data());
    if (berr < best_berr) {
      best_berr = berr;
      std::copy(x, x + n, best.begin());
    }
    // The estimate may claim convergence that the true residual denies (an ill-conditioned
    // M⁻¹ after perturbed pivots); restarting from the true residual recovers, so give up
    // only after a few cycles without progress.
    stagnant = berr < 0.9 * previous ? 0 : stagnant + 1;
    if (stagnant >= 3) break;
  }
  std::copy(best.begin(), best.end(), x);
  res.backward_error = best_berr;
  return res;
}

}  // namespace strata::solve
