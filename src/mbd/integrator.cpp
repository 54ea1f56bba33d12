// strata::mbd — BDF integrator with Newton's method on the partitioned index-3 system.
#include "mbd/integrator.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <thread>

#include "core/timer.hpp"
#include "strata/matrix_market.hpp"

namespace strata::mbd {

std::vector<double> bdf_coefficients(const std::vector<double>& T) {
  const int p = static_cast<int>(T.size()) - 1;
  std::vector<double> al(p + 1, 0.0);
  for (int m = 1; m <= p; ++m) al[0] += 1.0 / (T[0] - T[m]);
  for (int j = 1; j <= p; ++j) {
    double num = 1, den = 1;
    for (int m = 1; m <= p; ++m)
      if (m != j) num *= T[0] - T[m];
    for (int m = 0; m <= p; ++m)
      if (m != j) den *= T[j] - T[m];
    al[j] = num / den;
  }
  return al;
}

namespace {

// Lagrange weights of the nodes T at the point t.
std::vector<double> lagrange_weights(const std::vector<double>& T, double t) {
  std::vector<double> w(T.size(), 1.0);
  for (std::size_t j = 0; j < T.size(); ++j)
    for (std::size_t m = 0; m < T.size(); ++m)
      if (m != j) w[j] *= (t - T[m]) / (T[j] - T[m]);
  return w;
}

double max_abs(const std::vector<double>& x) {
  double m = 0;
  for (double v : x) m = std::max(m, std::abs(v));
  return m;
}

bool all_finite(const std::vector<double>& x) {
  for (double v : x)
    if (!std::isfinite(v)) return false;
  return true;
}

}  // namespace

Integrator::Integrator(const Model& model, IntegratorOptions options)
    : model_(model), opts_(std::move(options)), sys_(model) {
  if (opts_.order < 1 || opts_.order > 5)
    throw InvalidInput("BDF order must be 1..5, got " + std::to_string(opts_.order));
  if (!(opts_.step > 0)) throw InvalidInput("the step must be positive");
  if (opts_.min_step <= 0) opts_.min_step = opts_.step * 1e-6;
  if (opts_.startup_levels < 0) opts_.startup_levels = 3 * (opts_.order - 1);
  // Threads: small systems run faster on one (thread start-up costs more than the work).
  const bool small = sys_.size() < 20000;
  const std::size_t elements = model.forces.size() + model.constraints.size();
  sys_.set_threads(opts_.threads > 0 ? opts_.threads
                   : elements < 500
                       ? 1
                       : static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
  if (opts_.threads == 0 && small) opts_.threads = 1;
}

std::unique_ptr<LinearSolver> Integrator::new_solver() const {
  if (opts_.dense_solver) return make_dense_solver();
  return make_strata_solver(opts_.backend, opts_.threads, opts_.device_memory_limit);
}

void Integrator::repartition(double t, const double* q) {
  Timer timer;
  SparseRows rows = sys_.constraint_jacobian(q, t);
  partition_ = partition_coordinates(rows, opts_.partition_threshold, 1e-9,
                                     [&](index_t r) { return sys_.row_name(r); });
  sys_.set_partition(partition_);
  pattern_changed_ = true;
  factor_valid_ = false;
  ++stats_.repartitions;
  stats_.partition_seconds += timer.seconds();
}

void Integrator::initialize() {
  Timer timer;
  const index_t n = sys_.n(), m = sys_.m();
  q_ = model_.q0;
  v_ = model_.v0;
  a_.assign(n, 0.0);
  lambda_.assign(m, 0.0);
  t_ = 0;
  step_ = 0;
  for (const Body& b : model_.bodies)
    if (b.kind == BodyKind::spatial && b.offset >= 0) {
      double s = 0;
      for (int i = 3; i < 7; ++i) s += q_[b.offset + i] * q_[b.offset + i];
      for (int i = 3; i < 7; ++i) q_[b.offset + i] /= std::sqrt(s);
    }
  sys_.update_candidates(q_.data());
  repartition(t_, q_.data());
  stats_.repartitions = 0;

  // [Φ_q; Uᵀ] for the position and velocity analyses.
  auto partitioned = [&](const SparseRows& rows) {
    std::vector<index_t> ri, ci;
    std::vector<double> vals;
    for (index_t r = 0; r < m; ++r)
      for (index_t p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) {
        ri.push_back(r);
        ci.push_back(rows.cols[p]);
        vals.push_back(rows.vals[p]);
      }
    const auto& ind = partition_.independent;
    for (std::size_t k = 0; k < ind.size(); ++k) {
      ri.push_back(m + static_cast<index_t>(k));
      ci.push_back(ind[k]);
      vals.push_back(1.0);
    }
    return from_triplets(n, n, ri, ci, vals);
  };
  auto solve = [&](const SparseMatrix& k, const std::vector<double>& b, const char* what) {
    auto s = new_solver();
    s->analyze(k);
    s->factorize(k);
    std::vector<double> x(b.size());
    s->solve(b.data(), x.data());
    if (!all_finite(x))
      throw SimulationError(std::string("initial conditions: the ") + what +
                            " analysis produced non-finite values");
    return x;
  };
  std::vector<double> zero(n, 0.0), phi(m), phid(m), phidd(m), b(n);
  // position analysis: Newton on Φ(q) = 0 with the independent coordinates held
  bool converged = m == 0;
  for (int it = 0; it < 50 && !converged; ++it) {
    sys_.constraint_values(q_.data(), zero.data(), zero.data(), t_, phi.data(), nullptr, nullptr);
    SparseRows rows = sys_.constraint_jacobian(q_.data(), t_);
    std::fill(b.begin(), b.end(), 0.0);
    for (index_t r = 0; r < m; ++r) b[r] = -phi[r];
    const std::vector<double> dq = solve(partitioned(rows), b, "position");
    double err = 0;
    for (index_t i = 0; i < n; ++i) {
      q_[i] += dq[i];
      err = std::max(err,
                     std::abs(dq[i]) / (opts_.newton_atol + opts_.newton_rtol * std::abs(q_[i])));
    }
    converged = err <= 1;
  }
  sys_.constraint_values(q_.data(), zero.data(), zero.data(), t_, phi.data(), nullptr, nullptr);
  if (!converged || !(max_abs(phi) < 1e-6)) {
    index_t worst = 0;
    for (index_t r = 0; r < m; ++r)
      if (std::abs(phi[r]) > std::abs(phi[worst])) worst = r;
    throw SimulationError(fmt::format(
        "initial conditions: the position analysis did not converge; the largest violation "
        "({:.3e}) is in {}. Check the initial poses and joint locations.",
        m ? phi[worst] : 0.0, m ? sys_.row_name(worst) : std::string("-")));
  }
  repartition(t_, q_.data());
  stats_.repartitions = 0;
  SparseRows rows = sys_.constraint_jacobian(q_.data(), t_);
  const SparseMatrix kq = partitioned(rows);
  // velocity analysis: Φ_q v = −Φ_t, independent velocities as given
  sys_.constraint_values(q_.data(), zero.data(), zero.data(), t_, nullptr, phid.data(), nullptr);
  std::fill(b.begin(), b.end(), 0.0);
  for (index_t r = 0; r < m; ++r) b[r] = -phid[r];
  for (std::size_t k = 0; k < partition_.independent.size(); ++k)
    b[m + k] = model_.v0[partition_.independent[k]];
  v_ = solve(kq, b, "velocity");
  // acceleration analysis: [M Φ_qᵀ; Φ_q 0][a; λ] = [−g(q, v, 0); −Φ̈(q, v, 0)]
  {
    std::vector<index_t> ri, ci;
    std::vector<double> vals;
    sys_.mass_triplets(q_.data(), v_.data(), t_, ri, ci, vals);
    for (index_t r = 0; r < m; ++r)
      for (index_t p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) {
        ri.push_back(n + r);
        ci.push_back(rows.cols[p]);
        vals.push_back(rows.vals[p]);
        ri.push_back(rows.cols[p]);
        ci.push_back(n + r);
        vals.push_back(rows.vals[p]);
      }
    const SparseMatrix ka = from_triplets(n + m, n + m, ri, ci, vals);
    std::vector<double> g(n), rhs(n + m);
    sys_.force_values(q_.data(), v_.data(), zero.data(), t_, g.data());
    sys_.constraint_values(q_.data(), v_.data(), zero.data(), t_, nullptr, nullptr, phidd.data());
    for (index_t i = 0; i < n; ++i) rhs[i] = -g[i];
    for (index_t r = 0; r < m; ++r) rhs[n + r] = -phidd[r];
    const std::vector<double> al = solve(ka, rhs, "acceleration");
    std::copy(al.begin(), al.begin() + n, a_.begin());
    std::copy(al.begin() + n, al.end(), lambda_.begin());
  }
  history_.clear();
  history_.push_front({t_, q_, v_, a_});
  order_ = opts_.variable_step ? 1 : opts_.order;
  steps_at_order_ = 0;
  h_ = opts_.step * std::ldexp(1.0, -opts_.startup_levels);
  stats_.initial_conditions_seconds = timer.seconds();
  stats_.jacobian_size = sys_.size();
}

bool Integrator::done() const { return t_ >= opts_.t_end * (1 - 1e-12) - 1e-15; }

void Integrator::constraint_violation(double* position, double* velocity) const {
  std::vector<double> phi(sys_.m()), phid(sys_.m());
  sys_.constraint_values(q_.data(), v_.data(), a_.data(), t_, phi.data(), phid.data(), nullptr);
  *position = max_abs(phi);
  *velocity = max_abs(phid);
}

void Integrator::analyze(const BdfTerms& bdf, double t) {
  // The solver's matching and scaling are computed from the values it is given (the
  // current Jacobian). Leaving the contact entries out of them would be wrong too: the
  // scaling would then not see the contact stiffness.
  Timer ta;
  sys_.evaluate(x_.data(), t, bdf, true, res_.data());
  if (!solver_) solver_ = new_solver();
  solver_->analyze(sys_.matrix());
  stats_.analysis_seconds += ta.seconds();
  ++stats_.analyses;
  pattern_changed_ = false;
  stats_.jacobian_nnz = sys_.matrix().nnz();
  stats_.factor_nnz = solver_->factor_entries();
}

void Integrator::factorize(StepInfo& info, const BdfTerms& bdf, double t) {
  Timer timer;
  Timer tf;
  solver_->factorize(sys_.matrix());
  stats_.factor_seconds += tf.seconds();
  if (solver_->perturbed_pivots() > 0 && !fresh_analysis_) {
    // The analysis was made for other values; with the current ones its matching may put
    // tiny entries on the diagonal. Analyze again and refactorize.
    ++stats_.reanalyses;
    if (opts_.verbose)
      fmt::print(stderr, "t = {:.9g} step {}: {} perturbed pivots; analyzing again\n", t, step_ + 1,
                 solver_->perturbed_pivots());
    analyze(bdf, t);
    sys_.evaluate(x_.data(), t, bdf, true, res_.data());
    Timer tf2;
    solver_->factorize(sys_.matrix());
    stats_.factor_seconds += tf2.seconds();
    ++stats_.factorizations;
  }
  fresh_analysis_ = false;
  stats_.perturbed_pivots += solver_->perturbed_pivots();
  stats_.solver = solver_->describe();
  factor_valid_ = true;
  ++info.factorizations;
  ++stats_.factorizations;
  const double s = timer.seconds();
  info.solver_seconds += s;
  stats_.solver_seconds += s;
}

bool Integrator::try_step(double h, StepInfo& info) {
  const index_t n = sys_.n(), m = sys_.m(), N = sys_.size();
  const int target = opts_.variable_step ? order_ : opts_.order;
  const int p = std::min<int>(target, static_cast<int>(history_.size()));
  const double tn = t_ + h;
  std::vector<double> T{tn};
  for (int j = 0; j < p; ++j) T.push_back(history_[j].t);
  const std::vector<double> al = bdf_coefficients(T);
  BdfTerms bdf;
  bdf.beta = 1.0 / al[0];
  zeta1_.assign(n, 0.0);
  zeta2_.assign(n, 0.0);
  for (int j = 1; j <= p; ++j) {
    const double c = al[j] / al[0];
    for (index_t i = 0; i < n; ++i) {
      zeta1_[i] += c * history_[j - 1].v[i];
      zeta2_[i] += c * history_[j - 1].q[i];
    }
  }
  bdf.zeta1 = zeta1_.data();
  bdf.zeta2 = zeta2_.data();
  // predictor: extrapolation through up to p+1 past points
  const int np = std::min<int>(p + 1, static_cast<int>(history_.size()));
  std::vector<double> Tp;
  for (int j = 0; j < np; ++j) Tp.push_back(history_[j].t);
  const std::vector<double> w = lagrange_weights(Tp, tn);
  x_.assign(N, 0.0);
  double *xa = x_.data(), *xv = xa + n, *xq = xa + 2 * n, *xl = xa + 3 * n;
  for (int j = 0; j < np; ++j)
    for (index_t i = 0; i < n; ++i) {
      xq[i] += w[j] * history_[j].q[i];
      xv[i] += w[j] * history_[j].v[i];
    }
  for (index_t i = 0; i < n; ++i) xa[i] = (xv[i] + zeta1_[i]) / bdf.beta;
  qpred_.assign(xq, xq + n);
  vpred_.assign(xv, xv + n);
  std::copy(lambda_.begin(), lambda_.end(), xl);

  if (!opts_.modified_newton || slow_last_step_ ||
      std::abs(factor_beta_ - bdf.beta) > 0.2 * bdf.beta)
    factor_valid_ = false;
  res_.resize(N);
  dx_.resize(N);
  rhs_.resize(N);
  double err_first = 0;
  int since_jac = 0;  // iterations since the factor was last refreshed
  bool refresh = false, converged = false, fresh = false;
  const bool dump = opts_.dump_step == step_ + 1 && !opts_.dump_dir.empty();
  for (int it = 1; it <= opts_.max_newton_iterations; ++it) {
    const bool need_jac = !factor_valid_ || refresh || !opts_.modified_newton || (dump && it == 1);
    if (need_jac && (pattern_changed_ || !solver_)) {
      Timer tan;
      analyze(bdf, tn);
      fresh_analysis_ = true;
      const double s = tan.seconds();
      info.solver_seconds += s;
      stats_.solver_seconds += s;
    }
    Timer ta;
    sys_.evaluate(x_.data(), tn, bdf, need_jac, res_.data());
    const double s = ta.seconds();
    info.assembly_seconds += s;
    stats_.assembly_seconds += s;
    if (!all_finite(res_)) return false;
    if (need_jac) {
      if (dump && it == 1) {
        std::filesystem::create_directories(opts_.dump_dir);
        const std::string base = opts_.dump_dir + "/" + fmt::format("jacobian_step{}", step_ + 1);
        write_matrix_market(base + ".mtx", sys_.matrix());
        for (index_t i = 0; i < N; ++i) rhs_[i] = -res_[i];
        write_dense_matrix_market(opts_.dump_dir + "/" + fmt::format("rhs_step{}.mtx", step_ + 1),
                                  rhs_.data(), N, 1);
      }
      try {
        factorize(info, bdf, tn);
      } catch (const InvalidInput&) {  // non-finite values: a numerical failure of the step
        factor_valid_ = false;
        return false;
      }
      factor_beta_ = bdf.beta;
      refresh = false;
      fresh = true;
      since_jac = 0;
    }
    for (index_t i = 0; i < N; ++i) rhs_[i] = -res_[i];
    Timer ts;
    try {
      solver_->solve(rhs_.data(), dx_.data());
    } catch (const InvalidInput&) {  // non-finite values: a numerical failure of the step
      factor_valid_ = false;
      return false;
    }
    const double s2 = ts.seconds();
    stats_.solve_seconds += s2;
    info.solver_seconds += s2;
    stats_.solver_seconds += s2;
    ++stats_.solves;
    ++info.newton_iterations;
    ++stats_.newton_iterations;
    if (!all_finite(dx_)) {
      factor_valid_ = false;
      return false;
    }
    double err = 0;
    // weights: atol + rtol|x| for q and v (so that the constraints hold to that level at
    // both), atol·b0/h + rtol|a| for a (an error δa moves v by (h/b0)·δa); in variable-step
    // mode at most a tenth of the local error tolerances
    double atol = opts_.newton_atol, rtol = opts_.newton_rtol;
    if (opts_.variable_step) {
      atol = std::min(atol, 0.1 * opts_.atol);
      rtol = std::min(rtol, 0.1 * opts_.rtol);
    }
    const double atol_a = atol / bdf.beta;
    for (index_t i = 0; i < N; ++i) x_[i] += dx_[i];
    for (index_t i = 0; i < n; ++i) {
      err = std::max(err, std::abs(dx_[i]) / (atol_a + rtol * std::abs(xa[i])));
      err = std::max(err, std::abs(dx_[n + i]) / (atol + rtol * std::abs(xv[i])));
      err = std::max(err, std::abs(dx_[2 * n + i]) / (atol + rtol * std::abs(xq[i])));
    }
    // Convergence test (Brenan, Campbell & Petzold 1996, §5.2.2, as in DASSL): with the
    // rate ρ = (‖δ_k‖/‖δ_1‖)^(1/(k−1)) since the last new Jacobian, the remaining error is
    // about ρ/(1−ρ)‖δ_k‖. An update 1000 times below the tolerance is accepted as it is
    // (rounding level: the rate is meaningless there).
    ++since_jac;
    if (opts_.verbose)
      fmt::print(stderr,
                 "t = {:.9g} h = {:.3g} iteration {}{}: weighted update {:.3e}, backward error "
                 "{:.1e}, perturbed pivots {}\n",
                 tn, h, it, need_jac ? " (new Jacobian)" : "", err, solver_->backward_error(),
                 solver_->perturbed_pivots());
    if (since_jac == 1) {
      err_first = err;
      converged = fresh && err <= 1e-3;  // a stale Jacobian may understate a first update
    } else {
      const double rho = std::pow(err / err_first, 1.0 / (since_jac - 1));
      if ((rho < 1 && rho / (1 - rho) * err <= 1) || err <= 1e-3) {
        converged = true;
      } else if (rho >= 0.9 && fresh && err <= 1) {
        converged = true;  // stalled at rounding level within the tolerance
      } else if (rho >= 0.9) {
        if (fresh) {  // diverging or stalling with a Jacobian of this step: give up the step
          factor_valid_ = false;
          return false;
        }
        refresh = true;  // stale Jacobian: get a new one and restart the rate estimate
        since_jac = 0;
      } else if (rho > 0.5) {
        refresh = true;
      }
    }
    if (refresh) since_jac = 0;
    if (converged && sys_.check_candidates(xq) == 2) {
      // a contact pair outside the Newton matrix closed during the step: take it in and
      // redo the step
      sys_.update_candidates(xq);
      ++stats_.contact_updates;
      pattern_changed_ = true;
      factor_valid_ = false;
      retry_ = true;
      return false;
    }
    if (converged && opts_.variable_step && np > 1) {
      // local error estimate: (x − x_pred)/(p + 2) for a predictor of the corrector's
      // order (BDF error constant 1/(p+1), extrapolation error constant 1)
      const double c = np == p + 1 ? 1.0 / (p + 2) : 1.0 / (np + 1);
      double sum = 0, worst = 0;
      index_t wi = 0;
      for (index_t i = 0; i < n; ++i) {
        const double eq = c * (xq[i] - qpred_[i]) / (opts_.atol + opts_.rtol * std::abs(xq[i]));
        const double ev = c * (xv[i] - vpred_[i]) / (opts_.atol + opts_.rtol * std::abs(xv[i]));
        sum += eq * eq + ev * ev;
        if (eq * eq > worst) worst = eq * eq, wi = i;
        if (ev * ev > worst) worst = ev * ev, wi = n + i;
      }
      const double est = std::sqrt(sum / (2.0 * n));
      info.error_estimate = est;
      if (opts_.verbose)
        fmt::print(stderr,
                   "t = {:.9g} h = {:.3g} order {}: local error estimate {:.3e} (largest: {} {})\n",
                   tn, h, p, est, wi < n ? "q" : "v", wi % n);
      const double factor = 0.9 * std::pow(std::max(est, 1e-10), -1.0 / (p + 1));
      if (est > 1) {
        lte_reject_h_ = h * std::clamp(factor, 0.2, 0.9);
        return false;
      }
      next_h_ = h * std::clamp(factor, 0.5, 2.0);
      choose_order(h, p, tn, xq, xv, est);
    }
    if (converged) {
      slow_last_step_ = it > 3;
      q_.assign(xq, xq + n);
      v_.assign(xv, xv + n);
      a_.assign(xa, xa + n);
      lambda_.assign(xl, xl + m);
      info.h = h;
      info.order = p;
      return true;
    }
  }
  factor_valid_ = false;
  return false;
}

// Order selection of the variable-step mode (after Shampine & Reichelt 1997, and
// Brenan, Campbell & Petzold §5.2.3): the local error of order k is about
// h^{k+1} y^{(k+1)}/(k+1) ≈ h^{k+1} k! [y_n, …, y_{n−k−1}] (divided differences over the
// actual time points). Every p+1 steps at least, the order k ∈ {p−1, p, p+1} that allows
// the largest next step is taken (a higher order only when it gains 20 %).
void Integrator::choose_order(double h, int p, double tn, const double* xq, const double* xv,
                              double est_p) {
  ++steps_at_order_;
  if (steps_at_order_ < p + 1) return;
  const index_t n = sys_.n();
  const int avail = static_cast<int>(history_.size()) + 1;  // points incl. the new one
  auto estimate = [&](int k) {  // weighted RMS of h^{k+1} k! DD_{k+1}; needs k+2 points
    std::vector<double> T{tn};
    for (int j = 0; j <= k; ++j) T.push_back(history_[j].t);
    double fact = 1;
    for (int j = 2; j <= k; ++j) fact *= j;
    double sum = 0;
    std::vector<double> dd(k + 2);
    for (int which = 0; which < 2; ++which)
      for (index_t i = 0; i < n; ++i) {
        dd[0] = which ? xv[i] : xq[i];
        for (int j = 0; j <= k; ++j) dd[j + 1] = which ? history_[j].v[i] : history_[j].q[i];
        for (int level = 1; level <= k + 1; ++level)
          for (int j = 0; j + level <= k + 1; ++j)
            dd[j] = (dd[j] - dd[j + 1]) / (T[j] - T[j + level]);
        const double x = which ? xv[i] : xq[i];
        const double e =
            std::pow(h, k + 1) * fact * dd[0] / (opts_.atol + opts_.rtol * std::abs(x));
        sum += e * e;
      }
    return std::sqrt(sum / (2.0 * n));
  };
  auto gain = [](double e, int k) { return std::pow(std::max(e, 1e-12), -1.0 / (k + 1)); };
  int best = p;
  double best_gain = gain(est_p, p);
  if (p > 1 && avail >= p + 1) {
    const double g = gain(estimate(p - 1), p - 1);
    if (g > best_gain) best = p - 1, best_gain = g;
  }
  if (p < opts_.order && avail >= p + 3) {
    const double g = gain(estimate(p + 1), p + 1);
    if (g > 1.2 * best_gain) best = p + 1, best_gain = g;
  }
  if (best != p) {
    order_ = best;
    steps_at_order_ = 0;
    next_h_ = h * std::clamp(0.9 * best_gain, 0.5, 2.0);
  }
}

StepInfo Integrator::advance() {
  StepInfo info;
  info.step = step_ + 1;
  double h = h_;
  const double remaining = opts_.t_end - t_;
  if (h > remaining * (1 - 1e-9)) h = remaining;
  while (!try_step(h, info)) {
    if (retry_) {  // not a failure: the contact set changed
      retry_ = false;
      continue;
    }
    if (lte_reject_h_ > 0) {  // converged, but the local error is too large
      h = lte_reject_h_;
      lte_reject_h_ = 0;
      ++info.rejected;
      ++stats_.rejected;
      ++stats_.error_rejections;
      if (h < opts_.min_step)
        throw SimulationError(fmt::format(
            "the local error test failed at t = {:.9g} s even with a step of {:.3g} s", t_, h));
      continue;
    }
    ++info.rejected;
    ++stats_.rejected;
    slow_last_step_ = true;
    h *= 0.5;
    if (h < opts_.min_step)
      throw SimulationError(fmt::format(
          "Newton's method did not converge at t = {:.9g} s even with a step of {:.3g} s "
          "(nominal {:.3g} s); the model may be too stiff, badly scaled, or locked",
          t_, h * 2, opts_.step));
  }
  t_ += h;
  ++step_;
  info.t = t_;
  history_.push_front({t_, q_, v_, a_});
  while (static_cast<int>(history_.size()) > opts_.order + 2) history_.pop_back();
  // next step: variable steps follow the error control; fixed steps grow back towards
  // the nominal step (the startup ramp doubles each step)
  if (opts_.variable_step) {
    const double max_step = opts_.max_step > 0 ? opts_.max_step : opts_.t_end / 10;
    h_ = std::min(max_step, next_h_ > 0 ? next_h_ : h);
    if (info.rejected && !info.error_estimate) h_ = h;  // a Newton failure: keep the smaller step
    next_h_ = 0;
  } else if (info.rejected) {
    h_ = h;
  } else if (h_ < opts_.step) {
    // the start-up ramp doubles the step at orders 1–2 and grows it gently at higher
    // orders, where variable-coefficient BDF tolerates only moderate step ratios
    h_ = std::min(opts_.step, (info.order <= 2 ? 2.0 : 1.25) * h_);
  }
  // contact pairs approaching: update the set in the Newton matrix
  if (sys_.check_candidates(q_.data()) == 1 && sys_.update_candidates(q_.data())) {
    ++stats_.contact_updates;
    pattern_changed_ = true;
    factor_valid_ = false;
  }
  // partition still good?
  if (sys_.m() > 0 && opts_.partition_check_interval > 0 &&
      (step_ % opts_.partition_check_interval == 0 || info.rejected)) {
    Timer timer;
    const double quality =
        partition_quality(sys_.constraint_jacobian(q_.data(), t_), partition_.dependent);
    stats_.partition_seconds += timer.seconds();
    if (quality < opts_.repartition_quality) {
      repartition(t_, q_.data());
      info.repartitioned = true;
    }
  }
  ++stats_.steps;
  return info;
}

}  // namespace strata::mbd
