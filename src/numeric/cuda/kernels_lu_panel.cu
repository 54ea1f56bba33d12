// strata — the pivot block, the L panel and the U panel of a strip of large LU fronts
// (Options::gpu_lu_strip_pivots pivot columns; lu_fronts.cu cuts the fronts into strips),
// for all the chunk's fronts with pivots in that strip at once, without row interchanges:
// three launches per 64-column step, or five with the look-ahead (see kernels.cuh,
// launch_lu_panel_batched).
//
// Why: the library path (kernels_lu.cu) is one cuSOLVER GETRF of the k×k fully summed
// block A11 and two cuBLAS TRSMs (L21 = A21·U11⁻¹, U12 = L11⁻¹·A12) per front, and at
// the shapes of a multifrontal LU those run far below the device's rate: under Nsight
// Compute GETRF and the two TRSMs take most of the kernel time, the contribution-block
// GEMM, where most flops are, a small share (bench/history.md has the profile).
//
// How: the right-looking blocked LU of the strip without pivoting (Golub & Van Loan,
// "Matrix Computations", 4th ed., §3.2.11), in steps of 64 columns,
// each step one launch of each kernel over every front still active (items sorted by k,
// largest first, so the active fronts of a step are a prefix):
//   1. lu_pivot_block_kernel, one block of 512 threads per front: the w×w diagonal block
//      (w ≤ 64) into registers, eight threads per row, unblocked LU (row j published
//      through shared memory, one barrier per column), the block written back (L unit
//      lower, U upper), and the inverses L_jj⁻¹ and U_jj⁻¹ into the front's two 64×64
//      slots of the workspace, formed during the elimination (L⁻¹ by Gauss–Jordan on the
//      identity in the rows still being eliminated, U⁻¹ column by column in the rows done
//      with); after interchanges by substitution on the identity, both at once on half the
//      threads each. Its time is the chain of 64 dependent steps, latency rather than
//      arithmetic: eight threads per row make each link shorter;
//   2. lu_panels_kernel, one block per 64-row tile below the diagonal block, L_ij =
//      A_ij·U_jj⁻¹, and one per 64-column tile right of it, U_jc = L_jj⁻¹·A_jc — the U
//      panel over every column of the front, so that the last step leaves U12 complete;
//   3. lu_update_kernel, one block per 64×64 tile of the trailing part of the strip's
//      L-shaped region: A_rc −= L_rj·U_jc where r < k or c < k, k the strip's pivots
//      (the rest, r ≥ k and c ≥ k, is the caller's: GEMMs per front, lu_fronts.cu).
// A step's pivot block is the chain's slow link, and the next one needs only the first
// tiles of this step's two panels and the trailing diagonal tile: with a look-ahead stream
// (LuLookahead) those go first, then the next pivot block runs beside the rest of the
// step's panels and update; the inverses are kept in two pairs of slots by the step's
// parity, so that it does not overwrite those the rest of the step reads.
// The products run on the FP64 tensor cores (tile_mma.cuh). Panels by the inverses of the
// 64×64 diagonal blocks, as MAGMA's GPU TRSM does; the error bound grows with κ(U_jj) and
// κ(L_jj) (Higham, "Accuracy and Stability of Numerical Algorithms", 2nd ed., §14.2),
// which the check below keeps bounded: |L| ≤ 1/u in the fully summed rows.
//
// Restricted threshold partial pivoting (the CPU kernel's rule, numeric/cpu/
// dense_front.cpp, with u = Options::diagonal_pivot_threshold) keeps the diagonal of column j when
// |a_jj| ≥ u·|a_ij| for every fully summed row i of j..kc−1, else takes the largest
// magnitude among them; it interchanges nothing exactly when every multiplier L(i, j),
// j < i < kc, has u·|L(i, j)| ≤ 1. The kernels check that (and that every pivot is finite
// with |U(j, j)| at least the static-pivot threshold) and set bad[item] on the first
// violation; every later launch leaves that front alone, and the caller factors it again
// from its assembled values by the pivoting path. So a front this path keeps is the one
// the CPU's pivoting would have produced, in another order of summation.
#include <algorithm>
#include <cfloat>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/divide.cuh"
#include "numeric/cuda/kernels.cuh"
#include "numeric/cuda/row_lanes.cuh"
#include "numeric/cuda/tile_mma.cuh"
#include "numeric/cuda/warp_argmax.cuh"

namespace strata::cuda {
namespace {

constexpr int kStep = tile::kEdge;        // columns per step, and the tile edge
constexpr int kSlot = kStep * kStep;      // one inverse in the workspace
constexpr int kThreads = tile::kThreads;  // the product kernels

__device__ std::int64_t imin(std::int64_t a, std::int64_t b) { return a < b ? a : b; }
__host__ __device__ std::int64_t tiles_of(std::int64_t n) {
  return n > 0 ? (n + kStep - 1) / kStep : 0;
}

// Where item b's two inverses of the step at pivot j0 live in the workspace: two pairs of
// slots per item, by the parity of the step, so that the next step's pivot block (run
// ahead, launch_lu_panel_batched) does not overwrite the inverses this step's panels read.
__host__ __device__ std::int64_t inverse_slots(std::int64_t b, std::int64_t j0) {
  return (2 * b + (j0 / kStep) % 2) * 2 * kSlot;
}

// Which tiles of a step a panels or update launch takes (launch_lu_panel_batched): all of
// them, only those the next step's pivot block depends on (the L and U panels' first tiles;
// the trailing diagonal tile's update is that pivot block's own), or the others.
enum class StepTiles : int { all, next_pivot_block, rest };

// The pivot block kernel's threads: row_lanes.cuh (eight per row of the 64×64 block while
// it is eliminated; after interchanges, four per column of each inverse).
using row_lanes::kLanes;
using row_lanes::kPad;
using row_lanes::kPerThread;
constexpr int kPivotThreads = row_lanes::kThreads;

// The unblocked LU of the w×w block held as above, without interchanges, and with it the
// inverses of both factors, so that no chain of their own follows the elimination's. At
// column j row j of U and row j of L⁻¹ are published to R[(j mod 2)·128 …] (two buffers: a
// row is overwritten two steps later, after a barrier every reader has passed) and U's row
// j is kept in T (the block staged there is no longer needed: each row was read by its own
// threads before the loop); one barrier per column. Then
//   rows i > j: the multiplier l = a(i, j)/a(j, j), the update of a(i, ·) right of j, and
//     x(i, ·) −= l·x(j, ·) (Gauss–Jordan on the identity: x ends as row i of L⁻¹);
//   rows i ≤ j (done eliminating): column j of U⁻¹, y(i, j) = (δ_ij − Σ_{i≤l<j} y(i, l)·
//     U(l, j)) / U(j, j) — Y·U = I read along row i, with U's rows kept in T.
// *sbad set when a pivot is not finite or under static_pivot, or an entry below it exceeds
// |pivot|/u (u = threshold: the pivoting rule would take another row). Every thread takes
// part in the shuffles (the sums of the U⁻¹ column are formed by all, kept by the rows
// i ≤ j).
__device__ __forceinline__ void eliminate(double (&a)[kPerThread], double (&x)[kPerThread],
                                          double (&y)[kPerThread], double* T, double* R, int* sbad,
                                          int w, double static_pivot, double threshold) {
  const int i = threadIdx.x / kLanes, q = threadIdx.x % kLanes, lane = threadIdx.x & 31;
#pragma unroll
  for (int c = 0; c < kPerThread; ++c) {
    x[c] = kLanes * c + q == i ? 1.0 : 0.0;
    y[c] = 0.0;
  }
  // columns j = kLanes·cb + jq (row_lanes.cuh: only the loop over cb unrolled)
  bool stop = false;
#pragma unroll
  for (int cb = 0; cb < kPerThread; ++cb) {
#pragma unroll 1
    for (int jq = 0; jq < kLanes; ++jq) {
      const int j = kLanes * cb + jq;
      if (j >= w) {
        stop = true;
        break;
      }
      double* row = R + (j & 1) * 2 * kStep;  // U's row j, then L⁻¹'s
      if (i == j) {
#pragma unroll
        for (int c = 0; c < kPerThread; ++c) {
          row[kLanes * c + q] = a[c];
          row[kStep + kLanes * c + q] = x[c];
          T[j * kPad + kLanes * c + q] = a[c];
        }
      }
      __syncthreads();
      const double d = row[j];  // the same in every thread: a uniform break
      if (!(fabs(d) >= fabs(static_pivot)) || !(fabs(d) <= DBL_MAX)) {
        if (threadIdx.x == 0) *sbad = 1;
        stop = true;
        break;
      }
      // A(i, j) from the thread of row i that holds column j (every lane takes part)
      const PivotReciprocal by_d(d);  // one reciprocal for the step's multipliers
      const double aij = __shfl_sync(0xffffffffu, a[cb], (lane & ~(kLanes - 1)) | jq);
      if (i > j && i < w) {
        const double l = by_d(aij);
        if (q == jq) {
          a[cb] = l;
          // the CPU's test, |a_jj| ≥ u·|a_ij|: else its pivoting would interchange rows
          if (!(fabs(d) >= threshold * fabs(aij))) *sbad = 1;
        }
        // The columns after j, then L⁻¹'s row j up to column j. Of the register columns
        // only cb holds columns on both sides of j (lanes after jq, lanes up to jq); every
        // other one lies wholly after (c > cb) or before (c < cb), so those need no
        // per-lane test — the compiler cannot tell that jq < kLanes and would test each.
        if (q > jq) a[cb] -= l * row[kLanes * cb + q];
#pragma unroll
        for (int c = cb + 1; c < kPerThread; ++c) a[c] -= l * row[kLanes * c + q];
#pragma unroll
        for (int c = 0; c < cb; ++c) x[c] -= l * row[kStep + kLanes * c + q];
        if (q <= jq) x[cb] -= l * row[kStep + kLanes * cb + q];
      }
      // U⁻¹'s column j: columns l of row i with i ≤ l < j (c < cb wholly before j)
      double part = 0.0;
#pragma unroll
      for (int c = 0; c < cb; ++c)
        if (kLanes * c + q >= i) part += y[c] * T[(kLanes * c + q) * kPad + j];
      if (q < jq && kLanes * cb + q >= i) part += y[cb] * T[(kLanes * cb + q) * kPad + j];
      part = row_lanes::lane_sum<kLanes>(part);
      if (i <= j && q == jq) y[cb] = by_d((i == j ? 1.0 : 0.0) - part);
    }
    if (stop) break;
  }
}

// The same with restricted threshold partial pivoting among the block's w rows (a whole
// front's fully summed rows): at column j row j when |a(j, j)| ≥ u·max, else the row with
// the largest |a(·, j)| among rows j … w−1, the first on ties (LAPACK's IDAMAX, as the CPU
// kernel), is published as U's row j and row j moves to its place (whole rows, the
// multipliers of earlier columns with them); pos tracks which local row is where. Two
// barriers per column (the search's and the interchange's); *sbad only for a pivot that
// is not finite or under static_pivot.
__device__ __forceinline__ void eliminate_with_interchanges(double (&a)[kPerThread], double* R,
                                                            double* S, int* pos, int* sbad, int w,
                                                            double static_pivot, double threshold) {
  constexpr int kWarps = kPivotThreads / 32;
  __shared__ double best_v[kWarps];
  __shared__ int best_i[kWarps];
  __shared__ double diag;  // |a(j, j)| at column j
  const int i = threadIdx.x / kLanes, q = threadIdx.x % kLanes, lane = threadIdx.x & 31;
  const int warp = threadIdx.x >> 5;
  // columns j = kLanes·cb + jq, only the loop over cb unrolled (as in eliminate)
  bool stop = false;
#pragma unroll
  for (int cb = 0; cb < kPerThread; ++cb) {
#pragma unroll 1
    for (int jq = 0; jq < kLanes; ++jq) {
      const int j = kLanes * cb + jq;
      if (j >= w) {
        stop = true;
        break;
      }
      double* row = R + (j & 1) * kStep;
      // the candidates: column j's entries in rows j … w−1, held by the lanes q = j mod kLanes
      double v = q == jq && i >= j && i < w ? fabs(a[cb]) : -1.0;
      int at = i;
      warp_argmax_down(v, at);
      if (lane == 0) {
        best_v[warp] = v;
        best_i[warp] = at;
      }
      if (i == j && q == jq) diag = fabs(a[cb]);
      __syncthreads();
      // the warps hold rows in order: a later warp's row wins only when strictly larger; no
      // candidate at all (a column of NaNs) leaves row j, whose pivot the check refuses; a
      // diagonal within the threshold stays
      double bv = best_v[0];
      int p = best_i[0];
#pragma unroll
      for (int x = 1; x < kWarps; ++x)
        if (best_v[x] > bv) {
          bv = best_v[x];
          p = best_i[x];
        }
      if (!(bv >= 0.0) || diag >= threshold * bv) p = j;
      if (i == p) {
#pragma unroll
        for (int c = 0; c < kPerThread; ++c) row[kLanes * c + q] = a[c];
      } else if (i == j) {
#pragma unroll
        for (int c = 0; c < kPerThread; ++c) S[kLanes * c + q] = a[c];
      }
      if (threadIdx.x == 0 && p != j) {
        const int t = pos[j];
        pos[j] = pos[p];
        pos[p] = t;
      }
      __syncthreads();
      if (p != j && i == p) {
#pragma unroll
        for (int c = 0; c < kPerThread; ++c) a[c] = S[kLanes * c + q];
      } else if (p != j && i == j) {
#pragma unroll
        for (int c = 0; c < kPerThread; ++c) a[c] = row[kLanes * c + q];
      }
      const double d = row[j];
      if (!(fabs(d) >= fabs(static_pivot)) || !(fabs(d) <= DBL_MAX)) {
        if (threadIdx.x == 0) *sbad = 1;
        stop = true;
        break;
      }
      const PivotReciprocal by_d(d);  // one reciprocal for the step's multipliers
      const double aij = __shfl_sync(0xffffffffu, a[cb], (lane & ~(kLanes - 1)) | jq);
      if (i > j && i < w) {
        const double l = by_d(aij);
        if (q == jq) a[cb] = l;
#pragma unroll
        for (int c = cb; c < kPerThread; ++c)  // the columns after j
          if (kLanes * c + q > j) a[c] -= l * row[kLanes * c + q];
      }
    }
    if (stop) break;
  }
}

// L⁻¹ and U⁻¹ of the packed LU in T (row r at T[r·kPad …], the identity outside the w×w
// block), written to WL (column-major: entry (r, c) at c·64 + r) and WU (row-major: at
// r·64 + c), zero outside w×w. The two are independent, so each has half the threads at
// the same time (the first eight warps L⁻¹, the last eight U⁻¹, each branch warp-uniform):
// thread t of a half forms column c = t/kInvLanes, rows r ≡ t mod kInvLanes, by rows in
// order (L⁻¹) and in reverse (U⁻¹):
//   X(r, c) = δ_rc − Σ_{l<r} L(r, l)·X(l, c),
//   Y(r, c) = (δ_rc − Σ_{l>r} U(r, l)·Y(l, c)) / U(r, r),
// each sum in kInvLanes parts (one per thread of the column) added by shuffles. The entries
// of a column above (L⁻¹) or below (U⁻¹) the diagonal are formed as 0, which the sums need.
// Rows r = kInvLanes·rb + rq: only the loop over rb unrolled (as in eliminate).
constexpr int kInvLanes = 4;
constexpr int kInvPerThread = kStep / kInvLanes;  // the rows of a column a thread holds
static_assert(kInvLanes * kStep == kPivotThreads / 2, "a half of the threads per inverse");
__device__ __forceinline__ void triangular_inverses(const double* T, int w, double* WL,
                                                    double* WU) {
  const bool upper = threadIdx.x >= kPivotThreads / 2;
  const int t = threadIdx.x % (kPivotThreads / 2);
  const int c = t / kInvLanes, q = t % kInvLanes;
  double x[kInvPerThread];
#pragma unroll
  for (int s = 0; s < kInvPerThread; ++s) x[s] = 0.0;
  if (!upper) {
#pragma unroll
    for (int rb = 0; rb < kInvPerThread; ++rb) {
#pragma unroll 1
      for (int rq = 0; rq < kInvLanes; ++rq) {
        const int r = kInvLanes * rb + rq;
        double part = 0.0;
#pragma unroll
        for (int s = 0; s <= rb; ++s)
          if (kInvLanes * s + q < r) part += T[r * kPad + kInvLanes * s + q] * x[s];
        part = row_lanes::lane_sum<kInvLanes>(part);
        if (q == rq) x[rb] = r == c ? 1.0 : (r > c ? -part : 0.0);
      }
    }
#pragma unroll
    for (int s = 0; s < kInvPerThread; ++s) {
      const int r = kInvLanes * s + q;
      WL[c * kStep + r] = r < w && c < w ? x[s] : 0.0;
    }
  } else {
#pragma unroll
    for (int rb = kInvPerThread - 1; rb >= 0; --rb) {
#pragma unroll 1
      for (int rq = kInvLanes - 1; rq >= 0; --rq) {
        const int r = kInvLanes * rb + rq;
        double part = 0.0;
#pragma unroll
        for (int s = kInvPerThread - 1; s >= rb; --s)
          if (kInvLanes * s + q > r) part += T[r * kPad + kInvLanes * s + q] * x[s];
        part = row_lanes::lane_sum<kInvLanes>(part);
        if (q == rq) x[rb] = divide_rn((r == c ? 1.0 : 0.0) - part, T[r * kPad + r]);
      }
    }
#pragma unroll
    for (int s = 0; s < kInvPerThread; ++s) {
      const int r = kInvLanes * s + q;
      WU[r * kStep + c] = r < w && c < w ? x[s] : 0.0;
    }
  }
}

// Launch 1 of a step: block b (kPivotThreads threads) factors item b's w×w diagonal block
// at (j0, j0) — for an item with a perm (a front of one step), with the interchanges that
// partial pivoting makes, if any, and their permutation written;
// writes the packed LU back, L_jj⁻¹ (column-major: entry (r, c) at c·64 + r) to work[2b]
// and U_jj⁻¹ (row-major: entry (r, c) at r·64 + c, the layout tile::product reads as
// kBRows) to work[2b + 1], both zero outside w×w.
// With `own_update` (a step after the first, its block run ahead of the previous step's
// update, launch_lu_panel_batched), the block first takes the previous step's update of
// itself, A(j0.., j0..) −= L(j0.., j0 − 64..)·U(j0 − 64.., j0..) over that step's 64
// columns (lu_update_kernel's tile q = 0), from that step's first panel tiles
// (lu_panels_kernel, StepTiles::next_pivot_block): one launch less in the chain of steps.
__global__ void __launch_bounds__(kPivotThreads)
    lu_pivot_block_kernel(const LuPanelItem* items, double* work, int* bad, double static_pivot,
                          double threshold, std::int64_t j0, bool own_update) {
  // the block, row-major: staging, then the packed LU; before it, tile::product's buffer
  // for the previous step's update of the block
  __shared__ __align__(32) double T[kStep * kPad];
  static_assert(kStep * kPad >= tile::kSharedDoubles, "the update's product fits in T");
  __shared__ double R[4 * kStep];  // the pivot rows (U's, L⁻¹'s) of the last two columns
  __shared__ double S[kStep];      // a row on its way to the pivot row's place
  __shared__ int pos[kStep];       // the local row now in each position (interchanges)
  __shared__ int sbad;
  if (bad[blockIdx.x]) return;  // rejected at an earlier step
  const LuPanelItem it = items[blockIdx.x];
  const std::int64_t ld = it.ld;
  const int w = static_cast<int>(imin(kStep, it.k - j0));
  double* D = it.F + j0 * ld + j0;
  const int t = threadIdx.x, i = t / kLanes, q = t % kLanes;
  // this thread's entries of the block, e = t + kPivotThreads·u (row e mod 64, column
  // e / 64; read by columns, coalesced), loaded first so that the loads overlap the update
  constexpr int kStaged = kSlot / kPivotThreads;
  double v[kStaged];
#pragma unroll
  for (int u = 0; u < kStaged; ++u) {
    const int e = t + u * kPivotThreads, r = e % kStep, c = e / kStep;
    v[u] = r < w && c < w ? D[static_cast<std::int64_t>(c) * ld + r] : 0.0;
  }
  if (own_update) {  // as lu_update_kernel's tile q = 0 of the step at j0 − 64
    const std::int64_t p0 = j0 - kStep;
    const int n = static_cast<int>(imin(kStep, it.m - j0));
    const double* C = tile::product<tile::BLayout::kBCols, kPivotThreads>(
        it.F + p0 * ld + j0, ld, n, it.F + j0 * ld + p0, ld, n, kStep, T);
#pragma unroll
    for (int u = 0; u < kStaged; ++u) {
      const int e = t + u * kPivotThreads, r = e % kStep, c = e / kStep;
      if (r < n && c < n && (j0 + r < it.k || j0 + c < it.k)) {
        double* at = D + static_cast<std::int64_t>(c) * ld + r;
        if (r < w && c < w) {  // the block: its write-back below stores it factored
          v[u] -= C[e];
          if (it.perm) *at = v[u];  // the elimination with interchanges reads it again
        } else {  // a last step narrower than 64: the rest of the tile is the panels'
          *at -= C[e];
        }
      }
    }
    __syncthreads();  // C (in T) read by every thread before T is overwritten
  }
  if (t == 0) sbad = 0;
  if (t < kStep) pos[t] = t;
#pragma unroll
  for (int u = 0; u < kStaged; ++u) {
    const int e = t + u * kPivotThreads;
    T[(e % kStep) * kPad + e / kStep] = v[u];
  }
  __syncthreads();
  double a[kPerThread], x[kPerThread], y[kPerThread];
#pragma unroll
  for (int c = 0; c < kPerThread; ++c) a[c] = T[i * kPad + kLanes * c + q];
  // Without interchanges first, also for an item factored with them: the pivoting rule
  // interchanges no row exactly when every multiplier is at most 1/u in magnitude, and then
  // both eliminations do the same operations; otherwise (or at a bad pivot) again from the
  // block, read once more from the front (T holds U's rows now), with interchanges (two
  // barriers a column and a search), and the inverses formed after it.
  eliminate(a, x, y, T, R, &sbad, w, static_pivot, threshold);
  __syncthreads();
  const bool interchanged = it.perm && sbad;
  if (interchanged) {
    __syncthreads();  // sbad read by every thread
    if (t == 0) sbad = 0;
    for (int e = t; e < kStep * kStep; e += kPivotThreads) {
      const int r = e % kStep, c = e / kStep;
      T[r * kPad + c] = r < w && c < w ? D[static_cast<std::int64_t>(c) * ld + r] : 0.0;
    }
    __syncthreads();
#pragma unroll
    for (int c = 0; c < kPerThread; ++c) a[c] = T[i * kPad + kLanes * c + q];
    __syncthreads();
    eliminate_with_interchanges(a, R, S, pos, &sbad, w, static_pivot, threshold);
    __syncthreads();
  }
  if (sbad) {
    if (t == 0) bad[blockIdx.x] = 1;
    return;
  }
  // the packed LU into T, the identity outside w×w (what the inverses need there)
#pragma unroll
  for (int c = 0; c < kPerThread; ++c) {
    const int col = kLanes * c + q;
    T[i * kPad + col] = i < w && col < w ? a[c] : (i == col ? 1.0 : 0.0);
  }
  if (it.perm && t < w) it.perm[t] = pos[t];
  __syncthreads();
  for (int e = t; e < kStep * kStep; e += kPivotThreads) {
    const int r = e % kStep, c = e / kStep;
    if (r < w && c < w) D[static_cast<std::int64_t>(c) * ld + r] = T[r * kPad + c];
  }
  double* WL = work + inverse_slots(blockIdx.x, j0);
  double* WU = WL + kSlot;
  if (interchanged) {
    triangular_inverses(T, w, WL, WU);
    return;
  }
#pragma unroll
  for (int c = 0; c < kPerThread; ++c) {
    const int col = kLanes * c + q;
    const bool in = i < w && col < w;
    WL[col * kStep + i] = in ? x[c] : 0.0;
    WU[i * kStep + col] = in ? y[c] : 0.0;
  }
}

// Launch 2 of a step: item blockIdx.x's T tiles of the L panel (rows j0 + w + 64y …,
// columns j0 … j0 + w; T of them, to the last row), L = A·U_jj⁻¹ with the multipliers of
// the fully summed rows checked, then its T tiles of the U panel (rows j0 … j0 + w,
// columns j0 + w + 64y …), U = L_jj⁻¹·A; grid-stride over the 2T tiles (gridDim.y is
// capped). In place: a tile is read whole before it is written, and no two tiles overlap.
__global__ void lu_panels_kernel(const LuPanelItem* items, const double* work, int* bad,
                                 double threshold, std::int64_t j0, StepTiles which) {
  __shared__ __align__(32) double sm[tile::kSharedDoubles];
  if (bad[blockIdx.x]) return;
  const LuPanelItem it = items[blockIdx.x];
  const std::int64_t m = it.m, ld = it.ld;
  const int w = static_cast<int>(imin(kStep, it.k - j0));
  const std::int64_t base = j0 + w, T = tiles_of(m - base);
  const double* WL = work + inverse_slots(blockIdx.x, j0);
  const double* WU = WL + kSlot;
  // an item factored with interchanges: its U panel is L_jj⁻¹·P·A, the rows read through P
  __shared__ int prow[kStep];
  if (it.perm && threadIdx.x < w) prow[threadIdx.x] = static_cast<int>(it.perm[threadIdx.x]);
  __syncthreads();
  // the first tiles of both panels are q = 0 and q = T
  const std::int64_t count = which == StepTiles::all                ? 2 * T
                             : which == StepTiles::next_pivot_block ? (T > 0 ? 2 : 0)
                                                                    : (T > 0 ? 2 * T - 2 : 0);
  for (std::int64_t e = blockIdx.y; e < count; e += gridDim.y) {
    const std::int64_t q = which == StepTiles::all                ? e
                           : which == StepTiles::next_pivot_block ? e * T
                                                                  : (e < T - 1 ? e + 1 : e + 2);
    const bool lpanel = q < T;
    const std::int64_t x0 = base + (lpanel ? q : q - T) * kStep;
    const int n = static_cast<int>(imin(kStep, m - x0));
    if (lpanel) {
      double* A = it.F + j0 * ld + x0;
      const double* C = tile::product<tile::BLayout::kBRows>(A, ld, n, WU, kStep, w, w, sm);
      bool over = false;
      for (int x = threadIdx.x; x < kSlot; x += kThreads) {
        const int r = x & (kStep - 1), c = x >> 6;
        if (r < n && c < w) {
          const double v = C[x];
          A[static_cast<std::int64_t>(c) * ld + r] = v;
          if (x0 + r < it.kc && !(threshold * fabs(v) <= 1.0)) over = true;
        }
      }
      if (over) bad[blockIdx.x] = 1;  // every writer writes 1; the next launch reads it
    } else {
      double* A = it.F + x0 * ld + j0;
      const double* C = tile::product<tile::BLayout::kBCols>(WL, kStep, w, A, ld, n, w, sm,
                                                             it.perm ? prow : nullptr);
      for (int x = threadIdx.x; x < kSlot; x += kThreads) {
        const int r = x & (kStep - 1), c = x >> 6;
        if (r < w && c < n) A[static_cast<std::int64_t>(c) * ld + r] = C[x];
      }
    }
    __syncthreads();  // C (in sm) read by every thread before the next tile's staging
  }
}

// Launch 3 of a step: item blockIdx.x's tiles of the trailing L-shaped region, rows and
// columns from j0 + w on in 64-tiles (T of them each way, the first Tk of which hold
// fully summed rows/columns): the Tk·T tiles of the trailing pivot columns (all rows),
// then the (T − Tk)·Tk tiles of the contribution block's columns in the fully summed
// rows; A_rc −= L_rj·U_jc, entries with r ≥ k and c ≥ k left alone. Grid-stride over the
// tiles (gridDim.y is capped).
__global__ void lu_update_kernel(const LuPanelItem* items, const int* bad, std::int64_t j0,
                                 StepTiles which) {
  __shared__ __align__(32) double sm[tile::kSharedDoubles];
  if (bad[blockIdx.x]) return;
  const LuPanelItem it = items[blockIdx.x];
  const std::int64_t m = it.m, k = it.k, ld = it.ld;
  const int w = static_cast<int>(imin(kStep, k - j0));
  const std::int64_t base = j0 + w;
  const std::int64_t T = tiles_of(m - base), Tk = tiles_of(k - base);
  // the trailing diagonal tile is q = 0: with StepTiles::rest the next step's pivot block
  // takes it (own_update); StepTiles::next_pivot_block is not a launch of this kernel
  const std::int64_t count = Tk * (2 * T - Tk);
  const std::int64_t first = which == StepTiles::rest && count > 0 ? 1 : 0;
  for (std::int64_t q = first + blockIdx.y; q < count; q += gridDim.y) {
    std::int64_t y, z;
    if (q < Tk * T) {
      z = q / T;
      y = q % T;
    } else {
      y = (q - Tk * T) % Tk;
      z = Tk + (q - Tk * T) / Tk;
    }
    const std::int64_t r0 = base + y * kStep, c0 = base + z * kStep;
    const int rows = static_cast<int>(imin(kStep, m - r0));
    const int cols = static_cast<int>(imin(kStep, m - c0));
    const double* C = tile::product<tile::BLayout::kBCols>(it.F + j0 * ld + r0, ld, rows,
                                                           it.F + c0 * ld + j0, ld, cols, w, sm);
    double* A = it.F + c0 * ld + r0;
    for (int x = threadIdx.x; x < kSlot; x += kThreads) {
      const int r = x & (kStep - 1), c = x >> 6;
      if (r < rows && c < cols && (r0 + r < k || c0 + c < k))
        A[static_cast<std::int64_t>(c) * ld + r] -= C[x];
    }
    __syncthreads();  // C (in sm) read by every thread before the next tile's staging
  }
}

// The contribution block of item blockIdx.x, A22 −= L21·U12, by 64×64 tiles (grid-stride
// over the T² tiles, T = ⌈(m − k)/64⌉), each the product over all k pivot columns.
__global__ void lu_cb_update_kernel(const LuPanelItem* items) {
  __shared__ __align__(32) double sm[tile::kSharedDoubles];
  const LuPanelItem it = items[blockIdx.x];
  const std::int64_t m = it.m, k = it.k, ld = it.ld;
  const std::int64_t T = tiles_of(m - k);
  for (std::int64_t q = blockIdx.y; q < T * T; q += gridDim.y) {
    const std::int64_t r0 = k + (q % T) * kStep, c0 = k + (q / T) * kStep;
    const int rows = static_cast<int>(imin(kStep, m - r0));
    const int cols = static_cast<int>(imin(kStep, m - c0));
    const double* C = tile::product<tile::BLayout::kBCols>(it.F + r0, ld, rows, it.F + c0 * ld, ld,
                                                           cols, static_cast<int>(k), sm);
    double* A = it.F + c0 * ld + r0;
    for (int x = threadIdx.x; x < kSlot; x += kThreads) {
      const int r = x & (kStep - 1), c = x >> 6;
      if (r < rows && c < cols) A[static_cast<std::int64_t>(c) * ld + r] -= C[x];
    }
    __syncthreads();  // C (in sm) read by every thread before the next tile's staging
  }
}

constexpr std::int64_t kMaxGridY = 65535;

unsigned grid_y(std::int64_t n) {
  return static_cast<unsigned>(std::clamp<std::int64_t>(n, 1, kMaxGridY));
}

}  // namespace

std::size_t lu_panel_work_size(std::int64_t count) {
  return static_cast<std::size_t>(std::max<std::int64_t>(count, 1)) * 4 * kSlot;
}

void launch_lu_panel_batched(const LuPanelItem* items, const std::vector<std::int64_t>& rows,
                             const std::vector<std::int64_t>& pivots, double* work, int* bad,
                             double static_pivot, double threshold, cudaStream_t s,
                             const LuLookahead* ahead) {
  const std::size_t count = pivots.size();
  if (count == 0) return;
  auto active_at = [&](std::int64_t j0) {  // the items with pivots from j0 on: a prefix
    std::size_t a = count;
    while (a > 0 && pivots[a - 1] <= j0) --a;
    return static_cast<unsigned>(a);
  };
  auto pivot_block = [&](std::int64_t j0, cudaStream_t on, bool own_update) {
    lu_pivot_block_kernel<<<active_at(j0), kPivotThreads, 0, on>>>(items, work, bad, static_pivot,
                                                                   threshold, j0, own_update);
    STRATA_CUDA_LAUNCH();
  };
  auto panels = [&](std::int64_t j0, unsigned n, std::int64_t tiles, StepTiles which) {
    if (tiles <= 0) return;
    lu_panels_kernel<<<dim3(n, grid_y(tiles)), kThreads, 0, s>>>(items, work, bad, threshold, j0,
                                                                 which);
    STRATA_CUDA_LAUNCH();
  };
  auto update = [&](std::int64_t j0, unsigned n, std::int64_t tiles, StepTiles which) {
    if (tiles <= 0) return;
    lu_update_kernel<<<dim3(n, grid_y(tiles)), kThreads, 0, s>>>(items, bad, j0, which);
    STRATA_CUDA_LAUNCH();
  };
  pivot_block(0, s, false);
  for (std::int64_t j0 = 0; j0 < pivots[0]; j0 += kStep) {
    const unsigned n = active_at(j0);
    // per step: the most tiles of any active front below / right of its diagonal block,
    // and the most update tiles
    std::int64_t panel_tiles = 0, update_tiles = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const std::int64_t base = j0 + std::min<std::int64_t>(kStep, pivots[i] - j0);
      const std::int64_t T = tiles_of(rows[i] - base), Tk = tiles_of(pivots[i] - base);
      panel_tiles = std::max(panel_tiles, T);
      update_tiles = std::max(update_tiles, Tk * (2 * T - Tk));
    }
    const std::int64_t next = j0 + kStep;
    if (next >= pivots[0]) {  // the last step
      panels(j0, n, 2 * panel_tiles, StepTiles::all);
      update(j0, n, update_tiles, StepTiles::all);
    } else if (!ahead) {
      panels(j0, n, 2 * panel_tiles, StepTiles::all);
      update(j0, n, update_tiles, StepTiles::all);
      pivot_block(next, s, false);
    } else {
      // the next step's pivot block needs the first tiles of this step's panels and the
      // trailing diagonal tile only: the panels' first tiles, then that pivot block on the
      // side stream, which updates its diagonal tile itself (own_update), while the rest
      // of this step's panels and update run here; the next step's panels wait for it
      panels(j0, n, 2, StepTiles::next_pivot_block);
      STRATA_CUDA(cudaEventRecord(ahead->ready, s));
      STRATA_CUDA(cudaStreamWaitEvent(ahead->stream, ahead->ready, 0));
      pivot_block(next, ahead->stream, true);
      STRATA_CUDA(cudaEventRecord(ahead->done, ahead->stream));
      panels(j0, n, 2 * panel_tiles - 2, StepTiles::rest);
      update(j0, n, update_tiles - 1, StepTiles::rest);
      STRATA_CUDA(cudaStreamWaitEvent(s, ahead->done, 0));
    }
  }
}

void launch_lu_cb_update_batched(const LuPanelItem* items, std::int64_t count,
                                 std::int64_t max_tiles, cudaStream_t s) {
  if (count <= 0 || max_tiles <= 0) return;
  lu_cb_update_kernel<<<dim3(static_cast<unsigned>(count), grid_y(max_tiles)), kThreads, 0, s>>>(
      items);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda
