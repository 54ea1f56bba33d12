// strata — a large front's update split over idle GPUs (several GPUs; issue 6's "large
// top fronts are split across GPUs by tiles", docs/multigpu.md).
//
// What: while one GPU factors a front of the top part (or of an upper part in a layer
// with fewer parts than GPUs), the other GPUs have nothing to do: the multi-worker driver
// hands them to it as helpers (FactorContext::helpers). For a front whose contribution
// block C has at least Options::split_front_min_cb rows (n = m − k), the owner computes
// the pivot block and the panel (POTRF + TRSM, or GETRF + the two TRSMs) as before, and
// the update C −= L₂₁L₂₁ᵀ (LLᵀ, lower triangle) or C −= L₂₁U₁₂ (LU) — n²k (LU: 2n²k)
// flops against the panel's k²n, i.e. almost all of a large front's work — is cut into
// one column strip per GPU:
//   strip 0 (the leftmost, tallest one) on the owner's lane: SYRK on its diagonal block,
//     GEMM below;
//   strip j ≥ 1 on helper j's lane, into the helper's pool (its own fronts are done, the
//     pool is free): C's strip (rows from the strip's first column down; LU: all n rows)
//     copied there as soon as the front is assembled — while the owner still factors the
//     pivot block —, then the panel rows the strip needs (LU: all of L₂₁ and the strip's
//     columns of U₁₂) once the owner's panel is done, one GEMM, and the strip copied back
//     into the owner's front. All copies are peer-to-peer (cudaMemcpy2DAsync between
//     devices, unified addressing; peer access enabled both ways).
// Strips have about equal flops (LLᵀ: equal areas of the lower triangle, so the left
// strips are narrower; LU: equal widths), their bounds multiples of 64 columns.
//
// Why strips of the update and not a distributed front (ScaLAPACK-style 1-D block-cyclic
// columns over the GPUs, the plan in docs/multigpu.md): the front, its assembly, its
// panel and its contribution block stay where the one-GPU code puts them — the stores,
// the factor layout, the chunk pipeline and the host bookkeeping are unchanged — and
// what moves per front is C's strips twice and the panel once, about (n² + nk)·8 bytes
// over NVLink against n²k flops: with k = 1024 pivots that is ≈ 128 flops per byte,
// enough to keep the GEMMs fed at NVLink's hundreds of GB/s. The price: the pivot block
// and panel are still one GPU's, in sequence with the strips.
//
// Synchronization: the helper's lane waits for the owner's `assembled` event (before
// copying C's strip) and for team_.split_ready, recorded on the owner's lane after the panel
// (before copying the panel rows); the owner's stream waits for each used helper's
// team_.help_done before the chunk's stores (join_team). set_team makes each helper's lane
// wait for its own stream first (its last part's work may still be in flight), and
// release_team (end_part) waits on the host for the helpers' lanes, so a helper's pool
// is its own again when the driver moves on. One team_.help_done per helper suffices: its
// lane runs the strips in order and the owner waits for the last one.
//
// Results: the strips' GEMMs add the same k products per entry as the one-GPU SYRK/GEMM,
// in cuBLAS's order for that shape, so a split front agrees with the one-GPU factor to
// rounding (not bitwise); tests compare within 1e-13 (test_multi_gpu).
#include <algorithm>
#include <string>

#include "numeric/cuda/cuda_executor.hpp"

namespace strata::cuda {

namespace {
constexpr std::int64_t kStripAlign = 64;  // strip bounds: multiples of this many columns

// Peer access from the current device to `peer` (idempotent).
void enable_peer_access(int peer) {
  const cudaError_t e = cudaDeviceEnablePeerAccess(peer, 0);
  if (e == cudaErrorPeerAccessAlreadyEnabled)
    (void)cudaGetLastError();
  else
    STRATA_CUDA(e);
}

// Column bounds c[0] = 0 < … < c[parts] = n of `parts` strips of an n × n update with
// about equal flops: equal widths (LU), or equal areas of the lower triangle (LLᵀ: the
// strip [a, b) holds Σ_{a ≤ c < b} (n − c) entries); bounds rounded to kStripAlign. A
// strip may come out empty on a narrow update.
std::vector<std::int64_t> strip_bounds(std::int64_t n, int parts, bool lower) {
  std::vector<std::int64_t> c(parts + 1, n);
  c[0] = 0;
  const double total = lower ? 0.5 * static_cast<double>(n) * static_cast<double>(n + 1)
                             : static_cast<double>(n) * static_cast<double>(n);
  double area = 0;
  std::int64_t col = 0;
  for (int j = 1; j < parts; ++j) {
    const double target = total * j / parts;
    while (col < n && area < target) {
      area += lower ? static_cast<double>(n - col) : static_cast<double>(n);
      ++col;
    }
    const std::int64_t rounded = (col + kStripAlign / 2) / kStripAlign * kStripAlign;
    c[j] = std::clamp(rounded, c[j - 1], n);
  }
  return c;
}
}  // namespace

Lane& CudaExecutor::help_lane() { return *lanes()[1]; }

void CudaExecutor::set_team(const numeric::FactorContext& ctx) {
  team_.members.clear();
  team_.used.clear();
  if ((split_min_cb_ <= 0 && dist_min_rows_ <= 0) || ctx.helpers.empty() ||
      ctx.type == MatrixType::symmetric_indefinite)
    return;
  for (numeric::Executor* e : ctx.helpers) {
    auto* h = dynamic_cast<CudaExecutor*>(e);
    if (!h || h == this || h->device_ == device_) continue;
    int there = 0, back = 0;
    STRATA_CUDA(cudaDeviceCanAccessPeer(&there, device_, h->device_));
    STRATA_CUDA(cudaDeviceCanAccessPeer(&back, h->device_, device_));
    if (!there || !back) continue;  // through host memory the strips would not pay
    enable_peer_access(h->device_);
    STRATA_CUDA(cudaSetDevice(h->device_));
    enable_peer_access(device_);
    Lane& hl = h->help_lane();
    STRATA_CUDA(cudaEventRecord(h->team_.help_ready, h->stream_));
    STRATA_CUDA(cudaStreamWaitEvent(hl.stream, h->team_.help_ready, 0));
    STRATA_CUDA(cudaSetDevice(device_));
    team_.members.push_back(h);
  }
}

void CudaExecutor::release_team() {
  for (CudaExecutor* h : team_.members) {
    if (!h->team_.helped) continue;
    STRATA_CUDA(cudaSetDevice(h->device_));
    STRATA_CUDA(cudaStreamSynchronize(h->help_lane().stream));
    h->team_.helped = false;
  }
  STRATA_CUDA(cudaSetDevice(device_));
  team_.members.clear();
  team_.used.clear();
}

void CudaExecutor::join_team() {
  for (CudaExecutor* h : team_.used)
    STRATA_CUDA(cudaStreamWaitEvent(stream_, h->team_.help_done, 0));
  team_.used.clear();
}

void CudaExecutor::split_update(Lane& lane, double* F, int m, int k, bool lu,
                                cudaEvent_t assembled) {
  const double one = 1.0, minus_one = -1.0;
  const std::int64_t n = m - k;
  const std::size_t ld = static_cast<std::size_t>(m);
  const int parts = static_cast<int>(team_.members.size()) + 1;
  const std::vector<std::int64_t> c = strip_bounds(n, parts, !lu);
  double* const C = F + static_cast<std::size_t>(k) * ld + k;  // n × n, leading dimension m
  double* const L = F + k;                                     // n × k
  STRATA_CUDA(cudaEventRecord(team_.split_ready, lane.stream));
  std::vector<int> mine{0};  // strips done here: the first, and any no helper could hold
  for (int j = 1; j < parts; ++j) {
    const std::int64_t a = c[j], w = c[j + 1] - c[j];
    if (w <= 0) continue;
    const std::int64_t r0 = lu ? 0 : a, h = n - r0;  // the strip's rows [r0, n)
    const std::size_t need = static_cast<std::size_t>(h * w + h * k + (lu ? k * w : 0));
    CudaExecutor& x = *team_.members[j - 1];
    if (x.pool_.size() < need) {
      mine.push_back(j);
      continue;
    }
    STRATA_CUDA(cudaSetDevice(x.device_));
    Lane& hl = x.help_lane();
    double* const Cg = x.pool_.data();
    double* const Lg = Cg + h * w;
    double* const Ug = Lg + h * k;
    const std::size_t row_bytes = sizeof(double) * static_cast<std::size_t>(h);
    double* const Cs = C + static_cast<std::size_t>(a) * ld + r0;  // the strip in the front
    STRATA_CUDA(cudaStreamWaitEvent(hl.stream, assembled, 0));
    STRATA_CUDA(cudaMemcpy2DAsync(Cg, row_bytes, Cs, sizeof(double) * ld, row_bytes, w,
                                  cudaMemcpyDefault, hl.stream));
    STRATA_CUDA(cudaStreamWaitEvent(hl.stream, team_.split_ready, 0));
    STRATA_CUDA(cudaMemcpy2DAsync(Lg, row_bytes, L + r0, sizeof(double) * ld, row_bytes, k,
                                  cudaMemcpyDefault, hl.stream));
    if (lu) {  // U₁₂'s columns of the strip: rows 0..k of front columns k + a ..
      STRATA_CUDA(cudaMemcpy2DAsync(Ug, sizeof(double) * k, F + (k + a) * ld, sizeof(double) * ld,
                                    sizeof(double) * k, w, cudaMemcpyDefault, hl.stream));
      STRATA_CUBLAS(cublasDgemm(hl.blas, CUBLAS_OP_N, CUBLAS_OP_N, static_cast<int>(h),
                                static_cast<int>(w), k, &minus_one, Lg, static_cast<int>(h), Ug, k,
                                &one, Cg, static_cast<int>(h)));
    } else {  // rows [a, n) of L times its rows [a, a + w) transposed (the first w of Lg)
      STRATA_CUBLAS(cublasDgemm(hl.blas, CUBLAS_OP_N, CUBLAS_OP_T, static_cast<int>(h),
                                static_cast<int>(w), k, &minus_one, Lg, static_cast<int>(h), Lg,
                                static_cast<int>(h), &one, Cg, static_cast<int>(h)));
    }
    STRATA_CUDA(cudaMemcpy2DAsync(Cs, sizeof(double) * ld, Cg, row_bytes, row_bytes, w,
                                  cudaMemcpyDefault, hl.stream));
    STRATA_CUDA(cudaEventRecord(x.team_.help_done, hl.stream));
    x.team_.helped = true;
    ++x.team_.strips_helped;
    x.team_.help_bytes += sizeof(double) * need + sizeof(double) * static_cast<std::size_t>(h * w);
    if (std::find(team_.used.begin(), team_.used.end(), &x) == team_.used.end())
      team_.used.push_back(&x);
  }
  STRATA_CUDA(cudaSetDevice(device_));
  for (const int j : mine) {
    const std::int64_t a = c[j], w = c[j + 1] - c[j];
    if (w <= 0) continue;
    double* const Cs = C + static_cast<std::size_t>(a) * ld;  // column a of C, row 0
    if (lu) {
      STRATA_CUBLAS(cublasDgemm(lane.blas, CUBLAS_OP_N, CUBLAS_OP_N, static_cast<int>(n),
                                static_cast<int>(w), k, &minus_one, L, m, F + (k + a) * ld, m, &one,
                                Cs, m));
      continue;
    }
    STRATA_CUBLAS(cublasDsyrk(lane.blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, static_cast<int>(w),
                              k, &minus_one, L + a, m, &one, Cs + a, m));
    if (a + w < n)
      STRATA_CUBLAS(cublasDgemm(lane.blas, CUBLAS_OP_N, CUBLAS_OP_T, static_cast<int>(n - a - w),
                                static_cast<int>(w), k, &minus_one, L + a + w, m, L + a, m, &one,
                                Cs + a + w, m));
  }
  ++team_.fronts_split;
}

void CudaExecutor::report_worker(DeviceStats& d) const {
  d.fronts_split += team_.fronts_split;
  d.fronts_distributed += team_.fronts_distributed;
  d.strips_helped += team_.strips_helped;
  d.bytes_transferred += team_.help_bytes;
}

}  // namespace strata::cuda
