// strata — internal hooks into the Solver for tests and benchmarks (not public API).
//
// The multi-worker factorization (numeric/multi_device.cpp) is reached through the
// public API only with several GPUs. So that machines without GPUs test and measure the
// same path through the whole Solver (analysis split, solve, refinement,
// refactorization, per-worker statistics), this hook makes a Solver use N CPU executors
// as its workers, exactly as it would use N CUDA executors.
#pragma once

#include <functional>
#include <string>

#include "numeric/factor.hpp"
#include "strata/solver.hpp"

namespace strata::detail {

/// The numeric phases of a Solver done elsewhere: the distributed solver (src/distributed)
/// runs rank 0's Solver with these, so that type resolution, scaling, statistics and
/// iterative refinement stay the Solver's, while the factorization and every solve with
/// the factor are collective over the ranks.
struct ExternalNumeric {
  /// > 0: the analysis is split for this many workers (ranks × workers per rank).
  int workers = 0;
  /// Replaces the numeric factorization (factorize / factorize_multi): fills `factor` or
  /// throws as they do.
  std::function<void(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
                     double static_pivot, numeric::NumericFactor& factor)>
      factor;
  /// Replaces solve_in_place (x in tree numbering, n×nrhs).
  std::function<void(const Analysis& an, const numeric::NumericFactor& factor, double* x,
                     index_t nrhs)>
      solve;
  Backend backend = Backend::cpu;  ///< FactorStats::backend
  /// Adds backend figures to the statistics of a factorization (may be empty).
  std::function<void(FactorStats& fs)> report;
};

struct SolverAccess {
  /// Makes `s` analyze for `workers` workers and factor with that many CPU executors of
  /// `threads_each` host threads each, with `config` (work stealing from
  /// Options::work_stealing is overridden by config.work_stealing; the injected delay is
  /// for tests). Call before analyze. workers == 0 restores the normal behaviour. Throws
  /// InvalidInput for negative workers or threads_each < 1.
  static void use_host_workers(Solver& s, int workers, int threads_each,
                               numeric::MultiWorkerConfig config = {});
  /// Makes `s` run its numeric phases through `external` (see ExternalNumeric); drops
  /// its analysis and factor. An empty ExternalNumeric restores the normal behaviour.
  static void set_external(Solver& s, ExternalNumeric external);
  /// The analysis of `s` (nullptr before analyze), for the distributed solver to
  /// broadcast and to give a rank-local factor layout.
  static Analysis* analysis(Solver& s);
};

}  // namespace strata::detail
