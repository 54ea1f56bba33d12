// strata benchmark — the analysis phase against CHOLMOD's analyze with METIS.
//
// For each problem: nnz(L), factor flops and analysis time of strata (its own nested
// dissection by default) next to cholmod_l_analyze with the METIS ordering, in the same
// run; the median of --repeat runs is reported. Results: bench/results/analysis-*.json
// (analysis-<tag>-*.json with --tag).
//
// The multibody Newton matrices (files written by `strata simulate --dump-matrix`, given
// by path) are unsymmetric and analyzed as the engine does: --matching keeps strata's
// matching and scaling (the pattern-only comparison with CHOLMOD turns them off), and
// --umfpack adds the time of UMFPACK's symbolic phase (umfpack_dl_symbolic with its
// default strategy, the values given) on the same matrix, one call after each of strata's
// analyses; the ratios reported are the medians of these pairs' ratios.
//
//   bench_analysis [--problems a,b,...] [--repeat R] [--ordering nd|metis|amd|auto] [--no-cholmod]
//                  [--matching] [--umfpack] [--threads N] [--tag NAME] [--results-dir DIR]
#include <cholmod.h>
#include <fmt/core.h>
#include <sys/resource.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <optional>
#ifdef STRATA_BENCH_HAVE_UMFPACK
#include <umfpack.h>
#endif

#include "base/timer.hpp"
#include "bench_common.hpp"
#include "crash_report.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

namespace {

struct CholmodAnalysis {
  double lnz = 0, flops = 0, seconds = 0;
};

CholmodAnalysis cholmod_analysis(const SparseMatrix& a, bool symmetric, int repeat) {
  cholmod_common cc;
  cholmod_l_start(&cc);
  cc.nmethods = 1;
  cc.method[0].ordering = CHOLMOD_METIS;
  // CHOLMOD analyzes A (stype -1: lower triangle) or, unsymmetric, A+Aᵀ via stype 0 and
  // cholmod_analyze of A Aᵀ — so for unsymmetric problems hand it the symmetrized pattern.
  SparseMatrix s = symmetric ? canonicalize(a) : expand_symmetric(a);
  if (!symmetric) {  // lower triangle of A + Aᵀ
    SparseMatrix t = s;
    t.layout = Layout::csr;  // transpose
    SparseMatrix tt = canonicalize(t);
    SparseMatrix sum;
    sum.n_rows = sum.n_cols = s.n_cols;
    sum.storage = Storage::lower;
    sum.offsets.assign(s.n_cols + 1, 0);
    for (index_t j = 0; j < s.n_cols; ++j) {
      std::vector<index_t> rows;
      for (index_t p = s.offsets[j]; p < s.offsets[j + 1]; ++p)
        if (s.indices[p] >= j) rows.push_back(s.indices[p]);
      for (index_t p = tt.offsets[j]; p < tt.offsets[j + 1]; ++p)
        if (tt.indices[p] >= j) rows.push_back(tt.indices[p]);
      std::sort(rows.begin(), rows.end());
      rows.erase(std::unique(rows.begin(), rows.end()), rows.end());
      for (index_t r : rows) sum.indices.push_back(r);
      sum.offsets[j + 1] = sum.indices.size();
    }
    s = std::move(sum);
  }
  const index_t n = s.n_cols;
  cholmod_sparse* A = cholmod_l_allocate_sparse(n, n, s.nnz(), 1, 1, -1, CHOLMOD_PATTERN, &cc);
  std::copy(s.offsets.begin(), s.offsets.end(), static_cast<SuiteSparse_long*>(A->p));
  std::copy(s.indices.begin(), s.indices.end(), static_cast<SuiteSparse_long*>(A->i));
  std::vector<double> times;
  CholmodAnalysis r;
  for (int k = 0; k < repeat; ++k) {
    Timer t;
    cholmod_factor* L = cholmod_l_analyze(A, &cc);
    times.push_back(t.seconds());
    r.lnz = cc.lnz;
    r.flops = cc.fl;
    cholmod_l_free_factor(&L, &cc);
  }
  r.seconds = bench::median(times);
  cholmod_l_free_sparse(&A, &cc);
  cholmod_l_finish(&cc);
  return r;
}

#ifdef STRATA_BENCH_HAVE_UMFPACK
// umfpack_dl_symbolic (default control: its own choice of strategy and ordering) on the
// full matrix, values included (its strategy looks at them), timed one call at a time so
// that the driver can interleave its calls with strata's analyses.
class UmfpackSymbolic {
 public:
  explicit UmfpackSymbolic(const SparseMatrix& a) : f_(expand_symmetric(a)) {
    ap_.assign(f_.offsets.begin(), f_.offsets.end());
    ai_.assign(f_.indices.begin(), f_.indices.end());
    umfpack_dl_defaults(control_);
  }
  double seconds() {
    void* symbolic = nullptr;
    double info[UMFPACK_INFO];
    Timer t;
    const SuiteSparse_long status = umfpack_dl_symbolic(
        static_cast<SuiteSparse_long>(f_.n_cols), static_cast<SuiteSparse_long>(f_.n_cols),
        ap_.data(), ai_.data(), f_.values.data(), &symbolic, control_, info);
    const double s = t.seconds();
    if (status != UMFPACK_OK)
      throw Error("umfpack_dl_symbolic failed with status " + std::to_string(status));
    umfpack_dl_free_symbolic(&symbolic);
    return s;
  }

 private:
  SparseMatrix f_;
  std::vector<SuiteSparse_long> ap_, ai_;
  double control_[UMFPACK_CONTROL];
};
#endif

}  // namespace

static int driver_main(int argc, char** argv) {
  app::report_fatal_signals();  // a crash on a lent machine says where
  CLI::App app{"strata analysis benchmark (vs CHOLMOD + METIS)"};
  std::vector<std::string> problems = {"bcsstk09",         "bcsstk13",       "bcsstk16",
                                       "ccx_segmenttet_K", "ccx_cubef2f3_K", "lap3d-60",
                                       "lap3d-80",         "elast3d-30",     "elast3d-40"};
  int repeat = 3;
  std::string ordering = "nd";
  bool no_cholmod = false;
  app.add_option("--problems", problems, "problems (shared matrix names or lap3d-N, elast3d-N)")
      ->delimiter(',');
  app.add_option("--repeat", repeat, "runs per measurement (median reported)");
  app.add_option("--ordering", ordering)->check(CLI::IsMember({"nd", "metis", "amd", "auto"}));
  app.add_flag("--no-cholmod", no_cholmod, "skip the CHOLMOD reference (e.g. for huge problems)");
  bool matching = false, umfpack = false;
  int threads = 0;
  app.add_flag("--matching", matching,
               "keep strata's matching and scaling (general matrices, as the engine analyzes)");
  app.add_flag("--umfpack", umfpack, "add the time of UMFPACK's symbolic phase");
  app.add_option("--threads", threads, "host threads of strata's analysis (default: all)")
      ->check(CLI::NonNegativeNumber);
  std::string tag, results_dir;
  app.add_option("--tag", tag,
                 "label stored in the results (\"tag\") and added to the file name, e.g. mbs-64")
      ->check(bench::check_tag);
  app.add_option("--results-dir", results_dir,
                 "folder for the results file (default bench/results)");
  CLI11_PARSE(app, argc, argv);
#ifndef STRATA_BENCH_HAVE_UMFPACK
  if (umfpack) {
    fmt::print(stderr, "bench_analysis: built without UMFPACK; --umfpack is not available\n");
    return 2;
  }
#endif

  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "analysis";
  out["matching"] = matching;
  out["threads"] = threads;
  out["tag"] = tag;
  out["rows"] = json::array();
  fmt::print("{:<18} {:>9} {:>12} {:>12} {:>6} {:>10} {:>10} {:>8} {:>8} {:>6}\n", "problem", "n",
             "nnzL strata", "nnzL cholmod", "ratio", "flops s", "flops c", "t strata", "t chol",
             "ratio");
  std::vector<double> lnz_ratios, time_ratios, umfpack_ratios, umfpack_phase_ratios;
  for (const std::string& name : problems) {
    bench::Problem p = bench::load_problem(name);
    Options o;
    o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
    o.matching_and_scaling = matching;  // off: the pattern-only comparison with CHOLMOD
    o.num_threads = threads;
    o.ordering = ordering == "nd"      ? OrderingMethod::nested_dissection
                 : ordering == "metis" ? OrderingMethod::metis
                 : ordering == "amd"   ? OrderingMethod::amd
                                       : OrderingMethod::automatic;
    // times: Solver::analyze as a caller sees it; phase_times: the analysis itself
    // (AnalysisStats::total_seconds: matching and scaling, ordering, symbolic phase, plan),
    // without the solver's validation of the input and its copy of it for the
    // factorizations and refinement
    // With --umfpack each analysis is followed by one UMFPACK symbolic phase, and the
    // ratios are the medians of these pairs' ratios: a machine whose speed drifts over
    // the run (a shared or throttled host) moves both members of a pair alike.
    std::vector<double> times, phase_times, umfpack_times, pair_ratios, phase_pair_ratios;
#ifdef STRATA_BENCH_HAVE_UMFPACK
    std::optional<UmfpackSymbolic> umf;
    if (umfpack) umf.emplace(p.a);
#endif
    AnalysisStats st;
    for (int k = 0; k < repeat; ++k) {
      {
        Solver s(o);
        Timer t;
        s.analyze(p.a);
        times.push_back(t.seconds());
        st = s.stats().analysis;
        phase_times.push_back(st.total_seconds);
      }
#ifdef STRATA_BENCH_HAVE_UMFPACK
      if (umf) {
        umfpack_times.push_back(umf->seconds());
        pair_ratios.push_back(times.back() / umfpack_times.back());
        phase_pair_ratios.push_back(phase_times.back() / umfpack_times.back());
      }
#endif
    }
    const double ts = bench::median(times), tp = bench::median(phase_times);
    json row = {{"problem", name},
                {"n", st.n},
                {"nnz_a", st.nnz_a},
                {"strata",
                 {{"nnz_l", st.nnz_l},
                  {"flops", st.factor_flops},
                  {"seconds", ts},
                  {"analysis_phase_seconds", tp},
                  {"ordering_seconds", st.ordering_seconds},
                  {"symbolic_seconds", st.symbolic_seconds},
                  {"plan_seconds", st.plan_seconds},
                  {"fronts", st.n_fronts},
                  {"ordering", to_string(st.ordering)},
                  {"tree_height", st.tree_height}}}};
#ifdef STRATA_BENCH_HAVE_UMFPACK
    if (umfpack) {
      const double tu = bench::median(umfpack_times);
      const double rt = bench::median(pair_ratios), rp = bench::median(phase_pair_ratios);
      row["umfpack_symbolic_seconds"] = tu;
      row["umfpack_time_ratio"] = rt;
      row["umfpack_phase_ratio"] = rp;
      row["umfpack_phase_ratio_range"] = {
          *std::min_element(phase_pair_ratios.begin(), phase_pair_ratios.end()),
          *std::max_element(phase_pair_ratios.begin(), phase_pair_ratios.end())};
      umfpack_ratios.push_back(rt);
      umfpack_phase_ratios.push_back(rp);
      fmt::print(
          "{:<18} strata analyze {:.4f} s, of which the analysis {:.4f} s (matching and "
          "ordering {:.4f}, symbolic {:.4f}, plan {:.4f}); UMFPACK symbolic {:.4f} s; ratio "
          "{:.2f} (the analysis alone {:.2f}, pairs {:.2f}-{:.2f})\n",
          name, ts, tp, st.ordering_seconds, st.symbolic_seconds, st.plan_seconds, tu, rt, rp,
          row["umfpack_phase_ratio_range"][0].get<double>(),
          row["umfpack_phase_ratio_range"][1].get<double>());
    }
#endif
    if (!no_cholmod) {
      CholmodAnalysis c = cholmod_analysis(p.a, p.symmetric, repeat);
      row["cholmod_metis"] = {{"nnz_l", c.lnz}, {"flops", c.flops}, {"seconds", c.seconds}};
      row["nnz_l_ratio"] = st.nnz_l / c.lnz;
      row["time_ratio"] = ts / c.seconds;
      lnz_ratios.push_back(st.nnz_l / c.lnz);
      time_ratios.push_back(ts / c.seconds);
      fmt::print(
          "{:<18} {:>9} {:>12} {:>12.0f} {:>6.3f} {:>10.3g} {:>10.3g} {:>8.3f} {:>8.3f} {:>6.2f}\n",
          name, st.n, st.nnz_l, c.lnz, st.nnz_l / c.lnz, st.factor_flops, c.flops, ts, c.seconds,
          ts / c.seconds);
    } else {
      fmt::print("{:<18} {:>9} {:>12} {:>12} {:>6} {:>10.3g} {:>10} {:>8.3f}\n", name, st.n,
                 st.nnz_l, "-", "-", st.factor_flops, "-", ts);
    }
    std::fflush(stdout);
    out["rows"].push_back(row);
  }
  struct rusage ru;
  getrusage(RUSAGE_SELF, &ru);
  out["peak_rss_bytes"] = static_cast<double>(ru.ru_maxrss) * 1024.0;
  if (!lnz_ratios.empty()) {
    out["geomean_nnz_l_ratio"] = bench::geometric_mean(lnz_ratios);
    out["geomean_time_ratio"] = bench::geometric_mean(time_ratios);
    fmt::print("geometric mean: nnz(L) ratio {:.3f}, analysis time ratio {:.3f}\n",
               bench::geometric_mean(lnz_ratios), bench::geometric_mean(time_ratios));
  }
  if (!umfpack_ratios.empty()) {
    out["geomean_umfpack_time_ratio"] = bench::geometric_mean(umfpack_ratios);
    out["geomean_umfpack_phase_ratio"] = bench::geometric_mean(umfpack_phase_ratios);
    fmt::print(
        "geometric mean: analyze time / UMFPACK symbolic {:.3f} (the analysis alone {:.3f})\n",
        bench::geometric_mean(umfpack_ratios), bench::geometric_mean(umfpack_phase_ratios));
  }
  fmt::print("peak RSS {:.1f} MB\n", ru.ru_maxrss / 1024.0);
  const std::string stem = tag.empty() ? "analysis" : "analysis-" + tag;
  fmt::print("results: {}\n", bench::write_result(out, stem, results_dir));
  return 0;
}

int main(int argc, char** argv) { return strata::bench::run_driver(argc, argv, driver_main); }
