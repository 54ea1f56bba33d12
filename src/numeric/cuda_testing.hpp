// strata — entry points into the CUDA executor's kernels for tests (not used by the
// solver itself): each runs one kernel family on device 0 on host data, so that the tests
// can check its result against the CPU's (tests/gpu/). In a build without CUDA each throws
// NotSupported (numeric/backends.cpp).
#pragma once

#include <memory>
#include <vector>

#include "strata/types.hpp"

namespace strata::numeric {

/// The pivot block and panel of one Cholesky front on CUDA device 0, by the CUDA
/// executor's recursive method (numeric/cuda/llt_recursive.cu), so that tests can check
/// that kernel against the CPU's factor_front_llt: `f` (host) is m × m, column-major,
/// leading dimension m, lower triangle; its first k columns become L₁₁ and L₂₁ with the
/// strict upper triangle of the k × k pivot block set to zero (as the executor's fronts
/// have it), the contribution block is left as it was. Returns -1,
/// or the local index (0..k-1) of the first pivot that is not positive, as
/// factor_front_llt does. Throws NotSupported in a build without CUDA.
index_t cuda_llt_pivot_block_and_panel(double* f, index_t m, index_t k);

/// The CUDA executor's contribution-block update of a Cholesky front on device 0
/// (numeric/cuda/llt_update.cu), so that tests can check it: `c` (host, n × n,
/// column-major, leading dimension n) gets c −= l·lᵀ on its lower triangle, `l` (host) is
/// n × k with leading dimension n; c's strict upper triangle is scratch afterwards.
/// Returns whether the update was one DGEMM (else cuBLAS DSYRK). Throws InvalidInput for
/// n < 1 or k < 1, NotSupported in a build without CUDA.
bool cuda_llt_update(double* c, const double* l, index_t n, index_t k);

/// The packing of a symmetric block's lower triangle for its transfer between ranks and
/// its unpacking (numeric/cuda/triangle_pack.cu) on device 0, so that tests can check them:
/// returns the packed lower triangle of `a` (host, m × m, column-major; m(m+1)/2 doubles,
/// column j's rows j … m − 1 in order) and sets `full` (m × m) to its unpacking, both
/// triangles from the lower one. Throws InvalidInput for m < 0, NotSupported in a build
/// without CUDA.
std::vector<double> cuda_pack_and_unpack_lower(const double* a, index_t m,
                                               std::vector<double>& full);

/// The gathering and scattering of values by position that distributed ranks use for
/// their shares of the scaled values (numeric/cuda/value_positions.cu) on device 0, so that
/// tests can check them: returns values[pos[k]] for each k and sets `scattered` (as long as
/// `values`, zero elsewhere) to those gathered values put back at pos. Throws InvalidInput
/// for a position outside `values`, NotSupported in a build without CUDA.
std::vector<double> cuda_gather_and_scatter_positions(const std::vector<double>& values,
                                                      const std::vector<index_t>& pos,
                                                      std::vector<double>& scattered);

/// The CUDA executor's LU of large fronts without row interchanges on device 0
/// (numeric/cuda/lu_fronts.cu, enqueue_lu_strips: strips of `strip` pivot columns whose
/// pivot blocks and panels come from the batched kernels of kernels_lu_panel.cu, all fronts
/// together, the rest of each strip's update and the contribution block's by cuBLAS DGEMM),
/// so that tests can check it against the CPU's factor_front_lu. fronts[i] (host) is
/// m[i] × m[i], column-major, leading dimension m[i], k[i] fully summed rows and columns
/// (1 ≤ k[i] ≤ m[i]). A front of one 64-column step and one strip (k ≤ 64, k ≤ strip) is
/// factored with restricted threshold partial pivoting (u = threshold, in (0, 1]) by the
/// kernels; the others without interchanges. Returns, per front, 1 when it was kept — every
/// pivot finite with magnitude at least static_pivot and, without interchanges, the
/// factor_front_lu rule with u = threshold would have interchanged no row — and 0 when it
/// was rejected. A kept front comes back as
/// factor_front_lu leaves it (L11 unit lower, U11, L21, U12, the Schur complement in its
/// contribution block), with its local permutation in (*perms)[i] when perms is given (the
/// identity for a front factored without interchanges); a rejected one is partly factored.
/// `lookahead`: the strips' pivot blocks run one step ahead on a side stream, as the CUDA
/// executor runs them (launch_lu_panel_batched's LuLookahead). Throws InvalidInput for
/// inconsistent sizes or strip < 1, NotSupported in a build without CUDA.
std::vector<char> cuda_lu_fronts_batched(std::vector<std::vector<double>>& fronts,
                                         const std::vector<index_t>& m,
                                         const std::vector<index_t>& k, index_t strip,
                                         double static_pivot, double threshold,
                                         std::vector<std::vector<index_t>>* perms = nullptr,
                                         bool lookahead = false);

/// divide_rn (numeric/cuda/divide.cuh), the quotient of the elimination kernels that divide,
/// on CUDA device 0 for each pair (x[i], d[i]), so that tests can check it against the
/// host's IEEE division bit for bit. Throws InvalidInput when x and d differ in length,
/// NotSupported in a build without CUDA.
std::vector<double> cuda_divide_rn(const std::vector<double>& x, const std::vector<double>& d);
/// PivotReciprocal (numeric/cuda/divide.cuh), the elimination kernels' multipliers x / d as
/// x · (1/d), on CUDA device 0 for each pair; errors as cuda_divide_rn.
std::vector<double> cuda_pivot_reciprocal(const std::vector<double>& x,
                                          const std::vector<double>& d);

/// y + alpha·A·x by the device solve's GEMV (cuda::launch_gemv_n) on CUDA device 0, for A
/// rows × cols column-major with leading dimension lda ≥ max(rows, 1) (a.size() ≥
/// lda·cols), x of cols entries and y of rows, so that tests can check it against the
/// host. Throws InvalidInput for inconsistent sizes, NotSupported in a build without CUDA.
std::vector<double> cuda_gemv_n(index_t rows, index_t cols, double alpha,
                                const std::vector<double>& a, index_t lda,
                                const std::vector<double>& x, std::vector<double> y);

/// x ← op(A)⁻¹ x by the device solve's tiled triangular solve (cuda::launch_trsv_inverses,
/// then cuda::launch_trsv_tiles, twice, so that the second run starts from the flags the
/// first left) on CUDA device 0: op(A) the lower (form 0), upper (1) or transposed lower
/// (2) triangle of the n × n A (column-major, leading dimension lda ≥ max(n, 1),
/// a.size() ≥ lda·n), with a unit diagonal when `unit`; x of n entries. Throws
/// InvalidInput for inconsistent arguments, NotSupported in a build without CUDA.
std::vector<double> cuda_trsv_tiles(int form, bool unit, index_t n, const std::vector<double>& a,
                                    index_t lda, std::vector<double> x);

/// The threads per block the small-front kernels get on CUDA device 0 for a launch of
/// `count` fronts of at most max_rows rows (1 ≤ max_rows ≤ 256) under
/// Options::gpu_small_front_threads = max_threads (numeric/cuda/kernels.cu), with each
/// front copied into shared memory (`shared`: LU fronts that fit it) or not, so that tests
/// can see which width a factorization used. Throws InvalidInput for count < 1 or max_rows
/// outside [1, 256], NotSupported in a build without CUDA.
int cuda_small_front_threads(index_t count, index_t max_rows, int max_threads, bool shared = false);

/// The most rows of a front that a launch group assembled, factored and stored by one
/// launch in shared memory (Options::gpu_fused_small_batches) may have on CUDA device 0,
/// for LU (lu) or Cholesky (a Cholesky front is held as its packed lower triangle, so it
/// fits larger fronts), so that tests can tell which fronts are fused; 0 when none fits.
/// Throws NotSupported in a build without CUDA.
index_t cuda_fused_front_max_rows(bool lu);

/// A copy of `host` in device memory of CUDA device 0 (cudaMalloc), freed with the last
/// owner, so that tests can give the solver values that live on the GPU. Throws
/// DeviceError, NotSupported in a build without CUDA or without a GPU.
std::shared_ptr<double> cuda_device_copy(const std::vector<double>& host);

}  // namespace strata::numeric
