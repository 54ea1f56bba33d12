// strata — the CUDA executor: level-batched multifrontal factorization on one GPU.
//
// Per batch of the memory plan (fronts of one level, DESIGN.md §2):
//   1. one launch assembles every front of the batch in the device pool (zero, scatter
//      original entries, extend-add children's contribution blocks from the CB arena);
//   2. one launch factors all small fronts (one thread block each); large fronts go to
//      cuSOLVER POTRF + cuBLAS TRSM/SYRK (LLᵀ) or a blocked LU with our panel kernel and
//      cuBLAS TRSM/GEMM, both with pivoting restricted to the fully summed rows and the
//      CPU backend's static pivoting;
//   3. one launch stores the contribution blocks in the device CB arena;
//   4. the factor panels are copied to the host factor.
// What stays on the device between batches: the analysis arrays, the scaled values and
// the CB arena. Version 1 keeps the whole CB arena resident and fails with a clear
// NotSupported error when the arena and the largest batch exceed device memory or the
// budget; streaming contribution blocks to the host is the next step (issue 5).
// LDLᵀ (Bunch–Kaufman) is not on the GPU yet: NotSupported, and Backend::automatic uses
// the CPU for it.
#include <cmath>
#include <cstdint>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/kernels.cuh"
#include "numeric/factor.hpp"

namespace strata::cuda {

[[noreturn]] void throw_cuda(cudaError_t e, const char* call, const char* file, int line) {
  if (e == cudaErrorMemoryAllocation)
    throw OutOfMemory(0, std::string(call) + " at " + file + ":" + std::to_string(line));
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) + ": " +
                    cudaGetErrorName(e) + " (" + cudaGetErrorString(e) + ")");
}
[[noreturn]] void throw_cublas(cublasStatus_t s, const char* call, const char* file, int line) {
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) + ": " +
                    cublasGetStatusName(s) + " (" + cublasGetStatusString(s) + ")");
}
[[noreturn]] void throw_cusolver(cusolverStatus_t s, const char* call, const char* file, int line) {
  throw DeviceError(std::string(call) + " failed at " + file + ":" + std::to_string(line) +
                    ": cusolver status " + std::to_string(static_cast<int>(s)));
}

namespace {

using numeric::FactorContext;
constexpr std::int64_t kSmallFront = 256;  // fronts up to this many rows: one block each
constexpr std::int64_t kLuPanel = 64;      // panel width of the blocked LU of large fronts

template <class T>
void upload(DeviceBuffer<T>& d, const std::vector<T>& h, cudaStream_t s) {
  d.upload(h.data(), h.size(), s);
}

class CudaExecutor final : public numeric::Executor {
 public:
  explicit CudaExecutor(const Options& o) : limit_(o.device_memory_limit) {
    STRATA_CUDA(cudaStreamCreate(&stream_));
    STRATA_CUBLAS(cublasCreate(&blas_));
    STRATA_CUBLAS(cublasSetStream(blas_, stream_));
    STRATA_CUSOLVER(cusolverDnCreate(&solver_));
    STRATA_CUSOLVER(cusolverDnSetStream(solver_, stream_));
  }
  ~CudaExecutor() override {
    cusolverDnDestroy(solver_);
    cublasDestroy(blas_);
    cudaStreamDestroy(stream_);
  }
  const char* name() const override { return "cuda"; }

  void begin(const FactorContext& ctx) override {
    if (ctx.type == MatrixType::symmetric_indefinite)
      throw NotSupported("LDLᵀ (symmetric_indefinite) is not implemented on the CUDA backend yet");
    const Analysis& an = *ctx.analysis;
    if (an.id != analysis_id_) upload_analysis(an);
    values_.upload(ctx.values, an.pattern_indices.size(), stream_);
  }

  void factor_batch(const FactorContext& ctx, const BatchInfo& b) override;

  void begin_part(const FactorContext& ctx) override {
    if (ctx.part->id != -1)
      throw NotSupported("the CUDA executor does not factor parts of a split tree yet");
  }
  std::size_t export_cb(const FactorContext&, numeric::CbTransfer&) override {
    throw NotSupported("the CUDA executor does not export contribution blocks yet");
  }
  std::size_t import_cb(const FactorContext&, const numeric::CbTransfer&) override {
    throw NotSupported("the CUDA executor does not import contribution blocks yet");
  }

 private:
  void upload_analysis(const Analysis& an);

  cudaStream_t stream_ = nullptr;
  cublasHandle_t blas_ = nullptr;
  cusolverDnHandle_t solver_ = nullptr;
  std::size_t limit_ = 0;
  std::uint64_t analysis_id_ = 0;
  std::size_t pattern_nnz_ = 0;
  DeviceBuffer<std::int64_t> fronts_, pos_offset_, n_rows_, n_pivots_, parent_, entry_offsets_,
      entry_src_, entry_dst_, child_offsets_, children_, cb_offset_, rel_offsets_, rel_;
  DeviceTree tree_{};
  std::vector<std::int64_t> pos_offset_host_;
  DeviceBuffer<double> values_, arena_, pool_, potrf_work_;
  DeviceBuffer<int> potrf_info_;
  DeviceBuffer<std::int64_t> small_pos_, info_, perturbed_, perm_, perm_offset_, stage_offset_;
  DeviceBuffer<double> staging_;
  PinnedBuffer<double> host_staging_;
};

void CudaExecutor::upload_analysis(const Analysis& an) {
  const auto& t = an.tree;
  const auto& s = an.schedule;
  const index_t nf = t.n_fronts();
  std::vector<std::int64_t> n_rows(nf), n_piv(nf), cb_off(nf);
  for (index_t f = 0; f < nf; ++f) {
    n_rows[f] = t.n_rows(f);
    n_piv[f] = t.n_pivots(f);
    cb_off[f] = static_cast<std::int64_t>(an.cb_layout.cb_offset[f]);
  }
  // positions of each batch's fronts in the pool, and the largest batch
  pos_offset_host_.assign(s.fronts.size(), 0);
  std::size_t pool = 0;
  for (const BatchInfo& b : an.plan.batches) {
    std::size_t off = 0;
    for (index_t p = b.begin; p < b.end; ++p) {
      pos_offset_host_[p] = static_cast<std::int64_t>(off);
      const std::size_t m = static_cast<std::size_t>(n_rows[s.fronts[p]]);
      off += m * m;
    }
    pool = std::max(pool, off);
  }
  // relative positions of each child's contribution rows in its parent
  std::vector<std::int64_t> rel_off(nf + 1, 0), rel;
  std::vector<index_t> position(an.n, -1);
  for (index_t f = 0; f < nf; ++f) rel_off[f + 1] = rel_off[f] + t.cb_size(f);
  rel.resize(rel_off[nf]);
  for (index_t f = 0; f < nf; ++f) {
    const index_t* rows = t.rows_of(f);
    for (index_t i = 0; i < t.n_rows(f); ++i) position[rows[i]] = i;
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      const index_t* crow = t.rows_of(c) + t.n_pivots(c);
      for (index_t i = 0; i < t.cb_size(c); ++i) rel[rel_off[c] + i] = position[crow[i]];
    }
    for (index_t i = 0; i < t.n_rows(f); ++i) position[rows[i]] = -1;
  }
  const std::size_t bytes = 8 * (an.cb_layout.arena_size + pool);
  if (limit_ > 0 && bytes > limit_)
    throw NotSupported(
        "the CUDA backend keeps the contribution-block arena and the largest "
        "batch on the device (" +
        std::to_string(bytes) +
        " bytes), over the "
        "device_memory_limit of " +
        std::to_string(limit_) + " bytes; streaming to the host is not implemented yet");
  upload(fronts_, s.fronts, stream_);
  upload(pos_offset_, pos_offset_host_, stream_);
  upload(n_rows_, n_rows, stream_);
  upload(n_pivots_, n_piv, stream_);
  upload(parent_, t.parent, stream_);
  upload(entry_offsets_, an.assembly.entry_offsets, stream_);
  upload(entry_src_, an.assembly.entry_src, stream_);
  upload(entry_dst_, an.assembly.entry_dst, stream_);
  upload(child_offsets_, t.child_offsets, stream_);
  upload(children_, t.children, stream_);
  upload(cb_offset_, cb_off, stream_);
  upload(rel_offsets_, rel_off, stream_);
  upload(rel_, rel, stream_);
  arena_.resize(std::max<std::size_t>(an.cb_layout.arena_size, 1));
  pool_.resize(std::max<std::size_t>(pool, 1));
  pattern_nnz_ = an.pattern_indices.size();
  tree_ = DeviceTree{fronts_.data(),    pos_offset_.data(), n_rows_.data(),
                     n_pivots_.data(),  parent_.data(),     entry_offsets_.data(),
                     entry_src_.data(), entry_dst_.data(),  child_offsets_.data(),
                     children_.data(),  cb_offset_.data(),  rel_offsets_.data(),
                     rel_.data()};
  // cuSOLVER workspace for the largest pivot block of a large front
  int lwork = 0;
  index_t kmax = 0, mmax = 1;
  for (index_t f = 0; f < nf; ++f)
    if (t.n_rows(f) > kSmallFront) {
      kmax = std::max(kmax, t.n_pivots(f));
      mmax = std::max(mmax, t.n_rows(f));
    }
  if (kmax > 0)
    STRATA_CUSOLVER(cusolverDnDpotrf_bufferSize(solver_, CUBLAS_FILL_MODE_LOWER,
                                                static_cast<int>(kmax), pool_.data(),
                                                static_cast<int>(mmax), &lwork));
  potrf_work_.resize(std::max(lwork, 1));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  analysis_id_ = an.id;
}

void CudaExecutor::factor_batch(const FactorContext& ctx, const BatchInfo& b) {
  const Analysis& an = *ctx.analysis;
  const auto& t = an.tree;
  const auto& s = an.schedule;
  numeric::NumericFactor& fac = *ctx.factor;
  const bool lu = ctx.type == MatrixType::general;
  const std::int64_t count = b.end - b.begin;
  launch_assemble(tree_, b.begin, count, values_.data(), arena_.data(), pool_.data(), !lu, stream_);

  // small fronts: one launch for the whole batch
  std::vector<std::int64_t> small, big, perm_off{0};
  for (index_t p = b.begin; p < b.end; ++p) {
    const index_t f = s.fronts[p];
    if (t.n_rows(f) <= kSmallFront) {
      small.push_back(p);
      perm_off.push_back(perm_off.back() + t.n_pivots(f));
    } else {
      big.push_back(p);
    }
  }
  const std::size_t ns = small.size();
  upload(small_pos_, small, stream_);
  upload(perm_offset_, perm_off, stream_);
  info_.resize(ns + big.size() + 1);
  perturbed_.resize(ns + big.size() + 1);
  std::int64_t big_perm = 0;
  for (std::int64_t p : big) big_perm += t.n_pivots(s.fronts[p]);
  perm_.resize(perm_off.back() + big_perm + 1);
  potrf_info_.resize(big.size() + 1);
  launch_factor_small(tree_, small_pos_.data(), static_cast<std::int64_t>(ns), pool_.data(), lu,
                      ctx.static_pivot, info_.data(), perturbed_.data(), perm_.data(),
                      perm_offset_.data(), stream_);

  // large fronts: library calls, one front after another on the stream
  const double one = 1.0, minus_one = -1.0;
  std::int64_t perm_at = perm_off.back();
  std::vector<std::int64_t> big_perm_at;
  for (std::size_t i = 0; i < big.size(); ++i) {
    const index_t p = big[i], f = s.fronts[p];
    const int m = static_cast<int>(t.n_rows(f)), k = static_cast<int>(t.n_pivots(f));
    double* F = pool_.data() + pos_offset_host_[p];
    big_perm_at.push_back(perm_at);
    if (!lu) {
      STRATA_CUSOLVER(cusolverDnDpotrf(solver_, CUBLAS_FILL_MODE_LOWER, k, F, m, potrf_work_.data(),
                                       static_cast<int>(potrf_work_.size()),
                                       potrf_info_.data() + i));
      if (m > k) {
        STRATA_CUBLAS(cublasDtrsm(blas_, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                                  CUBLAS_DIAG_NON_UNIT, m - k, k, &one, F, m, F + k, m));
        STRATA_CUBLAS(cublasDsyrk(blas_, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, m - k, k, &minus_one,
                                  F + k, m, &one, F + static_cast<std::size_t>(k) * m + k, m));
      }
    } else {
      std::vector<std::int64_t> iota(k);
      for (int r = 0; r < k; ++r) iota[r] = r;
      STRATA_CUDA(cudaMemcpyAsync(perm_.data() + perm_at, iota.data(), sizeof(std::int64_t) * k,
                                  cudaMemcpyHostToDevice, stream_));
      STRATA_CUDA(cudaMemsetAsync(perturbed_.data() + ns + i, 0, sizeof(std::int64_t), stream_));
      for (int p0 = 0; p0 < k; p0 += kLuPanel) {
        const int w = std::min<int>(kLuPanel, k - p0), rest = m - p0 - w;
        launch_lu_panel(F, m, k, p0, w, ctx.static_pivot, perm_.data() + perm_at,
                        perturbed_.data() + ns + i, stream_);
        if (rest > 0) {
          double* a11 = F + static_cast<std::size_t>(p0) * m + p0;
          double* a12 = F + static_cast<std::size_t>(p0 + w) * m + p0;
          STRATA_CUBLAS(cublasDtrsm(blas_, CUBLAS_SIDE_LEFT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N,
                                    CUBLAS_DIAG_UNIT, w, rest, &one, a11, m, a12, m));
          STRATA_CUBLAS(cublasDgemm(blas_, CUBLAS_OP_N, CUBLAS_OP_N, rest, rest, w, &minus_one,
                                    a11 + w, m, a12, m, &one, a12 + w, m));
        }
      }
      // the iota upload must not outlive its host vector
      STRATA_CUDA(cudaStreamSynchronize(stream_));
    }
    perm_at += k;
  }
  launch_store_cb(tree_, b.begin, count, pool_.data(), arena_.data(), !lu, stream_);

  // factor panels back to the host: packed on the device, one copy per batch into pinned
  // memory, then placed in the factor (one transfer instead of one per front)
  std::vector<std::int64_t> stage_off(count + 1, 0);
  for (std::int64_t i = 0; i < count; ++i) {
    const index_t f = s.fronts[b.begin + i];
    stage_off[i + 1] =
        stage_off[i] + static_cast<std::int64_t>(an.factor_layout.panel_offset[f + 1] -
                                                 an.factor_layout.panel_offset[f]);
  }
  upload(stage_offset_, stage_off, stream_);
  staging_.resize(std::max<std::int64_t>(stage_off[count], 1));
  host_staging_.resize(static_cast<std::size_t>(stage_off[count]));
  launch_pack_panels(tree_, b.begin, count, pool_.data(), stage_offset_.data(), staging_.data(), lu,
                     stream_);
  if (stage_off[count] > 0)
    STRATA_CUDA(cudaMemcpyAsync(host_staging_.data(), staging_.data(),
                                sizeof(double) * stage_off[count], cudaMemcpyDeviceToHost,
                                stream_));
  const std::size_t nall = ns + big.size();
  std::vector<std::int64_t> info(nall), perturbed(nall), perm(perm_at);
  std::vector<int> pinfo(big.size());
  if (ns)
    STRATA_CUDA(
        cudaMemcpyAsync(info.data(), info_.data(), 8 * ns, cudaMemcpyDeviceToHost, stream_));
  if (nall)
    STRATA_CUDA(cudaMemcpyAsync(perturbed.data(), perturbed_.data(), 8 * nall,
                                cudaMemcpyDeviceToHost, stream_));
  if (perm_at)
    STRATA_CUDA(
        cudaMemcpyAsync(perm.data(), perm_.data(), 8 * perm_at, cudaMemcpyDeviceToHost, stream_));
  if (!big.empty() && !lu)
    STRATA_CUDA(cudaMemcpyAsync(pinfo.data(), potrf_info_.data(), sizeof(int) * big.size(),
                                cudaMemcpyDeviceToHost, stream_));
  STRATA_CUDA(cudaStreamSynchronize(stream_));
  for (std::int64_t i = 0; i < count; ++i) {
    const index_t f = s.fronts[b.begin + i];
    std::copy(host_staging_.data() + stage_off[i], host_staging_.data() + stage_off[i + 1],
              fac.panels.data() + an.factor_layout.panel_offset[f]);
  }

  // host bookkeeping: failures, permuted rows, pivot statistics
  auto finish = [&](index_t f, std::int64_t bad, std::int64_t npert, const std::int64_t* lperm) {
    const index_t m = t.n_rows(f), k = t.n_pivots(f);
    const double* panel = fac.panels.data() + an.factor_layout.panel_offset[f];
    if (bad >= 0) throw NotPositiveDefinite(an.perm[t.first_pivot[f] + bad], std::nan(""));
    const index_t* rows = t.rows_of(f);
    index_t* frows = fac.rows.data() + t.row_offsets[f];
    numeric::cpu::PivotStats& ps = fac.front_stats[f];
    ps = numeric::cpu::PivotStats{};
    int sign = 1;
    for (index_t i = 0; i < k; ++i) {
      frows[i] = rows[lu ? lperm[i] : i];
      const double d = panel[i * m + i];
      ps.log_abs_det += lu ? std::log(std::abs(d)) : 2.0 * std::log(d);
      if (d < 0) sign = -sign;
    }
    for (index_t i = k; i < m; ++i) frows[i] = rows[i];
    if (lu) {  // parity of the local row permutation
      std::vector<char> seen(k, 0);
      for (index_t i = 0; i < k; ++i) {
        if (seen[i]) continue;
        index_t len = 0;
        for (index_t j = i; !seen[j]; j = lperm[j]) {
          seen[j] = 1;
          ++len;
        }
        if (len % 2 == 0) sign = -sign;
      }
      ps.perturbed = npert;
    } else {
      ps.positive = k;
    }
    ps.det_sign = sign;
  };
  for (std::size_t i = 0; i < ns; ++i)
    finish(s.fronts[small[i]], lu ? -1 : info[i], perturbed[i], perm.data() + perm_off[i]);
  for (std::size_t i = 0; i < big.size(); ++i)
    finish(s.fronts[big[i]], (!lu && pinfo[i] > 0) ? pinfo[i] - 1 : -1, perturbed[ns + i],
           perm.data() + big_perm_at[i]);
}

}  // namespace

bool device_present() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return false;
  }
  return count > 0;
}

}  // namespace strata::cuda

namespace strata::numeric {

bool cuda_available() { return cuda::device_present(); }

int cuda_device_count() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return 0;
  }
  return count;
}

std::unique_ptr<Executor> make_cuda_executor(const Options& opts, int device) {
  if (!cuda::device_present())
    throw NotSupported("the CUDA backend was asked for, but no CUDA GPU is visible");
  if (device != 0)
    throw NotSupported("the CUDA executor runs on device 0 only for now");
  return std::make_unique<cuda::CudaExecutor>(opts);
}

}  // namespace strata::numeric
