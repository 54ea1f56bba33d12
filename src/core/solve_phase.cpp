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
// With a factor resident on a GPU (and Options::gpu_refinement) the whole checked solve
// runs there: b up once, the residuals from a device copy of A's values and the
// refinement steps (solve/refinement.hpp's refine_steps over a DeviceSpace), x down once;
// only GMRES, for columns refinement leaves above the tolerance, runs on the host.
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

// The factorization's rescaling as the device solves take it (none: null, id 0).
numeric::RescaleView rescale_view(const SolverState& s) {
  if (s.rescaling.row.empty()) return {};
  return {s.rescaling.row.data(), s.rescaling.col.data(), s.rescaling.id};
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
  const numeric::RescaleView view = rescale_view(s);
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

// Per column of a solve: ‖b − A x‖∞ (where known), ‖x‖∞ and ‖b‖∞.
struct ColumnMaxima {
  double r = 0, x = 0, b = 0;
};

// The columns' maxima of host arrays b and x; the residual's only after perturbed pivots
// (the statistics read it only then).
std::vector<ColumnMaxima> host_maxima(SolverState& s, const double* b, const double* x,
                                      index_t nrhs) {
  const index_t n = s.analysis->n;
  std::vector<ColumnMaxima> m(nrhs);
  std::vector<double> r;
  if (s.stats.factor.perturbed_pivots > 0) r.resize(n);
  const solve::Operator op_a = [&](const double* in, double* out) { multiply(s.values, in, out); };
  for (index_t c = 0; c < nrhs; ++c) {
    for (index_t i = 0; i < n; ++i) {
      m[c].x = std::max(m[c].x, std::abs(x[i + c * n]));
      m[c].b = std::max(m[c].b, std::abs(b[i + c * n]));
    }
    if (r.empty()) continue;
    solve::backward_error(n, op_a, s.norm_inf, b + c * n, x + c * n, r.data());
    for (index_t i = 0; i < n; ++i) m[c].r = std::max(m[c].r, std::abs(r[i]));
  }
  return m;
}

// The solve's statistics from its refinement (`check`: it ran) and its columns' maxima.
void record_solve(SolverState& s, const solve::RefinementResult& refined, bool check,
                  const std::vector<ColumnMaxima>& m, double first_solve_seconds, bool on_device,
                  const Timer& timer) {
  const double floor = rounding_floor(s);
  const double enough = std::max(s.options.refinement_tolerance, floor);
  SolveStats& ss = s.stats.solve;
  ss.gmres_iterations = refined.gmres_iterations;
  ss.refinement_steps = refined.steps;
  ss.backward_error = 0;
  for (double e : refined.backward_error) ss.backward_error = std::max(ss.backward_error, e);
  if (!check) ss.backward_error = std::numeric_limits<double>::quiet_NaN();
  ss.backward_error_floor = floor;
  // κ∞(A) ≥ ‖A‖∞‖x‖∞/‖b‖∞ for every solution: a singular or ill-conditioned A shows here
  // even when no pivot was small enough to perturb (a rank deficiency spread over the
  // off-diagonal of U)
  ss.condition_lower_bound = 0;
  for (const ColumnMaxima& c : m)
    if (c.b > 0)
      ss.condition_lower_bound = std::max(ss.condition_lower_bound, s.norm_inf * c.x / c.b);
  ss.refinement_converged = ss.backward_error <= enough;
  // Pivots perturbed: A is numerically singular, and a small normwise backward error only
  // says that x solves a nearby nonsingular matrix (x grows along A's near-null space as
  // b's component there is divided by the static pivots). Whether b is in A's range shows
  // in the residual relative to b alone: no x brings ‖b − A x‖ below b's distance from
  // the range. Within √u·‖b‖ of it, x is one of A's solutions.
  ss.relative_residual = 0;
  ss.singular_consistent = false;
  if (s.stats.factor.perturbed_pivots > 0) {
    for (const ColumnMaxima& c : m)
      ss.relative_residual = std::max(ss.relative_residual, c.b > 0   ? c.r / c.b
                                                            : c.r > 0 ? 1.0
                                                                      : 0.0);
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

// Refinement (max_steps of them) and GMRES where it stalls, on the host (solve/
// refinement.hpp), of x = A⁻¹ b in host arrays.
solve::RefinementResult refine_on_host(SolverState& s, const double* b, double* x, index_t nrhs,
                                       int max_steps) {
  const Options& o = s.options;
  const solve::Operator op_a = [&](const double* in, double* out) { multiply(s.values, in, out); };
  const solve::BlockOperator m_inv = [&](const double* in, double* out, index_t k) {
    apply_inverse(s, in, out, k);
  };
  return solve::refine(
      s.analysis->n, nrhs, op_a, m_inv, s.norm_inf, b, x,
      {max_steps, o.refinement_tolerance, rounding_floor(s), o.gmres_max_iterations});
}

// After the first application of the factor (x = A⁻¹ b, host arrays, its seconds and
// whether it ran on the device): the backward error of each column, refinement, GMRES
// where it stalls (solve/refinement.hpp) when `check`, and the statistics.
void finish_solve(SolverState& s, const double* b, double* x, index_t nrhs, bool check,
                  double first_solve_seconds, bool on_device, const Timer& timer) {
  solve::RefinementResult refined;
  if (check) refined = refine_on_host(s, b, x, nrhs, s.options.refinement_max_steps);
  check_solution_finite(x, s.analysis->n, nrhs);  // refinement keeps the better iterate
  record_solve(s, refined, check, host_maxima(s, b, x, nrhs), first_solve_seconds, on_device,
               timer);
}

// The vectors of a refinement in the memory of the GPU that holds the factor: the
// residuals there (Executor::residual, with A's values copied there once per
// factorization), each correction a solve with b and x in that memory.
class DeviceSpace final : public solve::RefinementSpace {
 public:
  DeviceSpace(SolverState& s, const double* b, double* x, double* r, double* d, double* kept,
              index_t nrhs, const numeric::RescaleView& view)
      : s_(s),
        b_(b),
        x_(x),
        r_(r),
        d_(d),
        kept_(kept),
        nrhs_(nrhs),
        view_(view),
        m_(nrhs),
        kept_m_(nrhs) {}
  // the first residual, false where the device cannot make it (nothing changed)
  bool prime() {
    primed_.resize(nrhs_);
    if (!measure()) return false;
    for (index_t c = 0; c < nrhs_; ++c) primed_[c] = berr_of(c);
    return true;
  }
  void residual(double* berr, const char*) override {  // every column, in one launch
    if (!primed_.empty()) {
      std::copy(primed_.begin(), primed_.end(), berr);
      primed_.clear();
      return;
    }
    if (!measure()) throw InternalError("the GPU could not compute a residual it computed before");
    for (index_t c = 0; c < nrhs_; ++c) berr[c] = berr_of(c);
  }
  // d = M⁻¹ r. With every residual finite the host does not wait for it: a d that is not
  // finite makes x's maxima not finite at the next residual, whose backward error is then
  // +inf, and refine_steps undoes the step. A residual that is not finite would leave d
  // as it was (solve_gpu_arrays does not write x for such a b): d = 0 then.
  void correct() override {
    bool finite = true;
    for (const ColumnMaxima& c : m_) finite &= std::isfinite(c.r);
    numeric::GpuArrayCheck found;
    if (!s_.driver->solve_gpu_arrays(*s_.analysis, s_.factor, r_, d_, nrhs_, view_,
                                     finite ? nullptr : &found))
      throw InternalError("the GPU that holds the factor declined a refinement step's solve");
    if (!finite && (found.b_not_finite >= 0 || found.x_not_finite >= 0))  // x stays
      numeric::copy_to_device(d_, std::vector<double>(size(), 0.0).data(), size());
  }
  void step(index_t c) override {
    kept_m_[c] = m_[c];
    s_.driver->refinement_step(x_ + c * n(), d_ + c * n(), kept_ + c * n(), n(), false);
  }
  void undo(index_t c) override {
    m_[c] = kept_m_[c];
    s_.driver->refinement_step(x_ + c * n(), d_ + c * n(), kept_ + c * n(), n(), true);
  }
  const std::vector<ColumnMaxima>& maxima() const { return m_; }
  // every column's b and x finite at the last residual
  bool finite() const {
    bool f = true;
    for (const ColumnMaxima& c : m_) f &= std::isfinite(c.x) && std::isfinite(c.b);
    return f;
  }

 private:
  index_t n() const { return s_.analysis->n; }
  std::size_t size() const { return static_cast<std::size_t>(n()) * nrhs_; }
  bool measure() {
    const bool on_device = s_.kept_values_on_device || s_.values_copy_on_device;
    const numeric::MatrixValues a{on_device ? nullptr : s_.values.values.data(), s_.values_serial};
    std::vector<double> mx(3 * static_cast<std::size_t>(nrhs_));
    if (!s_.driver->residual(*s_.analysis, a, b_, x_, r_, nrhs_, mx.data())) return false;
    for (index_t c = 0; c < nrhs_; ++c) m_[c] = {mx[3 * c], mx[3 * c + 1], mx[3 * c + 2]};
    return true;
  }
  double berr_of(index_t c) const {
    return solve::backward_error_of(m_[c].r, m_[c].x, m_[c].b, s_.norm_inf);
  }
  SolverState& s_;
  const double* b_;
  double *x_, *r_, *d_, *kept_;
  index_t nrhs_;
  numeric::RescaleView view_;
  std::vector<ColumnMaxima> m_, kept_m_;
  std::vector<double> primed_;
};

// A checked solve on the GPU that holds the factor (Options::gpu_refinement): b up once
// (unless it lies in that GPU's memory; through the page-locked solve_work), the first
// solve, the residuals and refinement steps there, x down once (unless it lies there); GMRES
// on the host for the columns that refinement leaves above what can be checked. The host
// waits for the first solve only with its residual, and reads the solve's own check of b
// and x only where the residual's maxima show an entry that is not finite. Returns false,
// having written nothing the caller sees, where it cannot run: the caller then solves on
// the host.
bool checked_solve_on_device(SolverState& s, const double* b, double* x, index_t nrhs, bool b_gpu,
                             bool x_gpu, const Timer& timer) {
  const Analysis& an = *s.analysis;
  const index_t n = an.n;
  const Options& o = s.options;
  if (!o.gpu_refinement || s.delayed.valid || s.correction.active || n == 0 || nrhs == 0)
    return false;
  const std::size_t count = static_cast<std::size_t>(n) * static_cast<std::size_t>(nrhs);
  double* const work = s.driver->refinement_workspace(count * (3 + !b_gpu + !x_gpu));
  if (!work) return false;
  double *r = work, *d = work + count, *kept = work + 2 * count, *next = work + 3 * count;
  // b and x pass through the page-locked stage when they are host arrays
  double* const stage = b_gpu && x_gpu ? nullptr : solve_work(s, count);
  Timer first;
  const double* bd = b;
  if (!b_gpu) {
    std::copy(b, b + count, stage);
    numeric::copy_to_device(next, stage, count);
    bd = next;
    next += count;
  }
  double* const xd = x_gpu ? x : next;
  const numeric::RescaleView view = rescale_view(s);
  if (!s.driver->solve_gpu_arrays(an, s.factor, bd, xd, nrhs, view, nullptr)) return false;
  DeviceSpace space(s, bd, xd, r, d, kept, nrhs, view);
  const bool primed = space.prime();  // waits for the solve and its residual
  const double first_seconds = first.seconds();
  if (!primed || !space.finite()) {
    numeric::GpuArrayCheck found;
    s.driver->last_gpu_array_check(found);
    if (found.b_not_finite >= 0) throw_rhs_not_finite(found.b_not_finite, n);
    if (found.x_not_finite >= 0) throw_no_representable_solution(found.x_not_finite, n);
  }
  // the host's part: x (and b, where it lies on the GPU) in host arrays, A's values there
  std::vector<double> hb, hx;
  const auto to_host = [&]() -> const double* {
    hx.resize(count);
    numeric::copy_from_device(hx.data(), xd, count);
    host_values(s);
    if (!b_gpu) return b;
    hb.resize(count);
    numeric::copy_from_device(hb.data(), b, count);
    return hb.data();
  };
  const auto from_host = [&] {
    if (x_gpu)
      numeric::copy_to_device(x, hx.data(), count);
    else
      std::copy(hx.begin(), hx.end(), x);
  };
  if (!primed) {  // no residual on the device: refine on the host
    const double* bh = to_host();
    finish_solve(s, bh, hx.data(), nrhs, true, first_seconds, true, timer);
    from_host();
    return true;
  }
  solve::RefinementResult refined =
      solve::refine_steps(space, nrhs, o.refinement_max_steps, o.refinement_tolerance);
  const double enough = std::max(o.refinement_tolerance, rounding_floor(s));
  bool stalled = false;
  for (double e : refined.backward_error) stalled |= !(e <= enough);
  std::vector<ColumnMaxima> maxima = space.maxima();
  bool finite = true;
  for (const ColumnMaxima& c : maxima) finite &= std::isfinite(c.x);
  if ((stalled && o.gmres_max_iterations > 0) || !finite) {
    // GMRES where refinement stalled (or the entry that is not finite named), on the host
    const double* bh = to_host();
    const int steps = refined.steps;
    refined = refine_on_host(s, bh, hx.data(), nrhs, 0);
    refined.steps = steps;
    check_solution_finite(hx.data(), n, nrhs);
    maxima = host_maxima(s, bh, hx.data(), nrhs);
    from_host();
  } else if (!x_gpu) {
    numeric::copy_from_device(stage, xd, count);
    std::copy(stage, stage + count, x);
  }
  record_solve(s, refined, true, maxima, first_seconds, true, timer);
  return true;
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
  if (check && checked_solve_on_device(s, b, x, nrhs, b_gpu, x_gpu, timer)) return;
  if (b_gpu && x_gpu && !s.delayed.valid && !s.correction.active) {
    if (check) host_values(s);  // the residuals' matrix
    const numeric::RescaleView view = rescale_view(s);
    numeric::GpuArrayCheck found;
    Timer first;
    if (s.driver->solve_gpu_arrays(an, s.factor, b, x, nrhs, view, &found)) {
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
  if (check && checked_solve_on_device(s, b, x, nrhs, false, false, timer)) return;
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
