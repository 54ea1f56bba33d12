// strata::mbd — Anderson acceleration (see anderson.hpp for the method and its sources).
#include "mbd/anderson.hpp"

#include <cmath>

namespace strata::mbd {
namespace {

// Σ a_i b_i (c_i) in four interleaved partial sums: one running sum waits for each
// addition in turn, and these products are most of an Anderson step's arithmetic.
double dot(const double* a, const double* b, index_t n) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  index_t i = 0;
  for (; i + 4 <= n; i += 4) {
    s0 += a[i] * b[i];
    s1 += a[i + 1] * b[i + 1];
    s2 += a[i + 2] * b[i + 2];
    s3 += a[i + 3] * b[i + 3];
  }
  for (; i < n; ++i) s0 += a[i] * b[i];
  return (s0 + s1) + (s2 + s3);
}

double dot(const double* a, const double* b, const double* c, index_t n) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  index_t i = 0;
  for (; i + 4 <= n; i += 4) {
    s0 += a[i] * b[i] * c[i];
    s1 += a[i + 1] * b[i + 1] * c[i + 1];
    s2 += a[i + 2] * b[i + 2] * c[i + 2];
    s3 += a[i + 3] * b[i + 3] * c[i + 3];
  }
  for (; i < n; ++i) s0 += a[i] * b[i] * c[i];
  return (s0 + s1) + (s2 + s3);
}

}  // namespace

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
    for (index_t i = 0; i < n; ++i) qc[i] = w[i] * col[i];
    const double norm0 = dot(qc, qc, n);
    for (int l = 0; l < c; ++l) {
      const double* ql = q_.data() + un * l;
      const double d = dot(ql, qc, n);
      r_[l + c * m] = d;
      for (index_t i = 0; i < n; ++i) qc[i] -= d * ql[i];
    }
    const double norm = std::sqrt(dot(qc, qc, n));
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
    gamma_[c] = dot(q_.data() + un * c, w, f, n);
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
