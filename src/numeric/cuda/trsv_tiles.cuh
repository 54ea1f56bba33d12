// strata — a dense triangular solve with one right-hand side over several thread blocks,
// each tile of unknowns solved by a product with its diagonal block's inverse; for the
// library-path fronts of the device solve (cuda_solve.cu: DeviceOps::trsv).
//
// What: x ← op(A)⁻¹ x for the n × n triangle of a column-major A (leading dimension lda,
// device pointers) in three forms: lower (the forward sweep's L11, unit for LU and LDLᵀ),
// upper (LU's backward U11) and lower transposed (the backward sweep's L11ᵀ of LLᵀ and
// LDLᵀ). The unknowns are cut into tiles of kTrsvTile; trsv_inverse_kernel first writes,
// for every tile t, the inverse of op(A)'s diagonal block of that tile, and
// trsv_tiles_kernel then solves with them.
//
// Why: a triangle is a chain of dependent steps. A library TRSV hands 32 solved unknowns
// at a time from one thread block to the next through global memory, and each hand-over
// costs a round trip through L2. With the diagonal blocks' inverses a step is a
// matrix–vector product, so a block takes 64 unknowns per step in about the time of one
// hand-over: half the steps, and none of them a chain inside the block (the measurements
// are in bench/history.md, "The library fronts' triangles by tiles").
//
// How: the blocked column substitution (Golub & Van Loan, "Matrix Computations", 4th ed.,
// §3.1) with inverted diagonal blocks, as in the block-inverse triangular solves of the
// dense GPU libraries. Block t (taken in order from an atomic ticket, so that every block it
// waits for is already running) solves tile t: for each earlier tile j in the order of the
// substitution it loads its coefficients of tile j's unknowns, waits for tile j's flag,
// reads x_j through L2 and accumulates; then x_t = inv_t · (b_t − Σ_j A_tj x_j), written
// back, a fence, its flag. Each warp waits on the flags itself (no barrier while loads are
// in flight). The last block to finish clears the flags and the ticket for the next launch
// (so that a recorded graph can replay the kernel). Sums run in a fixed order: the same
// result at every run, not the bits of a library TRSV.
//
// The inverses: a block per tile, a thread per column j of the inverse, which solves
// op(A)_tt m = e_j by right-looking substitution with the tile in shared memory and m in
// registers (Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed., §14.2:
// the column-by-column inversion of a triangular matrix). A tile's inverse is as accurate
// as its condition allows; the fronts' pivoting keeps the triangles' multipliers bounded,
// and the solve's refinement sees the rest.
#pragma once

#include <cstdint>

namespace strata::cuda::trsv_tiles {

/// Which triangle and operation: op(A) lower (A's lower triangle), upper (A's upper
/// triangle), or lower transposed (the transpose of A's lower triangle, an upper one).
enum class TrsvForm : int { lower, upper, lower_transposed };

/// The coefficient of unknown c in equation r of op(A).
template <TrsvForm F>
__device__ __forceinline__ double coef(const double* __restrict__ a, std::int64_t lda,
                                       std::int64_t r, std::int64_t c) {
  return F == TrsvForm::lower_transposed ? a[c + r * lda] : a[r + c * lda];
}

/// The flags, ticket and counter of one triangle's launch: zero before the first launch;
/// each launch leaves them zero.
struct TrsvSync {
  int* flags;   ///< one per tile: 1 once its unknowns are in x
  int* ticket;  ///< the next tile to take, in the order of the substitution
  int* done;    ///< blocks finished
};

/// Unknowns per tile (per step of the substitution).
constexpr int kTrsvTile = 64;
/// Threads of a solve block: four column groups of kTrsvTile / 4 per row.
constexpr int kTrsvThreads = 4 * kTrsvTile;

/// One tile's inverse to make: op(A)'s diagonal block of unknowns [t·kTrsvTile, +kTrsvTile)
/// of the n × n triangle at panels + panel, leading dimension lda, into the kTrsvTile²
/// doubles at inverses + out (column-major, zero past n).
struct TrsvTileJob {
  std::int64_t panel, lda, n, t, out;
};

/// The inverses: a block of kTrsvTile threads per job.
template <TrsvForm F, bool Unit>
__global__ void __launch_bounds__(kTrsvTile)
    trsv_inverse_kernel(const TrsvTileJob* __restrict__ jobs, const double* __restrict__ panels,
                        double* __restrict__ inverses) {
  constexpr int T = kTrsvTile;
  constexpr bool forward = F == TrsvForm::lower;
  __shared__ double tile[T][T + 1];  // tile[r][c] = coef(base + r, base + c), then m
  __shared__ double rdiag[T];
  const TrsvTileJob job = jobs[blockIdx.x];
  const double* a = panels + job.panel;
  const int j = static_cast<int>(threadIdx.x);
  const std::int64_t base = job.t * T;
  const std::int64_t left = job.n - base;
  const int rows = left < T ? static_cast<int>(left) : T;
  for (int r = 0; r < T; ++r) {  // consecutive threads read consecutive entries of A
    const bool in = r < rows && j < rows;
    if (F == TrsvForm::lower_transposed)
      tile[r][j] = in ? coef<F>(a, job.lda, base + r, base + j) : 0.0;
    else
      tile[j][r] = in ? coef<F>(a, job.lda, base + j, base + r) : 0.0;
  }
  __syncthreads();
  rdiag[j] = Unit || j >= rows ? 1.0 : 1.0 / tile[j][j];
  __syncthreads();
  double m[T];
#pragma unroll
  for (int r = 0; r < T; ++r) m[r] = r == j ? 1.0 : 0.0;
#pragma unroll
  for (int s = 0; s < T; ++s) {  // unknown r of the substitution, then its column's update
    const int r = forward ? s : T - 1 - s;
    m[r] *= rdiag[r];
#pragma unroll
    for (int q = 0; q < T; ++q)
      if (forward ? q > r : q < r) m[q] -= tile[q][r] * m[r];
  }
  __syncthreads();
#pragma unroll
  for (int r = 0; r < T; ++r) tile[r][j] = m[r];
  __syncthreads();
  double* out = inverses + job.out;
  for (int e = j; e < T * T; e += T) out[e] = tile[e % T][e / T];
}

/// The solve: ⌈n/kTrsvTile⌉ blocks of kTrsvThreads threads; `inv` the inverses of the
/// triangle's tiles, kTrsvTile² doubles each in tile order.
template <TrsvForm F>
__global__ void __launch_bounds__(kTrsvThreads)
    trsv_tiles_kernel(int n, const double* __restrict__ a, std::int64_t lda, double* x,
                      const double* __restrict__ inv, TrsvSync sync) {
  constexpr int T = kTrsvTile, G = 4, CG = T / G;
  constexpr bool forward = F == TrsvForm::lower;
  __shared__ int s_tile;
  __shared__ double part[G][T + 1];
  __shared__ double rhs[T];
  const int tid = static_cast<int>(threadIdx.x), i = tid % T, g = tid / T, lane = tid % 32;
  const int tiles = (n + T - 1) / T;
  if (tid == 0) s_tile = atomicAdd(sync.ticket, 1);
  __syncthreads();
  const int k = s_tile, t = forward ? k : tiles - 1 - k, base = t * T;
  const int rows = min(T, n - base);
  // this thread's part of inv_t: row i, columns [g·CG, g·CG + CG)
  double m[CG];
  const double* it = inv + static_cast<std::int64_t>(t) * T * T;
#pragma unroll
  for (int q = 0; q < CG; ++q) m[q] = it[i + (g * CG + q) * T];
  double acc = 0.0;
  for (int s = 0; s < k; ++s) {
    const int j = forward ? s : tiles - 1 - s, jb = j * T, cols = min(T, n - jb);
    double c[CG];
#pragma unroll
    for (int q = 0; q < CG; ++q) {
      const int col = g * CG + q;
      c[q] = i < rows && col < cols ? coef<F>(a, lda, base + i, jb + col) : 0.0;
    }
    if (lane == 0)
      while (*reinterpret_cast<volatile int*>(sync.flags + j) == 0) {
      }
    __syncwarp();
#pragma unroll
    for (int q = 0; q < CG; ++q) {
      const int col = g * CG + q;
      if (col < cols) acc += c[q] * __ldcg(x + jb + col);
    }
  }
  part[g][i] = acc;
  __syncthreads();
  if (g == 0) {
    double sum = i < rows ? __ldcg(x + base + i) : 0.0;
    for (int q = 0; q < G; ++q) sum -= part[q][i];
    rhs[i] = sum;
  }
  __syncthreads();
  double y = 0.0;
#pragma unroll
  for (int q = 0; q < CG; ++q) y += m[q] * rhs[g * CG + q];
  part[g][i] = y;
  __syncthreads();
  if (g == 0 && i < rows) {
    double sum = 0.0;
    for (int q = 0; q < G; ++q) sum += part[q][i];
    x[base + i] = sum;
  }
  __threadfence();
  __syncthreads();
  if (tid == 0) {
    atomicExch(sync.flags + t, 1);
    if (atomicAdd(sync.done, 1) == tiles - 1) {  // the last block: clear for the next launch
      for (int q = 0; q < tiles; ++q) sync.flags[q] = 0;
      *sync.ticket = 0;
      *sync.done = 0;
      __threadfence();
    }
  }
}

}  // namespace strata::cuda::trsv_tiles
