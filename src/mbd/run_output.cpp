// strata::mbd — a simulation run's outputs (see run_output.hpp).
#include "mbd/run_output.hpp"

#include <fmt/format.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>

#include "base/atomic_file.hpp"
#include "base/timer.hpp"
#include "mbd/vtk.hpp"

namespace strata::mbd::detail {

// A CSV history written row by row to NAME.partial.csv (renamed to NAME.csv only when the
// run completes), flushed at the end and at checkpoints, so that a run that stops keeps
// its rows. A resumed run starts the file with the text saved in the checkpoint.
class Csv {
 public:
  Csv(const std::string& dir, const std::string& name, const std::vector<std::string>& header,
      const std::string* resumed_text)
      : dir_(dir), name_(name), out_(partial_path()) {
    if (!out_) throw Error("cannot write " + partial_path());
    if (resumed_text) {
      out_ << *resumed_text;
      return;
    }
    for (std::size_t i = 0; i < header.size(); ++i) out_ << (i ? "," : "") << header[i];
    out_ << '\n';
  }
  // One row formatted into a buffer kept from row to row, then written at once.
  void row(double t, const double* x, std::size_t n) {
    buf_.clear();
    fmt::format_to(std::back_inserter(buf_), "{:.17g}", t);
    for (std::size_t i = 0; i < n; ++i) fmt::format_to(std::back_inserter(buf_), ",{:.17g}", x[i]);
    buf_.push_back('\n');
    out_.write(buf_.data(), static_cast<std::streamsize>(buf_.size()));
  }
  void raw(const std::string& line) { out_ << line << '\n'; }
  void flush() {
    out_.flush();
    if (!out_) throw Error("cannot write " + partial_path());
  }
  // The whole file so far (for a checkpoint).
  std::string text() {
    flush();
    std::ifstream in(partial_path(), std::ios::binary);
    std::ostringstream ss;
    ss << in.rdbuf();
    if (!in) throw Error("cannot read back " + partial_path() + " for the checkpoint");
    return ss.str();
  }
  // The run is complete: close and rename NAME.partial.csv to NAME.csv.
  void complete() {
    flush();
    out_.close();
    rename_file(partial_path(), dir_ + "/" + name_ + ".csv");
  }
  const std::string& name() const { return name_; }
  std::string partial_path() const { return dir_ + "/" + name_ + ".partial.csv"; }

 private:
  std::string dir_, name_;
  std::ofstream out_;
  fmt::memory_buffer buf_;
};

namespace {

const char* const kHistories[] = {"positions", "velocities", "accelerations", "reactions", "steps"};

// Results of an earlier run in `dir` must not pass for this run's: its histories (whole
// and partial), its ParaView series index and its status.json are removed.
}  // namespace

void clear_earlier_results(const std::string& dir) {
  namespace fs = std::filesystem;
  for (const char* name : kHistories)
    for (const char* suffix : {".csv", ".partial.csv"}) fs::remove(dir + "/" + name + suffix);
  fs::remove(dir + "/vtk/series.pvd");
  fs::remove(dir + "/status.json");
}

namespace {

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
// (q, λ of every model row, t): the state of a row of the histories
void reactions(const Model& m, const double* q, const std::vector<double>& lam, double t,
               std::vector<double>& out) {
  out.clear();
  std::vector<double> lq, zero;
  ConstraintEval ce;
  index_t row = 0;
  for (const auto& c : m.constraints) {
    if (c->reaction_dim > 0) {
      lq.resize(c->dofs.size());
      for (std::size_t i = 0; i < c->dofs.size(); ++i) lq[i] = q[c->dofs[i]];
      zero.assign(c->dofs.size(), 0.0);
      c->evaluate_gradient(lq.data(), zero.data(), zero.data(), t, ce);
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

}  // namespace

// status.json, written whole (a reader never sees half of it).
void write_status(const std::string& dir, const std::string& state, const SimulationResult& r,
                  double t_end, index_t steps, const std::vector<std::string>& files) {
  const bool complete = state == "complete";
  auto list = [](const std::vector<std::string>& v) {
    std::string f;
    for (std::size_t i = 0; i < v.size(); ++i) f += (i ? ", \"" : "\"") + json_escape(v[i]) + "\"";
    return f;
  };
  const std::string f = list(files);
  write_file_atomically(
      dir + "/status.json",
      fmt::format("{{\n  \"state\": \"{}\",\n  \"complete\": {},\n  \"partial\": {},\n"
                  "  \"t_reached\": {:.17g},\n  \"t_end\": {:.17g},\n  \"steps\": {},\n"
                  "  \"message\": \"{}\",\n  \"checkpoint_step\": {},\n  \"files\": [{}],\n"
                  "  \"warnings\": [{}],\n  \"removed_constraints\": [{}],\n"
                  "  \"reference_error\": {}\n}}\n",
                  state, complete, !complete, r.t_reached, t_end, steps, json_escape(r.message),
                  r.checkpoint_step, f, list(r.warnings), list(r.removed_constraints),
                  r.reference_error >= 0 ? fmt::format("{:.6e}", r.reference_error) : "null"));
}

RunOutput::RunOutput(const Model& model, const SimulationOptions& opts, Integrator& in)
    : model_(model),
      opts_(opts),
      in_(in),
      files_(!opts.output_dir.empty()),
      mem_(opts.history),
      oq_(model.n),
      ov_(model.n),
      oa_(model.n) {}

RunOutput::~RunOutput() = default;

void RunOutput::open(const nlohmann::json* ck, SimulationResult& res) {
  if (mem_) {
    // (a resumed run's rows start at the restart point: the rows before it are in the
    // checkpoint's CSV text only)
    *mem_ = SimulationHistory{};
    mem_->coordinate_names = model_.coordinate_names();
    mem_->reaction_names = reaction_names(model_);
  }
  if (ck) next_output_ = ck->at("simulation").at("next_output").get<double>();
  if (!files_) return;
  std::filesystem::create_directories(opts_.output_dir);
  clear_earlier_results(opts_.output_dir);
  std::vector<std::string> h{"time"};
  for (const auto& s : model_.coordinate_names()) h.push_back(s);
  std::vector<std::string> rh{"time"};
  for (const auto& s : reaction_names(model_)) rh.push_back(s);
  const std::vector<std::string> sh{"step",
                                    "time",
                                    "h",
                                    "order",
                                    "newton_iterations",
                                    "factorizations",
                                    "rejected",
                                    "assembly_seconds",
                                    "solver_seconds",
                                    "kinetic_energy",
                                    "potential_energy",
                                    "total_energy",
                                    "position_violation",
                                    "velocity_violation"};
  const std::vector<std::string>* headers[] = {&h, &h, &h, &rh, &sh};
  for (int k = 0; k < 5; ++k) {
    // a resumed run starts with the rows written before its checkpoint (a checkpoint of a
    // run that wrote no files has none: the histories then start at the restart)
    std::string saved;
    const bool have = ck && ck->at("histories").contains(kHistories[k]);
    if (have) saved = ck->at("histories").at(kHistories[k]).get<std::string>();
    hist_.push_back(std::make_unique<Csv>(opts_.output_dir, kHistories[k], *headers[k],
                                          have ? &saved : nullptr));
  }
  if (opts_.vtk) {
    vtk_ = std::make_unique<VtkSeries>(model_, opts_.output_dir + "/vtk");
    if (ck && ck->at("simulation").contains("vtk_frames"))
      vtk_->restore_frames(
          ck->at("simulation").at("vtk_frames").get<std::vector<std::pair<double, std::string>>>());
  }
  res.t_reached = in_.t();
  res.message = "running";
  write_status(opts_.output_dir, "running", res, opts_.integrator.t_end, in_.stats().steps,
               file_list(false));
  res.message.clear();
}

void RunOutput::write_row(double tt, const double* q, const double* v, const double* a,
                          const std::vector<double>& lam) {
  const index_t n = model_.n;
  reactions(model_, q, lam, tt, rbuf_);
  if (files_) {
    hist_[0]->row(tt, q, n);
    hist_[1]->row(tt, v, n);
    hist_[2]->row(tt, a, n);
    hist_[3]->row(tt, rbuf_.data(), rbuf_.size());
    if (vtk_) vtk_->write(tt, q);
  }
  if (mem_) {
    mem_->time.push_back(tt);
    mem_->positions.insert(mem_->positions.end(), q, q + n);
    mem_->velocities.insert(mem_->velocities.end(), v, v + n);
    mem_->accelerations.insert(mem_->accelerations.end(), a, a + n);
    mem_->reactions.insert(mem_->reactions.end(), rbuf_.begin(), rbuf_.end());
  }
  last_row_t_ = tt;
}

void RunOutput::write_state() {
  if (!files_ && !mem_) return;
  Timer t;
  const double tt = in_.t(), dt = opts_.output_interval;
  if (dt <= 0) {
    write_row(tt, in_.q().data(), in_.v().data(), in_.a().data(), in_.model_lambda());
  } else {
    const double eps = 1e-9 * dt;
    for (double k = std::round(next_output_ / dt); k * dt <= tt + eps; k += 1) {
      const double to = k * dt;
      if (std::abs(to - tt) <= eps) {
        write_row(tt, in_.q().data(), in_.v().data(), in_.a().data(), in_.model_lambda());
      } else {
        std::vector<double> lam(in_.system().model_m());
        in_.interpolate(to, oq_.data(), ov_.data(), oa_.data(), lam.data());
        write_row(to, oq_.data(), ov_.data(), oa_.data(), lam);
      }
      next_output_ = (k + 1) * dt;
    }
    if (in_.done() && last_row_t_ < tt - eps)
      write_row(tt, in_.q().data(), in_.v().data(), in_.a().data(), in_.model_lambda());
  }
  seconds_ += t.seconds();
}

void RunOutput::write_initial_step(const StepRecord& r) {
  const double e = r.kinetic_energy + r.potential_energy;
  if (files_)
    hist_[4]->raw(fmt::format("0,{:.17g},0,0,0,0,0,0,0,{:.17g},{:.17g},{:.17g},{:.6e},{:.6e}", r.t,
                              r.kinetic_energy, r.potential_energy, e, r.position_violation,
                              r.velocity_violation));
  if (mem_) mem_->steps.push_back(r);
}

void RunOutput::write_step(const StepRecord& r) {
  if (files_)
    hist_[4]->raw(fmt::format(
        "{},{:.17g},{:.6e},{},{},{},{},{:.6e},{:.6e},{:.17g},{:.17g},{:.17g},{:.6e},{:.6e}", r.step,
        r.t, r.h, r.order, r.newton_iterations, r.factorizations, r.rejected, r.assembly_seconds,
        r.solver_seconds, r.kinetic_energy, r.potential_energy,
        r.kinetic_energy + r.potential_energy, r.position_violation, r.velocity_violation));
  if (mem_) mem_->steps.push_back(r);
}

nlohmann::json RunOutput::histories() const {
  nlohmann::json h = nlohmann::json::object();
  for (const auto& csv : hist_) h[csv->name()] = csv->text();
  return h;
}

std::vector<std::pair<double, std::string>> RunOutput::vtk_frames() const {
  return vtk_ ? vtk_->frames() : std::vector<std::pair<double, std::string>>{};
}

std::vector<std::string> RunOutput::file_list(bool complete) const {
  std::vector<std::string> f;
  for (const auto& c : hist_) f.push_back(c->name() + (complete ? ".csv" : ".partial.csv"));
  if (vtk_) f.push_back("vtk/series.pvd");
  return f;
}

void RunOutput::close(const std::string& state, const SimulationResult& res) {
  if (!files_) return;
  for (const auto& c : hist_) c->flush();
  if (vtk_) vtk_->finish();
  if (res.complete)
    for (const auto& c : hist_) c->complete();
  write_status(opts_.output_dir, state, res, opts_.integrator.t_end, res.stats.steps,
               file_list(res.complete));
}

}  // namespace strata::mbd::detail
