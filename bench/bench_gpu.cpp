// strata benchmark — the CUDA backend against the CPU backend and CHOLMOD on the same
// machine, same permutation, in one run (issue 5 / experiment 2 of the report).
//
// For each problem: strata's analysis once; GPU factorization (median of --repeat
// refactorizations, which is what the multibody loop calls), CPU factorization with each
// thread count of --threads (strata's CPU executor and, for SPD problems, CHOLMOD
// supernodal with strata's permutation), solve time and backward error. The fastest CPU
// thread count is the baseline of the reported ratio, and every count is kept in the
// JSON. Results: <results-dir>/gpu-*.json with "backend": "cuda".
//
//   bench_gpu [--problems a,b,...] [--repeat R] [--threads 4,16] [--gpu-only] [--tag T]
//             [--solver-option NAME=VALUE]... [--page-locked-values] [--results-dir DIR]
// Solve times: the median of R solves after a first one (solve: the whole call, with the
// refinement its check asks for; apply: one application of the factor; apply-gpu: the same
// with b and x in GPU memory, -1 where not measured).
// --tag T: stored in the results and in the file name (gpu-T-*.json), so that runs over
// different problem sets (bench/run gpu splits them) are kept apart by the report.
// --page-locked-values: the matrix's values page-locked (cudaHostRegister) for the GPU's
// refactorizations, which then copy them to the device directly (Solver::refactorize).
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <cstdio>

#include "base/blas.hpp"
#include "base/timer.hpp"
#include "bench_common.hpp"
#include "crash_report.hpp"
#include "numeric/cuda_testing.hpp"
#include "numeric/factor.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

namespace {

struct Timing {
  double factor = 0, solve = 0, backward_error = 0;
  double gflops = 0;
  FactorStats last;        ///< the last refactorization's statistics
  double first_solve = 0;  ///< the first application of the factor (no refinement)
  /// the same with b and x in GPU memory (-1: not measured: a CPU run, or no device copy)
  double first_solve_gpu_arrays = -1;
  int refinement_steps = 0;
};

Timing time_strata(const bench::Problem& p, Options o, int repeat,
                   std::vector<index_t>* perm = nullptr) {
  Solver s(o);
  s.analyze(p.a);
  s.factorize(p.a);
  std::vector<double> times;
  for (int k = 0; k < repeat; ++k) {
    Timer t;
    s.refactorize(p.a);
    times.push_back(t.seconds());
  }
  const index_t n = p.a.n_rows;
  std::vector<double> ones(n, 1.0), b(n);
  multiply(p.a, ones.data(), b.data());
  (void)s.solve(b);  // warm-up: the first solve after a factorization
  std::vector<double> solves, applications;
  std::vector<double> x;
  for (int k = 0; k < std::max(repeat, 1); ++k) {
    Timer ts;
    x = s.solve(b);
    solves.push_back(ts.seconds());
    applications.push_back(s.stats().solve.first_solve_seconds);
  }
  Timing r;
  r.solve = bench::median(solves);
  r.factor = bench::median(times);
  r.last = s.stats().factor;
  r.first_solve = bench::median(applications);
  // b and x in GPU memory (cudaMalloc), as bench_cudss times cuDSS's SOLVE: the
  // permutations and checks on the device, no copy through the host
  if (o.backend == Backend::cuda) {
    try {
      const std::shared_ptr<double> db = numeric::cuda_device_copy(b);
      const std::shared_ptr<double> dx = numeric::cuda_device_copy(b);
      s.solve(db.get(), dx.get(), 1);  // warm-up
      std::vector<double> on_gpu;
      for (int k = 0; k < std::max(repeat, 1); ++k) {
        s.solve(db.get(), dx.get(), 1);
        on_gpu.push_back(s.stats().solve.first_solve_seconds);
      }
      r.first_solve_gpu_arrays = bench::median(on_gpu);
    } catch (const Error& e) {
      fmt::print(stderr, "first solve from GPU arrays not measured: {}\n", e.what());
    }
  }
  r.refinement_steps = s.stats().solve.refinement_steps;
  r.backward_error = bench::berr(p.a, x, b);
  const double flops = s.stats().analysis.factor_flops * (o.type == MatrixType::general ? 2 : 1);
  r.gflops = flops / r.factor * 1e-9;
  if (perm) *perm = s.permutation();
  return r;
}

}  // namespace

static int driver_main(int argc, char** argv) {
  app::report_fatal_signals();  // a crash on a lent machine says where
  CLI::App app{"strata GPU benchmark (CUDA backend vs CPU backend and CHOLMOD)"};
  std::vector<std::string> problems = {"bcsstk16",    "ccx_cubef2f3_K", "lap3d-60",
                                       "lap3d-80",    "elast3d-30",     "elast3d-40",
                                       "uelast3d-20", "uelast3d-30"};
  std::vector<int> threads = {4, 16};
  int repeat = 3;
  std::string results_dir, tag;
  app.add_option("--problems", problems, "problems")->delimiter(',');
  app.add_option("--threads", threads, "CPU thread counts to measure")->delimiter(',');
  app.add_option("--repeat", repeat, "factorizations per measurement (median)");
  bool gpu_only = false;
  app.add_flag("--gpu-only", gpu_only,
               "time the GPU only (no CPU or CHOLMOD columns: a profile of the GPU phases)");
  app.add_option("--tag", tag, "label stored in the results and the file name")
      ->check(bench::check_tag);
  app.add_option("--results-dir", results_dir, "where to write the JSON (default bench/results)");
  std::vector<std::string> solver_options;
  app.add_option("--solver-option", solver_options,
                 "a strata option for the GPU runs, NAME=VALUE (the names of strata::set_option, "
                 "as strata simulate --solver-option); repeatable");
  bool page_locked_values = false;
  app.add_flag("--page-locked-values", page_locked_values,
               "page-lock the values the GPU refactorizations are given");
  CLI11_PARSE(app, argc, argv);
  if (gpu_only) threads.clear();
  if (!numeric::cuda_available()) {
    fmt::print(stderr, "bench_gpu: no CUDA GPU present (or no CUDA backend in this build)\n");
    return 3;
  }
  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = threads.empty() ? "gpu-profile" : "factor";  // a profile: not in the report
  out["backend"] = "cuda";
  if (!tag.empty()) out["tag"] = tag;
  out["solver_options"] = solver_options;
  out["page_locked_values"] = page_locked_values;
  out["rows"] = json::array();
  fmt::print(
      "{:<14} {:>8} {:>11} {:>9} {:>8} {:>9} {:>4} {:>9} {:>7} {:>7} {:>9} {:>9} {:>9} {:>9}\n",
      "problem", "n", "nnz(L)", "gpu s", "GFLOP/s", "cpu s", "thr", "chol s", "cpu/gpu", "chol/gpu",
      "berr gpu", "solve ms", "apply ms", "apply-gpu");
  const std::string stem =
      std::string(threads.empty() ? "gpu-profile" : "gpu") + (tag.empty() ? "" : "-" + tag);
  std::string partial, previous;
  for (const std::string& name : problems) {
    bench::Problem p = bench::load_problem(name);
    Options o;
    o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
    Options og = o;
    og.backend = Backend::cuda;
    og.num_gpus = 1;  // the single-GPU comparison, whatever the machine has
    for (const std::string& so : solver_options) {
      const auto eq = so.find('=');
      if (eq == std::string::npos) {
        fmt::print(stderr, "bench_gpu: --solver-option takes NAME=VALUE, got '{}'\n", so);
        return 2;
      }
      set_option(og, so.substr(0, eq), so.substr(eq + 1));
    }
    std::vector<index_t> perm;
    Timing g;
    try {
      const auto pin =
          page_locked_values
              ? numeric::pin_host_memory(p.a.values.data(), p.a.values.size() * sizeof(double))
              : nullptr;
      if (page_locked_values && !pin)
        fmt::print(stderr, "bench_gpu: {}: the values could not be page-locked\n", name);
      g = time_strata(p, og, repeat, &perm);
    } catch (const NotPositiveDefinite& e) {
      // a symmetric matrix is timed as spd (the CHOLMOD anchor is Cholesky): say so and go
      // on with the next problem, the row left out
      fmt::print("{:<14} skipped: symmetric but not positive definite ({})\n", name, e.what());
      out["skipped"].push_back({{"problem", name}, {"reason", e.what()}});
      continue;
    }
    Solver probe(o);
    probe.analyze(p.a);
    const AnalysisStats an = probe.stats().analysis;
    json row = {{"problem", name},
                {"n", p.a.n_rows},
                {"nnz_l", an.nnz_l},
                {"factor_bytes", an.factor_bytes},
                {"factor_flops", an.factor_flops},
                {"type", to_string(o.type)},
                {"strata_gpu",
                 {{"seconds", g.factor},
                  {"gflops", g.gflops},
                  {"solve_seconds", g.solve},
                  {"first_solve_seconds", g.first_solve},
                  {"first_solve_gpu_arrays_seconds", g.first_solve_gpu_arrays},
                  {"refinement_steps", g.refinement_steps},
                  {"backward_error", g.backward_error},
                  {"last_refactor", bench::device_figures(g.last)}}},
                {"cpu", json::array()}};
    double best_cpu = 1e300, best_chol = 1e300;
    int best_threads = 0;
    std::vector<double> ones(p.a.n_rows, 1.0), b(p.a.n_rows);
    multiply(p.a, ones.data(), b.data());
    for (int t : threads) {
      Options oc = o;
      oc.num_threads = t;
      Timing c = time_strata(p, oc, repeat);
      json cj = {{"threads", t},
                 {"strata_seconds", c.factor},
                 {"strata_gflops", c.gflops},
                 {"strata_solve_seconds", c.solve},
                 {"strata_backward_error", c.backward_error}};
      if (p.symmetric) {
        openblas_set_num_threads(t);
        bench::RefResult ch = bench::run_cholmod(p.a, perm, b, repeat);
        cj["cholmod_seconds"] = ch.seconds;
        cj["cholmod_backward_error"] = ch.backward_error;
        best_chol = std::min(best_chol, ch.seconds);
      }
      row["cpu"].push_back(cj);
      if (c.factor < best_cpu) {
        best_cpu = c.factor;
        best_threads = t;
      }
    }
    if (!threads.empty()) {
      row["best_cpu_seconds"] = best_cpu;
      row["best_cpu_threads"] = best_threads;
      row["ratio_cpu_over_gpu"] = best_cpu / g.factor;
      if (p.symmetric) row["ratio_cholmod_over_gpu"] = best_chol / g.factor;
    }
    if (threads.empty())
      fmt::print(
          "{:<14} {:>8} {:>11} {:>9.4f} {:>8.1f} {:>9} {:>4} {:>9} {:>7} {:>7} {:>9.1e} {:>9.3f} "
          "{:>9.3f} {:>9.3f}\n",
          name, p.a.n_rows, an.nnz_l, g.factor, g.gflops, "-", "-", "-", "-", "-", g.backward_error,
          g.solve * 1e3, g.first_solve * 1e3, g.first_solve_gpu_arrays * 1e3);
    else
      fmt::print(
          "{:<14} {:>8} {:>11} {:>9.4f} {:>8.1f} {:>9.4f} {:>4} {:>9} {:>7.2f} {:>7} {:>9.1e} "
          "{:>9.3f} {:>9.3f} {:>9.3f}\n",
          name, p.a.n_rows, an.nnz_l, g.factor, g.gflops, best_cpu, best_threads,
          p.symmetric ? fmt::format("{:.4f}", best_chol) : "-", best_cpu / g.factor,
          p.symmetric ? fmt::format("{:.2f}", best_chol / g.factor) : "-", g.backward_error,
          g.solve * 1e3, g.first_solve * 1e3, g.first_solve_gpu_arrays * 1e3);
    std::fflush(stdout);
    out["rows"].push_back(row);
    // keep what is measured so far, in case the run is cut off
    out["partial"] = true;
    partial = bench::write_result(out, stem + "-partial", results_dir);
    if (!previous.empty() && previous != partial) std::remove(previous.c_str());
    previous = partial;
  }
  out.erase("partial");
  fmt::print("results: {}\n", bench::write_result(out, stem, results_dir));
  if (!partial.empty()) std::remove(partial.c_str());
  return 0;
}

int main(int argc, char** argv) { return strata::bench::run_driver(argc, argv, driver_main); }
