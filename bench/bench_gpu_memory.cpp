// strata benchmark — the GPU backend under a device memory budget (the paper's
// solvability claim; experiment 4 of the report), the GPU block-size sweep (experiment 1,
// GPU part) and the device's own figures (pinned transfer bandwidth, cuBLAS DGEMM peak),
// measured in one run on the lent machine.
//
// Solvability: for each problem, the factorization in core (device_memory_limit 0) and
// with the budget set to factor bytes / ratio for each --ratios; per run the median of
// --repeat refactorizations, bytes moved each way, tiled fronts, spilled contribution
// blocks, backward error, and the transfer floor: the larger of (bytes to the device /
// host→device bandwidth) and (bytes to the host / device→host bandwidth), with the
// bandwidths measured here on pinned memory. Each budget runs once per pair of
// --tiled-pool-shares, --tiled-stream-columns and --tiled-prefetch
// (Options::gpu_tiled_pool_share, gpu_tiled_stream_columns, gpu_tiled_prefetch; default:
// the library's), the in-core run once.
// Block size: the in-core GPU factorization time for each --block-sizes.
// Dense kernels: the rates cuBLAS / cuSOLVER reach on the shapes of the large fronts
// (a front of m rows and k pivots: POTRF of k×k, TRSM of (m−k)×k, the rank-k update of
// the (m−k)×(m−k) contribution block by DSYRK and by GEMMs over column blocks), next to
// the DGEMM peak: where the factorization loses the peak (issue 5's ≥ 40% target).
//
// Panel kernels: in-core Cholesky refactorization time for each value of
// Options::gpu_panel_kernel_max_pivots (which fronts get our pivot-block and panel
// kernels, kernels_panel.cu, instead of POTRF + TRSM). POTRF blocks: the same for
// Options::gpu_potrf_block_size (the larger fronts' pivot block and panel in column
// blocks, llt_blocked.cu, or by one POTRF and one TRSM). Recursive panel: the same for
// Options::gpu_recursive_panel off and on (llt_recursive.cu). LU panel: in-core LU
// refactorization time for each value of Options::gpu_lu_strip_pivots (the strips in
// which large LU fronts are eliminated by our batched kernels, lu_fronts.cu; 0: GETRF +
// TRSMs instead), on LU problems, with how many fronts each path took.
//
//   bench_gpu_memory [--parts devices,kernels,solvability,blocks,panel,potrf-block,
//                             recursive-panel,lu-panel]
//                    [--problems a,b] [--potrf-blocks 0,128,...]
//                    [--ratios 1,5,20,50] [--tiled-pool-shares 0,0.5,...]
//                    [--tiled-stream-columns 0,256,...] [--tiled-prefetch 0,1]
//                    [--block-sizes 256,...] [--block-problems a,b]
//                    [--panel-problems a,b] [--panel-max-pivots 0,64,...]
//                    [--lu-panel-problems a,b] [--lu-strip-pivots 0,256,...]
//                    [--fronts m:k,...] [--repeat R] [--tag NAME] [--results-dir DIR]
#include <cublas_v2.h>
#include <cuda_runtime.h>
#include <cusolverDn.h>
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <tuple>

#include "base/timer.hpp"
#include "bench_common.hpp"
#include "core/stats_json.hpp"
#include "crash_report.hpp"
#include "numeric/cuda/cuda_executor.hpp"
#include "numeric/cuda/kernels.cuh"
#include "numeric/factor.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

namespace {

void check(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string(what) + ": " + cudaGetErrorString(e));
}

// Pinned host↔device bandwidth in bytes/s (median of 5 copies of 256 MiB).
std::pair<double, double> transfer_bandwidth() {
  const std::size_t bytes = 256u << 20;
  void *h = nullptr, *d = nullptr;
  check(cudaMallocHost(&h, bytes), "cudaMallocHost");
  check(cudaMalloc(&d, bytes), "cudaMalloc");
  std::vector<double> up, down;
  for (int k = 0; k < 5; ++k) {
    Timer t;
    check(cudaMemcpy(d, h, bytes, cudaMemcpyHostToDevice), "H2D");
    up.push_back(bytes / t.seconds());
    t.reset();
    check(cudaMemcpy(h, d, bytes, cudaMemcpyDeviceToHost), "D2H");
    down.push_back(bytes / t.seconds());
  }
  cudaFree(d);
  cudaFreeHost(h);
  return {bench::median(up), bench::median(down)};
}

// cuBLAS DGEMM rate on n×n matrices (best of 5), in FLOP/s.
double dgemm_peak(int n) {
  double *a = nullptr, *b = nullptr, *c = nullptr;
  const std::size_t bytes = sizeof(double) * n * n;
  check(cudaMalloc(&a, bytes), "cudaMalloc");
  check(cudaMalloc(&b, bytes), "cudaMalloc");
  check(cudaMalloc(&c, bytes), "cudaMalloc");
  check(cudaMemset(a, 0, bytes), "memset");
  check(cudaMemset(b, 0, bytes), "memset");
  cublasHandle_t h;
  cublasCreate(&h);
  const double one = 1.0, zero = 0.0;
  double best = 0;
  for (int k = 0; k < 6; ++k) {
    cudaDeviceSynchronize();
    Timer t;
    cublasDgemm(h, CUBLAS_OP_N, CUBLAS_OP_N, n, n, n, &one, a, n, b, n, &zero, c, n);
    cudaDeviceSynchronize();
    if (k > 0) best = std::max(best, 2.0 * n * n * static_cast<double>(n) / t.seconds());
  }
  cublasDestroy(h);
  cudaFree(a);
  cudaFree(b);
  cudaFree(c);
  return best;
}

// Best of 3 (after one warm-up) of f(), timed on the device with events, in seconds.
template <class F>
double device_seconds(F&& f) {
  cudaEvent_t a, b;
  check(cudaEventCreate(&a), "cudaEventCreate");
  check(cudaEventCreate(&b), "cudaEventCreate");
  double best = 1e300;
  for (int r = 0; r < 4; ++r) {
    check(cudaEventRecord(a), "cudaEventRecord");
    f();
    check(cudaEventRecord(b), "cudaEventRecord");
    check(cudaEventSynchronize(b), "cudaEventSynchronize");
    float ms = 0;
    check(cudaEventElapsedTime(&ms, a, b), "cudaEventElapsedTime");
    if (r > 0) best = std::min(best, 1e-3 * ms);
  }
  cudaEventDestroy(a);
  cudaEventDestroy(b);
  return best;
}

// `count` fronts of m rows and k pivots at pool + p·m² as the DeviceTree and item list
// that cuda::launch_llt_panel (kernels_panel.cu) reads, with its workspace.
struct PanelFronts {
  std::int64_t* arr = nullptr;  // fronts, pos_offset, n_rows, n_pivots, items (2 each)
  double* work = nullptr;
  int* info = nullptr;
  cuda::DeviceTree t{};
  std::vector<std::int64_t> rows, pivots;
  PanelFronts(int m, int k, int count) : rows(count, m), pivots(count, k) {
    std::vector<std::int64_t> h(6 * static_cast<std::size_t>(count));
    for (int p = 0; p < count; ++p) {
      h[p] = p;
      h[count + p] = static_cast<std::int64_t>(p) * m * m;
      h[2 * count + p] = m;
      h[3 * count + p] = k;
      h[4 * count + 2 * p] = p;
      h[4 * count + 2 * p + 1] = p;
    }
    check(cudaMalloc(&arr, sizeof(std::int64_t) * h.size()), "cudaMalloc");
    check(cudaMemcpy(arr, h.data(), sizeof(std::int64_t) * h.size(), cudaMemcpyHostToDevice),
          "H2D");
    check(cudaMalloc(&work, sizeof(double) * cuda::llt_panel_work_size(count)), "cudaMalloc");
    check(cudaMalloc(&info, sizeof(int) * count), "cudaMalloc");
    t.fronts = arr;
    t.pos_offset = arr + count;
    t.n_rows = arr + 2 * count;
    t.n_pivots = arr + 3 * count;
  }
  ~PanelFronts() {
    cudaFree(arr);
    cudaFree(work);
    cudaFree(info);
  }
  PanelFronts(const PanelFronts&) = delete;
  PanelFronts& operator=(const PanelFronts&) = delete;
  void run(double* pool) {
    cuda::launch_llt_panel(t, arr + 4 * pivots.size(), rows, pivots, pool, work, info, nullptr);
  }
};

// The first k columns (m×k) of the m×m front at F, to the host.
std::vector<double> panel_to_host(const double* F, int m, int k) {
  std::vector<double> h(static_cast<std::size_t>(m) * k);
  check(cudaMemcpy(h.data(), F, sizeof(double) * h.size(), cudaMemcpyDeviceToHost), "D2H");
  for (int j = 0; j < k; ++j)  // the strict upper triangle is not part of the factor
    for (int i = 0; i < j; ++i) h[static_cast<std::size_t>(j) * m + i] = 0;
  return h;
}

// The dense kernels of a front of m rows and k pivots (LLᵀ), each timed alone on a
// well-conditioned SPD-like matrix (diagonal m, off-diagonal entries in [0, 1)): rates in
// FLOP/s counted with the kernel's own flop count (the GEMM-blocked update is credited
// with the rank-k update's (m−k)²·k, not the extra work it does on the diagonal blocks).
json front_kernels(int m, int k) {
  const int c = m - k;
  const std::size_t n = static_cast<std::size_t>(m) * m;
  std::vector<double> h(n);
  std::uint64_t x = 88172645463325252ull;
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i) {
      x ^= x << 13, x ^= x >> 7, x ^= x << 17;
      h[static_cast<std::size_t>(j) * m + i] = i == j ? m : (x >> 11) * 0x1.0p-53;
    }
  double *F = nullptr, *F0 = nullptr, *W = nullptr;
  int* info = nullptr;
  check(cudaMalloc(&F, sizeof(double) * n), "cudaMalloc");
  check(cudaMalloc(&F0, sizeof(double) * n), "cudaMalloc");
  check(cudaMemcpy(F0, h.data(), sizeof(double) * n, cudaMemcpyHostToDevice), "H2D");
  check(cudaMalloc(&info, sizeof(int)), "cudaMalloc");
  cublasHandle_t blas;
  cusolverDnHandle_t sol;
  if (cublasCreate(&blas) != CUBLAS_STATUS_SUCCESS) throw std::runtime_error("cublasCreate");
  if (cusolverDnCreate(&sol) != CUSOLVER_STATUS_SUCCESS)
    throw std::runtime_error("cusolverDnCreate");
  int lwork = 0;
  cusolverDnDpotrf_bufferSize(sol, CUBLAS_FILL_MODE_LOWER, k, F, m, &lwork);
  check(cudaMalloc(&W, sizeof(double) * std::max(lwork, 1)), "cudaMalloc");
  // the front back to its assembled values (device to device: fast next to the kernels)
  auto reset = [&] {
    check(cudaMemcpyAsync(F, F0, sizeof(double) * n, cudaMemcpyDeviceToDevice), "D2D");
  };
  const double one = 1.0, minus_one = -1.0;
  double* L21 = F + k;
  double* C = F + static_cast<std::size_t>(k) * m + k;
  json row = {{"m", m}, {"k", k}};
  const double kd = k, cd = c;
  reset();
  const double t_potrf = device_seconds([&] {
    reset();
    cusolverDnDpotrf(sol, CUBLAS_FILL_MODE_LOWER, k, F, m, W, lwork, info);
  });
  // the copy inside the timed region, measured alone and taken off
  const double t_copy = device_seconds(reset);
  row["potrf_flops_per_second"] = kd * kd * kd / 3 / std::max(t_potrf - t_copy, 1e-9);
  // an LU front's pivot block: cuSOLVER GETRF of k×k with partial pivoting and without
  // (devIpiv null), credited with 2k³/3 flops (the executor's large LU fronts use the first)
  {
    int glwork = 0;
    cusolverDnDgetrf_bufferSize(sol, k, k, F, m, &glwork);
    double* GW = nullptr;
    int* ipiv = nullptr;
    check(cudaMalloc(&GW, sizeof(double) * std::max(glwork, 1)), "cudaMalloc");
    check(cudaMalloc(&ipiv, sizeof(int) * k), "cudaMalloc");
    for (const bool pivoting : {true, false}) {
      const double t = device_seconds([&] {
        reset();
        cusolverDnDgetrf(sol, k, k, F, m, GW, pivoting ? ipiv : nullptr, info);
      });
      row[pivoting ? "getrf_flops_per_second" : "getrf_nopiv_flops_per_second"] =
          2 * kd * kd * kd / 3 / std::max(t - t_copy, 1e-9);
    }
    cudaFree(GW);
    cudaFree(ipiv);
  }
  double t_trsm = 0;
  if (c > 0) {
    t_trsm = device_seconds([&] {
      cublasDtrsm(blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                  CUBLAS_DIAG_NON_UNIT, c, k, &one, F, m, L21, m);
    });
    row["trsm_flops_per_second"] = cd * kd * kd / t_trsm;
  }
  // our pivot-block and panel kernels (kernels_panel.cu) in place of POTRF + TRSM, and the
  // largest difference between the two factors, relative to the largest entry
  {
    reset();
    cusolverDnDpotrf(sol, CUBLAS_FILL_MODE_LOWER, k, F, m, W, lwork, info);
    if (c > 0)
      cublasDtrsm(blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                  CUBLAS_DIAG_NON_UNIT, c, k, &one, F, m, L21, m);
    const std::vector<double> lib = panel_to_host(F, m, k);
    PanelFronts one_front(m, k, 1);
    const double t_ours = device_seconds([&] {
      reset();
      one_front.run(F);
    });
    const std::vector<double> ours = panel_to_host(F, m, k);
    double diff = 0, big = 0;
    for (std::size_t i = 0; i < lib.size(); ++i) {
      diff = std::max(diff, std::abs(lib[i] - ours[i]));
      big = std::max(big, std::abs(lib[i]));
    }
    const double flops = kd * kd * kd / 3 + cd * kd * kd;
    row["potrf_trsm_flops_per_second"] = flops / std::max(t_potrf - t_copy + t_trsm, 1e-9);
    row["panel_kernels_flops_per_second"] = flops / std::max(t_ours - t_copy, 1e-9);
    row["panel_kernels_max_rel_diff"] = diff / big;
    // the pivot block and panel in column blocks (llt_blocked.cu, what the executor runs for
    // Options::gpu_potrf_block_size), against the same one POTRF + TRSM
    for (int nb : {128, 256, 512}) {
      if (nb >= k) continue;
      cuda::Lane ln;  // the default stream and this function's handles
      ln.blas = blas;
      ln.solver = sol;
      reset();
      cuda::llt_pivot_block_and_panel(ln, F, m, k, nb, info);  // sizes its workspaces
      const double t = device_seconds([&] {
        reset();
        cuda::llt_pivot_block_and_panel(ln, F, m, k, nb, info);
      });
      const std::vector<double> blocked = panel_to_host(F, m, k);
      double bdiff = 0;
      for (std::size_t i = 0; i < lib.size(); ++i)
        bdiff = std::max(bdiff, std::abs(lib[i] - blocked[i]));
      const std::string key = "blocked_" + std::to_string(nb) + "_potrf_trsm";
      row[key + "_flops_per_second"] = flops / std::max(t - t_copy, 1e-9);
      row[key + "_max_rel_diff"] = bdiff / big;
    }
    // by recursion on the pivot columns (llt_recursive.cu, Options::gpu_recursive_panel)
    {
      cuda::Lane ln;  // the default stream and this function's handles
      ln.blas = blas;
      ln.solver = sol;
      reset();
      cuda::llt_pivot_block_and_panel_recursive(ln, F, m, k, info);  // sizes its workspace
      const double t = device_seconds([&] {
        reset();
        cuda::llt_pivot_block_and_panel_recursive(ln, F, m, k, info);
      });
      const std::vector<double> rec = panel_to_host(F, m, k);
      double rdiff = 0;
      for (std::size_t i = 0; i < lib.size(); ++i)
        rdiff = std::max(rdiff, std::abs(lib[i] - rec[i]));
      row["recursive_potrf_trsm_flops_per_second"] = flops / std::max(t - t_copy, 1e-9);
      row["recursive_potrf_trsm_max_rel_diff"] = rdiff / big;
    }
  }
  if (c > 0) {
    // the panel's TRSM by the explicit inverse: L11 copied and inverted (cuSOLVER
    // Xtrtri), then one GEMM into a buffer (GEMM cannot write over its input) and a copy
    // back — the variant the library kernels' rates above suggest for k ≲ 2000
    {
      double *inv = nullptr, *tmp = nullptr, *dwork = nullptr;
      int* tinfo = nullptr;
      check(cudaMalloc(&inv, sizeof(double) * k * k), "cudaMalloc");
      check(cudaMalloc(&tmp, sizeof(double) * c * k), "cudaMalloc");
      check(cudaMalloc(&tinfo, sizeof(int)), "cudaMalloc");
      std::size_t dbytes = 0, hbytes = 0;
      cusolverDnXtrtri_bufferSize(sol, CUBLAS_FILL_MODE_LOWER, CUBLAS_DIAG_NON_UNIT, k, CUDA_R_64F,
                                  inv, k, &dbytes, &hbytes);
      check(cudaMalloc(&dwork, std::max<std::size_t>(dbytes, 8)), "cudaMalloc");
      std::vector<char> hwork(std::max<std::size_t>(hbytes, 8));
      const double zero = 0.0;
      auto invert = [&] {
        cudaMemcpy2DAsync(inv, sizeof(double) * k, F, sizeof(double) * m, sizeof(double) * k, k,
                          cudaMemcpyDeviceToDevice);
        cusolverDnXtrtri(sol, CUBLAS_FILL_MODE_LOWER, CUBLAS_DIAG_NON_UNIT, k, CUDA_R_64F, inv, k,
                         dwork, dbytes, hwork.data(), hbytes, tinfo);
      };
      const double t_inv = device_seconds(invert);
      row["trtri_flops_per_second"] = kd * kd * kd / 3 / t_inv;
      const double t_inv_trsm = device_seconds([&] {
        invert();
        cublasDgemm(blas, CUBLAS_OP_N, CUBLAS_OP_T, c, k, k, &one, L21, m, inv, k, &zero, tmp, c);
        cudaMemcpy2DAsync(L21, sizeof(double) * m, tmp, sizeof(double) * c, sizeof(double) * c, k,
                          cudaMemcpyDeviceToDevice);
      });
      row["trsm_by_inverse_flops_per_second"] = cd * kd * kd / t_inv_trsm;
      cudaFree(inv);
      cudaFree(tmp);
      cudaFree(tinfo);
      cudaFree(dwork);
    }
    const double t_syrk = device_seconds([&] {
      cublasDsyrk(blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, c, k, &minus_one, L21, m, &one, C, m);
    });
    row["syrk_flops_per_second"] = cd * cd * kd / t_syrk;
    for (int nb : {512, 1024, 2048}) {
      if (nb >= c) continue;
      const double t = device_seconds([&] {
        for (int j = 0; j < c; j += nb) {
          const int w = std::min(nb, c - j);
          cublasDgemm(blas, CUBLAS_OP_N, CUBLAS_OP_T, c - j, w, k, &minus_one, L21 + j, m, L21 + j,
                      m, &one, C + static_cast<std::size_t>(j) * m + j, m);
        }
      });
      row["gemm_blocked_" + std::to_string(nb) + "_flops_per_second"] = cd * cd * kd / t;
    }
    const double t_gemm = device_seconds([&] {
      cublasDgemm(blas, CUBLAS_OP_N, CUBLAS_OP_T, c, c, k, &minus_one, L21, m, L21, m, &one, C, m);
    });
    row["gemm_full_flops_per_second"] = 2 * cd * cd * kd / t_gemm;
  }
  cublasDestroy(blas);
  cusolverDnDestroy(sol);
  cudaFree(W);
  cudaFree(info);
  cudaFree(F);
  cudaFree(F0);
  return row;
}

// A well-conditioned SPD m×m front on the device (diagonal m, entry (i, j) = 1/(1 + i + j)
// elsewhere): the assembled front the many-front measurements below start from.
double* device_front(int m) {
  const std::size_t n = static_cast<std::size_t>(m) * m;
  std::vector<double> h(n);
  for (int j = 0; j < m; ++j)
    for (int i = 0; i < m; ++i)
      h[static_cast<std::size_t>(j) * m + i] = i == j ? m : 1.0 / (1.0 + i + j);
  double* F0 = nullptr;
  check(cudaMalloc(&F0, sizeof(double) * n), "cudaMalloc");
  check(cudaMemcpy(F0, h.data(), sizeof(double) * n, cudaMemcpyHostToDevice), "H2D");
  return F0;
}

// `count` streams, each with a cuBLAS and a cuSOLVER handle, a POTRF workspace for the k×k
// block of an m×m front like `sample` and an info word: the executor's lanes, for the
// library side of the many-front measurements.
struct BenchLanes {
  struct Lane {
    cudaStream_t s{};
    cublasHandle_t blas{};
    cusolverDnHandle_t sol{};
    double* W = nullptr;
    int* info = nullptr;
    int lwork = 0;
  };
  std::vector<Lane> lanes;
  BenchLanes(int count, int m, int k, double* sample) : lanes(count) {
    for (Lane& l : lanes) {
      check(cudaStreamCreateWithFlags(&l.s, cudaStreamNonBlocking), "cudaStreamCreate");
      cublasCreate(&l.blas);
      cublasSetStream(l.blas, l.s);
      cusolverDnCreate(&l.sol);
      cusolverDnSetStream(l.sol, l.s);
      cusolverDnDpotrf_bufferSize(l.sol, CUBLAS_FILL_MODE_LOWER, k, sample, m, &l.lwork);
      check(cudaMalloc(&l.W, sizeof(double) * std::max(l.lwork, 1)), "cudaMalloc");
      check(cudaMalloc(&l.info, sizeof(int)), "cudaMalloc");
    }
  }
  ~BenchLanes() {
    for (Lane& l : lanes) {
      cudaFree(l.W);
      cudaFree(l.info);
      cublasDestroy(l.blas);
      cusolverDnDestroy(l.sol);
      cudaStreamDestroy(l.s);
    }
  }
  BenchLanes(const BenchLanes&) = delete;
  BenchLanes& operator=(const BenchLanes&) = delete;
  // POTRF of the m×m front F's k×k block, then TRSM of its panel, on lane l
  void potrf_trsm(int l, double* F, int m, int k) {
    Lane& ln = lanes[l];
    const double one = 1.0;
    cusolverDnDpotrf(ln.sol, CUBLAS_FILL_MODE_LOWER, k, F, m, ln.W, ln.lwork, ln.info);
    if (m > k)
      cublasDtrsm(ln.blas, CUBLAS_SIDE_RIGHT, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_T,
                  CUBLAS_DIAG_NON_UNIT, m - k, k, &one, F, m, F + k, m);
  }
};

// Best of 3 (after one warm-up) of f() with `reset` before each, in host seconds.
template <class R, class F>
double best_of_3(R&& reset, F&& f) {
  double best = 1e300;
  for (int rep = 0; rep < 4; ++rep) {
    reset();
    check(cudaDeviceSynchronize(), "cudaDeviceSynchronize");
    Timer t;
    f();
    check(cudaDeviceSynchronize(), "cudaDeviceSynchronize");
    if (rep > 0) best = std::min(best, t.seconds());
  }
  return best;
}

// Many fronts of one shape (m rows, k pivots) factored side by side — POTRF, TRSM, SYRK
// each, the large-front sequence of the CUDA executor — on `streams` streams with a
// cuBLAS and a cuSOLVER handle each, `per_stream` fronts per stream: the aggregate FLOP/s.
// A level of the tree holds tens to hundreds of such fronts, and the executor runs them
// on its lanes (8 streams): this says how much more streams would hide the latency of
// the library calls on medium fronts.
double concurrent_fronts(int m, int k, int streams, int per_stream) {
  const int c = m - k;
  const std::size_t n = static_cast<std::size_t>(m) * m;
  double* F0 = device_front(m);
  BenchLanes lanes(streams, m, k, F0);
  std::vector<double*> F(streams);
  for (double*& f : F) check(cudaMalloc(&f, sizeof(double) * n), "cudaMalloc");
  const double minus_one = -1.0, one = 1.0;
  const double t = best_of_3(
      [] {},
      [&] {
        for (int r = 0; r < per_stream; ++r)
          for (int l = 0; l < streams; ++l) {
            auto& ln = lanes.lanes[l];
            cudaMemcpyAsync(F[l], F0, sizeof(double) * n, cudaMemcpyDeviceToDevice, ln.s);
            lanes.potrf_trsm(l, F[l], m, k);
            if (c > 0)
              cublasDsyrk(ln.blas, CUBLAS_FILL_MODE_LOWER, CUBLAS_OP_N, c, k, &minus_one, F[l] + k,
                          m, &one, F[l] + static_cast<std::size_t>(k) * m + k, m);
          }
      });
  for (double* f : F) cudaFree(f);
  cudaFree(F0);
  const double kd = k, cd = c;
  const double flops = kd * kd * kd / 3 + cd * kd * kd + cd * cd * kd;
  return flops * streams * per_stream / t;
}

// `count` fronts of one shape, their pivot blocks and panels only (POTRF + TRSM's work):
// by cuSOLVER POTRF + cuBLAS TRSM per front on 8 streams (the executor's lanes), and by
// our kernels in one go (launch_llt_panel) — the aggregate FLOP/s of each, in that order.
std::pair<double, double> batched_panels(int m, int k, int count) {
  const std::size_t n = static_cast<std::size_t>(m) * m;
  double* F0 = device_front(m);
  double* pool = nullptr;
  check(cudaMalloc(&pool, sizeof(double) * n * count), "cudaMalloc");
  constexpr int streams = 8;
  BenchLanes lanes(streams, m, k, F0);
  auto reset = [&] {
    for (int p = 0; p < count; ++p)
      check(cudaMemcpyAsync(pool + n * p, F0, sizeof(double) * n, cudaMemcpyDeviceToDevice), "D2D");
  };
  const double t_lib = best_of_3(reset, [&] {
    for (int p = 0; p < count; ++p) lanes.potrf_trsm(p % streams, pool + n * p, m, k);
  });
  PanelFronts fronts(m, k, count);
  const double t_ours = best_of_3(reset, [&] { fronts.run(pool); });
  cudaFree(F0);
  cudaFree(pool);
  const double kd = k, cd = m - k;
  const double flops = (kd * kd * kd / 3 + cd * kd * kd) * count;
  return {flops / t_lib, flops / t_ours};
}

struct Run {
  double seconds = 0, berr = 0;
  FactorStats fs;
  bool on_device = false;
  double solve_seconds = 0;        // the checked solve (Options::solve_check)
  double first_solve_seconds = 0;  // of it, the first application of the factor
  index_t refinement_steps = 0;
};

Run run(const bench::Problem& p, Options o, int repeat) {
  Solver s(o);
  s.analyze(p.a);
  s.factorize(p.a);
  std::vector<double> times;
  for (int k = 0; k < repeat; ++k) {
    Timer t;
    s.refactorize(p.a);
    times.push_back(t.seconds());
  }
  Run r;
  r.seconds = bench::median(times);
  r.fs = s.stats().factor;
  std::vector<double> ones(p.a.n_rows, 1.0), b(p.a.n_rows);
  multiply(p.a, ones.data(), b.data());
  Timer ts;
  auto x = s.solve(b);
  r.solve_seconds = ts.seconds();
  r.on_device = s.stats().solve.on_device;
  r.first_solve_seconds = s.stats().solve.first_solve_seconds;
  r.refinement_steps = s.stats().solve.refinement_steps;
  r.berr = bench::berr(p.a, x, b);
  return r;
}

}  // namespace

static int driver_main(int argc, char** argv) {
  app::report_fatal_signals();  // a crash on a lent machine says where
  CLI::App app{"strata GPU memory-budget, block-size and device benchmark"};
  std::vector<std::string> problems = {"lap3d-60", "elast3d-30", "uelast3d-20"};
  std::vector<std::string> block_problems = {"lap3d-60", "elast3d-30", "uelast3d-20",
                                             "ccx_cubef2f3_K"};
  std::vector<double> ratios = {1, 5, 20, 50};
  std::vector<index_t> block_sizes = {128, 256, 512, 1024, 2048};
  std::vector<std::string> fronts = {"10000:10000", "12000:4000", "8000:4000", "6000:2000",
                                     "4000:1000",   "3000:500",   "2000:250",  "1500:1000",
                                     "1000:100",    "600:64",     "733:65"};
  std::vector<std::string> parts = {"devices", "kernels", "solvability", "blocks"};
  std::vector<std::string> panel_problems = {"lap3d-60", "lap3d-100", "elast3d-30", "elast3d-50"};
  std::vector<index_t> panel_max_pivots = {0, 64, 128, 256, 512, 1024};
  std::vector<std::string> lu_panel_problems = {"uelast3d-20", "uelast3d-30"};
  std::vector<index_t> lu_strip_pivots = {0, 64, 128, 256, 512};
  std::vector<index_t> potrf_blocks = {0, 128, 256, 512};
  int repeat = 3;
  std::string results_dir;
  app.add_option("--parts", parts,
                 "what to measure: devices, kernels, solvability, blocks, panel, potrf-block, "
                 "recursive-panel, lu-panel")
      ->delimiter(',')
      ->check(CLI::IsMember({"devices", "kernels", "solvability", "blocks", "panel", "potrf-block",
                             "recursive-panel", "lu-panel"}));
  app.add_option("--lu-panel-problems", lu_panel_problems,
                 "LU problems for the lu-panel sweep (generated names or .mtx paths)")
      ->delimiter(',');
  std::vector<index_t> tiled_stream_columns = {Options{}.gpu_tiled_stream_columns};
  std::vector<int> tiled_prefetch = {Options{}.gpu_tiled_prefetch ? 1 : 0};
  app.add_option("--tiled-prefetch", tiled_prefetch,
                 "gpu_tiled_prefetch values (0, 1) for each budget of the solvability runs "
                 "(default: the library's)")
      ->delimiter(',');
  app.add_option("--tiled-stream-columns", tiled_stream_columns,
                 "gpu_tiled_stream_columns values for each budget of the solvability runs "
                 "(default: the library's)")
      ->delimiter(',');
  app.add_option("--lu-strip-pivots", lu_strip_pivots,
                 "gpu_lu_strip_pivots values for the lu-panel sweep")
      ->delimiter(',');
  app.add_option("--potrf-blocks", potrf_blocks,
                 "gpu_potrf_block_size values for the potrf-block sweep (on --panel-problems)")
      ->delimiter(',');
  app.add_option("--panel-problems", panel_problems, "problems for the panel-kernel sweep")
      ->delimiter(',');
  app.add_option("--panel-max-pivots", panel_max_pivots,
                 "gpu_panel_kernel_max_pivots values for the panel-kernel sweep")
      ->delimiter(',');
  app.add_option("--fronts", fronts, "front shapes m:k for the dense-kernel table")->delimiter(',');
  app.add_option("--problems", problems, "problems for the budget sweep")->delimiter(',');
  app.add_option("--ratios", ratios, "factor bytes / device budget")->delimiter(',');
  std::vector<double> tiled_pool_shares = {Options{}.gpu_tiled_pool_share};
  app.add_option("--tiled-pool-shares", tiled_pool_shares,
                 "gpu_tiled_pool_share values for each budget of the solvability runs (default: "
                 "the library's)")
      ->delimiter(',');
  app.add_option("--block-problems", block_problems, "problems for the block sweep")
      ->delimiter(',');
  app.add_option("--block-sizes", block_sizes, "max_block_size values")->delimiter(',');
  app.add_option("--repeat", repeat, "factorizations per measurement (median)");
  std::string tag;
  app.add_option("--tag", tag, "label stored in the results and the file name")
      ->check(bench::check_tag);
  app.add_option("--results-dir", results_dir, "where to write the JSON (default bench/results)");
  CLI11_PARSE(app, argc, argv);
  if (!numeric::cuda_available()) {
    fmt::print(stderr, "bench_gpu_memory: no CUDA GPU present\n");
    return 3;
  }
  auto want = [&](const char* part) {
    return std::find(parts.begin(), parts.end(), part) != parts.end();
  };
  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "gpu_memory";
  out["backend"] = "cuda";
  out["tag"] = tag;
  const std::string stem = tag.empty() ? "gpu-memory" : "gpu-memory-" + tag;
  // the transfer floor of the solvability rows needs the bandwidths
  const bool devices = want("devices") || want("solvability");
  const auto [h2d, d2h] = devices ? transfer_bandwidth() : std::pair<double, double>{0, 0};
  const double peak = devices || want("kernels") ? dgemm_peak(8192) : 0;
  if (devices) {
    out["device_figures"] = {{"h2d_bytes_per_second", h2d},
                             {"d2h_bytes_per_second", d2h},
                             {"dgemm_flops_per_second", peak},
                             {"dgemm_n", 8192}};
    fmt::print("pinned H2D {:.1f} GB/s, D2H {:.1f} GB/s; cuBLAS DGEMM (8192) {:.1f} TFLOP/s\n",
               h2d * 1e-9, d2h * 1e-9, peak * 1e-12);
  }
  std::fflush(stdout);

  if (want("kernels")) {
    out["front_kernels"] = {{"dgemm_flops_per_second", peak}, {"rows", json::array()}};
    fmt::print(
        "{:>6} {:>6} {:>7} {:>7} {:>7} {:>7} {:>9} {:>7} {:>9} {:>7} {:>7} {:>7} {:>7} {:>8} "
        "{:>7} {:>8} {:>8} {:>7} {:>8}   TFLOP/s (DGEMM {:.1f}; p+t: POTRF + TRSM, ours: "
        "kernels_panel.cu, diff: max |ours - p+t| / max |L|, rec: p+t by recursion, "
        "llt_recursive.cu, and its diff; bNB: p+t in column blocks of NB, llt_blocked.cu; "
        "getrf k×k, np: without pivoting)\n",
        "m", "k", "potrf", "trsm", "p+t", "ours", "diff", "rec", "rec-diff", "b128", "b256", "b512",
        "syrk", "gemm512", "gemm1k", "gemm2k", "gemm", "getrf", "getrf-np", peak * 1e-12);
    for (const std::string& shape : fronts) {
      const auto colon = shape.find(':');
      if (colon == std::string::npos) throw InvalidInput("--fronts: " + shape + " is not m:k");
      const int m = std::stoi(shape.substr(0, colon)), k = std::stoi(shape.substr(colon + 1));
      if (k < 1 || k > m) throw InvalidInput("--fronts: " + shape + " needs 1 <= k <= m");
      const json row = front_kernels(m, k);
      auto tf = [&](const char* key) {
        return row.contains(key) ? fmt::format("{:.1f}", row[key].get<double>() * 1e-12)
                                 : std::string("-");
      };
      fmt::print(
          "{:>6} {:>6} {:>7} {:>7} {:>7} {:>7} {:>9.1e} {:>7} {:>9.1e} {:>7} {:>7} {:>7} {:>7} "
          "{:>8} {:>7} {:>8} {:>8} {:>7} {:>8}\n",
          m, k, tf("potrf_flops_per_second"), tf("trsm_flops_per_second"),
          tf("potrf_trsm_flops_per_second"), tf("panel_kernels_flops_per_second"),
          row["panel_kernels_max_rel_diff"].get<double>(),
          tf("recursive_potrf_trsm_flops_per_second"),
          row["recursive_potrf_trsm_max_rel_diff"].get<double>(),
          tf("blocked_128_potrf_trsm_flops_per_second"),
          tf("blocked_256_potrf_trsm_flops_per_second"),
          tf("blocked_512_potrf_trsm_flops_per_second"), tf("syrk_flops_per_second"),
          tf("gemm_blocked_512_flops_per_second"), tf("gemm_blocked_1024_flops_per_second"),
          tf("gemm_blocked_2048_flops_per_second"), tf("gemm_full_flops_per_second"),
          tf("getrf_flops_per_second"), tf("getrf_nopiv_flops_per_second"));
      std::fflush(stdout);
      out["front_kernels"]["rows"].push_back(row);
    }
    // pivot blocks and panels of many fronts at once: the library on 8 streams against
    // our kernels
    out["front_kernels"]["batched_panels"] = json::array();
    fmt::print("{:>6} {:>6} {:>7} {:>9} {:>9}   aggregate TFLOP/s of POTRF + TRSM's work\n", "m",
               "k", "fronts", "library", "ours");
    for (auto [m, k, count] :
         {std::tuple{600, 64, 256}, std::tuple{1000, 100, 128}, std::tuple{2000, 250, 64},
          std::tuple{3000, 500, 32}, std::tuple{4000, 1000, 16}, std::tuple{2000, 1000, 32}}) {
      const auto [lib, ours] = batched_panels(m, k, count);
      out["front_kernels"]["batched_panels"].push_back({{"m", m},
                                                        {"k", k},
                                                        {"fronts", count},
                                                        {"library_flops_per_second", lib},
                                                        {"ours_flops_per_second", ours}});
      fmt::print("{:>6} {:>6} {:>7} {:>9.2f} {:>9.2f}\n", m, k, count, lib * 1e-12, ours * 1e-12);
      std::fflush(stdout);
    }
    // the same sequence on many fronts at once, by stream count (fronts: 32 in all)
    out["front_kernels"]["concurrent"] = json::array();
    fmt::print("{:>6} {:>6} {:>8}   aggregate TFLOP/s of 32 fronts on S streams\n", "m", "k", "S");
    for (const std::string& shape : {std::string("1000:100"), std::string("2000:250"),
                                     std::string("3000:500"), std::string("5000:1000")}) {
      const auto colon = shape.find(':');
      const int m = std::stoi(shape.substr(0, colon)), k = std::stoi(shape.substr(colon + 1));
      for (int streams : {1, 4, 8, 16, 32}) {
        const double rate = concurrent_fronts(m, k, streams, 32 / streams);
        out["front_kernels"]["concurrent"].push_back(
            {{"m", m}, {"k", k}, {"streams", streams}, {"fronts", 32}, {"flops_per_second", rate}});
        fmt::print("{:>6} {:>6} {:>8} {:>8.1f}\n", m, k, streams, rate * 1e-12);
        std::fflush(stdout);
      }
    }
  }

  out["solvability"] = json::array();
  if (!want("solvability")) problems.clear();
  if (!want("blocks")) block_problems.clear();
  std::string partial;
  fmt::print("{:<14} {:>6} {:>10} {:>9} {:>9} {:>9} {:>6} {:>7} {:>9} {:>8}\n", "problem", "ratio",
             "budget MB", "factor s", "floor s", "slowdown", "tiled", "spilled", "solve s", "berr");
  for (const std::string& name : problems) {
    bench::Problem p = bench::load_problem(name);
    Options o;
    o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
    o.backend = Backend::cuda;
    o.num_gpus = 1;  // the single-GPU comparison, whatever the machine has
    std::size_t factor_bytes = 0;
    {  // gone before the runs: its analysis prepared the device (pool, arena, resident
       // factor), which the runs' solvers would otherwise plan around
      Solver probe(o);
      probe.analyze(p.a);
      factor_bytes = probe.stats().analysis.factor_bytes;
    }
    const Run in_core = run(p, o, repeat);
    json rows = json::array();
    std::vector<double> all_ratios = {0};
    all_ratios.insert(all_ratios.end(), ratios.begin(), ratios.end());
    // every (pool share, streamed piece width, prefetch) for each budget; in core once
    struct Variant {
      double share;
      index_t cols;
      bool prefetch;
    };
    std::vector<Variant> variants;
    for (double share : tiled_pool_shares)
      for (index_t cols : tiled_stream_columns)
        for (int pf : tiled_prefetch) variants.push_back({share, cols, pf != 0});
    const std::vector<Variant> in_core_only = {
        {o.gpu_tiled_pool_share, o.gpu_tiled_stream_columns, o.gpu_tiled_prefetch}};
    for (double ratio : all_ratios)
      for (const Variant& v : ratio > 0 ? variants : in_core_only) {
        const double share = v.share;
        const index_t cols = v.cols;
        Options ob = o;
        ob.device_memory_limit =
            ratio > 0 ? static_cast<std::size_t>(static_cast<double>(factor_bytes) / ratio) : 0;
        ob.gpu_tiled_pool_share = share;
        ob.gpu_tiled_stream_columns = cols;
        ob.gpu_tiled_prefetch = v.prefetch;
        const Run r = ratio > 0 ? run(p, ob, repeat) : in_core;
        const double floor = std::max(r.fs.bytes_to_device / h2d, r.fs.bytes_to_host / d2h);
        rows.push_back({{"ratio", ratio},
                        {"budget_bytes", ob.device_memory_limit},
                        {"tiled_pool_share", share},
                        {"tiled_stream_columns", cols},
                        {"tiled_prefetch", v.prefetch},
                        {"tiled_fronts_prefetched", r.fs.tiled_fronts_prefetched},
                        {"device_pool_bytes", r.fs.device_pool_bytes},
                        {"device_working_bytes", r.fs.device_working_bytes},
                        {"factor_seconds", r.seconds},
                        {"transfer_floor_seconds", floor},
                        {"slowdown_vs_in_core", r.seconds / in_core.seconds},
                        {"bytes_to_device", r.fs.bytes_to_device},
                        {"bytes_to_host", r.fs.bytes_to_host},
                        {"device_batches", r.fs.device_batches},
                        {"tiled_fronts", r.fs.tiled_fronts},
                        {"contribution_blocks_on_host", r.fs.contribution_blocks_on_host},
                        {"factor_resident", r.fs.factor_resident},
                        {"solve_seconds", r.solve_seconds},
                        {"solve_on_device", r.on_device},
                        {"first_solve_seconds", r.first_solve_seconds},
                        {"refinement_steps", r.refinement_steps},
                        {"backward_error", r.berr},
                        {"factor_phases", r.fs.device_phases}});
        fmt::print(
            "{:<14} {:>6} {:>10.1f} {:>9.4f} {:>9.4f} {:>9.2f} {:>6} {:>7} {:>9.4f} {:>8.1e}\n",
            name,
            ratio > 0 ? fmt::format("{:g}/{:g}/{}{}", ratio, share, cols, v.prefetch ? "p" : "")
                      : "core",
            ob.device_memory_limit * 1e-6, r.seconds, floor, r.seconds / in_core.seconds,
            r.fs.tiled_fronts, r.fs.contribution_blocks_on_host ? "yes" : "no", r.solve_seconds,
            r.berr);
        std::fflush(stdout);
      }
    out["solvability"].push_back({{"problem", name},
                                  {"n", p.a.n_rows},
                                  {"factor_bytes", factor_bytes},
                                  {"type", to_string(o.type)},
                                  {"runs", rows}});
    const std::string now = bench::write_result(out, stem + "-partial", results_dir);
    if (!partial.empty() && partial != now) std::remove(partial.c_str());
    partial = now;
  }

  // One in-core run per value of one option, on each problem: the block-size sweep
  // (max_block_size), which Cholesky fronts go to the panel kernels
  // (gpu_panel_kernel_max_pivots; Cholesky problems only), which LU fronts go to the
  // batched LU kernels (gpu_lu_strip_pivots; LU problems only).
  enum class Only { any, cholesky, lu };
  auto sweep = [&](const std::vector<std::string>& names, const std::vector<index_t>& values,
                   const char* key, auto set, Only only) {
    json all = json::array();
    if (!names.empty())
      fmt::print("{:<14} {:>9} {:>9} {:>9} {:>8}   ({})\n", "problem", "value", "factor s",
                 "GFLOP/s", "berr", key);
    for (const std::string& name : names) {
      bench::Problem p = bench::load_problem(name);
      if ((only == Only::cholesky && !p.symmetric) || (only == Only::lu && p.symmetric)) continue;
      json rows = json::array();
      for (index_t v : values) {
        Options o;
        o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
        o.backend = Backend::cuda;
        o.num_gpus = 1;  // the single-GPU comparison, whatever the machine has
        set(o, v);
        const Run r = run(p, o, repeat);
        const double flops = r.fs.gflops * r.fs.seconds;  // GFLOP of this factorization
        rows.push_back({{key, v},
                        {"factor_seconds", r.seconds},
                        {"gflops", flops / r.seconds},
                        {"backward_error", r.berr},
                        {"lu_large_fronts", r.fs.lu_large_fronts},
                        {"lu_large_fronts_pivoted", r.fs.lu_large_fronts_pivoted},
                        {"lu_large_fronts_batched", r.fs.lu_large_fronts_batched},
                        {"factor_phases", r.fs.device_phases}});
        fmt::print("{:<14} {:>9} {:>9.4f} {:>9.1f} {:>8.1e}", p.name, v, r.seconds,
                   flops / r.seconds, r.berr);
        if (!p.symmetric)
          fmt::print("   LU large fronts {} (batched {}, pivoted {})", r.fs.lu_large_fronts,
                     r.fs.lu_large_fronts_batched, r.fs.lu_large_fronts_pivoted);
        fmt::print("\n");
        std::fflush(stdout);
      }
      all.push_back({{"problem", p.name}, {"n", p.a.n_rows}, {"runs", rows}});
    }
    return all;
  };
  out["block_size"] = sweep(
      block_problems, block_sizes, "max_block_size",
      [](Options& o, index_t v) { o.max_block_size = v; }, Only::any);
  const std::vector<std::string> none;
  out["panel_kernels"] = sweep(
      want("panel") ? panel_problems : none, panel_max_pivots, "gpu_panel_kernel_max_pivots",
      [](Options& o, index_t v) { o.gpu_panel_kernel_max_pivots = v; }, Only::cholesky);
  out["lu_panel_kernels"] = sweep(
      want("lu-panel") ? lu_panel_problems : none, lu_strip_pivots, "gpu_lu_strip_pivots",
      [](Options& o, index_t v) { o.gpu_lu_strip_pivots = v; }, Only::lu);
  out["potrf_block"] = sweep(
      want("potrf-block") ? panel_problems : none, potrf_blocks, "gpu_potrf_block_size",
      [](Options& o, index_t v) { o.gpu_potrf_block_size = v; }, Only::cholesky);
  out["recursive_panel"] = sweep(
      want("recursive-panel") ? panel_problems : none, {0, 1}, "gpu_recursive_panel",
      [](Options& o, index_t v) { o.gpu_recursive_panel = v != 0; }, Only::cholesky);
  fmt::print("results: {}\n", bench::write_result(out, stem, results_dir));
  if (!partial.empty()) std::remove(partial.c_str());
  return 0;
}

int main(int argc, char** argv) { return strata::bench::run_driver(argc, argv, driver_main); }
