// strata — the layout of a 64×64 diagonal block factored by one block of threads in the
// batched panel kernels (kernels_lu_panel.cu for LU, kernels_panel.cu for Cholesky): eight
// threads per row while it is eliminated (thread t holds row t / kLanes's columns
// c ≡ t mod kLanes in registers); the inverses are formed in the same rows (Gauss–Jordan),
// or, in the LU kernel after row interchanges, four threads per column. Every dependent
// chain of the block is thus several times shorter than with one thread per row or
// column, and the threads of a row or column are neighbouring lanes of one warp, which
// combine their parts by shuffles.
//
// The kernels' loops over the block's 64 columns (or rows) are written as an unrolled loop
// over the kPerThread register columns and, inside it, a loop over the kLanes columns of
// each that is not unrolled: a register array needs indices known at compile time, and 64
// unrolled steps would make each kernel hundreds of KB of code, more than the SM's
// instruction cache holds, fetched again at every launch.
#pragma once

#include "numeric/cuda/tile_mma.cuh"

namespace strata::cuda::row_lanes {

constexpr int kEdge = tile::kEdge;          ///< the block's rows and columns
constexpr int kLanes = 8;                   ///< threads per row
constexpr int kThreads = kLanes * kEdge;    ///< threads of the block
constexpr int kPerThread = kEdge / kLanes;  ///< the columns of its row a thread holds
constexpr int kPad = kEdge + 1;             ///< row stride of the block in shared memory

/// Σ over kN neighbouring lanes (kN a power of two; lane groups aligned to kN) of their
/// parts, in every one of them: butterfly shuffles, all 32 lanes of the warp taking part.
template <int kN>
__device__ __forceinline__ double lane_sum(double part) {
  static_assert(kN > 0 && kN <= 32 && (kN & (kN - 1)) == 0, "a power of two up to a warp");
#pragma unroll
  for (int o = 1; o < kN; o <<= 1) part += __shfl_xor_sync(0xffffffffu, part, o);
  return part;
}

}  // namespace strata::cuda::row_lanes
