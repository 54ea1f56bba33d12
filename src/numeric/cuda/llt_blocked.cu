// strata — the pivot block and panel of a large Cholesky front, by column blocks.
//
// A front F (m × m, column-major, lower triangle) with k pivots needs L₁₁ = chol(F₁₁)
// and L₂₁ = F₂₁ L₁₁⁻ᵀ before the update of its contribution block. One cuSOLVER POTRF of
// order k and one cuBLAS TRSM of (m−k) × k do that, but at the sizes of separator fronts
// both run far below the GPU's DGEMM rate, and the pivot block and panel take longer than
// the update (bench/REPORT.md, "Dense kernels at the shapes of large fronts").
//
// Here the k pivot columns go in blocks of nb, right-looking (the blocked Cholesky of
// LAPACK's DPOTRF, Golub & Van Loan, Matrix Computations, 4th ed., §4.2.9, applied to
// the m × k panel): for the block of columns [j, j+b),
//   1. POTRF of the diagonal block F[j:j+b, j:j+b] (cuSOLVER),
//   2. TRSM of the rows below it, F[j+b:m, j:j+b] ← F[j+b:m, j:j+b] L⁻ᵀ (cuBLAS),
//   3. the remaining pivot columns updated by the block: SYRK of the diagonal part
//      F[j+b:k, j+b:k] and GEMM of the rows below the pivots, F[k:m, j+b:k].
// Most of the flops (the (m−k)·k²/2 of the panel) move from TRSM into GEMM, and the
// solves are nb wide. The result is the same factor (same operations, another order of
// summation). Each block's POTRF reports to its own slot; one thread then writes the
// front's status as one POTRF of order k would: 0, or the 1-based order of the first
// leading minor that is not positive definite.
#include <algorithm>

#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {
namespace {

__global__ void first_failed_block_kernel(const int* block_info, int nblocks, int nb, int* info) {
  int r = 0;
  for (int b = 0; b < nblocks; ++b)
    if (block_info[b] != 0) {
      r = block_info[b] > 0 ? b * nb + block_info[b] : block_info[b];
      break;
    }
  *info = r;
}

}  // namespace

void llt_pivot_block_and_panel(Lane& ln, double* F, int m, int k, int nb, int* info) {
  const double one = 1.0, minus_one = -1.0;
  const std::size_t ld = static_cast<std::size_t>(m);
  if (nb <= 0 || nb >= k) {  // one POTRF and one TRSM
    grow_potrf_work(ln.solver, ln.potrf_work, F, k, m);
    STRATA_CUSOLVER(cusolverDnDpotrf(ln.solver, CUBLAS_FILL_MODE_LOWER, k, F, m,
                                     ln.potrf_work.data(), static_cast<int>(ln.potrf_work.size()),
                                     info));
    if (m > k)
      STRATA_CUBLAS(cublasDtrsm(ln.blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                                CUBLAS_DIAG_NON_UNIT, m - k, k, &one, F, m, F + k, m));
    return;
  }
  const int nblocks = (k + nb - 1) / nb;
  ln.block_info.resize(static_cast<std::size_t>(nblocks));
  grow_potrf_work(ln.solver, ln.potrf_work, F, nb, m);
  for (int b = 0; b < nblocks; ++b) {
    const int j = b * nb, w = std::min(nb, k - j);
    double* Fjj = F + j * ld + j;
    STRATA_CUSOLVER(cusolverDnDpotrf(ln.solver, CUBLAS_FILL_MODE_LOWER, w, Fjj, m,
                                     ln.potrf_work.data(), static_cast<int>(ln.potrf_work.size()),
                                     ln.block_info.data() + b));
    const int below = m - j - w;  // rows under the diagonal block
    if (below == 0) continue;
    STRATA_CUBLAS(cublasDtrsm(ln.blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                              CUBLAS_DIAG_NON_UNIT, below, w, &one, Fjj, m, Fjj + w, m));
    const int rest = k - j - w;  // pivot columns right of the block
    if (rest == 0) continue;
    const double* Lr = Fjj + w;  // rows j+w.. of the block's columns
    double* Frr = F + (j + w) * ld + (j + w);
    STRATA_CUBLAS(cublasDsyrk(ln.blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, rest, w, &minus_one, Lr,
                              m, &one, Frr, m));
    if (m > k)
      STRATA_CUBLAS(cublasDgemm(ln.blas, CUBLAS_OP_N, CUBLAS_OP_T, m - k, rest, w, &minus_one,
                                Fjj + (k - j), m, Lr, m, &one, Frr + rest, m));
  }
  first_failed_block_kernel<<<1, 1, 0, ln.stream>>>(ln.block_info.data(), nblocks, nb, info);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
