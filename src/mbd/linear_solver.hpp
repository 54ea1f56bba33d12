// strata::mbd — the sparse linear solver behind every Newton step.
//
// The engine talks to strata through this small interface: analyze once per pattern,
// factorize (a refactorization after the first), solve. make_strata_solver is what the
// engine uses; make_dense_solver (LAPACK dgetrf) exists as an independent reference for
// tests and for comparing Newton behaviour on small models.
#pragma once

#include <memory>
#include <string>

#include "strata/options.hpp"
#include "strata/solver.hpp"
#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"

namespace strata::mbd {

class LinearSolver {
 public:
  virtual ~LinearSolver() = default;
  /// Analysis of the pattern (and, for strata's matching and scaling, the values) of A.
  virtual void analyze(const SparseMatrix& a) = 0;
  /// analyze(a) with strata's matching started from `start` (strata::Solver::analyze(a,
  /// start), an earlier analysis's matching_start()); a solver without that analyzes
  /// afresh.
  virtual void analyze_from(const SparseMatrix& a, const MatchingStart& start) {
    (void)start;
    analyze(a);
  }
  /// The analysis's matching as a later analysis's start (empty when there is none).
  virtual MatchingStart matching_start() const { return {}; }
  /// The order of the system that analyze(a) hands the sparse solver (that of a matching
  /// start for it): a's, unless the solver condenses it first (condensed_solver.hpp).
  virtual index_t system_order(const SparseMatrix& a) const { return a.n_rows; }
  /// Analysis of a pattern that contains the analyzed one, keeping its ordering
  /// (strata::Solver::analyze_keeping_order); a solver without that analyzes afresh.
  virtual void analyze_keeping_order(const SparseMatrix& a) { analyze(a); }
  /// The entries of the factor that analyze_keeping_order(a) would give (nnz(L), as
  /// factor_entries), counted without analyzing; the solver is not changed.
  virtual index_t factor_entries_keeping_order(const SparseMatrix& a) const = 0;
  /// Analysis of a changed pattern with a new ordering and the analyzed matching and
  /// scaling kept (strata::Solver::analyze_keeping_matching; A's values are not read);
  /// a solver without that analyzes afresh. Throws InvalidInput, changing nothing, when
  /// the pattern lacks a matched entry.
  virtual void analyze_keeping_matching(const SparseMatrix& a) { analyze(a); }
  /// Numeric factorization of A with the analyzed pattern.
  virtual void factorize(const SparseMatrix& a) = 0;
  /// As factorize, when the caller knows that A's pattern is the very one analyzed (the
  /// same arrays, unchanged since): a solver may then skip comparing it.
  virtual void factorize_analyzed_pattern(const SparseMatrix& a) { factorize(a); }
  /// x = A⁻¹ b (one right-hand side of length n).
  virtual void solve(const double* b, double* x) = 0;
  /// Entries of the factor (nnz(L) + nnz(U) for LU; 0 if unknown).
  virtual index_t factor_entries() const = 0;
  /// Pivots replaced by static pivoting in the last factorization.
  virtual index_t perturbed_pivots() const = 0;
  /// Backward error of the last solve (0 if unknown; NaN when the solve did not check its
  /// solution: no perturbed pivot, see Options::solve_check).
  virtual double backward_error() const = 0;
  /// "strata LU on cpu", "dense LAPACK", ...
  virtual std::string describe() const = 0;
  /// The strata statistics, when the solver is strata.
  virtual const Stats* stats() const { return nullptr; }
  /// Host seconds the last factorize or solve call spent condensing the system before
  /// the sparse solver's part and expanding its solution after (condensed_solver.hpp; 0
  /// for a solver that does not condense).
  virtual double condensation_seconds() const { return 0; }
  /// Adaptive pivoting (strata on a GPU without a pivoting choice): whether the
  /// factorizations delay pivots directly (the last analyze put the factor on the host, or
  /// a factorization since needed static pivots in the analysis's order). A
  /// checkpoint keeps it so that a restart factors as the uninterrupted run did.
  virtual bool delaying() const { return false; }
  virtual void set_delaying(bool) {}
};

/// The options of the engine's Newton matrices unless a run sets others: strata's
/// defaults with the GPU when the build and machine have one (Backend::automatic; with
/// Options::gpu_min_flops, only for a Newton matrix whose factor is that large), one GPU
/// (the Newton matrices are far too small for the tree split over several to pay), and
/// solves checked only after perturbed pivots (Newton computes the residual at every
/// iterate and stops on the size of its updates: a factor without perturbed pivots needs
/// no separate check), and one METIS separator per nested-dissection bisection
/// (Options::nd_separators = 1: these matrices' analyses repeat during a run).
Options engine_solver_options();

/// strata's multifrontal LU of the Newton matrix (MatrixType::general) with options `o`.
/// Pivoting::automatic (the default) is the engine's choice: delayed pivoting on the host
/// for every factorization, and on a GPU the analysis's fixed order until a factorization
/// needs static pivots, which delays them on the host, as every later factorization of
/// the same analysis does directly (LinearSolver::delaying; so does one that
/// Backend::automatic put on the host); Pivoting::fixed,
/// delayed and corrected as Options::pivoting says. Throws InvalidInput when o.type is neither
/// automatic nor general (the Newton matrix is unsymmetric) or when validate(o) refuses a field.
std::unique_ptr<LinearSolver> make_strata_solver(const Options& o);
/// strata's multifrontal L D Lᵀ (MatrixType::symmetric_indefinite: restricted Bunch–Kaufman
/// 1×1/2×2 pivots in the analysis's order; where that order needs static pivots, delayed
/// 1×1/2×2 pivots on the host, as Options::pivoting says) with options `o`, for a
/// symmetric matrix given with both triangles,
/// such as the set-up's saddle-point system [M Φ_qᵀ; Φ_q 0]: half the factorization of LU
/// and no unsymmetric matching. Throws InvalidInput when o.type is neither automatic nor
/// symmetric_indefinite or when validate(o) refuses a field.
std::unique_ptr<LinearSolver> make_strata_symmetric_solver(const Options& o);
/// Whether make_strata_solver({.backend = backend, ...}) may factorize on a GPU:
/// Backend::cuda, or Backend::automatic in a build and on a machine with one (where the
/// analysis may still put a small factor on the host: Options::gpu_min_flops).
bool solver_on_gpu(Backend backend);
/// Dense LU with partial pivoting (LAPACK); for tests and tiny models only.
std::unique_ptr<LinearSolver> make_dense_solver();

}  // namespace strata::mbd
