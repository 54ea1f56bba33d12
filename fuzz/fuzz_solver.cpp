// strata fuzz target — the solver on small arbitrary matrices.
//
// What. The input is a Matrix Market text (read through the reader, so mutations keep
// the structure); matrices of order ≤ 48 with ≤ 600 entries are analyzed, factorized and
// solved with b = 1 for every MatrixType (automatic, spd, symmetric_indefinite, general)
// under two orderings. This is where the numerical edge cases of docs/reliability.md
// meet random patterns: empty rows, zero and tiny pivots, values near the overflow and
// underflow thresholds, indefinite matrices declared spd.
//
// Defined outcomes: a strata::Error, or a solution x that is finite with a reported
// backward error that is not NaN and matches the one recomputed here (in long double) from
// the matrix the solver factorized (the lower triangle, mirrored, for the symmetric
// types) — the statistics must not claim an accuracy the solution does not have.
// Anything else aborts.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "mm_checks.hpp"
#include "strata/solver.hpp"

namespace {

using namespace strata;

// ‖b − A x‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) of the dense n×n A, in long double.
double backward_error(const std::vector<double>& a, index_t n, const std::vector<double>& x,
                      const std::vector<double>& b) {
  long double rmax = 0, anorm = 0, xmax = 0, bmax = 0;
  for (index_t i = 0; i < n; ++i) {
    long double r = b[i], row = 0;
    for (index_t j = 0; j < n; ++j) {
      r -= static_cast<long double>(a[i + j * n]) * x[j];
      row += std::fabs(static_cast<long double>(a[i + j * n]));
    }
    rmax = std::max(rmax, std::fabs(r));
    anorm = std::max(anorm, row);
    xmax = std::max(xmax, std::fabs(static_cast<long double>(x[i])));
    bmax = std::max(bmax, std::fabs(static_cast<long double>(b[i])));
  }
  const long double den = anorm * xmax + bmax;
  return static_cast<double>(den > 0 ? rmax / den : rmax);
}

// Dense copy of what a solver of type `t` factorizes: A itself for general (and for
// automatic on an unsymmetric matrix), the lower triangle mirrored for symmetric types.
std::vector<double> effective(const SparseMatrix& a, bool symmetric) {
  std::vector<double> d = fuzz::dense_of(a);
  const index_t n = a.n_rows;
  if (symmetric)
    for (index_t j = 0; j < n; ++j)
      for (index_t i = 0; i < j; ++i) d[i + j * n] = d[j + i * n];
  return d;
}

void run(const SparseMatrix& a, MatrixType type, OrderingMethod ordering) {
  Options o;
  o.type = type;
  o.ordering = ordering;
  o.num_threads = 1;
  Solver s(o);
  std::vector<double> x;
  const std::vector<double> b(a.n_rows, 1.0);
  try {
    s.factorize(a);
    x = s.solve(b);
  } catch (const Error&) {
    return;
  }
  for (double v : x) fuzz::require(std::isfinite(v), "a solution that is not finite");
  const double reported = s.stats().solve.backward_error;
  // +inf is a report (the residual overflowed); NaN is not
  fuzz::require(!std::isnan(reported), "a backward error that is NaN");
  const bool symmetric = s.matrix_type() != MatrixType::general;
  const double actual = backward_error(effective(a, symmetric), a.n_rows, x, b);
  // both are rounded; a reported 1e-16 for an actual 1e-15 is fine, 1e-16 for 1e-3 is not
  if (actual > 100 * reported + 1e-13)
    fuzz::finding("reported backward error " + std::to_string(reported) + ", actual " +
                  std::to_string(actual) + " (type " + to_string(s.matrix_type()) + ")");
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  static fuzz::ScratchFile input(".mtx");
  MMMatrix mm;
  const std::string& path = input.write(data, size);
  if (!fuzz::small_dimensions(path)) return 0;
  try {
    mm = read_matrix_market(path);
  } catch (const Error&) {
    return 0;
  }
  const SparseMatrix& a = mm.matrix;
  if (a.n_rows > 48 || a.n_cols > 48 || a.nnz() > 600) return 0;
  for (MatrixType t : {MatrixType::automatic, MatrixType::spd, MatrixType::symmetric_indefinite,
                       MatrixType::general})
    for (OrderingMethod o : {OrderingMethod::nested_dissection, OrderingMethod::natural})
      run(a, t, o);
  return 0;
}
