// strata — the command line.
//
//   strata analyze FILE [--ordering nd|metis|amd|natural] [--max-block-size N]
//                       [--device-memory-limit BYTES] [--json]
//   strata solve A.mtx [--rhs b.mtx] [--type spd|symmetric_indefinite|general|auto]
//                      [--ordering ...] [--max-block-size N] [--out x.mtx] [--json]
//
// Exit status: 0 on success, 1 on a solver error (the message names the problem),
// 2 on a usage error.
#include <fmt/core.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <nlohmann/json.hpp>
#include <string>

#include "strata/strata.hpp"

namespace {

using json = nlohmann::json;
using namespace strata;

const std::map<std::string, OrderingMethod> kOrderings = {{"nd", OrderingMethod::nested_dissection},
                                                          {"metis", OrderingMethod::metis},
                                                          {"amd", OrderingMethod::amd},
                                                          {"natural", OrderingMethod::natural}};
const std::map<std::string, MatrixType> kTypes = {
    {"auto", MatrixType::automatic},
    {"spd", MatrixType::spd},
    {"symmetric_indefinite", MatrixType::symmetric_indefinite},
    {"general", MatrixType::general}};

struct CommonArgs {
  std::string file;
  std::string ordering = "nd";
  index_t max_block_size = Options{}.max_block_size;
  std::size_t device_memory_limit = 0;
  int threads = 0;
  bool json = false;
};

void add_common(CLI::App* cmd, CommonArgs& a) {
  cmd->add_option("file", a.file, "matrix in Matrix Market format (.mtx or .mtx.gz)")
      ->required()
      ->check(CLI::ExistingFile);
  cmd->add_option("--ordering", a.ordering, "fill-reducing ordering")
      ->check(CLI::IsMember({"nd", "metis", "amd", "natural"}));
  cmd->add_option("--max-block-size", a.max_block_size,
                  "most pivots per front (separator blocking)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("--device-memory-limit", a.device_memory_limit,
                  "memory budget of the batch plan in bytes (0: unlimited)");
  cmd->add_option("--threads", a.threads, "host threads (0: all)");
  cmd->add_flag("--json", a.json, "print the report as JSON");
}

Options options_from(const CommonArgs& a) {
  Options o;
  o.ordering = kOrderings.at(a.ordering);
  o.max_block_size = a.max_block_size;
  o.device_memory_limit = a.device_memory_limit;
  o.num_threads = a.threads;
  return o;
}

json analysis_json(const AnalysisStats& s) {
  json batches = json::array();
  for (const auto& b : s.batches)
    batches.push_back(
        {{"level", b.level}, {"fronts", b.end - b.begin}, {"bytes", b.bytes}, {"tiled", b.tiled}});
  return {{"n", s.n},
          {"nnz_a", s.nnz_a},
          {"nnz_l", s.nnz_l},
          {"nnz_l_fronts", s.nnz_l_fronts},
          {"factor_flops", s.factor_flops},
          {"fronts", s.n_fronts},
          {"largest_front_rows", s.largest_front_rows},
          {"largest_front_pivots", s.largest_front_pivots},
          {"tree_height", s.tree_height},
          {"fronts_per_level", s.fronts_per_level},
          {"peak_working_bytes", s.peak_working_bytes},
          {"factor_bytes", s.factor_bytes},
          {"memory_budget", s.memory_budget},
          {"batches", batches},
          {"type", to_string(s.type)},
          {"pairs", s.pairs},
          {"odd_cycles", s.odd_cycles},
          {"ordering", to_string(s.ordering)},
          {"seconds",
           {{"ordering", s.ordering_seconds},
            {"symbolic", s.symbolic_seconds},
            {"plan", s.plan_seconds},
            {"total", s.total_seconds}}}};
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
  fmt::print("largest front         {} rows, {} pivots\n", s.largest_front_rows,
             s.largest_front_pivots);
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
  fmt::print(
      "time [s]              read {:.3f}  ordering {:.3f}  symbolic {:.3f}  plan {:.3f}  "
      "analysis total {:.3f}\n",
      read_seconds, s.ordering_seconds, s.symbolic_seconds, s.plan_seconds, s.total_seconds);
}

double seconds_since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

int run_analyze(const CommonArgs& a) {
  auto t0 = std::chrono::steady_clock::now();
  MMMatrix mm = read_matrix_market(a.file);
  const double read_seconds = seconds_since(t0);
  Options o = options_from(a);
  o.type = mm.symmetry == MMSymmetry::symmetric ? MatrixType::automatic : MatrixType::general;
  Solver solver(o);
  solver.analyze(mm.matrix);
  const AnalysisStats& s = solver.stats().analysis;
  if (a.json) {
    json j = analysis_json(s);
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

int run_solve(const SolveArgs& a) {
  auto t0 = std::chrono::steady_clock::now();
  MMMatrix mm = read_matrix_market(a.common.file);
  const double read_seconds = seconds_since(t0);
  const index_t n = mm.matrix.n_rows;
  if (mm.matrix.n_rows != mm.matrix.n_cols)
    throw InvalidInput(a.common.file + ": matrix is " + std::to_string(mm.matrix.n_rows) + "x" +
                       std::to_string(mm.matrix.n_cols) + ", not square");
  std::vector<double> b;
  index_t nrhs = 1;
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
  Options o = options_from(a.common);
  o.type = kTypes.at(a.type);
  if (o.type == MatrixType::automatic && mm.symmetry == MMSymmetry::general &&
      !is_numerically_symmetric(mm.matrix))
    o.type = MatrixType::general;
  Solver solver(o);
  auto t1 = std::chrono::steady_clock::now();
  solver.analyze(mm.matrix);
  solver.factorize(mm.matrix);
  std::vector<double> x(b.size());
  solver.solve(b.data(), x.data(), nrhs);
  const double total = seconds_since(t1);
  const Stats& st = solver.stats();
  if (!a.out.empty()) write_dense_matrix_market(a.out, x.data(), n, nrhs);
  const FactorStats& f = st.factor;
  if (a.common.json) {
    json j = analysis_json(st.analysis);
    j["file"] = a.common.file;
    j["seconds"]["read"] = read_seconds;
    j["factor"] = {{"type", to_string(f.type)},
                   {"backend", f.backend},
                   {"seconds", f.seconds},
                   {"gflops", f.gflops},
                   {"perturbed_pivots", f.perturbed_pivots},
                   {"two_by_two_pivots", f.two_by_two_pivots},
                   {"inertia", {f.inertia_positive, f.inertia_negative, f.inertia_zero}},
                   {"log_abs_determinant", f.log_abs_determinant},
                   {"determinant_sign", f.determinant_sign}};
    j["solve"] = {{"seconds", st.solve.seconds},
                  {"refinement_steps", st.solve.refinement_steps},
                  {"gmres_iterations", st.solve.gmres_iterations},
                  {"backward_error", st.solve.backward_error},
                  {"converged", st.solve.refinement_converged}};
    j["total_seconds"] = total;
    fmt::print("{}\n", j.dump(2));
  } else {
    fmt::print("strata solve {}\n", a.common.file);
    print_analysis(st.analysis, read_seconds);
    fmt::print("factorization         {} on {}: {:.3f} s, {:.2f} GFLOP/s\n", to_string(f.type),
               f.backend, f.seconds, f.gflops);
    fmt::print("pivots                {} perturbed, {} 2x2; inertia (+{}, -{}, 0:{})\n",
               f.perturbed_pivots, f.two_by_two_pivots, f.inertia_positive, f.inertia_negative,
               f.inertia_zero);
    fmt::print("log|det A|            {:.10g} (sign {})\n", f.log_abs_determinant,
               f.determinant_sign);
    fmt::print(
        "solve                 {:.3f} s, {} refinement steps, {} GMRES iterations, "
        "backward error {:.3e}{}\n",
        st.solve.seconds, st.solve.refinement_steps, st.solve.gmres_iterations,
        st.solve.backward_error, st.solve.refinement_converged ? "" : " (above tolerance)");
    fmt::print("total                 {:.3f} s (analyze + factorize + solve)\n", total);
    if (!a.out.empty()) fmt::print("solution written to   {}\n", a.out);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app{"strata: a multifrontal sparse direct solver for CPU and GPU"};
  app.require_subcommand(1);
  CommonArgs analyze_args;
  auto* analyze =
      app.add_subcommand("analyze", "ordering, assembly tree, level schedule, memory plan");
  add_common(analyze, analyze_args);
  SolveArgs solve_args;
  auto* solve = app.add_subcommand("solve", "analyze, factorize and solve A x = b");
  add_common(solve, solve_args.common);
  solve->add_option("--rhs", solve_args.rhs, "right-hand side(s) in Matrix Market (default: A*1)")
      ->check(CLI::ExistingFile);
  solve->add_option("--type", solve_args.type, "factorization type")
      ->check(CLI::IsMember({"auto", "spd", "symmetric_indefinite", "general"}));
  solve->add_option("--out", solve_args.out, "write the solution here (Matrix Market array)");
  CLI11_PARSE(app, argc, argv);
  try {
    if (*analyze) return run_analyze(analyze_args);
    if (*solve) return run_solve(solve_args);
  } catch (const strata::Error& e) {
    std::fprintf(stderr, "strata: error: %s\n", e.what());
    return 1;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "strata: unexpected error: %s\n", e.what());
    return 1;
  }
  return 2;
}
