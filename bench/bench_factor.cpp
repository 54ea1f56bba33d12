// strata benchmark — numeric factorization against CHOLMOD (supernodal) and MUMPS, with
// the same fill-reducing permutation passed to all three, in one run.
//
// strata's permutation (nested dissection + etree postorder) is handed to CHOLMOD via
// cholmod_l_analyze_p (CHOLMOD_GIVEN) and to MUMPS via ICNTL(7) = 1 (PERM_IN). Times are
// medians over --repeat factorizations (strata: refactorize, which is what the multibody
// loop calls; CHOLMOD: cholmod_l_factorize on the same symbolic object; MUMPS: JOB=2),
// and over as many solves of one right-hand side (strata and CHOLMOD).
// All three use the same OpenBLAS with --threads threads.
// Memory: each solver's analysis and first factorization also run once in a fresh process
// (this binary again, --measure-memory SOLVER) whose peak resident set (VmHWM) is
// reported next to the times, with the same input in every process (the problem loaded,
// CHOLMOD and MUMPS given strata's permutation from a file), so that the figures compare;
// strata's is also set against what the analysis says a CPU factorization holds
// (AnalysisStats::analysis_bytes + cpu_factorization_bytes) plus the input. --no-memory skips it.
// Results: bench/results/factor-*.json (factor-<tag>-*.json with --tag).
//
//   bench_factor [--problems a,b,...] [--repeat R] [--threads T] [--max-block-size N]
//                [--no-mumps] [--no-memory] [--tag NAME] [--results-dir DIR]
#include <cholmod.h>
#include <fmt/core.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>

#ifdef STRATA_BENCH_HAVE_MUMPS
#include <dmumps_c.h>
#endif

#include "base/blas.hpp"
#include "base/timer.hpp"
#include "bench_common.hpp"
#include "crash_report.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

namespace {

using bench::berr;
using bench::RefResult;
using bench::run_cholmod;

#ifdef STRATA_BENCH_HAVE_MUMPS
RefResult run_mumps(const SparseMatrix& a, const std::vector<index_t>& perm,
                    const std::vector<double>& b, bool spd, int repeat) {
  RefResult r;
  DMUMPS_STRUC_C id{};
  id.comm_fortran = -987654;  // USE_COMM_WORLD (sequential library)
  id.par = 1;
  id.sym = spd ? 1 : 0;
  id.job = -1;
  dmumps_c(&id);
  // lower triangle (symmetric) or full, 1-based coordinates
  std::vector<MUMPS_INT> irn, jcn;
  std::vector<double> val;
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      irn.push_back(static_cast<MUMPS_INT>(a.indices[p] + 1));
      jcn.push_back(static_cast<MUMPS_INT>(j + 1));
      val.push_back(a.values[p]);
    }
  std::vector<MUMPS_INT> perm_in(a.n_rows);
  for (std::size_t k = 0; k < perm.size(); ++k) perm_in[perm[k]] = static_cast<MUMPS_INT>(k + 1);
  id.n = static_cast<MUMPS_INT>(a.n_rows);
  id.nnz = static_cast<MUMPS_INT8>(irn.size());
  id.irn = irn.data();
  id.jcn = jcn.data();
  id.a = val.data();
  id.icntl[0] = -1;  // no error/diagnostic output
  id.icntl[1] = -1;
  id.icntl[2] = -1;
  id.icntl[3] = 0;
  id.icntl[6] = 1;  // ICNTL(7) = 1: given ordering in PERM_IN (position of each variable)
  id.perm_in = perm_in.data();
  id.icntl[13] = 50;  // ICNTL(14): 50% more working space than estimated
  id.job = 1;
  dmumps_c(&id);
  std::vector<double> times;
  for (int k = 0; k < repeat && id.infog[0] >= 0; ++k) {
    id.job = 2;
    Timer t;
    dmumps_c(&id);
    times.push_back(t.seconds());
  }
  r.ok = id.infog[0] >= 0;
  if (r.ok) {
    r.seconds = bench::median(times);
    r.lnz = static_cast<double>(id.infog[28] > 0 ? id.infog[28] : -id.infog[28] * 1e6);
    std::vector<double> x = b;
    id.rhs = x.data();
    id.job = 3;
    dmumps_c(&id);
    r.backward_error = berr(a, x, b);
  }
  id.job = -2;
  dmumps_c(&id);
  return r;
}
#endif

// strata's options in this benchmark: Cholesky, the threads and block size asked for.
Options strata_options(int threads, index_t max_block) {
  Options o;
  o.type = MatrixType::spd;
  o.num_threads = threads;
  o.max_block_size = max_block;
  // the solves timed bare, as CHOLMOD's (the backward error is computed here apart)
  o.solve_check = SolveCheck::after_perturbed_pivots;
  return o;
}

// Peak resident set of this process so far (VmHWM in /proc/self/status), in bytes; 0
// where it cannot be read.
std::size_t peak_rss_bytes() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line))
    if (line.rfind("VmHWM:", 0) == 0) return std::stoull(line.substr(6)) * 1024;
  return 0;
}

// --measure-memory SOLVER (a child process): loads the problem, runs SOLVER's analysis and
// one factorization (CHOLMOD and MUMPS with the permutation in perm_file) and prints
// {"input_rss_bytes": …, "peak_rss_bytes": …} on stdout. Returns the exit status.
int measure_memory(const std::string& solver, const std::string& name, int threads,
                   index_t max_block, const std::string& perm_file) {
  openblas_set_num_threads(threads);
  bench::Problem p = bench::load_problem(name);
  const index_t n = p.a.n_rows;
  std::vector<double> ones(n, 1.0), b(n);
  multiply(p.a, ones.data(), b.data());
  std::vector<index_t> perm;
  if (solver != "strata") {
    std::ifstream in(perm_file);
    index_t v = 0;
    while (in >> v) perm.push_back(v);
    if (static_cast<index_t>(perm.size()) != n) {
      fmt::print(stderr, "--measure-memory: {} holds {} entries, not n = {}\n", perm_file,
                 perm.size(), n);
      return 1;
    }
  }
  const std::size_t input = peak_rss_bytes();
  if (solver == "strata") {
    Solver s(strata_options(threads, max_block));
    s.factorize(p.a);
  } else if (solver == "cholmod") {
    if (!run_cholmod(p.a, perm, b, 1).ok) return 1;
#ifdef STRATA_BENCH_HAVE_MUMPS
  } else if (solver == "mumps") {
    if (!run_mumps(p.a, perm, b, true, 1).ok) return 1;
#endif
  } else {
    fmt::print(stderr, "--measure-memory: unknown solver '{}'\n", solver);
    return 2;
  }
  fmt::print("{}\n", json{{"input_rss_bytes", input}, {"peak_rss_bytes", peak_rss_bytes()}}.dump());
  return 0;
}

// The peak resident set of `solver` on problem `name` in a fresh process (this binary with
// --measure-memory); null when it could not be measured.
json memory_of(const std::string& solver, const std::string& name, int threads, index_t max_block,
               const std::string& perm_file) {
  char self[4096];
  const ssize_t len = readlink("/proc/self/exe", self, sizeof self - 1);
  if (len <= 0) return json();
  self[len] = '\0';
  const std::string cmd = fmt::format(
      "'{}' --measure-memory {} --problems '{}' --threads {} --max-block-size {} --perm-file '{}'",
      self, solver, name, threads, max_block, perm_file);
  std::unique_ptr<FILE, int (*)(FILE*)> pipe(popen(cmd.c_str(), "r"), pclose);
  if (!pipe) return json();
  std::string text;
  char buf[256];
  while (std::fgets(buf, sizeof buf, pipe.get())) text += buf;
  if (pclose(pipe.release()) != 0) return json();
  try {
    return json::parse(text);
  } catch (const json::exception&) {
    return json();
  }
}

}  // namespace

static int driver_main(int argc, char** argv) {
  app::report_fatal_signals();  // a crash on a lent machine says where
  CLI::App app{"strata factorization benchmark (vs CHOLMOD and MUMPS, same permutation)"};
  std::vector<std::string> problems = {"bcsstk09",         "bcsstk13",       "bcsstk16",
                                       "ccx_segmenttet_K", "ccx_cubef2f3_K", "lap3d-40",
                                       "lap3d-60",         "elast3d-20",     "elast3d-30"};
  int repeat = 3, threads = 2;
  bool no_mumps = false;
  index_t max_block = Options{}.max_block_size;
  app.add_option("--problems", problems, "problems")->delimiter(',');
  app.add_option("--repeat", repeat, "factorizations per measurement (median)");
  app.add_option("--threads", threads, "threads for every solver (OpenBLAS and strata)");
  app.add_option("--max-block-size", max_block, "strata's maximum block size");
  app.add_flag("--no-mumps", no_mumps, "skip MUMPS");
  bool no_memory = false;
  app.add_flag("--no-memory", no_memory,
               "skip the peak resident set of each solver (measured in fresh processes)");
  std::string measure, perm_file;
  app.add_option("--measure-memory", measure,
                 "internal: run this solver once on the one problem and print its peak "
                 "resident set")
      ->group("");
  app.add_option("--perm-file", perm_file, "internal: the permutation for --measure-memory")
      ->group("");
  std::string tag, results_dir;
  app.add_option("--tag", tag,
                 "label stored in the results (\"tag\") and added to the file name, e.g. mbs-64")
      ->check(bench::check_tag);
  app.add_option("--results-dir", results_dir,
                 "folder for the results file (default bench/results)");
  CLI11_PARSE(app, argc, argv);
  if (!measure.empty()) {
    if (problems.size() != 1) {
      fmt::print(stderr, "--measure-memory takes one problem\n");
      return 2;
    }
    return measure_memory(measure, problems[0], threads, max_block, perm_file);
  }
  openblas_set_num_threads(threads);

  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "factor";
  out["tag"] = tag;
  out["threads"] = threads;
  out["max_block_size"] = max_block;
  out["rows"] = json::array();
  fmt::print("{:<18} {:>8} {:>11} {:>9} {:>8} {:>9} {:>9} {:>7} {:>7} {:>9} {:>9}\n", "problem",
             "n", "nnz(L)", "strata s", "GFLOP/s", "cholmod s", "mumps s", "s/chol", "s/mumps",
             "berr s", "berr c");
  std::vector<double> ratio_c, ratio_m;
  for (const std::string& name : problems) {
    bench::Problem p = bench::load_problem(name);
    if (!p.symmetric) {
      fmt::print("{:<18} skipped: not symmetric (the SPD comparison needs an SPD matrix)\n", name);
      continue;
    }
    const index_t n = p.a.n_rows;
    std::vector<double> ones(n, 1.0), b(n);
    multiply(p.a, ones.data(), b.data());
    Solver s(strata_options(threads, max_block));
    s.analyze(p.a);
    Timer t0;
    s.factorize(p.a);
    const double first = t0.seconds();
    std::vector<double> times;
    for (int k = 0; k < repeat; ++k) {
      Timer t;
      s.refactorize(p.a);
      times.push_back(t.seconds());
    }
    const double ts = bench::median(times);
    auto x = s.solve(b);
    const double be = berr(p.a, x, b);
    times.clear();
    for (int k = 0; k < repeat; ++k) {
      Timer t;
      x = s.solve(b);
      times.push_back(t.seconds());
    }
    const double solve_s = bench::median(times);
    const AnalysisStats& an = s.stats().analysis;
    const double gflops = an.factor_flops / ts * 1e-9;
    openblas_set_num_threads(threads);
    RefResult c = run_cholmod(p.a, s.permutation(), b, repeat);
    RefResult m;
#ifdef STRATA_BENCH_HAVE_MUMPS
    if (!no_mumps) m = run_mumps(p.a, s.permutation(), b, true, repeat);
#endif
    json row = {{"problem", name},
                {"n", n},
                {"nnz_l", an.nnz_l},
                {"factor_flops", an.factor_flops},
                {"strata",
                 {{"seconds", ts},
                  {"first_factorize_seconds", first},
                  {"gflops", gflops},
                  {"backward_error", be},
                  {"solve_seconds", solve_s},
                  {"refinement_steps", s.stats().solve.refinement_steps}}},
                {"cholmod",
                 {{"seconds", c.seconds},
                  {"solve_seconds", c.solve_seconds},
                  {"nnz_l", c.lnz},
                  {"backward_error", c.backward_error},
                  {"ok", c.ok}}}};
    if (m.ok) row["mumps"] = {{"seconds", m.seconds}, {"backward_error", m.backward_error}};
    std::string rss = "";
    if (!no_memory) {
      const std::string pf = fmt::format("/tmp/strata-bench-perm-{}-{}.txt", getpid(), name);
      {
        std::ofstream f(pf);
        for (index_t v : s.permutation()) f << v << '\n';
      }
      const json ms = memory_of("strata", name, threads, max_block, pf);
      const json mc = memory_of("cholmod", name, threads, max_block, pf);
      json mm;
#ifdef STRATA_BENCH_HAVE_MUMPS
      if (m.ok) mm = memory_of("mumps", name, threads, max_block, pf);
#endif
      std::remove(pf.c_str());
      if (ms.is_object()) {
        row["strata"]["peak_rss_bytes"] = ms["peak_rss_bytes"];
        row["input_rss_bytes"] = ms["input_rss_bytes"];
        // what the analysis said its arrays and the factorization need, beside the input
        row["strata"]["reported_peak_bytes"] = an.analysis_bytes + an.cpu_factorization_bytes +
                                               ms["input_rss_bytes"].get<std::size_t>();
      }
      // a solver's own memory: its process's peak above what the process held with the
      // input loaded (the libraries' and the input's pages, the same in every process)
      auto own = [](const json& x) {
        return x["peak_rss_bytes"].get<double>() - x["input_rss_bytes"].get<double>();
      };
      if (ms.is_object()) row["strata"]["rss_above_input_bytes"] = own(ms);
      if (mc.is_object()) {
        row["cholmod"]["peak_rss_bytes"] = mc["peak_rss_bytes"];
        row["cholmod"]["rss_above_input_bytes"] = own(mc);
      }
      if (mm.is_object() && row.contains("mumps")) {
        row["mumps"]["peak_rss_bytes"] = mm["peak_rss_bytes"];
        row["mumps"]["rss_above_input_bytes"] = own(mm);
      }
      if (ms.is_object() && mc.is_object() && mc["peak_rss_bytes"].get<double>() > 0) {
        const double r = ms["peak_rss_bytes"].get<double>() / mc["peak_rss_bytes"].get<double>();
        row["rss_ratio_cholmod"] = r;
        if (own(mc) > 0) row["rss_above_input_ratio_cholmod"] = own(ms) / own(mc);
        rss = fmt::format(
            "  peak RSS {:.0f} / {:.0f} MB ({:.2f}×; above the input {:.0f} / {:.0f} MB)",
            ms["peak_rss_bytes"].get<double>() * 1e-6, mc["peak_rss_bytes"].get<double>() * 1e-6, r,
            own(ms) * 1e-6, own(mc) * 1e-6);
      }
    }
    row["ratio_cholmod"] = ts / c.seconds;
    ratio_c.push_back(ts / c.seconds);
    if (c.solve_seconds > 0) {
      row["solve_ratio_cholmod"] = solve_s / c.solve_seconds;
      rss += fmt::format("  solve {:.4f} / {:.4f} s ({:.2f}×)", solve_s, c.solve_seconds,
                         solve_s / c.solve_seconds);
    }
    if (m.ok) {
      row["ratio_mumps"] = ts / m.seconds;
      ratio_m.push_back(ts / m.seconds);
    }
    fmt::print(
        "{:<18} {:>8} {:>11} {:>9.4f} {:>8.2f} {:>9.4f} {:>9} {:>7.3f} {:>7} {:>9.1e} {:>9.1e}{}\n",
        name, n, an.nnz_l, ts, gflops, c.seconds, m.ok ? fmt::format("{:.4f}", m.seconds) : "-",
        ts / c.seconds, m.ok ? fmt::format("{:.3f}", ts / m.seconds) : "-", be, c.backward_error,
        rss);
    std::fflush(stdout);
    out["rows"].push_back(row);
  }
  out["geomean_ratio_cholmod"] = bench::geometric_mean(ratio_c);
  if (!ratio_m.empty()) out["geomean_ratio_mumps"] = bench::geometric_mean(ratio_m);
  fmt::print("geometric mean of strata/CHOLMOD factorization time: {:.3f}\n",
             bench::geometric_mean(ratio_c));
  if (!ratio_m.empty())
    fmt::print("geometric mean of strata/MUMPS factorization time:   {:.3f}\n",
               bench::geometric_mean(ratio_m));
  const std::string stem = tag.empty() ? "factor" : "factor-" + tag;
  fmt::print("results: {}\n", bench::write_result(out, stem, results_dir));
  return 0;
}

int main(int argc, char** argv) { return strata::bench::run_driver(argc, argv, driver_main); }
