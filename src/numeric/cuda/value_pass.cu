// strata — the value pass of a factorization on the device.
//
// What: the checks, norms and scaling the host's value pass makes (core/value_pass.hpp:
// every value finite, the row and column magnitude sums of A finite, ‖A‖∞, the scaled
// values B = Dr·A(:,Q)·Dc in A's entry order, ‖B‖₁, and whether B's row and column
// maxima are already within a factor 2 of 1; when they are not, the equilibration sweeps
// of core/rescale.hpp), made on the GPU from the raw values of a refactorization copied
// there once. The scaled values stay on the device, where the assembly reads them
// (FactorContext::values_on_device); the host gets five numbers, and the sweeps' factors
// when there were sweeps (the scaled values themselves only when a host algorithm asks for
// them: download_scaled_values). Values the caller holds in GPU memory or page-locked host
// memory are also kept on the device as given (copy_input, keep_device_input), so that the
// host copies them back only when it needs them (download_device_input).
//
// How: two passes over the entries, one warp per row and one per column. The row pass
// reads the entries of a row through a row-wise map of the canonical (column-wise)
// pattern, made and uploaded once per analysis: per row i, the positions of its entries
// and their columns. It sums |a| and |b| and takes the maximum of |b| over the row. The
// column pass then does the same per column, writes b over a in place and flags a value
// that is not finite. For symmetric storage (the lower triangle) a row of the full matrix
// is its stored row plus the column of the same index below the diagonal, so the column
// pass leaves the diagonal out there. The column pass also combines the per-row and
// per-column figures into the five numbers: each block its own indices, and the block
// that finishes last (a ticket counter) the blocks' partial figures.
//
// Why: on the multibody Newton matrices the host pass was a third of a refactorization on
// the GPU (bench/history.md). Each entry of B is computed as the host computes it,
// (a·r_i)·c_j, so both give the same bits; every sum is taken in a fixed order (a lane's
// entries in order, then a fixed shuffle tree), so the device's figures are the same from
// run to run (they may differ from the host's in the last bits: a different order). Maxima
// are exact in any order.
#include <algorithm>
#include <cfloat>
#include <cmath>
#include <memory>

#include "numeric/cuda/cuda_executor.hpp"
#include "sparse/bucket_entries.hpp"

namespace strata::cuda {
namespace {

constexpr int kWarp = 32;
constexpr int kThreads = 256;  // 8 warps: 8 rows (columns) per block

struct Figures {
  double a_sum, b_sum, b_max;
};

__device__ Figures warp_reduce(Figures f) {
  for (int off = kWarp / 2; off > 0; off /= 2) {
    f.a_sum += __shfl_xor_sync(0xffffffffu, f.a_sum, off);
    f.b_sum += __shfl_xor_sync(0xffffffffu, f.b_sum, off);
    f.b_max = fmax(f.b_max, __shfl_xor_sync(0xffffffffu, f.b_max, off));
  }
  return f;
}

// Per row i: the sums of |a| and |b| and the maximum of |b| over the row's stored entries
// (row_ptr/row_pos/row_col: the row-wise map; rs, cs: the scaling, or null).
__global__ void row_pass(std::int64_t n, const std::int64_t* row_ptr, const int* row_pos,
                         const int* row_col, const double* a, const double* rs, const double* cs,
                         double* ra, double* rb, double* rm) {
  const std::int64_t i =
      static_cast<std::int64_t>(blockIdx.x) * (kThreads / kWarp) + threadIdx.x / kWarp;
  const int lane = threadIdx.x % kWarp;
  if (i >= n) return;  // whole warps leave together
  const double ri = rs ? rs[i] : 1.0;
  Figures f{0, 0, 0};
  for (std::int64_t q = row_ptr[i] + lane; q < row_ptr[i + 1]; q += kWarp) {
    const double x = a[row_pos[q]];
    const double b = cs ? x * ri * cs[row_col[q]] : x;
    f.a_sum += fabs(x);
    f.b_sum += fabs(b);
    f.b_max = fmax(f.b_max, fabs(b));
  }
  f = warp_reduce(f);
  if (lane == 0) {
    ra[i] = f.a_sum;
    rb[i] = f.b_sum;
    rm[i] = f.b_max;
  }
}

__device__ bool outside_factor_two(double v) { return v != 0 && (v < 0.5 || v > 2); }

// The five numbers' parts over some indices: ‖A‖∞ and ‖B‖₁ so far, whether a row or
// column sum of |a| was not finite, whether a maximum of |b| was outside {0} ∪ [½, 2].
struct Combined {
  double norm_inf = 0, norm1 = 0;
  int overflow = 0, spread = 0;
};

__device__ Combined merge(Combined x, const Combined& y) {
  x.norm_inf = fmax(x.norm_inf, y.norm_inf);
  x.norm1 = fmax(x.norm1, y.norm1);
  x.overflow |= y.overflow;
  x.spread |= y.spread;
  return x;
}

// Index i's part: its row's figures (ra, rb, rm) and its column's (a, b, m). For symmetric
// storage a row of the full matrix is its stored row plus the column of the same index.
__device__ Combined index_part(bool symmetric, double ra, double rb, double rm, double a, double b,
                               double m) {
  Combined c;
  if (symmetric) {
    const double row_a = ra + a, row_b = rb + b;
    c.norm_inf = row_a;
    c.norm1 = row_b;
    c.overflow = !(row_a <= DBL_MAX);
    c.spread = outside_factor_two(fmax(rm, m));
  } else {
    c.norm_inf = ra;
    c.norm1 = b;
    c.overflow = !(ra <= DBL_MAX) || !(a <= DBL_MAX);
    c.spread = outside_factor_two(rm) || outside_factor_two(m);
  }
  // fmax, as the maxima are taken, leaves a NaN sum out (its overflow flag tells)
  c.norm_inf = fmax(0.0, c.norm_inf);
  c.norm1 = fmax(0.0, c.norm1);
  return c;
}

// Per column j: the same figures over its entries (symmetric storage: below the diagonal
// only), b written over a, flags[0] set when a value is not finite; then the five numbers
// (out[0] ‖A‖∞, out[1] ‖B‖₁, out[2] 1 when a row or column sum of |a| is not finite,
// out[3] 1 when a row or column maximum of |b| is outside {0} ∪ [½, 2], out[4] 1 when a
// value was not finite): each block's part of them in partial (4 per block), and the last
// block to finish (flags[1], a ticket the caller zeroes) merges the parts into out. Max
// and or do not depend on the order of merging: the numbers are the same every run.
__global__ void column_pass(std::int64_t n, const std::int64_t* col_ptr, const int* col_row,
                            double* a, const double* rs, const double* cs, bool symmetric,
                            const double* ra, const double* rb, const double* rm, double* ca,
                            double* cb, double* cm, int* flags, double* partial, double* out) {
  __shared__ Combined s_part[kThreads / kWarp];
  __shared__ bool s_last;
  const int warp = threadIdx.x / kWarp, lane = threadIdx.x % kWarp;
  const std::int64_t j = static_cast<std::int64_t>(blockIdx.x) * (kThreads / kWarp) + warp;
  Combined part;
  if (j < n) {  // whole warps: a column each
    const double cj = cs ? cs[j] : 1.0;
    Figures f{0, 0, 0};
    bool not_finite = false;
    for (std::int64_t p = col_ptr[j] + lane; p < col_ptr[j + 1]; p += kWarp) {
      const int i = col_row[p];
      const double x = a[p];
      not_finite |= !(fabs(x) <= DBL_MAX);
      const double b = rs ? x * rs[i] * cj : x;
      a[p] = b;
      if (symmetric && i == j) continue;
      f.a_sum += fabs(x);
      f.b_sum += fabs(b);
      f.b_max = fmax(f.b_max, fabs(b));
    }
    f = warp_reduce(f);
    if (__any_sync(0xffffffffu, not_finite) && lane == 0) atomicOr(flags, 1);
    if (lane == 0) {
      ca[j] = f.a_sum;
      cb[j] = f.b_sum;
      cm[j] = f.b_max;
      part = index_part(symmetric, ra[j], rb[j], rm[j], f.a_sum, f.b_sum, f.b_max);
    }
  }
  if (lane == 0) s_part[warp] = part;
  __syncthreads();
  if (threadIdx.x == 0) {
    Combined b = s_part[0];
    for (int w = 1; w < kThreads / kWarp; ++w) b = merge(b, s_part[w]);
    double* mine = partial + 4 * static_cast<std::int64_t>(blockIdx.x);
    mine[0] = b.norm_inf;
    mine[1] = b.norm1;
    mine[2] = b.overflow;
    mine[3] = b.spread;
    __threadfence();  // the part, and this block's not-finite flag, before the ticket
    s_last = atomicAdd(reinterpret_cast<unsigned*>(flags + 1), 1u) == gridDim.x - 1;
  }
  __syncthreads();
  if (!s_last) return;
  __threadfence();
  Combined all;
  for (std::int64_t q = threadIdx.x; q < gridDim.x; q += kThreads) {
    const double* x = partial + 4 * q;
    Combined c;
    c.norm_inf = __ldcg(x);  // written by other blocks: read past this SM's L1
    c.norm1 = __ldcg(x + 1);
    c.overflow = __ldcg(x + 2) != 0;
    c.spread = __ldcg(x + 3) != 0;
    all = merge(all, c);
  }
  for (int off = kWarp / 2; off > 0; off /= 2) {
    Combined o;
    o.norm_inf = __shfl_xor_sync(0xffffffffu, all.norm_inf, off);
    o.norm1 = __shfl_xor_sync(0xffffffffu, all.norm1, off);
    o.overflow = __shfl_xor_sync(0xffffffffu, all.overflow, off);
    o.spread = __shfl_xor_sync(0xffffffffu, all.spread, off);
    all = merge(all, o);
  }
  if (lane == 0) s_part[warp] = all;
  __syncthreads();
  if (threadIdx.x == 0) {
    for (int w = 1; w < kThreads / kWarp; ++w) all = merge(all, s_part[w]);
    out[0] = all.norm_inf;
    out[1] = all.norm1;
    out[2] = all.overflow;
    out[3] = all.spread;
    out[4] = atomicOr(flags, 0) != 0;
    flags[1] = 0;  // the ticket, for the next pass (the caller zeroes it too)
  }
}

// The power of two nearest to 1/√x (x > 0), as core/rescale.cpp takes it.
__device__ double inverse_sqrt_pow2(double x) {
  int e = 0;
  frexp(x, &e);  // x = f·2^e, f in [1/2, 1)
  return ldexp(1.0, -((e - 1) / 2));
}

// One equilibration sweep's factors (core/rescale.hpp): r_i from row i's maximum of |b|,
// s_j from column j's (symmetric: both from the full row's, rm and cm together), 1 for an
// empty row or column; the factors of the sweeps so far, R and C, multiplied by them (set
// by the first sweep).
__global__ void sweep_factors(std::int64_t n, bool symmetric, bool first, const double* rm,
                              const double* cm, double* r, double* s, double* R, double* C) {
  const std::int64_t i = static_cast<std::int64_t>(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const double row = symmetric ? fmax(rm[i], cm[i]) : rm[i];
  const double col = symmetric ? row : cm[i];
  r[i] = row > 0 ? inverse_sqrt_pow2(row) : 1.0;
  s[i] = col > 0 ? inverse_sqrt_pow2(col) : 1.0;
  R[i] = first ? r[i] : R[i] * r[i];
  C[i] = first ? s[i] : C[i] * s[i];
}

// The column-wise map's row of each entry from the row-wise map (one warp per row, as
// row_pass): col_row[row_pos[q]] = i for the entries q of row i.
__global__ void fill_col_row(std::int64_t n, const std::int64_t* row_ptr, const int* row_pos,
                             int* col_row) {
  const std::int64_t i =
      static_cast<std::int64_t>(blockIdx.x) * (kThreads / kWarp) + threadIdx.x / kWarp;
  if (i >= n) return;
  for (std::int64_t q = row_ptr[i] + threadIdx.x % kWarp; q < row_ptr[i + 1]; q += kWarp)
    col_row[row_pos[q]] = static_cast<int>(i);
}

unsigned blocks_for(std::int64_t n) {
  return static_cast<unsigned>((n + kThreads / kWarp - 1) / (kThreads / kWarp));
}

}  // namespace

void CudaExecutor::prepare_value_pass(const Analysis& an) {
  value_pass_.analysis = 0;
  const auto n = static_cast<std::size_t>(an.n);
  const std::size_t nnz = an.pattern_indices.size();
  // positions and indices are stored in 32 bits; a pattern this large keeps the host pass
  if (nnz >= static_cast<std::size_t>(INT32_MAX) || an.pattern_offsets.size() != n + 1) return;
  // the row-wise map of the canonical pattern: a stable counting sort of the entries by
  // row over the host's threads (sparse/bucket_entries.hpp: each row's entries in column
  // order, whatever the thread count), into arrays that sorting writes in full (not zeroed
  // first); the column-wise map's rows are made from it on the device
  const std::unique_ptr<int[]> row_pos(new int[std::max<std::size_t>(nnz, 1)]);
  const std::unique_ptr<int[]> row_col(new int[std::max<std::size_t>(nnz, 1)]);
  const std::vector<index_t> by_row = detail::bucket_entries(
      an.n, an.n,
      [&](index_t j) {
        return std::pair<index_t, index_t>{an.pattern_offsets[j], an.pattern_offsets[j + 1]};
      },
      [&](index_t, index_t p) { return an.pattern_indices[p]; },
      [&](index_t q, index_t j, index_t p) {
        row_pos[q] = static_cast<int>(p);
        row_col[q] = static_cast<int>(j);
      });
  const std::vector<std::int64_t> row_ptr(by_row.begin(), by_row.end());
  ValuePass& v = value_pass_;
  try {
    upload(v.row_ptr, row_ptr);
    upload(v.col_ptr,
           std::vector<std::int64_t>(an.pattern_offsets.begin(), an.pattern_offsets.end()));
    v.row_pos.upload(row_pos.get(), nnz, stream_);
    v.row_col.upload(row_col.get(), nnz, stream_);
    bytes_h2d_ += 2 * nnz * sizeof(int);
    v.col_row.resize(std::max<std::size_t>(nnz, 1));
    if (an.n > 0) {
      fill_col_row<<<blocks_for(an.n), kThreads, 0, stream_>>>(an.n, v.row_ptr.data(),
                                                               v.row_pos.data(), v.col_row.data());
      STRATA_CUDA_LAUNCH();
    }
    if (!an.row_scaling.empty()) {
      upload(v.row_scaling, an.row_scaling);
      upload(v.col_scaling, an.col_scaling);
    }
    // the row and column figures (6n), then column_pass's partial figures (4 per block)
    v.sums.resize(std::max<std::size_t>(6 * n + 4 * static_cast<std::size_t>(blocks_for(an.n)), 1));
    v.rescale.resize(std::max<std::size_t>(4 * n, 1));
    v.bad.resize(2);  // the not-finite flag, column_pass's ticket
    v.out.resize(5);
    values_.resize(std::max<std::size_t>(nnz, 1));
    STRATA_CUDA(cudaStreamSynchronize(stream_));
  } catch (const OutOfMemory&) {
    // no room: the host pass serves; give back what was taken
    for (auto* b : {&v.row_ptr, &v.col_ptr}) b->clear();
    for (auto* b : {&v.row_pos, &v.row_col, &v.col_row}) b->clear();
    for (auto* b : {&v.row_scaling, &v.col_scaling, &v.sums, &v.rescale}) b->clear();
    return;
  }
  v.analysis = an.id;
}

bool CudaExecutor::prepare_shared_value_pass(const Analysis& an) {
  if (an.id != analysis_id_) return false;  // not prepared for `an`
  STRATA_CUDA(cudaSetDevice(device_));
  if (value_pass_.analysis != an.id) prepare_value_pass(an);
  return value_pass_.analysis == an.id;
}

const double* CudaExecutor::device_scaled_values(const Analysis& an) {
  if (value_pass_.analysis != an.id || an.id != analysis_id_ ||
      values_.size() < an.pattern_indices.size())
    return nullptr;
  STRATA_CUDA(cudaSetDevice(device_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  return values_.data();
}

bool CudaExecutor::download_scaled_values(const Analysis& an, double* host) {
  const std::size_t nnz = an.pattern_indices.size();
  if (value_pass_.analysis != an.id || an.id != analysis_id_ || values_.size() < nnz) return false;
  STRATA_CUDA(cudaSetDevice(device_));
  if (nnz > 0)
    STRATA_CUDA(cudaMemcpyAsync(host, values_.data(), nnz * sizeof(double), cudaMemcpyDeviceToHost,
                                stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  return true;
}

bool CudaExecutor::keep_device_input(const Analysis& an) {
  if (an.id != analysis_id_ || input_next_.size() < an.pattern_indices.size()) return false;
  std::swap(input_, input_next_);
  input_analysis_ = an.id;
  return true;
}

bool CudaExecutor::download_device_input(const Analysis& an, double* host) {
  const std::size_t nnz = an.pattern_indices.size();
  if (input_analysis_ != an.id || an.id != analysis_id_ || input_.size() < nnz) return false;
  STRATA_CUDA(cudaSetDevice(device_));
  if (nnz > 0)
    STRATA_CUDA(cudaMemcpyAsync(host, input_.data(), nnz * sizeof(double), cudaMemcpyDeviceToHost,
                                stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  return true;
}

bool CudaExecutor::scale_values_on_device(const Analysis& an, const double* values,
                                          const numeric::StageValues& stage, int max_sweeps,
                                          bool copy_input, numeric::DeviceValueNorms& out) {
  STRATA_CUDA(cudaSetDevice(device_));
  ValuePass& v = value_pass_;
  // the whole tree's plan or the parts' (several GPUs: this one's pass serves them all);
  // tiled fronts assemble from the host's scaled values
  if (v.analysis != an.id || an.id != analysis_id_ || reads_host_values()) return false;
  const auto n = static_cast<std::int64_t>(an.n);
  const std::size_t nnz = an.pattern_indices.size();
  const bool scale = !an.row_scaling.empty();
  // each piece copied as soon as the caller has staged it, from the thread that staged it
  // (counted by begin, in FactorStats::bytes_to_device)
  values_.resize(std::max<std::size_t>(nnz, 1));
  double* const to = values_.data();
  const int device = device_;
  cudaStream_t const stream = stream_;
  const auto upload_piece = [to, values, device, stream](std::size_t b, std::size_t e) {
    if (e <= b) return;
    STRATA_CUDA(cudaSetDevice(device));  // the staging thread's current device
    // cudaMemcpyDefault: `values` may also be device memory (Solver::refactorize)
    STRATA_CUDA(
        cudaMemcpyAsync(to + b, values + b, (e - b) * sizeof(double), cudaMemcpyDefault, stream));
  };
  if (stage)
    stage(0, nnz, upload_piece);
  else
    upload_piece(0, nnz);
  // the values as given, before the passes scale them in place (outside the memory plan:
  // where the device has no room the caller keeps them on the host)
  out.input_copied = false;
  if (copy_input && nnz > 0) {
    try {
      input_next_.resize(nnz);
      out.input_copied = true;
    } catch (const OutOfMemory&) {
    }
    if (out.input_copied)
      STRATA_CUDA(cudaMemcpyAsync(input_next_.data(), values_.data(), nnz * sizeof(double),
                                  cudaMemcpyDeviceToDevice, stream_));
  }
  STRATA_CUDA(cudaMemsetAsync(v.bad.data(), 0, 2 * sizeof(int), stream_));
  double* s = v.sums.data();
  double *ra = s, *rb = s + n, *rm = s + 2 * n, *ca = s + 3 * n, *cb = s + 4 * n, *cm = s + 5 * n;
  double* const partial = s + 6 * n;
  // the row and column passes over values_ scaled by (rs, cs) in place, and the five
  // numbers, on the host when this returns
  auto passes = [&](const double* rs, const double* cs) {
    if (n == 0) {  // no entries: the numbers of an empty matrix
      std::fill(v.out.data(), v.out.data() + 5, 0.0);
      return;
    }
    {
      row_pass<<<blocks_for(n), kThreads, 0, stream_>>>(n, v.row_ptr.data(), v.row_pos.data(),
                                                        v.row_col.data(), values_.data(), rs, cs,
                                                        ra, rb, rm);
      STRATA_CUDA(cudaGetLastError());
      column_pass<<<blocks_for(n), kThreads, 0, stream_>>>(
          n, v.col_ptr.data(), v.col_row.data(), values_.data(), rs, cs, an.symmetric, ra, rb, rm,
          ca, cb, cm, v.bad.data(), partial, v.out.data());
      STRATA_CUDA(cudaGetLastError());
    }
    STRATA_CUDA(cudaStreamSynchronize(stream_));
  };
  passes(scale ? v.row_scaling.data() : nullptr, scale ? v.col_scaling.data() : nullptr);
  const double* r = v.out.data();
  out.norm_inf = r[0];
  out.scaled_norm1 = r[1];
  out.sums_finite = r[2] == 0;
  out.equilibrated = r[3] == 0;
  out.finite = r[4] == 0;
  out.rescaling_sweeps = 0;
  out.row_rescaling.clear();
  out.col_rescaling.clear();
  if (!scale || out.equilibrated || !out.finite || !out.sums_finite || max_sweeps <= 0 || n == 0)
    return true;
  // Equilibrated again as rescale_values does it on the host: per sweep the factors from
  // the last maxima, then the row and column passes scale B in place by them and take its
  // new maxima and ‖B‖₁ (the figures of A in ra and ca are not read again), until every
  // maximum is within a factor 2 of 1 or max_sweeps sweeps are made. The factors are
  // powers of two, so B's bits are the host's.
  double* R = v.rescale.data();
  double *C = R + n, *rr = C + n, *ss = rr + n;
  const unsigned grid = static_cast<unsigned>((n + kThreads - 1) / kThreads);
  while (out.rescaling_sweeps < max_sweeps) {
    sweep_factors<<<grid, kThreads, 0, stream_>>>(n, an.symmetric, out.rescaling_sweeps == 0, rm,
                                                  cm, rr, ss, R, C);
    STRATA_CUDA(cudaGetLastError());
    passes(rr, ss);
    ++out.rescaling_sweeps;
    out.scaled_norm1 = r[1];
    out.equilibrated = r[3] == 0;
    if (out.equilibrated) break;
  }
  out.row_rescaling.resize(static_cast<std::size_t>(n));
  out.col_rescaling.resize(static_cast<std::size_t>(n));
  STRATA_CUDA(cudaMemcpy(out.row_rescaling.data(), R, sizeof(double) * n, cudaMemcpyDeviceToHost));
  STRATA_CUDA(cudaMemcpy(out.col_rescaling.data(), C, sizeof(double) * n, cudaMemcpyDeviceToHost));
  return true;
}

}  // namespace strata::cuda
