// strata — the direct solver: analyze / factorize / refactorize / solve.
//
// Usage:
//   strata::Solver solver(options);
//   solver.analyze(A);          // pattern only: ordering, assembly tree, level schedule, plan
//   solver.factorize(A);        // values: multifrontal LLᵀ / LDLᵀ / LU
//   solver.solve(b, x, nrhs);   // triangular solves + iterative refinement
//   solver.refactorize(A2);     // same pattern, new values: reuses analysis and buffers
//
// Method: Jung & Bae, "An improved direct linear equation solver using multi-GPU in
// multi-body dynamics", Adv. Eng. Software 2018 (level-scheduled multifrontal method);
// Duff & Reid 1983 (multifrontal); Liu 1992 (the multifrontal method, SIAM Review).
#pragma once

#include <memory>
#include <span>
#include <vector>

#include "strata/errors.hpp"
#include "strata/options.hpp"
#include "strata/sparse_matrix.hpp"
#include "strata/stats.hpp"

namespace strata {

namespace detail {
struct SolverState;
struct SolverAccess;  // internal hooks for tests and benchmarks (src/core/solver_internal.hpp)
}  // namespace detail

/// Where the maximum-product matching of a general matrix's analysis may start
/// (Solver::analyze(a, start)): the row scaling and the matched column of each row of an
/// earlier analysis of a matrix of the same order n (Solver::matching_start()). Both
/// vectors have n entries, 0-based; row_scaling[i] > 0 is exp(u_i) of the matching's row
/// dual, matched_column[i] the column whose entry the analysis put on row i's diagonal.
struct MatchingStart {
  std::vector<double> row_scaling;
  std::vector<index_t> matched_column;
  bool empty() const { return row_scaling.empty() && matched_column.empty(); }
};

/// A sparse direct solver for one matrix pattern. Not thread-safe: one Solver per thread.
class Solver {
 public:
  /// Creates a solver with the given options (validated at analyze).
  explicit Solver(Options options = {});
  ~Solver();
  Solver(Solver&&) noexcept;
  Solver& operator=(Solver&&) noexcept;
  Solver(const Solver&) = delete;
  Solver& operator=(const Solver&) = delete;

  /// Analysis phase: validates A (square; see strata::validate), resolves the matrix type
  /// (MatrixType::automatic looks at symmetry here and tries Cholesky in factorize),
  /// computes the fill-reducing ordering, the assembly tree, the level schedule and the
  /// memory plan. Uses the pattern of A, and its values only for the matching and
  /// scaling of general and symmetric_indefinite matrices. Throws InvalidInput (also for a
  /// structurally singular matrix: an empty row or column, or, for symmetric_indefinite
  /// and general, no perfect matching on the nonzero values — the message names a row or
  /// column), NotSupported, OutOfMemory (the solver then holds no analysis and stays
  /// usable).
  void analyze(const SparseMatrix& a);

  /// analyze(a) with the maximum-product matching of a general matrix (Options::
  /// matching_and_scaling) started from `start` instead of from scratch: the row duals
  /// u_i = log start.row_scaling[i], the column duals made feasible for A's values
  /// (v_j = min_i (c_ij − u_i)), and the start's pairs that are then tight kept as the
  /// initial matching; the shortest augmenting paths (Duff & Koster 2001) match the rest.
  /// The result is again a maximum-product matching with its scaling; when A's values are
  /// near those of the analysis the start came from (a Newton loop's next analysis), most
  /// columns keep their pair and the searches are few. Where several matchings have the
  /// same product it may be another one than analyze(a) finds, so the factor may differ
  /// from a fresh solver's in its rounding. An empty start, or any other matrix type,
  /// gives analyze(a). Throws as analyze, and InvalidInput when the start's vectors do not
  /// have n entries, a row scaling is not finite and positive, or a matched column is out
  /// of range (named; the solver is left as it was).
  void analyze(const SparseMatrix& a, const MatchingStart& start);

  /// The current analysis's matching as the start of a later analysis (Solver::analyze(a,
  /// start)): its row scaling and matched columns. Empty before analyze and for analyses
  /// without an unsymmetric matching (symmetric types, matching_and_scaling off).
  MatchingStart matching_start() const;

  /// Analysis of a pattern that contains the analyzed one (entries added, none removed:
  /// in a Newton loop, a contact that closes adds a block) keeping the last analysis's
  /// matching, scaling and fill-reducing order: only the symbolic phase is redone (assembly
  /// tree, level schedule, memory plan), at a fraction of analyze's cost. The factor may
  /// have more fill than a fresh ordering would give; the values' drift from the kept
  /// scaling is corrected at each factorization (delayed pivoting and rescaling, as for a
  /// refactorization). Follow it with factorize. The factor is discarded. Throws
  /// InvalidState before analyze, InvalidInput when A is not square of the analyzed size or
  /// an analyzed entry is missing (named; nothing changes then), OutOfMemory as analyze.
  void analyze_keeping_order(const SparseMatrix& a);

  /// The number of entries of L (stats().analysis.nnz_l: the column counts' sum, diagonal
  /// included, before amalgamation) that analyze_keeping_order(a) would give, from the
  /// elimination tree and column counts of A's pattern in the kept order (Gilbert, Ng &
  /// Peyton, SIMAX 15, 1994) and nothing else of the analysis: whether keeping the order is
  /// worth it, decided before paying for the rest. The solver is not changed. Throws
  /// InvalidState before analyze, InvalidInput as analyze_keeping_order.
  index_t factor_entries_keeping_order(const SparseMatrix& a) const;

  /// Analysis of a pattern that differs from the analyzed one (entries added and removed:
  /// contact pairs that closed and others that opened) keeping the matching and scaling of
  /// the current analysis and computing a new fill-reducing order for A's pattern: analyze
  /// without its matching (Options::matching_and_scaling), where the kept order would fill
  /// too much and a new matching would cost more than the order. A's values are not read.
  /// A general matrix's pattern must hold every matched entry; a symmetric indefinite one
  /// with 2×2 pivots must contain the analyzed pattern. The values' drift from the kept
  /// scaling is corrected at each factorization, as after analyze_keeping_order. Follow it
  /// with factorize. The factor is discarded. Throws InvalidState before analyze,
  /// InvalidInput when A is not square of the analyzed size, has an empty row or column,
  /// or misses such an entry (named; nothing changes then), OutOfMemory as analyze.
  void analyze_keeping_matching(const SparseMatrix& a);

  /// Analysis of the factorized pattern in the order in which the last factorization took
  /// its pivots; that factorization must have delayed pivots (stats().factor.delayed_pivoting:
  /// the analysis's order needed static pivots for its values, Options::pivoting). The
  /// matching is changed so that those pivots lie on the diagonal of the scaled matrix B, in
  /// that sequence (the scaling includes the factorization's rescaling); only the symbolic
  /// phase is redone (assembly tree, level schedule, memory plan), at analyze_keeping_order's
  /// cost. A fixed-order factorization of the same values then takes the same pivots
  /// (LU without interchanges in a given order is unique), so it needs neither static nor
  /// delayed pivots, and values close to them usually do not either: a matrix refactorized
  /// many times with the same or slowly changing values then stays in the fixed order (on
  /// the GPU too) instead of delaying pivots on the host at every factorization. Values that
  /// change more (a multibody Newton loop across steps) soon need delayed pivots again.
  /// The factor may have more entries than the fresh analysis's (delayed pivots move up
  /// the tree: stats().analysis.nnz_l says). The factor is discarded: follow it with factorize or
  /// refactorize. Throws InvalidState when the last factorization delayed no pivot (or there
  /// is none), NotSupported when it was of a symmetric indefinite matrix (LU only),
  /// OutOfMemory as analyze (the solver then keeps its analysis and factor).
  void analyze_in_pivot_order();

  /// Numeric factorization of A, whose pattern must be the analyzed one (analyzes first
  /// if analyze was not called). Throws NotPositiveDefinite for a failed Cholesky of a
  /// matrix declared spd, InvalidInput for a NaN/Inf value, a changed pattern or values
  /// whose row or column sums overflow the double range, OutOfMemory (the factor, the workspaces
  /// and the device buffers are then released, the analysis is kept: a later factorize can succeed
  /// once memory is available). Perturbed pivots and inertia go to stats().factor. See
  /// docs/reliability.md for the outcome of each kind of singular or badly scaled matrix.
  void factorize(const SparseMatrix& a);

  /// Factorization of new values with the analyzed pattern. Reuses the analysis and all
  /// workspace; gives bitwise the same factor as a fresh factorize.
  void refactorize(const SparseMatrix& a);

  /// refactorize for values alone, as cuDSS's cudssMatrixSetValues: values[p] is the
  /// value of entry p of the matrix given to the last analysis (its `values` array: the
  /// same layout, storage and entry order; duplicates are added; of a symmetric matrix
  /// given in full storage only the lower triangle is read, as refactorize(A) reads it).
  /// The pattern is not compared (refactorize(A) does), so a caller that assembles into a
  /// fixed pattern saves a pass over it; a canonical matrix (CSC, row indices sorted, no
  /// duplicates, the lower triangle when symmetric) is read in place, another is gathered
  /// into that form first. `values` may also lie in GPU memory (cudaMalloc), as cuDSS's
  /// cudssMatrixSetValues takes them. On one GPU (the CUDA backend) a canonical matrix's
  /// values in GPU memory or in page-locked host memory (cudaMallocHost, cudaHostAlloc,
  /// cudaHostRegister) are copied to the device directly and the solver's copy of them is
  /// kept there, copied to the host only when the host needs it (the residuals of a checked
  /// solve); values in pageable memory are first staged in a page-locked buffer of the
  /// solver's (stats().factor.input_seconds); without that GPU pass, values in GPU memory
  /// are fetched to the host first. Either way the caller may change its values once this
  /// returns. Throws InvalidState before analyze, InvalidInput when values.size() is not
  /// that matrix's number of entries, and as refactorize.
  void refactorize(std::span<const double> values);

  /// Solves A X = B for nrhs right-hand sides. b and x are column-major n×nrhs arrays
  /// (leading dimension n); they may not alias. The solution is checked and refined as
  /// Options::solve_check and Options::refinement_* say (solve/refinement.hpp). Throws InvalidState
  /// before factorize, InvalidInput for a non-finite b, OutOfMemory (the factor is kept), or when
  /// the solution overflows the double range ("no representable solution"; x is then unspecified).
  /// A singular matrix factorized with perturbed pivots gives a finite x whose
  /// stats().solve.backward_error says whether it solves the system (+inf when the residual
  /// overflows).
  /// b and x may also lie in GPU memory (cudaMalloc), as cuDSS's dense matrices may: with
  /// the factor resident on that GPU (one GPU, stats().factor.factor_resident), b is read
  /// and x written there with nothing through the host (a non-finite b is found there too,
  /// and x is then left as it was); a checked solve's residuals and refinement steps run
  /// there as well (Options::gpu_refinement), only GMRES after a stalled refinement on the
  /// host. Otherwise b is fetched to the host and x copied back. With host arrays and a
  /// resident factor, the checked solve's residuals and steps also run on that GPU. Work that writes b must be complete, or on
  /// the legacy default stream, when solve is called; x is complete when it returns.
  void solve(const double* b, double* x, index_t nrhs = 1);

  /// Convenience overload: one or several right-hand sides stored column-major in b
  /// (size must be a multiple of n). Throws InvalidInput on a wrong size.
  std::vector<double> solve(const std::vector<double>& b);

  /// The order n of the analyzed matrix (0 before analyze).
  index_t size() const;
  /// The resolved matrix type after factorize (automatic before).
  MatrixType matrix_type() const;
  /// Statistics of the last call of each phase.
  const Stats& stats() const;
  const Options& options() const;
  /// Sets Options::pivoting for the factorizations from the next one on; the analysis and
  /// the current factor are kept. (A Newton loop whose values have left what the analysis's
  /// order takes switches from Pivoting::automatic to Pivoting::delayed, saving the fixed
  /// order's attempt at each refactorization.)
  void set_pivoting(Pivoting pivoting);
  /// The fill-reducing permutation in use (new to old), after analyze.
  const std::vector<index_t>& permutation() const;

 private:
  friend struct detail::SolverAccess;
  std::unique_ptr<detail::SolverState> state_;
};

}  // namespace strata
