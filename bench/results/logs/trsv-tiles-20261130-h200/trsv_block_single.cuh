// strata — a dense triangular solve with one right-hand side by one thread block, for the
// library-path fronts of the device solve (cuda_solve.cu: DeviceOps::trsv).
//
// What: x ← op(A)⁻¹ x for the n × n triangle of a column-major A (leading dimension lda,
// device pointers), n ≤ kTrsvMaxOrder, in three forms: lower (the forward sweep's L11,
// unit for LU and LDLᵀ), upper (LU's backward U11) and lower transposed (the backward
// sweep's L11ᵀ of LLᵀ and LDLᵀ).
//
// Why: a front's triangle is a chain of dependent steps. A library TRSV splits it over
// several thread blocks that hand each 32 solved unknowns to the next through global
// memory (about 1.8 µs per step on an H200: 58 µs for a front of 1,024 pivots); here the
// whole triangle stays in one block, the unknowns in shared memory, so a step costs a
// barrier instead.
//
// How (the column-oriented substitution of Golub & Van Loan, "Matrix Computations", 4th
// ed., §3.1, by blocks of kTrsvTile unknowns): thread r owns equation r. Step k solves the
// k-th tile of unknowns in the order of the substitution (forward for lower, backward for
// the other two): the warp holding that tile's equations solves its triangle (a kTrsvTile
// × kTrsvTile block in shared memory, one unknown per shuffle), then every later equation
// subtracts the tile's contribution with the coefficients it loaded one step earlier, so
// that the loads run while the previous triangle is being solved. Meanwhile another warp
// loads the next tile's triangle. One barrier per step. The sums run in a fixed order, so
// the result is the same at every run; it is not the bits of a library TRSV.
#pragma once

#include <cstdint>

namespace strata::cuda::trsv_block {

/// The largest order solved by one block (a thread per equation).
constexpr int kTrsvMaxOrder = 1024;
/// Unknowns per step (the triangle a warp solves); 16 keeps a thread's prefetched
/// coefficients within the registers a block of 1,024 threads allows.
constexpr int kTrsvTile = 16;

/// Which triangle and operation: op(A) lower (A's lower triangle), upper (A's upper
/// triangle), or lower transposed (the transpose of A's lower triangle, an upper one).
enum class TrsvForm : int { lower, upper, lower_transposed };

/// The coefficient of unknown c in equation r of op(A).
template <TrsvForm F>
__device__ __forceinline__ double trsv_coef(const double* __restrict__ a, std::int64_t lda, int r,
                                            int c) {
  return F == TrsvForm::lower_transposed ? a[c + static_cast<std::int64_t>(r) * lda]
                                         : a[r + static_cast<std::int64_t>(c) * lda];
}

/// The kernel: one block of 32·⌈n/32⌉ threads (at most kTrsvMaxOrder), x of n entries.
template <TrsvForm F, bool Unit>
__global__ void __launch_bounds__(kTrsvMaxOrder, 1)
    trsv_block_kernel(int n, const double* __restrict__ a, std::int64_t lda, double* x) {
  constexpr int T = kTrsvTile;
  constexpr bool forward = F == TrsvForm::lower;
  __shared__ double xs[kTrsvMaxOrder];
  __shared__ double tri[2][T][T + 1];  // a tile's triangle: tri[i][j] = coef(base+i, base+j)
  __shared__ double rdiag[2][T];       // 1 / its diagonal (1 for a unit triangle)
  const int r = static_cast<int>(threadIdx.x), lane = r % 32, warp = r / 32;
  const int warps = static_cast<int>(blockDim.x) / 32, tiles = (n + T - 1) / T;
  auto tile_at = [&](int k) { return forward ? k : tiles - 1 - k; };
  // equation r takes tile t's unknowns after they are solved
  auto after = [&](int t) { return r < n && (forward ? r >= (t + 1) * T : r < t * T); };
  // tile t's triangle into buffer b, by one warp: lane (i, q) with i = lane % T
  auto load_triangle = [&](int t, int b) {
    const int base = t * T, i = lane % T;
    for (int q = lane / T; q < T; q += 32 / T) {
      const bool in = base + i < n && base + q < n;
      const double v = in ? a[(base + i) + static_cast<std::int64_t>(base + q) * lda] : 0.0;
      if (F == TrsvForm::lower_transposed)
        tri[b][q][i] = v;  // coef(base + q, base + i)
      else
        tri[b][i][q] = v;  // coef(base + i, base + q)
    }
    if (lane < T)
      rdiag[b][lane] = Unit || base + lane >= n
                           ? 1.0
                           : 1.0 / a[(base + lane) + static_cast<std::int64_t>(base + lane) * lda];
  };
  double c[T];  // equation r's coefficients of the next tile's unknowns
  auto load_coefficients = [&](int t) {
    const int base = t * T;
#pragma unroll
    for (int j = 0; j < T; ++j) c[j] = base + j < n ? trsv_coef<F>(a, lda, r, base + j) : 0.0;
  };

  xs[r] = r < n ? x[r] : 0.0;  // zeros past n: a last partial tile adds nothing
  {
    const int t0 = tile_at(0);
    if (warp == t0 * T / 32) load_triangle(t0, 0);
    if (after(t0)) load_coefficients(t0);
  }
  __syncthreads();
  for (int k = 0; k < tiles; ++k) {
    const int t = tile_at(k), b = k & 1, base = t * T, owner = base / 32;
    if (warp == owner) {  // the tile's triangle: lanes [h, h + T) of the owning warp
      const int h = base % 32, il = lane - h;
      double v = il >= 0 && il < T && base + il < n ? xs[base + il] : 0.0;
#pragma unroll
      for (int s = 0; s < T; ++s) {
        const int j = forward ? s : T - 1 - s;
        if (il == j) v *= rdiag[b][j];
        const double xj = __shfl_sync(0xffffffffu, v, h + j);
        if (il >= 0 && il < T && (forward ? il > j : il < j)) v -= tri[b][il][j] * xj;
      }
      if (il >= 0 && il < T && base + il < n) xs[base + il] = v;
    }
    const int loader = warps > 1 ? (owner + 1) % warps : owner;
    if (k + 1 < tiles && warp == loader) load_triangle(tile_at(k + 1), b ^ 1);
    __syncthreads();
    if (after(t)) {  // this tile's contribution to equation r, in a fixed order
      double acc0 = 0.0, acc1 = 0.0;
#pragma unroll
      for (int j = 0; j < T; j += 2) {
        acc0 += c[j] * xs[base + j];
        acc1 += c[j + 1] * xs[base + j + 1];
      }
      xs[r] -= acc0 + acc1;
    }
    if (k + 1 < tiles && after(tile_at(k + 1))) load_coefficients(tile_at(k + 1));
  }
  __syncthreads();
  if (r < n) x[r] = xs[r];
}

}  // namespace strata::cuda::trsv_block
