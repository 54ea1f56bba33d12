// strata — CUDA kernels of the level-batched multifrontal factorization (see kernels.cuh).
//
// The small-front kernel factors each front of up to Options::gpu_small_front_rows (at most
// 256) rows by one thread block, the fronts of a batch side by side in one launch: the
// batched-small-front case that vendor batched POTRF handles poorly (DESIGN.md §2). It is
// blocked right-looking with one row per thread (llt_front_blocked, lu_front_blocked:
// panels of kSmallNb = 8 pivot columns in registers: each pivot step of a panel is unrolled,
// and a wider panel costs more in registers and instruction fetches than the trailing
// passes it saves), the trailing matrix updated once per panel by
// all the block's threads whatever the number of trailing rows (for an LU front in shared
// memory on the FP64 tensor cores: lu_trailing_update_mma); the multipliers are the entries
// times the pivot's reciprocal (PivotReciprocal, divide.cuh: one reciprocal a step instead
// of a division per row on the step's chain); the unblocked one-pivot-at-a-
// time forms (llt_front, lu_columns) remain for larger blocks (lu_columns also serves the
// large LU fronts' static-pivoting path and the tiled slabs). An LU batch whose fronts all
// fit the device's shared memory per block (about 168 rows on an H100) copies each front
// there and factors it in place (lu_small_shared_kernel); when the whole launch group is
// such fronts and the factor stays on the device, one launch does the group's assembly,
// factorization, stores and packing, each front assembled straight into shared memory
// (small_fused_kernel, for Cholesky groups too, whose fronts are held as their packed
// lower triangle: up to about 230 rows). A launch of few fronts gets blocks wider than a
// thread per row (small_front_threads), so that the trailing updates, a large share of a front's
// time, are spread over more threads of an SM that would otherwise idle. Threshold partial pivoting
// for LU searches only the fully summed rows (restricted pivoting), keeps the diagonal when it is
// at least u times the largest candidate, and replaces tiny pivots by ±static_pivot, exactly as the
// CPU kernels do (numeric/cpu/dense_front.hpp).
#include <algorithm>
#include <atomic>
#include <cfloat>
#include <string>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/divide.cuh"
#include "numeric/cuda/kernels.cuh"
#include "numeric/cuda/multiprocessors.hpp"
#include "numeric/cuda_testing.hpp"
#include "numeric/static_pivot.hpp"
#include "strata/errors.hpp"

namespace strata::cuda {
namespace {

using numeric::needs_static_pivot;
using numeric::static_pivot_value;

constexpr int kThreads = 256;  // the most rows of a small front; its shared arrays' size
// the widest small-front block (launch_factor_small): two of kThreads' register budget
constexpr int kWideThreads = 2 * kThreads;

// The per-front kernels below run on a 2-D grid: blockIdx.x is the front (its batch
// position minus `begin`), blockIdx.y a slice of `slice` columns of it, so that a large
// front is spread over many SMs instead of one. Slices write disjoint columns, and within
// a slice children are added one after another: no two writes collide and the order of
// additions is fixed (results do not depend on scheduling). The host picks the slice
// width (slice_width) so that a launch has enough blocks to fill the GPU: a level of one
// or two large fronts gets narrow slices, a level of many fronts wide ones.
//
// Inside a block each warp takes whole columns and its lanes walk down a column: loads
// and stores are coalesced, and there is no 64-bit division per element (index
// arithmetic x / mc, x % mc cost more than the memory traffic it addressed).
constexpr std::int64_t kMaxSliceCols = 64;
constexpr std::int64_t kMinSliceCols = 8;
constexpr std::int64_t kTargetBlocks = 2048;  // ≈ 16 blocks of 256 threads per Hopper SM
constexpr int kWarp = 32;

// The first e in [lo, hi) with a[e] ≥ key (hi if none), where a[e] < key holds on a prefix
// of [lo, hi); every lane of the calling warp takes part and gets the result. Each round
// reads 32 samples spread over the range and keeps the gap after the last one under the
// key: about log₃₂ of the length dependent reads instead of log₂.
__device__ std::int64_t warp_lower_bound(const std::int64_t* a, std::int64_t lo, std::int64_t hi,
                                         std::int64_t key) {
  const int lane = threadIdx.x % kWarp;
  while (hi - lo > kWarp) {
    const std::int64_t step = (hi - lo + kWarp - 1) / kWarp;
    const std::int64_t at = lo + lane * step;
    const int n = __popc(__ballot_sync(0xffffffffu, at < hi && a[at] < key));
    if (n == 0) return lo;
    const std::int64_t last = lo + (n - 1) * step;  // a[last] < key ≤ a[last + step]
    lo = last + 1;
    hi = min(hi, last + step);
  }
  const std::int64_t at = lo + lane;
  return lo + __popc(__ballot_sync(0xffffffffu, at < hi && a[at] < key));
}

// dst[i] = src[i] for i in [from, to), `step` apart per thread starting at from + tid:
// four loads in flight before their stores. The two never overlap, but without the
// unrolling each load waits for the store before it (the compiler cannot know they do
// not alias), and a copy kernel then runs at a fraction of the memory bandwidth.
__device__ void copy_range(double* __restrict__ dst, const double* __restrict__ src,
                           std::int64_t from, std::int64_t to, std::int64_t tid,
                           std::int64_t step) {
  std::int64_t i = from + tid;
  for (; i + 3 * step < to; i += 4 * step) {
    const double a = src[i], b = src[i + step], c = src[i + 2 * step], d = src[i + 3 * step];
    dst[i] = a;
    dst[i + step] = b;
    dst[i + 2 * step] = c;
    dst[i + 3 * step] = d;
  }
  for (; i < to; i += step) dst[i] = src[i];
}

__global__ void assemble_kernel(DeviceTree t, std::int64_t begin, std::int64_t slice,
                                const double* values, double* pool, bool symmetric) {
  const std::int64_t pos = begin + blockIdx.x;
  const std::int64_t f = t.fronts[pos];
  const std::int64_t m = t.n_rows[f];
  const std::int64_t c0 = blockIdx.y * slice, c1 = min(m, c0 + slice);
  if (c0 >= m) return;
  double* F = pool + t.pos_offset[pos];
  const int warp = threadIdx.x / kWarp, lane = threadIdx.x % kWarp;
  const int warps = blockDim.x / kWarp;
  // nothing reads the strict upper triangle of a symmetric front's contribution block (the
  // factor kernels, the block store and the panel pack use the lower one): it stays
  // unwritten, about a third less to zero in a large front. The pivot columns are zeroed
  // whole: the packed panel carries its k×k block's upper triangle as zeros, as the CPU's.
  const std::int64_t whole_cols = symmetric ? t.n_pivots[f] : m;
  for (std::int64_t c = c0 + warp; c < c1; c += warps)
    for (std::int64_t i = (c < whole_cols ? 0 : c) + lane; i < m; i += kWarp) F[c * m + i] = 0.0;
  __syncthreads();
  // the front's entries are ordered by column (AssemblyMap): the slice's are a range
  const std::int64_t e0 =
      warp_lower_bound(t.entry_dst, t.entry_offsets[f], t.entry_offsets[f + 1], c0 * m);
  const std::int64_t e1 = warp_lower_bound(t.entry_dst, e0, t.entry_offsets[f + 1], c1 * m);
  for (std::int64_t e = e0 + threadIdx.x; e < e1; e += blockDim.x)
    F[t.entry_dst[e]] += values[t.entry_src[e]];  // distinct destinations
  __syncthreads();
  for (std::int64_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const std::int64_t c = t.children[q];
    const std::int64_t mc = t.n_rows[c] - t.n_pivots[c];
    if (mc == 0) continue;
    const double* cb = t.cb_ptr[c];
    const std::int64_t* rel = t.rel + t.rel_offsets[c];
    const std::int64_t j0 = warp_lower_bound(rel, 0, mc, c0);
    const std::int64_t j1 = warp_lower_bound(rel, j0, mc, c1);
    for (std::int64_t jj = j0 + warp; jj < j1; jj += warps) {
      double* fcol = F + rel[jj] * m;
      const double* src = cb + jj * mc;
      std::int64_t ii = (symmetric ? jj : 0) + lane;
      for (; ii + kWarp < mc; ii += 2 * kWarp) {  // two in flight (see copy_range)
        const std::int64_t r0 = rel[ii], r1 = rel[ii + kWarp];
        const double v0 = src[ii], v1 = src[ii + kWarp];
        const double f0 = fcol[r0], f1 = fcol[r1];
        fcol[r0] = f0 + v0;
        fcol[r1] = f1 + v1;
      }
      if (ii < mc) fcol[rel[ii]] += src[ii];
    }
    __syncthreads();  // children are added one after another: no two writes collide
  }
}

__global__ void store_cb_kernel(DeviceTree t, std::int64_t begin, std::int64_t slice,
                                const double* pool, bool symmetric) {
  const std::int64_t pos = begin + blockIdx.x;
  const std::int64_t f = t.fronts[pos];
  if (t.parent[f] < 0) return;
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f], mc = m - k;
  const std::int64_t c0 = blockIdx.y * slice, c1 = min(mc, c0 + slice);
  if (c0 >= mc) return;
  const double* F = pool + t.pos_offset[pos];
  double* cb = t.cb_ptr[f];
  const int warp = threadIdx.x / kWarp, lane = threadIdx.x % kWarp;
  for (std::int64_t jj = c0 + warp; jj < c1; jj += blockDim.x / kWarp) {
    const double* src = F + (k + jj) * m + k;
    double* dst = cb + jj * mc;
    copy_range(dst, src, symmetric ? jj : 0, mc, lane, kWarp);
  }
}

__global__ void pack_panels_kernel(DeviceTree t, std::int64_t begin, std::int64_t slice,
                                   const double* pool, const std::int64_t* staging_offset,
                                   double* staging, bool lu) {
  const std::int64_t pos = begin + blockIdx.x;
  const std::int64_t f = t.fronts[pos];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  const std::int64_t c0 = blockIdx.y * slice;
  const double* F = pool + t.pos_offset[pos];
  double* dst = staging + staging_offset[blockIdx.x];
  if (c0 < k) {  // panel columns [c0, c1): contiguous in the front and in the panel
    const std::int64_t c1 = min(k, c0 + slice);
    copy_range(dst, F, c0 * m, c1 * m, threadIdx.x, blockDim.x);
  }
  if (lu && c0 < m - k) {  // U12 columns [c0, c1): U12(i, j) = F(i, k + j), i < k
    const std::int64_t c1 = min(m - k, c0 + slice);
    double* u12 = dst + m * k;
    const int warp = threadIdx.x / kWarp, lane = threadIdx.x % kWarp;
    for (std::int64_t j = c0 + warp; j < c1; j += blockDim.x / kWarp)
      for (std::int64_t i = lane; i < k; i += kWarp) u12[j * k + i] = F[(k + j) * m + i];
  }
}

// Block-wide argmax of |F(i, j)| over rows [r0, r1). Returns the row (or r0 if empty).
__device__ std::int64_t block_argmax(const double* col, std::int64_t r0, std::int64_t r1,
                                     double* sval, std::int64_t* sidx) {
  double best = -1.0;
  std::int64_t arg = r0;
  for (std::int64_t i = r0 + threadIdx.x; i < r1; i += blockDim.x) {
    const double v = fabs(col[i]);
    if (v > best) {
      best = v;
      arg = i;
    }
  }
  sval[threadIdx.x] = best;
  sidx[threadIdx.x] = arg;
  __syncthreads();
  for (int stride = blockDim.x / 2; stride > 0; stride /= 2) {
    if (threadIdx.x < stride) {
      const double o = sval[threadIdx.x + stride];
      const std::int64_t oi = sidx[threadIdx.x + stride];
      // ties go to the smaller row, as the CPU kernel (first maximum) does
      if (o > sval[threadIdx.x] || (o == sval[threadIdx.x] && oi < sidx[threadIdx.x])) {
        sval[threadIdx.x] = o;
        sidx[threadIdx.x] = oi;
      }
    }
    __syncthreads();
  }
  const std::int64_t r = sidx[0];
  __syncthreads();
  return r;
}

// Static pivoting (numeric/cpu/dense_front.hpp): a pivot below static_pivot in magnitude
// becomes ±static_pivot (sign(0) taken as +), counted in *perturbed.
__device__ double static_pivoted(double p, double static_pivot, std::int64_t* perturbed) {
  if (!needs_static_pivot(p, static_pivot)) return p;
  ++*perturbed;
  return static_pivot_value(p, static_pivot);
}

// Unblocked right-looking partial LU of columns [p0, p0+w) of the m-row matrix F (leading
// dimension ld), updating columns up to `update_end` (m: whole front; p0+w: panel only).
// Threshold partial pivoting among the fully summed rows as the CPU kernel's: the diagonal
// when |F(j, j)| ≥ threshold · the column's largest candidate, else that largest.
// Row swaps among the fully summed rows [j, k) move the columns [0, swap_end) (the whole
// row of an in-core front; the slab's own columns for a front factored tile by tile).
__device__ void lu_columns(double* F, std::int64_t ld, std::int64_t m, std::int64_t k,
                           std::int64_t p0, std::int64_t w, std::int64_t update_end,
                           std::int64_t swap_end, double static_pivot, double threshold,
                           std::int64_t* perm, std::int64_t* perturbed) {
  __shared__ double sval[kThreads];
  __shared__ std::int64_t sidx[kThreads];
  __shared__ double spiv;
  for (std::int64_t j = p0; j < p0 + w; ++j) {
    double* colj = F + j * ld;
    std::int64_t r = block_argmax(colj, j, k, sval, sidx);
    if (fabs(colj[j]) >= threshold * fabs(colj[r])) r = j;
    if (r != j) {
      for (std::int64_t c = threadIdx.x; c < swap_end; c += blockDim.x) {
        const double tmp = F[c * ld + j];
        F[c * ld + j] = F[c * ld + r];
        F[c * ld + r] = tmp;
      }
    }
    __syncthreads();
    if (threadIdx.x == 0) {
      if (r != j) {
        const std::int64_t tp = perm[j];
        perm[j] = perm[r];
        perm[r] = tp;
      }
      colj[j] = static_pivoted(colj[j], static_pivot, perturbed);
      spiv = colj[j];
    }
    __syncthreads();
    const double inv = 1.0 / spiv;
    for (std::int64_t i = j + 1 + threadIdx.x; i < m; i += blockDim.x) colj[i] *= inv;
    __syncthreads();
    const std::int64_t rows = m - j - 1, cols = update_end - j - 1;
    for (std::int64_t x = threadIdx.x; x < rows * cols; x += blockDim.x) {
      const std::int64_t i = j + 1 + x % rows, c = j + 1 + x / rows;
      F[c * ld + i] -= colj[i] * F[c * ld + j];
    }
    __syncthreads();
  }
}

// Unblocked right-looking partial Cholesky of a small front (lower triangle).
__device__ void llt_front(double* F, std::int64_t m, std::int64_t k, std::int64_t* info) {
  __shared__ double sdiag;
  __shared__ int sfail;
  if (threadIdx.x == 0) sfail = 0;
  __syncthreads();
  for (std::int64_t j = 0; j < k; ++j) {
    double* colj = F + j * m;
    if (threadIdx.x == 0) {
      const double d = colj[j];
      if (!(d > 0.0)) {
        sfail = 1;
        *info = j;
      } else {
        sdiag = sqrt(d);
        colj[j] = sdiag;
      }
    }
    __syncthreads();
    if (sfail) return;
    const double inv = 1.0 / sdiag;
    for (std::int64_t i = j + 1 + threadIdx.x; i < m; i += blockDim.x) colj[i] *= inv;
    __syncthreads();
    const std::int64_t rows = m - j - 1;
    // lower triangle of the trailing matrix: pairs (i, c) with i >= c > j
    for (std::int64_t x = threadIdx.x; x < rows * rows; x += blockDim.x) {
      const std::int64_t i = j + 1 + x % rows, c = j + 1 + x / rows;
      if (i >= c) F[c * m + i] -= colj[i] * colj[c];
    }
    __syncthreads();
  }
}

// Blocked right-looking partial Cholesky of a small front (m ≤ blockDim.x rows, lower
// triangle, leading dimension ld: m in the pool, shared_ld(m) in shared memory), one row
// per thread: thread i keeps row i of the current panel of kSmallNb
// pivot columns in registers, factors the panel there (each column's entries shared
// through shared memory as they are finished), writes it back, and then updates the
// trailing lower triangle by the rank-kSmallNb product of the panel with itself (all the
// block's threads, whatever the number of trailing rows), reading and writing each
// trailing entry once per panel. The unblocked kernel (llt_front) read and
// wrote the whole trailing triangle in global memory once per pivot, with a 64-bit
// division per entry: a small front of k pivots made k such passes. The arithmetic is
// the unblocked one's in another order (same operations per entry, summed panel by panel).
constexpr int kSmallNb = 8;
// a front's panels (at most kThreads pivots) as the bits of DeviceTree::lu_interchanges
static_assert(kThreads / kSmallNb <= 32);

// The trailing update of the blocked small-front kernels after a panel of w ≤ kSmallNb
// pivot columns ending at c0: F(i, c) −= Σ_{p<w} L(i, p) · V(p, c) for the rows i ∈ [c0, m)
// and the columns c ∈ [c0, m) (lower: c ≤ i only) of F (entry (i, c) at F[at(i, c)]), V(p, c) =
// col_v(p, c) and L(i, p) = row_l(i, p) (from shared memory, or from F in the pool). By the whole
// block rather than one thread per row: the nr = m − c0 trailing rows times ⌊blockDim.x / nr⌋
// groups of columns (thread t: row c0 + t mod nr, columns c0 + t div nr + groups·q), four columns'
// loads in flight at once. Each entry takes its w products in the order p = 0, 1, …, as one thread
// per row did: the same result bit for bit. Needs m ≤ blockDim.x.
template <class At, class ColV, class RowL>
__device__ __forceinline__ void trailing_update(double* F, At at, std::int64_t m, std::int64_t c0,
                                                int w, ColV col_v, bool lower, RowL row_l) {
  const std::int64_t nr = m - c0;
  if (nr <= 0) return;
  const std::int64_t groups = blockDim.x / nr;  // ≥ 1: nr < m ≤ blockDim.x
  const std::int64_t t = threadIdx.x;
  if (t >= groups * nr) return;
  const std::int64_t ri = c0 + t % nr;
  const std::int64_t end = lower ? ri + 1 : m;  // columns [c0, end) of row ri
  double l[kSmallNb];
#pragma unroll
  for (int p = 0; p < kSmallNb; ++p) l[p] = p < w ? row_l(ri, p) : 0.0;
  std::int64_t c = c0 + t / nr;
  for (; c + 3 * groups < end; c += 4 * groups) {
    double a[4];
#pragma unroll
    for (int q = 0; q < 4; ++q) a[q] = F[at(ri, c + q * groups)];
#pragma unroll
    for (int q = 0; q < 4; ++q) {
#pragma unroll
      for (int p = 0; p < kSmallNb; ++p)
        if (p < w) a[q] -= l[p] * col_v(p, c + q * groups);
    }
#pragma unroll
    for (int q = 0; q < 4; ++q) F[at(ri, c + q * groups)] = a[q];
  }
  for (; c < end; c += groups) {
    double acc = F[at(ri, c)];
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p)
      if (p < w) acc -= l[p] * col_v(p, c);
    F[at(ri, c)] = acc;
  }
}
// Where entry (i, c) of a front lies: column-major with leading dimension ld (a front in the
// pool), or the lower triangle's columns one after another (PackedLower, a Cholesky front in
// shared memory: column c holds rows [c, m) and starts at c·(2m − c − 1)/2 + c, so that
// (i, c) is at c·(2m − c − 1)/2 + i). The packed triangle takes about half a square's room,
// so that fronts of up to ~230 rows fit an H100's or H200's shared memory per block.
struct ColumnMajor {
  std::int64_t ld;
  __device__ std::int64_t operator()(std::int64_t i, std::int64_t c) const { return c * ld + i; }
};
struct PackedLower {
  int m;
  __device__ int operator()(std::int64_t i, std::int64_t c) const {
    const int ci = static_cast<int>(c);
    return ci * (2 * m - ci - 1) / 2 + static_cast<int>(i);
  }
};
// Doubles of a packed lower triangle of m rows (PackedLower).
__host__ __device__ constexpr std::int64_t packed_lower_size(std::int64_t m) {
  return m * (m + 1) / 2;
}

template <class At>
__device__ void llt_front_blocked(double* F, At at, std::int64_t m, std::int64_t k,
                                  std::int64_t* info, double (*lsh)[kThreads]) {
  // lsh[p][row]: the panel's columns, L(row, j0 + p) (the kernel's shared buffer)
  __shared__ int sfail;
  const std::int64_t i = threadIdx.x;  // this thread's row
  const bool row = i < m;
  if (threadIdx.x == 0) sfail = 0;
  __syncthreads();
  for (std::int64_t j0 = 0; j0 < k; j0 += kSmallNb) {
    const int w = static_cast<int>(k - j0 < kSmallNb ? k - j0 : kSmallNb);
    double r[kSmallNb];
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p)
      r[p] = (p < w && row && i >= j0 + p) ? F[at(i, j0 + p)] : 0.0;
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p) {
      if (p < w) {
        const std::int64_t j = j0 + p;
        if (i == j) {
          if (!(r[p] > 0.0)) {
            sfail = 1;
            *info = j;
          } else {
            r[p] = sqrt(r[p]);
          }
          lsh[p][i] = r[p];
        }
        __syncthreads();
        if (sfail) return;
        if (i > j && row) r[p] = PivotReciprocal(lsh[p][j])(r[p]);
        if (i > j && i < kThreads) lsh[p][i] = row ? r[p] : 0.0;
        __syncthreads();
        // the panel's later columns: r[q] -= L(i, j) L(j0 + q, j) for rows at or below them
#pragma unroll
        for (int q = p + 1; q < kSmallNb; ++q)
          if (q < w && row && i >= j0 + q) r[q] -= r[p] * lsh[p][j0 + q];
      }
    }
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p)
      if (p < w && row && i >= j0 + p) F[at(i, j0 + p)] = r[p];
    // trailing lower triangle: F(i, c) −= Σ_p L(i, j0 + p) L(c, j0 + p), j0 + w ≤ c ≤ i;
    // every row's panel is in lsh by now
    trailing_update(
        F, at, m, j0 + w, w, [&](int p, std::int64_t c) { return lsh[p][c]; }, true,
        [&](std::int64_t ri, int p) { return lsh[p][ri]; });
    __syncthreads();  // the next panel reads what this one wrote, and reuses lsh
  }
}

// d = a·b + c on the FP64 tensor cores (PTX mma.m8n8k4 with .f64: an 8 × 4 A, a 4 × 8 B and
// an 8 × 8 C), in the PTX ISA's fragment layout for that shape: with g = lane / 4 and
// t = lane % 4, a = A(g, t), b = B(t, g), and (c0, c1) = C(g, 2t), C(g, 2t + 1) (d the same).
// Every lane of the warp takes part.
__device__ __forceinline__ void mma_8x8x4(double& d0, double& d1, double a, double b, double c0,
                                          double c1) {
  asm volatile("mma.sync.aligned.m8n8k4.row.col.f64.f64.f64.f64 {%0, %1}, {%2}, {%3}, {%4, %5};"
               : "=d"(d0), "=d"(d1)
               : "d"(a), "d"(b), "d"(c0), "d"(c1));
}

// lu_front_blocked's trailing update for a front in shared memory, on the FP64 tensor cores:
// F(i, c) −= Σ_{p<w} F(i, j0 + p) · F(j0 + p, c) for the rows and columns [j0 + w, m) (the
// panel's L columns times its U rows; F column-major, leading dimension ld). The trailing
// block is cut into 8 × 8 tiles; a warp takes a row of tiles and kChunk consecutive column
// tiles, keeps −L's two 8 × 4 fragments in registers and, per tile, reads U's two 4 × 8
// fragments and the tile, adds the two products (mma_8x8x4) and writes the tile back.
// Entries past row or column m and pivots past w enter as zeros and are not written. The
// same tiles and the same two products per entry whatever the block's width: the result
// does not depend on it.
__device__ __forceinline__ void lu_trailing_update_mma(double* F, int ld, int m, int j0, int w) {
  const int c0 = j0 + w, nr = m - c0;
  if (nr <= 0) return;
  constexpr int kChunk = 4;  // column tiles a warp takes at once
  const int tiles = (nr + 7) / 8, chunks = (tiles + kChunk - 1) / kChunk;
  const int lane = static_cast<int>(threadIdx.x) % kWarp,
            warps = static_cast<int>(blockDim.x) / kWarp;
  const int g = lane >> 2, t = lane & 3;
  for (int u = static_cast<int>(threadIdx.x) / kWarp; u < tiles * chunks; u += warps) {
    const int ti = u % tiles, ch = u / tiles;
    const int r = c0 + 8 * ti + g;  // this lane's row of A and of the tiles
    const bool row_in = r < m;
    const double a0 = row_in && t < w ? -F[(j0 + t) * ld + r] : 0.0;
    const double a1 = row_in && t + 4 < w ? -F[(j0 + t + 4) * ld + r] : 0.0;
    // every fragment and tile of the chunk loaded before any tile is written back (the
    // tiles are disjoint, and U's rows are not written here): the loads of one tile do not
    // wait for the stores of the one before
    double b0[kChunk], b1[kChunk], x0[kChunk], x1[kChunk];
    bool in0[kChunk], in1[kChunk];
#pragma unroll
    for (int q = 0; q < kChunk; ++q) {
      const int tj = ch * kChunk + q;
      const bool tile = tj < tiles;
      const int cb = c0 + 8 * tj + g;  // this lane's column of B
      b0[q] = tile && cb < m && t < w ? F[cb * ld + j0 + t] : 0.0;
      b1[q] = tile && cb < m && t + 4 < w ? F[cb * ld + j0 + t + 4] : 0.0;
      const int cc = c0 + 8 * tj + 2 * t;  // this lane's two columns of the tile
      in0[q] = tile && row_in && cc < m;
      in1[q] = tile && row_in && cc + 1 < m;
      x0[q] = in0[q] ? F[cc * ld + r] : 0.0;
      x1[q] = in1[q] ? F[(cc + 1) * ld + r] : 0.0;
    }
#pragma unroll
    for (int q = 0; q < kChunk; ++q) {
      if (ch * kChunk + q < tiles) {  // the same for the whole warp
        mma_8x8x4(x0[q], x1[q], a0, b0[q], x0[q], x1[q]);
        mma_8x8x4(x0[q], x1[q], a1, b1[q], x0[q], x1[q]);
      }
    }
#pragma unroll
    for (int q = 0; q < kChunk; ++q) {
      const int cc = c0 + 8 * (ch * kChunk + q) + 2 * t;
      if (in0[q]) F[cc * ld + r] = x0[q];
      if (in1[q]) F[(cc + 1) * ld + r] = x1[q];
    }
  }
}

// The rest of lu_front_blocked's pivot step p (pivot column j = j0 + p) for this thread's
// row i, once the pivot row's panel entries u are in shared memory: the pivot u[p], or
// ±static_pivot in its place (counted in thread 0's `count`), stored in row j, and below
// it the multiplier and the update of the panel's later columns.
__device__ __forceinline__ void lu_pivot_step(double (&r)[kSmallNb], const double* u, int p, int w,
                                              int i, int j, bool row, double static_pivot,
                                              int& count) {
  double piv = u[p];
  if (needs_static_pivot(piv, static_pivot)) {  // static_pivoted, counted once
    if (i == 0) ++count;
    piv = static_pivot_value(piv, static_pivot);
  }
  if (i == j) r[p] = piv;
  if (row && i > j) {
    r[p] = PivotReciprocal(piv)(r[p]);
#pragma unroll
    for (int q = p + 1; q < kSmallNb; ++q)
      if (q < w) r[q] -= r[p] * u[q];
  }
}

// Blocked right-looking partial LU of a small front (m ≤ blockDim.x rows, F full), one
// row per thread as llt_front_blocked, with threshold partial pivoting among the fully
// summed rows [j, k) and static pivoting exactly as lu_columns (the diagonal when it is at
// least `threshold` times the largest magnitude, else that largest, first row on ties;
// |pivot| < static_pivot replaced by ±static_pivot). A front's time is the chain of its
// pivot steps, so each panel is first factored on its diagonal, one barrier a step and no
// search, every candidate row checking that the threshold test would keep the diagonal
// (after a matching and scaling it mostly does); only a panel where some row beats its
// diagonal (or one that interchanged rows in the front's last factorization) is factored
// again step by step, each step trying its diagonal first in the same way (two barriers)
// and searching only when a row beats it: two more barriers and no global memory, the
// search a shuffle reduction in the warps that hold candidate rows, whose maxima every
// thread then reads; the pivot row and row j trade their panel registers through shared
// memory, and the pivot row is read there by all. Either way the multipliers and the
// panel's later columns are updated in registers, with the same operations. The
// interchanges of the columns outside the panel are made once per panel (LAPACK's DLASWP
// after each panel of DGETRF): thread c takes column c, reads the rows the panel moved from
// where they were (src, the panel's net row permutation), and, for a trailing column,
// solves the panel's unit L₁₁ for its U rows in the same registers; then the rows below the
// panel get the rank-w product, each trailing entry read and written once per panel (Golub
// & Van Loan, 4th ed., §3.4.7). The front is in the pool (ld = m; the U rows for the update
// also go to ush) or copied into shared memory by the caller (kShared: ld of the copy). In
// the pool every entry gets the operations of the unblocked form in the same order; in
// shared memory the rank-w product runs on the FP64 tensor cores (lu_trailing_update_mma),
// whose sums are rounded otherwise. Either way the results do not change with the block's
// width.
template <bool kShared>
__device__ void lu_front_blocked(double* F, int ld, int m, int k, double static_pivot,
                                 double threshold, std::int64_t* perm, std::int64_t* perturbed,
                                 double (*ush)[kThreads], std::uint32_t* interchanges) {
  __shared__ double l11[kSmallNb][kSmallNb];  // L(j0 + q, j0 + p), q > p
  __shared__ double sdiag;                    // |F(j, j)| at the current pivot step
  __shared__ double xch[2][kSmallNb];         // [1]: the pivot row's panel entries; [0]: row j's
  __shared__ double sval[kThreads / kWarp];
  __shared__ int sidx[kThreads / kWarp];
  // row j's panel entries when the panel is tried on its diagonal, by step parity: a step
  // writes the other half than the step before, which slower threads may still read
  __shared__ double xdiag[2][kSmallNb];
  __shared__ int src[kThreads];   // rows [j0, k): the row that position r held at the panel's start
  __shared__ int ipiv[kSmallNb];  // the panel's pivot rows
  __shared__ int lperm[kThreads];  // the front's row permutation, rows [0, k)
  const int i = threadIdx.x;       // this thread's row, and the column it swaps and solves
  const bool row = i < m;
  const int wid = i / kWarp;
  int npert = 0;  // static pivots (thread 0's count)
  // panels that interchanged rows in the front's last factorization are searched straight
  // away (read by all before thread 0 may write it, after the last barrier)
  const std::uint32_t searched_before = interchanges ? *interchanges : 0u;
  std::uint32_t searched_now = 0;  // thread 0's
  if (i < k) lperm[i] = i;
  for (int j0 = 0; j0 < k; j0 += kSmallNb) {
    const int w = k - j0 < kSmallNb ? k - j0 : kSmallNb;
    double r[kSmallNb];
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p) r[p] = (p < w && row) ? F[(j0 + p) * ld + i] : 0.0;
    if (i >= j0 && i < k) src[i] = i;
    // First the panel on its diagonal: row j's entries through xdiag, no search. Every
    // candidate row checks that it would not have been chosen, i.e. that the threshold
    // test keeps the diagonal; when all do, the steps are those of the search below, which
    // would have kept every diagonal.
    const std::uint32_t panel_bit = 1u << (j0 / kSmallNb);
    const bool diagonal_first = !(searched_before & panel_bit);
    int spert = 0;  // thread 0's static pivots on the diagonal
    bool beaten = false;
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p) {
      if (diagonal_first && p < w) {
        const int j = j0 + p;
        double* x = xdiag[p % 2];
        if (i == j) {
#pragma unroll
          for (int q = 0; q < kSmallNb; ++q) x[q] = r[q];
        }
        __syncthreads();
        const double dj = x[p];
        if (i > j && i < k) {  // a NaN candidate is never chosen
          const double a = fabs(r[p]);
          if (a == a && !(fabs(dj) >= threshold * a)) beaten = true;
        }
        lu_pivot_step(r, x, p, w, i, j, row, static_pivot, spert);
      }
    }
    const bool search = !diagonal_first || __syncthreads_or(beaten);
    if (!search) {
      npert += spert;
      if (i < w) ipiv[i] = j0 + i;
    } else if (diagonal_first) {  // a row beat its diagonal: the panel again from F, searched
#pragma unroll
      for (int p = 0; p < kSmallNb; ++p) r[p] = (p < w && row) ? F[(j0 + p) * ld + i] : 0.0;
    }
    bool interchanged = false;         // thread 0's: the search moved a row
    const int w_hi = (k - 1) / kWarp;  // the last warp with fully summed rows
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p) {
      if (search && p < w) {
        const int j = j0 + p;
        // this step's diagonal first: when no candidate row beats it, the search would keep
        // it too, and the step is a diagonal step (two barriers, no search)
        double* x = xdiag[p % 2];
        if (i == j) {
#pragma unroll
          for (int q = 0; q < kSmallNb; ++q) x[q] = r[q];
        }
        __syncthreads();
        bool beats = false;
        if (i > j && i < k) {  // a NaN candidate is never chosen
          const double a = fabs(r[p]);
          beats = a == a && !(fabs(x[p]) >= threshold * a);
        }
        if (!__syncthreads_or(beats)) {
          if (i == 0) ipiv[p] = j;
          lu_pivot_step(r, x, p, w, i, j, row, static_pivot, npert);
          continue;
        }
        const int w_lo = j / kWarp;  // warps [w_lo, w_hi] hold the candidates [j, k)
        if (wid >= w_lo && wid <= w_hi) {
          double v = (i >= j && i < k) ? fabs(r[p]) : -1.0;
          if (!(v >= 0.0)) v = -1.0;  // a NaN is never chosen (block_argmax does the same)
          int at = i;
          for (int off = kWarp / 2; off > 0; off /= 2) {
            const double ov = __shfl_down_sync(0xffffffffu, v, off);
            const int oi = __shfl_down_sync(0xffffffffu, at, off);
            if (ov > v || (ov == v && oi < at)) {
              v = ov;
              at = oi;
            }
          }
          if (i % kWarp == 0) {
            sval[wid] = v;
            sidx[wid] = at;
          }
        }
        if (i == j) sdiag = fabs(r[p]);
        __syncthreads();
        // every thread the same choice: later warps hold later rows, so a tie stays with
        // the first
        double bv = sval[w_lo];
        int pr = sidx[w_lo];
        for (int q = w_lo + 1; q <= w_hi; ++q)
          if (sval[q] > bv) {
            bv = sval[q];
            pr = sidx[q];
          }
        if (bv < 0 || sdiag >= threshold * bv) pr = j;  // NaNs compare false: row j stays
        if (i == pr) {
#pragma unroll
          for (int q = 0; q < kSmallNb; ++q) xch[1][q] = r[q];
        }
        if (i == j && pr != j) {
#pragma unroll
          for (int q = 0; q < kSmallNb; ++q) xch[0][q] = r[q];
        }
        if (i == 0) {
          ipiv[p] = pr;
          if (pr != j) {
            interchanged = true;
            const int tp = lperm[j];
            lperm[j] = lperm[pr];
            lperm[pr] = tp;
            const int ts = src[j];
            src[j] = src[pr];
            src[pr] = ts;
          }
        }
        __syncthreads();
        if (pr != j && (i == j || i == pr)) {
#pragma unroll
          for (int q = 0; q < kSmallNb; ++q) r[q] = xch[i == j ? 1 : 0][q];
        }
        lu_pivot_step(r, xch[1], p, w, i, j, row, static_pivot, npert);
      }
    }
    // the panel back to F, and L₁₁ to shared memory (only now: a later interchange in the
    // panel moves rows' earlier multipliers too)
#pragma unroll
    for (int p = 0; p < kSmallNb; ++p) {
      if (p < w && row) F[(j0 + p) * ld + i] = r[p];
      if (p < w && i > j0 + p && i < j0 + w) l11[i - j0][p] = r[p];
    }
    if (interchanged) searched_now |= panel_bit;
    __syncthreads();
    // column c = i outside the panel: its moved rows, each read from where it was (all
    // reads before any write), and for a trailing column its U rows by forward substitution
    // with L₁₁
    const int c = i;
    if (c < m && (c < j0 || c >= j0 + w)) {
      double* col = F + static_cast<std::int64_t>(c) * ld;
      double u[kSmallNb], below[kSmallNb];
#pragma unroll
      for (int q = 0; q < kSmallNb; ++q) u[q] = q < w ? col[src[j0 + q]] : 0.0;
#pragma unroll
      for (int p = 0; p < kSmallNb; ++p)
        below[p] = (p < w && ipiv[p] >= j0 + w) ? col[src[ipiv[p]]] : 0.0;
      if (c >= j0 + w) {
#pragma unroll
        for (int q = 1; q < kSmallNb; ++q)
#pragma unroll
          for (int p = 0; p < q; ++p)
            if (q < w) u[q] -= l11[q][p] * u[p];
      }
#pragma unroll
      for (int q = 0; q < kSmallNb; ++q)
        if (q < w) {
          col[j0 + q] = u[q];
          if (!kShared && c >= j0 + w) ush[q][c] = u[q];
        }
#pragma unroll
      for (int p = 0; p < kSmallNb; ++p)
        if (p < w && ipiv[p] >= j0 + w) col[ipiv[p]] = below[p];  // repeats write one value
    }
    __syncthreads();
    // the rows below the panel: F(i, c) −= Σ_p L(i, j0 + p) U(j0 + p, c), L(i, ·) read back
    // from F (stored above)
    if constexpr (kShared)
      lu_trailing_update_mma(F, ld, m, j0, w);
    else
      trailing_update(
          F, ColumnMajor{ld}, m, j0 + w, w, [&](int p, std::int64_t c) { return ush[p][c]; }, false,
          [&](std::int64_t ri, int p) { return F[(j0 + p) * ld + ri]; });
    __syncthreads();  // the next panel reads what this one wrote, and reuses the buffers
  }
  if (i < k) perm[i] = lperm[i];
  if (i == 0 && interchanges && searched_now != searched_before) *interchanges = searched_now;
  if (i == 0) *perturbed += npert;
}

// kBlock threads: kThreads, two blocks per SM at least (a register cap of 128: a level of
// many small fronts otherwise runs one block per SM, in waves), or kWideThreads, one per SM
// at the same cap (a launch of few fronts, launch_factor_small). Threads past the front's
// rows take part in the trailing updates and the barriers only.
template <int kBlock>
__global__ void __launch_bounds__(kBlock, kThreads * 2 / kBlock)
    factor_small_kernel(DeviceTree t, const std::int64_t* positions, double* pool, bool lu,
                        double static_pivot, double threshold, std::int64_t* info,
                        std::int64_t* perturbed, std::int64_t* perm,
                        const std::int64_t* perm_offset) {
  const std::int64_t i = blockIdx.x;
  const std::int64_t pos = positions[i];
  const std::int64_t f = t.fronts[pos];
  const std::int64_t m = t.n_rows[f], k = t.n_pivots[f];
  double* F = pool + t.pos_offset[pos];
  if (threadIdx.x == 0) {
    info[i] = -1;
    perturbed[i] = 0;
  }
  __shared__ double panel[kSmallNb][kThreads];  // the blocked kernels' panel buffer
  if (lu) {
    std::int64_t* p = perm + perm_offset[i];
    for (std::int64_t r = threadIdx.x; r < k; r += blockDim.x) p[r] = r;
    __syncthreads();
    if (m <= blockDim.x)
      lu_front_blocked<false>(F, static_cast<int>(m), static_cast<int>(m), static_cast<int>(k),
                              static_pivot, threshold, p, perturbed + i, panel,
                              t.lu_interchanges ? t.lu_interchanges + f : nullptr);
    else
      lu_columns(F, m, m, k, 0, k, m, m, static_pivot, threshold, p, perturbed + i);
  } else {
    __syncthreads();
    if (m <= blockDim.x)
      llt_front_blocked(F, ColumnMajor{m}, m, k, info + i, panel);
    else
      llt_front(F, m, k, info + i);
  }
}

// The leading dimension of a front's copy in shared memory: odd, so that the threads of a
// warp reading along a row (a column each, the interchanges and U rows) hit different banks.
__host__ __device__ constexpr int shared_ld(int m) { return m | 1; }

// Bytes of dynamic shared memory for a copy of a front of m rows (shared_ld(m) · m doubles).
std::size_t shared_front_bytes(std::int64_t m) {
  return sizeof(double) * static_cast<std::size_t>(m) *
         static_cast<std::size_t>(shared_ld(static_cast<int>(m)));
}

// Small LU fronts each copied into shared memory, factored there (lu_front_blocked<true>)
// and copied back: a pivot step and the trailing update then wait for shared memory, not
// for global memory, many times per front. Dynamic shared memory of
// shared_ld(max_rows) · max_rows doubles. kBlock as factor_small_kernel's.
template <int kBlock>
__global__ void __launch_bounds__(kBlock, kThreads * 2 / kBlock)
    lu_small_shared_kernel(DeviceTree t, const std::int64_t* positions, double* pool,
                           double static_pivot, double threshold, std::int64_t* info,
                           std::int64_t* perturbed, std::int64_t* perm,
                           const std::int64_t* perm_offset) {
  extern __shared__ double fs[];
  const std::int64_t b = blockIdx.x;
  const std::int64_t pos = positions[b];
  const std::int64_t f = t.fronts[pos];
  const int m = static_cast<int>(t.n_rows[f]), k = static_cast<int>(t.n_pivots[f]);
  const int ld = shared_ld(m);
  double* F = pool + t.pos_offset[pos];
  if (threadIdx.x == 0) {
    info[b] = -1;
    perturbed[b] = 0;
  }
  // the front in and out in column-major order, eight loads in flight per thread
  constexpr int kInFlight = 8;
  const int total = m * m, step = static_cast<int>(blockDim.x);
  for (int at = threadIdx.x; at < total; at += kInFlight * step) {
    double v[kInFlight];
#pragma unroll
    for (int u = 0; u < kInFlight; ++u) {
      const int x = at + u * step;
      v[u] = x < total ? F[x] : 0.0;
    }
#pragma unroll
    for (int u = 0; u < kInFlight; ++u) {
      const int x = at + u * step;
      if (x < total) {
        const int c = x / m;
        fs[c * ld + (x - c * m)] = v[u];
      }
    }
  }
  __syncthreads();
  lu_front_blocked<true>(fs, ld, m, k, static_pivot, threshold, perm + perm_offset[b],
                         perturbed + b, nullptr,
                         t.lu_interchanges ? t.lu_interchanges + f : nullptr);
  __syncthreads();
  for (int x = threadIdx.x; x < total; x += step) {
    const int c = x / m;
    F[x] = fs[c * ld + (x - c * m)];
  }
}

// Small Cholesky fronts each copied into shared memory as their packed lower triangle
// (PackedLower), factored there (llt_front_blocked) and copied back: the Cholesky
// counterpart of lu_small_shared_kernel, for the launches that are not fused. Dynamic
// shared memory of llt_fused_bytes(max_rows): the triangle, then llt_front_blocked's panel
// buffer. kBlock as factor_small_kernel's.
template <int kBlock>
__global__ void __launch_bounds__(kBlock, kThreads * 2 / kBlock)
    llt_small_shared_kernel(DeviceTree t, const std::int64_t* positions, double* pool,
                            std::int64_t* info, std::int64_t* perturbed) {
  extern __shared__ double fs[];
  const std::int64_t b = blockIdx.x;
  const std::int64_t pos = positions[b];
  const std::int64_t f = t.fronts[pos];
  const int m = static_cast<int>(t.n_rows[f]), k = static_cast<int>(t.n_pivots[f]);
  double* F = pool + t.pos_offset[pos];
  if (threadIdx.x == 0) {
    info[b] = -1;
    perturbed[b] = 0;
  }
  // the lower triangle in and out a column per warp, its lanes down the column
  const PackedLower at{m};
  const int lane = static_cast<int>(threadIdx.x) % kWarp,
            warps = static_cast<int>(blockDim.x) / kWarp;
  for (int c = static_cast<int>(threadIdx.x) / kWarp; c < m; c += warps) {
    const double* src = F + static_cast<std::int64_t>(c) * m;
    double* dst = fs + at(0, c);
    for (int i = c + lane; i < m; i += kWarp) dst[i] = src[i];
  }
  __syncthreads();
  auto* lsh = reinterpret_cast<double(*)[kThreads]>(fs + packed_lower_size(m));
  llt_front_blocked(fs, at, m, k, info + b, lsh);
  __syncthreads();
  for (int c = static_cast<int>(threadIdx.x) / kWarp; c < m; c += warps) {
    double* dst = F + static_cast<std::int64_t>(c) * m;
    const double* src = fs + at(0, c);
    for (int i = c + lane; i < m; i += kWarp) dst[i] = src[i];
  }
}

// A launch group of small LU (kLu) or Cholesky fronts in one launch (launch_small_fused):
// each block assembles its front straight into shared memory in assemble_kernel's order of
// additions (zeros, the original entries at distinct places, then each child's block —
// Cholesky: its lower triangle — one child after another), factors it there
// (lu_front_blocked<true>, llt_front_blocked) and writes out what the separate launches
// would have left: the panel (and U12) into the factor, the contribution block (Cholesky:
// its lower triangle, as store_cb_kernel) into the arena, the pivots' diagonal entries. One
// launch per group instead of four (assembly, factorization, store, pack), and no trip of
// the front through the pool. Dynamic shared memory: LU as lu_small_shared_kernel's;
// Cholesky the front's lower triangle packed (PackedLower) and llt_front_blocked's panel
// buffer after it (llt_fused_bytes).
constexpr std::size_t kLltPanelBytes = sizeof(double) * kSmallNb * kThreads;
std::size_t llt_fused_bytes(std::int64_t m) {
  return sizeof(double) * static_cast<std::size_t>(packed_lower_size(m)) + kLltPanelBytes;
}
template <int kBlock, bool kLu>
__global__ void __launch_bounds__(kBlock, kThreads * 2 / kBlock)
    small_fused_kernel(DeviceTree t, const std::int64_t* positions, const double* values,
                       double static_pivot, double threshold, std::int64_t* info,
                       std::int64_t* perturbed, std::int64_t* perm, const std::int64_t* perm_offset,
                       const std::int64_t* panel_offset, double* panels,
                       const std::int64_t* diag_offset, double* diag) {
  extern __shared__ double fs[];
  const std::int64_t b = blockIdx.x;
  const std::int64_t f = t.fronts[positions[b]];
  const int m = static_cast<int>(t.n_rows[f]), k = static_cast<int>(t.n_pivots[f]);
  const int ld = shared_ld(m), mc = m - k;
  const int tid = threadIdx.x, step = static_cast<int>(blockDim.x);
  const int warp = tid / kWarp, lane = tid % kWarp, warps = step / kWarp;
  if (tid == 0) {
    info[b] = -1;
    perturbed[b] = 0;
  }
  // LU: the square with leading dimension ld; Cholesky: the packed lower triangle
  auto column = [&](int c) { return kLu ? c * ld : PackedLower{m}(0, c); };
  const int size = kLu ? m * ld : static_cast<int>(packed_lower_size(m));
  for (int x = tid; x < size; x += step) fs[x] = 0.0;
  __syncthreads();
  // the original entries (distinct destinations) and each child's block, kUnroll loads in
  // flight per thread before their additions: the loads' latency, not the additions, is
  // what an assembly waits for
  constexpr int kUnroll = 4;
  auto add_entry = [&](std::int64_t d, double v) {
    const int di = static_cast<int>(d), c = di / m;
    fs[column(c) + (di - c * m)] += v;
  };
  {
    const std::int64_t e1 = t.entry_offsets[f + 1];
    std::int64_t e = t.entry_offsets[f] + tid;
    for (; e + (kUnroll - 1) * step < e1; e += kUnroll * step) {
      std::int64_t d[kUnroll], from[kUnroll];
      double v[kUnroll];
#pragma unroll
      for (int u = 0; u < kUnroll; ++u) {
        d[u] = t.entry_dst[e + u * step];
        from[u] = t.entry_src[e + u * step];
      }
#pragma unroll
      for (int u = 0; u < kUnroll; ++u) v[u] = values[from[u]];
#pragma unroll
      for (int u = 0; u < kUnroll; ++u) add_entry(d[u], v[u]);
    }
    for (; e < e1; e += step) add_entry(t.entry_dst[e], values[t.entry_src[e]]);
  }
  __syncthreads();
  for (std::int64_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const std::int64_t c = t.children[q];
    const int cm = static_cast<int>(t.n_rows[c] - t.n_pivots[c]);
    if (cm == 0) continue;
    const double* cb = t.cb_ptr[c];
    const std::int64_t* rel = t.rel + t.rel_offsets[c];
    for (int jj = warp; jj < cm; jj += warps) {
      double* col = fs + column(static_cast<int>(rel[jj]));
      const double* src = cb + static_cast<std::int64_t>(jj) * cm;
      int ii = (kLu ? 0 : jj) + lane;  // Cholesky: the block's lower triangle
      for (; ii + (kUnroll - 1) * kWarp < cm; ii += kUnroll * kWarp) {
        std::int64_t to[kUnroll];
        double v[kUnroll];
#pragma unroll
        for (int u = 0; u < kUnroll; ++u) {
          to[u] = rel[ii + u * kWarp];
          v[u] = src[ii + u * kWarp];
        }
#pragma unroll
        for (int u = 0; u < kUnroll; ++u) col[to[u]] += v[u];  // distinct rows
      }
      for (; ii < cm; ii += kWarp) col[rel[ii]] += src[ii];
    }
    __syncthreads();  // one child after another: no two additions to one entry collide
  }
  if constexpr (kLu) {
    lu_front_blocked<true>(fs, ld, m, k, static_pivot, threshold, perm + perm_offset[b],
                           perturbed + b, nullptr,
                           t.lu_interchanges ? t.lu_interchanges + f : nullptr);
  } else {
    (void)static_pivot, (void)threshold, (void)perm, (void)perm_offset;
    auto* lsh = reinterpret_cast<double(*)[kThreads]>(fs + size);
    llt_front_blocked(fs, PackedLower{m}, m, k, info + b, lsh);
  }
  __syncthreads();
  double* panel = panels + panel_offset[b];
  for (int x = tid; x < m * k; x += step) {  // L11\U11 (L11) and L21: columns [0, k), ld m
    const int c = x / m, i = x - c * m;
    panel[x] = kLu || i >= c ? fs[column(c) + i] : 0.0;  // Cholesky: zeros above L11
  }
  if constexpr (kLu) {
    double* u12 = panel + static_cast<std::int64_t>(m) * k;
    for (int x = tid; x < k * mc; x += step) {  // U12(i, j) = F(i, k + j), ld k
      const int j = x / k;
      u12[x] = fs[(k + j) * ld + (x - j * k)];
    }
  }
  double* d = diag + diag_offset[b];
  for (int i = tid; i < k; i += step) d[i] = fs[column(i) + i];
  if (t.parent[f] >= 0 && mc > 0) {  // the contribution block, ld mc
    double* out = t.cb_ptr[f];
    for (int x = tid; x < mc * mc; x += step) {
      const int j = x / mc, i = x - j * mc;
      if (kLu || i >= j) out[x] = fs[column(k + j) + k + i];
    }
  }
}

__global__ void lu_panel_kernel(double* f, std::int64_t m, std::int64_t k, std::int64_t p0,
                                std::int64_t w, double static_pivot, double threshold,
                                std::int64_t* perm, std::int64_t* perturbed) {
  lu_columns(f, m, m, k, p0, w, p0 + w, m, static_pivot, threshold, perm, perturbed);
}

__global__ void lu_slab_kernel(double* s, std::int64_t r, std::int64_t w, std::int64_t kk,
                               double static_pivot, double threshold, std::int64_t* perm,
                               std::int64_t* perturbed) {
  lu_columns(s, r, r, kk, 0, w, w, w, static_pivot, threshold, perm, perturbed);
}

}  // namespace

// Columns per slice: the widest (kMaxSliceCols) that still gives the launch about
// kTargetBlocks blocks, and never below kMinSliceCols.
std::int64_t slice_width(std::int64_t count, std::int64_t max_rows) {
  std::int64_t w = kMaxSliceCols;
  while (w > kMinSliceCols && count * ((max_rows + w - 1) / w) < kTargetBlocks) w /= 2;
  return w;
}

dim3 sliced_grid(std::int64_t count, std::int64_t max_rows, std::int64_t slice) {
  const std::int64_t slices = std::max<std::int64_t>(1, (max_rows + slice - 1) / slice);
  return dim3(static_cast<unsigned>(count), static_cast<unsigned>(slices));
}

void launch_assemble(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                     std::int64_t max_rows, const double* values, double* pool, bool symmetric,
                     cudaStream_t s) {
  if (count == 0) return;
  const std::int64_t w = slice_width(count, max_rows);
  assemble_kernel<<<sliced_grid(count, max_rows, w), kThreads, 0, s>>>(t, begin, w, values, pool,
                                                                       symmetric);
  STRATA_CUDA_LAUNCH();
}

void launch_store_cb(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                     std::int64_t max_rows, const double* pool, bool symmetric, cudaStream_t s) {
  if (count == 0) return;
  const std::int64_t w = slice_width(count, max_rows);
  store_cb_kernel<<<sliced_grid(count, max_rows, w), kThreads, 0, s>>>(t, begin, w, pool,
                                                                       symmetric);
  STRATA_CUDA_LAUNCH();
}

void launch_pack_panels(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                        std::int64_t max_rows, const double* pool,
                        const std::int64_t* staging_offset, double* staging, bool lu,
                        cudaStream_t s) {
  if (count == 0) return;
  const std::int64_t w = slice_width(count, max_rows);
  pack_panels_kernel<<<sliced_grid(count, max_rows, w), kThreads, 0, s>>>(
      t, begin, w, pool, staging_offset, staging, lu);
  STRATA_CUDA_LAUNCH();
}

namespace {
constexpr int kDevices = 64;
// per device: the shared-memory LU kernels' own (static) shared memory, bytes (0: not
// asked yet; lu_shared_max_rows sets it)
std::atomic<std::size_t>& static_bytes(int dev) {
  static std::atomic<std::size_t> bytes[kDevices];
  return bytes[dev];
}
}  // namespace

std::size_t lu_shared_static_bytes() {
  int dev = 0;
  STRATA_CUDA(cudaGetDevice(&dev));
  if (dev >= kDevices) return 0;
  if (static_bytes(dev).load(std::memory_order_acquire) == 0) (void)lu_shared_max_rows();
  return static_bytes(dev).load(std::memory_order_acquire);
}

// Per device: the most rows of a front the fused Cholesky kernel takes (0: not asked yet,
// −1: none; lu_shared_max_rows sets it).
std::atomic<int>& llt_fused_rows(int dev) {
  static std::atomic<int> rows[kDevices];
  return rows[dev];
}

// The most rows of a front lu_small_shared_kernel takes on the current device: its copy
// and the kernel's own shared memory within the device's opt-in limit per block (which the
// kernel is allowed once per device); also the fused Cholesky kernel's, whose front shares
// that room with its panel buffer (llt_fused_max_rows). Devices of one process may differ,
// so per device.
std::int64_t lu_shared_max_rows() {
  static std::atomic<int> rows[kDevices];  // 0: not asked yet
  int dev = 0;
  STRATA_CUDA(cudaGetDevice(&dev));
  if (dev < kDevices && rows[dev].load(std::memory_order_acquire) > 0) return rows[dev].load();
  int optin = 0;
  STRATA_CUDA(cudaDeviceGetAttribute(&optin, cudaDevAttrMaxSharedMemoryPerBlockOptin, dev));
  // the kernels that take a front in dynamic shared memory, beside their own
  const void* lu_kernels[] = {
      reinterpret_cast<const void*>(lu_small_shared_kernel<kThreads>),
      reinterpret_cast<const void*>(lu_small_shared_kernel<kWideThreads>),
      reinterpret_cast<const void*>(small_fused_kernel<kThreads, true>),
      reinterpret_cast<const void*>(small_fused_kernel<kWideThreads, true>)};
  const void* llt_kernels[] = {
      reinterpret_cast<const void*>(llt_small_shared_kernel<kThreads>),
      reinterpret_cast<const void*>(llt_small_shared_kernel<kWideThreads>),
      reinterpret_cast<const void*>(small_fused_kernel<kThreads, false>),
      reinterpret_cast<const void*>(small_fused_kernel<kWideThreads, false>)};
  cudaFuncAttributes attr{};
  for (const void* k : lu_kernels) {
    cudaFuncAttributes a{};
    STRATA_CUDA(cudaFuncGetAttributes(&a, k));
    attr.sharedSizeBytes = std::max(attr.sharedSizeBytes, a.sharedSizeBytes);
  }
  for (const void* k : llt_kernels) {
    cudaFuncAttributes a{};
    STRATA_CUDA(cudaFuncGetAttributes(&a, k));
    attr.sharedSizeBytes = std::max(attr.sharedSizeBytes, a.sharedSizeBytes);
  }
  if (dev < kDevices) static_bytes(dev).store(attr.sharedSizeBytes, std::memory_order_release);
  const std::size_t room = optin > static_cast<int>(attr.sharedSizeBytes)
                               ? static_cast<std::size_t>(optin) - attr.sharedSizeBytes
                               : 0;
  int m = 0;
  while (m < kThreads && shared_front_bytes(m + 1) <= room) ++m;
  if (m > 0) {
    const int bytes = static_cast<int>(shared_front_bytes(m));
    for (const void* k : lu_kernels)
      STRATA_CUDA(cudaFuncSetAttribute(k, cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
  }
  int ml = 0;
  while (ml < kThreads && llt_fused_bytes(ml + 1) <= room) ++ml;
  if (ml > 0) {
    const int bytes = static_cast<int>(llt_fused_bytes(ml));
    for (const void* k : llt_kernels)
      STRATA_CUDA(cudaFuncSetAttribute(k, cudaFuncAttributeMaxDynamicSharedMemorySize, bytes));
  }
  if (dev < kDevices) llt_fused_rows(dev).store(ml > 0 ? ml : -1, std::memory_order_release);
  if (dev < kDevices) rows[dev].store(m > 0 ? m : -1, std::memory_order_release);
  return m;
}

std::int64_t llt_fused_max_rows() {
  int dev = 0;
  STRATA_CUDA(cudaGetDevice(&dev));
  if (dev >= kDevices) return 0;
  if (llt_fused_rows(dev).load(std::memory_order_acquire) == 0) (void)lu_shared_max_rows();
  return std::max(llt_fused_rows(dev).load(std::memory_order_acquire), 0);
}

unsigned small_front_threads(std::int64_t count, std::int64_t max_rows, int max_threads,
                             std::size_t shared_bytes) {
  // a row per thread, in the fewest warps that hold the largest front (a power of two, as
  // block_argmax's tree needs): a pivot step's barriers then wait for fewer warps
  unsigned threads = kWarp;
  while (threads < kThreads && threads < max_rows) threads *= 2;
  // A launch of few fronts leaves SMs idle and each busy one latency-bound (one instruction
  // issued every ~8 cycles), with the trailing updates on at most one thread per row: wider
  // blocks, up to max_threads, spread them (trailing_update's column groups) while the
  // threads of the blocks that run at once stay within a quarter of the device's (512 per
  // SM). Fronts in shared memory: no more blocks run at once than the SMs' shared memory
  // holds (the kernels' own shared memory and the 1 KiB the device keeps per block beside
  // each front's copy), however many the launch has.
  if (max_threads <= 0) return threads;
  int dev = 0;
  STRATA_CUDA(cudaGetDevice(&dev));
  const int sms = multiprocessor_count(dev);
  std::int64_t running = count;
  if (shared_bytes > 0) {
    int per_sm = 0;
    STRATA_CUDA(cudaDeviceGetAttribute(&per_sm, cudaDevAttrMaxSharedMemoryPerMultiprocessor, dev));
    const std::size_t block = shared_bytes + lu_shared_static_bytes() + 1024;
    const auto fit = static_cast<std::int64_t>(static_cast<std::size_t>(per_sm) / block);
    running = std::min(count, static_cast<std::int64_t>(sms) * std::max<std::int64_t>(fit, 1));
  }
  const std::int64_t room = static_cast<std::int64_t>(sms) * kWideThreads;
  const unsigned cap = static_cast<unsigned>(std::min(max_threads, kWideThreads));
  while (2 * threads <= cap && running * 2 * static_cast<std::int64_t>(threads) <= room)
    threads *= 2;
  return threads;
}

void launch_factor_small(const DeviceTree& t, const std::int64_t* positions, std::int64_t count,
                         std::int64_t max_rows, double* pool, bool lu, double static_pivot,
                         double threshold, std::int64_t* info, std::int64_t* perturbed,
                         std::int64_t* perm, const std::int64_t* perm_offset, int max_threads,
                         cudaStream_t s) {
  if (count == 0) return;
  const bool shared = max_rows <= (lu ? lu_shared_max_rows() : llt_fused_max_rows());
  const std::size_t bytes =
      !shared ? 0 : (lu ? shared_front_bytes(max_rows) : llt_fused_bytes(max_rows));
  const unsigned threads = small_front_threads(count, max_rows, max_threads, bytes);
  const bool wide = threads > static_cast<unsigned>(kThreads);
  const unsigned blocks = static_cast<unsigned>(count);
  if (shared && !lu) {
    if (wide)
      llt_small_shared_kernel<kWideThreads>
          <<<blocks, threads, bytes, s>>>(t, positions, pool, info, perturbed);
    else
      llt_small_shared_kernel<kThreads>
          <<<blocks, threads, bytes, s>>>(t, positions, pool, info, perturbed);
    STRATA_CUDA_LAUNCH();
    return;
  }
  if (shared) {
    if (wide)
      lu_small_shared_kernel<kWideThreads><<<blocks, threads, bytes, s>>>(
          t, positions, pool, static_pivot, threshold, info, perturbed, perm, perm_offset);
    else
      lu_small_shared_kernel<kThreads><<<blocks, threads, bytes, s>>>(
          t, positions, pool, static_pivot, threshold, info, perturbed, perm, perm_offset);
    STRATA_CUDA_LAUNCH();
    return;
  }
  if (wide)
    factor_small_kernel<kWideThreads><<<blocks, threads, 0, s>>>(
        t, positions, pool, lu, static_pivot, threshold, info, perturbed, perm, perm_offset);
  else
    factor_small_kernel<kThreads><<<blocks, threads, 0, s>>>(
        t, positions, pool, lu, static_pivot, threshold, info, perturbed, perm, perm_offset);
  STRATA_CUDA_LAUNCH();
}

void launch_small_fused(const DeviceTree& t, bool lu, const std::int64_t* positions,
                        std::int64_t count, std::int64_t max_rows, const double* values,
                        double static_pivot, double threshold, std::int64_t* info,
                        std::int64_t* perturbed, std::int64_t* perm,
                        const std::int64_t* perm_offset, const std::int64_t* panel_offset,
                        double* panels, const std::int64_t* diag_offset, double* diag,
                        int max_threads, cudaStream_t s) {
  if (count == 0) return;
  if (max_rows > (lu ? lu_shared_max_rows() : llt_fused_max_rows()))
    throw InternalError("launch_small_fused: a front of " + std::to_string(max_rows) +
                        " rows does not fit shared memory");
  const std::size_t bytes = lu ? shared_front_bytes(max_rows) : llt_fused_bytes(max_rows);
  const unsigned threads = small_front_threads(count, max_rows, max_threads, bytes);
  const unsigned blocks = static_cast<unsigned>(count);
  const bool wide = threads > static_cast<unsigned>(kThreads);
  auto kernel =
      lu ? (wide ? small_fused_kernel<kWideThreads, true> : small_fused_kernel<kThreads, true>)
         : (wide ? small_fused_kernel<kWideThreads, false> : small_fused_kernel<kThreads, false>);
  kernel<<<blocks, threads, bytes, s>>>(t, positions, values, static_pivot, threshold, info,
                                        perturbed, perm, perm_offset, panel_offset, panels,
                                        diag_offset, diag);
  STRATA_CUDA_LAUNCH();
}

void launch_lu_panel(double* f, std::int64_t m, std::int64_t k, std::int64_t p0, std::int64_t w,
                     double static_pivot, double threshold, std::int64_t* perm,
                     std::int64_t* perturbed, cudaStream_t s) {
  lu_panel_kernel<<<1, kThreads, 0, s>>>(f, m, k, p0, w, static_pivot, threshold, perm, perturbed);
  STRATA_CUDA_LAUNCH();
}

namespace {
template <bool kReciprocal>
__global__ void divide_rn_kernel(const double* x, const double* d, std::int64_t n, double* q) {
  const std::int64_t i = blockIdx.x * static_cast<std::int64_t>(blockDim.x) + threadIdx.x;
  if (i < n) q[i] = kReciprocal ? PivotReciprocal(d[i])(x[i]) : divide_rn(x[i], d[i]);
}
}  // namespace

void launch_lu_slab(double* s_, std::int64_t r, std::int64_t w, std::int64_t kk,
                    double static_pivot, double threshold, std::int64_t* perm,
                    std::int64_t* perturbed, cudaStream_t s) {
  lu_slab_kernel<<<1, kThreads, 0, s>>>(s_, r, w, kk, static_pivot, threshold, perm, perturbed);
  STRATA_CUDA_LAUNCH();
}

}  // namespace strata::cuda

namespace strata::numeric {

namespace {
std::vector<double> device_quotients(const std::vector<double>& x, const std::vector<double>& d,
                                     bool reciprocal, const char* who) {
  if (x.size() != d.size())
    throw InvalidInput(std::string(who) + ": " + std::to_string(x.size()) + " dividends but " +
                       std::to_string(d.size()) + " divisors");
  STRATA_CUDA(cudaSetDevice(0));
  const std::size_t n = x.size();
  cuda::DeviceBuffer<double> X(n ? n : 1), D(n ? n : 1), Q(n ? n : 1);
  STRATA_CUDA(cudaMemcpy(X.data(), x.data(), n * sizeof(double), cudaMemcpyHostToDevice));
  STRATA_CUDA(cudaMemcpy(D.data(), d.data(), n * sizeof(double), cudaMemcpyHostToDevice));
  if (n > 0) {
    constexpr int kBlock = 256;
    const unsigned blocks = static_cast<unsigned>((n + kBlock - 1) / kBlock);
    if (reciprocal)
      cuda::divide_rn_kernel<true>
          <<<blocks, kBlock>>>(X.data(), D.data(), static_cast<std::int64_t>(n), Q.data());
    else
      cuda::divide_rn_kernel<false>
          <<<blocks, kBlock>>>(X.data(), D.data(), static_cast<std::int64_t>(n), Q.data());
    STRATA_CUDA_LAUNCH();
  }
  std::vector<double> q(n);
  STRATA_CUDA(cudaMemcpy(q.data(), Q.data(), n * sizeof(double), cudaMemcpyDeviceToHost));
  return q;
}
}  // namespace

std::vector<double> cuda_divide_rn(const std::vector<double>& x, const std::vector<double>& d) {
  return device_quotients(x, d, false, "cuda_divide_rn");
}

std::vector<double> cuda_pivot_reciprocal(const std::vector<double>& x,
                                          const std::vector<double>& d) {
  return device_quotients(x, d, true, "cuda_pivot_reciprocal");
}

int cuda_small_front_threads(index_t count, index_t max_rows, int max_threads, bool shared) {
  if (count < 1 || max_rows < 1 || max_rows > cuda::kThreads)
    throw InvalidInput(
        "cuda_small_front_threads: needs count >= 1 and max_rows in [1, 256] (count = " +
        std::to_string(count) + ", max_rows = " + std::to_string(max_rows) + ")");
  STRATA_CUDA(cudaSetDevice(0));
  return static_cast<int>(cuda::small_front_threads(
      count, max_rows, max_threads, shared ? cuda::shared_front_bytes(max_rows) : 0));
}

index_t cuda_fused_front_max_rows(bool lu) {
  STRATA_CUDA(cudaSetDevice(0));
  return lu ? cuda::lu_shared_max_rows() : cuda::llt_fused_max_rows();
}

}  // namespace strata::numeric
