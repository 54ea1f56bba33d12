// strata::mbd — Anderson acceleration (see anderson.hpp for the method and its sources).
#include "mbd/anderson.hpp"

#include <cmath>

namespace strata::mbd {

void AndersonMixing::reset() {
  have_prev_ = false;
  // keep the storage for the next iteration's differences
  for (auto* h : {&df_, &dg_})
    for (auto& v : *h) spare_.push_back(std::move(v));
  df_.clear();
  dg_.clear();
}

int AndersonMixing::step(double* x, const double* f, const double* w, index_t n) {
  if (depth_ <= 0) {
    for (index_t i = 0; i < n; ++i) x[i] += f[i];
    return 0;
  }
  const auto un = static_cast<std::size_t>(n);
  if (have_prev_) {
    // the new differences reuse the oldest ones' storage once the history is full (no
    // allocation per Newton iteration)
    std::vector<double> df, dg;
    if (static_cast<int>(df_.size()) == depth_) {
      df = std::move(df_.front());
      dg = std::move(dg_.front());
      df_.pop_front();
      dg_.pop_front();
    } else if (spare_.size() >= 2) {
      df = std::move(spare_.back());
      spare_.pop_back();
      dg = std::move(spare_.back());
      spare_.pop_back();
    }
    df.resize(un);
    dg.resize(un);
    for (index_t i = 0; i < n; ++i) {
      df[i] = f[i] - f_prev_[i];
      dg[i] = (x[i] + f[i]) - (x_prev_[i] + f_prev_[i]);
    }
    df_.push_back(std::move(df));
    dg_.push_back(std::move(dg));
  }
  x_prev_.assign(x, x + n);
  f_prev_.assign(f, f + n);
  have_prev_ = true;

  // Weighted least squares min ‖W(f − ΔF γ)‖ by modified Gram–Schmidt over the columns,
  // newest first; a column (nearly) in the span of the newer ones ends the basis, and it
  // and the older ones are forgotten.
  const int m = static_cast<int>(df_.size());
  q_.resize(un * m);  // every column is written before it is read
  r_.assign(static_cast<std::size_t>(m) * m, 0.0);
  int p = 0;  // columns kept
  for (int c = 0; c < m; ++c) {
    const std::vector<double>& col = df_[m - 1 - c];
    double* qc = q_.data() + un * c;
    double norm0 = 0;
    for (index_t i = 0; i < n; ++i) {
      qc[i] = w[i] * col[i];
      norm0 += qc[i] * qc[i];
    }
    for (int l = 0; l < c; ++l) {
      const double* ql = q_.data() + un * l;
      double d = 0;
      for (index_t i = 0; i < n; ++i) d += ql[i] * qc[i];
      r_[l + c * m] = d;
      for (index_t i = 0; i < n; ++i) qc[i] -= d * ql[i];
    }
    double norm = 0;
    for (index_t i = 0; i < n; ++i) norm += qc[i] * qc[i];
    norm = std::sqrt(norm);
    if (!(norm > 1e-8 * std::sqrt(norm0))) break;
    r_[c + c * m] = norm;
    for (index_t i = 0; i < n; ++i) qc[i] /= norm;
    p = c + 1;
  }
  while (static_cast<int>(df_.size()) > p) {  // the dependent column and the older ones
    spare_.push_back(std::move(df_.front()));
    spare_.push_back(std::move(dg_.front()));
    df_.pop_front();
    dg_.pop_front();
  }
  // R γ = Qᵀ W f, back substitution (column c of the basis is difference m−1−c)
  gamma_.assign(p, 0.0);
  for (int c = 0; c < p; ++c) {
    const double* qc = q_.data() + un * c;
    double d = 0;
    for (index_t i = 0; i < n; ++i) d += qc[i] * w[i] * f[i];
    gamma_[c] = d;
  }
  for (int c = p - 1; c >= 0; --c) {
    for (int l = c + 1; l < p; ++l) gamma_[c] -= r_[c + l * m] * gamma_[l];
    gamma_[c] /= r_[c + c * m];
  }
  bool finite = true;
  for (double g : gamma_) finite = finite && std::isfinite(g);
  for (index_t i = 0; i < n; ++i) x[i] += f[i];
  if (!finite || p == 0) return 0;
  const int kept = static_cast<int>(df_.size());  // == p: newest is df_[kept − 1]
  for (int c = 0; c < p; ++c) {
    const std::vector<double>& dg = dg_[kept - 1 - c];
    for (index_t i = 0; i < n; ++i) x[i] -= gamma_[c] * dg[i];
  }
  return p;
}

}  // namespace strata::mbd
