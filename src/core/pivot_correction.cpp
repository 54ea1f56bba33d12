// strata — static pivots corrected in the solve by a low-rank update (see
// pivot_correction.hpp for the method).
#include "core/pivot_correction.hpp"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

#include "base/blas.hpp"
#include "base/roundoff.hpp"
#include "core/solver_state.hpp"
#include "numeric/static_pivot.hpp"

namespace strata::detail {

namespace {

// S's solves lose about log10(1/rcond) digits: a correction that would lose more than
// three is left to delayed pivoting, whose solves a Newton loop then converges with as
// fast as with an exact factor (bench/history.md, "Static pivots corrected in the solve").
constexpr double kCorrectionMinRcond = 1e-3;

}  // namespace

void PivotCorrection::clear() {
  entries.clear();
  active = false;
  log_abs_det = 0;
  det_sign = 1;
  probe_backward_error = std::numeric_limits<double>::quiet_NaN();
}

bool find_shifted_pivots(const SolverState& s, std::vector<CorrectedEntry>& out) {
  const Analysis& an = *s.analysis;
  const auto& t = an.tree;
  const numeric::NumericFactor& fac = s.factor;
  out.clear();
  if (fac.static_pivot_at.size() != static_cast<std::size_t>(an.n)) return false;
  const bool scale = !an.row_scaling.empty();
  const bool match = !an.matching_perm.empty();
  const bool rescale = !s.rescaling.row.empty();
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    const index_t np = fac.front_stats[f].perturbed;
    if (np == 0) continue;
    index_t found = 0;
    for (index_t j = 0; j < t.n_pivots(f); ++j) {
      const unsigned char mark = fac.static_pivot_at[t.first_pivot[f] + j];
      if (mark == 0) continue;
      ++found;
      // B's entry (the pivot's row, its column) in tree numbering → A's: B's rows are
      // A's rows, column c of B is column matching_perm[c] of A
      CorrectedEntry e;
      e.row = an.perm[fac.rows[t.row_offsets[f] + j]];
      const index_t bc = an.perm[t.first_pivot[f] + j];
      e.col = match ? an.matching_perm[bc] : bc;
      e.shift = mark == 2 ? -numeric::kCorrectedPivotShift : numeric::kCorrectedPivotShift;
      e.row_scale =
          (scale ? an.row_scaling[e.row] : 1.0) * (rescale ? s.rescaling.row[e.row] : 1.0);
      e.col_scale =
          (scale ? an.col_scaling[e.col] : 1.0) * (rescale ? s.rescaling.col[e.col] : 1.0);
      out.push_back(e);
    }
    if (found != np) {
      out.clear();
      return false;
    }
  }
  return !out.empty();
}

bool build_correction(
    PivotCorrection& c, index_t n,
    const std::function<void(const double* b, double* x, index_t nrhs)>& apply_factor,
    const double* probe_b, double* probe_x) {
  c.active = false;
  const index_t k = c.k();
  if (k == 0) return false;
  const std::size_t nk = static_cast<std::size_t>(n) * static_cast<std::size_t>(k);
  const index_t columns = k + (probe_b ? 1 : 0);
  // W = F⁻¹·U·D_r⁻¹: column m solves with e_{i_m} / r_{i_m}; the probe's right-hand side
  // as column k of the same solve
  std::vector<double> u(nk + (probe_b ? n : 0), 0.0);
  for (index_t m = 0; m < k; ++m)
    u[static_cast<std::size_t>(m) * n + c.entries[m].row] = 1.0 / c.entries[m].row_scale;
  if (probe_b) std::copy(probe_b, probe_b + n, u.begin() + static_cast<std::ptrdiff_t>(nk));
  c.w.resize(nk + (probe_b ? n : 0));
  apply_factor(u.data(), c.w.data(), columns);
  if (probe_b) {
    std::copy(c.w.begin() + static_cast<std::ptrdiff_t>(nk), c.w.end(), probe_x);
    c.w.resize(nk);
  }
  for (double v : c.w)
    if (!std::isfinite(v)) return false;
  // S = D_c⁻¹·(Γ⁻¹ − Vᵀ·F⁻¹·U)·D_r⁻¹: S_lm = δ_lm/σ_l − W(j_l, m) / c_{j_l}
  c.s_lu.assign(static_cast<std::size_t>(k) * k, 0.0);
  for (index_t m = 0; m < k; ++m)
    for (index_t l = 0; l < k; ++l) {
      const CorrectedEntry& e = c.entries[l];
      c.s_lu[static_cast<std::size_t>(m) * k + l] =
          (l == m ? 1.0 / e.shift : 0.0) -
          c.w[static_cast<std::size_t>(m) * n + e.col] / e.col_scale;
    }
  // rows equilibrated (D·S, D = diag(1/max_m |S_lm|)), so that the condition number
  // measures S's nearness to singularity, not how differently its rows are scaled (a
  // diagonal S, pivots of independent blocks, is exact whatever its entries)
  c.s_row_scale.assign(k, 0.0);
  for (index_t m = 0; m < k; ++m)
    for (index_t l = 0; l < k; ++l)
      c.s_row_scale[l] =
          std::max(c.s_row_scale[l], std::abs(c.s_lu[static_cast<std::size_t>(m) * k + l]));
  for (index_t l = 0; l < k; ++l) {
    if (!(c.s_row_scale[l] > 0) || !std::isfinite(c.s_row_scale[l])) return false;  // singular
    c.s_row_scale[l] = 1.0 / c.s_row_scale[l];
  }
  for (index_t m = 0; m < k; ++m)
    for (index_t l = 0; l < k; ++l) c.s_lu[static_cast<std::size_t>(m) * k + l] *= c.s_row_scale[l];
  const int kk = static_cast<int>(k);
  int info = 0;
  const char one = '1';
  std::vector<double> work(4 * static_cast<std::size_t>(k));
  std::vector<int> iwork(k);
  const double anorm = dlange_(&one, &kk, &kk, c.s_lu.data(), &kk, work.data());
  c.ipiv.resize(k);
  dgetrf_(&kk, &kk, c.s_lu.data(), &kk, c.ipiv.data(), &info);
  if (info != 0 || !std::isfinite(anorm)) return false;
  double rcond = 0;
  dgecon_(&one, &kk, c.s_lu.data(), &kk, &anorm, &rcond, work.data(), iwork.data(), &info);
  if (info != 0 || !(rcond >= kCorrectionMinRcond)) return false;
  // det A / det F = Π σ_l · det S, det S = det(D·S) / Π d_l
  c.log_abs_det = 0;
  c.det_sign = 1;
  for (index_t l = 0; l < k; ++l) {
    c.log_abs_det += std::log(std::abs(c.entries[l].shift)) - std::log(c.s_row_scale[l]);
    if (c.entries[l].shift < 0) c.det_sign = -c.det_sign;
    const double d = c.s_lu[static_cast<std::size_t>(l) * k + l];
    c.log_abs_det += std::log(std::abs(d));
    if (d < 0) c.det_sign = -c.det_sign;
    if (c.ipiv[l] != l + 1) c.det_sign = -c.det_sign;
  }
  c.active = true;
  if (probe_b) apply_correction(c, n, probe_x, 1);
  return true;
}

void correction_probe(index_t n, double* x_hat) {
  for (index_t i = 0; i < n; ++i) x_hat[i] = (i % 2 ? -1.0 : 1.0) * (1.0 + 0.5 * (i % 3));
}

void apply_correction(const PivotCorrection& c, index_t n, double* x, index_t nrhs) {
  const index_t k = c.k();
  if (!c.active || k == 0 || nrhs <= 0) return;
  const int kk = static_cast<int>(k), nn = static_cast<int>(n), nr = static_cast<int>(nrhs);
  // t = D_c⁻¹·Vᵀ·x for every column, then y = S⁻¹·t = (D·S)⁻¹·D·t (one getrs for all
  // columns)
  std::vector<double> y(static_cast<std::size_t>(k) * nrhs);
  for (index_t r = 0; r < nrhs; ++r)
    for (index_t l = 0; l < k; ++l)
      y[static_cast<std::size_t>(r) * k + l] =
          x[static_cast<std::size_t>(r) * n + c.entries[l].col] / c.entries[l].col_scale *
          c.s_row_scale[l];
  int info = 0;
  const char no = 'N';
  dgetrs_(&no, &kk, &nr, c.s_lu.data(), &kk, c.ipiv.data(), y.data(), &kk, &info);
  // x += W·y
  const double alpha = 1.0, beta = 1.0;
  if (nrhs == 1) {
    const int inc = 1;
    dgemv_(&no, &nn, &kk, &alpha, c.w.data(), &nn, y.data(), &inc, &beta, x, &inc);
  } else {
    dgemm_(&no, &no, &nn, &nr, &kk, &alpha, c.w.data(), &nn, y.data(), &kk, &beta, x, &nn);
  }
}

}  // namespace strata::detail
