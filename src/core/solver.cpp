// strata — the Solver: phases, type resolution, scaling (the solve phase: solve_phase.cpp).
//
// The Solver keeps the Analysis (pattern), the canonical values of the last factorized
// matrix (for residuals), the factor and the numeric driver (numeric/driver.hpp) with
// its executors and their workspaces. factorize and
// refactorize run the same code: every buffer is sized by the analysis and reused, so a
// refactorization gives bitwise the factor a fresh factorization would. The host passes
// over the values (checks, norms, the matching's scaling) are in value_pass.hpp, the
// equilibration of values far from the analysis's in rescale.hpp.
//
// The solve (solve_phase.cpp) applies the factor once, then (Options::solve_check) checks
// and refines the solution with solve/refinement.hpp: iterative refinement, GMRES where it
// stalls. The state both files work on is core/solver_state.hpp.
//
// Several GPUs (Options::num_gpus resolving to more than one with the CUDA backend): the
// analysis splits the tree for that many workers and the multi-worker driver factors on
// one CUDA executor per GPU (numeric::factorize_multi); the solve fetches the parts'
// panels to the host. The distributed solver sets a driver of its own
// (SolverAccess::set_driver) whose phases are collective over MPI ranks.
#include "strata/solver.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstring>
#include <limits>
#include <numbers>
#include <optional>
#include <span>
#include <string>
#include <string_view>

#include "analysis/analysis.hpp"
#include "base/alloc.hpp"
#include "base/cpu_level.hpp"
#include "base/host_copy.hpp"
#include "base/timer.hpp"
#include "core/rescale.hpp"
#include "core/solver_internal.hpp"
#include "core/solver_state.hpp"
#include "core/value_pass.hpp"
#include "numeric/delayed.hpp"
#include "numeric/driver.hpp"
#include "numeric/factor.hpp"
#include "ordering/matching.hpp"
#include "solve/refinement.hpp"
#include "sparse/canonical.hpp"

namespace strata {

tbb::task_arena& detail::host_arena(SolverState& s) {
  const int threads = s.options.num_threads;
  if (!s.arena || s.arena_threads != threads) {
    s.arena = std::make_unique<tbb::task_arena>(
        threads > 0 ? threads : static_cast<int>(tbb::task_arena::automatic));
    s.arena_threads = threads;
  }
  return *s.arena;
}

namespace {

using detail::blocked_sums;
using detail::check_norms;
using detail::copy_values;
using detail::has_analyzed_pattern;
using detail::host_arena;
using detail::norm_inf;
using detail::phase;
using detail::refactor_values;
using detail::scaled_norm1;
using detail::scaling_clamped;
using detail::SolverState;
using detail::ValueNorms;

// Parity of a permutation: +1 even, -1 odd.
int parity(const std::vector<index_t>& p) {
  std::vector<char> seen(p.size(), 0);
  int sign = 1;
  for (std::size_t i = 0; i < p.size(); ++i) {
    if (seen[i]) continue;
    std::size_t len = 0;
    for (std::size_t j = i; !seen[j]; j = static_cast<std::size_t>(p[j])) {
      seen[j] = 1;
      ++len;
    }
    if (len % 2 == 0) sign = -sign;
  }
  return sign;
}

// The driver of an analysis for `workers` workers (resolve_workers), on the host when
// `host` (Backend::automatic resolved to the CPU: automatic_on_host): kept while the count
// and the backend stay, else one executor on the whole tree or one per GPU over the split
// tree. A driver set through SolverAccess is kept as it is.
void ensure_driver(SolverState& s, int workers, bool host) {
  if (s.driver_set) return;
  if (s.driver && s.driver->workers() == workers &&
      (s.driver->backend() == Backend::cpu) == (host || !numeric::uses_cuda(s.options.backend)))
    return;
  if (host) {
    Options o = s.options;
    o.backend = Backend::cpu;
    s.driver = numeric::make_tree_driver(o);
  } else if (workers > 1) {
    numeric::MultiWorkerConfig config;
    config.work_stealing = s.options.work_stealing;
    // GPUs keep their parts' panels: the host copy is what made several GPUs slower than
    // one (it is fetched only when a host solve needs it)
    config.keep_panels_on_devices = true;
    s.driver = numeric::make_multi_worker_driver(s.options, workers, 0, std::move(config));
  } else {
    s.driver = numeric::make_tree_driver(s.options);
  }
}

// Backend::automatic with a GPU present, and a factor of fewer flops than
// Options::gpu_min_flops: the host factors and solves (where the GPU's fixed costs would
// outweigh what it saves).
bool automatic_on_host(const Options& o, const Analysis& an) {
  return o.backend == Backend::automatic && numeric::uses_cuda(o.backend) &&
         an.stats.factor_flops < o.gpu_min_flops;
}

// Sizes the scaled values to n, first releasing their pinning if that may move them.
void resize_scaled(SolverState& s, std::size_t n, const char* what) {
  if (s.scaled.size() == n) return;
  s.scaled_pin.reset();
  sized_resize(s.scaled, n, what);
}

// Pins the scaled values for the GPU uploads when a CUDA executor will read them (a copy
// from pageable memory goes through a staging buffer at a fraction of the pinned rate).
// Kept while the storage stays; nothing when pinning is refused.
void pin_scaled(SolverState& s) {
  const std::size_t bytes = s.scaled.size() * sizeof(double);
  if (s.scaled_pin && s.scaled_pin->data() == s.scaled.data() && s.scaled_pin->bytes() == bytes)
    return;
  s.scaled_pin.reset();
  if (s.driver && s.driver->uploads_values())
    s.scaled_pin = numeric::pin_host_memory(s.scaled.data(), bytes);
}

// The CUDA backend's device set-up at analysis (Executor::prepare: uploads, the device
// memory plan, streams and library handles), as cuDSS's analysis phase prepares the
// device; the first factorization is then numeric work only. Nothing for a driver that
// does not upload values to a GPU (CPU backend, host workers, the distributed driver), or
// without a GPU (factorize then reports that). A failure here is not reported: the factorization
// meets it again and reports it with its context (its OutOfMemory releases what was allocated).
// Returns the seconds spent.
double prepare_devices(SolverState& s) {
  if (!s.driver->uploads_values() || !numeric::cuda_available()) return 0;
  const Timer t;
  try {
    const Analysis& an = *s.analysis;
    s.driver->prepare(an);
    // the factor's host arrays (its row indices: Σ rows of the fronts, 0.3 GB for a
    // Laplacian 100³) sized and first touched here, not in the first factorization
    numeric::prepare_factor(an, an.type == MatrixType::automatic ? MatrixType::spd : an.type,
                            s.factor, false);
    pin_scaled(s);
  } catch (const InternalError&) {
    throw;  // a bug, not a device that could not be set up
  } catch (const Error& e) {
    s.analysis->stats.device_setup_error = e.what();
    s.driver->drop_executors();
  }
  return t.seconds();
}

// At analysis, for an input already in the analyzed (canonical) pattern: the copy of its
// pattern the solver keeps for the residuals, the scaled values' storage and the value
// pass's per-range sums (64 MB for n = 10⁶, zero-filled the first time), made here
// so that the first factorization copies only values, as every refactorization does (the
// pattern copy and the first touch of these arrays are otherwise several times the input
// work of a refactorization).
void keep_analyzed_input(SolverState& s, const SparseMatrix& a) {
  const Analysis& an = *s.analysis;
  s.values_pin.reset();
  s.kept_values_on_device = false;
  s.values_copy_on_device = false;
  s.input_map.clear();
  s.input_map_analysis = 0;
  if (has_analyzed_pattern(an, a, host_arena(s))) {
    s.values = a;
  } else {
    // another form (CSR, duplicates, a symmetric matrix's full or upper storage): the
    // analyzed pattern kept with zero values until a factorization, and where the input's
    // entries land in it, so that refactorize(values) can take values in its order
    s.input_map = detail::input_entry_map(an, a);
    s.input_map_analysis = an.id;
    s.values = SparseMatrix{};
    s.values.n_rows = s.values.n_cols = an.n;
    s.values.offsets = an.pattern_offsets;
    s.values.indices = an.pattern_indices;
    s.values.values.assign(an.pattern_indices.size(), 0.0);
  }
  s.values.storage = an.symmetric ? Storage::lower : Storage::full;
  s.values_analysis = an.id;
  resize_scaled(s, s.values.values.size(), "analyze: scaled values");
  // refactor_values' per-range row arrays
  sized_resize(s.value_sums, std::max(s.value_sums.size(), detail::refactor_work_size(an)),
               "analyze: value sums");
}

}  // namespace

void detail::host_values(SolverState& s) {
  if (!s.kept_values_on_device) return;
  if (!s.driver || !s.driver->download_device_input(*s.analysis, s.values.values.data()))
    throw InternalError("the factorized values kept on the GPU could not be copied back");
  s.kept_values_on_device = false;
}

namespace {

// Equilibration sweeps of values far from the analysis's (rescale.hpp), on the host or the
// device: each halves the logarithm of every row's and column's distance from 1.
constexpr int kRescalingSweeps = 3;

// `values` as the host can read them: values in GPU memory copied into `fetched` first.
std::span<const double> host_readable(std::span<const double> values,
                                      std::vector<double>& fetched) {
  if (numeric::device_memory_of(values.data()) < 0) return values;
  fetched.resize(values.size());
  numeric::copy_from_device(fetched.data(), values.data(), values.size());
  return fetched;
}

// The input stage on the GPU (the tree driver's CUDA executor, numeric/cuda/value_pass.cu)
// for `values` in the entry order of `pattern`, the analyzed pattern: staged in the
// page-locked `scaled`, checked, scaled, equilibrated again where they are far from the
// analysis's (the host's sweeps, on the device) and measured on the device, which keeps
// the scaled values for the factorization. On acceptance the staged values become the
// kept ones (the two buffers trade places, so nothing is copied twice); refused values
// (not finite, overflowing sums) throw with the kept values and the factor as they were.
// Values the caller holds in GPU memory or page-locked host memory go to the device from
// there, unstaged, and the device keeps a copy of them as given, which becomes the kept
// values (copied to the host only when the host needs them: host_values); where the device
// has no room for that copy, the host copies them. False, with nothing changed that matters, where
// the driver has no such pass. Sets norm1 = ‖B‖₁.
bool values_on_gpu(SolverState& s, const SparseMatrix& pattern, std::span<const double> values,
                   double& norm1) {
  const Analysis& an = *s.analysis;
  if (!s.driver->uploads_values() || values.empty()) return false;
  tbb::task_arena& arena = host_arena(s);
  resize_scaled(s, values.size(), "factorize: staged values");
  const bool on_device = numeric::device_memory_of(values.data()) >= 0;
  const bool direct = on_device || numeric::page_locked(values.data(), values.size_bytes());
  if (!direct) pin_scaled(s);
  double* staged = s.scaled.data();
  numeric::StageValues stage;
  if (!direct)
    stage = [&](std::size_t b, std::size_t e, const numeric::StagedPiece& done) {
      s.scaled_current = false;  // raw values now, whatever follows
      detail::stage_range(staged + b, values.data() + b, e - b, arena,
                          [&](std::size_t pb, std::size_t pe) { done(b + pb, b + pe); });
    };
  // values far from the analysis's are equilibrated again there, as on the host (not
  // when the analysis's scaling was clamped: see prepare_values)
  const bool equilibrate = !an.row_scaling.empty() && !scaling_clamped(an);
  numeric::DeviceValueNorms dn;
  // the values as given kept on the device too where checked solves will read them there
  // (a copy on the device, instead of one from the host per factorization)
  const bool keep_copy = s.options.solve_check == SolveCheck::always && s.options.gpu_refinement;
  if (!s.driver->scale_values_on_device(an, direct ? values.data() : staged, stage,
                                        equilibrate ? kRescalingSweeps : 0, direct || keep_copy,
                                        dn))
    return false;
  // refused: the host names the first bad value or sum
  std::vector<double> fetched;
  if (!dn.finite) detail::throw_first_not_finite(pattern, host_readable(values, fetched).data());
  if (!dn.sums_finite) {
    check_norms(pattern, host_readable(values, fetched).data());
    throw InternalError("the device found a row or column sum that overflows; the host did not");
  }
  if (equilibrate && !dn.equilibrated && dn.rescaling_sweeps == 0) return false;
  s.factor.valid = false;
  s.correction.clear();
  s.delayed.valid = false;
  s.norm_inf = dn.norm_inf;
  norm1 = dn.scaled_norm1;
  if (!direct) {
    std::swap(s.values.values, s.scaled);  // same size: the kept values are the staged ones
    std::swap(s.values_pin, s.scaled_pin);
    s.kept_values_on_device = false;
    s.values_copy_on_device = dn.input_copied && s.driver->keep_device_input(an);
  } else {
    s.scaled_current = false;  // of the values before
    s.kept_values_on_device = dn.input_copied && s.driver->keep_device_input(an);
    s.values_copy_on_device = s.kept_values_on_device;
    if (!s.kept_values_on_device && on_device)
      numeric::copy_from_device(s.values.values.data(), values.data(), values.size());
    else if (!s.kept_values_on_device)
      copy_values(s.values.values, values, arena);
  }
  s.values_on_device = true;
  s.rescaling = Rescaling{};
  if (dn.rescaling_sweeps > 0) {
    s.rescaling.row = std::move(dn.row_rescaling);
    s.rescaling.col = std::move(dn.col_rescaling);
    s.rescaling.sweeps = dn.rescaling_sweeps;
  }
  return true;
}

// The scaled values on the host for a host algorithm (the delayed factorization) after a
// value pass on the GPU: copied back from the device (one copy instead of the host's pass
// and sweeps, up to six passes over the entries), else recomputed from the kept values by
// the host's pass, which gives the bits the device computed.
void host_scaled(SolverState& s) {
  if (s.scaled_current) return;
  const Analysis& an = *s.analysis;
  if (s.values_on_device && s.scaled.size() == an.pattern_indices.size() &&
      s.driver->download_scaled_values(an, s.scaled.data())) {
    s.scaled_current = true;
    return;
  }
  host_values(s);
  refactor_values(*s.analysis, s.values, s.values.values.data(), host_arena(s), s.value_sums,
                  s.scaled);
  apply_rescaling(s.values, s.rescaling, s.scaled, &host_arena(s));  // the device's, if any
  s.scaled_current = true;
}

// The input stage of a factorization: the values checked (finite, the analyzed pattern
// or a canonical form of a new one), their norms, the scaling of the analysis applied
// into s.scaled and, for values far from the analysis's, equilibrated again
// (s.rescaling). Returns ‖B‖₁ of the scaled matrix B. Throws InvalidInput before the
// current factor is touched, so that bad input leaves the solver usable. The values are
// those of `a`, or, with a == nullptr, `values` in the entry order of the kept pattern
// (Solver::refactorize(span): the caller vouches for the pattern).
double prepare_values(SolverState& s, const SparseMatrix* a, std::span<const double> values) {
  const Analysis& an = *s.analysis;
  const bool scale = !an.row_scaling.empty();
  double norm1 = 0;                      // of the scaled matrix, for static pivoting
  bool equilibrated = false;             // B's row and column maxima known to be within a factor 2
  std::vector<double> row_max, col_max;  // B's maxima when known and not equilibrated
  tbb::task_arena& arena = host_arena(s);
  s.values_on_device = false;
  ++s.values_serial;  // whatever follows: the values may change from here on
  const bool analyzed_pattern = a == nullptr || has_analyzed_pattern(an, *a, arena);
  if (analyzed_pattern && a != nullptr && s.values_analysis != an.id) {
    // the pattern kept from now on; no factor of this analysis exists that the values
    // could still belong to
    s.values_pin.reset();
    s.values = *a;
    s.values.storage = an.symmetric ? Storage::lower : Storage::full;
    s.values_analysis = an.id;
    s.kept_values_on_device = false;
    s.values_copy_on_device = false;
  }
  if (analyzed_pattern && values_on_gpu(s, s.values, values, norm1)) return norm1;
  s.kept_values_on_device = false;  // every path below writes the kept values
  s.values_copy_on_device = false;
  std::vector<double> fetched;  // every path below reads the values on the host
  values = host_readable(values, fetched);
  s.scaled_current = true;  // every path below writes the scaled values
  if (analyzed_pattern) {
    // Refactorization with the analyzed pattern (a Newton loop, a benchmark): one parallel
    // pass checks the values and the norms and scales them (refactor_values), then only
    // the values are copied. The general path below makes several passes and copies the
    // pattern; on a large matrix that host work was of the order of the GPU refactorization.
    resize_scaled(s, values.size(), "factorize: scaled values");
    const ValueNorms norms =
        refactor_values(an, s.values, values.data(), arena, s.value_sums, s.scaled);
    s.factor.valid = false;
    s.correction.clear();
    s.delayed.valid = false;
    s.norm_inf = norms.norm_inf;
    norm1 = norms.scaled_norm1;
    equilibrated = norms.equilibrated;
    row_max = std::move(norms.row_max);
    col_max = std::move(norms.col_max);
    if (s.values.values.data() != values.data())
      copy_values(s.values.values, values, arena);  // pattern: the analyzed one
  } else {
    SparseMatrix checked = canonical_values(an, *a);
    check_norms(checked);
    s.factor.valid = false;
    s.correction.clear();
    s.delayed.valid = false;
    s.values_pin.reset();
    s.values = std::move(checked);
    s.values_analysis = an.id;
    s.norm_inf = norm_inf(s.values);
    // scaled values: general matrices use Dr·A(:,Q)·Dc from the matching, symmetric
    // indefinite ones D·A·D (row_scaling == col_scaling == D, Q = I; the lower triangle
    // scaled entrywise stays the lower triangle of D·A·D)
    const SparseMatrix& c = s.values;
    resize_scaled(s, c.nnz(), "factorize: scaled values");
    const bool sym = an.symmetric;
    const auto colsum =
        blocked_sums(c, 1, c.storage == Storage::lower, arena, s.value_sums,
                     [&](index_t j, index_t p, double* const* sum) {
                       const index_t i = c.indices[p];
                       const double v = scale ? c.values[p] * an.row_scaling[i] * an.col_scaling[j]
                                              : c.values[p];
                       s.scaled[p] = v;
                       sum[0][j] += std::abs(v);
                       if (sym && i != j) sum[0][i] += std::abs(v);
                     });
    for (double v : colsum[0]) norm1 = std::max(norm1, v);
  }
  // values far from the analysis's: equilibrate B again (a no-op within a factor 2). Not
  // when the analysis's scaling was clamped at e^±700 (values near the ends of the double
  // range): equilibrating further would only move the solve's intermediates toward the
  // subnormal range. The refactorization's pass has already found whether B needs it.
  s.rescaling = Rescaling{};
  if (scale && !equilibrated && !scaling_clamped(an)) {
    s.rescaling = rescale_values(s.values, an.symmetric, s.scaled, kRescalingSweeps, &arena,
                                 &s.value_sums, row_max, col_max);
    if (!s.rescaling.row.empty())
      norm1 = scaled_norm1(s.values, an.symmetric, s.scaled, arena, s.value_sums);
  }
  return norm1;
}

// Pivoting::corrected after a fixed-order factorization that shifted static pivots
// (numeric/static_pivot.hpp): the low-rank correction of its solves
// (core/pivot_correction.hpp). Returns true when s.correction is active; false (cleared)
// when delayed pivoting must take over: the pivots could not all be told, there are more
// than Options::max_corrected_pivots, A is singular to working precision, or the corrected
// solve of the probe b = A·x̂ (correction_probe) misses the backward error that a checked
// solve must reach, max(Options::refinement_tolerance, rounding floor), even after one
// step of refinement (none where Options::refinement_max_steps is 0): later solves would
// then need several steps or GMRES, where the delayed factor needs none.
bool correct_shifted_pivots(SolverState& s) {
  detail::PivotCorrection& c = s.correction;
  c.clear();
  const index_t n = s.analysis->n;
  if (!detail::find_shifted_pivots(s, c.entries) ||
      c.k() > static_cast<index_t>(s.options.max_corrected_pivots)) {
    c.clear();
    return false;
  }
  host_values(s);  // the probe's matrix
  std::vector<double> x_hat(n), b(n), x(n);
  detail::correction_probe(n, x_hat.data());
  multiply(s.values, x_hat.data(), b.data());
  bool done = detail::build_correction(
      c, n,
      [&](const double* rhs, double* sol, index_t nrhs) {
        detail::apply_factor(s, rhs, sol, nrhs);
      },
      b.data(), x.data());
  if (done) {  // the probe's solve as a checked solve would refine it, by one step at most
    const Options& o = s.options;
    const solve::Operator op_a = [&](const double* in, double* out) {
      multiply(s.values, in, out);
    };
    const solve::BlockOperator m_inv = [&](const double* in, double* out, index_t k) {
      detail::apply_factor(s, in, out, k);
      detail::apply_correction(c, n, out, k);
    };
    const double floor = detail::rounding_floor(s);
    const solve::RefinementResult probe =
        solve::refine(n, 1, op_a, m_inv, s.norm_inf, b.data(), x.data(),
                      {std::min(o.refinement_max_steps, 1), o.refinement_tolerance, floor, 0});
    c.probe_backward_error = probe.backward_error.at(0);
    done = c.probe_backward_error <= std::max(o.refinement_tolerance, floor);
  }
  const double probe_error = c.probe_backward_error;
  if (!done) c.clear();
  c.probe_backward_error = probe_error;
  return done;
}

// What the numeric stage did: the type factored (automatic resolved) and the perturbed
// pivots of the fixed order (before a delayed factorization).
struct NumericRun {
  MatrixType type = MatrixType::automatic;
  index_t fixed_perturbed = 0;
  bool driver_ran = false;  // false: delayed pivoting alone, on the host
  bool corrected = false;   // Pivoting::corrected made the static pivots regular
};

// The numeric stage: the factor of s.scaled by the driver (one executor, several
// workers, or the distributed driver), Cholesky tried first for an automatic symmetric type, then,
// for a general or symmetric indefinite matrix with delayed pivoting allowed, the delayed
// factorization on the host when the fixed order needed static pivots (or always with
// Pivoting::delayed).
NumericRun factor_values(SolverState& s, double norm1, double static_pivot) {
  const Analysis& an = *s.analysis;
  tbb::task_arena& arena = host_arena(s);
  NumericRun r;
  pin_scaled(s);
  // Pivoting::corrected: LU's static pivots shifted (a negative static pivot,
  // numeric/static_pivot.hpp) and corrected in the solve
  const bool shift = s.options.pivoting == Pivoting::corrected && an.type == MatrixType::general &&
                     s.driver->in_one_process();
  auto run = [&](MatrixType t) {
    r.driver_ran = true;
    s.driver->factorize(an, s.scaled, s.values_on_device, t,
                        numeric::PivotPolicy(shift ? -static_pivot : static_pivot,
                                             s.options.diagonal_pivot_threshold),
                        s.factor);
  };

  MatrixType type = an.type;
  if (type == MatrixType::automatic) {
    // symmetric: try Cholesky, fall back to LDLᵀ on a non-positive pivot
    try {
      run(MatrixType::spd);
      type = MatrixType::spd;
    } catch (const NotPositiveDefinite&) {
      type = MatrixType::symmetric_indefinite;
    }
  }
  // Delayed pivoting (general and symmetric indefinite, the whole tree in this process;
  // Options::pivoting): the fixed order first unless asked to delay always, the delayed
  // factorization on the host when the fixed order needed static pivots.
  s.delayed.valid = false;
  const bool can_delay =
      s.options.pivoting != Pivoting::fixed &&
      (type == MatrixType::general || type == MatrixType::symmetric_indefinite) &&
      s.driver->in_one_process();
  const bool delay_directly = can_delay && s.options.pivoting == Pivoting::delayed;
  index_t fixed_perturbed = 0;
  if (delay_directly) {
    s.factor.valid = false;
    s.correction.clear();
  } else if (type != MatrixType::spd || an.type != MatrixType::automatic) {
    run(type);
    for (const auto& ps : s.factor.front_stats) fixed_perturbed += ps.perturbed;
  }
  // Pivoting::corrected: delayed pivoting only where the correction cannot be made
  if (shift && fixed_perturbed > 0 && correct_shifted_pivots(s)) r.corrected = true;
  if (can_delay && (delay_directly || (fixed_perturbed > 0 && !r.corrected))) {
    // a root takes every remaining pivot by partial pivoting over the whole remaining
    // Schur complement (backward stable); only those at the rounding level of ‖B‖₁ are
    // zeros of a numerically singular matrix and get static pivots
    const double root_static = std::numeric_limits<double>::epsilon() * (norm1 > 0 ? norm1 : 1.0);
    host_scaled(s);
    numeric::factorize_delayed(an, s.scaled.data(), type, s.options.pivot_threshold, root_static,
                               s.delayed, s.delayed_work, arena);
  }
  s.resolved = type;

  r.type = type;
  r.fixed_perturbed = fixed_perturbed;
  return r;
}

// FactorStats of the factorization just made: pivots, inertia, determinant (of A, the
// scaling undone), flop rate and the executors' device figures.
void report_factorization(SolverState& s, const NumericRun& r, double norm1, double input_seconds,
                          const Timer& timer) {
  const Analysis& an = *s.analysis;
  const bool scale = !an.row_scaling.empty();
  const MatrixType type = r.type;
  const index_t fixed_perturbed = r.fixed_perturbed;
  FactorStats& fs = s.stats.factor;
  fs = FactorStats{};
  fs.type = type;
  fs.input_seconds = input_seconds;
  fs.values_scaled_on_device = s.values_on_device;
  fs.backend = s.driver->backend();
  numeric::PivotStats total;
  if (s.delayed.valid)
    for (const auto& fr : s.delayed.fronts) total.merge(fr.stats);
  else
    for (const auto& ps : s.factor.front_stats) total.merge(ps);
  if (s.delayed.valid) {
    fs.delayed_pivoting = true;
    fs.delayed_pivots = s.delayed.delayed;
    fs.fronts_delaying = s.delayed.fronts_delaying;
    fs.fixed_order_perturbed_pivots = fixed_perturbed;
    total.det_sign = numeric::delayed_determinant_sign(an, s.delayed);
  }
  fs.correction_backward_error = s.correction.probe_backward_error;
  if (s.correction.active) {  // det A = det F · det S (core/pivot_correction.hpp)
    fs.corrected_pivots = s.correction.k();
    fs.fixed_order_perturbed_pivots = fixed_perturbed;
    total.perturbed = 0;  // shifted, and corrected by every solve
    total.log_abs_det += s.correction.log_abs_det;
    total.det_sign *= s.correction.det_sign;
  }
  fs.perturbed_pivots = total.perturbed;
  fs.two_by_two_pivots = total.two_by_two;
  fs.inertia_positive = total.positive;
  fs.inertia_negative = total.negative;
  fs.inertia_zero = total.zero;
  fs.inertia_valid = total.perturbed == 0;
  fs.matrix_norm = norm1;
  // det A from det B = det(Dr) det(A) det(Q) det(Dc) (symmetric: det(D)² det(A))
  // (the analysis's terms once per analysis: 2n logarithms were a tenth of a small
  // matrix's refactorization on the GPU)
  if (s.det_terms_of != an.id) {
    s.scaling_log_sum = 0;
    for (double r : an.row_scaling) s.scaling_log_sum += std::log(r);
    for (double v : an.col_scaling) s.scaling_log_sum += std::log(v);
    s.matching_sign = an.matching_perm.empty() ? 1 : parity(an.matching_perm);
    s.det_terms_of = an.id;
  }
  double logdet = total.log_abs_det;
  int sign = total.det_sign;
  if (scale) {
    logdet -= s.scaling_log_sum;
    // the rescaling's factors are powers of two: Σ log = ln 2 · (Σ of their exponents)
    std::int64_t exponents = 0;
    for (double r : s.rescaling.row) exponents += std::ilogb(r);
    for (double v : s.rescaling.col) exponents += std::ilogb(v);
    logdet -= static_cast<double>(exponents) * std::numbers::ln2;
  }
  fs.rescaling_sweeps = s.rescaling.sweeps;
  sign *= s.matching_sign;
  fs.log_abs_determinant = logdet;
  fs.determinant_sign = sign;
  fs.seconds = timer.seconds();
  const double flops = s.stats.analysis.factor_flops * (type == MatrixType::general ? 2.0 : 1.0);
  fs.gflops = fs.seconds > 0 ? flops / fs.seconds * 1e-9 : 0;
  // the executors' figures (device time, bytes moved, batches) are of their last run: none
  // when this factorization delayed its pivots straight away on the host
  if (r.driver_ran) s.driver->report(fs);
}

void run_factorization(SolverState& s, const SparseMatrix* a, std::span<const double> values) {
  Timer timer;
  const double norm1 = prepare_values(s, a, values);
  const double input_seconds = timer.seconds();
  const double static_pivot = s.options.static_pivot_epsilon * (norm1 > 0 ? norm1 : 1.0);
  const NumericRun r = factor_values(s, norm1, static_pivot);
  report_factorization(s, r, norm1, input_seconds, timer);
}

// After an allocation failure in a factorization: give back everything the factor and the
// executor hold (panels, contribution blocks, front workspaces, device buffers), so that
// the caller can free memory elsewhere and try again. The analysis is kept.
void release_factor(SolverState& s) noexcept {
  try {
    host_values(s);  // before the device that keeps them lets them go
  } catch (const Error&) {
    // left on the device that is going: host_values reports it if they are ever needed
  }
  s.factor = numeric::NumericFactor{};
  s.correction = detail::PivotCorrection{};
  s.delayed = numeric::DelayedFactor{};
  s.scaled_pin.reset();
  std::vector<double>().swap(s.scaled);
  s.scaled_current = false;
  s.values_on_device = false;
  s.values_copy_on_device = false;
  std::vector<double>().swap(s.value_sums);
  if (s.driver) s.driver->release();
}

// The factorization of `a`, or (a == nullptr) of `values` in the kept pattern's order.
void factor_phase(SolverState& s, const SparseMatrix* a, std::span<const double> values) {
  try {
    phase("factorize", [&] { run_factorization(s, a, values); });
  } catch (const OutOfMemory&) {
    release_factor(s);
    throw;
  }
}

}  // namespace

Solver::Solver(Options options) : state_(std::make_unique<detail::SolverState>()) {
  // The start-up check has stopped the program on a CPU below the build's level already;
  // this call also links that check into every program that makes a Solver.
  if (!detail::cpu_supports_build_level())
    throw NotSupported(std::string("this CPU lacks instructions of ") + detail::build_cpu_arch() +
                       ", which strata was compiled for: rebuild with -DSTRATA_CPU_ARCH=native");
  state_->options = std::move(options);
}
Solver::~Solver() = default;
Solver::Solver(Solver&&) noexcept = default;
Solver& Solver::operator=(Solver&&) noexcept = default;

namespace {

// The factor and the numeric workspaces of the analysis before go (a new analysis).
void clear_numeric(SolverState& s) {
  s.factor = numeric::NumericFactor{};
  s.correction = detail::PivotCorrection{};
  s.delayed = numeric::DelayedFactor{};
  if (s.driver) s.driver->release_workspaces();
}

// Makes `an` (of A's pattern) the solver's analysis: the input kept for the first
// factorization, the devices prepared, the statistics started anew.
void adopt_analysis(SolverState& s, Analysis an, const SparseMatrix& a) {
  s.analysis = std::move(an);
  s.analysis->stats.backend = s.driver->backend();
  keep_analyzed_input(s, a);
  const double setup = prepare_devices(s);
  s.analysis->stats.device_setup_seconds = setup;
  s.analysis->stats.total_seconds += setup;
  s.stats = Stats{};
  s.stats.analysis = s.analysis->stats;
  s.resolved = MatrixType::automatic;
}

}  // namespace

namespace {

// Solver::analyze with the matching started from `start` (null: from scratch).
void analyze_phase(SolverState& s, const SparseMatrix& a, const ordering::Matching* start) {
  const bool canonical_full = detail::is_canonical_full(a);  // validates a
  clear_numeric(s);
  s.analysis.reset();
  const Options& o = s.options;
  int workers = s.driver_set ? s.driver->workers() : resolve_workers(o);
  // the device's context, streams and handles made while the host analyzes (unless the
  // analysis may still send the factorization to the host: Options::gpu_min_flops)
  if (!(o.backend == Backend::automatic && o.gpu_min_flops > 0)) {
    ensure_driver(s, workers, false);
    s.driver->begin_setup();
  }
  Analysis an = analyze_validated(a, canonical_full, o, workers, start);
  const bool host = !s.driver_set && automatic_on_host(o, an);
  if (host && workers > 1) {  // made again for the one worker the host is
    Options one = o;
    one.backend = Backend::cpu;
    workers = 1;
    an = analyze_validated(a, canonical_full, one, workers, start);
  }
  ensure_driver(s, workers, host);
  adopt_analysis(s, std::move(an), a);
}

// The start as the matching takes it, after checking it against A's order n.
ordering::Matching checked_start(const MatchingStart& start, index_t n) {
  if (static_cast<index_t>(start.row_scaling.size()) != n ||
      static_cast<index_t>(start.matched_column.size()) != n)
    throw InvalidInput("analyze: the matching start has " +
                       std::to_string(start.row_scaling.size()) + " row scalings and " +
                       std::to_string(start.matched_column.size()) +
                       " matched columns for a matrix of order " + std::to_string(n));
  for (index_t i = 0; i < n; ++i) {
    const double d = start.row_scaling[i];
    if (!(std::isfinite(d) && d > 0))
      throw InvalidInput("analyze: the matching start's row_scaling[" + std::to_string(i) +
                         "] = " + std::to_string(d) + " is not finite and positive");
    const index_t j = start.matched_column[i];
    if (j < 0 || j >= n)
      throw InvalidInput("analyze: the matching start's matched_column[" + std::to_string(i) +
                         "] = " + std::to_string(j) + " is out of range [0, " + std::to_string(n) +
                         ")");
  }
  ordering::Matching m;
  m.row_scaling = start.row_scaling;
  m.column_permutation = start.matched_column;
  return m;
}

}  // namespace

void Solver::analyze(const SparseMatrix& a) {
  phase("analyze", [&] { analyze_phase(*state_, a, nullptr); });
}

void Solver::analyze(const SparseMatrix& a, const MatchingStart& start) {
  if (start.empty()) {
    analyze(a);
    return;
  }
  phase("analyze", [&] {
    if (a.n_rows != a.n_cols) {  // analyze's own message
      analyze_phase(*state_, a, nullptr);
      return;
    }
    const ordering::Matching m = checked_start(start, a.n_rows);  // before anything changes
    analyze_phase(*state_, a, &m);
  });
}

MatchingStart Solver::matching_start() const {
  const auto& an = state_->analysis;
  if (!an || an->symmetric || an->matching_perm.empty() || an->row_scaling.empty()) return {};
  return MatchingStart{an->row_scaling, an->matching_perm};
}

namespace {

// analyze_keeping_order and analyze_keeping_matching: `make` (analyze_with_order or
// analyze_with_matching) builds the next analysis from the current one before anything is
// released, so bad input leaves the solver as it was.
template <class Make>
void analyze_keeping(SolverState& s, const SparseMatrix& a, const char* what, Make make) {
  if (!s.analysis) throw InvalidState(std::string(what) + " called before analyze");
  phase("analyze", [&] {
    validate(a);
    const int workers = static_cast<int>(std::max<index_t>(1, s.analysis->stats.workers));
    Analysis next = make(a, *s.analysis, s.options, workers);
    clear_numeric(s);
    adopt_analysis(s, std::move(next), a);
  });
}

}  // namespace

void Solver::analyze_keeping_order(const SparseMatrix& a) {
  analyze_keeping(*state_, a, "analyze_keeping_order",
                  [](const SparseMatrix& m, const Analysis& previous, const Options& o,
                     int workers) { return analyze_with_order(m, previous, o, workers); });
}

index_t Solver::factor_entries_keeping_order(const SparseMatrix& a) const {
  const SolverState& s = *state_;
  if (!s.analysis) throw InvalidState("factor_entries_keeping_order called before analyze");
  index_t entries = 0;
  phase("analyze", [&] {
    validate(a);
    entries = factor_entries_with_order(a, *s.analysis);
  });
  return entries;
}

void Solver::analyze_keeping_matching(const SparseMatrix& a) {
  analyze_keeping(*state_, a, "analyze_keeping_matching",
                  [](const SparseMatrix& m, const Analysis& previous, const Options& o,
                     int workers) { return analyze_with_matching(m, previous, o, workers); });
}

void Solver::analyze_in_pivot_order() {
  SolverState& s = *state_;
  if (!s.analysis || !s.delayed.valid)
    throw InvalidState(
        "analyze_in_pivot_order: the last factorization delayed no pivot "
        "(stats().factor.delayed_pivoting is false), so its order is the analysis's");
  if (s.delayed.type != MatrixType::general)
    throw NotSupported(
        "analyze_in_pivot_order: the order of a symmetric matrix's delayed pivots is not "
        "kept (an LU's row and column pivot sequences are)");
  phase("analyze", [&] {
    std::vector<index_t> rows, cols;
    numeric::delayed_pivot_sequence(*s.analysis, s.delayed, rows, cols);
    const int workers = static_cast<int>(std::max<index_t>(1, s.analysis->stats.workers));
    // computed before anything is released: an allocation failure leaves the solver as it was
    Analysis next = analyze_with_pivot_sequence(*s.analysis, rows, cols, s.rescaling.row,
                                                s.rescaling.col, s.options, workers);
    host_values(s);
    const SparseMatrix values = s.values;  // the factorized values, in the analyzed pattern
    // the same pattern: refactorize(values) keeps taking the analyzed matrix's order
    std::vector<index_t> input_map = s.input_map;
    const bool mapped = s.input_map_analysis == s.analysis->id;
    clear_numeric(s);
    s.rescaling = Rescaling{};
    adopt_analysis(s, std::move(next), values);
    if (mapped) {
      s.input_map = std::move(input_map);
      s.input_map_analysis = s.analysis->id;
    }
  });
}

void Solver::factorize(const SparseMatrix& a) {
  if (!state_->analysis) analyze(a);
  factor_phase(*state_, &a, a.values);
}

void Solver::refactorize(const SparseMatrix& a) {
  if (!state_->analysis) throw InvalidState("refactorize called before analyze");
  factor_phase(*state_, &a, a.values);
}

void Solver::refactorize(std::span<const double> values) {
  SolverState& s = *state_;
  if (!s.analysis) throw InvalidState("refactorize called before analyze");
  const bool mapped = s.input_map_analysis == s.analysis->id;
  const std::size_t entries = mapped ? s.input_map.size() : s.values.values.size();
  if (s.values_analysis != s.analysis->id)
    throw InternalError("refactorize(values): the analyzed pattern was not kept");
  if (values.size() != entries)
    throw InvalidInput("refactorize(values): " + std::to_string(values.size()) +
                       " values for a matrix of " + std::to_string(entries) + " entries");
  if (!mapped) {
    factor_phase(s, nullptr, values);
    return;
  }
  std::vector<double> fetched;  // gathered on the host below
  values = host_readable(values, fetched);
  // the analyzed matrix's own order: its values gathered into the canonical pattern
  // (duplicates added in its order; entries the analysis does not keep left out)
  phase("factorize",
        [&] { sized_resize(s.gathered, s.values.values.size(), "factorize: values"); });
  // (every value checked, the ones left out too: refactorize(A) refuses them all)
  std::fill(s.gathered.begin(), s.gathered.end(), 0.0);
  for (std::size_t p = 0; p < values.size(); ++p) {
    if (!std::isfinite(values[p]))
      throw InvalidInput("values[" + std::to_string(p) + "] is not finite");
    if (s.input_map[p] >= 0) s.gathered[static_cast<std::size_t>(s.input_map[p])] += values[p];
  }
  factor_phase(s, nullptr, s.gathered);
}

void Solver::solve(const double* b, double* x, index_t nrhs) {
  phase("solve", [&] { detail::solve_phase(*state_, b, x, nrhs); });
}

std::vector<double> Solver::solve(const std::vector<double>& b) {
  if (!state_->analysis || !(state_->factor.valid || state_->delayed.valid))
    throw InvalidState("solve called before factorize");
  const index_t n = size();
  if (n == 0) {
    if (!b.empty())
      throw InvalidInput("right-hand side has " + std::to_string(b.size()) +
                         " entries for a 0x0 matrix");
    return {};
  }
  if (b.empty() || static_cast<index_t>(b.size()) % n != 0)
    throw InvalidInput("right-hand side has " + std::to_string(b.size()) +
                       " entries, not a multiple of n = " + std::to_string(n));
  std::vector<double> x;
  phase("solve", [&] { x.resize(b.size()); });
  solve(b.data(), x.data(), static_cast<index_t>(b.size()) / n);
  return x;
}

void detail::SolverAccess::use_host_workers(Solver& solver, int workers, int threads_each,
                                            numeric::MultiWorkerConfig config) {
  if (workers < 0 || threads_each < 1)
    throw InvalidInput("use_host_workers: workers must be at least 0 and threads at least 1");
  set_driver(solver, workers > 0 ? numeric::make_multi_worker_driver(
                                       solver.options(), workers, threads_each, std::move(config))
                                 : nullptr);
}

void detail::SolverAccess::set_driver(Solver& solver,
                                      std::unique_ptr<numeric::NumericDriver> driver) {
  SolverState& s = *solver.state_;
  s.driver_set = driver != nullptr;
  s.driver = std::move(driver);
  s.analysis.reset();
  s.factor = numeric::NumericFactor{};
  s.correction = detail::PivotCorrection{};
  s.delayed = numeric::DelayedFactor{};
}

Analysis* detail::SolverAccess::analysis(Solver& solver) {
  auto& a = solver.state_->analysis;
  return a ? &*a : nullptr;
}

index_t Solver::size() const { return state_->analysis ? state_->analysis->n : 0; }
MatrixType Solver::matrix_type() const { return state_->resolved; }
const Stats& Solver::stats() const { return state_->stats; }
const Options& Solver::options() const { return state_->options; }
void Solver::set_pivoting(Pivoting pivoting) { state_->options.pivoting = pivoting; }
const std::vector<index_t>& Solver::permutation() const {
  static const std::vector<index_t> empty;
  return state_->analysis ? state_->analysis->perm : empty;
}

}  // namespace strata
