// strata — CUDA LDLᵀ of fronts with restricted Bunch–Kaufman pivoting (see kernels_ldlt.cuh).
//
// The pivoting is the CPU kernel's, rule for rule (numeric/cpu/dense_front.cpp): Bunch–
// Kaufman with α = (1+√17)/8 (Bunch & Kaufman 1977; Golub & Van Loan, 4th ed., §4.4.4)
// whose candidate search and magnitude tests (colmax, rowmax) use only the fully summed
// rows/columns 0..k−1; if every entry of the candidate column (diagonal included) is below
// static_pivot the step is a 1×1 pivot without interchange; a 1×1 pivot d with
// |d| < static_pivot becomes sign(d)·static_pivot (sign(0) = +) and is counted; a zero
// pivot (static pivoting off) is inverted as 0; a 2×2 pivot is inverted relative to its
// off-diagonal and falls back to a 1×1 pivot when |ac/b² − 1| < 1/4 (rounding only).
// Symmetric interchanges move whole rows and columns of the front restricted to indices
// < k (rows ≥ k never move; the columns of F21 are permuted).
//
// Small fronts: one thread block per front, the whole batch in one launch; the
// right-looking loop over the whole front (the CPU's ldlt_small): pivot search, interchange,
// then the rank-1 or rank-2 update of the lower trailing matrix F[j:m, j:m], all in global
// memory by the block's threads.
//
// Large fronts: a blocked factorization in the manner of LAPACK's dsytrf/dlasyf (Anderson
// et al., LAPACK Users' Guide), the CPU's ldlt_pivot_block extended to all m rows. A panel
// kernel (one block) factors up to kLdltPanel columns left-looking: each column, and each
// pivot candidate column it needs, is first brought up to date against the panel's
// finished columns with W = L·D (the updated columns before division by D, kept for rows
// kk..m−1), so pivot candidates come from the whole remaining fully summed block, not only
// from the panel — the pivot sequence is the CPU's up to rounding. The trailing matrix
// F[e:m, e:m] (the rest of F11, F21 and F22 together) then takes one lower-triangular
// update −L_panel W_panelᵀ by cublasDsyrkx, where the flops are. Because a 2×2 pivot
// starting at a panel's last column makes the panel one column wider (as in dlasyf), the
// host reads the panel's end before the update: one 8-byte synchronous copy per panel.
//
// The device code is in ldlt_device.cuh (so that a CPU test can run it too); this file
// holds the kernels and the host driver of the large-front path.
#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/kernels_ldlt.cuh"
#include "numeric/cuda/ldlt_device.cuh"

namespace strata::cuda {
namespace {

using ldlt_device::kLdltPanel;
using ldlt_device::kLdltThreads;

__global__ void ldlt_small_kernel(DeviceTree t, const std::int64_t* positions, double* pool,
                                  double static_pivot, std::int64_t* perturbed, std::int64_t* perm,
                                  int* pivot_size, const std::int64_t* perm_offset) {
  const std::int64_t i = blockIdx.x;
  const std::int64_t pos = positions[i];
  const std::int64_t f = t.fronts[pos];
  ldlt_device::ldlt_small_front(pool + t.pos_offset[pos], t.n_rows[f], t.n_pivots[f], static_pivot,
                                perm + perm_offset[i], pivot_size + perm_offset[i], perturbed + i);
}

__global__ void ldlt_panel_kernel(double* F, std::int64_t m, std::int64_t k, std::int64_t j0,
                                  double sp, double* W, std::int64_t* perm, int* psize,
                                  std::int64_t* perturbed, std::int64_t* end) {
  ldlt_device::ldlt_panel(F, m, k, j0, sp, W, perm, psize, perturbed, end);
}

// One block per front: unit diagonal, and the (j+1, j) entry of each 2×2 pivot zeroed (a
// 2×2 pivot's columns both have local size 2, so the first of a pair is found by a scan).
__global__ void ldlt_unit_panels_kernel(DeviceTree t, std::int64_t begin,
                                        const std::int64_t* panel_offset, const int* pivot_size,
                                        const std::int64_t* psize_at, double* panels) {
  const std::int64_t f = t.fronts[begin + blockIdx.x];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  double* L = panels + panel_offset[blockIdx.x];
  const int* ps = pivot_size + psize_at[blockIdx.x];
  for (std::int64_t i = threadIdx.x; i < k; i += blockDim.x) L[i * m + i] = 1.0;
  if (threadIdx.x == 0)
    for (std::int64_t j = 0; j < k; j += ps[j] == 2 ? 2 : 1)
      if (ps[j] == 2 && j + 1 < k) L[j * m + j + 1] = 0.0;
}

}  // namespace

void launch_ldlt_unit_panels(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                             const std::int64_t* panel_offset, const int* pivot_size,
                             const std::int64_t* psize_at, double* panels, cudaStream_t s) {
  if (count == 0) return;
  ldlt_unit_panels_kernel<<<static_cast<unsigned>(count), kLdltThreads, 0, s>>>(
      t, begin, panel_offset, pivot_size, psize_at, panels);
  STRATA_CUDA_LAUNCH();
}

void launch_ldlt_small(const DeviceTree& t, const std::int64_t* positions, std::int64_t count,
                       double* pool, double static_pivot, std::int64_t* perturbed,
                       std::int64_t* perm, int* pivot_size, const std::int64_t* perm_offset,
                       cudaStream_t s) {
  if (count == 0) return;
  ldlt_small_kernel<<<static_cast<unsigned>(count), kLdltThreads, 0, s>>>(
      t, positions, pool, static_pivot, perturbed, perm, pivot_size, perm_offset);
  STRATA_CUDA_LAUNCH();
}

void LdltLarge::factor(cublasHandle_t blas, cudaStream_t s, double* f, std::int64_t m,
                       std::int64_t k, double static_pivot, std::int64_t* perm, int* pivot_size,
                       std::int64_t* perturbed) {
  if (k == 0) {
    STRATA_CUDA(cudaMemsetAsync(perturbed, 0, sizeof(std::int64_t), s));
    return;
  }
  const std::size_t need = static_cast<std::size_t>(m) * (kLdltPanel + 1);
  if (work_.size() < need) {
    STRATA_CUDA(cudaStreamSynchronize(s));  // the previous front's update may still read it
    work_.resize(need);
  }
  end_.resize(1);
  end_host_.resize(1);
  const double one = 1.0, minus_one = -1.0;
  std::int64_t j0 = 0;
  while (j0 < k) {
    ldlt_panel_kernel<<<1, kLdltThreads, 0, s>>>(f, m, k, j0, static_pivot, work_.data(), perm,
                                                 pivot_size, perturbed, end_.data());
    STRATA_CUDA_LAUNCH();
    STRATA_CUDA(cudaMemcpyAsync(end_host_.data(), end_.data(), sizeof(std::int64_t),
                                cudaMemcpyDeviceToHost, s));
    STRATA_CUDA(cudaStreamSynchronize(s));
    const std::int64_t e = end_host_.data()[0];
    if (e <= j0 || e > k) throw InternalError("LDLᵀ panel made no progress");
    if (e < m) {
      // F[e:m, e:m] (lower) −= L(e:m, j0:e) · W(e:m, 0:e−j0)ᵀ  (= L D Lᵀ, symmetric)
      const int n = static_cast<int>(m - e), w = static_cast<int>(e - j0), ld = static_cast<int>(m);
      STRATA_CUBLAS(cublasDsyrkx(blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, n, w, &minus_one,
                                 f + j0 * m + e, ld, work_.data() + e, ld, &one, f + e * m + e,
                                 ld));
    }
    j0 = e;
  }
}

}  // namespace strata::cuda
