// strata — CUDA LDLᵀ (Bunch–Kaufman, restricted to the fully summed block) of fronts.
//
// Both entry points leave a front exactly in the layout of the CPU kernel
// (numeric/cpu/dense_front.hpp, factor_front_ldlt): on the m×m column-major front F
// (leading dimension m, lower triangle), L11 unit lower below the diagonal of F[0:k,0:k]
// with D's diagonal on the diagonal and, for a 2×2 pivot at j, D(j+1, j) in F(j+1, j);
// L21 in F[k:m, 0:k]; the contribution block S = F22 − L21 D L21ᵀ in the lower triangle of
// F[k:m, k:m]. Per front they return the local symmetric permutation (position i holds
// original local index perm[i]), the local pivot sizes (1, or 2 on both columns of a 2×2
// pivot) and the number of pivots replaced by ±static_pivot. The statistics (inertia,
// determinant) are computed on the host from D (cpu::ldlt_stats_from_d).
#pragma once

#include <cublas_v2.h>
#include <cuda_runtime.h>

#include <cstdint>

#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/kernels.cuh"

namespace strata::cuda {

/// Partial LDLᵀ of small fronts, one thread block each, in place in the pool: the
/// right-looking Bunch–Kaufman loop over the whole front. `positions` lists batch positions
/// (device array of `count`). Per listed front i: perturbed[i] = static pivots; the local
/// permutation and pivot sizes of its k pivots go to perm + perm_offset[i] and
/// pivot_size + perm_offset[i].
void launch_ldlt_small(const DeviceTree& t, const std::int64_t* positions, std::int64_t count,
                       double* pool, double static_pivot, std::int64_t* perturbed,
                       std::int64_t* perm, int* pivot_size, const std::int64_t* perm_offset,
                       cudaStream_t s);

/// Gives the factor panels of the fronts at chunk positions [begin, begin+count) — in
/// `panels` at panel_offset[i] — the layout store_ldlt_front gives the host factor: unit
/// diagonal, and zeros in the (j+1, j) places of 2×2 pivots (D is kept apart). Their local
/// pivot sizes are at pivot_size + psize_at[i]. For the resident device factor.
void launch_ldlt_unit_panels(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                             const std::int64_t* panel_offset, const int* pivot_size,
                             const std::int64_t* psize_at, double* panels, cudaStream_t s);

/// Partial LDLᵀ of one large front, blocked: panels of 64 columns (ldlt_device.cuh's kLdltPanel)
/// factored by one thread block (left-looking inside the panel, with pivot candidates from the
/// whole fully summed block, as the CPU's blocked kernel), each followed by the trailing update
/// F[e:m, e:m] −= L·Wᵀ (W = L·D of the panel) by cublasDsyrkx. The host reads each panel's
/// end back (one small synchronous copy per panel: a 2×2 pivot may extend a panel by one
/// column). Owns its device workspace (m × 65 doubles), grown on demand.
class LdltLarge {
 public:
  /// Factors F (m×m, device, leading dimension m) with k fully summed columns on stream `s`
  /// (the cuBLAS handle must be bound to `s`). perm (k), pivot_size (k) and perturbed (1)
  /// are device pointers written as described above. Returns when the work is queued on
  /// `s`, except that it waits for each panel's end.
  void factor(cublasHandle_t blas, cudaStream_t s, double* f, std::int64_t m, std::int64_t k,
              double static_pivot, std::int64_t* perm, int* pivot_size, std::int64_t* perturbed);

 private:
  DeviceBuffer<double> work_;
  DeviceBuffer<std::int64_t> end_;
  PinnedBuffer<std::int64_t> end_host_;
};

}  // namespace strata::cuda
