// strata::mbd — running a simulation: the integrator loop, time histories (CSV), the
// ParaView series (VTK), a progress bar, partial results on failure, and the summary.
//
// Files written to the output folder:
//   positions.csv, velocities.csv, accelerations.csv  time + one column per coordinate
//   reactions.csv   time + reaction force of each joint on its body j (body i if j is
//                   fixed), global frame, N; then the multipliers λ of every equation
//   steps.csv       per step: time, step size, order, Newton iterations, factorizations,
//                   assembly and solver seconds, kinetic/potential/total energy (J),
//                   max |Φ| and max |Φ̇| (constraint violation)
//   status.json     "complete": true, or false with the reason (results are partial)
//   vtk/            with vtk: one .vtu per output time and series.pvd (ParaView)
#pragma once

#include <cstdio>
#include <string>

#include "mbd/integrator.hpp"
#include "mbd/model.hpp"

namespace strata::mbd {

struct SimulationOptions {
  IntegratorOptions integrator;
  std::string output_dir;      ///< empty: write nothing
  double output_interval = 0;  ///< s between rows of the large CSV files (0: every step)
  bool vtk = false;            ///< also write a ParaView series
  bool progress = false;       ///< draw a progress bar on `progress_stream`
  std::FILE* progress_stream = nullptr;
};

struct SimulationResult {
  bool complete = false;
  std::string message;  ///< why the run stopped early (empty when complete)
  double t_reached = 0;
  double wall_seconds = 0;
  double output_seconds = 0;
  double max_position_violation = 0, max_velocity_violation = 0;
  double energy_initial = 0, energy_final = 0;
  IntegratorStats stats;
};

/// Runs the model to opts.integrator.t_end. Errors during the integration do not
/// throw: the result is marked incomplete and the files written so far are kept.
/// Errors before the first step (model, initial conditions) throw.
SimulationResult simulate(const Model& model, const SimulationOptions& opts);

/// Human-readable summary (steps, Newton iterations, factorizations, solver vs assembly
/// time, matrix sizes).
std::string summary(const Model& model, const SimulationResult& r);

}  // namespace strata::mbd
