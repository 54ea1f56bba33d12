// strata::mbd — what a simulation run writes while it steps (internal to simulate()):
// the CSV histories (positions, velocities, accelerations, reactions, steps) under their
// partial names until the run completes, the ParaView series, the in-memory
// SimulationHistory, and status.json. Rows fall at every step or, with an output interval
// Δ, at t = 0, Δ, 2Δ, … from the BDF interpolation of the step that contains them.
#pragma once

#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "mbd/integrator.hpp"
#include "mbd/simulation.hpp"

namespace strata::mbd {
class VtkSeries;
}  // namespace strata::mbd

namespace strata::mbd::detail {

/// Removes an earlier run's results from `dir` (histories whole and partial, the ParaView
/// series index, status.json), so that they do not pass for this run's.
void clear_earlier_results(const std::string& dir);

/// Writes `dir`/status.json whole (a reader never sees half of it): `state`
/// ("running", "complete", "interrupted", "failed"), r's times, message, warnings and
/// files. Throws Error when it cannot be written.
void write_status(const std::string& dir, const std::string& state, const SimulationResult& r,
                  double t_end, index_t steps, const std::vector<std::string>& files);

class Csv;

/// The outputs of one run of `model` by `in` under `opts` (the objects must outlive it).
class RunOutput {
 public:
  RunOutput(const Model& model, const SimulationOptions& opts, Integrator& in);
  ~RunOutput();
  RunOutput(const RunOutput&) = delete;
  RunOutput& operator=(const RunOutput&) = delete;

  /// Opens the outputs: the in-memory history reset; with an output folder, an earlier
  /// run's results cleared, the histories opened (a resumed run's start with the text its
  /// `checkpoint` saved, and its ParaView frames and next output time are restored), and
  /// status.json says "running" at `res`. Throws Error when a file cannot be written.
  void open(const nlohmann::json* checkpoint, SimulationResult& res);
  /// The rows of the current state (see the file header; the last row at t_end).
  void write_state();
  /// The steps history's row of the initial state (step 0).
  void write_initial_step(const StepRecord& r);
  /// The steps history's row of a step.
  void write_step(const StepRecord& r);
  /// Flushes the histories and finishes the ParaView series; a complete run's histories
  /// take their final names; status.json says `state`.
  void close(const std::string& state, const SimulationResult& res);

  /// For a checkpoint: the next output time, each history's text by name, the ParaView
  /// frames written (empty without a series).
  double next_output() const { return next_output_; }
  nlohmann::json histories() const;
  bool has_vtk() const { return vtk_ != nullptr; }
  std::vector<std::pair<double, std::string>> vtk_frames() const;
  /// Seconds spent writing outputs so far (add_seconds: the checkpoints').
  double seconds() const { return seconds_; }
  void add_seconds(double s) { seconds_ += s; }

 private:
  void write_row(double t, const double* q, const double* v, const double* a,
                 const std::vector<double>& lambda);
  std::vector<std::string> file_list(bool complete) const;

  const Model& model_;
  const SimulationOptions& opts_;
  Integrator& in_;
  const bool files_;
  SimulationHistory* mem_;
  std::vector<std::unique_ptr<Csv>> hist_;
  std::unique_ptr<VtkSeries> vtk_;
  std::vector<double> rbuf_, oq_, ov_, oa_;
  double next_output_ = 0, last_row_t_ = -1, seconds_ = 0;
};

}  // namespace strata::mbd::detail
