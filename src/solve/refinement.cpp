// strata — iterative refinement and GMRES after the first solve (see refinement.hpp).
#include "solve/refinement.hpp"

#include <algorithm>

namespace strata::solve {

namespace {

// Host arrays: A applied one column at a time, M⁻¹ to all columns at once.
class HostSpace final : public RefinementSpace {
 public:
  HostSpace(index_t n, index_t nrhs, const Operator& a, const BlockOperator& m_inv, double norm_a,
            const double* b, double* x)
      : n_(n),
        nrhs_(nrhs),
        a_(a),
        m_inv_(m_inv),
        norm_a_(norm_a),
        b_(b),
        x_(x),
        r_(static_cast<std::size_t>(n) * nrhs),
        d_(r_.size()),
        kept_(r_.size()) {}
  void residual(double* berr, const char* active) override {
    for (index_t c = 0; c < nrhs_; ++c)
      if (!active || active[c])
        berr[c] = backward_error(n_, a_, norm_a_, b_ + c * n_, x_ + c * n_, r_.data() + c * n_);
  }
  void correct() override { m_inv_(r_.data(), d_.data(), nrhs_); }
  void step(index_t c) override {
    double* x = x_ + c * n_;
    std::copy(x, x + n_, kept_.data() + c * n_);
    for (index_t i = 0; i < n_; ++i) x[i] += d_[i + c * n_];
  }
  void undo(index_t c) override {
    std::copy(kept_.data() + c * n_, kept_.data() + (c + 1) * n_, x_ + c * n_);
  }

 private:
  index_t n_, nrhs_;
  const Operator& a_;
  const BlockOperator& m_inv_;
  double norm_a_;
  const double* b_;
  double* x_;
  std::vector<double> r_, d_, kept_;
};

}  // namespace

RefinementResult refine_steps(RefinementSpace& space, index_t nrhs, int max_steps,
                              double tolerance) {
  RefinementResult res;
  std::vector<double>& berr = res.backward_error;
  berr.assign(nrhs, 0.0);
  std::vector<double> last(nrhs);
  std::vector<char> active(nrhs, 1);
  space.residual(berr.data(), nullptr);
  for (; res.steps < max_steps; ++res.steps) {
    bool any = false;
    for (index_t c = 0; c < nrhs; ++c) {
      if (active[c] && berr[c] <= tolerance) active[c] = 0;
      any |= active[c] != 0;
    }
    if (!any) break;
    space.correct();
    for (index_t c = 0; c < nrhs; ++c)
      if (active[c]) space.step(c);
    last = berr;
    space.residual(berr.data(), active.data());
    bool improved = false;
    for (index_t c = 0; c < nrhs; ++c) {
      if (!active[c]) {
        berr[c] = last[c];  // x(:, c) did not change
        continue;
      }
      if (berr[c] > 0.5 * last[c]) {  // no longer converging: keep the better iterate
        if (berr[c] > last[c]) {
          space.undo(c);
          berr[c] = last[c];
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
  return res;
}

RefinementResult refine(index_t n, index_t nrhs, const Operator& a, const BlockOperator& m_inv,
                        double norm_a, const double* b, double* x, const RefinementSettings& s) {
  HostSpace space(n, nrhs, a, m_inv, norm_a, b, x);
  RefinementResult res = refine_steps(space, nrhs, s.max_steps, s.tolerance);
  std::vector<double>& berr = res.backward_error;
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
