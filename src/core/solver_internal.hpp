// strata — internal hooks into the Solver for tests and benchmarks (not public API).
//
// The multi-worker factorization (numeric/multi_device.cpp) is reached through the
// public API only with several GPUs. So that machines without GPUs test and measure the
// same path through the whole Solver (analysis split, solve, refinement,
// refactorization, per-worker statistics), this hook makes a Solver use N CPU executors
// as its workers, exactly as it would use N CUDA executors.
#pragma once

#include "numeric/factor.hpp"
#include "strata/solver.hpp"

namespace strata::detail {

struct SolverAccess {
  /// Makes `s` analyze for `workers` workers and factor with that many CPU executors of
  /// `threads_each` host threads each, with `config` (work stealing from
  /// Options::work_stealing is overridden by config.work_stealing; the injected delay is
  /// for tests). Call before analyze. workers == 0 restores the normal behaviour. Throws
  /// InvalidInput for negative workers or threads_each < 1.
  static void use_host_workers(Solver& s, int workers, int threads_each,
                               numeric::MultiWorkerConfig config = {});
};

}  // namespace strata::detail
