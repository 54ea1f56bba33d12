// strata benchmark — the distributed factorization over MPI ranks (docs/distributed.md):
// one configuration per run, R ranks (mpirun -n R) × G workers per rank (GPUs with
// --backend cuda, CPU executors with --backend cpu), on generated or shared problems.
// Rank 0 builds the problem; every rank takes part. Per problem: the analysis, then
// one factorization (it sets the executors up: reported apart), then the median of
// --repeat refactorizations (as bench_multigpu, bench_gpu and bench_cudss report), the
// first solve after them (it sets the solve's plans and buffers up: reported apart) and the
// median of --repeat solves after it, and each rank's figures of the last factorization:
// its subtrees, flops, time,
// bytes sent and received (scaled values, contribution blocks, pivot statistics). The
// values are scattered (each rank is sent what its subtrees assemble): the row gives their
// bytes and, beside them, what the broadcast of the whole array would have moved.
// Writes bench/results/distributed-<date>.json (or --results-dir) on rank 0.
//
//   mpirun -n R bench_distributed [--problems lap3d-80,elast3d-40] [--backend cuda|cpu]
//          [--gpus-per-rank G] [--repeat 3] [--tag T] [--results-dir DIR]
#include <mpi.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <nlohmann/json.hpp>
#include <thread>

#include "base/timer.hpp"
#include "bench_common.hpp"
#include "blas_kernels.hpp"
#include "core/stats_json.hpp"
#include "crash_report.hpp"
#include "distributed/distributed_internal.hpp"
#include "strata/distributed.hpp"
#include "strata/mpi.hpp"
#include "strata/strata.hpp"

using namespace strata;
using json = nlohmann::json;

namespace {

int run(int argc, char** argv) {
  CLI::App app{"strata distributed factorization benchmark (run under mpirun)"};
  std::vector<std::string> problems = {"lap3d-30"};
  std::string backend = "cpu", tag, results_dir;
  int per_rank = 1, repeat = 3, threads = 0;
  app.add_option("--problems", problems, "problems (shared matrix names, lap3d-N, elast3d-N)")
      ->delimiter(',');
  app.add_option("--backend", backend, "cuda: GPUs; cpu: CPU executors standing in for GPUs")
      ->check(CLI::IsMember({"cpu", "cuda"}));
  app.add_option("--gpus-per-rank", per_rank, "workers (GPUs) per rank")
      ->check(CLI::PositiveNumber);
  app.add_option("--repeat", repeat, "factorizations per problem (median reported)")
      ->check(CLI::PositiveNumber);
  app.add_option("--threads", threads,
                 "host threads per rank (Options::num_threads; default: 1 with --backend cpu, "
                 "where they are each CPU executor's, else the machine's hardware threads "
                 "shared by the ranks on it)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--tag", tag, "label stored in the results and the file name")
      ->check(bench::check_tag);
  app.add_option("--results-dir", results_dir, "folder for the results file");
  CLI11_PARSE(app, argc, argv);

  Communicator comm = mpi_communicator(MPI_COMM_WORLD);
  const int rank = comm.rank(), ranks = comm.size();
  if (threads == 0) {
    // the ranks sharing this machine (MPI-3 shared-memory split) share its threads
    MPI_Comm node;
    MPI_Comm_split_type(MPI_COMM_WORLD, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node);
    int local = 1;
    MPI_Comm_size(node, &local);
    MPI_Comm_free(&node);
    const int hw = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
    threads = backend == "cpu" ? 1 : std::max(1, hw / std::max(1, local));
  }
  json out = bench::run_metadata(argc, argv);
  out["benchmark"] = "distributed";
  out["backend"] = backend;
  out["tag"] = tag;
  out["ranks"] = ranks;
  out["gpus_per_rank"] = per_rank;
  out["threads_per_rank"] = threads;
  out["rows"] = json::array();
  for (const std::string& name : problems) {
    bench::Problem p;
    std::vector<double> b;
    if (rank == 0) {
      p = bench::load_problem(name);
      b.resize(p.a.n_rows);
      std::vector<double> ones(p.a.n_rows, 1.0);
      multiply(p.a, ones.data(), b.data());
    }
    int symmetric = p.symmetric ? 1 : 0;
    MPI_Bcast(&symmetric, 1, MPI_INT, 0, MPI_COMM_WORLD);
    Options o;
    o.type = symmetric ? MatrixType::spd : MatrixType::general;
    o.num_threads = threads;
    if (backend == "cuda") {
      o.backend = Backend::cuda;
      o.num_gpus = per_rank;
    }
    DistributedSolver solver(comm, o);
    if (backend == "cpu") detail::DistributedAccess::use_host_workers(solver, per_rank);
    Timer t;
    solver.analyze(p.a);
    const double analysis_seconds = t.seconds();
    std::vector<double> times;
    double first_factor = 0;
    t.reset();
    solver.factorize(p.a);
    first_factor = t.seconds();
    for (int k = 0; k < repeat; ++k) {
      t.reset();
      solver.refactorize(p.a);
      times.push_back(t.seconds());
    }
    std::vector<double> x = solver.solve(b);
    const double first_solve = solver.stats().solve.seconds;  // rank 0's figures
    std::vector<double> solves;
    for (int k = 0; k < repeat; ++k) {
      x = solver.solve(b);
      solves.push_back(solver.stats().solve.seconds);
    }
    if (rank != 0) continue;
    const Stats& st = solver.stats();
    const DistributedStats& ds = solver.distributed_stats();
    std::size_t between = 0;
    json per = json::array();
    for (const RankStats& r : ds.per_rank) {
      between += r.factor_bytes_sent;
      per.push_back(r);
    }
    const json devices = st.factor.devices;
    // the values the factorization reads: one triangle (diagonal included) when symmetric
    std::size_t nnz_values = static_cast<std::size_t>(p.a.nnz());
    if (symmetric && p.a.storage == Storage::full) {
      nnz_values = 0;
      for (index_t j = 0; j < p.a.n_rows; ++j)  // CSR or CSC: one triangle either way
        for (index_t q = p.a.offsets[j]; q < p.a.offsets[j + 1]; ++q)
          nnz_values += p.a.indices[q] >= j ? 1 : 0;
    }
    const std::size_t values_broadcast =
        sizeof(double) * nnz_values * static_cast<std::size_t>(ranks - 1);
    const std::size_t values_scattered = ds.per_rank.empty() ? 0 : ds.per_rank[0].values_bytes;
    json row = {{"problem", name},
                {"n", st.analysis.n},
                {"ranks", ranks},
                {"gpus_per_rank", per_rank},
                {"flops", st.analysis.factor_flops},
                {"subtrees", st.analysis.subtrees},
                {"top_flops_fraction", st.analysis.top_flops_fraction},
                {"subtree_balance", st.analysis.subtree_balance},
                {"analysis_seconds", analysis_seconds},
                {"analysis_bytes", ds.analysis_bytes},
                {"first_factor_seconds", first_factor},
                {"factor_seconds", bench::median(times)},
                // rank 0's Solver: of its last refactorization, the input (checks, scaling)
                {"input_seconds", st.factor.input_seconds},
                {"bytes_between_ranks", between},
                {"blocks_transport", ds.blocks_transport},
                {"values_bytes_between_ranks", values_scattered},
                {"values_bytes_if_broadcast", values_broadcast},
                {"first_solve_seconds", first_solve},
                {"solve_seconds", solves.empty() ? first_solve : bench::median(solves)},
                // a wrong factor shows here first (refinement hides it in the error)
                {"refinement_steps", st.solve.refinement_steps},
                {"gmres_iterations", st.solve.gmres_iterations},
                {"backward_error", bench::berr(p.a, x, b)},
                {"per_rank", per},
                {"devices", devices}};
    out["rows"].push_back(row);
    std::printf(
        "%-12s %dx%d  factor %.3f s (first %.3f s), %.1f MB between ranks%s%s (values %.1f MB, "
        "%.1f MB if broadcast), solve %.3f s (first %.3f s; %d refinement steps, %d GMRES "
        "iterations), berr %.1e\n",
        name.c_str(), ranks, per_rank, bench::median(times), first_factor, between * 1e-6,
        ds.blocks_transport.empty() ? "" : ", blocks by ", ds.blocks_transport.c_str(),
        values_scattered * 1e-6, values_broadcast * 1e-6, row["solve_seconds"].get<double>(),
        first_solve, st.solve.refinement_steps, st.solve.gmres_iterations,
        row["backward_error"].get<double>());
    std::fflush(stdout);
  }
  if (rank == 0) {
    const std::string stem = tag.empty() ? "distributed" : "distributed-" + tag;
    std::printf("written: %s\n", bench::write_result(out, stem, results_dir).c_str());
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  app::use_fitting_blas_kernels(argv);  // before MPI_Init: the program may start again
  app::report_fatal_signals();          // a crash on a lent machine says where
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_SERIALIZED, &provided);
  int rc = 1;
  try {
    rc = run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_distributed: %s\n", e.what());
  }
  MPI_Finalize();
  return rc;
}
