// strata tests — shared helpers: paths to the shared matrices, random matrices of each
// type, dense conversions and dense LAPACK references.
#pragma once

#include <optional>
#include <random>
#include <string>
#include <vector>

#include "strata/options.hpp"
#include "strata/sparse_matrix.hpp"

// STRATA_TEST_HAS_ASAN: 1 in AddressSanitizer builds (gcc defines __SANITIZE_ADDRESS__,
// clang answers __has_feature), for tests whose measurements ASan changes.
#if defined(__SANITIZE_ADDRESS__)
#define STRATA_TEST_HAS_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define STRATA_TEST_HAS_ASAN 1
#endif
#endif
#ifndef STRATA_TEST_HAS_ASAN
#define STRATA_TEST_HAS_ASAN 0
#endif

namespace strata {
struct Analysis;
namespace numeric {
struct NumericFactor;
}
}  // namespace strata

namespace strata::test {

/// Path of a shared SuiteSparse matrix, e.g. matrix_path("bcsstk09") → ".../bcsstk09.mtx.gz".
std::string matrix_path(const std::string& name);

/// Names (without .mtx.gz) of every matrix in the shared folder, sorted.
std::vector<std::string> shared_matrix_names();

/// A fresh random engine, seeded from std::random_device; the seed is printed through
/// gtest's RecordProperty/SCOPED_TRACE by the caller when it matters. To replay a failure,
/// STRATA_TEST_SEED=<the printed seed> seeds it instead (tests only: the library reads
/// no environment variable).
std::mt19937_64 fresh_rng(unsigned long long* seed_out = nullptr);

/// A test matrix, its name in traces, and the factorization type it is given.
struct NamedMatrix {
  std::string name;
  SparseMatrix a;  ///< (MPI tests: empty on ranks other than 0)
  MatrixType type;
};

/// A path under the system temporary folder that no other test process uses (name,
/// process id and a random number): test binaries of several builds run side by side on
/// one machine, and a fixed path let one delete the other's files. Not created.
std::string unique_temp_path(const std::string& name);

/// Kinds of random matrices.
enum class RandomKind { spd, symmetric_indefinite, general };

/// A random sparse n×n matrix with about `per_column` off-diagonal entries per column.
/// spd: symmetric, diagonally dominant, positive diagonal (Storage::lower).
/// symmetric_indefinite: symmetric with diagonal entries of both signs and some zero
/// diagonal entries (a KKT-like block), nonsingular with probability ~1 (Storage::lower).
/// general: unsymmetric, with some zero diagonal entries, nonsingular with probability ~1
/// (Storage::full). Canonical CSC.
SparseMatrix random_sparse(index_t n, index_t per_column, RandomKind kind, std::mt19937_64& rng);

/// A matrix and new values for its pattern: a random_sparse matrix `a` (3 entries per
/// column) of each kind and size 1, 2, 3, 5 and 733, `next` the same with every value
/// scaled by a factor drawn from [0.97, 1.03], and the type to factor them as (LU; LLᵀ
/// trying first then LDLᵀ, MatrixType::automatic; LDLᵀ).
struct ValueChange {
  MatrixType type;
  index_t n;
  SparseMatrix a, next;
};
std::vector<ValueChange> value_changes(std::mt19937_64& rng);

/// `a` with an explicit zero after each column's entries, repeating the column's first
/// row: the same matrix, not in the analyzed pattern (it has duplicates), so that the
/// Solver takes the host's value pass for it.
SparseMatrix with_duplicate_zeros(const SparseMatrix& a);

/// A random KKT (saddle point) matrix K = P [[H, Bᵀ], [B, 0]] Pᵀ of order n, Storage::lower,
/// canonical: n/3 constraints, H random sparse SPD (diagonally dominant) of order
/// n − n/3, B random sparse of full row rank (each row has one entry of magnitude in
/// [0.5, 1.5] in a column of its own, plus about two entries in [−1, 1]), and P a random
/// permutation that interleaves constraints and variables. Its inertia is exactly
/// (n − n/3, n/3, 0). With `decades` > 0 it is further scaled symmetrically by random
/// powers of ten in [−decades, decades] (which keeps the inertia). `is_constraint`, when
/// given, receives the flags of the constraint unknowns (zero diagonal).
SparseMatrix random_kkt(index_t n, std::mt19937_64& rng, double decades = 0,
                        std::vector<char>* is_constraint = nullptr);

/// A random_kkt matrix with explicit diagonal entries in its constraint rows: `analyzed`
/// with 20 there, `kkt` with 0 (the KKT matrix itself, its pattern holding the diagonal),
/// so that an analysis of `analyzed` is stale for `kkt`: the zero pivots may be where its
/// order cannot take them. `constraints` = n/3, kkt's inertia (n − n/3, n/3, 0).
struct StaleKkt {
  SparseMatrix analyzed, kkt;
  index_t constraints = 0;
};
StaleKkt stale_kkt(index_t n, std::mt19937_64& rng, double decades = 0);

/// A random n×n pattern (canonical CSC, Storage::full, values 0): the diagonal, plus
/// `per_column` random entries per column and the transposed positions of half of them.
SparseMatrix random_pattern_with_diagonal(index_t n, index_t per_column, std::mt19937_64& rng);

/// `pattern` with values: off-diagonal entries uniform in [−1, 1], the diagonal `diag`.
SparseMatrix with_values(const SparseMatrix& pattern, double diag, std::mt19937_64& rng);

/// Whether the nonzero entries of a (explicit zeros left out) hold a perfect matching of
/// rows to columns (augmenting paths, Kuhn's algorithm): an independent check of structural
/// singularity for small random draws.
bool structurally_nonsingular(const SparseMatrix& a);

/// A refactorization whose analysis is stale: on one random general pattern with its
/// diagonal (n × n, about 3 off-diagonal entries per column), `analyzed` has a dominant
/// diagonal (20), `stale` a zero one and fresh off-diagonal values, so every pivot of the
/// order made for `analyzed` is zero for `stale`; `b` is uniform in [−1, 1]. Drawn again
/// until `stale` is structurally nonsingular and dense LU (dgesv) solves it.
struct StaleAnalysis {
  SparseMatrix analyzed, stale;
  std::vector<double> b;
};
StaleAnalysis stale_analysis(index_t n, std::mt19937_64& rng);

/// Values far from an analysis's on one pattern with its diagonal, for static pivots in the
/// analysis's order: `analyzed` with a dominant diagonal (20), `stale` with the diagonal 8
/// and one diagonal entry in `zero_one_in` zeroed (fresh off-diagonal values for each);
/// `b` uniform in [−1, 1], `ref` = stale⁻¹·b by dense LU (dgesv) and `kappa` = κ∞(stale).
/// Empty for a singular draw (structurally, or for dgesv) or κ∞ ≥ 1e10.
struct StaleValues {
  SparseMatrix analyzed, stale;
  std::vector<double> b, ref;
  double kappa = 0;
};
std::optional<StaleValues> stale_values(const SparseMatrix& pattern, int zero_one_in,
                                        std::mt19937_64& rng);

/// Dense column-major n_rows×n_cols copy of A (symmetric storage expanded).
std::vector<double> to_dense(const SparseMatrix& a);

/// Solves the dense system with LAPACK dgesv (column-major, n×nrhs). Returns false if
/// dgesv reports a singular matrix.
bool dense_solve(std::vector<double> a, index_t n, std::vector<double>& b, index_t nrhs);

/// log|det A| and its sign from LAPACK's dgetrf of a dense copy (sign 0 when singular).
void dense_logdet(const SparseMatrix& a, double* logdet, int* sign);

/// Sets to zero, in place, the diagonal entry of every column of A (square, full storage,
/// pattern kept) with probability 1/one_in (every column for one_in ≤ 1): pivots an
/// analysis made with a dominant diagonal cannot take.
void zero_some_diagonal(SparseMatrix& a, int one_in, std::mt19937_64& rng);

/// κ∞(A) = ‖A‖∞‖A⁻¹‖∞ as LAPACK estimates it on a dense copy (dgetrf, then dgecon:
/// Higham's estimator of ‖A⁻¹‖₁ on Aᵀ), for tolerances that follow the conditioning;
/// +∞ when dgetrf finds A singular. O(n³): for matrices of a few thousand rows.
double condition_inf(const SparseMatrix& a);

/// ‖b − A x‖∞ / (‖A‖∞ ‖x‖∞ + ‖b‖∞) for one right-hand side.
double backward_error(const SparseMatrix& a, const double* x, const double* b);

/// Max-norm relative difference ‖x − y‖∞ / ‖y‖∞ (or the absolute one when y is 0); +∞
/// where an entry is NaN in one vector and not in the other.
double relative_difference(const std::vector<double>& x, const std::vector<double>& y);

/// The values the numeric phase factors for `an` (A's canonical values with the
/// analysis's row/column scaling applied, in entry order), and in *pivot a static pivot
/// threshold of the Solver's kind: 1e-8 · max(max |value|, 1).
std::vector<double> scaled_values(const Analysis& an, const SparseMatrix& a, double* pivot);

/// The factor of one single-threaded CPU executor taking an's level schedule batch by
/// batch (the driver's path for an executor without a whole-tree traversal): the kernels
/// the multi-worker and distributed drivers run on each part, so their factors must equal
/// it bitwise. A plain CPU executor factors the whole tree depth-first, forming Cholesky
/// fronts in column panels: the same factor to rounding, bitwise only where the BLAS
/// computes a product the same way whatever its blocking (OpenBLAS's small-matrix kernels
/// on AVX-512 do not).
numeric::NumericFactor level_schedule_factor(const Analysis& an, const std::vector<double>& v,
                                             MatrixType type, double pivot);

/// Sleeps `seconds` on the calling thread when `slow` (a slow worker, for the
/// multi-worker factorization's MultiWorkerConfig::before_subtree).
void sleep_if(bool slow, double seconds);

}  // namespace strata::test
