// strata — the numeric factor and the executor interface every backend implements.
//
// One algorithm, several executors (DESIGN.md §4): the driver in numeric/multifrontal.cpp
// walks the memory plan batch by batch and hands each batch to an Executor, which
// assembles, factors and stores its fronts. The CPU executor runs the fronts of a batch
// on host threads with BLAS/LAPACK; the CUDA executor (numeric/cuda) runs them as
// batched launches. Both fill the same NumericFactor, so the solve and every test can
// compare them entry by entry.
#pragma once

#include <memory>
#include <vector>

#include "core/analysis.hpp"
#include "numeric/cpu/dense_front.hpp"
#include "strata/options.hpp"

namespace strata::numeric {

/// The factor of one matrix, in the tree numbering of its Analysis.
///   panels:     front f's first k columns (n_rows×k column-major: L11 or L11\U11 packed,
///               then L21) at factor_layout.panel_offset[f]; for LU the k×(n_rows−k) U12
///               follows. LDLᵀ: L11 is unit lower with zeros in the (j+1, j) places of
///               2×2 pivots; D is kept apart in d_diag / d_off.
///   rows:       row indices of each front with its local pivot permutation applied to
///               the first k (same offsets as AssemblyTree::rows).
///   d_diag, d_off: LDLᵀ only, by pivot position: D(j,j) and, for the first column of a
///               2×2 pivot, D(j+1,j) (pivot_size[j] == 2 there, 0 on the second column).
struct NumericFactor {
  MatrixType type = MatrixType::automatic;
  std::vector<double> panels;
  std::vector<index_t> rows;
  std::vector<double> d_diag;
  std::vector<double> d_off;
  std::vector<int> pivot_size;
  std::vector<cpu::PivotStats> front_stats;  ///< per front, merged in front order
  bool valid = false;
};

/// Everything an executor needs to factor a batch.
struct FactorContext {
  const Analysis* analysis = nullptr;
  const double* values = nullptr;  ///< scaled values of the canonical input (entry order)
  MatrixType type = MatrixType::spd;
  double static_pivot = 0;  ///< absolute threshold / replacement for tiny pivots
  NumericFactor* factor = nullptr;
  std::vector<double>* cb_arena = nullptr;  ///< contribution blocks (CbLayout)
};

/// A backend that factors batches of fronts. Implementations: CpuExecutor, CudaExecutor.
class Executor {
 public:
  virtual ~Executor() = default;
  virtual const char* name() const = 0;
  /// Called once before the first batch of a factorization.
  virtual void begin(const FactorContext& ctx) {}
  /// Assembles (original entries + extend-add of children's contribution blocks),
  /// factors and stores the fronts schedule.fronts[batch.begin .. batch.end). Throws
  /// NotPositiveDefinite (original column) for a failed Cholesky pivot.
  virtual void factor_batch(const FactorContext& ctx, const BatchInfo& batch) = 0;
  /// Called once after the last batch.
  virtual void end(const FactorContext& ctx) {}
  /// Solves with `fac` where this executor keeps it (the CUDA executor, when the factor
  /// stayed resident on the device): x as solve_in_place. Returns false when it cannot
  /// (the caller then runs solve_in_place on the host); the default cannot.
  virtual bool solve(const Analysis& an, const NumericFactor& fac, double* x, index_t nrhs) {
    return false;
  }
  /// Adds backend figures of the last factorization (bytes moved, device time) to `fs`.
  virtual void report(FactorStats& fs) const {}
};

/// The CPU executor; `threads` host threads (0: all hardware threads). `reproducible`:
/// large fronts too run single-threaded BLAS (see Options::reproducible).
std::unique_ptr<Executor> make_cpu_executor(int threads, bool reproducible = false);

/// The CUDA executor; throws NotSupported in a build without CUDA or without a GPU.
std::unique_ptr<Executor> make_cuda_executor(const Options& opts);

/// True when this build has the CUDA backend and a GPU is visible.
bool cuda_available();

/// LDLᵀ bookkeeping of front f once its partial factorization is in the factor (shared by
/// the executors, so that a CPU and a GPU factor have one layout): moves D out of the
/// front's panel (its diagonal to d_diag, the (j+1, j) entries of 2×2 pivots to d_off,
/// leaving L11 unit lower with zeros there), sets pivot_size by global pivot position
/// (first_pivot[f] + i: 1, or 2 then 0 for a 2×2 pivot) and the permuted pivot rows.
/// local_perm[0..k) and local_pivot_size[0..k) are as factor_front_ldlt returns them.
void store_ldlt_front(const Analysis& an, index_t f, const index_t* local_perm,
                      const int* local_pivot_size, NumericFactor& factor);

/// Runs the numeric factorization of the scaled canonical values with `exec`.
/// Fills `factor`; throws as Executor::factor_batch.
void factorize(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
               double static_pivot, Executor& exec, NumericFactor& factor,
               std::vector<double>& cb_arena);

/// Solves with the factor in place: x (tree numbering, n×nrhs column-major, leading
/// dimension n) holds the right-hand sides on entry and the solutions on return.
void solve_in_place(const Analysis& an, const NumericFactor& factor, double* x, index_t nrhs);

}  // namespace strata::numeric
