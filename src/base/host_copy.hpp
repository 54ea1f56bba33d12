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
#include <cstddef>

namespace strata {

/// dst[0, n) = src[0, n); the ranges must not overlap.
void parallel_copy(double* dst, const double* src, std::size_t n);

/// The rows × cols column-major block at src (leading dimension ld_src ≥ rows) into dst
/// (leading dimension ld_dst ≥ rows), columns in parallel; the blocks must not overlap.
void parallel_copy_2d(double* dst, std::size_t ld_dst, const double* src, std::size_t ld_src,
                      std::size_t rows, std::size_t cols);

}  // namespace strata
