// strata — the command line.
//
//   strata analyze FILE [--ordering nd|metis|amd|natural|auto] [--max-block-size N]
//                       [--device-memory-limit BYTES] [--json] [multi-GPU options]
//   [mpirun -n R] strata solve A.mtx [--rhs b.mtx] [--type spd|symmetric_indefinite|general|auto]
//                      [--ordering ...] [--max-block-size N] [--out x.mtx] [--json]
//                      [--device cpu|gpu|auto] [--device-memory-limit BYTES]
//   multi-GPU options (analyze, solve): [--num-gpus N] [--subtrees-per-gpu S]
//                      [--balance-by-work on|off] [--work-stealing on|off]
//                      [--split-top on|off]
//   strata simulate [MODEL.json] [--generate KIND:SIZE] [--t-end T] [--step h] [--order k]
//                   [--device cpu|gpu|auto] [--device-memory-limit BYTES] [--output DIR]
//                   [--vtk] [--dump-matrix DIR]
//                   [--dump-step K] [--output-interval S] [--full-newton] [--write-model F]
//                   [--variable-step [--rtol R] [--atol A] [--max-step H]] [--verbose]
//                   [--formulation auto|partitioned|stabilized] [--energy-tol E]
//                   [--checkpoint-every N [--checkpoint-dir DIR]]
//   strata simulate --resume DIR [--t-end T] [--output DIR] [--checkpoint-every N]
//                   [--device-memory-limit BYTES] ...
//   strata simulate ... --plot [--plot-coordinates NAME,...]
//   strata plot DIR [--coordinates NAME,...] [--title T]
//   strata --version | strata SUBCOMMAND --help
//
// Exit status (printed by --help): 0 on success, 1 on a solver or
// input error, 2 on a usage error, 128 + the signal number (130, 143) when SIGINT/SIGTERM
// stopped a simulation (its partial results and a checkpoint are kept). Every error line
// starts with "strata: error:".
#include <fmt/core.h>
#include <malloc.h>
#include <unistd.h>

#include <CLI/CLI.hpp>
#include <cfloat>
#include <chrono>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>

#include "base/atomic_file.hpp"
#include "base/cpu_level.hpp"
#include "blas_kernels.hpp"
#include "core/stats_json.hpp"
#include "crash_report.hpp"
#include "launch.hpp"
#include "mbd/generators.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"
#include "plot.hpp"
#include "strata/distributed.hpp"
#include "strata/strata.h"
#include "strata/strata.hpp"

namespace {

using json = nlohmann::json;
using namespace strata;

struct CommonArgs {
  std::string file;
  std::string ordering = "nd";
  index_t max_block_size = Options{}.max_block_size;
  std::size_t device_memory_limit = 0;
  std::string device = "auto";
  int threads = 0;
  bool json = false;
  bool reproducible = false;
  int num_gpus = Options{}.num_gpus;
  int subtrees_per_gpu = Options{}.subtrees_per_gpu;
  std::string balance_by_work = Options{}.balance_by_work ? "on" : "off";
  std::string work_stealing = Options{}.work_stealing ? "on" : "off";
  std::string split_top = Options{}.split_top ? "on" : "off";
};

// Value checks with readable messages (CLI11's own print the range's bound, 1.8e308, in
// full). Each returns "" when the value is good.
std::string bad_number(const std::string& v, bool integer, double least, bool strict) {
  const std::string want = std::string(integer ? "a whole number " : "a number ") +
                           (strict ? "greater than " : "of at least ") + fmt::format("{:g}", least);
  char* end = nullptr;
  errno = 0;
  const double x = integer ? static_cast<double>(std::strtoll(v.c_str(), &end, 10))
                           : std::strtod(v.c_str(), &end);
  if (v.empty() || end != v.c_str() + v.size() || errno == ERANGE || !std::isfinite(x) ||
      (strict ? !(x > least) : !(x >= least)))
    return "must be " + want + ", got '" + v + "'";
  return "";
}
const CLI::Validator kPositive([](std::string& v) { return bad_number(v, false, 0, true); },
                               "NUMBER>0");
const CLI::Validator kNonNegative([](std::string& v) { return bad_number(v, false, 0, false); },
                                  "NUMBER>=0");
const CLI::Validator kNonNegativeCount([](std::string& v) { return bad_number(v, true, 0, false); },
                                       "N>=0");
const CLI::Validator kCount([](std::string& v) { return bad_number(v, true, 1, false); }, "N>=1");

// A value of one of the solver's enums, checked by the vocabulary every interface shares
// (strata::parse): the same names and the same message as the C API, Python and the
// engine. The choices shown are the canonical names.
template <class E>
CLI::Validator choice() {
  std::string shown;
  for (const std::string& name : option_names<E>()) {
    E value{};
    parse(name, &value);
    if (to_string(value) == name) shown += (shown.empty() ? "" : ",") + name;
  }
  return CLI::Validator(
      [](std::string& v) {
        E value{};
        try {
          parse(v, &value);
        } catch (const Error& e) {
          return std::string(e.what());
        }
        return std::string();
      },
      "{" + shown + "}");
}

template <class E>
E value_of(const std::string& name) {
  E value{};
  parse(name, &value);
  return value;
}

void add_common(CLI::App* cmd, CommonArgs& a) {
  cmd->add_option("file", a.file, "matrix in Matrix Market format (.mtx or .mtx.gz)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--ordering", a.ordering, "fill-reducing ordering (default nd)")
      ->check(choice<OrderingMethod>());
  cmd->add_option("--max-block-size", a.max_block_size,
                  "most pivots per front (separator blocking); 0: by backend and type "
                  "(4096 for Cholesky on the GPU, else 1024)")
      ->check(kNonNegativeCount);
  cmd->add_option("--device-memory-limit", a.device_memory_limit,
                  "GPU memory budget [bytes] (default 0: 90% of the free device memory); "
                  "also the batch plan's");
  cmd->add_option("--threads", a.threads, "host threads (default: all)")->check(kCount);
  cmd->add_flag("--json", a.json, "print the report as JSON");
  cmd->add_flag("--reproducible", a.reproducible,
                "bitwise the same result for every --threads (large fronts on one BLAS thread)");
  cmd->add_option("--num-gpus", a.num_gpus, "GPUs for the CUDA backend (default 0: all visible)")
      ->check(kNonNegativeCount);
  cmd->add_option(
         "--subtrees-per-gpu", a.subtrees_per_gpu,
         fmt::format("subtrees per GPU in the tree split (default {})", Options{}.subtrees_per_gpu))
      ->check(kCount);
  cmd->add_option(
         "--balance-by-work", a.balance_by_work,
         "balance the top bisections by work with several GPUs (default " + a.balance_by_work + ")")
      ->check(CLI::IsMember({"on", "off"}));
  cmd->add_option("--work-stealing", a.work_stealing,
                  "idle GPUs take other GPUs' subtrees (default " + a.work_stealing + ")")
      ->check(CLI::IsMember({"on", "off"}));
  cmd->add_option("--split-top", a.split_top,
                  "split the top part above the subtrees into layers over the GPUs (default " +
                      a.split_top + ")")
      ->check(CLI::IsMember({"on", "off"}));
}

Options options_from(const CommonArgs& a) {
  Options o;
  o.ordering = value_of<OrderingMethod>(a.ordering);
  o.max_block_size = a.max_block_size;
  o.device_memory_limit = a.device_memory_limit;
  o.num_threads = a.threads;
  o.reproducible = a.reproducible;
  o.backend = value_of<Backend>(a.device);
  o.num_gpus = a.num_gpus;
  o.subtrees_per_gpu = a.subtrees_per_gpu;
  o.balance_by_work = a.balance_by_work == "on";
  o.work_stealing = a.work_stealing == "on";
  o.split_top = a.split_top == "on";
  return o;
}

void print_analysis(const AnalysisStats& s, double read_seconds) {
  fmt::print("n                     {}\n", s.n);
  fmt::print("nnz(A)                {}\n", s.nnz_a);
  fmt::print("nnz(L)                {} (in fronts: {})\n", s.nnz_l, s.nnz_l_fronts);
  fmt::print("factor flops          {:.4g}\n", s.factor_flops);
  fmt::print("fronts                {}\n", s.n_fronts);
  if (s.pairs + s.odd_cycles > 0)
    fmt::print("pivot groups          {} pairs, {} odd cycles (kept in one front each)\n", s.pairs,
               s.odd_cycles);
  fmt::print("largest front         {} rows, {} pivots (separator blocks of at most {})\n",
             s.largest_front_rows, s.largest_front_pivots, s.max_block_size);
  fmt::print("tree height           {} levels\n", s.tree_height);
  std::string per_level;
  for (std::size_t l = 0; l < s.fronts_per_level.size(); ++l) {
    if (l == 12 && s.fronts_per_level.size() > 16) {
      per_level += fmt::format("... ({} more)", s.fronts_per_level.size() - 12);
      break;
    }
    per_level += fmt::format("{} ", s.fronts_per_level[l]);
  }
  fmt::print("fronts per level      {}(deepest first)\n", per_level);
  fmt::print("peak working memory   {:.3f} MB (factor {:.3f} MB)\n", s.peak_working_bytes / 1e6,
             s.factor_bytes / 1e6);
  std::size_t tiled = 0, maxb = 0;
  for (const auto& b : s.batches) {
    tiled += b.tiled;
    maxb = std::max(maxb, b.bytes);
  }
  fmt::print(
      "batch plan            {} batches for {} levels, budget {}, largest batch {:.3f} MB, "
      "{} tiled fronts\n",
      s.batches.size(), s.tree_height,
      s.memory_budget ? fmt::format("{:.3f} MB", s.memory_budget / 1e6) : "unlimited", maxb / 1e6,
      tiled);
  if (s.workers > 1)
    fmt::print(
        "tree split            {} workers: {} subtrees, balance {:.3f} (makespan / mean); {} "
        "upper layers of {} parts with {:.1f}% of the flops; {:.1f}% of the flops in the top "
        "part; estimated speedup {:.2f} (flops only); {} bisections rebalanced by work ({:.3f} "
        "s)\n",
        s.workers, s.subtrees, s.subtree_balance, s.upper_layers, s.upper_parts,
        100 * s.upper_flops_fraction, 100 * s.top_flops_fraction, s.estimated_speedup,
        s.nd_rebisections, s.nd_balance_seconds);
  fmt::print(
      "time [s]              read {:.3f}  ordering {:.3f} (matching {:.3f})  symbolic {:.3f}  "
      "plan {:.3f}  device set-up {:.3f}  analysis total {:.3f}\n",
      read_seconds, s.ordering_seconds, s.matching_seconds, s.symbolic_seconds, s.plan_seconds,
      s.device_setup_seconds, s.total_seconds);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

// Runs f, naming `file` in the message of the bad input it reports (a structurally
// singular matrix found by the analysis, say), as the reader's own messages do.
template <class F>
void naming_file(const std::string& file, F&& f) {
  try {
    f();
  } catch (const ParseError&) {
    throw;
  } catch (const InvalidInput& e) {
    throw InvalidInput(file + ": " + e.what());
  }
}

int run_analyze(const CommonArgs& a) {
  auto t0 = std::chrono::steady_clock::now();
  MMMatrix mm = read_matrix_market(a.file, MMCheck::factorable);
  const double read_seconds = seconds_since(t0);
  Options o = options_from(a);
  o.type = mm.symmetry == MMSymmetry::symmetric ? MatrixType::automatic : MatrixType::general;
  Solver solver(o);
  naming_file(a.file, [&] { solver.analyze(mm.matrix); });
  const AnalysisStats& s = solver.stats().analysis;
  if (a.json) {
    json j = s;
    j["file"] = a.file;
    j["seconds"]["read"] = read_seconds;
    fmt::print("{}\n", j.dump(2));
  } else {
    fmt::print("strata analyze {}\n", a.file);
    print_analysis(s, read_seconds);
  }
  return 0;
}

struct SolveArgs {
  CommonArgs common;
  std::string rhs, out, type = "auto";
};

// Under `mpirun -n R` (R > 1) the ranks solve together (strata::DistributedSolver): rank
// 0 reads the matrix and the right-hand side, prints and writes; the others stay silent.
int run_solve(const SolveArgs& a, const Communicator& comm) {
  const bool root = comm.rank() == 0;
  auto t0 = std::chrono::steady_clock::now();
  MMMatrix mm;
  std::vector<double> b;
  index_t nrhs = 1, n = 0;
  double read_seconds = 0;
  Options o = options_from(a.common);
  std::exception_ptr failed;
  if (root) try {
      // before any work: a solution that cannot be written is found now, not after the solve
      if (!a.out.empty()) check_output_path(a.out);
      mm = read_matrix_market(a.common.file, MMCheck::factorable);
      read_seconds = seconds_since(t0);
      n = mm.matrix.n_rows;
      if (!a.rhs.empty()) {
        index_t rows = 0, cols = 0;
        b = read_dense_matrix_market(a.rhs, &rows, &cols);
        if (rows != n)
          throw InvalidInput(a.rhs + ": right-hand side has " + std::to_string(rows) +
                             " rows, the matrix has " + std::to_string(n));
        nrhs = cols;
      } else {  // b = A·1
        std::vector<double> ones(n, 1.0);
        b.resize(n);
        multiply(mm.matrix, ones.data(), b.data());
      }
      o.type = value_of<MatrixType>(a.type);
      if (o.type == MatrixType::automatic && mm.symmetry == MMSymmetry::general &&
          !is_numerically_symmetric(mm.matrix))
        o.type = MatrixType::general;
    } catch (...) {
      failed = std::current_exception();
    }
  if (!cli::all_ok(comm, !failed)) {
    if (failed) std::rethrow_exception(failed);
    return 1;  // rank 0 says why
  }
  DistributedSolver solver(comm, o);
  auto t1 = std::chrono::steady_clock::now();
  naming_file(a.common.file, [&] {
    solver.analyze(mm.matrix);
    solver.factorize(mm.matrix);
  });
  std::vector<double> x(b.size());
  solver.solve(root ? b.data() : nullptr, root ? x.data() : nullptr, nrhs);
  const double total = seconds_since(t1);
  if (!root) return 0;
  const Stats& st = solver.stats();
  const DistributedStats& ds = solver.distributed_stats();
  if (!a.out.empty()) write_dense_matrix_market(a.out, x.data(), n, nrhs);
  const FactorStats& f = st.factor;
  if (a.common.json) {
    json j = stats_document(st, true, true);
    j["file"] = a.common.file;
    j["seconds"]["read"] = read_seconds;
    if (ds.ranks > 1) j["distributed"] = ds;
    j["total_seconds"] = total;
    fmt::print("{}\n", j.dump(2));
  } else {
    fmt::print("strata solve {}\n", a.common.file);
    print_analysis(st.analysis, read_seconds);
    fmt::print(
        "factorization         {} on {}: {:.3f} s ({:.3f} s checking and scaling the input), "
        "{:.2f} GFLOP/s\n",
        to_string(f.type), to_string(f.backend), f.seconds, f.input_seconds, f.gflops);
    if (f.backend == Backend::cuda)
      fmt::print(
          "GPU                   {:.3f} s on the device, {:.2f} TFLOP/s, {} launch groups, {} "
          "tiled fronts; {:.1f} MB to the device, {:.1f} MB back; budget {:.1f} MB ({:.1f} MB "
          "held), {:.1f} MB page-locked on the host{}{}\n",
          f.device_seconds, f.gflops * 1e-3, f.device_batches, f.tiled_fronts,
          f.bytes_to_device * 1e-6, f.bytes_to_host * 1e-6, f.device_budget * 1e-6,
          f.device_working_bytes * 1e-6, f.host_pinned_bytes * 1e-6,
          f.contribution_blocks_on_host ? ", contribution blocks spilled to host" : "",
          f.factor_resident ? ", factor resident (solve on the GPU)" : "");
    if (f.backend == Backend::cuda) {
      const auto& ph = f.device_phases;
      fmt::print(
          "  GPU phases          assembly {:.3f} s, small fronts {:.3f} s, large fronts {:.3f} "
          "s, stores {:.3f} s, tiled fronts {:.3f} s (assembly {:.3f}, slabs {:.3f}, stores "
          "{:.3f}); host after each group {:.3f} s; device set-up {:.3f} s\n",
          ph.assembly, ph.small_fronts, ph.large_fronts, ph.store, ph.tiled_fronts,
          ph.tiled_assembly, ph.tiled_slabs, ph.tiled_store, ph.host, ph.setup);
    }
    for (const DeviceStats& d : f.devices)
      fmt::print(
          "  worker {} ({:<7})   busy {:.3f} s, idle {:.3f} s, {} subtrees ({} stolen), {} "
          "upper parts, {:.3f} MB transferred, {:.3g} flops, {} fronts split, {} strips "
          "of others' fronts\n",
          d.worker, d.device, d.busy_seconds, d.idle_seconds, d.subtrees_run, d.subtrees_stolen,
          d.upper_parts_run, d.bytes_transferred / 1e6, d.flops, d.fronts_split, d.strips_helped);
    if (ds.ranks > 1) {
      fmt::print(
          "ranks                 {} x {} workers; analysis broadcast {:.1f} MB in {:.3f} s\n",
          ds.ranks, ds.workers_per_rank, ds.analysis_bytes * 1e-6, ds.analysis_broadcast_seconds);
      for (const RankStats& r : ds.per_rank)
        fmt::print(
            "  rank {:<3}            {} subtrees, {:.3g} flops, factor {:.3f} s, sent {:.3f} MB, "
            "received {:.3f} MB ({:.3f} MB of values), holds {:.1f} MB of the factor; solve "
            "{:.3f} s\n",
            r.rank, r.subtrees, r.factor_flops, r.factor_seconds, r.factor_bytes_sent * 1e-6,
            r.factor_bytes_received * 1e-6, r.values_bytes * 1e-6, r.factor_bytes_held * 1e-6,
            r.solve_seconds);
    }
    if (f.inertia_valid) {
      fmt::print("pivots                {} perturbed, {} 2x2; inertia (+{}, -{}, 0:{})\n",
                 f.perturbed_pivots, f.two_by_two_pivots, f.inertia_positive, f.inertia_negative,
                 f.inertia_zero);
      fmt::print("log|det A|            {:.10g} (sign {})\n", f.log_abs_determinant,
                 f.determinant_sign);
    } else {
      fmt::print(
          "pivots                {} perturbed (A is numerically singular), {} 2x2; inertia and "
          "log|det A| not shown: they would be those of the perturbed matrix, not A's\n",
          f.perturbed_pivots, f.two_by_two_pivots);
    }
    const SolveStats& sv = st.solve;
    std::string verdict;
    if (sv.singular_consistent)
      verdict = " (A is numerically singular and b is in its range: x is one of its solutions)";
    else if (f.perturbed_pivots > 0 && sv.relative_residual > std::sqrt(DBL_EPSILON / 2))
      verdict = fmt::format(
          " (A is numerically singular and b is NOT in its range: ‖b−Ax‖/‖b‖ = {:.3e}; x "
          "solves only the perturbed matrix)",
          sv.relative_residual);
    else if (!sv.refinement_converged)
      verdict = fmt::format(" (ABOVE the tolerance {:.1e} and the rounding floor {:.3e}{})",
                            Options{}.refinement_tolerance, sv.backward_error_floor,
                            f.perturbed_pivots > 0 ? ": A is numerically singular and b may "
                                                     "not be in its range"
                                                   : "");
    fmt::print(
        "solve                 {:.3f} s, {} refinement steps, {} GMRES iterations, "
        "backward error {:.3e}{}\n",
        sv.seconds, sv.refinement_steps, sv.gmres_iterations, sv.backward_error, verdict);
    if (sv.condition_lower_bound > 1e12)
      fmt::print(
          "warning               A is {} to working precision: κ∞(A) ≥ ‖A‖‖x‖/‖b‖ = {:.3e}\n",
          sv.condition_lower_bound > 1e15 ? "singular" : "nearly singular",
          sv.condition_lower_bound);
    fmt::print("total                 {:.3f} s (analyze + factorize + solve)\n", total);
    if (!a.out.empty()) fmt::print("solution written to   {}\n", a.out);
  }
  return 0;
}

struct SimulateArgs {
  std::string model, generate, output = "out", dump_dir, write_model, device = "auto";
  std::string checkpoint_dir, resume, formulation = "auto", pivoting;
  index_t checkpoint_every = 0;
  double energy_tol = -1;
  std::vector<std::string> resume_conflicts;  // integration options given with --resume
  std::size_t device_memory_limit = 0;
  double t_end = 0, step = 0, output_interval = 0, newton_tol = 0, rtol = 1e-4, atol = 1e-6,
         max_step = 0;
  int order = 0, threads = 0, anderson_depth = -1;
  index_t dump_step = 1;
  bool vtk = false, full_newton = false, quiet = false, verbose = false, dense = false,
       no_condensation = false, variable_step = false, plot = false;
  std::string plot_coordinates;             // comma-separated coordinate names (implies plot)
  std::vector<std::string> solver_options;  // NAME=VALUE, set_option's vocabulary
};

// --solver-option NAME=VALUE: a strata option by its field name (set_option), checked
// when the command line is read.
void set_solver_option(Options& o, const std::string& assignment) {
  const std::size_t eq = assignment.find('=');
  if (eq == std::string::npos || eq == 0)
    throw InvalidInput("--solver-option takes NAME=VALUE, got '" + assignment + "'");
  set_option(o, std::string_view(assignment).substr(0, eq),
             std::string_view(assignment).substr(eq + 1));
}
const CLI::Validator kSolverOption(
    [](std::string& v) {
      Options scratch;
      try {
        set_solver_option(scratch, v);
      } catch (const Error& e) {
        return std::string(e.what());
      }
      return std::string();
    },
    "NAME=VALUE");

// The default model: a tracked vehicle of a few hundred links (runs in well under a
// minute on two cores).
constexpr const char* kDefaultModel = "tracked:100";

// SIGINT/SIGTERM during a simulation: remembered here, read by the simulation loop between
// steps (it stops, keeps its partial results, writes a checkpoint). SA_RESETHAND: a second
// signal kills the process at once.
volatile std::sig_atomic_t g_signal = 0;
extern "C" void on_signal(int sig) { g_signal = sig; }
void catch_interrupts() {
  struct sigaction sa {};
  sa.sa_handler = on_signal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_RESETHAND;
  sigaction(SIGINT, &sa, nullptr);
  sigaction(SIGTERM, &sa, nullptr);
}

int run_simulate_checked(const SimulateArgs& a, bool& started);

// A run that fails before its first step marks its output folder (status.json "failed"
// with the reason, an earlier run's results removed) before the error is reported; a
// folder that cannot be marked leaves the original error to be reported. (Once the
// simulation has started, strata::mbd::simulate keeps the folder's status itself.)
int run_simulate(const SimulateArgs& a) {
  bool started = false;
  try {
    return run_simulate_checked(a, started);
  } catch (const Error& e) {
    if (!started) try {
        strata::mbd::mark_failed_before_start(a.output, e.what());
      } catch (const std::exception&) {
      }
    throw;
  }
}

// An output folder exists (or is made) and files can be written there, checked before
// the model is read and its initial conditions computed (empty: none).
void check_output_folder(const std::string& dir) {
  if (dir.empty()) return;
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw Error("cannot write to the output folder " + dir + ": " + ec.message());
  check_output_path(dir + "/status.json");
}

int run_simulate_checked(const SimulateArgs& a, bool& started) {
  using namespace strata::mbd;
  auto t0 = std::chrono::steady_clock::now();
  check_output_folder(a.output);
  check_output_folder(a.dump_dir);
  if (a.checkpoint_every > 0)
    check_output_folder(a.checkpoint_dir.empty() ? a.output + "/checkpoint" : a.checkpoint_dir);
  if (!a.write_model.empty()) check_output_path(a.write_model);
  if (!a.model.empty() && !a.generate.empty())
    throw InvalidInput("give either a model file or --generate, not both");
  Model model;
  std::string source;
  nlohmann::json doc, checkpoint;
  std::string model_name;
  if (!a.resume.empty()) {
    // the model and the integration options come from the checkpoint
    if (!a.model.empty() || !a.generate.empty())
      throw InvalidInput(
          "--resume takes the model from the checkpoint: give no model file or "
          "--generate with it");
    if (!a.resume_conflicts.empty())
      throw InvalidInput("--resume continues with the options of the checkpointed run: " +
                         a.resume_conflicts.front() + " cannot be changed");
    checkpoint = read_checkpoint(a.resume);
    const nlohmann::json& meta = checkpoint.at("meta");
    if (!meta.contains("model"))
      throw InvalidInput(a.resume + ": the checkpoint holds no model document");
    doc = meta.at("model");
    model_name = meta.value("model_name", std::string("model"));
    model = build_model(doc, model_name);
    source = fmt::format("{} (resumed from {} at step {}, t = {:.9g} s)",
                         meta.value("source", model_name), a.resume,
                         checkpoint.at("integrator").at("step").get<index_t>(),
                         checkpoint.at("integrator").at("t").get<double>());
  } else if (!a.model.empty()) {
    doc = load_model_document(a.model);
    model_name = model_file_name(a.model);
    model = build_model(doc, model_name);
    source = a.model;
  } else {
    const std::string spec = a.generate.empty() ? kDefaultModel : a.generate;
    doc = generate(spec);
    if (!a.write_model.empty()) write_file_atomically(a.write_model, doc.dump(1) + "\n");
    model_name = spec;
    model = build_model(doc, spec);
    source = "generated " + spec + (a.generate.empty() ? " (default model)" : "");
  }
  const double read_seconds = seconds_since(t0);
  SimulationOptions o;
  if (!a.resume.empty()) {
    // the integration options of the checkpointed run; --t-end may extend it, and the GPU
    // budget may change (a restart on another device)
    IntegratorOptions& io = o.integrator;
    io = checkpoint_integrator_options(checkpoint);
    if (a.t_end > 0) io.t_end = a.t_end;
    const double t_ck = checkpoint.at("integrator").at("t").get<double>();
    if (!(io.t_end > t_ck))
      throw InvalidInput(fmt::format("--t-end {:g} s is not after the checkpoint's time {:.9g} s",
                                     io.t_end, t_ck));
    if (a.device_memory_limit > 0) io.solver.device_memory_limit = a.device_memory_limit;
    io.dump_dir = a.dump_dir;
    io.verbose = a.verbose;
    io.dump_step = a.dump_dir.empty() ? -1 : a.dump_step;
    o.output_interval = checkpoint.at("simulation").at("output_interval").get<double>();
    o.vtk = checkpoint.at("simulation").at("vtk").get<bool>();
    o.output_dir = a.output;
    o.resume = &checkpoint;
  } else {
    RunSettings rs;
    rs.t_end = a.t_end;
    rs.step = a.step;
    rs.order = a.order;
    rs.solver.backend = value_of<Backend>(a.device);
    rs.solver.device_memory_limit = a.device_memory_limit;
    if (!a.pivoting.empty()) rs.solver.pivoting = value_of<Pivoting>(a.pivoting);
    rs.solver.num_threads = a.threads;
    for (const std::string& s : a.solver_options) set_solver_option(rs.solver, s);
    rs.full_newton = a.full_newton;
    rs.anderson_depth = a.anderson_depth;
    rs.newton_tol = a.newton_tol;
    rs.variable_step = a.variable_step;
    rs.rtol = a.rtol;
    rs.atol = a.atol;
    rs.max_step = a.max_step;
    rs.dense_reference = a.dense;
    rs.condensation = !a.no_condensation;
    rs.formulation = a.formulation == "partitioned"  ? FormulationChoice::partitioned
                     : a.formulation == "stabilized" ? FormulationChoice::stabilized
                                                     : FormulationChoice::automatic;
    rs.energy_tolerance = a.energy_tol;
    rs.verbose = a.verbose;
    rs.output_dir = a.output;
    rs.output_interval = a.output_interval;
    rs.vtk = a.vtk;
    rs.dump_dir = a.dump_dir;
    rs.dump_step = a.dump_step;
    o = simulation_options(model, rs);
  }
  const IntegratorOptions& io = o.integrator;
  o.progress = !a.quiet && isatty(fileno(stdout));
  o.progress_stream = stdout;
  o.checkpoint_every = a.checkpoint_every;
  o.checkpoint_dir = a.checkpoint_dir.empty() ? a.output + "/checkpoint" : a.checkpoint_dir;
  o.checkpoint_meta = {{"model", doc}, {"model_name", model_name}, {"source", source}};
  if (!a.resume.empty())
    o.checkpoint_meta["source"] = checkpoint.at("meta").value("source", source);
  o.interrupt = &g_signal;
  catch_interrupts();
  fmt::print("strata simulate {}\n", source);
  fmt::print("integrator            BDF{} with {} {:g} s to t = {:g} s, {} Newton\n", io.order,
             io.variable_step
                 ? fmt::format("variable step (rtol {:g}, atol {:g}) from", io.rtol, io.atol)
                 : std::string("step"),
             io.step, io.t_end, io.modified_newton ? "modified" : "full");
  std::fflush(stdout);
  started = true;  // simulate() keeps the output folder's status from here on
  const SimulationResult r = simulate(model, o);
  fmt::print("{}", summary(model, r));
  fmt::print("model read/build      {:.3f} s\n", read_seconds);
  if (!o.output_dir.empty())
    fmt::print(
        "output                {}/ (positions, velocities, accelerations, reactions, "
        "steps .csv{}{})\n",
        o.output_dir, o.vtk ? ", vtk/series.pvd" : "",
        r.complete ? "" : "; *.partial.csv, marked partial in status.json");
  if (io.dump_step > 0)
    fmt::print("Newton matrix         step {} written to {}/jacobian_step{}.mtx (+ rhs)\n",
               io.dump_step, io.dump_dir, io.dump_step);
  if (r.checkpoint_step > 0 && o.checkpoint_every > 0)
    fmt::print("checkpoint            step {} in {}/ (continue with --resume {})\n",
               r.checkpoint_step, o.checkpoint_dir, o.checkpoint_dir);
  // plots of what was written, partial results included; a plot that cannot be drawn
  // does not hide how the run itself ended
  int plot_rc = 0;
  if ((a.plot || !a.plot_coordinates.empty()) && !o.output_dir.empty()) try {
      plot_rc = cli::run_plot(o.output_dir, a.plot_coordinates, source);
    } catch (const strata::Error& e) {
      std::fprintf(stderr, "strata: error: %s\n", e.what());
      plot_rc = 1;
    }
  if (r.state == "interrupted") {
    std::fprintf(stderr, "strata: %s; partial results kept\n", r.message.c_str());
    return 128 + static_cast<int>(g_signal);
  }
  if (!r.complete) {
    std::fprintf(stderr, "strata: error: the simulation stopped at t = %.9g s: %s\n", r.t_reached,
                 r.message.c_str());
    return 1;
  }
  return plot_rc;
}

}  // namespace

int main(int argc, char** argv) {
  strata::app::use_fitting_blas_kernels(argv);  // may execute the program again, at once
  strata::app::report_fatal_signals();          // an internal crash says where, on stderr
  // The analyses and factorizations allocate and free large temporaries (graphs, copies of
  // the matrix, fronts) many times over; glibc serves every block above its mmap threshold
  // with a mapping of its own and unmaps it when freed, so the kernel faults in and zeroes
  // the same amount again at each allocation. This program keeps them in the heap, freed
  // memory kept for the next one (glibc mallopt: M_MMAP_MAX 0, M_TRIM_THRESHOLD), as a
  // solver process would; the library leaves its caller's allocator as it is.
  mallopt(M_MMAP_MAX, 0);
  mallopt(M_TRIM_THRESHOLD, INT_MAX);
  CLI::App app{"strata: a multifrontal sparse direct solver for CPU and GPU"};
  app.require_subcommand(1);
  app.set_version_flag(
      "--version", fmt::format("strata {} ({}; host code for {})", strata_version(),
                               strata::app::blas_description(), strata::detail::build_cpu_arch()));
  // every --help ends with the exit statuses (README.md, "Exit status")
  const std::string exit_codes =
      "Exit status: 0 success; 1 solver or input error (\"strata: error: ...\"); 2 usage "
      "error (bad option or argument, missing file); 128+signal (130 SIGINT, 143 SIGTERM) "
      "when a simulation was interrupted (partial results and a checkpoint kept).";
  app.footer(exit_codes);
  CommonArgs analyze_args;
  auto* analyze =
      app.add_subcommand("analyze", "ordering, assembly tree, level schedule, memory plan");
  add_common(analyze, analyze_args);
  SolveArgs solve_args;
  auto* solve = app.add_subcommand("solve", "analyze, factorize and solve A x = b");
  add_common(solve, solve_args.common);
  solve->add_option("--rhs", solve_args.rhs, "right-hand side(s) in Matrix Market (default: A·1)")
      ->check(CLI::ExistingFile);
  solve
      ->add_option(
          "--type", solve_args.type,
          "factorization type (default auto: Cholesky when symmetric and it succeeds, else "
          "LDLᵀ when symmetric, else LU)")
      ->check(choice<MatrixType>());
  solve->add_option("--out", solve_args.out,
                    "write the solution here (Matrix Market array; default: not written)");
  solve
      ->add_option("--device", solve_args.common.device,
                   "where the factorization and solve run (default auto: the GPU when the "
                   "build and the machine have one; --solver-option gpu_min_flops=F keeps "
                   "factors of fewer flops on the host)")
      ->check(choice<Backend>());
  SimulateArgs sim;
  auto* simulate = app.add_subcommand(
      "simulate", "implicit multibody dynamics (BDF + Newton, every step solved by strata)");
  simulate
      ->add_option("model", sim.model,
                   "model file (JSON, docs/model-format.md; default: the tracked vehicle "
                   "tracked:100)")
      ->check(CLI::ExistingFile);
  simulate->add_option("--generate", sim.generate,
                       "generated model: andrews, tracked:N, lattice:N, flexible:NXxNYxNZ, "
                       "chain:N, chain2d:N");
  simulate->add_option("--t-end", sim.t_end, "end time [s] (default: the model's, else 1 s)")
      ->check(kPositive);
  simulate->add_option("--step", sim.step, "step size [s] (default: the model's, else 1e-3 s)")
      ->check(kPositive);
  simulate->add_option("--order", sim.order, "BDF order 1..5 (default: the model's, else 2)")
      ->check(CLI::Range(1, 5));
  simulate
      ->add_option("--device", sim.device,
                   "where strata factorizes (default auto: the GPU when present; "
                   "--solver-option gpu_min_flops=F keeps a Newton matrix whose factor needs "
                   "fewer flops on the host)")
      ->check(choice<Backend>());
  simulate->add_option("--device-memory-limit", sim.device_memory_limit,
                       "GPU memory budget [bytes] (default 0: 90% of the free device memory)");
  simulate->add_option("--output", sim.output, "output folder (default: out)");
  simulate->add_flag("--vtk", sim.vtk, "also write a ParaView series (OUTPUT/vtk/series.pvd)");
  simulate
      ->add_option("--output-interval", sim.output_interval,
                   "time between rows of the large CSV files and VTK frames [s] "
                   "(default: the model's, else every step)")
      ->check(kNonNegative);
  simulate->add_option("--dump-matrix", sim.dump_dir,
                       "write the Newton Jacobian and right-hand side of one step here (Matrix "
                       "Market)");
  simulate->add_option("--dump-step", sim.dump_step, "the step to dump (default 1)")->check(kCount);
  simulate->add_option("--write-model", sim.write_model, "write the generated model (JSON)");
  simulate->add_flag("--full-newton", sim.full_newton,
                     "refactorize at every Newton iteration (default: modified Newton)");
  simulate
      ->add_option("--anderson-depth", sim.anderson_depth,
                   "modified Newton: Anderson acceleration over this many past updates while "
                   "a factor is reused (default 3; 0: off)")
      ->check(CLI::Range(0, 10));
  simulate
      ->add_option("--newton-tol", sim.newton_tol,
                   "relative Newton tolerance (default: the model's, else 1e-6)")
      ->check(kPositive);
  simulate
      ->add_option("--pivoting", sim.pivoting,
                   "pivots the analysis's order cannot take: fixed (static pivots), delayed "
                   "(delayed pivoting, on the host), corrected (static pivots shifted and "
                   "corrected in the solve, where the factor lives), automatic (default: "
                   "delayed on the CPU; on a GPU the analysis's order until a "
                   "factorization needs static pivots, then delayed until the next "
                   "analysis)")
      ->check(choice<Pivoting>());
  simulate
      ->add_option("--solver-option", sim.solver_options,
                   "any strata option for the Newton matrices by its name, e.g. "
                   "ordering=amd or pivot_threshold=0.1 (repeatable; the names are those of "
                   "strata::Options, docs/cli.md)")
      ->check(kSolverOption);
  simulate
      ->add_option("--formulation", sim.formulation,
                   "auto: coordinate partitioning, stabilized from where no partition is well "
                   "conditioned (singular configurations); or always one of them")
      ->check(CLI::IsMember({"auto", "partitioned", "stabilized"}));
  simulate
      ->add_option("--energy-tol", sim.energy_tol,
                   "conservative models: energy drift allowed, relative to the largest "
                   "kinetic energy (default 1e-3; 0: not monitored)")
      ->check(kNonNegative);
  simulate
      ->add_option("--threads", sim.threads,
                   "host threads for strata and the assembly (default: all)")
      ->check(kCount);
  simulate->add_flag("--quiet", sim.quiet, "no progress bar");
  simulate->add_flag("--verbose", sim.verbose, "print every Newton iteration (stderr)");
  simulate->add_flag("--variable-step", sim.variable_step,
                     "variable step size and order (up to --order) with local error control "
                     "(--step is the first step)");
  simulate->add_option("--rtol", sim.rtol, "relative local error tolerance [1] (default 1e-4)")
      ->check(kPositive);
  simulate
      ->add_option("--atol", sim.atol,
                   "absolute local error tolerance [m, rad: the coordinates' units] "
                   "(default 1e-6)")
      ->check(kPositive);
  simulate->add_option("--max-step", sim.max_step, "largest variable step [s] (default t_end/10)")
      ->check(kPositive);
  simulate->add_flag("--dense-reference", sim.dense,
                     "solve with dense LAPACK LU instead of strata (diagnosis; small models)");
  simulate->add_flag("--no-condensation", sim.no_condensation,
                     "factor the full Newton matrix: do not eliminate its BDF relations' rows "
                     "first (docs/formulation.md §5)");
  simulate
      ->add_option("--checkpoint-every", sim.checkpoint_every,
                   "write a restart point every N accepted steps (and when interrupted; "
                   "default: none)")
      ->check(kCount);
  simulate->add_option("--checkpoint-dir", sim.checkpoint_dir,
                       "folder of the restart point (default: OUTPUT/checkpoint)");
  simulate
      ->add_option("--resume", sim.resume,
                   "continue the run checkpointed in this folder (model and options from "
                   "the checkpoint; --t-end may extend it)")
      ->check(CLI::ExistingDirectory);
  simulate->add_flag("--plot", sim.plot,
                     "draw OUTPUT/summary.png: energy [J], constraint violation, step size [s], "
                     "Newton iterations and time per step [ms] against time [s] (Python 3 with "
                     "matplotlib)");
  simulate->add_option("--plot-coordinates", sim.plot_coordinates,
                       "also draw OUTPUT/coordinates.png of these coordinates against time, "
                       "e.g. chassis.x,chassis.z (m; .phi in rad; .e0-.e3 Euler parameters); "
                       "implies --plot");
  std::string plot_dir, plot_coordinates, plot_title;
  auto* plot = app.add_subcommand(
      "plot", "plots of an output folder of strata simulate (as simulate --plot)");
  plot->add_option("dir", plot_dir, "output folder of strata simulate (steps.csv, positions.csv)")
      ->required()
      ->check(CLI::ExistingDirectory);
  plot->add_option("--coordinates", plot_coordinates,
                   "also draw DIR/coordinates.png of these coordinates, e.g. chassis.x,crank.phi "
                   "(m; .phi in rad; .e0-.e3 Euler parameters; default: none)");
  plot->add_option("--title", plot_title, "title of the figures (default: the folder's name)");
  for (CLI::App* sub : {analyze, solve, simulate, plot}) sub->footer(exit_codes);
  try {
    app.parse(argc, argv);
  } catch (const CLI::Success& e) {  // --help, --version
    return app.exit(e);
  } catch (const CLI::ParseError& e) {
    std::fprintf(
        stderr, "strata: error: %s\n(strata --help, or strata COMMAND --help, lists the options)\n",
        e.what());
    return 2;
  }
  // mpirun -n R: `solve` runs on every rank; the other commands on rank 0 alone
  std::optional<Communicator> comm(cli::launch(&argc, &argv));
  const int rank = comm->rank();
  struct Finish {
    std::optional<Communicator>& c;
    ~Finish() {
      c.reset();
      cli::finish();
    }
  } finish{comm};
  if (rank != 0 && !*solve) return 0;
  // the options --resume refuses: a resumed run integrates as its checkpoint says
  static const char* const kFromCheckpoint[] = {
      "--step",        "--order",          "--device",     "--output-interval", "--vtk",
      "--full-newton", "--anderson-depth", "--newton-tol", "--threads",         "--variable-step",
      "--rtol",        "--atol",           "--max-step",   "--dense-reference", "--no-condensation",
      "--write-model", "--formulation",    "--energy-tol", "--pivoting",        "--solver-option"};
  for (const char* opt : kFromCheckpoint)
    if (simulate->count(opt) > 0) sim.resume_conflicts.push_back(opt);
  try {
    if (*analyze) return run_analyze(analyze_args);
    if (*solve) return run_solve(solve_args, *comm);
    if (*simulate) return run_simulate(sim);
    if (*plot) return cli::run_plot(plot_dir, plot_coordinates, plot_title);
  } catch (const strata::InternalError& e) {
    std::fprintf(stderr, "strata: %s (a bug in strata: please report it with the input)\n",
                 e.what());
    return 1;
  } catch (const strata::Error& e) {
    if (rank == 0) std::fprintf(stderr, "strata: error: %s\n", e.what());
    return 1;
  } catch (const std::bad_alloc&) {
    std::fprintf(stderr,
                 "strata: error: out of memory (the size of the failed allocation is "
                 "not known)\n");
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "strata: error: internal error: %s\n", e.what());
    return 1;
  }
  return 2;
}
