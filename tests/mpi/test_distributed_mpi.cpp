// strata tests — the distributed solver over MPI ranks (src/distributed), run by ctest
// under `mpiexec -n 2` and `-n 4` on the CPU backend. Every rank runs every test; the
// matrices and right-hand sides exist on rank 0 only (the others pass empty ones), and
// rank 0 checks the distributed solution against the one-process Solver on the same
// matrix, against a dense LAPACK solve where the matrix is small, and its backward error;
// the pivot statistics (inertia, perturbed pivots, log|det|), which rank 0 assembles from
// every rank's fronts, against the one-process figures; the scaled values scattered to
// the ranks add up (each rank only its subtrees' entries: tests/unit/
// test_distributed_serialize.cpp checks which). Also: refactorization with new values —
// with refinement and, so that a stale or missing value on any rank shows in the answer,
// without — several right-hand sides, R ranks × 2 CPU workers each, and an error raised
// on some rank thrown on every rank. Where CUDA GPUs are visible (a lent machine, run by
// hand under mpirun), GPU ranks: the solve on the GPUs that hold the factor's parts
// against the host solve and the one-process solve.
#include <gtest/gtest.h>
#include <mpi.h>

#include <cmath>
#include <string>

#include "base/device.hpp"
#include "distributed/distributed_internal.hpp"
#include "sparse/generators.hpp"
#include "strata/distributed.hpp"
#include "strata/mpi.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

int world_rank() {
  int r = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &r);
  return r;
}
int world_size() {
  int r = 0;
  MPI_Comm_size(MPI_COMM_WORLD, &r);
  return r;
}

using Problem = test::NamedMatrix;

// spd, symmetric indefinite and general problems (built on rank 0 only): generated 3D
// grids, shared matrices, random matrices of awkward sizes.
std::vector<Problem> problems() {
  const bool root = world_rank() == 0;
  auto rng = test::fresh_rng();
  std::vector<Problem> p;
  auto on_root = [&](auto make) { return root ? make() : SparseMatrix{}; };
  auto shared = [&](const char* name) {
    return on_root([&] { return read_matrix_market(test::matrix_path(name)).matrix; });
  };
  p.push_back(
      {"lap3d 12", on_root([] { return generators::laplacian_3d(12, 12, 12); }), MatrixType::spd});
  p.push_back({"elasticity 5", on_root([] { return generators::elasticity_3d(5, 5, 5); }),
               MatrixType::spd});
  p.push_back({"bcsstk16", shared("bcsstk16"), MatrixType::spd});
  for (index_t n : {1, 2, 5, 733})
    p.push_back({"random spd " + std::to_string(n),
                 on_root([&] { return test::random_sparse(n, 3, test::RandomKind::spd, rng); }),
                 MatrixType::spd});
  p.push_back({"hangGlider_2", shared("hangGlider_2"), MatrixType::symmetric_indefinite});
  p.push_back({"random kkt 733", on_root([&] { return test::random_kkt(733, rng); }),
               MatrixType::symmetric_indefinite});
  p.push_back({"random indefinite 3", on_root([&] {
                 return test::random_sparse(3, 2, test::RandomKind::symmetric_indefinite, rng);
               }),
               MatrixType::symmetric_indefinite});
  p.push_back({"random indefinite 1500 (automatic)", on_root([&] {
                 return test::random_sparse(1500, 4, test::RandomKind::symmetric_indefinite, rng);
               }),
               MatrixType::automatic});
  p.push_back({"watt_2", shared("watt_2"), MatrixType::general});
  p.push_back({"nnc1374", shared("nnc1374"), MatrixType::general});
  p.push_back({"random general 5",
               on_root([&] { return test::random_sparse(5, 2, test::RandomKind::general, rng); }),
               MatrixType::general});
  p.push_back({"random general 1500", on_root([&] {
                 return test::random_sparse(1500, 4, test::RandomKind::general, rng);
               }),
               MatrixType::general});
  return p;
}

Options options_for(MatrixType type) {
  Options o;
  o.type = type;
  o.num_threads = 1;  // several ranks share the machine's cores
  return o;
}

// Rank 0: the distributed run against the one-process Solver and a dense solve.
void check_against_one_process(const Problem& pr, const DistributedSolver& ds,
                               const std::vector<double>& b, const std::vector<double>& x,
                               index_t nrhs) {
  const SparseMatrix& a = pr.a;
  const index_t n = a.n_rows;
  Solver ref(options_for(pr.type));
  ref.factorize(a);
  std::vector<double> xr(b.size());
  ref.solve(b.data(), xr.data(), nrhs);
  const FactorStats& f = ds.stats().factor;
  const FactorStats& fr = ref.stats().factor;
  EXPECT_EQ(f.type, fr.type);
  EXPECT_EQ(f.inertia_positive, fr.inertia_positive);
  EXPECT_EQ(f.inertia_negative, fr.inertia_negative);
  EXPECT_EQ(f.inertia_zero, fr.inertia_zero);
  if (f.perturbed_pivots == 0 && fr.perturbed_pivots == 0) {
    EXPECT_EQ(f.determinant_sign, fr.determinant_sign);
    EXPECT_NEAR(f.log_abs_determinant, fr.log_abs_determinant,
                1e-8 * std::max(1.0, std::abs(fr.log_abs_determinant)));
  }
  double kappa = -1;  // κ∞(A), estimated only where a difference needs it (O(n³))
  for (index_t c = 0; c < nrhs; ++c) {
    const double berr = test::backward_error(a, x.data() + c * n, b.data() + c * n);
    const double berr_ref = test::backward_error(a, xr.data() + c * n, b.data() + c * n);
    EXPECT_LE(berr, std::max(1e-14, 2 * berr_ref)) << "column " << c;
    const std::vector<double> xc(x.begin() + c * n, x.begin() + (c + 1) * n);
    const std::vector<double> xrc(xr.begin() + c * n, xr.begin() + (c + 1) * n);
    // two backward-stable solutions differ by at most about κ times their backward errors
    // (the two runs' orders differ; nnc1374's κ∞ is about 1e15)
    const double diff = test::relative_difference(xc, xrc);
    if (diff >= 1e-8 && kappa < 0) kappa = test::condition_inf(a);
    EXPECT_LE(diff, std::max(1e-8, 4 * kappa * (berr + berr_ref))) << "column " << c;
  }
  if (n <= 1500) {  // an independent reference: dense LAPACK LU
    std::vector<double> xd = b;
    ASSERT_TRUE(test::dense_solve(test::to_dense(a), n, xd, nrhs));
    EXPECT_LT(test::relative_difference(x, xd), 1e-7);
  }
}

// D·A·D for a diagonal D of factors drawn from `scale` (new values on the same pattern).
SparseMatrix symmetrically_scaled(const SparseMatrix& a,
                                  std::uniform_real_distribution<double>& scale,
                                  std::mt19937_64& rng) {
  SparseMatrix s = a;
  std::vector<double> d(static_cast<std::size_t>(a.n_rows));
  for (double& v : d) v = scale(rng);
  for (index_t j = 0; j < s.n_cols; ++j)
    for (index_t p = s.offsets[j]; p < s.offsets[j + 1]; ++p) s.values[p] *= d[s.indices[p]] * d[j];
  return s;
}

// Every problem, every type: the distributed solution agrees with the one-process one;
// every rank factored its subtrees and rank 0 gathered every rank's figures.
void run_all(int workers_per_rank) {
  const int rank = world_rank(), ranks = world_size();
  std::uniform_real_distribution<double> u(-1, 1);
  auto rng = test::fresh_rng();
  for (const Problem& pr : problems()) {
    SCOPED_TRACE(pr.name + ", " + std::to_string(ranks) + " ranks x " +
                 std::to_string(workers_per_rank));
    DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), options_for(pr.type));
    if (workers_per_rank > 1) detail::DistributedAccess::use_host_workers(ds, workers_per_rank);
    const index_t nrhs = pr.name == "bcsstk16" ? 3 : 1;
    const index_t n = pr.a.n_rows;
    std::vector<double> b(static_cast<std::size_t>(n) * nrhs);
    for (double& v : b) v = u(rng);
    std::vector<double> x(b.size());
    ds.analyze(pr.a);
    ds.factorize(pr.a);
    ds.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, nrhs);
    const DistributedStats& st = ds.distributed_stats();
    if (rank != 0) {
      ASSERT_EQ(st.per_rank.size(), 1u);
      continue;
    }
    EXPECT_EQ(ds.stats().analysis.workers, ranks * workers_per_rank);
    EXPECT_EQ(st.blocks_transport, ranks == 1 ? "" : "mpi");  // CPU ranks: host buffers
    ASSERT_EQ(st.per_rank.size(), static_cast<std::size_t>(ranks));
    index_t subtrees = 0;
    std::size_t held = 0, values_received = 0;
    for (int r = 0; r < ranks; ++r) {
      EXPECT_EQ(st.per_rank[r].rank, r);
      subtrees += st.per_rank[r].subtrees;
      held += st.per_rank[r].factor_bytes_held;
      if (r > 0) {
        values_received += st.per_rank[r].values_bytes;
        EXPECT_LE(st.per_rank[r].values_bytes, st.per_rank[r].factor_bytes_received);
      }
    }
    // scattered, not broadcast: what rank 0 sent is what the others received, and (the
    // ranks' entries being disjoint) at most the matrix once per factorization attempt
    const std::size_t attempts = pr.type == MatrixType::automatic ? 2 : 1;
    EXPECT_EQ(st.per_rank[0].values_bytes, values_received);
    EXPECT_LE(values_received, attempts * sizeof(double) * static_cast<std::size_t>(pr.a.nnz()));
    EXPECT_EQ(subtrees, ds.stats().analysis.subtrees);
    EXPECT_EQ(held, ds.stats().analysis.factor_bytes)
        << "the ranks' shares of the factor do not add up to the factor";
    check_against_one_process(pr, ds, b, x, nrhs);
  }
}

TEST(Distributed, SameSolutionAsOneProcessAllTypes) { run_all(1); }

TEST(Distributed, TwoWorkersPerRank) {
  // rank × 2 CPU executors, as ranks × 2 GPUs: work stealing within a rank
  const int rank = world_rank();
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1);
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::general, MatrixType::general}}) {
    SCOPED_TRACE(to_string(type));
    Problem pr{"random 733", rank == 0 ? test::random_sparse(733, 3, kind, rng) : SparseMatrix{},
               type};
    DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), options_for(type));
    detail::DistributedAccess::use_host_workers(ds, 2);
    std::vector<double> b(733);
    for (double& v : b) v = u(rng);
    ds.factorize(pr.a);  // analyzes first
    const std::vector<double> x = ds.solve(rank == 0 ? b : std::vector<double>{});
    if (rank != 0) {
      EXPECT_TRUE(x.empty());
      continue;
    }
    EXPECT_EQ(ds.distributed_stats().workers_per_rank, 2);
    EXPECT_EQ(ds.stats().analysis.workers, 2 * world_size());
    check_against_one_process(pr, ds, b, x, 1);
  }
}

// New values with the analyzed pattern: the solution of a fresh one-process solver.
TEST(Distributed, Refactorization) {
  const int rank = world_rank();
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1), scale(0.8, 1.2);
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::general, MatrixType::general}}) {
    SCOPED_TRACE(to_string(type));
    const index_t n = 900;
    Problem pr{"random 900", rank == 0 ? test::random_sparse(n, 3, kind, rng) : SparseMatrix{},
               type};
    DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), options_for(type));
    ds.analyze(pr.a);
    ds.factorize(pr.a);
    std::vector<double> b(n);
    for (double& v : b) v = u(rng);
    const SparseMatrix a2 = rank == 0 ? symmetrically_scaled(pr.a, scale, rng) : pr.a;
    ds.refactorize(a2);
    std::vector<double> x(n);
    ds.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, 1);
    if (rank != 0) continue;
    Problem p2{pr.name, a2, type};
    check_against_one_process(p2, ds, b, x, 1);
  }
}

// Refactorization with values drawn afresh on the same pattern and no iterative
// refinement (nor GMRES): the solution is the factor's alone, so a rank that factored a
// stale value of the first factorization, or missed one, would change the answer. It
// must equal the one-process solve of the new matrix with the same options, and a dense
// LAPACK solve.
TEST(Distributed, RefactorizationWithoutRefinementReadsTheNewValues) {
  const int rank = world_rank();
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1), scale(0.5, 2.0);
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::general, MatrixType::general}})
    for (const index_t n : {5, 733}) {
      SCOPED_TRACE(std::string(to_string(type)) + ", n = " + std::to_string(n));
      const SparseMatrix a = rank == 0 ? test::random_sparse(n, 3, kind, rng) : SparseMatrix{};
      Options o = options_for(type);
      o.refinement_max_steps = 0;
      o.gmres_max_iterations = 0;
      DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), o);
      ds.factorize(a);
      // new values: a two-sided diagonal scaling drawn afresh (symmetric for the symmetric
      // types, so that the type still holds), which changes every entry
      SparseMatrix a2 = a;
      if (rank == 0) {
        std::vector<double> dr(n), dc(n);
        for (double& v : dr) v = scale(rng);
        for (double& v : dc) v = scale(rng);
        const std::vector<double>& right = type == MatrixType::general ? dc : dr;
        for (index_t j = 0; j < a2.n_cols; ++j)
          for (index_t p = a2.offsets[j]; p < a2.offsets[j + 1]; ++p)
            a2.values[p] *= a2.layout == Layout::csc ? dr[a2.indices[p]] * right[j]
                                                     : dr[j] * right[a2.indices[p]];
      }
      ds.refactorize(a2);
      std::vector<double> b(n), x(n);
      for (double& v : b) v = u(rng);
      ds.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, 1);
      if (rank != 0) continue;
      EXPECT_EQ(ds.stats().solve.refinement_steps, 0);
      Solver ref(o);
      ref.factorize(a2);
      std::vector<double> xr(n);
      ref.solve(b.data(), xr.data(), 1);
      EXPECT_LT(test::relative_difference(x, xr), 1e-8);
      std::vector<double> xd = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(a2), n, xd, 1));
      EXPECT_LT(test::relative_difference(x, xd), 1e-7);
    }
}

// Errors: a matrix declared spd that is not (its failing pivot may be on any rank) gives
// NotPositiveDefinite on every rank; a bad right-hand side on rank 0 gives InvalidInput on
// every rank; and the solver stays usable.
TEST(Distributed, ErrorsReachEveryRank) {
  const int rank = world_rank();
  SparseMatrix a;
  if (rank == 0) {
    a = generators::laplacian_3d(10, 10, 10);
    for (index_t j = 0; j < a.n_cols; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        if (a.indices[p] == j) a.values[p] -= 4.0;  // indefinite
  }
  DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), options_for(MatrixType::spd));
  ds.analyze(a);
  EXPECT_THROW(ds.factorize(a), NotPositiveDefinite);
  DistributedSolver dsi(mpi_communicator(MPI_COMM_WORLD),
                        options_for(MatrixType::symmetric_indefinite));
  dsi.factorize(a);
  std::vector<double> b(rank == 0 ? 1000 : 0, 1.0);
  if (rank == 0) b[3] = std::nan("");
  std::vector<double> x(b.size());
  EXPECT_THROW(dsi.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, 1),
               InvalidInput);
  if (rank == 0) b[3] = 1.0;
  dsi.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, 1);
  if (rank == 0) {
    EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-14);
    EXPECT_GT(dsi.stats().factor.inertia_negative, 0);
  }
}

// A matrix declared spd whose only pivot that is not positive is the last one, in the top
// part that rank 0 factors after the other ranks sent their blocks: NotPositiveDefinite
// on every rank (rank 0's error reaches the others after they sent their pivot
// statistics), and the solver stays usable: refactorized with the first values it solves
// as the one-process Solver does.
TEST(Distributed, TopPartFailureReachesEveryRank) {
  const int rank = world_rank(), ranks = world_size();
  if (ranks == 1) GTEST_SKIP() << "one rank: no top part apart from the subtrees";
  SparseMatrix a = rank == 0 ? generators::laplacian_3d(12, 12, 12) : SparseMatrix{};
  DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), options_for(MatrixType::spd));
  ds.analyze(a);
  SparseMatrix bad = a;
  if (rank == 0) {
    const Analysis& an = *detail::DistributedAccess::analysis(ds);
    const index_t root = an.tree.n_fronts() - 1, last = an.n - 1;
    ASSERT_EQ(an.partition.part_of[root], -1) << "the root front is not in the top part";
    ASSERT_EQ(an.tree.front_of_column[last], root);
    const index_t v = an.perm[last];  // spd: B = A, pivot k is column perm[k]
    for (index_t p = bad.offsets[v]; p < bad.offsets[v + 1]; ++p)
      if (bad.indices[p] == v) bad.values[p] -= 1e3;
  }
  ds.factorize(a);
  EXPECT_THROW(ds.refactorize(bad), NotPositiveDefinite);
  ds.refactorize(a);
  std::vector<double> b(rank == 0 ? a.n_rows : 0, 1.0), x(b.size());
  ds.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, 1);
  if (rank == 0) check_against_one_process({"lap3d 12", a, MatrixType::spd}, ds, b, x, 1);
}

// GPU ranks (the CUDA backend, one GPU per rank: rank r on GPU r mod the visible ones;
// skipped without a GPU): each GPU keeps the panels of the parts it factored and the solve
// runs there (the Solver reports the solve on the device; LLᵀ and LU — an LDLᵀ factor's
// panels go to the host, as on one process, and the solve with them); the same
// factorization solved on the host instead (gpu_solve_parts off, the panels fetched at the
// solve) and the one-process CPU solve agree, for two right-hand sides, and again after a
// refactorization with new values (the held panels are the new factor's).
TEST(Distributed, GpuRanksSolveWhereTheFactorIs) {
  if (numeric::cuda_device_count() == 0)
    GTEST_SKIP() << "no CUDA GPU: the distributed solve on GPU ranks is not run";
  const int rank = world_rank(), ranks = world_size();
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1), scale(0.5, 2.0);
  std::vector<Problem> probs;
  probs.push_back({"lap3d 20", rank == 0 ? generators::laplacian_3d(20, 20, 20) : SparseMatrix{},
                   MatrixType::spd});
  probs.push_back({"random kkt 733", rank == 0 ? test::random_kkt(733, rng) : SparseMatrix{},
                   MatrixType::symmetric_indefinite});
  probs.push_back(
      {"random general 1500",
       rank == 0 ? test::random_sparse(1500, 4, test::RandomKind::general, rng) : SparseMatrix{},
       MatrixType::general});
  for (const Problem& pr : probs)
    for (const bool where_held : {true, false}) {
      SCOPED_TRACE(pr.name + (where_held ? ", solved on the GPUs" : ", solved on the host"));
      Options o = options_for(pr.type);
      o.backend = Backend::cuda;
      o.num_gpus = 1;
      o.gpu_solve_parts = where_held;
      // an LDLᵀ factor's panels come to the host (as on one process with several GPUs)
      const bool on_gpus = where_held && pr.type != MatrixType::symmetric_indefinite;
      DistributedSolver ds(mpi_communicator(MPI_COMM_WORLD), o);
      const index_t n = pr.a.n_rows, nrhs = 2;
      std::vector<double> b(static_cast<std::size_t>(n) * nrhs), x(b.size());
      for (double& v : b) v = u(rng);
      ds.analyze(pr.a);
      ds.factorize(pr.a);
      ds.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, nrhs);
      if (rank == 0) {
        if (ranks > 1) EXPECT_EQ(ds.stats().solve.on_device, on_gpus);
        check_against_one_process(pr, ds, b, x, nrhs);
      }
      const SparseMatrix a2 = rank == 0 ? symmetrically_scaled(pr.a, scale, rng) : pr.a;
      ds.refactorize(a2);
      ds.solve(rank == 0 ? b.data() : nullptr, rank == 0 ? x.data() : nullptr, nrhs);
      if (rank == 0) {
        if (ranks > 1) EXPECT_EQ(ds.stats().solve.on_device, on_gpus);
        check_against_one_process({pr.name, a2, pr.type}, ds, b, x, nrhs);
      }
    }
}

}  // namespace
}  // namespace strata

int main(int argc, char** argv) {
  int provided = 0;
  MPI_Init_thread(&argc, &argv, MPI_THREAD_SERIALIZED, &provided);
  ::testing::InitGoogleTest(&argc, argv);
  const int rc = RUN_ALL_TESTS();
  int worst = 0;
  MPI_Allreduce(&rc, &worst, 1, MPI_INT, MPI_MAX, MPI_COMM_WORLD);
  MPI_Finalize();
  return worst;
}
