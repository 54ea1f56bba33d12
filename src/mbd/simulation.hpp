// strata::mbd — running a simulation: the integrator loop, time histories (CSV), the
// ParaView series (VTK), a progress bar, partial results on failure or interruption,
// checkpoints (restart points) and restarts from them, and the summary.
//
// Files written to the output folder:
//   positions.csv, velocities.csv, accelerations.csv  time + one column per coordinate
//   reactions.csv   time + reaction force of each joint on its body j (body i if j is
//                   fixed), global frame, N; then the multipliers λ of every equation
//   steps.csv       per step: time, step size, order, Newton iterations, factorizations,
//                   assembly and solver seconds, kinetic/potential/total energy (J),
//                   max |Φ| and max |Φ̇| (constraint violation)
//   status.json     "state": "running", "complete", "failed" or "interrupted"; "complete"
//                   and "partial" booleans, the step and time reached, the reason, the files,
//                   "warnings" and "removed_constraints" (redundant equations switched off)
//   vtk/            with vtk: one .vtu per output time and series.pvd (ParaView)
// Partial results cannot be mistaken for a whole run: while the run goes on, and after a
// run that stopped early (a failure, an allocation failure, SIGINT/SIGTERM, a kill), the
// histories are named NAME.partial.csv; only a run that reached t_end renames them to
// NAME.csv, and then writes status.json with "complete": true. Stale histories of an
// earlier run in the same folder are removed at the start. status.json, the ParaView files
// and the checkpoints are written whole (base/atomic_file.hpp).
// The same rows can be kept in memory instead (or as well): SimulationHistory, filled
// when SimulationOptions::history is set (the Python binding uses it); after a run that
// stopped early it holds the rows up to the last accepted step, like the partial files.
#pragma once

#include <csignal>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <string>

#include "mbd/integrator.hpp"
#include "mbd/model.hpp"

namespace strata::mbd {

/// One row of steps.csv: an accepted step (step 0 is the initial state).
struct StepRecord {
  index_t step = 0;
  double t = 0, h = 0;  ///< s
  int order = 0, newton_iterations = 0, factorizations = 0, rejected = 0;
  double assembly_seconds = 0, solver_seconds = 0;
  double kinetic_energy = 0, potential_energy = 0;        ///< J
  double position_violation = 0, velocity_violation = 0;  ///< max |Φ|, max |Φ̇|
};

/// The time histories of a run in memory: the rows of positions/velocities/
/// accelerations/reactions.csv and steps.csv, at full double precision. Matrices are
/// row-major, one row per output time.
struct SimulationHistory {
  std::vector<std::string> coordinate_names;  ///< n names ("link3.e2")
  std::vector<std::string> reaction_names;    ///< joint forces ("j1.Fx"), then multipliers
  std::vector<double> time;                   ///< output times (s), rows
  std::vector<double> positions, velocities, accelerations;  ///< rows × n (SI units)
  std::vector<double> reactions;  ///< rows × reaction_names.size() (N; λ as solved)
  std::vector<StepRecord> steps;  ///< every accepted step, the initial state first
};

struct SimulationOptions {
  IntegratorOptions integrator;
  std::string output_dir;  ///< empty: write nothing
  /// s between rows of the large CSV files (0: every step). Rows fall at t = 0, Δ, 2Δ, …
  /// (dense output: the BDF interpolation polynomial of the step containing the time;
  /// reactions there are interpolated linearly) and at t_end.
  double output_interval = 0;
  bool vtk = false;       ///< also write a ParaView series
  bool progress = false;  ///< draw a progress bar on `progress_stream`
  std::FILE* progress_stream = nullptr;
  /// Write a checkpoint (restart point) to checkpoint_dir/checkpoint.cbor after every this
  /// many accepted steps, except after the step that ends the run, and when the run is
  /// interrupted (0: never). Each checkpoint replaces the previous one atomically.
  index_t checkpoint_every = 0;
  std::string checkpoint_dir;
  /// Kept in every checkpoint as it is (the command line stores the model document there).
  nlohmann::json checkpoint_meta;
  /// Continue from this checkpoint (read_checkpoint) instead of the initial conditions.
  /// The integrator options should be checkpoint_integrator_options(*resume) (t_end may be
  /// larger); the histories written before the checkpoint are written out again first.
  const nlohmann::json* resume = nullptr;
  /// Set asynchronously (a signal handler) to a nonzero signal number: the run stops before
  /// the next step, keeps its partial results and writes a checkpoint if checkpointing.
  const volatile std::sig_atomic_t* interrupt = nullptr;
  /// When set, cleared and filled with the same rows as the CSV files (at the same
  /// output_interval), whether or not output_dir is set.
  SimulationHistory* history = nullptr;
};

struct SimulationResult {
  bool complete = false;
  std::string state;    ///< "complete", "failed" or "interrupted"
  std::string message;  ///< why the run stopped early (empty when complete)
  double t_reached = 0;
  double wall_seconds = 0;
  double output_seconds = 0;
  double max_position_violation = 0, max_velocity_violation = 0;
  double energy_initial = 0, energy_final = 0;
  IntegratorStats stats;
  index_t checkpoint_step = 0;  ///< step of the last checkpoint written (0: none)
  /// Conditions that make the results doubtful although the run completed (energy drift
  /// of a conservative model beyond IntegratorOptions::energy_tolerance); also in
  /// status.json ("warnings") and the summary.
  std::vector<std::string> warnings;
  /// Redundant constraint equations switched off for the run (their names), also in
  /// status.json ("removed_constraints") and the summary.
  std::vector<std::string> removed_constraints;
  /// Models with a "reference": the deviation at the reference time (Model::reference_error;
  /// −1: the run did not get there) and which value deviated most. Beyond the reference's
  /// tolerance it is also a warning.
  double reference_error = -1;
  std::string reference_worst;
};

/// Marks the output folder `dir` of a run that failed before its first step (the model
/// could not be read or built, no consistent initial conditions, a bad option): the
/// results of an earlier run there are removed (histories, the ParaView series index,
/// status.json) and status.json says "failed" with `reason`, no files and t_end 0, so that
/// nothing in the folder passes for this run's. Creates `dir` if needed; an empty `dir`
/// does nothing. Throws Error (std::filesystem errors included) when the folder cannot
/// be written.
void mark_failed_before_start(const std::string& dir, const std::string& reason);

/// The settings of a run as `strata simulate` takes them (and strata.simulate in
/// Python): 0 means "the model's value" for t_end, step, order, output_interval and the
/// Newton tolerance (model files carry these in their "simulation" object).
struct RunSettings {
  double t_end = 0, step = 0;  ///< s
  int order = 0;               ///< BDF order 1..5
  /// strata's options for the Newton matrices (IntegratorOptions::solver); checked by
  /// validate.
  Options solver = engine_solver_options();
  bool full_newton = false;    ///< refactorize at every Newton iteration
  int anderson_depth = -1;     ///< IntegratorOptions::anderson_depth (< 0: its default)
  double newton_tol = 0;       ///< relative Newton tolerance
  bool variable_step = false;  ///< variable step and order with local error control
  double rtol = 1e-4, atol = 1e-6, max_step = 0;  ///< of variable steps (max_step 0: t_end/10)
  bool dense_reference = false;                   ///< dense LAPACK instead of strata (diagnosis)
  bool condensation = true;                       ///< IntegratorOptions::condensation
  FormulationChoice formulation = FormulationChoice::automatic;
  double energy_tolerance = -1;  ///< relative energy drift allowed (< 0: the model's or 1e-3)
  bool verbose = false;          ///< every Newton iteration to stderr
  std::string output_dir;        ///< CSV files (and vtk/) here; empty: none
  double output_interval = 0;    ///< s between rows of the histories
  bool vtk = false;
  std::string dump_dir;  ///< write the Newton matrix of step dump_step here (Matrix Market)
  index_t dump_step = 1;
};

/// The SimulationOptions of a run of `model` with `s`: the model's defaults where s
/// leaves a value at 0. Throws InvalidInput for a negative time or step, an order outside
/// 1..5, a non-positive tolerance or a dump step below 1.
SimulationOptions simulation_options(const Model& model, const RunSettings& s);

/// Runs the model to opts.integrator.t_end. Errors during the integration (including
/// OutOfMemory and std::bad_alloc) and interruptions do not throw: the result is marked
/// incomplete, with the reason, and the files written so far are kept, named partial.
/// Errors before the first step (model, initial conditions, a checkpoint that does not fit
/// the model) throw; an allocation failure there throws OutOfMemory.
SimulationResult simulate(const Model& model, const SimulationOptions& opts);

/// Reads DIR/checkpoint.cbor. Throws InvalidInput naming the file when it is missing or
/// not a strata checkpoint.
nlohmann::json read_checkpoint(const std::string& dir);

/// The integrator options a checkpoint was written with (the variable-step default of
/// max_step, t_end/10, is stored resolved, so that a longer t_end does not change it).
IntegratorOptions checkpoint_integrator_options(const nlohmann::json& checkpoint);

/// Human-readable summary (steps, Newton iterations, factorizations, solver vs assembly
/// time, matrix sizes).
std::string summary(const Model& model, const SimulationResult& r);

}  // namespace strata::mbd
