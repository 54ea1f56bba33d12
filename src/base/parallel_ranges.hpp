// strata — a loop over [0, n) in ranges over the calling TBB arena's threads.
//
// The analysis's passes over the columns of a pattern whose iterations are independent
// (each writes only its own outputs) run their ranges over the threads of the arena that
// called the analysis; inside a SerialScope (a small matrix, base/serial_scope.hpp), in
// an arena of one thread, or when n is below one grain, the whole range runs on the
// calling thread in one call, without entering TBB. The result is the same for any thread count
// when each iteration's output does not depend on the others.
#pragma once

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include "base/serial_scope.hpp"
#include "strata/types.hpp"

namespace strata::detail {

/// Calls body(begin, end) on ranges that cover [0, n) once, over the calling arena's
/// threads in ranges of at least `grain` (≥ 1), or body(0, n) on the calling thread (one
/// thread, see the file comment).
template <class Body>
void parallel_ranges(index_t n, index_t grain, const Body& body) {
  if (n <= 0) return;
  if (serial_passes() || n <= grain || tbb::this_task_arena::max_concurrency() == 1) {
    body(index_t{0}, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<index_t>(0, n, grain),
                    [&](const tbb::blocked_range<index_t>& r) { body(r.begin(), r.end()); });
}

}  // namespace strata::detail
