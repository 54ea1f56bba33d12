// strata — copies between large host buffers on the host's threads.
//
// Why: the GPU backend moves factor panels and contribution blocks between pinned staging
// buffers, the host factor and the host arena in blocks of hundreds of megabytes to
// gigabytes. One thread's memcpy runs at a fraction of the PCIe transfers it follows, so
// single-threaded copies of panels and of tiled fronts' contribution blocks become a
// large share of an out-of-core factorization (bench/history.md). These helpers split the
// copy over the calling thread's TBB arena in chunks of at least 1 MiB, so a small copy
// stays on one thread.
#pragma once
#include <tbb/task_arena.h>
#include <tbb/task_group.h>

#include <cstddef>

namespace strata {

/// dst[0, n) = src[0, n); the ranges must not overlap.
void parallel_copy(double* dst, const double* src, std::size_t n);

/// The rows × cols column-major block at src (leading dimension ld_src ≥ rows) into dst
/// (leading dimension ld_dst ≥ rows), columns in parallel; the blocks must not overlap.
void parallel_copy_2d(double* dst, std::size_t ld_dst, const double* src, std::size_t ld_src,
                      std::size_t rows, std::size_t cols);

/// A copy dst[0, n) = src[0, n) (parallel_copy) that runs on an arena's worker threads
/// while the thread that started it goes on, and is waited for by wait() or the
/// destructor. An arena of one thread has no worker to run it: start() then copies before
/// it returns. Neither range may be touched by anyone else until the wait.
class BackgroundCopy {
 public:
  BackgroundCopy() = default;
  BackgroundCopy(const BackgroundCopy&) = delete;
  BackgroundCopy& operator=(const BackgroundCopy&) = delete;
  ~BackgroundCopy() { wait(); }

  /// Starts the copy (one at a time: a copy still running is waited for first).
  void start(tbb::task_arena& arena, double* dst, const double* src, std::size_t n);
  /// Returns once the copy started last is complete (at once when none runs).
  void wait() noexcept;
  bool running() const { return arena_ != nullptr; }

 private:
  tbb::task_arena* arena_ = nullptr;  // where the running copy was started, or none
  tbb::task_group group_;
};

}  // namespace strata
