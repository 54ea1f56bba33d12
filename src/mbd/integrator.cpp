// strata::mbd — BDF integrator with Newton's method on the partitioned index-3 system.
#include "mbd/integrator.hpp"

#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <thread>

#include "base/device.hpp"
#include "base/host_copy.hpp"
#include "base/roundoff.hpp"
#include "base/timer.hpp"
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

std::vector<double> bdf_nodes(double tn, const std::vector<double>& past, double h) {
  std::vector<double> T{0.0};
  double prev = tn;
  for (const double tj : past) {
    double gap = prev - tj;
    if (std::abs(gap - h) <= 8 * kUnitRoundoff * (std::abs(prev) + std::abs(tj))) gap = h;
    T.push_back(T.back() - gap);
    prev = tj;
  }
  return T;
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
    : model_(model), opts_(std::move(options)), sys_(model), anderson_(opts_.anderson_depth) {
  if (opts_.anderson_depth < 0 || opts_.anderson_depth > 10)
    throw InvalidInput("the Anderson depth must be 0..10, got " +
                       std::to_string(opts_.anderson_depth));
  if (opts_.order < 1 || opts_.order > 5)
    throw InvalidInput("BDF order must be 1..5, got " + std::to_string(opts_.order));
  if (!(opts_.step > 0)) throw InvalidInput("the step must be positive");
  if (opts_.min_step <= 0) opts_.min_step = opts_.step * 1e-6;
  // start-up (docs/formulation.md §6): h/4 for BDF2, h/2^{3(k−1)} above
  if (opts_.startup_levels < 0)
    opts_.startup_levels = opts_.order <= 2 ? 2 * (opts_.order - 1) : 3 * (opts_.order - 1);
  if (opts_.formulation == FormulationChoice::partitioned) opts_.regularization = 0;
  // Threads: a small assembly runs faster on one (thread start-up costs more than the
  // work). The host factorization with delayed pivots factors the fronts of a level
  // concurrently and gains from every thread, on a GPU too (the refactorizations delay
  // pivots on the host once the analysis's order needs static pivots).
  const std::size_t elements = model.forces.size() + model.constraints.size();
  sys_.set_threads(opts_.solver.num_threads > 0 ? opts_.solver.num_threads
                   : elements < 500
                       ? 1
                       : static_cast<int>(std::max(1u, std::thread::hardware_concurrency())));
  // The CUDA backend asked for where it cannot run: refused now, as the set-up's first
  // solve on the device would have been (the small ones run on the host,
  // integrator_init.cpp)
  if (!opts_.dense_solver && opts_.solver.backend == Backend::cuda)
    if (const std::string why = numeric::cuda_unavailable_reason(); !why.empty())
      throw NotSupported(why);
  // The Newton matrix goes to a GPU: its CUDA context is created on a thread of its own
  // while the set-up works on the host
  if (!opts_.dense_solver && solver_on_gpu(opts_.solver.backend)) numeric::start_device_context(0);
}

// The solver of the Newton matrices: the system condensed by the BDF relations
// (condensed_solver.hpp) where condensation() gives eliminations, then strata (or the
// dense LU).
std::unique_ptr<LinearSolver> Integrator::new_solver() const {
  std::unique_ptr<LinearSolver> inner =
      opts_.dense_solver ? make_dense_solver() : make_strata_solver(opts_.solver);
  return make_condensed_solver(
      std::move(inner), [this] { return condensation(); }, [this] { return sys_.arena(); });
}

// The eliminations the solver of the Newton matrices condenses it by (none where they
// would not pay: worth_condensing).
std::vector<RowElimination> Integrator::condensation() const {
  if (!opts_.condensation) return {};
  std::vector<RowElimination> el = sys_.bdf_eliminations();
  if (!worth_condensing(sys_.size(), el.size())) el.clear();
  return el;
}

void Integrator::use_stabilized(const char* why) {
  if (sys_.formulation() == Formulation::stabilized) return;
  sys_.set_formulation(Formulation::stabilized);
  pattern_changed_ = true;
  factor_valid_ = false;
  stats_.stabilized_since = t_;
  stats_.jacobian_size = sys_.size();
  if (opts_.verbose)
    fmt::print(stderr, "t = {:.9g}: {}; stabilized formulation from here on\n", t_, why);
}

void Integrator::repartition(double t, const double* q) {
  Timer timer;
  SparseRows rows = sys_.constraint_jacobian(q, t);
  partition_ = partition_coordinates(rows, opts_.partition_threshold, 1e-9,
                                     [&](index_t r) { return sys_.row_name(r); });
  factor_valid_ = false;
  if (sys_.set_partition(partition_)) {  // the same independent coordinates keep the pattern
    pattern_changed_ = true;
    ++stats_.repartitions;
  }
  stats_.partition_seconds += timer.seconds();
}

bool Integrator::done() const { return t_ >= opts_.t_end * (1 - 1e-12) - 1e-15; }

void Integrator::constraint_violation(double* position, double* velocity) const {
  std::vector<double> phi(sys_.model_m()), phid(sys_.model_m());
  sys_.model_constraint_values(q_.data(), v_.data(), t_, phi.data(), phid.data());
  *position = max_abs(phi);
  *velocity = max_abs(phid);
}

void Integrator::analyze(const BdfTerms& bdf, double t) {
  // The solver's matching and scaling are computed from the values it is given (the
  // current Jacobian). Leaving the contact entries out of them would be wrong too: the
  // scaling would then not see the contact stiffness.
  Timer ta;
  sys_.prune_pattern();  // contact pairs that left since the last analysis
  sys_.evaluate(x_.data(), t, bdf, true, res_.data());
  // The matching starts from the last analysis's (a Newton matrix of the same order: its
  // values have moved since, but most of its pairs still hold), unless this analysis is
  // to be the fresh reference of analyze_every_step.
  analysis_start_ = {};
  if (solver_ && !opts_.analyze_every_step) {
    analysis_start_ = solver_->matching_start();
    if (static_cast<index_t>(analysis_start_.row_scaling.size()) !=
        solver_->system_order(sys_.matrix()))
      analysis_start_ = {};
  }
  if (!solver_) solver_ = new_solver();
  solver_->analyze_from(sys_.matrix(), analysis_start_);
  analyzed_pattern_ = sys_.pattern_id();
  keep_values(analysis_values_);
  analysis_forces_ = sys_.pattern_forces();
  reorder_forces_.clear();
  analysis_factor_entries_ = solver_->factor_entries();
  stats_.analysis_seconds += ta.seconds();
  ++stats_.analyses;
  if (opts_.verbose) {
    const Stats* ss = solver_->stats();
    fmt::print(
        stderr,
        "t = {:.9g}: analysis of the Newton matrix ({} rows, {} entries, nnz(L) {}): {:.3f} s", t,
        sys_.matrix().n_rows, sys_.matrix().nnz(), solver_->factor_entries(), ta.seconds());
    if (ss) {  // the solver's phases (AnalysisStats), the rest is the Jacobian and copies
      const AnalysisStats& as = ss->analysis;
      fmt::print(stderr,
                 " (matching {:.3f}, ordering {:.3f}, symbolic {:.3f}, plan {:.3f}, device "
                 "set-up {:.3f}, Jacobian and copies {:.3f})",
                 as.matching_seconds, as.ordering_seconds - as.matching_seconds,
                 as.symbolic_seconds, as.plan_seconds, as.device_setup_seconds,
                 ta.seconds() - as.total_seconds);
    }
    fmt::print(stderr, "\n");
    if (ss && !ss->analysis.device_setup_error.empty())
      fmt::print(stderr, "t = {:.9g}: the device set-up at analysis failed: {}\n", t,
                 ss->analysis.device_setup_error);
  }
  pattern_changed_ = false;
  stats_.jacobian_nnz = sys_.matrix().nnz();
  stats_.factor_nnz = solver_->factor_entries();
}

// After NewtonSystem::update_candidates returned `change`: a new Jacobian is needed; a
// pair new to the pattern grew it, and the solver analyzes the grown pattern keeping its
// order (the pattern contains the analyzed one: pairs that left stay in it until the next
// analysis), unless a full analysis is pending anyway. When the kept order's factor would
// grow by more than a quarter (counted from its elimination tree and column counts alone,
// before any of the analysis is paid for), the next Newton iteration analyzes afresh, or,
// with IntegratorOptions::reorder_keeping_matching, the pairs that left are dropped from
// the pattern and it is ordered anew with the analysis's matching and scaling kept (the
// matching's entries are those of bodies and joints, rarely of a contact; afresh where the
// pattern lost a matched entry).
void Integrator::contacts_changed(int change, StepInfo* info) {
  if (change == 0) return;
  ++stats_.contact_updates;
  factor_valid_ = false;
  if (change == 1) return;
  if (!solver_ || pattern_changed_) {
    pattern_changed_ = true;
    return;
  }
  Timer timer;
  const index_t kept_entries = solver_->factor_entries_keeping_order(sys_.matrix());
  const bool grown = kept_entries > 1.25 * static_cast<double>(analysis_factor_entries_);
  if (!grown) {
    solver_->analyze_keeping_order(sys_.matrix());
    analyzed_pattern_ = sys_.pattern_id();
    ++stats_.kept_order_analyses;
    stats_.jacobian_nnz = sys_.matrix().nnz();
    stats_.factor_nnz = solver_->factor_entries();
  }
  const double s = timer.seconds();
  stats_.analysis_seconds += s;
  stats_.solver_seconds += s;
  if (info) info->solver_seconds += s;
  if (opts_.verbose)
    fmt::print(stderr,
               "t = {:.9g}: contact pairs new to the pattern; nnz(L) in the kept order {} ({:.2f} "
               "times the last analysis's){} ({:.3f} s)\n",
               t_, kept_entries,
               kept_entries / std::max(1.0, static_cast<double>(analysis_factor_entries_)),
               grown ? ": a new analysis follows" : ": analysis keeping the order", s);
  if (!grown) return;
  ++stats_.contact_analyses;
  if (!opts_.reorder_keeping_matching) {
    pattern_changed_ = true;
    return;
  }
  Timer reorder;
  sys_.prune_pattern();  // contact pairs that left since the last analysis
  try {
    solver_->analyze_keeping_matching(sys_.matrix());
  } catch (const InvalidInput&) {  // a matched entry left with a pair: a new matching
    pattern_changed_ = true;
    stats_.analysis_seconds += reorder.seconds();
    stats_.solver_seconds += reorder.seconds();
    if (info) info->solver_seconds += reorder.seconds();
    return;
  }
  const double r = reorder.seconds();
  stats_.analysis_seconds += r;
  stats_.solver_seconds += r;
  if (info) info->solver_seconds += r;
  ++stats_.analyses;
  ++stats_.matching_kept_analyses;
  analyzed_pattern_ = sys_.pattern_id();
  reorder_forces_ = sys_.pattern_forces();
  analysis_factor_entries_ = solver_->factor_entries();
  stats_.jacobian_nnz = sys_.matrix().nnz();
  stats_.factor_nnz = analysis_factor_entries_;
  if (opts_.verbose)
    fmt::print(stderr,
               "t = {:.9g}: new order keeping the matching and scaling ({} rows, {} entries, "
               "nnz(L) {}): {:.3f} s\n",
               t_, sys_.matrix().n_rows, sys_.matrix().nnz(), analysis_factor_entries_, r);
}

void Integrator::keep_values(std::vector<double>& kept) const {
  const std::vector<double>& v = sys_.matrix().values;
  if (kept.size() != v.size()) kept.resize(v.size());
  if (tbb::task_arena* a = sys_.arena())
    a->execute([&] { parallel_copy(kept.data(), v.data(), v.size()); });
  else
    std::copy(v.begin(), v.end(), kept.begin());
}

void Integrator::factorize(StepInfo& info, const BdfTerms& bdf, double t) {
  Timer timer;
  Timer tf;
  if (sys_.pattern_id() == analyzed_pattern_)
    solver_->factorize_analyzed_pattern(sys_.matrix());
  else
    solver_->factorize(sys_.matrix());
  stats_.condensation_seconds += solver_->condensation_seconds();
  keep_values(factor_values_);
  stats_.factor_seconds += tf.seconds();
  if (solver_->perturbed_pivots() > 0 && !fresh_analysis_) {
    // The analysis was made for other values; with the current ones its matching may put
    // tiny entries on the diagonal. Analyze again and refactorize.
    ++stats_.reanalyses;
    if (opts_.verbose)
      fmt::print(stderr, "t = {:.9g} step {}: {} perturbed pivots; analyzing again\n", t, step_ + 1,
                 solver_->perturbed_pivots());
    analyze(bdf, t);  // evaluates the Jacobian (and the residual) at x_ again
    Timer tf2;
    solver_->factorize(sys_.matrix());
    stats_.condensation_seconds += solver_->condensation_seconds();
    keep_values(factor_values_);
    stats_.factor_seconds += tf2.seconds();
    ++stats_.factorizations;
  }
  fresh_analysis_ = false;
  stats_.perturbed_pivots += solver_->perturbed_pivots();
  if (const Stats* ss = solver_->stats()) {
    const FactorStats& f = ss->factor;
    if (f.delayed_pivoting) {
      ++stats_.delayed_factorizations;
      stats_.delayed_pivots += f.delayed_pivots;
    }
    if (f.corrected_pivots > 0) {
      ++stats_.corrected_factorizations;
      stats_.corrected_pivots += f.corrected_pivots;
    }
    if (opts_.verbose && f.fixed_order_perturbed_pivots > 0)
      fmt::print(stderr,
                 "t = {:.9g} step {}: the analysis's order needed {} static pivots: {} ({:.3f} "
                 "s)\n",
                 t, step_ + 1, f.fixed_order_perturbed_pivots,
                 f.corrected_pivots > 0 ? fmt::format("corrected in the solves")
                 : f.delayed_pivoting   ? fmt::format("delayed pivoting ({} delayed, {} perturbed)",
                                                      f.delayed_pivots, f.perturbed_pivots)
                                        : fmt::format("left perturbed"),
                 tf.seconds());
    stats_.factor_input_seconds += f.input_seconds;
    stats_.factor_device_seconds += f.device_seconds;
    stats_.values_on_device_factorizations += f.values_scaled_on_device ? 1 : 0;
    stats_.rescaled_factorizations += f.rescaling_sweeps > 0 ? 1 : 0;
  }
  stats_.solver = solver_->describe();
  factor_valid_ = true;
  ++info.factorizations;
  ++stats_.factorizations;
  const double s = timer.seconds();
  info.solver_seconds += s;
  stats_.solver_seconds += s;
}

// The BDF relation of a step to tn = t + h and the predictor (extrapolation through up to
// p+1 past points; a from the BDF relation with the predicted v; λ from the last step, the
// stabilizing multipliers μ, ν zero).
void Integrator::predict(double h, BdfTerms& bdf) {
  const index_t n = sys_.n(), m = sys_.m(), N = sys_.size();
  const int target = opts_.variable_step ? order_ : opts_.order;
  const int p = std::min<int>(target, static_cast<int>(history_.size()));
  const double tn = t_ + h;
  std::vector<double> past;
  for (int j = 0; j < p; ++j) past.push_back(history_[j].t);
  // equal steps: the same coefficients at every step, bit for bit, so that a factor made
  // at an earlier step has this step's β in its BDF rows (newton())
  const std::vector<double> al = bdf_coefficients(bdf_nodes(tn, past, h));
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
  bdf.regularization = opts_.regularization;
  bdf.lambda_prev = lambda_.data();
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
  (void)m;
}

// A converged step of more than this many Newton iterations makes the next step start
// with a new Jacobian.
constexpr int kSlowStepIterations = 8;

// Newton's method on H(x) = 0 from the predictor in x_. Returns 1 when converged, 0 when
// the iteration failed (the step is to be retried smaller), 2 when the contact set changed
// (retry at once).
int Integrator::newton(double h, StepInfo& info, const BdfTerms& bdf) {
  const index_t n = sys_.n(), N = sys_.size();
  const double tn = t_ + h;
  double *xa = x_.data(), *xv = xa + n, *xq = xa + 2 * n;
  // A factor made for another β has other BDF rows than this step's: its updates leave
  // them unsatisfied (Newton converges more slowly, and a condensed system's right-hand
  // side then needs every eliminated column: condensed_solver.hpp). With fixed steps β
  // changes only during the start-up and at a last, shorter step: a new factor then;
  // variable steps change it at every step, and a factor is kept within 20 %.
  const double beta_change = opts_.variable_step ? 0.2 : 0.0;
  if (!opts_.modified_newton || slow_last_step_ ||
      std::abs(factor_beta_ - bdf.beta) > beta_change * bdf.beta)
    factor_valid_ = false;
  res_.resize(N);
  dx_.resize(N);
  anderson_.reset();
  rhs_.resize(N);
  double err_first = 0;
  int since_jac = 0;  // iterations since the factor was last refreshed
  bool refresh = false, fresh = false;
  const bool dump = opts_.dump_step == step_ + 1 && !opts_.dump_dir.empty();
  for (int it = 1; it <= opts_.max_newton_iterations; ++it) {
    const bool need_jac = !factor_valid_ || refresh || !opts_.modified_newton || (dump && it == 1);
    if (need_jac && (pattern_changed_ || !solver_)) {
      Timer tan;
      analyze(bdf, tn);  // the Jacobian and the residual at x_ too
      fresh_analysis_ = true;
      const double s = tan.seconds();
      info.solver_seconds += s;
      stats_.solver_seconds += s;
    } else {
      Timer ta;
      sys_.evaluate(x_.data(), tn, bdf, need_jac, res_.data());
      const double s = ta.seconds();
      info.assembly_seconds += s;
      stats_.assembly_seconds += s;
    }
    if (!all_finite(res_)) return 0;
    if (need_jac) {
      if (dump && it == 1) {
        std::filesystem::create_directories(opts_.dump_dir);
        const std::string base = opts_.dump_dir + "/" + fmt::format("jacobian_step{}", step_ + 1);
        write_matrix_market(base + ".mtx", sys_.matrix());
        for (index_t i = 0; i < N; ++i) rhs_[i] = -res_[i];
        write_dense_matrix_market(opts_.dump_dir + "/" + fmt::format("rhs_step{}.mtx", step_ + 1),
                                  rhs_.data(), N, 1);
        // and the system the sparse solver factors when it is condensed by the BDF
        // relations
        if (const std::vector<RowElimination> el = condensation(); !el.empty()) {
          CondensedSystem cs;
          SparseMatrix reduced;
          cs.build(sys_.matrix(), el, reduced);
          cs.values(sys_.matrix().values, reduced.values);
          std::vector<double> reduced_rhs(reduced.n_rows);
          cs.reduce_rhs(rhs_.data(), reduced_rhs.data());
          write_matrix_market(
              opts_.dump_dir + "/" + fmt::format("jacobian_condensed_step{}.mtx", step_ + 1),
              reduced);
          write_dense_matrix_market(
              opts_.dump_dir + "/" + fmt::format("rhs_condensed_step{}.mtx", step_ + 1),
              reduced_rhs.data(), reduced.n_rows, 1);
        }
      }
      try {
        factorize(info, bdf, tn);
      } catch (const InvalidInput&) {  // non-finite values: a numerical failure of the step
        factor_valid_ = false;
        return 0;
      }
      factor_beta_ = bdf.beta;
      anderson_.reset();  // a new map x − J⁻¹H(x)
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
      return 0;
    }
    const double s2 = ts.seconds();
    stats_.solve_seconds += s2;
    stats_.condensation_seconds += solver_->condensation_seconds();
    if (const Stats* st = solver_->stats(); st && st->solve.on_device) {
      ++stats_.device_solves;
      stats_.device_solve_seconds += s2;
    }
    info.solver_seconds += s2;
    stats_.solver_seconds += s2;
    ++stats_.solves;
    ++info.newton_iterations;
    ++stats_.newton_iterations;
    if (!all_finite(dx_)) {
      factor_valid_ = false;
      return 0;
    }
    // weights: atol + rtol|x| for q and v (so that the constraints hold to that level at
    // both), atol·b0/h + rtol|a| for a (an error δa moves v by (h/b0)·δa); in variable-step
    // mode at most a tenth of the local error tolerances
    double atol = 0, rtol = 0;
    newton_tolerances(&atol, &rtol);
    const double atol_a = atol / bdf.beta;
    // the weights of the update's error norm, at the updated x (λ is not measured)
    weights_.assign(N, 0.0);
    for (index_t i = 0; i < n; ++i) {
      weights_[i] = 1 / (atol_a + rtol * std::abs(xa[i] + dx_[i]));
      weights_[n + i] = 1 / (atol + rtol * std::abs(xv[i] + dx_[n + i]));
      weights_[2 * n + i] = 1 / (atol + rtol * std::abs(xq[i] + dx_[2 * n + i]));
    }
    double err = 0;
    for (index_t i = 0; i < 3 * n; ++i) err = std::max(err, std::abs(dx_[i]) * weights_[i]);
    // Convergence test (Brenan, Campbell & Petzold 1996, §5.2.2, as in DASSL): with the
    // rate ρ = (‖δ_k‖/‖δ_1‖)^(1/(k−1)) since the last new Jacobian, the remaining error is
    // about ρ/(1−ρ)‖δ_k‖. An update 1000 times below the tolerance is accepted as it is
    // (rounding level: the rate is meaningless there).
    ++since_jac;
    if (opts_.verbose) {
      const double berr = solver_->backward_error();
      fmt::print(stderr,
                 "t = {:.9g} h = {:.3g} iteration {}{}: weighted update {:.3e}, backward error "
                 "{}, perturbed pivots {}\n",
                 tn, h, it, need_jac ? " (new Jacobian)" : "", err,
                 std::isnan(berr) ? "not checked" : fmt::format("{:.1e}", berr),
                 solver_->perturbed_pivots());
    }
    bool converged = false;
    if (since_jac == 1) {
      err_first = err;
      converged = fresh && err <= 1e-3;  // a stale Jacobian may understate a first update
    } else {
      const double rho = std::pow(err / err_first, 1.0 / (since_jac - 1));
      if ((rho < 1 && rho / (1 - rho) * err <= 1) || err <= 1e-3) {
        converged = true;
      } else if (rho >= 0.9 && fresh && err <= 1) {
        converged = true;  // stalled at the rounding level within the tolerance
      } else if (rho >= 0.9) {
        if (fresh) {  // diverging or stalling with a Jacobian of this step: give up the step
          factor_valid_ = false;
          return 0;
        }
        refresh = true;  // stale Jacobian: get a new one and restart the rate estimate
      } else if (rho > 0.5) {
        refresh = true;
      }
    }
    if (refresh) since_jac = 0;
    // the next iterate: Anderson-accelerated while the same factor is used again, the
    // plain Newton update when the iteration ends or a new Jacobian comes next
    if (converged || refresh) {
      for (index_t i = 0; i < N; ++i) x_[i] += dx_[i];
      anderson_.reset();
    } else {
      anderson_.step(x_.data(), dx_.data(), weights_.data(), N);
    }
    if (!converged) continue;
    converged_candidates_ = sys_.check_candidates(xq);
    if (converged_candidates_ == 2) {
      // a contact pair outside the Newton matrix closed during the step: take it in and
      // redo the step
      contacts_changed(sys_.update_candidates(xq), &info);
      return 2;
    }
    // the next step starts with a new Jacobian only after a slow one: a Jacobian and its
    // factorization cost as much as about ten iterations with the old factor (the
    // engine's Newton matrices, bench/e2e.py); with Anderson acceleration a few more
    // iterations on a stale factor cost less than a new one (bench/history.md)
    slow_last_step_ = it > kSlowStepIterations;
    return 1;
  }
  factor_valid_ = false;
  return 0;
}

// The Newton tolerances of this run (variable steps: at most a tenth of the local error
// tolerances).
void Integrator::newton_tolerances(double* atol, double* rtol) const {
  *atol = opts_.newton_atol;
  *rtol = opts_.newton_rtol;
  if (opts_.variable_step) {
    *atol = std::min(*atol, 0.1 * opts_.atol);
    *rtol = std::min(*rtol, 0.1 * opts_.rtol);
  }
}

// A converged step is accepted only when every active constraint equation holds at the
// position and velocity level to the accuracy of q and v: |Φ_r| ≤ 10 Σ_j |∂Φ_r/∂q_j| ·
// (atol + rtol max_j |q_j|) over the row's coordinates j (and the same for Φ̇_r with v).
// Removed (redundant) equations are checked at the partition checks instead.
bool Integrator::constraints_hold(const double* q, const double* v, double t) {
  const index_t m = sys_.m();
  if (m == 0) return true;
  const index_t n = sys_.n();
  std::vector<double> phi(m), phid(m), zero(n, 0.0);
  sys_.constraint_values(q, v, zero.data(), t, phi.data(), phid.data(), nullptr);
  const SparseRows& rows = constraint_jacobian_at(q, t);
  double atol = 0, rtol = 0;
  newton_tolerances(&atol, &rtol);
  for (index_t r = 0; r < m; ++r) {
    double g = 0, qmax = 0, vmax = 0;
    for (index_t p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) {
      if (rows.vals[p] == 0.0) continue;  // the coordinates Φ_r depends on
      g += std::abs(rows.vals[p]);
      qmax = std::max(qmax, std::abs(q[rows.cols[p]]));
      vmax = std::max(vmax, std::abs(v[rows.cols[p]]));
    }
    const double tp = g * (atol + rtol * qmax), tv = g * (atol + rtol * vmax);
    if (!(std::abs(phi[r]) <= 10 * tp + 1e-14) || !(std::abs(phid[r]) <= 10 * tv + 1e-14)) {
      if (opts_.verbose)
        fmt::print(stderr,
                   "t = {:.9g}: step not accepted: {} violated (|Phi| {:.3e} > {:.3e} or "
                   "|dPhi/dt| {:.3e} > {:.3e})\n",
                   t, sys_.row_name(r), std::abs(phi[r]), 10 * tp, std::abs(phid[r]), 10 * tv);
      return false;
    }
  }
  return true;
}

// Variable step, conservative model: one step may change the energy by at most a tenth of
// the whole run's budget, 0.1 · energy_tolerance · E_ref (E_ref the largest kinetic energy
// so far); otherwise it is redone with h·(budget/ΔE)^{1/(p+1)}. (The slow drift of BDF's
// numerical damping is not held per step: it is reported at the end, see warnings().)
bool Integrator::energy_ok(double h, int p, const double* q, const double* v, double t) {
  double kin = 0, pot = 0;
  sys_.energy(q, v, t, &kin, &pot);
  const double scale = std::max(stats_.energy_scale, kin);
  const double de = std::abs(kin + pot - energy_last_);
  const double budget =
      0.1 * opts_.energy_tolerance * scale + 1e-12 * (std::abs(kin) + std::abs(pot));
  if (!(de > budget)) return true;
  reject_measure_ = de / budget;
  const double f = 0.9 * std::pow(budget / de, 1.0 / (p + 1));
  lte_reject_h_ = h * std::clamp(f, 0.2, 0.9);
  energy_reject_ = true;
  if (opts_.verbose)
    fmt::print(stderr, "t = {:.9g} h = {:.3g}: energy change {:.3e} J over the budget {:.3e} J\n",
               t, h, de, budget);
  return false;
}

bool Integrator::try_step(double h, StepInfo& info) {
  const index_t n = sys_.n(), m = sys_.m();
  BdfTerms bdf;
  predict(h, bdf);
  const int p =
      std::min<int>(opts_.variable_step ? order_ : opts_.order, static_cast<int>(history_.size()));
  const int np = std::min<int>(p + 1, static_cast<int>(history_.size()));
  const double tn = t_ + h;
  if (opts_.analyze_every_step) {  // the reference the analysis-reusing loop is tested against
    pattern_changed_ = true;
    factor_valid_ = false;
  }
  converged_candidates_ = -1;
  const int r = newton(h, info, bdf);
  if (r == 2) retry_ = true;
  if (r != 1) return false;
  double *xa = x_.data(), *xv = xa + n, *xq = xa + 2 * n, *xl = xa + 3 * n;
  if (opts_.perturb_converged) {
    opts_.perturb_converged(xq, xv);
    converged_candidates_ = -1;  // the check was of the iterate before
  }
  if (!constraints_hold(xq, xv, tn)) {
    ++stats_.residual_rejections;
    factor_valid_ = false;
    return false;
  }
  if (opts_.variable_step && np > 1) {
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
    reject_measure_ = est;
    if (est > 1 && !accept_jump_) {
      lte_reject_h_ = h * std::clamp(factor, 0.2, 0.9);
      return false;
    }
    if (conservative_ && !accept_jump_ && !energy_ok(h, p, xq, xv, tn)) return false;
    next_h_ = h * std::clamp(factor, 0.5, 2.0);
    choose_order(h, p, tn, xq, xv, est);
  }
  lambda_prev_ = lambda_;
  q_.assign(xq, xq + n);
  v_.assign(xv, xv + n);
  a_.assign(xa, xa + n);
  lambda_.assign(xl, xl + m);
  info.h = h;
  info.order = p;
  info.stabilized = sys_.formulation() == Formulation::stabilized;
  return true;
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
  // the last step ends exactly at t_end (a step within 1e-6 of the remaining time is
  // stretched to it rather than leaving a sliver)
  if (remaining < h * (1 + 1e-6)) h = remaining;
  const bool automatic = opts_.formulation == FormulationChoice::automatic;
  double h_ref = h, est_ref = -1;  // a rejection the later ones compare with
  accept_jump_ = false;
  while (!try_step(h, info)) {
    if (retry_) {  // not a failure: the contact set changed
      retry_ = false;
      continue;
    }
    ++info.rejected;
    ++stats_.rejected;
    if (lte_reject_h_ > 0) {  // converged, but the local error or energy change is too large
      h = lte_reject_h_;
      lte_reject_h_ = 0;
      if (energy_reject_)
        ++stats_.energy_rejections;
      else
        ++stats_.error_rejections;
      // A test that a step 100 times shorter fails as badly does not see the truncation
      // error of a smooth solution but a jump of the numerical solution (near a singular
      // configuration the velocity along the vanishing singular vector is only determined
      // to the Newton tolerance over the singular value): take the step and restart the BDF
      // history there (order 1), as at a discontinuity.
      if (est_ref < 0 || reject_measure_ < 0.5 * est_ref) {
        est_ref = reject_measure_;
        h_ref = h;
      } else if (h < 1e-2 * h_ref) {
        accept_jump_ = true;
      }
      if (h < opts_.min_step)
        throw SimulationError(
            fmt::format("the {} test failed at t = {:.9g} s even with a step of {:.3g} s",
                        energy_reject_ ? "energy" : "local error", t_, h));
      energy_reject_ = false;
      continue;
    }
    slow_last_step_ = true;
    if (automatic && sys_.formulation() == Formulation::partitioned && sys_.m() > 0) {
      // The partitioned step failed. A step fails for other reasons too (a contact
      // closing, a fast transient), so the formulation changes only when the partition is
      // the cause: a partition gone bad gets a new one, and the stabilized formulation
      // comes when no partition is good here (a singular configuration), or when steps
      // 8 times shorter still fail (near one, before the partition's condition shows it).
      Timer timer;
      double quality = current_partition_quality();
      if (quality < opts_.repartition_quality) {
        repartition(t_, q_.data());
        info.repartitioned = true;
        quality = current_partition_quality();
      }
      stats_.partition_seconds += timer.seconds();
      if (quality < opts_.repartition_quality || h < 0.2 * h_ref) {
        use_stabilized(quality < opts_.repartition_quality
                           ? "a partitioned step failed and no partition is well conditioned"
                           : "partitioned steps 8 times shorter failed");
        continue;
      }
      if (info.repartitioned) continue;  // the same step with the new partition
    }
    h *= 0.5;
    if (h < opts_.min_step)
      throw SimulationError(fmt::format(
          "Newton's method did not converge (or the constraints did not hold) at t = {:.9g} s "
          "even with a step of {:.3g} s (nominal {:.3g} s); the model may be too stiff, badly "
          "scaled, or locked",
          t_, h * 2, opts_.step));
  }
  t_ += h;
  ++step_;
  info.t = t_;
  last_order_ = info.order;
  if (accept_jump_) {  // restart: the history before the jump is not used
    accept_jump_ = false;
    history_.clear();
    order_ = 1;
    steps_at_order_ = 0;
    next_h_ = h;
    ++stats_.restarts;
    if (opts_.verbose)
      fmt::print(stderr,
                 "t = {:.9g}: the error test did not improve with the step size; "
                 "step accepted and the BDF history restarted\n",
                 t_);
  }
  history_.push_front({t_, q_, v_, a_});
  while (static_cast<int>(history_.size()) > opts_.order + 2) history_.pop_back();
  if (info.stabilized) ++stats_.stabilized_steps;
  // next step: variable steps follow the error control; fixed steps grow back towards
  // the nominal step (the startup ramp doubles each step)
  if (opts_.variable_step) {
    const double max_step = opts_.max_step > 0 ? opts_.max_step : opts_.t_end / 10;
    h_ = std::min(max_step, next_h_ > 0 ? next_h_ : h);
    if (info.rejected && !info.error_estimate) h_ = h;  // a Newton failure: keep the smaller step
    next_h_ = 0;
  } else if (info.rejected) {
    h_ = h;
    ramp_repeat_ = false;
  } else if (ramp_repeat_) {
    ramp_repeat_ = false;  // orders 1–2: h/2^L twice, then doubling: the ramp ends at t = h
  } else if (h_ < opts_.step) {
    // the start-up ramp doubles the step at orders 1–2 and grows it gently at higher
    // orders, where variable-coefficient BDF tolerates only moderate step ratios
    h_ = std::min(opts_.step, (info.order <= 2 ? 2.0 : 1.25) * h_);
  }
  // contact pairs approaching: update the set in the Newton matrix (q_ is the iterate that
  // Newton's convergence test checked, unless something changed it since)
  const int candidates =
      converged_candidates_ >= 0 ? converged_candidates_ : sys_.check_candidates(q_.data());
  converged_candidates_ = -1;
  if (candidates == 1) contacts_changed(sys_.update_candidates(q_.data()), &info);
  partition_check(info);
  if (conservative_) {
    double kin = 0, pot = 0;
    sys_.energy(q_.data(), v_.data(), t_, &kin, &pot);
    energy_last_ = kin + pot;
    stats_.energy_scale = std::max(stats_.energy_scale, kin);
    stats_.energy_drift = std::max(stats_.energy_drift, std::abs(energy_last_ - energy0_));
  }
  ++stats_.steps;
  return info;
}

// Is the coordinate partition still good, and do the removed (redundant) equations still
// hold? Partitioned steps under the automatic choice are checked after every step (a
// singular configuration can come within a few steps), others every
// partition_check_interval steps and after a rejected step.
void Integrator::partition_check(StepInfo& info) {
  if (sys_.model_m() == 0 || opts_.partition_check_interval <= 0) return;
  const bool stab = sys_.formulation() == Formulation::stabilized;
  const bool every = !stab && opts_.formulation == FormulationChoice::automatic;
  if (!every && step_ % opts_.partition_check_interval != 0 && !info.rejected) return;
  if (step_ % opts_.partition_check_interval == 0 || info.rejected)
    check_removed(q_.data(), v_.data(), t_, false);
  if (stab || sys_.m() == 0) return;
  Timer timer;
  const double quality = current_partition_quality();
  stats_.partition_seconds += timer.seconds();
  if (quality >= opts_.repartition_quality) return;
  if (opts_.formulation == FormulationChoice::automatic) {
    use_stabilized(fmt::format("partition quality {:.2e}", quality).c_str());
  } else {
    repartition(t_, q_.data());
    info.repartitioned = true;
  }
}

// partition_quality of the current partition at (q_, t_): Φ_q by the elements in parallel,
// the elimination by the monitor, whose structure is remade only when the pattern (the
// active rows) or the dependent columns changed.
double Integrator::current_partition_quality() {
  const SparseRows& rows = constraint_jacobian_at(q_.data(), t_);
  if (!monitor_.matches(rows, partition_.dependent))
    monitor_ = PartitionMonitor(rows, partition_.dependent);
  return monitor_.quality(rows);
}

// Φ_q at (q, t) with the elements' whole pattern, evaluated once for a point: an accepted
// step's constraint test and its partition check ask for the same one.
const SparseRows& Integrator::constraint_jacobian_at(const double* q, double t) {
  const index_t n = sys_.n();
  const bool same = jacobian_t_ == t && jacobian_active_ == sys_.active_rows() &&
                    std::equal(q, q + n, jacobian_q_.begin(), jacobian_q_.end());
  if (!same) {
    sys_.constraint_jacobian_full(q, t, monitor_rows_);
    jacobian_t_ = t;
    jacobian_q_.assign(q, q + n);
    jacobian_active_ = sys_.active_rows();
  }
  return monitor_rows_;
}

std::vector<std::string> Integrator::warnings() const {
  std::vector<std::string> w = initial_warnings_;
  if (conservative_ && stats_.energy_drift > opts_.energy_tolerance * stats_.energy_scale &&
      stats_.energy_drift > 1e-12 * std::abs(energy0_))
    w.push_back(fmt::format(
        "energy drift: the model is conservative but its energy changed by up to {:.3e} J "
        "({:.2e} of the largest kinetic energy, {:.4g} J; tolerance {:g}); the results are "
        "inaccurate: use a smaller step, a higher order or --variable-step",
        stats_.energy_drift, stats_.energy_drift / std::max(stats_.energy_scale, 1e-300),
        stats_.energy_scale, opts_.energy_tolerance));
  return w;
}

}  // namespace strata::mbd
