// strata::mbd — consistent initial conditions and redundant constraint equations
// (docs/formulation.md §6 and §7).
//
// Redundant equations: when the coordinate partitioning finds a row of Φ_q that
// eliminates to zero, the rank-revealing QR of Φ_qᵀ (redundancy.hpp) names the equations
// that depend on earlier ones; they are switched off for the run (NewtonSystem active
// rows), as Adams and Chrono do with redundant constraints. They must still hold: after
// the position and velocity analyses their residuals are checked, and a set that no
// motion satisfies is refused naming the equations. During the run the removed equations
// are checked at every partition check; one that no longer holds (the configuration
// changed rank) makes the analysis run again at the current configuration.
#include <fmt/core.h>

#include <algorithm>
#include <cmath>
#include <string_view>

#include "base/timer.hpp"
#include "mbd/integrator.hpp"
#include "mbd/redundancy.hpp"

namespace strata::mbd {

namespace {

bool all_finite(const std::vector<double>& x) {
  for (double v : x)
    if (!std::isfinite(v)) return false;
  return true;
}

double max_abs(const std::vector<double>& x) {
  double m = 0;
  for (double v : x) m = std::max(m, std::abs(v));
  return m;
}

// The names of the first 12 rows of `rows` (then a count), joined with ", ".
template <class Name>
std::string name_list(const std::vector<index_t>& rows, Name name) {
  std::string s;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    if (k == 12) return s + fmt::format(", ... ({} more)", rows.size() - 12);
    s += (k ? ", " : "") + name(rows[k]);
  }
  return s;
}

}  // namespace

std::vector<std::string> Integrator::removed_equations() const {
  std::vector<std::string> names;
  for (index_t k = 0; k < sys_.model_m(); ++k)
    if (!sys_.active_rows()[k]) names.push_back(sys_.model_row_name(k));
  return names;
}

std::vector<double> Integrator::model_lambda() const {
  std::vector<double> out(sys_.model_m(), 0.0);
  for (index_t r = 0; r < sys_.m(); ++r) out[sys_.model_row(r)] = lambda_[r];
  return out;
}

// Switches off the equations of Φ_q(q) that depend on earlier ones (all rows considered).
void Integrator::find_redundant(const double* q, double t, bool initial) {
  Timer timer;
  const SparseRows rows = sys_.model_constraint_jacobian(q, t);
  const std::vector<index_t> dead = dependent_rows(rows, opts_.redundancy_tolerance);
  ++stats_.redundancy_checks;
  std::vector<char> active(sys_.model_m(), 1);
  for (index_t k : dead) active[k] = 0;
  stats_.partition_seconds += timer.seconds();
  if (active == sys_.active_rows()) return;
  const std::vector<double> lam = initial ? std::vector<double>() : model_lambda();
  sys_.set_active_rows(active);
  lambda_.assign(sys_.m(), 0.0);
  if (!initial)
    for (index_t r = 0; r < sys_.m(); ++r) lambda_[r] = lam[sys_.model_row(r)];
  lambda_prev_ = lambda_;
  if (opts_.verbose)
    fmt::print(stderr, "t = {:.9g}: {} redundant constraint equation(s) switched off: {}\n", t,
               dead.size(), name_list(dead, [&](index_t k) { return sys_.model_row_name(k); }));
}

// The removed equations must hold where the kept ones do (a consistent redundant set).
void Integrator::check_removed(const double* q, const double* v, double t, bool initial) {
  const index_t mm = sys_.model_m();
  if (sys_.m() == mm) return;
  std::vector<double> phi(mm), phid(mm);
  sys_.model_constraint_values(q, v, t, phi.data(), v ? phid.data() : nullptr);
  const double tol_p = initial ? 1e-6 : 100 * (opts_.newton_atol + opts_.newton_rtol);
  std::vector<index_t> bad;
  double worst = 0;
  const char* level = "position";
  for (index_t k = 0; k < mm; ++k) {
    if (sys_.active_rows()[k]) continue;
    const double e = std::abs(phi[k]);
    // velocity residual relative to the model's speeds
    const double ev = v ? std::abs(phid[k]) / (1 + max_abs(v_)) : 0.0;
    if (e > tol_p || ev > tol_p) {
      bad.push_back(k);
      if (std::max(e, ev) > worst)
        worst = std::max(e, ev), level = e > tol_p ? "position" : "velocity";
    }
  }
  if (bad.empty()) return;
  const std::string names = name_list(bad, [&](index_t k) { return sys_.model_row_name(k); });
  if (initial)
    throw RedundantConstraints(fmt::format(
        "inconsistent constraints: {} repeat(s) earlier equations of the model (a linear "
        "combination of them) but cannot hold where those do (largest {} violation {:.3e}); "
        "no motion satisfies this set: check the joint locations and axes, or the drivers",
        names, level, worst));
  // during the run: the configuration changed rank; analyse again here
  if (opts_.verbose)
    fmt::print(stderr,
               "t = {:.9g}: removed equation(s) {} no longer hold ({:.3e}); "
               "analysing the constraint rank again\n",
               t, names, worst);
  find_redundant(q, t, false);
  repartition(t, q);
}

void Integrator::initial_positions() {
  const index_t n = sys_.n();
  // Newton on Φ(q) = 0 with the independent coordinates held: [Φ_q; Uᵀ] Δq = [−Φ; 0]
  for (int it = 0, converged = sys_.m() == 0; it < 50 && !converged; ++it) {
    const index_t m = sys_.m();
    std::vector<double> phi(m), zero(n, 0.0), b(n, 0.0);
    sys_.constraint_values(q_.data(), zero.data(), zero.data(), t_, phi.data(), nullptr, nullptr);
    for (index_t r = 0; r < m; ++r) b[r] = -phi[r];
    const std::vector<double> dq =
        solve_partitioned(sys_.constraint_jacobian(q_.data(), t_), b, "position");
    double err = 0;
    for (index_t i = 0; i < n; ++i) {
      q_[i] += dq[i];
      err = std::max(err,
                     std::abs(dq[i]) / (opts_.newton_atol + opts_.newton_rtol * std::abs(q_[i])));
    }
    converged = err <= 1;
  }
  const index_t m = sys_.m();
  std::vector<double> phi(m), zero(n, 0.0);
  sys_.constraint_values(q_.data(), zero.data(), zero.data(), t_, phi.data(), nullptr, nullptr);
  if (!(max_abs(phi) < 1e-6)) {
    index_t worst = 0;
    for (index_t r = 0; r < m; ++r)
      if (std::abs(phi[r]) > std::abs(phi[worst])) worst = r;
    throw SimulationError(fmt::format(
        "initial conditions: the position analysis did not converge; the largest violation "
        "({:.3e}) is in {}. Check the initial poses and joint locations.",
        m ? phi[worst] : 0.0, m ? sys_.row_name(worst) : std::string("-")));
  }
}

// x = [Φ_q; Uᵀ]⁻¹ b for the current partition. The rows of Uᵀ give the independent
// coordinates (x_i = b[m + k]); the dependent ones solve the square m × m system
// Φ_q(:, d) x_d = b[0:m] − Φ_q(:, i) x_i (one sparse solve by strata), which the partition
// made nonsingular.
std::vector<double> Integrator::solve_partitioned(const SparseRows& rows,
                                                  const std::vector<double>& b,
                                                  const char* what) const {
  const index_t n = sys_.n(), m = sys_.m();
  std::vector<double> x(n, 0.0);
  const auto& ind = partition_.independent;
  for (std::size_t k = 0; k < ind.size(); ++k) x[ind[k]] = b[m + static_cast<index_t>(k)];
  if (m == 0) return x;
  std::vector<index_t> reduced(n, -1);  // a dependent coordinate's column in Φ_q(:, d)
  for (index_t r = 0; r < m; ++r) reduced[partition_.dependent[r]] = r;
  std::vector<index_t> ri, ci;
  std::vector<double> vals, rhs(b.begin(), b.begin() + m);
  for (index_t r = 0; r < m; ++r)
    for (index_t p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) {
      const index_t c = rows.cols[p];
      if (reduced[c] >= 0) {
        ri.push_back(r);
        ci.push_back(reduced[c]);
        vals.push_back(rows.vals[p]);
      } else {
        rhs[r] -= rows.vals[p] * x[c];
      }
    }
  const std::vector<double> xd =
      solve_once(from_triplets(m, m, ri, ci, vals, sys_.arena()), rhs, what);
  for (index_t r = 0; r < m; ++r) x[partition_.dependent[r]] = xd[r];
  return x;
}

// --verbose: the phases of one set-up solve (the matrix's size, the solver's analysis split
// as for the Newton matrix, its factorization and solve).
void Integrator::report_set_up_solve(const char* what, const char* method, const SparseMatrix& k,
                                     const LinearSolver& s, double analysis, double factorization,
                                     double solve) const {
  if (!opts_.verbose) return;
  std::string split;
  if (const Stats* ss = s.stats()) {
    const AnalysisStats& as = ss->analysis;
    split = fmt::format(
        " (matching {:.3f}, ordering {:.3f}, symbolic {:.3f}, plan {:.3f}, "
        "device set-up {:.3f})",
        as.matching_seconds, as.ordering_seconds - as.matching_seconds, as.symbolic_seconds,
        as.plan_seconds, as.device_setup_seconds);
  }
  fmt::print(stderr,
             "initial conditions: {} solve by {} ({} rows, {} entries, nnz(L) {}): analysis "
             "{:.3f} s{}, factorization {:.3f} s, solve {:.3f} s\n",
             what, method, k.n_rows, k.nnz(), s.factor_entries(), analysis, split, factorization,
             solve);
}

// A set-up matrix of fewer rows than this is solved on the host even when the Newton
// matrix goes to a GPU: its factorization takes milliseconds there, less than a device
// solver's set-up (the CUDA context at the first one, its streams, handles and plan).
constexpr index_t kHostSetUpRows = 50000;

// The set-up's solves take the Newton matrix's solver options, but not a user permutation
// (it is the Newton matrix's; these are other matrices): nested dissection instead. Not
// CHOLMOD's rule (OrderingMethod::automatic) by default: on a large flexible body's
// saddle-point matrix it rejects AMD and adds AMD's time to the dissection's. A matrix of
// `rows` < kHostSetUpRows goes to the host.
Options Integrator::set_up_options(index_t rows) const {
  Options o = opts_.solver;
  if (o.ordering == OrderingMethod::user) {
    o.ordering = OrderingMethod::nested_dissection;
    o.user_permutation.clear();
  }
  if (rows < kHostSetUpRows && solver_on_gpu(o.backend)) o.backend = Backend::cpu;
  return o;
}

std::vector<double> Integrator::solve_once(const SparseMatrix& k, const std::vector<double>& b,
                                           const char* what) const {
  auto s = opts_.dense_solver ? make_dense_solver() : make_strata_solver(set_up_options(k.n_rows));
  Timer t;
  s->analyze(k);
  const double analysis = t.seconds();
  t.reset();
  s->factorize(k);
  const double factorization = t.seconds();
  t.reset();
  std::vector<double> x(b.size());
  s->solve(b.data(), x.data());
  report_set_up_solve(what, "LU", k, *s, analysis, factorization, t.seconds());
  if (!all_finite(x))
    throw SimulationError(std::string("initial conditions: the ") + what +
                          " analysis produced non-finite values");
  return x;
}

// x = K⁻¹ b for a symmetric K given with both triangles (the acceleration analysis's
// saddle-point matrix) by strata's L D Lᵀ: about half the work of the LU of solve_once and
// no unsymmetric matching. Its pivots are restricted to the analysis's fronts, so a front
// may need static pivots; when it did and refinement did not bring the backward error down
// to Options::refinement_tolerance, the LU of solve_once (delayed pivoting) solves instead.
// On a GPU (a matrix of kHostSetUpRows rows or more) the LU of solve_once: there strata's L D Lᵀ
// took about twice the LU's time on a flexible body's saddle-point matrix (bench/history.md,
// 2026-11-27).
std::vector<double> Integrator::solve_symmetric_once(const SparseMatrix& k,
                                                     const std::vector<double>& b,
                                                     const char* what) const {
  Options o = set_up_options(k.n_rows);
  if (opts_.dense_solver || solver_on_gpu(o.backend)) return solve_once(k, b, what);
  o.type = MatrixType::symmetric_indefinite;
  auto s = make_strata_symmetric_solver(o);
  Timer t;
  s->analyze(k);
  const double analysis = t.seconds();
  t.reset();
  s->factorize(k);
  const double factorization = t.seconds();
  t.reset();
  std::vector<double> x(b.size());
  s->solve(b.data(), x.data());
  report_set_up_solve(what, "LDLT", k, *s, analysis, factorization, t.seconds());
  if (all_finite(x) &&
      (s->perturbed_pivots() == 0 || s->backward_error() <= opts_.solver.refinement_tolerance))
    return x;
  return solve_once(k, b, what);
}

// The largest change of a body's centre between the model's values and the consistent
// ones (positions or velocities), as a warning when it exceeds 1e-6 of the model's size.
void Integrator::report_initial_change(const std::vector<double>& given,
                                       const std::vector<double>& now, const char* what,
                                       const char* unit) {
  double worst = 0, scale = 1e-300;
  std::string body;
  for (const Body& b : model_.bodies) {
    if (b.offset < 0) continue;
    const int dim = b.kind == BodyKind::planar ? 2 : 3;
    double d2 = 0, s2 = 0;
    for (int i = 0; i < dim; ++i) {
      d2 += (now[b.offset + i] - given[b.offset + i]) * (now[b.offset + i] - given[b.offset + i]);
      s2 += given[b.offset + i] * given[b.offset + i];
    }
    scale = std::max(scale, std::sqrt(s2));
    if (std::sqrt(d2) > worst) worst = std::sqrt(d2), body = b.name;
  }
  if (worst > 1e-6 * std::max(scale, 1.0))
    initial_warnings_.push_back(fmt::format(
        "{} body '{}' by {:.3e} {} to satisfy the constraints (the model's initial "
        "{} do not fit its joints)",
        what, body, worst, unit, std::string_view(unit) == "m" ? "poses" : "velocities"));
}

void Integrator::initialize() {
  Timer timer;
  // --verbose: each phase of the set-up as it ends (large models take minutes here)
  double last = 0;
  auto phase_done = [&](const char* what) {
    if (!opts_.verbose) return;
    const double now = timer.seconds();
    fmt::print(stderr, "initial conditions: {} {:.3f} s\n", what, now - last);
    last = now;
  };
  const index_t n = sys_.n();
  q_ = model_.q0;
  v_ = model_.v0;
  a_.assign(n, 0.0);
  t_ = 0;
  step_ = 0;
  for (const Body& b : model_.bodies)
    if (b.kind == BodyKind::spatial && b.offset >= 0) {
      double s = 0;
      for (int i = 3; i < 7; ++i) s += q_[b.offset + i] * q_[b.offset + i];
      for (int i = 3; i < 7; ++i) q_[b.offset + i] /= std::sqrt(s);
    }
  initial_warnings_.clear();
  sys_.update_candidates(q_.data());
  sys_.prune_pattern();  // the pattern starts with the pairs in the matrix now
  if (opts_.formulation == FormulationChoice::stabilized)
    sys_.set_formulation(Formulation::stabilized);
  try {
    repartition(t_, q_.data());
  } catch (const RedundantConstraints&) {
    // switch the dependent equations off; a set that is still singular is refused
    find_redundant(q_.data(), t_, true);
    repartition(t_, q_.data());
  }
  phase_done("coordinate partitioning");
  initial_positions();
  check_removed(q_.data(), nullptr, t_, true);
  report_initial_change(model_.q0, q_, "position analysis moved", "m");
  phase_done("position analysis");
  repartition(t_, q_.data());
  stats_.repartitions = 0;
  phase_done("partitioning at the consistent positions");
  const index_t m = sys_.m();
  lambda_.assign(m, 0.0);
  // velocity analysis: Φ_q v = −Φ_t, independent velocities as given
  const SparseRows rows = sys_.constraint_jacobian(q_.data(), t_);
  std::vector<double> zero(n, 0.0), phid(m), phidd(m), b(n, 0.0);
  sys_.constraint_values(q_.data(), zero.data(), zero.data(), t_, nullptr, phid.data(), nullptr);
  for (index_t r = 0; r < m; ++r) b[r] = -phid[r];
  for (std::size_t k = 0; k < partition_.independent.size(); ++k)
    b[m + k] = model_.v0[partition_.independent[k]];
  v_ = solve_partitioned(rows, b, "velocity");
  check_removed(q_.data(), v_.data(), t_, true);
  report_initial_change(model_.v0, v_, "velocity analysis changed the velocity of", "m/s");
  phase_done("velocity analysis");
  // acceleration analysis: [M Φ_qᵀ; Φ_q 0][a; λ] = [−g(q, v, 0); −Φ̈(q, v, 0)]
  // Φ_q's triplets first, then M's appended (its arrays are the large ones: allocated once)
  std::vector<index_t> ri, ci;
  std::vector<double> vals;
  for (index_t r = 0; r < m; ++r)
    for (index_t p = rows.ptr[r]; p < rows.ptr[r + 1]; ++p) {
      ri.push_back(n + r);
      ci.push_back(rows.cols[p]);
      vals.push_back(rows.vals[p]);
      ri.push_back(rows.cols[p]);
      ci.push_back(n + r);
      vals.push_back(rows.vals[p]);
    }
  sys_.mass_triplets(q_.data(), v_.data(), t_, ri, ci, vals);
  std::vector<double> g(n), rhs(n + m);
  sys_.force_values(q_.data(), v_.data(), zero.data(), t_, g.data());
  sys_.constraint_values(q_.data(), v_.data(), zero.data(), t_, nullptr, nullptr, phidd.data());
  for (index_t i = 0; i < n; ++i) rhs[i] = -g[i];
  for (index_t r = 0; r < m; ++r) rhs[n + r] = -phidd[r];
  const std::vector<double> al = solve_symmetric_once(
      from_triplets(n + m, n + m, ri, ci, vals, sys_.arena()), rhs, "acceleration");
  std::copy(al.begin(), al.begin() + n, a_.begin());
  std::copy(al.begin() + n, al.end(), lambda_.begin());
  lambda_prev_ = lambda_;
  phase_done("acceleration analysis");
  history_.clear();
  history_.push_front({t_, q_, v_, a_});
  order_ = opts_.variable_step ? 1 : opts_.order;
  last_order_ = 1;
  steps_at_order_ = 0;
  h_ = opts_.step * std::ldexp(1.0, -opts_.startup_levels);
  ramp_repeat_ = !opts_.variable_step && opts_.order <= 2 && opts_.startup_levels > 0;
  conservative_ = model_.conservative() && opts_.energy_tolerance > 0;
  double kin = 0, pot = 0;
  sys_.energy(q_.data(), v_.data(), t_, &kin, &pot);
  energy0_ = energy_last_ = kin + pot;
  stats_.energy_scale = kin;
  stats_.initial_conditions_seconds = timer.seconds();
  stats_.jacobian_size = sys_.size();
}

}  // namespace strata::mbd
