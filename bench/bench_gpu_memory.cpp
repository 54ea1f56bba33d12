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
// bandwidths measured here on pinned memory.
// Block size: the in-core GPU factorization time for each --block-sizes.
//
//   bench_gpu_memory [--problems a,b] [--ratios 1,5,20,50] [--block-sizes 256,...]
//                    [--block-problems a,b] [--repeat R] [--results-dir DIR]
#include <cublas_v2.h>
#include <cuda_runtime.h>
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>

#include "bench_common.hpp"
#include "core/timer.hpp"
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

struct Run {
  double seconds = 0, berr = 0;
  FactorStats fs;
  bool on_device = false;
  double solve_seconds = 0;
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
  r.berr = bench::berr(p.a, x, b);
  return r;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"strata GPU memory-budget, block-size and device benchmark"};
  std::vector<std::string> problems = {"lap3d-60", "elast3d-30", "uelast3d-20"};
  std::vector<std::string> block_problems = {"lap3d-60", "elast3d-30", "uelast3d-20",
                                             "ccx_cubef2f3_K"};
  std::vector<double> ratios = {1, 5, 20, 50};
  std::vector<index_t> block_sizes = {128, 256, 512, 1024, 2048};
  int repeat = 3;
  std::string results_dir;
  app.add_option("--problems", problems, "problems for the budget sweep")->delimiter(',');
  app.add_option("--ratios", ratios, "factor bytes / device budget")->delimiter(',');
  app.add_option("--block-problems", block_problems, "problems for the block sweep")
      ->delimiter(',');
  app.add_option("--block-sizes", block_sizes, "max_block_size values")->delimiter(',');
  app.add_option("--repeat", repeat, "factorizations per measurement (median)");
  app.add_option("--results-dir", results_dir, "where to write the JSON (default bench/results)");
  CLI11_PARSE(app, argc, argv);
  if (!numeric::cuda_available()) {
    fmt::print(stderr, "bench_gpu_memory: no CUDA GPU present\n");
    return 3;
  }
  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "gpu_memory";
  out["backend"] = "cuda";
  const auto [h2d, d2h] = transfer_bandwidth();
  const double peak = dgemm_peak(8192);
  out["device_figures"] = {{"h2d_bytes_per_second", h2d},
                           {"d2h_bytes_per_second", d2h},
                           {"dgemm_flops_per_second", peak},
                           {"dgemm_n", 8192}};
  fmt::print("pinned H2D {:.1f} GB/s, D2H {:.1f} GB/s; cuBLAS DGEMM (8192) {:.1f} TFLOP/s\n",
             h2d * 1e-9, d2h * 1e-9, peak * 1e-12);
  std::fflush(stdout);

  out["solvability"] = json::array();
  std::string partial;
  fmt::print("{:<14} {:>6} {:>10} {:>9} {:>9} {:>9} {:>6} {:>7} {:>9} {:>8}\n", "problem", "ratio",
             "budget MB", "factor s", "floor s", "slowdown", "tiled", "spilled", "solve s", "berr");
  for (const std::string& name : problems) {
    bench::Problem p = bench::load_problem(name);
    Options o;
    o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
    o.backend = Backend::cuda;
    o.num_gpus = 1;  // the single-GPU comparison, whatever the machine has
    Solver probe(o);
    probe.analyze(p.a);
    const std::size_t factor_bytes = probe.stats().analysis.factor_bytes;
    const Run in_core = run(p, o, repeat);
    json rows = json::array();
    std::vector<double> all_ratios = {0};
    all_ratios.insert(all_ratios.end(), ratios.begin(), ratios.end());
    for (double ratio : all_ratios) {
      Options ob = o;
      ob.device_memory_limit =
          ratio > 0 ? static_cast<std::size_t>(static_cast<double>(factor_bytes) / ratio) : 0;
      const Run r = ratio > 0 ? run(p, ob, repeat) : in_core;
      const double floor = std::max(r.fs.bytes_to_device / h2d, r.fs.bytes_to_host / d2h);
      rows.push_back({{"ratio", ratio},
                      {"budget_bytes", ob.device_memory_limit},
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
                      {"backward_error", r.berr}});
      fmt::print(
          "{:<14} {:>6} {:>10.1f} {:>9.4f} {:>9.4f} {:>9.2f} {:>6} {:>7} {:>9.4f} {:>8.1e}\n", name,
          ratio > 0 ? fmt::format("{:g}", ratio) : "core", ob.device_memory_limit * 1e-6, r.seconds,
          floor, r.seconds / in_core.seconds, r.fs.tiled_fronts,
          r.fs.contribution_blocks_on_host ? "yes" : "no", r.solve_seconds, r.berr);
      std::fflush(stdout);
    }
    out["solvability"].push_back({{"problem", name},
                                  {"n", p.a.n_rows},
                                  {"factor_bytes", factor_bytes},
                                  {"type", to_string(o.type)},
                                  {"runs", rows}});
    const std::string now = bench::write_result(out, "gpu-memory-partial", results_dir);
    if (!partial.empty() && partial != now) std::remove(partial.c_str());
    partial = now;
  }

  out["block_size"] = json::array();
  fmt::print("{:<14} {:>6} {:>9} {:>9}\n", "problem", "block", "factor s", "GFLOP/s");
  for (const std::string& name : block_problems) {
    bench::Problem p = bench::load_problem(name);
    json rows = json::array();
    for (index_t bs : block_sizes) {
      Options o;
      o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
      o.backend = Backend::cuda;
      o.num_gpus = 1;  // the single-GPU comparison, whatever the machine has
      o.max_block_size = bs;
      const Run r = run(p, o, repeat);
      const double flops = r.fs.gflops * r.fs.seconds;  // GFLOP of this factorization
      rows.push_back({{"max_block_size", bs},
                      {"factor_seconds", r.seconds},
                      {"gflops", flops / r.seconds},
                      {"backward_error", r.berr}});
      fmt::print("{:<14} {:>6} {:>9.4f} {:>9.1f}\n", name, bs, r.seconds, flops / r.seconds);
      std::fflush(stdout);
    }
    out["block_size"].push_back({{"problem", name}, {"n", p.a.n_rows}, {"runs", rows}});
  }
  fmt::print("results: {}\n", bench::write_result(out, "gpu-memory", results_dir));
  if (!partial.empty()) std::remove(partial.c_str());
  return 0;
}
