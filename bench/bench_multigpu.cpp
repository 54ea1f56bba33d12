// strata benchmark — the multi-worker factorization (experiment 3: GPU count 1, 2, 4,
// with the ablation of balanced bisection, additional subtrees, work stealing and the
// split of the top part into upper layers).
//
// For each problem and each configuration (workers × subtrees per worker × balance by
// work on/off × work stealing on/off × top split on/off × split_front_min_cb values of
// --split-fronts, 0 = large fronts' updates not split over idle GPUs × distributed_front_min_rows
// values of --distributed-fronts, 0 = no front factored over the idle GPUs): the analysis figures
// of the tree split (ordering time, the part spent balancing the bisections by work, bisections
// redone, nnz(L), flops, subtrees, LPT balance, upper layers and their parts, the share
// of the flops in the upper layers and in the final top part) and, unless
// --no-factor, one factorization (reported apart as first_factor_seconds), then the median of
// --repeat refactorizations, the backward error of one solve, the median of --repeat
// applications of the factor (first_solve_seconds; solve_on_device: on the GPUs holding the
// parts) and the per-worker statistics of the last run (busy, idle, subtrees run and
// stolen, upper parts run, bytes transferred).
// --budget-share R (a list; 0: no budget) sets device_memory_limit to the per-GPU share of
// the factor, factor bytes / workers / R, found by a first analysis (issue 6's "budget far
// below the per-GPU factor share"); the row then also reports tiled fronts, spilled blocks
// and the bytes moved each way. Problems are the bench_common names, or Matrix Market files
// by path (the multibody Newton matrices of scripts/gpu/run_mechanical.sh). --backend
// cuda runs on that many GPUs (the lent machines);
// --backend cpu stands N host executors of --threads-per-worker threads each in for N
// GPUs (the same driver, for machines without GPUs). --solver-option sets any strata option
// for every run (e.g. gpu_solve_parts=false). Results: bench/results/multigpu-*.json.
//
//   bench_multigpu [--problems a,b,...] [--backend cpu|cuda] [--workers 1,2,4]
//                  [--subtrees 4] [--balance on,off] [--stealing on,off]
//                  [--split-top on,off] [--split-fronts 2048,0] [--budget-share 0,20]
//                  [--repeat R] [--max-block-size B]
//                  [--threads-per-worker T] [--no-factor] [--solver-option NAME=VALUE]...
//                  [--tag NAME] [--results-dir DIR]
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <memory>

#include "base/timer.hpp"
#include "bench_common.hpp"
#include "core/solver_internal.hpp"
#include "core/stats_json.hpp"
#include "crash_report.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

static int driver_main(int argc, char** argv) {
  app::report_fatal_signals();  // a crash on a lent machine says where
  CLI::App app{"strata multi-worker factorization benchmark"};
  std::vector<std::string> problems = {"lap3d-30", "elast3d-14"};
  // defaults: the library's (an ablation names its values)
  std::vector<int> workers = {1, 2, 4}, subtrees = {Options{}.subtrees_per_gpu};
  std::vector<std::string> balance = {Options{}.balance_by_work ? "on" : "off"},
                           stealing = {Options{}.work_stealing ? "on" : "off"},
                           split_top = {Options{}.split_top ? "on" : "off"};
  std::vector<double> budget_share = {0};
  std::vector<index_t> split_fronts = {Options{}.split_front_min_cb};
  std::vector<index_t> dist_fronts = {Options{}.distributed_front_min_rows};
  std::vector<index_t> dist_blocks = {Options{}.distributed_front_block_size};
  std::string backend = "cpu";
  index_t max_block_size = 0;
  int repeat = 3, threads_per_worker = 1;
  bool no_factor = false;
  std::string tag, results_dir;
  app.add_option("--problems", problems, "problems (shared matrix names, lap3d-N, elast3d-N, ...)")
      ->delimiter(',');
  app.add_option("--backend", backend, "cuda: GPUs; cpu: host executors standing in for GPUs")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--workers", workers, "worker (GPU) counts")->delimiter(',');
  app.add_option("--subtrees", subtrees, "subtrees per worker")->delimiter(',');
  app.add_option("--balance", balance, "balance the top bisections by work: on, off")
      ->delimiter(',');
  app.add_option("--stealing", stealing, "work stealing: on, off")->delimiter(',');
  app.add_option("--split-top", split_top, "split the top part into upper layers: on, off")
      ->delimiter(',');
  app.add_option("--split-fronts", split_fronts,
                 "Options::split_front_min_cb values (0: no front's update split over idle GPUs)")
      ->delimiter(',')
      ->check(CLI::NonNegativeNumber);
  app.add_option("--distributed-fronts", dist_fronts,
                 "Options::distributed_front_min_rows values (0: no front factored over the "
                 "idle GPUs)")
      ->delimiter(',')
      ->check(CLI::NonNegativeNumber);
  app.add_option("--distributed-block", dist_blocks,
                 "Options::distributed_front_block_size values (columns per block)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  app.add_option("--budget-share", budget_share,
                 "device budget = factor bytes / workers / R for each R (0: no budget)")
      ->delimiter(',')
      ->check(CLI::NonNegativeNumber);
  app.add_option("--max-block-size", max_block_size,
                 "Options::max_block_size (0: the backend's default; 4096 gives a CPU analysis "
                 "the CUDA backend's Cholesky tree)");
  app.add_option("--repeat", repeat, "factorizations per measurement (median reported)");
  app.add_option("--threads-per-worker", threads_per_worker, "host threads of each CPU worker");
  app.add_flag("--no-factor", no_factor, "analysis figures only");
  std::vector<std::string> solver_options;
  app.add_option("--solver-option", solver_options,
                 "a strata option for every run, NAME=VALUE (the names of strata::set_option, "
                 "as strata simulate --solver-option); repeatable");
  app.add_option("--tag", tag, "label stored in the results and the file name")
      ->check(bench::check_tag);
  app.add_option("--results-dir", results_dir, "folder for the results file");
  CLI11_PARSE(app, argc, argv);
  Options base;
  for (const std::string& so : solver_options) {
    const auto eq = so.find('=');
    if (eq == std::string::npos) {
      fmt::print(stderr, "bench_multigpu: --solver-option takes NAME=VALUE, got '{}'\n", so);
      return 2;
    }
    try {
      set_option(base, so.substr(0, eq), so.substr(eq + 1));
    } catch (const Error& e) {
      fmt::print(stderr, "bench_multigpu: --solver-option {}: {}\n", so, e.what());
      return 2;
    }
  }

  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "multigpu";
  out["backend"] = backend;
  out["tag"] = tag;
  out["solver_options"] = solver_options;
  out["rows"] = json::array();
  fmt::print(
      "{:<12} {:>2} {:>2} {:>3} {:>3} {:>3} {:>5} {:>9} {:>8} {:>8} {:>5} {:>9} {:>4} {:>7} {:>5} "
      "{:>6} "
      "{:>6} {:>5} {:>8} {:>8} {:>9} {:>9}\n",
      "problem", "W", "s", "bal", "stl", "top", "splcb", "dist/blk", "order s", "bal s", "rebis",
      "flops", "subt", "balance", "layer", "upp %", "top %", "est x", "factor s", "berr",
      "budget MB", "solve ms");
  for (const std::string& name : problems) {
    const bench::Problem p = bench::load_problem(name);
    std::vector<double> b(p.a.n_rows);
    {
      std::vector<double> ones(p.a.n_rows, 1.0);
      multiply(p.a, ones.data(), b.data());
    }
    for (int w : workers)
      for (int s : subtrees)
        for (const std::string& bal : balance)
          for (const std::string& stl : stealing)
            for (const std::string& split : split_top)
              for (double share : budget_share)
                for (const index_t split_cb : split_fronts)
                  for (const index_t dist : dist_fronts)
                    for (const index_t dist_block : dist_blocks) {
                      Options o = base;  // --solver-option, then this row's settings
                      o.type = p.symmetric ? MatrixType::spd : MatrixType::general;
                      o.subtrees_per_gpu = s;
                      o.balance_by_work = bal == "on";
                      o.work_stealing = stl == "on";
                      o.split_top = split == "on";
                      o.split_front_min_cb = split_cb;
                      o.distributed_front_min_rows = dist;
                      o.distributed_front_block_size = dist_block;
                      o.max_block_size = max_block_size;
                      // CPU workers: threads each; the CUDA backend keeps every host thread for the
                      // analysis and the input pass (one thread made that pass a third of an
                      // elasticity refactorization on the 4-GPU machine)
                      if (backend == "cpu") o.num_threads = threads_per_worker;
                      if (backend == "cuda") {
                        o.backend = Backend::cuda;
                        o.num_gpus = w;
                      }
                      auto make_solver = [&](const Options& opts) {
                        auto solver = std::make_unique<Solver>(opts);
                        if (backend == "cpu") {
                          numeric::MultiWorkerConfig cfg;
                          cfg.work_stealing = opts.work_stealing;
                          detail::SolverAccess::use_host_workers(*solver, w, threads_per_worker,
                                                                 cfg);
                        }
                        return solver;
                      };
                      std::size_t factor_bytes = 0;
                      if (share >
                          0) {  // the budget is a share of the factor: one analysis to size it
                        auto probe = make_solver(o);
                        probe->analyze(p.a);
                        factor_bytes = probe->stats().analysis.factor_bytes;
                        o.device_memory_limit =
                            static_cast<std::size_t>(static_cast<double>(factor_bytes) / w / share);
                      }
                      std::unique_ptr<Solver> owned = make_solver(o);
                      Solver& solver = *owned;
                      solver.analyze(p.a);
                      const AnalysisStats an = solver.stats().analysis;
                      json row = {{"problem", p.name},
                                  {"n", an.n},
                                  {"max_block_size", an.max_block_size},
                                  {"workers", w},
                                  {"subtrees_per_worker", s},
                                  {"balance_by_work", bal == "on"},
                                  {"work_stealing", stl == "on"},
                                  {"split_top", split == "on"},
                                  {"split_front_min_cb", split_cb},
                                  {"distributed_front_min_rows", dist},
                                  {"distributed_front_block_size", dist_block},
                                  {"ordering_seconds", an.ordering_seconds},
                                  {"nd_balance_seconds", an.nd_balance_seconds},
                                  {"nd_rebisections", an.nd_rebisections},
                                  {"nnz_l", an.nnz_l},
                                  {"flops", an.factor_flops},
                                  {"subtrees", an.subtrees},
                                  {"subtree_balance", an.subtree_balance},
                                  {"upper_layers", an.upper_layers},
                                  {"upper_parts", an.upper_parts},
                                  {"upper_flops_fraction", an.upper_flops_fraction},
                                  {"top_flops_fraction", an.top_flops_fraction},
                                  {"estimated_speedup", an.estimated_speedup},
                                  {"budget_share_ratio", share},
                                  {"device_memory_limit", o.device_memory_limit},
                                  {"factor_bytes", an.factor_bytes}};
                      double ts = 0, berr = 0, first = 0, solve = 0;
                      if (!no_factor) {
                        // the first factorization sets the executors up (device buffers, pinned
                        // host memory, library handles): reported apart; the figure is the median
                        // of the refactorizations that follow, as bench_gpu and bench_cudss do
                        Timer t0;
                        solver.factorize(p.a);
                        first = t0.seconds();
                        std::vector<double> times;
                        for (int k = 0; k < repeat; ++k) {
                          Timer t;
                          solver.refactorize(p.a);
                          times.push_back(t.seconds());
                        }
                        ts = bench::median(times);
                        const auto x = solver.solve(b);
                        berr = bench::berr(p.a, x, b);
                        // one application of the factor (SolveStats::first_solve_seconds:
                        // no refinement), median of --repeat solves; on the GPUs that hold
                        // the parts, or on the host with the panels fetched
                        std::vector<double> solves;
                        bool on_device = false;
                        for (int k = 0; k < repeat; ++k) {
                          (void)solver.solve(b);
                          solves.push_back(solver.stats().solve.first_solve_seconds);
                          on_device = solver.stats().solve.on_device;
                        }
                        solve = solves.empty() ? 0.0 : bench::median(solves);
                        row["first_solve_seconds"] = solve;
                        row["solve_times"] = solves;
                        row["solve_on_device"] = on_device;
                        const json devices = solver.stats().factor.devices;
                        row["factor_seconds"] = ts;
                        row["refactor_times"] = times;  // the spread behind the median
                        row["first_factor_seconds"] = first;
                        row["factor_phases"] = solver.stats().factor.device_phases;
                        row["input_seconds"] = solver.stats().factor.input_seconds;
                        row["backward_error"] = berr;
                        row["devices"] = devices;
                        const FactorStats& fs = solver.stats().factor;
                        row["tiled_fronts"] = fs.tiled_fronts;
                        row["contribution_blocks_on_host"] = fs.contribution_blocks_on_host;
                        row["bytes_to_device"] = fs.bytes_to_device;
                        row["bytes_to_host"] = fs.bytes_to_host;
                      }
                      out["rows"].push_back(row);
                      fmt::print(
                          "{:<12} {:>2} {:>2} {:>3} {:>3} {:>3} {:>5} {:>9} {:>8.3f} {:>8.3f} "
                          "{:>5} "
                          "{:>9.3g} "
                          "{:>4} {:>7.3f} {:>5} {:>6.1f} {:>6.1f} {:>5.2f} {:>8.3f} {:>8.1e} "
                          "{:>9} {:>9.3f}\n",
                          p.name, w, s, bal, stl, split, split_cb,
                          fmt::format("{}/{}", dist, dist_block), an.ordering_seconds,
                          an.nd_balance_seconds, an.nd_rebisections, an.factor_flops, an.subtrees,
                          an.subtree_balance, fmt::format("{}/{}", an.upper_layers, an.upper_parts),
                          100 * an.upper_flops_fraction, 100 * an.top_flops_fraction,
                          an.estimated_speedup, ts, berr,
                          share > 0 ? fmt::format("{:.1f}", o.device_memory_limit * 1e-6) : "-",
                          1e3 * solve);
                      std::fflush(stdout);
                    }
  }
  fmt::print("results: {}\n", bench::write_result(out, "multigpu", results_dir));
  return 0;
}

int main(int argc, char** argv) { return strata::bench::run_driver(argc, argv, driver_main); }
