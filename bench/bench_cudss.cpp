// strata benchmark — the CUDA backend against NVIDIA cuDSS on the same GPU, in one run
// (issue 5's anchor; experiment 2 of the report, GPU part).
//
// For each problem: strata on the GPU (analysis, first factorization, median of --repeat
// refactorizations, after one untimed, of the values alone (Solver::refactorize(span), as cuDSS's
// after cudssMatrixSetValues: from GPU memory, as cuDSS's timed REFACTORIZATION reads them, and
// from cudaMallocHost memory, as cuDSS's timed copy before it reads them), for LU also with
// Pivoting::fixed and, when the refactorization delayed pivots, in their order
// (Solver::analyze_in_pivot_order), the checked solve (residual, refinement; median of --repeat
// after one untimed, and right after each of --repeat refactorizations), and a solve with b
// and x in GPU
// memory as cuDSS's are, its application of the factor timed: the median of --repeat after
// one untimed); cuDSS with its default
// reordering and with strata's permutation given as CUDSS_DATA_USER_PERM (both directions of the
// permutation are tried and the one with the smaller LU_NNZ kept, since the documentation does not
// say which one it expects), each: analysis, factorization, median of --repeat REFACTORIZATION
// after one untimed, the
// same with the values copied to the device from page-locked host memory before each (what a
// host-assembled matrix such as the multibody engine's costs cuDSS, as strata's refactorizations
// take host values), solve, backward error computed on the host, LU_NNZ. cuDSS gets the upper
// triangle (CSR view of strata's lower CSC) for SPD matrices and the whole matrix for unsymmetric
// ones; 32-bit indices. cuDSS's SOLVE is timed once (the first after the
// refactorizations: solve_seconds) and then as the median of --repeat more
// (solve_again_seconds). Both analyses are timed --analysis-repeat times (strata: a new Solver
// each time; cuDSS: a new cudssData each time) and the median is reported, the last one's
// data kept for the rest. Results: <dir>/cudss-*.json.
//
//   bench_cudss [--problems a,b,...] [--repeat R] [--analysis-repeat A]
//               [--solver-option NAME=VALUE]... [--tag NAME] [--results-dir DIR]
//               [--dump-orders DIR]
#include <cuda_runtime.h>
#include <cudss.h>
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <cstdio>
#include <span>
#include <stdexcept>

#include "base/timer.hpp"
#include "bench_common.hpp"
#include "crash_report.hpp"
#include "numeric/factor.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

namespace {

void ck(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string(what) + ": " + cudaGetErrorString(e));
}
void ck(cudssStatus_t s, const char* what) {
  if (s != CUDSS_STATUS_SUCCESS)
    throw std::runtime_error(std::string(what) + ": cuDSS status " + std::to_string(int(s)));
}

struct CudssResult {
  double analysis = 0, factor = 0, refactor = 0, solve = 0, berr = 0;
  double solve_again = 0;           ///< the median of --repeat SOLVEs after the first
  double refactor_with_upload = 0;  ///< cudaMemcpy of the values (pinned) + REFACTORIZATION
  std::int64_t lu_nnz = 0;
  bool ok = false;
  std::string error;
};

template <class T>
T* to_device(const std::vector<T>& h) {
  T* d = nullptr;
  ck(cudaMalloc(&d, sizeof(T) * std::max<std::size_t>(h.size(), 1)), "cudaMalloc");
  ck(cudaMemcpy(d, h.data(), sizeof(T) * h.size(), cudaMemcpyHostToDevice), "H2D");
  return d;
}

// The matrix cuDSS gets, as CSR arrays: for SPD the upper triangle (the lower-triangle
// CSC read as CSR), for a general matrix A itself (the CSC of Aᵀ read as CSR; Aᵀ's CSC is
// A's CSC relabelled as CSR and canonicalized).
SparseMatrix cudss_csr(const SparseMatrix& a, bool spd) {
  SparseMatrix full = expand_symmetric(a);
  if (!spd) {
    full.layout = Layout::csr;  // the same arrays read by rows: Aᵀ
    return canonicalize(full);  // CSC of Aᵀ = CSR of A
  }
  SparseMatrix low;
  low.n_rows = low.n_cols = full.n_cols;
  low.storage = Storage::lower;
  low.offsets.assign(full.n_cols + 1, 0);
  for (index_t j = 0; j < full.n_cols; ++j) {
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) {
        low.indices.push_back(full.indices[p]);
        low.values.push_back(full.values[p]);
      }
    low.offsets[j + 1] = static_cast<index_t>(low.indices.size());
  }
  return low;
}

// cuDSS's own orders after its analysis into `path` (--dump-orders): one line each for
// CUDSS_DATA_PERM_REORDER_ROW, _REORDER_COL and _MATCHING (the last only when cuDSS
// matched), the name then n 0-based entries. For comparing cuDSS's elimination tree with
// strata's on the same matrix.
void dump_orders(cudssHandle_t h, cudssData_t data, std::int64_t n, const std::string& path) {
  std::FILE* f = std::fopen(path.c_str(), "w");
  if (!f) throw std::runtime_error("--dump-orders: cannot write " + path);
  const std::pair<const char*, cudssDataParam_t> what[] = {
      {"reorder_row", CUDSS_DATA_PERM_REORDER_ROW},
      {"reorder_col", CUDSS_DATA_PERM_REORDER_COL},
      {"matching", CUDSS_DATA_PERM_MATCHING}};
  std::vector<int> v(static_cast<std::size_t>(n));
  for (const auto& [name, param] : what) {
    std::size_t written = 0;
    if (cudssDataGet(h, data, param, v.data(), sizeof(int) * v.size(), &written) !=
        CUDSS_STATUS_SUCCESS)
      continue;
    std::fprintf(f, "%s", name);
    for (int x : v) std::fprintf(f, " %d", x);
    std::fprintf(f, "\n");
  }
  std::fclose(f);
}

CudssResult run_cudss(const SparseMatrix& a_input, bool spd, const std::vector<int>* perm,
                      int repeat, int analysis_repeat, const std::string& orders_to = "") {
  CudssResult r;
  const SparseMatrix csr = cudss_csr(a_input, spd);
  const std::int64_t n = csr.n_rows, nnz = csr.nnz();
  std::vector<int> rowptr(csr.offsets.begin(), csr.offsets.end());
  std::vector<int> col(csr.indices.begin(), csr.indices.end());
  std::vector<double> ones(n, 1.0), b(n), x(n);
  multiply(a_input, ones.data(), b.data());
  int* d_rowptr = to_device(rowptr);
  int* d_col = to_device(col);
  double* d_val = to_device(csr.values);
  double* d_b = to_device(b);
  double* d_x = to_device(x);
  cudssHandle_t h;
  cudssConfig_t cfg;
  cudssData_t data;
  cudssMatrix_t A, X, B;
  try {
    ck(cudssCreate(&h), "cudssCreate");
    ck(cudssConfigCreate(&cfg), "cudssConfigCreate");
    ck(cudssDataCreate(h, &data), "cudssDataCreate");
    ck(cudssMatrixCreateCsr(&A, n, n, nnz, d_rowptr, nullptr, d_col, d_val, CUDA_R_32I, CUDA_R_32I,
                            CUDA_R_64F, spd ? CUDSS_MTYPE_SPD : CUDSS_MTYPE_GENERAL,
                            spd ? CUDSS_MVIEW_UPPER : CUDSS_MVIEW_FULL, CUDSS_BASE_ZERO),
       "cudssMatrixCreateCsr");
    ck(cudssMatrixCreateDn(&B, n, 1, n, d_b, CUDA_R_64F, CUDSS_LAYOUT_COL_MAJOR), "Dn b");
    ck(cudssMatrixCreateDn(&X, n, 1, n, d_x, CUDA_R_64F, CUDSS_LAYOUT_COL_MAJOR), "Dn x");
    // the analyses before the kept one, each on data of its own
    std::vector<double> analyses;
    for (int k = 1; k < analysis_repeat; ++k) {
      cudssData_t scratch;
      ck(cudssDataCreate(h, &scratch), "cudssDataCreate");
      if (perm)
        ck(cudssDataSet(h, scratch, CUDSS_DATA_USER_PERM, perm->data(), sizeof(int) * n),
           "USER_PERM");
      cudaDeviceSynchronize();
      const Timer ta;
      const cudssStatus_t st = cudssExecute(h, CUDSS_PHASE_ANALYSIS, cfg, scratch, A, X, B);
      cudaDeviceSynchronize();
      analyses.push_back(ta.seconds());
      cudssDataDestroy(h, scratch);
      ck(st, "analysis");
    }
    if (perm)
      ck(cudssDataSet(h, data, CUDSS_DATA_USER_PERM, perm->data(), sizeof(int) * n), "USER_PERM");
    cudaDeviceSynchronize();
    Timer t;
    ck(cudssExecute(h, CUDSS_PHASE_ANALYSIS, cfg, data, A, X, B), "analysis");
    cudaDeviceSynchronize();
    analyses.push_back(t.seconds());
    r.analysis = bench::median(analyses);
    if (!orders_to.empty()) dump_orders(h, data, n, orders_to);
    t.reset();
    ck(cudssExecute(h, CUDSS_PHASE_FACTORIZATION, cfg, data, A, X, B), "factorization");
    cudaDeviceSynchronize();
    r.factor = t.seconds();
    std::vector<double> times;
    // one untimed first, as for strata: what a first refactorization sets up is not timed
    ck(cudssExecute(h, CUDSS_PHASE_REFACTORIZATION, cfg, data, A, X, B), "refactorization");
    cudaDeviceSynchronize();
    for (int k = 0; k < repeat; ++k) {
      t.reset();
      ck(cudssExecute(h, CUDSS_PHASE_REFACTORIZATION, cfg, data, A, X, B), "refactorization");
      cudaDeviceSynchronize();
      times.push_back(t.seconds());
    }
    r.refactor = bench::median(times);
    // the values from page-locked host memory first (the fastest copy a host-assembled
    // matrix can have), then the refactorization
    double* pinned = nullptr;
    ck(cudaMallocHost(&pinned, sizeof(double) * std::max<std::int64_t>(nnz, 1)), "cudaMallocHost");
    std::copy(csr.values.begin(), csr.values.end(), pinned);
    times.clear();
    for (int k = 0; k < repeat; ++k) {
      t.reset();
      ck(cudaMemcpy(d_val, pinned, sizeof(double) * nnz, cudaMemcpyHostToDevice), "H2D values");
      ck(cudssExecute(h, CUDSS_PHASE_REFACTORIZATION, cfg, data, A, X, B), "refactorization");
      cudaDeviceSynchronize();
      times.push_back(t.seconds());
    }
    cudaFreeHost(pinned);
    r.refactor_with_upload = bench::median(times);
    t.reset();
    ck(cudssExecute(h, CUDSS_PHASE_SOLVE, cfg, data, A, X, B), "solve");
    cudaDeviceSynchronize();
    r.solve = t.seconds();
    // and again: the first SOLVE may set up what later ones reuse
    times.clear();
    for (int k = 0; k < repeat; ++k) {
      t.reset();
      ck(cudssExecute(h, CUDSS_PHASE_SOLVE, cfg, data, A, X, B), "solve");
      cudaDeviceSynchronize();
      times.push_back(t.seconds());
    }
    r.solve_again = bench::median(times);
    std::size_t written = 0;
    ck(cudssDataGet(h, data, CUDSS_DATA_LU_NNZ, &r.lu_nnz, sizeof(r.lu_nnz), &written), "LU_NNZ");
    ck(cudaMemcpy(x.data(), d_x, sizeof(double) * n, cudaMemcpyDeviceToHost), "D2H x");
    r.berr = bench::berr(a_input, x, b);
    r.ok = true;
    cudssMatrixDestroy(A);
    cudssMatrixDestroy(B);
    cudssMatrixDestroy(X);
    cudssDataDestroy(h, data);
    cudssConfigDestroy(cfg);
    cudssDestroy(h);
  } catch (const std::exception& e) {
    r.error = e.what();
  }
  for (void* p : {(void*)d_rowptr, (void*)d_col, (void*)d_val, (void*)d_b, (void*)d_x}) cudaFree(p);
  return r;
}

json to_json(const CudssResult& r) {
  if (!r.ok) return {{"error", r.error}};
  return {
      {"analysis_seconds", r.analysis}, {"factor_seconds", r.factor},
      {"refactor_seconds", r.refactor}, {"refactor_with_upload_seconds", r.refactor_with_upload},
      {"solve_seconds", r.solve},       {"solve_again_seconds", r.solve_again},
      {"backward_error", r.berr},       {"lu_nnz", r.lu_nnz}};
}

}  // namespace

static int driver_main(int argc, char** argv) {
  app::report_fatal_signals();  // a crash on a lent machine says where
  CLI::App app{"strata vs NVIDIA cuDSS on one GPU"};
  std::vector<std::string> problems = {"bcsstk16",   "ccx_cubef2f3_K", "lap3d-60",
                                       "lap3d-80",   "lap3d-100",      "elast3d-30",
                                       "elast3d-40", "uelast3d-20",    "uelast3d-30"};
  int repeat = 3;
  int analysis_repeat = 1;
  std::string results_dir, tag;
  app.add_option("--problems", problems, "problems")->delimiter(',');
  app.add_option("--repeat", repeat, "refactorizations per measurement (median)");
  app.add_option("--analysis-repeat", analysis_repeat,
                 "analyses per measurement, strata's and cuDSS's (median; default 1)")
      ->check(CLI::PositiveNumber);
  app.add_option("--results-dir", results_dir, "where to write the JSON (default bench/results)");
  std::string orders_dir;
  app.add_option("--dump-orders", orders_dir,
                 "write cuDSS's reordering and matching permutations after its default analysis "
                 "to DIR/<problem>.cudss-orders (one line each, 0-based)");
  std::vector<std::string> solver_options;
  app.add_option("--solver-option", solver_options,
                 "a strata option for every problem, NAME=VALUE (the names of strata::set_option, "
                 "as strata simulate --solver-option); repeatable");
  app.add_option("--tag", tag,
                 "label stored in the results (\"tag\") and added to the file name; \"mbd\" "
                 "marks a run on the multibody Newton matrices (the report's own line)")
      ->check(bench::check_tag);
  CLI11_PARSE(app, argc, argv);
  if (!numeric::cuda_available()) {
    fmt::print(stderr, "bench_cudss: no CUDA GPU present\n");
    return 3;
  }
  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "cudss";
  out["tag"] = tag;
  int ver[3] = {0, 0, 0};
  cudssGetProperty(MAJOR_VERSION, &ver[0]);
  cudssGetProperty(MINOR_VERSION, &ver[1]);
  cudssGetProperty(PATCH_LEVEL, &ver[2]);
  out["cudss_version"] = fmt::format("{}.{}.{}", ver[0], ver[1], ver[2]);
  out["solver_options"] = solver_options;
  out["analysis_repeat"] = analysis_repeat;
  out["rows"] = json::array();
  fmt::print("cuDSS {}.{}.{}\n", ver[0], ver[1], ver[2]);
  fmt::print("{:<14} {:>8} {:>11} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8} {:>8}\n", "problem", "n",
             "nnz(L)", "strata f", "cudss f", "strata rf", "cudss rf", "cudss(p)", "rf ratio",
             "f ratio");
  // The CUDA context before any timer: cuDSS's analysis is timed after cudssCreate, which
  // made it, so strata's first analysis (the first problem's) must not pay for its
  // creation either.
  if (cudaFree(nullptr) != cudaSuccess) {
    fmt::print(stderr, "bench_cudss: the CUDA context could not be created\n");
    return 3;
  }
  std::string partial;
  for (const std::string& name : problems) {
    bench::Problem p = bench::load_problem(name);
    p.a = canonicalize(p.a);  // sorted, no duplicates: refactorize(values) follows its entries
    Options o;
    o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
    o.backend = Backend::cuda;
    o.num_gpus = 1;  // the single-GPU comparison, whatever the machine has
    for (const std::string& so : solver_options) {
      const std::size_t eq = so.find('=');
      if (eq == std::string::npos) {
        fmt::print(stderr, "bench_cudss: --solver-option takes NAME=VALUE, got '{}'\n", so);
        return 2;
      }
      set_option(o, so.substr(0, eq), so.substr(eq + 1));
    }
    validate(o);
    // the analyses before the kept one, each by a Solver of its own
    std::vector<double> analyses;
    for (int k = 1; k < analysis_repeat; ++k) {
      Solver scratch(o);
      const Timer ta;
      scratch.analyze(p.a);
      analyses.push_back(ta.seconds());
    }
    Solver s(o);
    Timer t;
    s.analyze(p.a);
    analyses.push_back(t.seconds());
    const double an_s = bench::median(analyses);
    t.reset();
    s.factorize(p.a);
    const double f_s = t.seconds();
    const FactorStats first_stats = s.stats().factor;  // its device set-up among the phases
    // the refactorizations take the values alone, as cuDSS's take cudssMatrixSetValues'
    // (the matrices here are canonical: the pattern is the analyzed one)
    // in page-locked memory from cudaMallocHost, as the values of cuDSS's timed copy
    struct PinnedValues {
      double* p = nullptr;
      ~PinnedValues() {
        if (p) cudaFreeHost(p);
      }
    } pinned;
    const std::size_t nv = p.a.values.size();
    if (cudaMallocHost(&pinned.p, sizeof(double) * std::max<std::size_t>(nv, 1)) != cudaSuccess) {
      (void)cudaGetLastError();
      pinned.p = nullptr;
    }
    if (pinned.p) std::copy(p.a.values.begin(), p.a.values.end(), pinned.p);
    const std::span<const double> values =
        pinned.p ? std::span<const double>(pinned.p, nv) : std::span<const double>(p.a.values);
    // and in GPU memory (cudaMalloc), as cuDSS's timed REFACTORIZATION reads them
    struct GpuValues {
      double* p = nullptr;
      ~GpuValues() {
        if (p) cudaFree(p);
      }
    } on_gpu;
    if (cudaMalloc(&on_gpu.p, sizeof(double) * std::max<std::size_t>(nv, 1)) != cudaSuccess ||
        cudaMemcpy(on_gpu.p, p.a.values.data(), sizeof(double) * nv, cudaMemcpyHostToDevice) !=
            cudaSuccess) {
      (void)cudaGetLastError();
      if (on_gpu.p) cudaFree(on_gpu.p);
      on_gpu.p = nullptr;
    }
    const std::span<const double> gpu_values =
        on_gpu.p ? std::span<const double>(on_gpu.p, nv) : values;
    std::vector<double> times, host_times;
    // one untimed first (the first refactorization from GPU values sets up its own
    // buffers), as for cuDSS
    s.refactorize(gpu_values);
    for (int k = 0; k < repeat; ++k) {
      t.reset();
      s.refactorize(gpu_values);
      times.push_back(t.seconds());
    }
    const double rf_s = bench::median(times);
    const FactorStats refactor_stats = s.stats().factor;  // the last refactorization's
    for (int k = 0; k < repeat; ++k) {
      t.reset();
      s.refactorize(values);
      host_times.push_back(t.seconds());
    }
    const double rf_host_s = bench::median(host_times);
    const FactorStats refactor_host_stats = s.stats().factor;
    // LU: also in the analysis's order alone (Pivoting::fixed, static pivots as cuDSS
    // takes them), which separates the device's refactorization from the delayed one on
    // the host that the default (automatic) adds when that order needs static pivots
    json fixed_order;
    if (o.type == MatrixType::general) {
      s.set_pivoting(Pivoting::fixed);
      std::vector<double> ft;
      for (int k = 0; k < repeat; ++k) {
        t.reset();
        s.refactorize(values);
        ft.push_back(t.seconds());
      }
      fixed_order = {{"refactor_seconds", bench::median(ft)},
                     {"perturbed_pivots", s.stats().factor.perturbed_pivots},
                     {"last_refactor", bench::device_figures(s.stats().factor)}};
      s.set_pivoting(o.pivoting);
      s.refactorize(p.a);  // the default's factor again, for the solve below
    }
    std::vector<double> ones(p.a.n_rows, 1.0), b(p.a.n_rows);
    multiply(p.a, ones.data(), b.data());
    (void)s.solve(b);  // warm-up: the first solve after an analysis plans the device solve
    // the checked solve (Options::solve_check: residual, refinement), host arrays: the
    // median of --repeat
    std::vector<double> solve_times, x;
    for (int k = 0; k < std::max(repeat, 1); ++k) {
      t.reset();
      x = s.solve(b);
      solve_times.push_back(t.seconds());
    }
    const double sol_s = bench::median(solve_times);
    const double berr = bench::berr(p.a, x, b);
    // copies: the pivot-order analysis below replaces the solver's statistics
    const AnalysisStats an = s.stats().analysis;
    const SolveStats solve_stats = s.stats().solve;
    // the checked solve right after each refactorization of the matrix from host memory:
    // what a caller that factors and then solves once pays (A's values for the residuals
    // read where the factorization left them)
    std::vector<double> after_refactor;
    for (int k = 0; k < std::max(repeat, 1); ++k) {
      s.refactorize(p.a);
      t.reset();
      (void)s.solve(b);
      after_refactor.push_back(t.seconds());
    }
    const double sol_after_refactor_s = bench::median(after_refactor);
    // the same solve with b and x in GPU memory, as cuDSS's are timed: its first
    // application of the factor (-1 where the device memory could not be had)
    double gpu_arrays_first = -1;
    {
      double *db = nullptr, *dx = nullptr;
      const std::size_t bytes = sizeof(double) * std::max<std::size_t>(b.size(), 1);
      if (cudaMalloc(&db, bytes) == cudaSuccess && cudaMalloc(&dx, bytes) == cudaSuccess &&
          cudaMemcpy(db, b.data(), sizeof(double) * b.size(), cudaMemcpyHostToDevice) ==
              cudaSuccess) {
        s.solve(db, dx, 1);  // warm-up: its first use sizes the device checks' buffers
        std::vector<double> applications;
        for (int k = 0; k < std::max(repeat, 1); ++k) {
          s.solve(db, dx, 1);
          applications.push_back(s.stats().solve.first_solve_seconds);
        }
        gpu_arrays_first = bench::median(applications);
      }
      (void)cudaGetLastError();
      cudaFree(db);
      cudaFree(dx);
    }
    // strata's pivot order (new to old) and its inverse, for cuDSS's user permutation
    std::vector<int> perm(s.permutation().begin(), s.permutation().end()), iperm(perm.size());
    for (std::size_t k = 0; k < perm.size(); ++k) iperm[perm[k]] = static_cast<int>(k);
    // LU whose refactorization delayed pivots: the analysis redone in the order they were
    // taken (Solver::analyze_in_pivot_order), then the refactorizations of the same values
    // in that fixed order on the device (after the solve above: the row's other figures
    // are the default's)
    json pivot_order;
    if (refactor_stats.delayed_pivoting && refactor_stats.type == MatrixType::general) {
      t.reset();
      s.analyze_in_pivot_order();
      const double pa = t.seconds();
      s.factorize(p.a);
      std::vector<double> pt;
      for (int k = 0; k < repeat; ++k) {
        t.reset();
        s.refactorize(values);
        pt.push_back(t.seconds());
      }
      const FactorStats& ps = s.stats().factor;
      const auto px = s.solve(b);
      pivot_order = {{"analysis_seconds", pa},
                     {"nnz_l", s.stats().analysis.nnz_l},
                     {"refactor_seconds", bench::median(pt)},
                     {"delayed_pivoting", ps.delayed_pivoting},
                     {"perturbed_pivots", ps.perturbed_pivots},
                     {"backward_error", bench::berr(p.a, px, b)},
                     {"last_refactor", bench::device_figures(ps)}};
    }
    const std::string stem = name.substr(name.find_last_of('/') + 1);
    const CudssResult def =
        run_cudss(p.a, p.symmetric, nullptr, repeat, analysis_repeat,
                  orders_dir.empty() ? "" : orders_dir + "/" + stem + ".cudss-orders");
    CudssResult up = run_cudss(p.a, p.symmetric, &perm, repeat, analysis_repeat);
    CudssResult ui = run_cudss(p.a, p.symmetric, &iperm, repeat, analysis_repeat);
    const bool use_inverse = ui.ok && (!up.ok || ui.lu_nnz < up.lu_nnz);
    const CudssResult& same = use_inverse ? ui : up;
    json row = {{"problem", p.name},
                {"n", p.a.n_rows},
                {"type", to_string(o.type)},
                {"nnz_l", an.nnz_l},
                {"nnz_l_fronts", an.nnz_l_fronts},
                {"factor_flops", an.factor_flops},
                {"strata_gpu",
                 {{"analysis_seconds", an_s},
                  {"analysis_phases",
                   {{"matching", an.matching_seconds},
                    {"ordering", an.ordering_seconds},
                    {"symbolic", an.symbolic_seconds},
                    {"plan", an.plan_seconds},
                    {"device_setup", an.device_setup_seconds}}},
                  {"factor_seconds", f_s},
                  {"refactor_seconds", rf_s},
                  {"solve_seconds", sol_s},
                  {"solve_after_refactor_seconds", sol_after_refactor_s},
                  {"solve_on_device", solve_stats.on_device},
                  {"first_solve_seconds", solve_stats.first_solve_seconds},
                  {"first_solve_gpu_arrays_seconds", gpu_arrays_first},
                  {"refinement_steps", solve_stats.refinement_steps},
                  {"backward_error", berr},
                  {"first_factor", bench::device_figures(first_stats)},
                  {"last_refactor", bench::device_figures(refactor_stats)},
                  {"delayed_pivoting", refactor_stats.delayed_pivoting},
                  {"values_page_locked", pinned.p != nullptr},
                  {"values_in_gpu_memory", on_gpu.p != nullptr},
                  {"refactor_host_seconds", rf_host_s},
                  {"last_refactor_host", bench::device_figures(refactor_host_stats)},
                  {"fixed_order", fixed_order},
                  {"pivot_order", pivot_order}}},
                {"cudss_default", to_json(def)},
                {"cudss_strata_perm", to_json(same)},
                {"cudss_user_perm_direction", use_inverse ? "old-to-new" : "new-to-old"}};
    const double best = std::min(def.ok ? def.refactor : 1e300, same.ok ? same.refactor : 1e300);
    if (best < 1e300) row["ratio_strata_refactor_over_best_cudss_refactor"] = rf_s / best;
    if (def.ok) row["ratio_strata_factor_over_cudss_default_factor"] = f_s / def.factor;
    // strata's refactorizations from host values: against cuDSS's with the values' copy
    const double best_up = std::min(def.ok ? def.refactor_with_upload : 1e300,
                                    same.ok ? same.refactor_with_upload : 1e300);
    if (best_up < 1e300)
      row["ratio_strata_refactor_over_best_cudss_refactor_with_upload"] = rf_host_s / best_up;
    if (best_up < 1e300 && !fixed_order.is_null())
      row["ratio_strata_fixed_order_refactor_over_best_cudss_refactor_with_upload"] =
          fixed_order["refactor_seconds"].get<double>() / best_up;
    if (best < 1e300 && !pivot_order.is_null())
      row["ratio_strata_pivot_order_refactor_over_best_cudss_refactor"] =
          pivot_order["refactor_seconds"].get<double>() / best;
    fmt::print(
        "{:<14} {:>8} {:>11} {:>9.4f} {:>9.4f} {:>9.4f} {:>9.4f} {:>9.4f} {:>8.2f} {:>8.2f}\n",
        p.name, p.a.n_rows, an.nnz_l, f_s, def.ok ? def.factor : -1.0, rf_s,
        def.ok ? def.refactor : -1.0, same.ok ? same.refactor : -1.0,
        best < 1e300 ? rf_s / best : -1.0, def.ok ? f_s / def.factor : -1.0);
    fmt::print(
        "  strata from page-locked host values: refactorization {:.4f} s; cuDSS with their copy "
        "{:.4f} s\n",
        rf_host_s, best_up < 1e300 ? best_up : -1.0);
    if (!fixed_order.is_null())
      fmt::print(
          "  strata in the analysis's order only (Pivoting::fixed): refactorization {:.4f} s, "
          "{} perturbed pivots\n",
          fixed_order["refactor_seconds"].get<double>(),
          fixed_order["perturbed_pivots"].get<long long>());
    if (!pivot_order.is_null())
      fmt::print(
          "  strata in its delayed pivots' order (analyze_in_pivot_order {:.4f} s, nnz(L) {}): "
          "refactorization {:.4f} s, delayed {}, {} perturbed pivots, backward error {:.1e}\n",
          pivot_order["analysis_seconds"].get<double>(), pivot_order["nnz_l"].get<long long>(),
          pivot_order["refactor_seconds"].get<double>(),
          pivot_order["delayed_pivoting"].get<bool>() ? "yes" : "no",
          pivot_order["perturbed_pivots"].get<long long>(),
          pivot_order["backward_error"].get<double>());
    fmt::print(
        "  application of the factor, b and x in GPU memory: strata {:.6f} s; cuDSS SOLVE "
        "{:.6f} s first, {:.6f} s again\n",
        gpu_arrays_first, def.ok ? def.solve : -1.0, def.ok ? def.solve_again : -1.0);
    fmt::print(
        "  checked solve from host arrays (residual and refinement{}): strata {:.6f} s, {} "
        "refinement steps, backward error {:.1e}; right after a refactorization {:.6f} s\n",
        o.gpu_refinement ? " on the GPU" : " with host residuals", sol_s,
        solve_stats.refinement_steps, solve_stats.backward_error, sol_after_refactor_s);
    if (!def.ok) fmt::print("  cuDSS default failed: {}\n", def.error);
    if (!same.ok) fmt::print("  cuDSS with strata's permutation failed: {}\n", same.error);
    std::fflush(stdout);
    out["rows"].push_back(row);
    // keep what is measured so far, in case the run is cut off (one partial file only)
    const std::string now = bench::write_result(
        out, tag.empty() ? "cudss-partial" : "cudss-" + tag + "-partial", results_dir);
    if (!partial.empty() && partial != now) std::remove(partial.c_str());
    partial = now;
  }
  fmt::print("results: {}\n",
             bench::write_result(out, tag.empty() ? "cudss" : "cudss-" + tag, results_dir));
  if (!partial.empty()) std::remove(partial.c_str());
  return 0;
}

int main(int argc, char** argv) { return strata::bench::run_driver(argc, argv, driver_main); }
