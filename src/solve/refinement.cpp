// strata — iterative refinement and GMRES after the first solve (see refinement.hpp).
#include "solve/refinement.hpp"

#include <algorithm>

namespace strata::solve {

RefinementResult refine(index_t n, index_t nrhs, const Operator& a, const BlockOperator& m_inv,
                        double norm_a, const double* b, double* x, const RefinementSettings& s) {
  RefinementResult res;
  std::vector<double> r(static_cast<std::size_t>(n) * nrhs), d(r.size());
  auto berr_of = [&](index_t col) {
    return backward_error(n, a, norm_a, b + col * n, x + col * n, r.data() + col * n);
  };
  std::vector<double>& berr = res.backward_error;
  berr.assign(nrhs, 0.0);
  std::vector<double> last(nrhs);
  std::vector<char> active(nrhs, 1);
  for (index_t c = 0; c < nrhs; ++c) berr[c] = berr_of(c);
  for (; res.steps < s.max_steps; ++res.steps) {
    bool any = false;
    for (index_t c = 0; c < nrhs; ++c) {
      if (active[c] && berr[c] <= s.tolerance) active[c] = 0;
      any |= active[c] != 0;
    }
    if (!any) break;
    m_inv(r.data(), d.data(), nrhs);
    bool improved = false;
    for (index_t c = 0; c < nrhs; ++c) {
      if (!active[c]) continue;
      std::vector<double> saved(x + c * n, x + (c + 1) * n);
      for (index_t i = 0; i < n; ++i) x[i + c * n] += d[i + c * n];
      last[c] = berr[c];
      berr[c] = berr_of(c);
      if (berr[c] > 0.5 * last[c]) {  // no longer converging: keep the better iterate
        if (berr[c] > last[c]) {
          std::copy(saved.begin(), saved.end(), x + c * n);
          berr[c] = last[c];
          berr_of(c);
        }
        active[c] = 0;
      } else {
        improved = true;
      }
    }
    if (!improved) {
      ++res.steps;
      break;
    }
  }
  // refinement stalled above what can be checked: GMRES preconditioned by the factor
  const double enough = std::max(s.tolerance, s.floor);
  if (s.gmres_max_iterations > 0) {
    const Operator op_m = [&](const double* in, double* out) { m_inv(in, out, 1); };
    for (index_t c = 0; c < nrhs; ++c) {
      if (berr[c] <= enough) continue;
      const GmresResult g =
          gmres(n, a, op_m, norm_a, b + c * n, x + c * n, 50, s.gmres_max_iterations, enough);
      res.gmres_iterations += g.iterations;
      berr[c] = std::min(berr[c], g.backward_error);
    }
  }
  return res;
}

}  // namespace strata::solve
