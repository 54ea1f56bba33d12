// strata::mbd — the simulation loop and its output (see simulation.hpp).
#include "mbd/simulation.hpp"

#include <fmt/core.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <memory>

#include "core/timer.hpp"
#include "mbd/vtk.hpp"

namespace strata::mbd {
namespace {

// A CSV file written row by row and flushed, so that a run that stops keeps its rows.
class Csv {
 public:
  Csv(const std::string& path, const std::vector<std::string>& header) : out_(path) {
    if (!out_) throw Error("cannot write " + path);
    for (std::size_t i = 0; i < header.size(); ++i) out_ << (i ? "," : "") << header[i];
    out_ << '\n';
  }
  void row(double t, const double* x, std::size_t n) {
    out_ << fmt::format("{:.17g}", t);
    for (std::size_t i = 0; i < n; ++i) out_ << fmt::format(",{:.17g}", x[i]);
    out_ << '\n';
  }
  void raw(const std::string& line) { out_ << line << '\n'; }
  void flush() { out_.flush(); }

 private:
  std::ofstream out_;
};

// Joint reaction forces (global, on body j) of every constraint that reports one.
std::vector<std::string> reaction_names(const Model& m) {
  std::vector<std::string> names;
  static const char* axis[] = {"Fx", "Fy", "Fz"};
  for (const auto& c : m.constraints)
    for (int d = 0; d < c->reaction_dim; ++d) names.push_back(c->name + "." + axis[d]);
  for (const auto& c : m.constraints)
    for (int r = 0; r < c->rows; ++r)
      names.push_back(c->rows == 1 ? c->name + ".lambda" : fmt::format("{}.lambda{}", c->name, r));
  return names;
}
void reactions(const Model& m, const Integrator& in, std::vector<double>& out) {
  out.clear();
  std::vector<double> lq, zero;
  ConstraintEval ce;
  index_t row = 0;
  const auto& q = in.q();
  const auto& lam = in.lambda();
  for (const auto& c : m.constraints) {
    if (c->reaction_dim > 0) {
      lq.resize(c->dofs.size());
      for (std::size_t i = 0; i < c->dofs.size(); ++i) lq[i] = q[c->dofs[i]];
      zero.assign(c->dofs.size(), 0.0);
      c->evaluate_gradient(lq.data(), zero.data(), zero.data(), in.t(), ce);
      const std::size_t nz = c->dofs.size();
      for (int d = 0; d < c->reaction_dim; ++d) {
        double f = 0;
        for (int r = 0; r < c->rows; ++r) f -= ce.jq[r * nz + c->reaction_local + d] * lam[row + r];
        out.push_back(f);
      }
    }
    row += c->rows;
  }
  out.insert(out.end(), lam.begin(), lam.end());
}

std::string json_escape(const std::string& s) {
  std::string r;
  for (char c : s) {
    if (c == '"' || c == '\\') r += '\\';
    if (c == '\n') {
      r += "\\n";
      continue;
    }
    r += c;
  }
  return r;
}

void write_status(const std::string& dir, const SimulationResult& r) {
  std::ofstream out(dir + "/status.json");
  out << "{\n  \"complete\": " << (r.complete ? "true" : "false") << ",\n"
      << "  \"partial\": " << (r.complete ? "false" : "true") << ",\n"
      << "  \"t_reached\": " << fmt::format("{:.17g}", r.t_reached) << ",\n"
      << "  \"steps\": " << r.stats.steps << ",\n"
      << "  \"message\": \"" << json_escape(r.message) << "\"\n}\n";
}

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

SimulationOptions simulation_options(const Model& model, const RunSettings& s) {
  auto check = [](bool ok, const std::string& what) {
    if (!ok) throw InvalidInput(what);
  };
  check(std::isfinite(s.t_end) && s.t_end >= 0,
        fmt::format("t_end must be >= 0 s, got {}", s.t_end));
  check(std::isfinite(s.step) && s.step >= 0, fmt::format("step must be >= 0 s, got {}", s.step));
  check(s.order >= 0 && s.order <= 5, fmt::format("order must be 1..5, got {}", s.order));
  check(s.threads >= 0, fmt::format("threads must be >= 0, got {}", s.threads));
  check(std::isfinite(s.newton_tol) && s.newton_tol >= 0,
        fmt::format("newton_tol must be >= 0, got {}", s.newton_tol));
  check(std::isfinite(s.rtol) && s.rtol > 0, fmt::format("rtol must be > 0, got {}", s.rtol));
  check(std::isfinite(s.atol) && s.atol > 0, fmt::format("atol must be > 0, got {}", s.atol));
  check(std::isfinite(s.max_step) && s.max_step >= 0,
        fmt::format("max_step must be >= 0 s, got {}", s.max_step));
  check(std::isfinite(s.output_interval) && s.output_interval >= 0,
        fmt::format("output_interval must be >= 0 s, got {}", s.output_interval));
  check(s.dump_step >= 1, fmt::format("dump_step must be >= 1, got {}", s.dump_step));
  SimulationOptions o;
  IntegratorOptions& io = o.integrator;
  io.t_end = s.t_end > 0 ? s.t_end : model.t_end;
  io.step = s.step > 0 ? s.step : model.step;
  io.order = s.order > 0 ? s.order : model.order;
  io.backend = s.backend;
  io.device_memory_limit = s.device_memory_limit;
  io.threads = s.threads;
  io.modified_newton = !s.full_newton;
  if (model.newton_rtol > 0) io.newton_rtol = model.newton_rtol;
  if (model.newton_atol > 0) io.newton_atol = model.newton_atol;
  if (s.newton_tol > 0) io.newton_rtol = s.newton_tol;
  io.dump_dir = s.dump_dir;
  io.verbose = s.verbose;
  io.dense_solver = s.dense_reference;
  io.variable_step = s.variable_step;
  io.rtol = s.rtol;
  io.atol = s.atol;
  io.max_step = s.max_step;
  io.dump_step = s.dump_dir.empty() ? -1 : s.dump_step;
  o.output_dir = s.output_dir;
  o.output_interval = s.output_interval > 0 ? s.output_interval : model.output_interval;
  o.vtk = s.vtk;
  return o;
}

SimulationResult simulate(const Model& model, const SimulationOptions& opts) {
  Timer wall;
  SimulationResult res;
  Integrator in(model, opts.integrator);
  in.initialize();
  const bool files = !opts.output_dir.empty();
  std::unique_ptr<Csv> pos, vel, acc, rea, steps;
  std::unique_ptr<VtkSeries> vtk;
  const index_t n = model.n;
  std::vector<double> rbuf;
  double next_output = 0;
  double out_seconds = 0;
  SimulationHistory* hist = opts.history;
  auto write_state = [&](double kin, double pot) {
    if (!files && !hist) return;
    Timer t;
    const double tt = in.t();
    if (opts.output_interval <= 0 || tt + 1e-12 >= next_output || in.done()) {
      reactions(model, in, rbuf);
      if (files) {
        pos->row(tt, in.q().data(), n);
        vel->row(tt, in.v().data(), n);
        acc->row(tt, in.a().data(), n);
        rea->row(tt, rbuf.data(), rbuf.size());
        if (vtk) vtk->write(tt, in.q().data());
      }
      if (hist) {
        hist->time.push_back(tt);
        hist->positions.insert(hist->positions.end(), in.q().begin(), in.q().end());
        hist->velocities.insert(hist->velocities.end(), in.v().begin(), in.v().end());
        hist->accelerations.insert(hist->accelerations.end(), in.a().begin(), in.a().end());
        hist->reactions.insert(hist->reactions.end(), rbuf.begin(), rbuf.end());
      }
      if (opts.output_interval > 0)
        next_output = (std::floor(tt / opts.output_interval + 1e-9) + 1) * opts.output_interval;
    }
    out_seconds += t.seconds();
  };
  if (hist) {
    *hist = SimulationHistory{};
    hist->coordinate_names = model.coordinate_names();
    hist->reaction_names = reaction_names(model);
  }
  if (files) {
    std::filesystem::create_directories(opts.output_dir);
    std::vector<std::string> h{"time"};
    for (const auto& s : model.coordinate_names()) h.push_back(s);
    pos = std::make_unique<Csv>(opts.output_dir + "/positions.csv", h);
    vel = std::make_unique<Csv>(opts.output_dir + "/velocities.csv", h);
    acc = std::make_unique<Csv>(opts.output_dir + "/accelerations.csv", h);
    std::vector<std::string> rh{"time"};
    for (const auto& s : reaction_names(model)) rh.push_back(s);
    rea = std::make_unique<Csv>(opts.output_dir + "/reactions.csv", rh);
    steps = std::make_unique<Csv>(
        opts.output_dir + "/steps.csv",
        std::vector<std::string>{"step", "time", "h", "order", "newton_iterations",
                                 "factorizations", "rejected", "assembly_seconds", "solver_seconds",
                                 "kinetic_energy", "potential_energy", "total_energy",
                                 "position_violation", "velocity_violation"});
    if (opts.vtk) vtk = std::make_unique<VtkSeries>(model, opts.output_dir + "/vtk");
  }
  double kin = 0, pot = 0, pv = 0, vv = 0;
  in.system().energy(in.q().data(), in.v().data(), in.t(), &kin, &pot);
  in.constraint_violation(&pv, &vv);
  res.energy_initial = kin + pot;
  res.max_position_violation = pv;
  res.max_velocity_violation = vv;
  write_state(kin, pot);
  if (files)
    steps->raw(fmt::format("0,{:.17g},0,0,0,0,0,0,0,{:.17g},{:.17g},{:.17g},{:.6e},{:.6e}", in.t(),
                           kin, pot, kin + pot, pv, vv));
  if (hist) {
    StepRecord r0;
    r0.t = in.t();
    r0.kinetic_energy = kin;
    r0.potential_energy = pot;
    r0.position_violation = pv;
    r0.velocity_violation = vv;
    hist->steps.push_back(r0);
  }
  Progress bar(opts.progress ? opts.progress_stream : nullptr, opts.integrator.t_end);
  try {
    while (!in.done()) {
      const StepInfo s = in.advance();
      in.system().energy(in.q().data(), in.v().data(), in.t(), &kin, &pot);
      in.constraint_violation(&pv, &vv);
      res.max_position_violation = std::max(res.max_position_violation, pv);
      res.max_velocity_violation = std::max(res.max_velocity_violation, vv);
      write_state(kin, pot);
      if (files) {
        steps->raw(fmt::format(
            "{},{:.17g},{:.6e},{},{},{},{},{:.6e},{:.6e},{:.17g},{:.17g},{:.17g},"
            "{:.6e},{:.6e}",
            s.step, s.t, s.h, s.order, s.newton_iterations, s.factorizations, s.rejected,
            s.assembly_seconds, s.solver_seconds, kin, pot, kin + pot, pv, vv));
      }
      if (hist)
        hist->steps.push_back(StepRecord{s.step, s.t, s.h, s.order, s.newton_iterations,
                                         s.factorizations, s.rejected, s.assembly_seconds,
                                         s.solver_seconds, kin, pot, pv, vv});
      bar.update(in.t(), in.stats().steps, in.stats().newton_iterations);
    }
    res.complete = true;
  } catch (const Error& e) {
    res.message = e.what();
  }
  bar.update(in.t(), in.stats().steps, in.stats().newton_iterations, true);
  bar.finish();
  res.energy_final = kin + pot;
  res.t_reached = in.t();
  res.stats = in.stats();
  if (files) {
    for (Csv* c : {pos.get(), vel.get(), acc.get(), rea.get(), steps.get()}) c->flush();
    if (vtk) vtk->finish();
    write_status(opts.output_dir, res);
  }
  res.output_seconds = out_seconds;
  res.wall_seconds = wall.seconds();
  return res;
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
                   r.complete ? "complete" : "PARTIAL (stopped early)", r.t_reached);
  if (!r.complete) o += fmt::format("reason                {}\n", r.message);
  o += fmt::format("steps                 {} accepted, {} rejected ({} by the local error test)\n",
                   s.steps, s.rejected, s.error_rejections);
  o += fmt::format("Newton iterations     {} ({:.2f} per step)\n", s.newton_iterations,
                   s.steps ? double(s.newton_iterations) / s.steps : 0.0);
  o += fmt::format(
      "factorizations        {} (analyses {}: first 1, new partitions {}, contact-set changes {}, "
      "perturbed pivots {}; static pivots left {})\n",
      s.factorizations, s.analyses, s.repartitions, s.contact_updates, s.reanalyses,
      s.perturbed_pivots);
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
        "each\n",
        1e3 * s.analysis_seconds / s.analyses, 1e3 * s.factor_seconds / s.factorizations,
        1e3 * s.solve_seconds / s.solves);
  o += fmt::format("energy [J]            initial {:.9g}, final {:.9g}\n", r.energy_initial,
                   r.energy_final);
  o += fmt::format("constraint violation  max |Phi| {:.3e}, max |dPhi/dt| {:.3e}\n",
                   r.max_position_violation, r.max_velocity_violation);
  return o;
}

}  // namespace strata::mbd
