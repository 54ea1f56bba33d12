// strata — copies between large host buffers on the host's threads.
//
// Why: the GPU backend moves factor panels and contribution blocks between pinned staging
// buffers, the host factor and the host arena in blocks of hundreds of megabytes to
// gigabytes. One thread's memcpy runs at about 6 GB/s, well below the PCIe transfers it
// follows (55 GB/s measured on the lent H100): at commit 4c2899b the single-threaded
// copies of the panels were half the time of a lap3d 100³ factorization whose factor did
// not stay on the device, and the copies of a tiled front's contribution block (a 2-D
// cudaMemcpy between host buffers) 60% of it under a budget of 1/20 of the factor. These
// helpers split the copy over the calling thread's TBB arena in chunks of at least 1 MiB,
// so a small copy stays on one thread.
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
