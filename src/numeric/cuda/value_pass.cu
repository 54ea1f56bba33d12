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
// them: download_scaled_values).
//
// How: two passes over the entries, one warp per row and one per column. The row pass
// reads the entries of a row through a row-wise map of the canonical (column-wise)
// pattern, made and uploaded once per analysis: per row i, the positions of its entries
// and their columns. It sums |a| and |b| and takes the maximum of |b| over the row. The
// column pass then does the same per column, writes b over a in place and flags a value
// that is not finite. For symmetric storage (the lower triangle) a row of the full matrix
// is its stored row plus the column of the same index below the diagonal, so the column
// pass leaves the diagonal out there. A last single-block kernel combines the per-row and
// per-column figures into the five numbers.
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

// Per column j: the same figures over its entries (symmetric storage: below the diagonal
// only), b written over a, `bad` set when a value is not finite.
__global__ void column_pass(std::int64_t n, const std::int64_t* col_ptr, const int* col_row,
                            double* a, const double* rs, const double* cs, bool symmetric,
                            double* ca, double* cb, double* cm, int* bad) {
  const std::int64_t j =
      static_cast<std::int64_t>(blockIdx.x) * (kThreads / kWarp) + threadIdx.x / kWarp;
  const int lane = threadIdx.x % kWarp;
  if (j >= n) return;
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
  if (__any_sync(0xffffffffu, not_finite) && lane == 0) atomicOr(bad, 1);
  if (lane == 0) {
    ca[j] = f.a_sum;
    cb[j] = f.b_sum;
    cm[j] = f.b_max;
  }
}

__device__ bool outside_factor_two(double v) { return v != 0 && (v < 0.5 || v > 2); }

// One block: out[0] ‖A‖∞, out[1] ‖B‖₁, out[2] 1 when a row or column sum of |a| is not
// finite, out[3] 1 when a row or column maximum of |b| is outside {0} ∪ [½, 2], out[4]
// 1 when a value was not finite (`bad`).
__global__ void combine(std::int64_t n, bool symmetric, const double* ra, const double* rb,
                        const double* rm, const double* ca, const double* cb, const double* cm,
                        const int* bad, double* out) {
  __shared__ double s_norm_inf[kThreads], s_norm1[kThreads];
  __shared__ int s_overflow[kThreads], s_spread[kThreads];
  double norm_inf = 0, norm1 = 0;
  bool overflow = false, spread = false;
  for (std::int64_t i = threadIdx.x; i < n; i += kThreads) {
    if (symmetric) {
      const double row_a = ra[i] + ca[i], row_b = rb[i] + cb[i];
      norm_inf = fmax(norm_inf, row_a);
      norm1 = fmax(norm1, row_b);
      overflow |= !(row_a <= DBL_MAX);
      spread |= outside_factor_two(fmax(rm[i], cm[i]));
    } else {
      norm_inf = fmax(norm_inf, ra[i]);
      norm1 = fmax(norm1, cb[i]);
      overflow |= !(ra[i] <= DBL_MAX) || !(ca[i] <= DBL_MAX);
      spread |= outside_factor_two(rm[i]) || outside_factor_two(cm[i]);
    }
  }
  s_norm_inf[threadIdx.x] = norm_inf;
  s_norm1[threadIdx.x] = norm1;
  s_overflow[threadIdx.x] = overflow;
  s_spread[threadIdx.x] = spread;
  __syncthreads();
  for (int half = kThreads / 2; half > 0; half /= 2) {
    if (threadIdx.x < half) {
      s_norm_inf[threadIdx.x] = fmax(s_norm_inf[threadIdx.x], s_norm_inf[threadIdx.x + half]);
      s_norm1[threadIdx.x] = fmax(s_norm1[threadIdx.x], s_norm1[threadIdx.x + half]);
      s_overflow[threadIdx.x] |= s_overflow[threadIdx.x + half];
      s_spread[threadIdx.x] |= s_spread[threadIdx.x + half];
    }
    __syncthreads();
  }
  if (threadIdx.x == 0) {
    out[0] = s_norm_inf[0];
    out[1] = s_norm1[0];
    out[2] = s_overflow[0];
    out[3] = s_spread[0];
    out[4] = *bad != 0;
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
  // order, whatever the thread count)
  std::vector<int> row_pos(nnz), row_col(nnz), col_row(nnz);
  const std::vector<index_t> by_row = detail::bucket_entries(
      an.n, an.n,
      [&](index_t j) {
        return std::pair<index_t, index_t>{an.pattern_offsets[j], an.pattern_offsets[j + 1]};
      },
      [&](index_t, index_t p) { return an.pattern_indices[p]; },
      [&](index_t q, index_t j, index_t p) {
        row_pos[q] = static_cast<int>(p);
        row_col[q] = static_cast<int>(j);
        col_row[p] = static_cast<int>(an.pattern_indices[p]);
      });
  const std::vector<std::int64_t> row_ptr(by_row.begin(), by_row.end());
  ValuePass& v = value_pass_;
  try {
    upload(v.row_ptr, row_ptr);
    upload(v.col_ptr,
           std::vector<std::int64_t>(an.pattern_offsets.begin(), an.pattern_offsets.end()));
    upload(v.row_pos, row_pos);
    upload(v.row_col, row_col);
    upload(v.col_row, col_row);
    if (!an.row_scaling.empty()) {
      upload(v.row_scaling, an.row_scaling);
      upload(v.col_scaling, an.col_scaling);
    }
    v.sums.resize(std::max<std::size_t>(6 * n, 1));
    v.rescale.resize(std::max<std::size_t>(4 * n, 1));
    v.bad.resize(1);
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

bool CudaExecutor::scale_values_on_device(const Analysis& an, const double* values,
                                          const numeric::StageValues& stage, int max_sweeps,
                                          numeric::DeviceValueNorms& out) {
  STRATA_CUDA(cudaSetDevice(device_));
  ValuePass& v = value_pass_;
  if (v.analysis != an.id || an.id != analysis_id_ || planned_ != 1) return false;
  const auto whole = parts_.find(-1);
  if (whole == parts_.end()) return false;
  for (char tiled : whole->second.tiled)
    if (tiled) return false;  // tiled fronts assemble from the host's scaled values
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
    STRATA_CUDA(cudaMemcpyAsync(to + b, values + b, (e - b) * sizeof(double),
                                cudaMemcpyHostToDevice, stream));
  };
  if (stage)
    stage(0, nnz, upload_piece);
  else
    upload_piece(0, nnz);
  STRATA_CUDA(cudaMemsetAsync(v.bad.data(), 0, sizeof(int), stream_));
  double* s = v.sums.data();
  double *ra = s, *rb = s + n, *rm = s + 2 * n, *ca = s + 3 * n, *cb = s + 4 * n, *cm = s + 5 * n;
  // the row and column passes over values_ scaled by (rs, cs) in place, then the five
  // numbers, on the host when this returns
  auto passes = [&](const double* rs, const double* cs) {
    if (n > 0) {
      row_pass<<<blocks_for(n), kThreads, 0, stream_>>>(n, v.row_ptr.data(), v.row_pos.data(),
                                                        v.row_col.data(), values_.data(), rs, cs,
                                                        ra, rb, rm);
      STRATA_CUDA(cudaGetLastError());
      column_pass<<<blocks_for(n), kThreads, 0, stream_>>>(n, v.col_ptr.data(), v.col_row.data(),
                                                           values_.data(), rs, cs, an.symmetric, ca,
                                                           cb, cm, v.bad.data());
      STRATA_CUDA(cudaGetLastError());
    }
    combine<<<1, kThreads, 0, stream_>>>(n, an.symmetric, ra, rb, rm, ca, cb, cm, v.bad.data(),
                                         v.out.data());
    STRATA_CUDA(cudaGetLastError());
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
