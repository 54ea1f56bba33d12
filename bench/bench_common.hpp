// strata benchmarks — shared pieces: problems by name, run metadata, result files.
#pragma once

#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"

namespace strata::bench {

/// Runs a driver's body: an exception it lets out (a matrix file that cannot be read, a
/// problem name that is not one, an error of a solver) is printed as
/// "<program>: error: <message>" on stderr with exit status 1, instead of terminating the
/// program with an abort. No results file is written then (the drivers write theirs last).
int run_driver(int argc, char** argv, int (*body)(int, char**));

/// A benchmark problem: a shared SuiteSparse matrix by name ("bcsstk16"), or a generated
/// one: "lap3d-N" (7-point Laplacian N³), "elast3d-N" (3-dof 27-point stencil N³),
/// "lap2d-N", "uelast3d-N" (elasticity pattern, unsymmetric values), or a Matrix Market
/// file given by a path with a '/' ending in .mtx or .mtx.gz (e.g. a multibody Newton
/// matrix written by `strata simulate --dump-matrix`): its name is then the file's name
/// without the folder and the .mtx / .mtx.gz ending.
/// Symmetric problems come as Storage::lower. Throws InvalidInput for an unknown name,
/// the reader's errors for a file.
struct Problem {
  std::string name;
  SparseMatrix a;
  bool symmetric = true;
};
Problem load_problem(const std::string& name);

/// Machine, date, git commit and the exact command line of this run.
nlohmann::json run_metadata(int argc, char** argv);

/// Writes `j` to <dir>/<stem>-<UTC date-time>.json atomically (temporary file, then
/// rename) and returns the path. An empty `dir` means bench/results of the source tree;
/// the folder is created if missing.
std::string write_result(const nlohmann::json& j, const std::string& stem,
                         const std::string& dir = "");

/// Checks a --tag value: letters, digits, '.', '_' and '-' only (it goes into a file name).
/// Returns an error message, empty when the tag is valid (CLI11 validator signature).
std::string check_tag(const std::string& tag);

/// Result of a reference solver run: median factorization seconds, nnz(L), backward
/// error of its solution of A x = b.
struct RefResult {
  double seconds = 0, lnz = 0, backward_error = 0;
  double solve_seconds = 0;  ///< median of the solves of one right-hand side (0: not timed)
  bool ok = false;
};

/// Normwise backward error ‖b − A x‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) (A in any storage).
double berr(const SparseMatrix& a, const std::vector<double>& x, const std::vector<double>& b);

/// CHOLMOD supernodal Cholesky of the SPD matrix `a` (lower storage) with the given
/// permutation (new to old): median of `repeat` cholmod_l_factorize calls, then the
/// median of `repeat` cholmod_l_solve calls with b.
RefResult run_cholmod(const SparseMatrix& a, const std::vector<index_t>& perm,
                      const std::vector<double>& b, int repeat);

/// Geometric mean of positive values (0 for an empty list).
double geometric_mean(const std::vector<double>& v);

/// Median of the values (they are copied).
double median(std::vector<double> v);

/// The GPU figures of a factorization (FactorStats' device fields, the per-phase GPU
/// time included) as a JSON object, for the benchmarks' result files.
nlohmann::json device_figures(const FactorStats& fs);

}  // namespace strata::bench
