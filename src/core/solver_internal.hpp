// strata — internal hooks into the Solver for tests and benchmarks (not public API).
//
// The multi-worker factorization (numeric/multi_device.cpp) is reached through the
// public API only with several GPUs. So that machines without GPUs test and measure the
// same path through the whole Solver (analysis split, solve, refinement,
// refactorization, per-worker statistics), this hook makes a Solver use N CPU executors
// as its workers, exactly as it would use N CUDA executors.
#pragma once

#include <memory>
#include <string>

#include "numeric/driver.hpp"
#include "numeric/factor.hpp"
#include "strata/solver.hpp"

namespace strata::detail {

struct SolverAccess {
  /// Makes `s` analyze for `workers` workers and factor with that many CPU executors of
  /// `threads_each` host threads each (a multi-worker driver, numeric/driver.hpp), with
  /// `config` as it is given (its work_stealing, not Options::work_stealing; its
  /// before_subtree hook for tests). Call before analyze. workers == 0 restores the normal
  /// behaviour. Throws InvalidInput for negative workers or threads_each < 1.
  static void use_host_workers(Solver& s, int workers, int threads_each,
                               numeric::MultiWorkerConfig config = {});
  /// Makes `s` run its numeric phases through `driver` (numeric/driver.hpp; the
  /// distributed solver's collective phases, host workers), analyzing for its workers();
  /// drops the analysis and factor. A null driver restores the normal choice (from the
  /// options, at the next analyze).
  static void set_driver(Solver& s, std::unique_ptr<numeric::NumericDriver> driver);
  /// The analysis of `s` (nullptr before analyze), for the distributed solver to
  /// broadcast and to give a rank-local factor layout.
  static Analysis* analysis(Solver& s);
};

}  // namespace strata::detail
