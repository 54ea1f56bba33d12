// strata — the pivot block and the panel of large Cholesky fronts (those with at most
// Options::gpu_panel_kernel_max_pivots pivots), for all such fronts of a chunk at once:
// three launches per 64-column step (see kernels.cuh, launch_llt_panel).
//
// Why: cuSOLVER POTRF and cuBLAS TRSM are one library call per front, and at the shapes of
// the large fronts of a multifrontal factorization they run far below the device's peak,
// also side by side on several streams (bench_gpu_memory --parts kernels, bench/REPORT.md
// §4), and they are a large share of the time of the fronts over gpu_small_front_rows
// rows.
//
// How: the right-looking blocked Cholesky of the front's first k columns (Golub & Van Loan,
// "Matrix Computations", 4th ed., §4.2.9), in steps of kStep = 64 columns, each step one
// launch of each kernel over every front still active (items sorted by k, largest first, so
// the active fronts of a step are a prefix):
//   1. pivot_block_kernel, one block of 512 threads per front: the w×w diagonal block
//      (w ≤ 64) into registers, eight threads per row (row_lanes.cuh), unblocked
//      right-looking Cholesky there (the pivot row shared through shared memory, one
//      barrier per column), L_jj written back (lower triangle; the strict upper one is
//      left as it was, as POTRF leaves it) and its inverse L_jj⁻¹ (Gauss–Jordan on the
//      identity, in the same steps) into the front's 64×64 slot of the workspace. Its
//      time is the chain of 64 dependent steps, latency rather than arithmetic: eight
//      threads per row make each link shorter;
//   2. panel_kernel, one block per 64-row tile below the diagonal block: L_ij = A_ij·L_jj⁻ᵀ,
//      a 64×64×w product from shared memory, written in place (the tile is read whole
//      before it is written);
//   3. update_kernel, one block per 64×64 tile of the pivot columns right of the step:
//      A_ic −= L_ij·L_cjᵀ (rows i ≥ c only inside the pivot block).
// The contribution-block update (SYRK, where most flops are) stays a cuBLAS call per front.
// The panel by the inverse of the diagonal block, not by substitution, is how MAGMA's GPU
// TRSM works too (inverted diagonal blocks, then GEMMs); the error bound grows with
// κ(L_jj) (Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed., §14.2),
// which stays small for the 64×64 diagonal blocks of an SPD front. Both products run on the FP64
// tensor cores (WMMA, m8n8k4 in FP64). A non-positive pivot at column j sets
// info = j + 1 (cuSOLVER's convention) and every later launch leaves that front alone,
// the front then failing on the host as before.
#include <algorithm>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/kernels.cuh"
#include "numeric/cuda/row_lanes.cuh"
#include "numeric/cuda/tile_mma.cuh"

namespace strata::cuda {
namespace {

constexpr int kStep = tile::kEdge;        // columns per step, and the tile edge of the products
constexpr int kThreads = tile::kThreads;  // products: 8 warps, a 32×16 part of the tile each

__device__ std::int64_t imin(std::int64_t a, std::int64_t b) { return a < b ? a : b; }

struct Item {
  std::int64_t m, k, slot;
  double* F;
};

__device__ Item item(const DeviceTree& t, const std::int64_t* items, double* pool) {
  const std::int64_t pos = items[2 * blockIdx.x];
  const std::int64_t f = t.fronts[pos];
  return {t.n_rows[f], t.n_pivots[f], items[2 * blockIdx.x + 1], pool + t.pos_offset[pos]};
}

// Launch 1 of a step: one block of row_lanes::kThreads threads per front factors its w×w
// diagonal block at (j0, j0), held as row_lanes.cuh lays it out (eight threads per row).
// The block is made symmetric (its lower triangle mirrored) and row j is published at column j, one
// barrier a column: L(c, j) = A(j, c)/√A(j, j) for every c > j comes from the published row instead
// of from the column, and A(i, c) −= L(i, j)·L(c, j) is applied to the whole trailing block, so
// that the row published next is up to date; the two entries of a pair get the same product, so the
// block stays exactly symmetric and every entry of L is what the column-oriented elimination
// computes. Writes L_jj back (lower triangle; the strict upper one is left as it was, as POTRF
// leaves it) and L_jj⁻¹ to work[blockIdx.x] (64×64, entry (c, t) at t·64 + c, zero outside the w×w
// lower triangle), formed in the same 64 steps by Gauss–Jordan on the identity (X(j, ·) =
// (e_j − Σ_{k<j} L(j, k)·X(k, ·)) / L(j, j), each row's sum taken one step at a time), so
// that no chain of its own follows; info on a non-positive pivot.
__global__ void __launch_bounds__(row_lanes::kThreads)
    pivot_block_kernel(DeviceTree t, const std::int64_t* items, double* pool, double* work,
                       int* info, std::int64_t j0) {
  using row_lanes::kLanes;
  using row_lanes::kPad;
  using row_lanes::kPerThread;
  __shared__ double T[kStep * kPad];  // the block by rows (symmetric), then L
  __shared__ double R[4 * kStep];     // row j and z's row j at column j, by parity (below)
  const Item it = item(t, items, pool);
  if (j0 > 0 && info[it.slot] != 0) return;  // failed at an earlier step
  const int w = static_cast<int>(imin(kStep, it.k - j0));
  const std::int64_t m = it.m;
  double* D = it.F + j0 * m + j0;  // the diagonal block, leading dimension m
  const int tid = threadIdx.x, i = tid / kLanes, q = tid % kLanes;
  // the lower triangle read by columns (coalesced) and mirrored; zero outside w×w
  for (int e = tid; e < kStep * kStep; e += row_lanes::kThreads) {
    const int r = e % kStep, c = e / kStep;
    if (c <= r) {
      const double v = r < w ? D[static_cast<std::int64_t>(c) * m + r] : 0.0;
      T[r * kPad + c] = v;
      T[c * kPad + r] = v;
    }
  }
  __syncthreads();
  double a[kPerThread];  // row i, columns kLanes·s + q
#pragma unroll
  for (int s = 0; s < kPerThread; ++s) a[s] = T[i * kPad + kLanes * s + q];
  // Row j goes to R[(j mod 2)·128 …]: a buffer is written again two columns later, after
  // a barrier that every reader of it has passed.
  // z: row i of the identity, less the rows of L⁻¹ taken so far (Gauss–Jordan): at column
  // j, row j of L⁻¹ is z(j, ·)/L(j, j), and each row i > j takes L(i, j) times it
  double z[kPerThread];
#pragma unroll
  for (int s = 0; s < kPerThread; ++s) z[s] = kLanes * s + q == i ? 1.0 : 0.0;
  // columns j = kLanes·js + jq (row_lanes.cuh: only the loop over js unrolled)
  int fail = 0;
  bool stop = false;
#pragma unroll
  for (int js = 0; js < kPerThread; ++js) {
#pragma unroll 1
    for (int jq = 0; jq < kLanes; ++jq) {
      const int j = kLanes * js + jq;
      if (j >= w) {
        stop = true;
        break;
      }
      double* row = R + (j & 1) * 2 * kStep;  // A's row j, then z's
      if (i == j) {
#pragma unroll
        for (int s = 0; s < kPerThread; ++s) {
          row[kLanes * s + q] = a[s];
          row[kStep + kLanes * s + q] = z[s];
        }
      }
      __syncthreads();
      const double d = row[j];  // the same in every thread: a uniform break
      if (!(d > 0.0)) {
        fail = static_cast<int>(j0) + j + 1;
        stop = true;
        break;
      }
      const double ljj = sqrt(d), r = __drcp_rn(ljj);  // 1.0 / ljj, the same bits
      if (i == j) {
        if (q == jq) a[js] = ljj;
#pragma unroll
        for (int s = 0; s <= js; ++s) z[s] *= r;  // row j of L⁻¹ (columns up to j)
      }
      if (i > j && i < w) {
        const double l = row[i] * r;  // L(i, j)
        if (q == jq) a[js] = l;
        // the columns after j, then L⁻¹'s row j up to column j: only register column js
        // holds columns on both sides of j, the others need no per-lane test
        if (q > jq) a[js] -= l * (row[kLanes * js + q] * r);
#pragma unroll
        for (int s = js + 1; s < kPerThread; ++s) a[s] -= l * (row[kLanes * s + q] * r);
#pragma unroll
        for (int s = 0; s < js; ++s) z[s] -= l * (row[kStep + kLanes * s + q] * r);
        if (q <= jq) z[js] -= l * (row[kStep + kLanes * js + q] * r);
      }
    }
    if (stop) break;
  }
  if (tid == 0 && (j0 == 0 || fail)) info[it.slot] = fail;
  if (fail) return;
  __syncthreads();  // every thread done reading T's first contents
#pragma unroll
  for (int s = 0; s < kPerThread; ++s) T[i * kPad + kLanes * s + q] = a[s];
  __syncthreads();
  for (int e = tid; e < kStep * kStep; e += row_lanes::kThreads) {
    const int r = e % kStep, c = e / kStep;
    if (c <= r && r < w) D[static_cast<std::int64_t>(c) * m + r] = T[r * kPad + c];
  }
  // L_jj⁻¹ by columns: entry (c, t) = X(c, t) at t·64 + c, zero outside w×w
  double* W = work + static_cast<std::int64_t>(blockIdx.x) * kStep * kStep;
#pragma unroll
  for (int s = 0; s < kPerThread; ++s) {
    const int col = kLanes * s + q;
    W[col * kStep + i] = i < w && col < w ? z[s] : 0.0;
  }
}

// Launch 2 of a step: block (i, y) computes L_ij = A_ij·L_jj⁻ᵀ for rows j0 + w + 64y … of
// front i's columns j0 … j0 + w, in place.
__global__ void panel_kernel(DeviceTree t, const std::int64_t* items, double* pool,
                             const double* work, const int* info, std::int64_t j0) {
  const Item it = item(t, items, pool);
  const std::int64_t w = imin(kStep, it.k - j0);
  const std::int64_t r0 = j0 + w + static_cast<std::int64_t>(blockIdx.y) * kStep;
  if (r0 >= it.m || info[it.slot] != 0) return;  // the whole block leaves together
  const int rows = static_cast<int>(imin(kStep, it.m - r0));
  double* A = it.F + j0 * it.m + r0;
  __shared__ __align__(32) double sm[tile::kSharedDoubles];
  const double* C = tile::product<tile::BLayout::kBRows>(
      A, it.m, rows, work + static_cast<std::int64_t>(blockIdx.x) * kStep * kStep, kStep, kStep,
      static_cast<int>(w), sm);
  for (int x = threadIdx.x; x < kStep * kStep; x += kThreads) {
    const int r = x & 63, c = x >> 6;
    if (r < rows && c < w) A[static_cast<std::int64_t>(c) * it.m + r] = C[x];
  }
}

// Launch 3 of a step: block (i, y, z) updates the 64×64 tile at rows j0 + w + 64y …,
// columns j0 + w + 64z … (columns < k) of front i: A −= L_ij·L_cjᵀ, lower triangle only.
__global__ void update_kernel(DeviceTree t, const std::int64_t* items, double* pool,
                              const int* info, std::int64_t j0) {
  const Item it = item(t, items, pool);
  const std::int64_t w = imin(kStep, it.k - j0);
  const std::int64_t r0 = j0 + w + static_cast<std::int64_t>(blockIdx.y) * kStep;
  const std::int64_t c0 = j0 + w + static_cast<std::int64_t>(blockIdx.z) * kStep;
  if (r0 >= it.m || c0 >= it.k || r0 + kStep <= c0 || info[it.slot] != 0) return;
  const int rows = static_cast<int>(imin(kStep, it.m - r0));
  const int cols = static_cast<int>(imin(kStep, it.k - c0));
  const double* P = it.F + j0 * it.m;  // the step's panel columns
  __shared__ __align__(32) double sm[tile::kSharedDoubles];
  const double* T = tile::product<tile::BLayout::kBRows>(P + r0, it.m, rows, P + c0, it.m, cols,
                                                         static_cast<int>(w), sm);
  double* C = it.F + c0 * it.m + r0;
  for (int x = threadIdx.x; x < kStep * kStep; x += kThreads) {
    const int r = x & 63, c = x >> 6;
    if (r < rows && c < cols && r0 + r >= c0 + c)
      C[static_cast<std::int64_t>(c) * it.m + r] -= T[x];
  }
}

unsigned tiles(std::int64_t n) {
  return static_cast<unsigned>(std::max<std::int64_t>(1, (n + kStep - 1) / kStep));
}

}  // namespace

std::size_t llt_panel_work_size(std::int64_t count) {
  return static_cast<std::size_t>(count) * kStep * kStep;
}

void launch_llt_panel(const DeviceTree& t, const std::int64_t* items,
                      const std::vector<std::int64_t>& rows,
                      const std::vector<std::int64_t>& pivots, double* pool, double* work,
                      int* info, cudaStream_t s) {
  const std::size_t count = pivots.size();
  if (count == 0) return;
  // per step: the active prefix (k > j0) and its most rows
  std::vector<std::int64_t> max_rows(count);
  for (std::size_t i = 0; i < count; ++i) max_rows[i] = std::max(rows[i], i ? max_rows[i - 1] : 0);
  std::size_t active = count;
  for (std::int64_t j0 = 0; j0 < pivots[0]; j0 += kStep) {
    while (active > 0 && pivots[active - 1] <= j0) --active;
    const unsigned n = static_cast<unsigned>(active);
    const std::int64_t below = max_rows[active - 1] - j0;  // rows at and below the step
    pivot_block_kernel<<<n, row_lanes::kThreads, 0, s>>>(t, items, pool, work, info, j0);
    STRATA_CUDA_LAUNCH();
    panel_kernel<<<dim3(n, tiles(below)), kThreads, 0, s>>>(t, items, pool, work, info, j0);
    STRATA_CUDA_LAUNCH();
    if (pivots[0] - j0 > kStep) {
      update_kernel<<<dim3(n, tiles(below), tiles(pivots[0] - j0 - kStep)), kThreads, 0, s>>>(
          t, items, pool, info, j0);
      STRATA_CUDA_LAUNCH();
    }
  }
}

}  // namespace strata::cuda
