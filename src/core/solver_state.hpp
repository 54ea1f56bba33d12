// strata — the state behind strata::Solver and what its phases' files share (internal).
//
// solver.cpp holds the analysis and factorization phases and the public methods;
// solve_phase.cpp the solve phase (one solve with the factor, the backward error,
// iterative refinement). Both work on a SolverState.
#pragma once

#include <tbb/task_arena.h>

#include <memory>
#include <new>
#include <optional>
#include <vector>

#include "analysis/analysis.hpp"
#include "core/pivot_correction.hpp"
#include "core/rescale.hpp"
#include "numeric/delayed.hpp"
#include "numeric/driver.hpp"
#include "numeric/factor.hpp"
#include "strata/errors.hpp"
#include "strata/options.hpp"
#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"

namespace strata::detail {

struct SolverState {
  Options options;
  std::optional<Analysis> analysis;
  SparseMatrix values;         // canonical input values of the factorized matrix
  std::vector<double> scaled;  // values as assembled (scaled for general)
  // `scaled` page-locked while a GPU backend uploads it at every factorization (declared
  // after it: released first); released before `scaled` is resized (resize_scaled)
  std::unique_ptr<numeric::PinnedHostRange> scaled_pin;
  // `values.values` page-locked: after a value pass on the GPU it and `scaled` trade
  // buffers, each with its pin (reset before `values` is assigned anew)
  std::unique_ptr<numeric::PinnedHostRange> values_pin;
  // `scaled` holds the scaled values of `values`; false after a value pass on the GPU,
  // which leaves them there (values_on_device) and `scaled` stale until a host algorithm
  // needs them (host_scaled)
  bool scaled_current = true;
  bool values_on_device = false;
  // the values of `values` are those of a refactorization that took them from GPU memory
  // or page-locked host memory, kept on the GPU that factored it (values_on_gpu), not yet
  // copied here: host_values fetches them before anything on the host reads them
  bool kept_values_on_device = false;
  // the GPU that factored them holds a copy of the values of `values` as given (kept
  // there by keep_device_input, also when the host has them too): the residuals of
  // checked solves on that GPU read it (numeric::MatrixValues with host null)
  bool values_copy_on_device = false;
  std::vector<double> value_sums;  // per-range vectors of the blocked value passes, kept
  // the host threads of those passes (Options::num_threads), kept: creating a task arena
  // for each parallel loop cost milliseconds per refactorization on a 64-core host
  std::unique_ptr<tbb::task_arena> arena;
  int arena_threads = -1;
  numeric::NumericFactor factor;
  // a solve's right-hand sides in the factor's numbering (apply_inverse), kept between
  // solves; page-locked while a GPU backend copies it (declared after it: released first;
  // released before it is resized)
  std::vector<double> solve_work;
  std::unique_ptr<numeric::PinnedHostRange> solve_work_pin;
  // the extra scaling of the last factorization (core/rescale.hpp), empty when none
  Rescaling rescaling;
  // Pivoting::corrected: the low-rank update every solve with `factor` applies
  // (core/pivot_correction.hpp); inactive when the factor needed none
  PivotCorrection correction;
  // the factor of delayed pivoting (Options::pivoting), valid instead of `factor`
  numeric::DelayedFactor delayed;
  numeric::DelayedWorkspace delayed_work;
  // the numeric phases (numeric/driver.hpp): chosen at analysis from the options (one
  // executor, or one per GPU), or set by SolverAccess (host workers for tests and
  // benchmarks, the distributed solver's collective phases): then `driver_set`
  std::unique_ptr<numeric::NumericDriver> driver;
  bool driver_set = false;
  MatrixType resolved = MatrixType::automatic;
  double norm_inf = 0;                // ‖A‖∞ of the input
  std::uint64_t values_analysis = 0;  // Analysis::id whose canonical pattern `values` holds
  // a new number at every factorization's input stage: names the values of `values` for
  // the copy a GPU keeps for the residuals of checked solves (numeric::MatrixValues::id)
  std::uint64_t values_serial = 0;
  // the analyzed matrix was not canonical: where its entries land in the canonical
  // pattern (input_entry_map), for refactorize(values) in its own order, and the
  // canonical values gathered from those
  std::vector<index_t> input_map;
  std::uint64_t input_map_analysis = 0;
  std::vector<double> gathered;
  // the most entries in a row of `values` (symmetric storage expanded), for the rounding
  // floor of the backward error; computed for the pattern of analysis `row_entries_of`
  index_t max_row_entries = 0;
  std::uint64_t row_entries_of = 0;
  // the determinant's terms that depend on the analysis alone (computed once per analysis
  // `det_terms_of`): Σ log of its row and column scalings, the matching's parity
  double scaling_log_sum = 0;
  int matching_sign = 1;
  std::uint64_t det_terms_of = 0;
  Stats stats;
};

/// Copies the factorized values that a refactorization left on the GPU alone
/// (kept_values_on_device) into `values`, so that the host can read them; nothing when they
/// are there already. Throws InternalError when the device no longer holds them, DeviceError.
void host_values(SolverState& s);

/// The solver's host task arena for Options::num_threads (0: all hardware threads), made
/// on first use and when the option changes.
tbb::task_arena& host_arena(SolverState& s);

/// Runs one phase. A std::bad_alloc from anywhere inside it becomes OutOfMemory naming the
/// phase (its size is not known there); the large buffers already throw OutOfMemory with
/// their size (base/alloc.hpp), which passes through unchanged.
template <class F>
void phase(const char* name, F&& f) {
  try {
    f();
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(0, name);
  }
}

/// One application of the factor `s.factor` or `s.delayed` (solve_phase.cpp): x = F⁻¹b for
/// nrhs columns (original numbering, column-major), without the low-rank correction of
/// Pivoting::corrected. Returns true when the triangular solves ran on the device that
/// holds the factor.
bool apply_factor(SolverState& s, const double* b, double* x, index_t nrhs);

/// The rounding level of a backward error with the factorized matrix `s.values`:
/// (m+1)·u for m the most entries in a row (symmetric storage expanded; Higham, "Accuracy
/// and Stability of Numerical Algorithms", 2nd ed., §3.5), m computed once per pattern.
double rounding_floor(SolverState& s);

/// The solve phase (solve_phase.cpp): x = A⁻¹ b for nrhs columns of n = analysis->n
/// entries each (column-major, original numbering), checked and refined as
/// Options::solve_check says; fills stats.solve. Throws InvalidState before a
/// factorization, InvalidInput for nrhs < 0, a non-finite b or a solution that overflows.
void solve_phase(SolverState& s, const double* b, double* x, index_t nrhs);

}  // namespace strata::detail
