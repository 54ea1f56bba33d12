// strata::mbd — saving and restoring the integrator between steps (checkpoint/restart).
//
// A restart must continue exactly as the uninterrupted run: the BDF formulas read the
// history of past points, the step-size/order controller its own state, modified Newton
// may keep the factor of an earlier step, and the solver's matching and scaling were
// computed from the Jacobian values at its last analysis. So the state holds all of them;
// the factor itself is not stored but rebuilt from the saved Jacobian values with the same
// analysis (strata's factorization is deterministic for a fixed thread count:
// docs/reliability.md, "Determinism"). Timing statistics are restored too (so that the
// summary adds up) but are of course not reproducible.
#include <algorithm>
#include <string>

#include "mbd/integrator.hpp"

namespace strata::mbd {

using nlohmann::json;

namespace {

json stats_to_json(const IntegratorStats& s) {
  return {{"steps", s.steps},
          {"rejected", s.rejected},
          {"newton_iterations", s.newton_iterations},
          {"factorizations", s.factorizations},
          {"analyses", s.analyses},
          {"repartitions", s.repartitions},
          {"solves", s.solves},
          {"reanalyses", s.reanalyses},
          {"contact_updates", s.contact_updates},
          {"kept_order_analyses", s.kept_order_analyses},
          {"contact_analyses", s.contact_analyses},
          {"matching_kept_analyses", s.matching_kept_analyses},
          {"error_rejections", s.error_rejections},
          {"perturbed_pivots", s.perturbed_pivots},
          {"delayed_factorizations", s.delayed_factorizations},
          {"delayed_pivots", s.delayed_pivots},
          {"corrected_factorizations", s.corrected_factorizations},
          {"corrected_pivots", s.corrected_pivots},
          {"residual_rejections", s.residual_rejections},
          {"energy_rejections", s.energy_rejections},
          {"stabilized_steps", s.stabilized_steps},
          {"stabilized_since", s.stabilized_since},
          {"redundancy_checks", s.redundancy_checks},
          {"restarts", s.restarts},
          {"energy_drift", s.energy_drift},
          {"energy_scale", s.energy_scale},
          {"factor_seconds", s.factor_seconds},
          {"factor_input_seconds", s.factor_input_seconds},
          {"factor_device_seconds", s.factor_device_seconds},
          {"values_on_device_factorizations", s.values_on_device_factorizations},
          {"rescaled_factorizations", s.rescaled_factorizations},
          {"solve_seconds", s.solve_seconds},
          {"device_solves", s.device_solves},
          {"device_solve_seconds", s.device_solve_seconds},
          {"condensation_seconds", s.condensation_seconds},
          {"assembly_seconds", s.assembly_seconds},
          {"solver_seconds", s.solver_seconds},
          {"analysis_seconds", s.analysis_seconds},
          {"partition_seconds", s.partition_seconds},
          {"initial_conditions_seconds", s.initial_conditions_seconds},
          {"jacobian_size", s.jacobian_size},
          {"jacobian_nnz", s.jacobian_nnz},
          {"factor_nnz", s.factor_nnz},
          {"solver", s.solver}};
}

IntegratorStats stats_from_json(const json& j) {
  IntegratorStats s;
  j.at("steps").get_to(s.steps);
  j.at("rejected").get_to(s.rejected);
  j.at("newton_iterations").get_to(s.newton_iterations);
  j.at("factorizations").get_to(s.factorizations);
  j.at("analyses").get_to(s.analyses);
  j.at("repartitions").get_to(s.repartitions);
  j.at("solves").get_to(s.solves);
  j.at("reanalyses").get_to(s.reanalyses);
  j.at("contact_updates").get_to(s.contact_updates);
  j.at("kept_order_analyses").get_to(s.kept_order_analyses);
  j.at("contact_analyses").get_to(s.contact_analyses);
  s.matching_kept_analyses = j.value("matching_kept_analyses", index_t{0});  // (older: none)
  j.at("error_rejections").get_to(s.error_rejections);
  j.at("perturbed_pivots").get_to(s.perturbed_pivots);
  j.at("delayed_factorizations").get_to(s.delayed_factorizations);
  j.at("delayed_pivots").get_to(s.delayed_pivots);
  s.corrected_factorizations = j.value("corrected_factorizations", index_t{0});  // (older: none)
  s.corrected_pivots = j.value("corrected_pivots", index_t{0});
  j.at("residual_rejections").get_to(s.residual_rejections);
  j.at("energy_rejections").get_to(s.energy_rejections);
  j.at("stabilized_steps").get_to(s.stabilized_steps);
  j.at("stabilized_since").get_to(s.stabilized_since);
  j.at("redundancy_checks").get_to(s.redundancy_checks);
  j.at("restarts").get_to(s.restarts);
  j.at("energy_drift").get_to(s.energy_drift);
  j.at("energy_scale").get_to(s.energy_scale);
  j.at("factor_seconds").get_to(s.factor_seconds);
  // (checkpoints written before these figures existed have none)
  s.factor_input_seconds = j.value("factor_input_seconds", 0.0);
  s.factor_device_seconds = j.value("factor_device_seconds", 0.0);
  s.values_on_device_factorizations = j.value("values_on_device_factorizations", index_t{0});
  s.rescaled_factorizations = j.value("rescaled_factorizations", index_t{0});
  j.at("solve_seconds").get_to(s.solve_seconds);
  s.device_solves = j.value("device_solves", index_t{0});  // (older checkpoints: none)
  s.device_solve_seconds = j.value("device_solve_seconds", 0.0);
  s.condensation_seconds = j.value("condensation_seconds", 0.0);
  j.at("assembly_seconds").get_to(s.assembly_seconds);
  j.at("solver_seconds").get_to(s.solver_seconds);
  j.at("analysis_seconds").get_to(s.analysis_seconds);
  j.at("partition_seconds").get_to(s.partition_seconds);
  j.at("initial_conditions_seconds").get_to(s.initial_conditions_seconds);
  j.at("jacobian_size").get_to(s.jacobian_size);
  j.at("jacobian_nnz").get_to(s.jacobian_nnz);
  j.at("factor_nnz").get_to(s.factor_nnz);
  j.at("solver").get_to(s.solver);
  return s;
}

template <class T>
void expect_size(const std::vector<T>& v, std::size_t n, const char* what) {
  if (v.size() != n)
    throw InvalidInput(std::string("checkpoint: ") + what + " has " + std::to_string(v.size()) +
                       " entries, the model needs " + std::to_string(n));
}

}  // namespace

json Integrator::save_state() const {
  json hist = json::array();
  for (const Point& p : history_) hist.push_back({{"t", p.t}, {"q", p.q}, {"v", p.v}, {"a", p.a}});
  std::vector<int> cand(sys_.candidates().begin(), sys_.candidates().end());
  std::vector<int> pattern(sys_.pattern_forces().begin(), sys_.pattern_forces().end());
  std::vector<int> analyzed(analysis_forces_.begin(), analysis_forces_.end());
  std::vector<int> reordered(reorder_forces_.begin(), reorder_forces_.end());
  std::vector<int> active(sys_.active_rows().begin(), sys_.active_rows().end());
  return {{"n", sys_.n()},
          {"m", sys_.model_m()},
          {"active_rows", active},
          {"stabilized", sys_.formulation() == Formulation::stabilized},
          {"lambda_prev", lambda_prev_},
          {"last_order", last_order_},
          {"ramp_repeat", ramp_repeat_},
          {"conservative", conservative_},
          {"energy0", energy0_},
          {"energy_last", energy_last_},
          {"initial_warnings", initial_warnings_},
          {"t", t_},
          {"h", h_},
          {"step", step_},
          {"order", order_},
          {"steps_at_order", steps_at_order_},
          {"next_h", next_h_},
          {"factor_beta", factor_beta_},
          {"slow_last_step", slow_last_step_},
          {"pattern_changed", pattern_changed_},
          {"factor_valid", factor_valid_},
          {"fresh_analysis", fresh_analysis_},
          {"has_solver", solver_ != nullptr},
          {"solver_delaying", solver_ != nullptr && solver_->delaying()},
          {"q", q_},
          {"v", v_},
          {"a", a_},
          {"lambda", lambda_},
          {"history", hist},
          {"partition",
           {{"dependent", partition_.dependent},
            {"independent", partition_.independent},
            {"quality", partition_.quality}}},
          {"candidates", cand},
          {"pattern_forces", pattern},
          {"analysis_forces", analyzed},
          {"reorder_forces", reordered},
          {"analysis_factor_entries", analysis_factor_entries_},
          {"analysis_values", analysis_values_},
          {"analysis_start",
           {{"row_scaling", analysis_start_.row_scaling},
            {"matched_column", analysis_start_.matched_column}}},
          {"factor_values", factor_values_},
          {"stats", stats_to_json(stats_)}};
}

void Integrator::restore_state(const json& j) {
  const index_t n = sys_.n(), mm = sys_.model_m();
  if (j.at("n").get<index_t>() != n || j.at("m").get<index_t>() != mm)
    throw InvalidInput("checkpoint: it was written for a model with n = " + j.at("n").dump() +
                       " coordinates and m = " + j.at("m").dump() +
                       " constraint equations; this model has " + std::to_string(n) + " and " +
                       std::to_string(mm));
  const auto active = j.at("active_rows").get<std::vector<int>>();
  if (active.size() != static_cast<std::size_t>(mm))
    throw InvalidInput("checkpoint: the active constraint rows do not fit the model");
  sys_.set_active_rows(std::vector<char>(active.begin(), active.end()));
  const index_t m = sys_.m();
  if (j.at("stabilized").get<bool>()) sys_.set_formulation(Formulation::stabilized);
  j.at("lambda_prev").get_to(lambda_prev_);
  j.at("last_order").get_to(last_order_);
  j.at("ramp_repeat").get_to(ramp_repeat_);
  j.at("conservative").get_to(conservative_);
  j.at("energy0").get_to(energy0_);
  j.at("energy_last").get_to(energy_last_);
  j.at("initial_warnings").get_to(initial_warnings_);
  energy_reject_ = false;
  accept_jump_ = false;
  j.at("t").get_to(t_);
  j.at("h").get_to(h_);
  j.at("step").get_to(step_);
  j.at("order").get_to(order_);
  j.at("steps_at_order").get_to(steps_at_order_);
  j.at("next_h").get_to(next_h_);
  j.at("factor_beta").get_to(factor_beta_);
  j.at("slow_last_step").get_to(slow_last_step_);
  j.at("pattern_changed").get_to(pattern_changed_);
  j.at("factor_valid").get_to(factor_valid_);
  j.at("fresh_analysis").get_to(fresh_analysis_);
  retry_ = false;
  lte_reject_h_ = 0;
  j.at("q").get_to(q_);
  j.at("v").get_to(v_);
  j.at("a").get_to(a_);
  j.at("lambda").get_to(lambda_);
  expect_size(q_, n, "q");
  expect_size(v_, n, "v");
  expect_size(a_, n, "a");
  expect_size(lambda_, m, "lambda");
  expect_size(lambda_prev_, m, "lambda_prev");
  history_.clear();
  for (const json& p : j.at("history")) {
    Point pt;
    p.at("t").get_to(pt.t);
    p.at("q").get_to(pt.q);
    p.at("v").get_to(pt.v);
    p.at("a").get_to(pt.a);
    expect_size(pt.q, n, "history q");
    expect_size(pt.v, n, "history v");
    expect_size(pt.a, n, "history a");
    history_.push_back(std::move(pt));
  }
  if (history_.empty()) throw InvalidInput("checkpoint: the BDF history is empty");
  const json& pj = j.at("partition");
  pj.at("dependent").get_to(partition_.dependent);
  pj.at("independent").get_to(partition_.independent);
  pj.at("quality").get_to(partition_.quality);
  const auto cand = j.at("candidates").get<std::vector<int>>();
  const auto pattern = j.at("pattern_forces").get<std::vector<int>>();
  const auto analyzed = j.at("analysis_forces").get<std::vector<int>>();
  j.at("analysis_factor_entries").get_to(analysis_factor_entries_);
  sys_.set_candidates(std::vector<char>(cand.begin(), cand.end()));
  analysis_forces_.assign(analyzed.begin(), analyzed.end());
  // (checkpoints written before the engine ordered contact patterns anew have none)
  const auto reordered = j.value("reorder_forces", std::vector<int>{});
  reorder_forces_.assign(reordered.begin(), reordered.end());
  const bool analyzed_pattern = !analysis_forces_.empty();
  // the pattern of the last analysis first (its values are saved for it), then the one
  // that grew from it by contact pairs with the analysis's order kept
  sys_.set_pattern_forces(analyzed_pattern ? analysis_forces_
                                           : std::vector<char>(pattern.begin(), pattern.end()));
  sys_.set_partition(partition_);  // rebuilds the Newton matrix pattern
  j.at("analysis_values").get_to(analysis_values_);
  analysis_start_ = {};
  if (const auto it = j.find("analysis_start"); it != j.end()) {  // older checkpoints: none
    it->at("row_scaling").get_to(analysis_start_.row_scaling);
    it->at("matched_column").get_to(analysis_start_.matched_column);
  }
  j.at("factor_values").get_to(factor_values_);
  stats_ = stats_from_json(j.at("stats"));
  // The solver as it was: same analysis (its matching and scaling come from the values it
  // saw), same factor. With a pending pattern change the next step analyzes anew anyway.
  solver_.reset();
  const std::vector<char> now(pattern.begin(), pattern.end());
  if (j.at("has_solver").get<bool>() && !pattern_changed_ && analyzed_pattern) {
    SparseMatrix a = sys_.matrix();
    expect_size(analysis_values_, a.values.size(), "the analyzed Jacobian");
    a.values = analysis_values_;
    solver_ = new_solver();
    if (!analysis_start_.empty()) {
      const auto order = static_cast<std::size_t>(solver_->system_order(a));
      expect_size(analysis_start_.row_scaling, order, "the analysis's matching start");
      expect_size(analysis_start_.matched_column, order, "the analysis's matching start");
    }
    solver_->analyze_from(a, analysis_start_);  // as the run made it
    // then the pattern ordered anew with that matching (contacts_changed), then the one
    // that grew from it with the order kept
    const std::vector<char>& ordered = reorder_forces_.empty() ? analysis_forces_ : reorder_forces_;
    if (!reorder_forces_.empty()) {
      sys_.set_pattern_forces(reorder_forces_);
      sys_.rebuild_pattern();
      solver_->analyze_keeping_matching(sys_.matrix());
      a = sys_.matrix();
    }
    if (now != ordered) {
      sys_.set_pattern_forces(now);
      sys_.rebuild_pattern();
      solver_->analyze_keeping_order(sys_.matrix());
      a = sys_.matrix();
    }
    analyzed_pattern_ = sys_.pattern_id();  // the pattern of `a` and of the Newton system
    solver_->set_delaying(j.at("solver_delaying").get<bool>());
    if (factor_valid_) {
      expect_size(factor_values_, a.values.size(), "the factorized Jacobian");
      a.values = factor_values_;
      solver_->factorize(a);
    }
  } else {
    sys_.set_pattern_forces(now);
    sys_.rebuild_pattern();
    factor_valid_ = false;
  }
}

void Integrator::interpolate(double t, double* q, double* v, double* a, double* lambda) const {
  const index_t n = sys_.n();
  const int np = std::min<int>(last_order_ + 1, static_cast<int>(history_.size()));
  std::vector<double> w(np, 1.0);  // Lagrange weights of the last np points at t
  for (int j = 0; j < np; ++j)
    for (int k = 0; k < np; ++k)
      if (k != j) w[j] *= (t - history_[k].t) / (history_[j].t - history_[k].t);
  auto mix = [&](double* out, std::vector<double> Point::*field) {
    if (!out) return;
    std::fill(out, out + n, 0.0);
    for (int j = 0; j < np; ++j) {
      const std::vector<double>& y = history_[j].*field;
      for (index_t i = 0; i < n; ++i) out[i] += w[j] * y[i];
    }
  };
  mix(q, &Point::q);
  mix(v, &Point::v);
  mix(a, &Point::a);
  if (lambda) {
    const std::vector<double> now = model_lambda();
    std::vector<double> before(now.size(), 0.0);
    if (lambda_prev_.size() == lambda_.size())
      for (index_t r = 0; r < sys_.m(); ++r) before[sys_.model_row(r)] = lambda_prev_[r];
    const double t0 = history_.size() > 1 ? history_[1].t : t_;
    const double s = t_ > t0 ? (t - t0) / (t_ - t0) : 1.0;
    for (std::size_t k = 0; k < now.size(); ++k) lambda[k] = before[k] + s * (now[k] - before[k]);
  }
}

}  // namespace strata::mbd
