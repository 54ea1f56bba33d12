// strata — power-of-two Ruiz equilibration of a refactorization's values (see rescale.hpp).
#include "core/rescale.hpp"

#include <algorithm>
#include <cmath>

namespace strata {
namespace {

// The power of two nearest to 1/√x (x > 0): an exact scale factor.
double inverse_sqrt_pow2(double x) {
  int e = 0;
  std::frexp(x, &e);  // x = f·2^e, f in [1/2, 1)
  return std::ldexp(1.0, -((e - 1) / 2));
}

bool within_factor_two(const std::vector<double>& maxima) {
  for (double v : maxima)
    if (v != 0 && (v < 0.5 || v > 2)) return false;
  return true;
}

}  // namespace

Rescaling rescale_values(const SparseMatrix& c, bool symmetric, std::vector<double>& values,
                         int max_sweeps) {
  const index_t n = c.n_cols;
  Rescaling out;
  std::vector<double> rmax(c.n_rows), cmax(n);
  auto maxima = [&] {
    std::fill(rmax.begin(), rmax.end(), 0.0);
    std::fill(cmax.begin(), cmax.end(), 0.0);
    for (index_t j = 0; j < n; ++j)
      for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
        const index_t i = c.indices[p];
        const double v = std::abs(values[p]);
        rmax[i] = std::max(rmax[i], v);
        cmax[j] = std::max(cmax[j], v);
        if (symmetric) {  // the mirrored entry (j, i)
          rmax[j] = std::max(rmax[j], v);
          cmax[i] = std::max(cmax[i], v);
        }
      }
  };
  maxima();
  if (within_factor_two(rmax) && within_factor_two(cmax)) return out;
  out.row.assign(c.n_rows, 1.0);
  out.col.assign(n, 1.0);
  std::vector<double> r(c.n_rows), s(n);
  for (; out.sweeps < max_sweeps; ++out.sweeps) {
    if (out.sweeps > 0) {
      maxima();
      if (within_factor_two(rmax) && within_factor_two(cmax)) break;
    }
    for (index_t i = 0; i < c.n_rows; ++i) r[i] = rmax[i] > 0 ? inverse_sqrt_pow2(rmax[i]) : 1.0;
    for (index_t j = 0; j < n; ++j) s[j] = cmax[j] > 0 ? inverse_sqrt_pow2(cmax[j]) : 1.0;
    // symmetric: the maxima are mirrored, so r == s and D·B·D stays symmetric
    for (index_t j = 0; j < n; ++j)
      for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) values[p] *= r[c.indices[p]] * s[j];
    for (index_t i = 0; i < c.n_rows; ++i) out.row[i] *= r[i];
    for (index_t j = 0; j < n; ++j) out.col[j] *= s[j];
  }
  return out;
}

}  // namespace strata
