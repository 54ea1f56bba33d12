// strata — the Solver's solve phase: one solve with the factor, its backward error, and
// iterative refinement with GMRES where it stalls (solve/refinement.hpp).
//
// One solve with the factor (apply_inverse) takes b to the analysis's numbering and
// scaling (B = Dr·P·A·Q·Dc, with the extra rescaling of the last factorization when there
// was one), solves with the factor where it lives (the host's delayed factor, the device's
// resident factor, or the host's copy) and takes the solution back; for a factor resident
// on a GPU the permutation and scaling run there too (Executor::solve_original), and b and
// x may lie in that GPU's memory (Executor::solve_gpu_arrays). Each column's
// normwise backward error ‖b − A x‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) (Rigal and Gaches; Higham,
// Accuracy and Stability of Numerical Algorithms, 2nd ed., §7.1) is checked against
// max(Options::refinement_tolerance, (m+1)·u) for m the most entries in a row of A (§3.5).
#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "base/roundoff.hpp"
#include "base/timer.hpp"
#include "core/solver_state.hpp"
#include "solve/refinement.hpp"
#include "strata/solver.hpp"

namespace strata::detail {
namespace {

// The errors for entry i (column-major) of b, or of x, that is not finite.
[[noreturn]] void throw_rhs_not_finite(index_t i, index_t n) {
  n = std::max<index_t>(n, 1);
  throw InvalidInput("right-hand side entry " + std::to_string(i % n) + " of column " +
                     std::to_string(i / n) + " is not finite");
}
[[noreturn]] void throw_no_representable_solution(index_t i, index_t n) {
  throw InvalidInput("no representable solution: entry " + std::to_string(i % n) +
                     " of solution column " + std::to_string(i / n) +
                     " overflows the double range in the solve with the factorization "
                     "(the matrix is singular to working precision, or A and b are too "
                     "badly scaled for double precision)");
}

// Throws when a column of x is not finite: the solution (or the solve with the factor)
// overflows the double range. Returning it would hand the caller Inf/NaN with nothing
// in the statistics to say so.
void check_solution_finite(const double* x, index_t n, index_t nrhs) {
  for (index_t i = 0; i < n * nrhs; ++i)
    if (!std::isfinite(x[i])) throw_no_representable_solution(i, n);
}

// v·d·e for a scale factor d and a power of two e: one rounding, as v·d alone would have,
// unless d·e leaves the normal range (then v·d·e: the product may still be representable).
inline double scaled_by(double v, double d, double e) {
  const double f = d * e;
  return std::isnormal(f) ? v * f : v * d * e;
}

// Entries (rows × right-hand sides) from which a solve's permutation and scaling loops run
// over the host's threads.
constexpr index_t kParallelEntries = index_t{1} << 15;

// f(e) for e in [0, count): on the host's threads for a large count (f writes entries of
// its own only).
template <class F>
void for_entries(SolverState& s, index_t count, const F& f) {
  if (count < kParallelEntries) {
    for (index_t e = 0; e < count; ++e) f(e);
    return;
  }
  host_arena(s).execute([&] {
    tbb::parallel_for(tbb::blocked_range<index_t>(0, count, kParallelEntries / 8),
                      [&](const tbb::blocked_range<index_t>& r) {
                        for (index_t e = r.begin(); e < r.end(); ++e) f(e);
                      });
  });
}

// s.solve_work sized for `entries` doubles, page-locked when a GPU backend will copy it
// (a copy from pageable memory is staged through a driver buffer and holds the host).
double* solve_work(SolverState& s, std::size_t entries) {
  if (s.solve_work.size() < entries) {
    s.solve_work_pin.reset();
    s.solve_work.resize(entries);
  }
  if (!s.solve_work_pin && s.driver->uploads_values() && !s.delayed.valid)
    s.solve_work_pin =
        numeric::pin_host_memory(s.solve_work.data(), s.solve_work.size() * sizeof(double));
  return s.solve_work.data();
}

}  // namespace

// One solve with the factor: x = F⁻¹ b for nrhs columns (original numbering), through
// s.solve_work. Returns true when the triangular solves ran on the device that holds the
// factor.
bool apply_factor(SolverState& s, const double* b, double* x, index_t nrhs) {
  const Analysis& an = *s.analysis;
  const index_t n = an.n;
  double* const work = solve_work(s, static_cast<std::size_t>(n) * nrhs);
  const bool scale = !an.row_scaling.empty();
  const bool match = !an.matching_perm.empty();
  const bool rescale = !s.rescaling.row.empty();
  // the factor resident on a GPU: the permutation and scaling there too
  const numeric::RescaleView view{rescale ? s.rescaling.row.data() : nullptr,
                                  rescale ? s.rescaling.col.data() : nullptr,
                                  rescale ? s.rescaling.id : 0};
  if (!s.delayed.valid && s.driver->solve_original(an, s.factor, b, x, nrhs, view, work))
    return true;
  for_entries(s, n * nrhs, [&](index_t e) {
    const index_t k = e % n, r = e / n;
    const index_t i = an.perm[k];  // row of B is a row of A
    work[e] = scaled_by(b[i + r * n], scale ? an.row_scaling[i] : 1.0,
                        rescale ? s.rescaling.row[i] : 1.0);
  });
  bool on_device = false;
  if (s.delayed.valid)  // by subtrees on the threads, whose split depends on their count:
                        // one thread under Options::reproducible
    numeric::solve_delayed(an, s.delayed, work, nrhs,
                           s.options.reproducible ? nullptr : &host_arena(s));
  else
    on_device = s.driver->solve(an, s.factor, work, nrhs);
  for_entries(s, n * nrhs, [&](index_t e) {
    const index_t k = e % n, r = e / n;
    const index_t col = match ? an.matching_perm[an.perm[k]] : an.perm[k];
    x[col + r * n] =
        scaled_by(work[e], scale ? an.col_scaling[col] : 1.0, rescale ? s.rescaling.col[col] : 1.0);
  });
  return on_device;
}

namespace {

// One solve with the factor and, for a factor of Pivoting::corrected, its low-rank
// correction: x = A⁻¹ b.
bool apply_inverse(SolverState& s, const double* b, double* x, index_t nrhs) {
  const bool on_device = apply_factor(s, b, x, nrhs);
  apply_correction(s.correction, s.analysis->n, x, nrhs);
  return on_device;
}

// After the first application of the factor (x = A⁻¹ b, host arrays, its seconds and
// whether it ran on the device): the backward error of each column, refinement, GMRES
// where it stalls (solve/refinement.hpp) when `check`, and the statistics.
void finish_solve(SolverState& s, const double* b, double* x, index_t nrhs, bool check,
                  double first_solve_seconds, bool on_device, const Timer& timer) {
  const index_t n = s.analysis->n;
  const Options& o = s.options;
  // backward error of each column, refinement, GMRES where it stalls (solve/refinement.hpp)
  const solve::Operator op_a = [&](const double* in, double* out) { multiply(s.values, in, out); };
  const double floor = rounding_floor(s);
  const double enough = std::max(o.refinement_tolerance, floor);
  solve::RefinementResult refined;
  if (check) {
    const solve::BlockOperator m_inv = [&](const double* in, double* out, index_t k) {
      apply_inverse(s, in, out, k);
    };
    refined = solve::refine(
        n, nrhs, op_a, m_inv, s.norm_inf, b, x,
        {o.refinement_max_steps, o.refinement_tolerance, floor, o.gmres_max_iterations});
  }
  const std::vector<double>& berr = refined.backward_error;
  check_solution_finite(x, n, nrhs);  // refinement keeps the better iterate: a safeguard
  SolveStats& ss = s.stats.solve;
  ss.gmres_iterations = refined.gmres_iterations;
  ss.refinement_steps = refined.steps;
  ss.backward_error = 0;
  for (double e : berr) ss.backward_error = std::max(ss.backward_error, e);
  if (!check) ss.backward_error = std::numeric_limits<double>::quiet_NaN();
  ss.backward_error_floor = floor;
  // κ∞(A) ≥ ‖A‖∞‖x‖∞/‖b‖∞ for every solution: a singular or ill-conditioned A shows here
  // even when no pivot was small enough to perturb (a rank deficiency spread over the
  // off-diagonal of U)
  ss.condition_lower_bound = 0;
  for (index_t c = 0; c < nrhs; ++c) {
    double xn = 0, bn = 0;
    for (index_t i = 0; i < n; ++i) {
      xn = std::max(xn, std::abs(x[i + c * n]));
      bn = std::max(bn, std::abs(b[i + c * n]));
    }
    if (bn > 0) ss.condition_lower_bound = std::max(ss.condition_lower_bound, s.norm_inf * xn / bn);
  }
  ss.refinement_converged = ss.backward_error <= enough;
  // Pivots perturbed: A is numerically singular, and a small normwise backward error only
  // says that x solves a nearby nonsingular matrix (x grows along A's near-null space as
  // b's component there is divided by the static pivots). Whether b is in A's range shows
  // in the residual relative to b alone: no x brings ‖b − A x‖ below b's distance from
  // the range. Within √u·‖b‖ of it, x is one of A's solutions.
  ss.relative_residual = 0;
  ss.singular_consistent = false;
  if (s.stats.factor.perturbed_pivots > 0) {
    std::vector<double> r(static_cast<std::size_t>(n) * nrhs);
    for (index_t c = 0; c < nrhs; ++c) {
      solve::backward_error(n, op_a, s.norm_inf, b + c * n, x + c * n, r.data() + c * n);
      double rn = 0, bn = 0;
      for (index_t i = 0; i < n; ++i) {
        rn = std::max(rn, std::abs(r[i + c * n]));
        bn = std::max(bn, std::abs(b[i + c * n]));
      }
      ss.relative_residual = std::max(ss.relative_residual, bn > 0 ? rn / bn : rn > 0 ? 1.0 : 0.0);
    }
    ss.singular_consistent =
        ss.refinement_converged && ss.relative_residual <= std::sqrt(kUnitRoundoff);
  }
  ss.on_device = on_device;
  ss.host_threads = 1;
  if (s.delayed.valid && !s.delayed.solve_plan.bins.empty() && !s.options.reproducible) {
    ss.host_threads = 0;
    for (const auto& bin : s.delayed.solve_plan.bins) ss.host_threads += !bin.empty();
  }
  ss.first_solve_seconds = first_solve_seconds;
  ss.seconds = timer.seconds();
}

// b or x in GPU memory (cudaMalloc), as cuDSS's dense matrices may lie. Where the factor
// is resident on that GPU, b is read and x written there, and only four check words come
// to the host (Executor::solve_gpu_arrays); a checked solve then fetches both and refines
// on the host (finish_solve), x going back once. Otherwise b is fetched, solved as a host
// array and x copied back.
void solve_gpu_arrays(SolverState& s, const double* b, double* x, index_t nrhs, bool b_gpu,
                      bool x_gpu, bool check, const Timer& timer) {
  const Analysis& an = *s.analysis;
  const index_t n = an.n;
  const std::size_t count = static_cast<std::size_t>(n) * static_cast<std::size_t>(nrhs);
  std::vector<double> hb, hx;
  auto fetch = [&](std::vector<double>& h, const double* d) {
    h.resize(count);
    numeric::copy_from_device(h.data(), d, count);
  };
  if (b_gpu && x_gpu && !s.delayed.valid && !s.correction.active) {
    if (check) host_values(s);  // the residuals' matrix
    const bool rescale = !s.rescaling.row.empty();
    const numeric::RescaleView view{rescale ? s.rescaling.row.data() : nullptr,
                                    rescale ? s.rescaling.col.data() : nullptr,
                                    rescale ? s.rescaling.id : 0};
    numeric::GpuArrayCheck found;
    Timer first;
    if (s.driver->solve_gpu_arrays(an, s.factor, b, x, nrhs, view, found)) {
      const double first_seconds = first.seconds();
      if (found.b_not_finite >= 0) throw_rhs_not_finite(found.b_not_finite, n);
      if (found.x_not_finite >= 0) throw_no_representable_solution(found.x_not_finite, n);
      if (check) {
        fetch(hb, b);
        fetch(hx, x);
        finish_solve(s, hb.data(), hx.data(), nrhs, true, first_seconds, true, timer);
        numeric::copy_to_device(x, hx.data(), count);
        return;
      }
      SolveStats& ss = s.stats.solve;
      ss = SolveStats{};
      ss.first_solve_seconds = first_seconds;
      ss.backward_error = std::numeric_limits<double>::quiet_NaN();  // unchecked
      ss.backward_error_floor = rounding_floor(s);
      // the largest magnitudes of all columns together: a bound no larger than the
      // host's per-column one
      ss.condition_lower_bound = found.b_max > 0 ? s.norm_inf * found.x_max / found.b_max : 0.0;
      ss.on_device = true;
      ss.seconds = timer.seconds();
      return;
    }
  }
  const double* bh = b;
  if (b_gpu) {
    fetch(hb, b);
    bh = hb.data();
  }
  if (x_gpu) hx.resize(count);
  solve_phase(s, bh, x_gpu ? hx.data() : x, nrhs);
  if (x_gpu) numeric::copy_to_device(x, hx.data(), count);
}

}  // namespace

double rounding_floor(SolverState& s) {
  if (s.row_entries_of != s.values_analysis || s.max_row_entries == 0) {
    const SparseMatrix& c = s.values;
    std::vector<index_t> count(c.n_rows, 0);
    for (index_t j = 0; j < c.n_cols; ++j)
      for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
        ++count[c.indices[p]];
        if (c.storage != Storage::full && c.indices[p] != j) ++count[j];
      }
    index_t m = 0;
    for (index_t k : count) m = std::max(m, k);
    s.max_row_entries = std::max<index_t>(m, 1);
    s.row_entries_of = s.values_analysis;
  }
  return static_cast<double>(s.max_row_entries + 1) * kUnitRoundoff;
}

// The solve phase: one solve with the factor, iterative refinement, GMRES if it stalls.
void solve_phase(SolverState& s, const double* b, double* x, index_t nrhs) {
  if (!s.analysis || !(s.factor.valid || s.delayed.valid))
    throw InvalidState("solve called before factorize");
  if (nrhs < 0) throw InvalidInput("negative number of right-hand sides");
  Timer timer;
  const index_t n = s.analysis->n;
  const Options& o = s.options;
  // Options::solve_check: after a factorization without perturbed or corrected pivots the
  // caller may take the factor's solution unchecked. A corrected solve is checked: the
  // Sherman–Morrison–Woodbury formula is not backward stable (Yip 1986), and the fixed
  // order's factor of A + E bounds no growth.
  const bool check = o.solve_check == SolveCheck::always || s.stats.factor.perturbed_pivots > 0 ||
                     s.correction.active;
  const bool b_gpu = numeric::device_memory_of(b) >= 0, x_gpu = numeric::device_memory_of(x) >= 0;
  if (b_gpu || x_gpu) {
    solve_gpu_arrays(s, b, x, nrhs, b_gpu, x_gpu, check, timer);
    return;
  }
  for (index_t i = 0; i < n * nrhs; ++i)
    if (!std::isfinite(b[i])) throw_rhs_not_finite(i, n);
  if (check) host_values(s);  // the residuals' matrix
  Timer first;
  const bool on_device = apply_inverse(s, b, x, nrhs);
  const double first_seconds = first.seconds();
  check_solution_finite(x, n, nrhs);
  finish_solve(s, b, x, nrhs, check, first_seconds, on_device, timer);
}

}  // namespace strata::detail
