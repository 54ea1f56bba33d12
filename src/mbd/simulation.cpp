// strata::mbd — the simulation loop: start, steps, checkpoints, interrupts, the summary (see
// simulation.hpp); what a run writes is in run_output.cpp.
#include "mbd/simulation.hpp"

#include <fmt/core.h>

#include <chrono>
#include <cmath>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <memory>
#include <new>
#include <sstream>

#include "base/atomic_file.hpp"
#include "base/timer.hpp"
#include "mbd/run_output.hpp"

namespace strata::mbd {
namespace {

class Progress {
 public:
  Progress(std::FILE* f, double t_end) : f_(f), t_end_(t_end) {}
  void update(double t, index_t steps, index_t newton, bool force = false) {
    if (!f_) return;
    const auto now = std::chrono::steady_clock::now();
    if (!force && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    const double frac = std::min(1.0, t / t_end_);
    const int width = 30, filled = static_cast<int>(frac * width);
    const double el = std::chrono::duration<double>(now - start_).count();
    const double eta = frac > 0 ? el * (1 - frac) / frac : 0;
    std::fprintf(f_, "\r[%s%s] %5.1f%%  t = %.4g s  step %lld  %.1f Newton/step  ETA %.0f s ",
                 std::string(filled, '=').c_str(), std::string(width - filled, ' ').c_str(),
                 100 * frac, t, static_cast<long long>(steps),
                 steps ? static_cast<double>(newton) / steps : 0.0, eta);
    std::fflush(f_);
  }
  void finish() {
    if (f_) std::fprintf(f_, "\n");
  }

 private:
  std::FILE* f_;
  double t_end_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now(), last_{};
};

}  // namespace

namespace {

// Every solver option by its name and text (set_option's vocabulary).
nlohmann::json solver_options_json(const Options& o) {
  nlohmann::json j = nlohmann::json::object();
  for (const std::string& name : option_fields()) j[name] = get_option(o, name);
  return j;
}

nlohmann::json integrator_options_json(const IntegratorOptions& o) {
  const double max_step =
      o.variable_step && o.max_step <= 0 ? o.t_end / 10 : o.max_step;  // resolved default
  return {{"t_end", o.t_end},
          {"step", o.step},
          {"order", o.order},
          {"modified_newton", o.modified_newton},
          {"anderson_depth", o.anderson_depth},
          {"reorder_keeping_matching", o.reorder_keeping_matching},
          {"max_newton_iterations", o.max_newton_iterations},
          {"newton_rtol", o.newton_rtol},
          {"newton_atol", o.newton_atol},
          {"partition_threshold", o.partition_threshold},
          {"repartition_quality", o.repartition_quality},
          {"partition_check_interval", o.partition_check_interval},
          {"startup_levels", o.startup_levels},
          {"min_step", o.min_step},
          {"solver", solver_options_json(o.solver)},
          {"dense_solver", o.dense_solver},
          {"condensation", o.condensation},
          {"variable_step", o.variable_step},
          {"rtol", o.rtol},
          {"atol", o.atol},
          {"max_step", max_step},
          {"formulation", static_cast<int>(o.formulation)},
          {"regularization", o.regularization},
          {"energy_tolerance", o.energy_tolerance},
          {"redundancy_tolerance", o.redundancy_tolerance}};
}

constexpr const char* kCheckpointFile = "checkpoint.cbor";
// 2: formulation, active rows, energy monitor; 3: the pattern's and the analysis's force
// sets; 5: every solver option by name (version 4, still read: backend, device_memory_limit,
// pivoting and threads only)
constexpr int kCheckpointVersion = 5;

}  // namespace

IntegratorOptions checkpoint_integrator_options(const nlohmann::json& ck) {
  const nlohmann::json& j = ck.at("integrator_options");
  IntegratorOptions o;
  j.at("t_end").get_to(o.t_end);
  j.at("step").get_to(o.step);
  j.at("order").get_to(o.order);
  j.at("modified_newton").get_to(o.modified_newton);
  o.anderson_depth = j.value("anderson_depth", 0);  // checkpoints written before it: plain
  // (written before it: a new matching at every such analysis)
  o.reorder_keeping_matching = j.value("reorder_keeping_matching", false);
  j.at("max_newton_iterations").get_to(o.max_newton_iterations);
  j.at("newton_rtol").get_to(o.newton_rtol);
  j.at("newton_atol").get_to(o.newton_atol);
  j.at("partition_threshold").get_to(o.partition_threshold);
  j.at("repartition_quality").get_to(o.repartition_quality);
  j.at("partition_check_interval").get_to(o.partition_check_interval);
  j.at("startup_levels").get_to(o.startup_levels);
  j.at("min_step").get_to(o.min_step);
  if (j.contains("solver")) {
    for (const auto& [name, text] : j.at("solver").items())
      set_option(o.solver, name, text.get<std::string>());
  } else {  // version 4
    o.solver.backend = static_cast<Backend>(j.at("backend").get<int>());
    o.solver.device_memory_limit = j.value("device_memory_limit", std::size_t{0});
    if (const int p = j.value("pivoting", -1); p >= 0) o.solver.pivoting = static_cast<Pivoting>(p);
    j.at("threads").get_to(o.solver.num_threads);
  }
  j.at("dense_solver").get_to(o.dense_solver);
  o.condensation = j.value("condensation", true);  // (written before it: automatic)
  j.at("variable_step").get_to(o.variable_step);
  j.at("rtol").get_to(o.rtol);
  j.at("atol").get_to(o.atol);
  j.at("max_step").get_to(o.max_step);
  o.formulation = static_cast<FormulationChoice>(j.at("formulation").get<int>());
  j.at("regularization").get_to(o.regularization);
  j.at("energy_tolerance").get_to(o.energy_tolerance);
  j.at("redundancy_tolerance").get_to(o.redundancy_tolerance);
  return o;
}

nlohmann::json read_checkpoint(const std::string& dir) {
  const std::string path = dir + "/" + kCheckpointFile;
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InvalidInput(path + ": cannot open the checkpoint (" + std::strerror(errno) + ")");
  std::ostringstream ss;
  ss << in.rdbuf();
  const std::string bytes = ss.str();
  nlohmann::json ck;
  try {
    ck = nlohmann::json::from_cbor(bytes);
  } catch (const nlohmann::json::exception& e) {
    throw InvalidInput(path + ": not a readable strata checkpoint: " + e.what());
  }
  if (!ck.is_object() || ck.value("format", "") != "strata-checkpoint")
    throw InvalidInput(path + ": not a strata checkpoint");
  if (const int v = ck.value("version", 0); v != kCheckpointVersion && v != 4)
    throw InvalidInput(path + ": checkpoint version " +
                       ck.value("version", nlohmann::json()).dump() +
                       ", this strata reads versions 4 and " + std::to_string(kCheckpointVersion));
  return ck;
}

SimulationOptions simulation_options(const Model& model, const RunSettings& s) {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw InvalidInput(what);
  };
  check(std::isfinite(s.t_end) && s.t_end >= 0,
        fmt::format("t_end must be >= 0 s, got {}", s.t_end));
  check(std::isfinite(s.step) && s.step >= 0, fmt::format("step must be >= 0 s, got {}", s.step));
  check(s.order >= 0 && s.order <= 5, fmt::format("order must be 1..5, got {}", s.order));
  validate(s.solver);
  check(std::isfinite(s.newton_tol) && s.newton_tol >= 0,
        fmt::format("newton_tol must be >= 0, got {}", s.newton_tol));
  check(std::isfinite(s.rtol) && s.rtol > 0, fmt::format("rtol must be > 0, got {}", s.rtol));
  check(std::isfinite(s.atol) && s.atol > 0, fmt::format("atol must be > 0, got {}", s.atol));
  check(std::isfinite(s.max_step) && s.max_step >= 0,
        fmt::format("max_step must be >= 0 s, got {}", s.max_step));
  check(std::isfinite(s.output_interval) && s.output_interval >= 0,
        fmt::format("output_interval must be >= 0 s, got {}", s.output_interval));
  check(s.dump_step >= 1, fmt::format("dump_step must be >= 1, got {}", s.dump_step));
  check(std::isfinite(s.energy_tolerance),
        fmt::format("energy_tolerance must be finite, got {}", s.energy_tolerance));
  SimulationOptions o;
  IntegratorOptions& io = o.integrator;
  io.t_end = s.t_end > 0 ? s.t_end : model.t_end;
  io.step = s.step > 0 ? s.step : model.step;
  io.order = s.order > 0 ? s.order : model.order;
  io.solver = s.solver;
  io.modified_newton = !s.full_newton;
  if (s.anderson_depth >= 0) io.anderson_depth = s.anderson_depth;
  if (model.newton_rtol > 0) io.newton_rtol = model.newton_rtol;
  if (model.newton_atol > 0) io.newton_atol = model.newton_atol;
  if (s.newton_tol > 0) io.newton_rtol = s.newton_tol;
  io.dump_dir = s.dump_dir;
  io.verbose = s.verbose;
  io.dense_solver = s.dense_reference;
  io.condensation = s.condensation;
  io.variable_step = s.variable_step;
  io.rtol = s.rtol;
  io.atol = s.atol;
  io.max_step = s.max_step;
  io.formulation = s.formulation;
  if (s.energy_tolerance >= 0) io.energy_tolerance = s.energy_tolerance;
  io.dump_step = s.dump_dir.empty() ? -1 : s.dump_step;
  o.output_dir = s.output_dir;
  o.output_interval = s.output_interval > 0 ? s.output_interval : model.output_interval;
  o.vtk = s.vtk;
  return o;
}

namespace {
SimulationResult run(const Model& model, const SimulationOptions& opts);
}  // namespace

SimulationResult simulate(const Model& model, const SimulationOptions& opts) {
  // an allocation failure outside the step loop (set-up, writing the final files): the
  // histories keep their partial names and status.json, if written, says "running"
  try {
    return run(model, opts);
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(0, "simulation (setting up or writing the results)");
  }
}

namespace {

// The integrator at its initial conditions, or at the state a checkpoint saved. When
// that fails no step was taken: the output folder must not keep an earlier run's
// results (a folder that cannot be marked leaves the original error to be reported).
std::unique_ptr<Integrator> start_integrator(const Model& model, const SimulationOptions& opts) {
  const nlohmann::json* ck = opts.resume;
  try {
    try {
      auto in = std::make_unique<Integrator>(model, opts.integrator);
      if (ck)
        in->restore_state(ck->at("integrator"));
      else
        in->initialize();
      return in;
    } catch (const std::bad_alloc&) {
      throw OutOfMemory(
          0, ck ? "simulation: restoring the checkpoint" : "simulation: initial conditions");
    } catch (const nlohmann::json::exception& e) {
      throw InvalidInput(std::string("checkpoint: missing or malformed state: ") + e.what());
    }
  } catch (const std::exception& e) {
    try {
      mark_failed_before_start(opts.output_dir, e.what());
    } catch (const std::exception&) {
    }
    throw;
  }
}

// A restart point: the integrator state, the loop's state in `res`, the outputs so far.
void write_checkpoint(const SimulationOptions& opts, const Integrator& in,
                      const detail::RunOutput& out, SimulationResult& res) {
  nlohmann::json c;
  c["format"] = "strata-checkpoint";
  c["version"] = kCheckpointVersion;
  c["meta"] = opts.checkpoint_meta;
  c["integrator_options"] = integrator_options_json(opts.integrator);
  c["integrator"] = in.save_state();
  nlohmann::json sj = {{"next_output", out.next_output()},
                       {"energy_initial", res.energy_initial},
                       {"max_position_violation", res.max_position_violation},
                       {"max_velocity_violation", res.max_velocity_violation},
                       {"output_interval", opts.output_interval},
                       {"vtk", opts.vtk}};
  if (out.has_vtk()) sj["vtk_frames"] = out.vtk_frames();
  c["simulation"] = sj;
  c["histories"] = out.histories();
  std::filesystem::create_directories(opts.checkpoint_dir);
  const std::vector<std::uint8_t> bytes = nlohmann::json::to_cbor(c);
  write_file_atomically(
      opts.checkpoint_dir + "/" + kCheckpointFile,
      std::string_view(reinterpret_cast<const char*>(bytes.data()), bytes.size()));
  res.checkpoint_step = in.stats().steps;
}

// The state's energies and constraint violations, as a row of the steps history.
StepRecord state_record(Integrator& in, const StepInfo& s) {
  StepRecord r{s.step,
               s.t,
               s.h,
               s.order,
               s.newton_iterations,
               s.factorizations,
               s.rejected,
               s.assembly_seconds,
               s.solver_seconds};
  in.system().energy(in.q().data(), in.v().data(), in.t(), &r.kinetic_energy, &r.potential_energy);
  in.constraint_violation(&r.position_violation, &r.velocity_violation);
  return r;
}

std::string interrupt_message(int sig, const Integrator& in) {
  return fmt::format("interrupted by signal {} ({}) after step {} at t = {:.9g} s", sig,
                     sig == SIGINT    ? "SIGINT"
                     : sig == SIGTERM ? "SIGTERM"
                                      : "?",
                     in.stats().steps, in.t());
}

// The loop's end: the state reached, the statistics and warnings (the reference's
// deviation among them), and the outputs closed.
void finish_run(const Model& model, const Integrator& in, double energy_final,
                detail::RunOutput& out, SimulationResult& res) {
  res.energy_final = energy_final;
  res.t_reached = in.t();
  res.stats = in.stats();
  res.warnings = in.warnings();
  if (res.reference_error > model.reference.tolerance)
    res.warnings.push_back(fmt::format(
        "reference: at t = {:g} s the model deviates from its reference values by {:.3e} "
        "({}), more than the reference's tolerance {:g}: use a smaller step or a higher "
        "order",
        model.reference.time, res.reference_error, res.reference_worst, model.reference.tolerance));
  res.removed_constraints = in.removed_equations();
  out.close(res.state, res);
  res.output_seconds = out.seconds();
}

SimulationResult run(const Model& model, const SimulationOptions& opts) {
  Timer wall;
  SimulationResult res;
  const nlohmann::json* ck = opts.resume;
  const std::unique_ptr<Integrator> integrator = start_integrator(model, opts);
  Integrator& in = *integrator;
  detail::RunOutput out(model, opts, in);
  out.open(ck, res);
  StepRecord last = state_record(in, StepInfo{0, in.t()});
  if (ck) {
    const nlohmann::json& sj = ck->at("simulation");
    res.energy_initial = sj.at("energy_initial").get<double>();
    res.max_position_violation = sj.at("max_position_violation").get<double>();
    res.max_velocity_violation = sj.at("max_velocity_violation").get<double>();
    res.checkpoint_step = in.stats().steps;
  } else {
    res.energy_initial = last.kinetic_energy + last.potential_energy;
    res.max_position_violation = last.position_violation;
    res.max_velocity_violation = last.velocity_violation;
    out.write_state();
    out.write_initial_step(last);
  }
  auto checkpoint = [&]() {
    if (opts.checkpoint_every <= 0 || opts.checkpoint_dir.empty()) return;
    Timer t;
    write_checkpoint(opts, in, out, res);
    out.add_seconds(t.seconds());
  };
  Progress bar(opts.progress ? opts.progress_stream : nullptr, opts.integrator.t_end);
  std::string state = "failed";
  try {
    while (!in.done()) {
      if (opts.interrupt && *opts.interrupt != 0) {
        state = "interrupted";
        res.message = interrupt_message(*opts.interrupt, in);
        checkpoint();
        break;
      }
      const double t_before = in.t();
      const StepInfo s = in.advance();
      // the reference time inside this step: compare with the model's reference values
      const double tr = model.reference.time;
      if (tr >= 0 && res.reference_error < 0 && tr <= in.t() * (1 + 1e-12) && tr > t_before) {
        std::vector<double> qr(model.n);
        in.interpolate(std::min(tr, in.t()), qr.data(), nullptr, nullptr, nullptr);
        res.reference_error = model.reference_error(qr.data(), &res.reference_worst);
      }
      last = state_record(in, s);
      res.max_position_violation = std::max(res.max_position_violation, last.position_violation);
      res.max_velocity_violation = std::max(res.max_velocity_violation, last.velocity_violation);
      out.write_state();
      out.write_step(last);
      // not after the last step: a restart from there would differ from a longer run
      // (the last step is shortened to end exactly at t_end)
      if (opts.checkpoint_every > 0 && in.stats().steps % opts.checkpoint_every == 0 && !in.done())
        checkpoint();
      bar.update(in.t(), in.stats().steps, in.stats().newton_iterations);
    }
    if (state != "interrupted") {
      res.complete = true;
      state = "complete";
    }
  } catch (const OutOfMemory& e) {  // from the solver: say where in the run
    res.message =
        fmt::format("step {} at t = {:.9g} s: {}", in.stats().steps + 1, in.t(), e.what());
  } catch (const Error& e) {
    res.message = e.what();
  } catch (const std::bad_alloc&) {
    res.message = OutOfMemory(0, fmt::format("simulation step {} at t = {:.9g} s",
                                             in.stats().steps + 1, in.t()))
                      .what();
  } catch (const std::exception& e) {
    res.message = std::string("unexpected error: ") + e.what();
  }
  res.state = state;
  bar.update(in.t(), in.stats().steps, in.stats().newton_iterations, true);
  bar.finish();
  finish_run(model, in, last.kinetic_energy + last.potential_energy, out, res);
  res.wall_seconds = wall.seconds();
  return res;
}

}  // namespace

void mark_failed_before_start(const std::string& dir, const std::string& reason) {
  if (dir.empty()) return;
  std::filesystem::create_directories(dir);
  detail::clear_earlier_results(dir);
  SimulationResult r;
  r.message = reason;
  detail::write_status(dir, "failed", r, 0, 0, {});
}

std::string summary(const Model& model, const SimulationResult& r) {
  const IntegratorStats& s = r.stats;
  std::string o;
  o += fmt::format(
      "model                 {} ({}; {} bodies, n = {} coordinates, m = {} "
      "constraint equations, {} force elements)\n",
      model.name, model.planar ? "planar" : "spatial", model.bodies.size() - 1, model.n,
      model.n_constraints(), model.forces.size());
  o += fmt::format("result                {} at t = {:.6g} s\n",
                   r.complete                 ? "complete"
                   : r.state == "interrupted" ? "PARTIAL (interrupted)"
                                              : "PARTIAL (stopped early)",
                   r.t_reached);
  if (!r.complete) o += fmt::format("reason                {}\n", r.message);
  o += fmt::format("steps                 {} accepted, {} rejected ({} by the local error test)\n",
                   s.steps, s.rejected, s.error_rejections);
  o += fmt::format("Newton iterations     {} ({:.2f} per step)\n", s.newton_iterations,
                   s.steps ? double(s.newton_iterations) / s.steps : 0.0);
  // analyses not caused by the first step, a partition, contacts or perturbed pivots: a
  // new formulation or a new set of active constraint equations
  const index_t other_analyses =
      std::max<index_t>(0, s.analyses - 1 - s.repartitions - s.contact_analyses - s.reanalyses);
  o += fmt::format(
      "factorizations        {} (analyses {}: first 1, new partitions {}, contact-set changes {} "
      "(matching kept in {}), perturbed pivots {}, new formulation or constraint set {}; order "
      "kept for {} of {} contact-set changes; static pivots left {}; delayed pivoting in {} "
      "factorizations, {} pivots delayed; static pivots corrected in {} factorizations, {} "
      "pivots)\n",
      s.factorizations, s.analyses, s.repartitions, s.contact_analyses, s.matching_kept_analyses,
      s.reanalyses, other_analyses, s.kept_order_analyses, s.contact_updates, s.perturbed_pivots,
      s.delayed_factorizations, s.delayed_pivots, s.corrected_factorizations, s.corrected_pivots);
  o += fmt::format("Newton matrix         {} x {}, nnz {}, nnz(L) {}\n", s.jacobian_size,
                   s.jacobian_size, s.jacobian_nnz, s.factor_nnz);
  o += fmt::format("linear solver         {}\n", s.solver);
  const double other = r.wall_seconds - s.assembly_seconds - s.solver_seconds;
  o += fmt::format(
      "time [s]              total {:.3f}: solver {:.3f} ({:.0f}%, of which analysis {:.3f}), "
      "assembly {:.3f} ({:.0f}%), other {:.3f} (initial conditions {:.3f}, partitioning "
      "{:.3f}, output {:.3f})\n",
      r.wall_seconds, s.solver_seconds, 100 * s.solver_seconds / std::max(r.wall_seconds, 1e-12),
      s.analysis_seconds, s.assembly_seconds,
      100 * s.assembly_seconds / std::max(r.wall_seconds, 1e-12), other,
      s.initial_conditions_seconds, s.partition_seconds, r.output_seconds);
  if (s.steps)
    o += fmt::format("per step [ms]         solver {:.3f}, assembly {:.3f}\n",
                     1e3 * s.solver_seconds / s.steps, 1e3 * s.assembly_seconds / s.steps);
  if (s.factorizations && s.solves && s.analyses)
    o += fmt::format(
        "strata [ms]           analysis {:.3f} each, factorization {:.3f} each, solve {:.3f} "
        "each{}{}\n",
        1e3 * s.analysis_seconds / s.analyses, 1e3 * s.factor_seconds / s.factorizations,
        1e3 * s.solve_seconds / s.solves,
        s.device_solves ? fmt::format(" ({} on the GPU, {:.3f} each)", s.device_solves,
                                      1e3 * s.device_solve_seconds / s.device_solves)
                        : std::string(),
        s.condensation_seconds > 0
            ? fmt::format("; condensation on the host {:.3f} in all", 1e3 * s.condensation_seconds)
            : std::string());
  if (s.factorizations && (s.factor_device_seconds > 0 || s.rescaled_factorizations))
    o += fmt::format(
        "factorization [ms]    value input {:.3f} each, GPU {:.3f} each; values scaled on the "
        "GPU in {} of {}, equilibrated again in {}\n",
        1e3 * s.factor_input_seconds / s.factorizations,
        1e3 * s.factor_device_seconds / s.factorizations, s.values_on_device_factorizations,
        s.factorizations, s.rescaled_factorizations);
  if (s.stabilized_since >= 0)
    o += fmt::format(
        "formulation           partitioned, stabilized from t = {:.6g} s ({} steps; no "
        "partition was well conditioned there)\n",
        s.stabilized_since, s.stabilized_steps);
  if (s.residual_rejections || s.energy_rejections || s.restarts)
    o += fmt::format(
        "step checks           {} redone for constraint residuals, {} for the energy change, "
        "{} BDF restarts after a jump\n",
        s.residual_rejections, s.energy_rejections, s.restarts);
  if (!r.removed_constraints.empty()) {
    o += fmt::format("redundant equations   {} switched off for the run:",
                     r.removed_constraints.size());
    for (std::size_t k = 0; k < r.removed_constraints.size(); ++k) {
      if (k == 20) {
        o += fmt::format(" ... ({} more)", r.removed_constraints.size() - 20);
        break;
      }
      o += (k ? ", " : " ") + r.removed_constraints[k];
    }
    o += "\n";
  }
  o += fmt::format("energy [J]            initial {:.9g}, final {:.9g}\n", r.energy_initial,
                   r.energy_final);
  o += fmt::format("constraint violation  max |Phi| {:.3e}, max |dPhi/dt| {:.3e}\n",
                   r.max_position_violation, r.max_velocity_violation);
  if (r.reference_error >= 0)
    o += fmt::format(
        "reference             t = {:g} s: largest deviation {:.3e} ({}; tolerance {:g})\n",
        model.reference.time, r.reference_error, r.reference_worst, model.reference.tolerance);
  for (const std::string& w : r.warnings) o += "WARNING               " + w + "\n";
  return o;
}

}  // namespace strata::mbd
