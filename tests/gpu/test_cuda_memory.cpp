// strata — GPU backend with any amount of device memory, and the solve on the device
// (ctest label `gpu`). References: the CPU executor on the same analysis, and the
// in-core GPU run. Skipped, with a message, where no CUDA GPU is present.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "analysis/analysis.hpp"
#include "numeric/factor.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

class CudaMemory : public ::testing::Test {
 protected:
  void SetUp() override {
    if (!numeric::cuda_available())
      GTEST_SKIP() << "no CUDA GPU present (or this build has no CUDA backend): GPU test skipped";
  }
};

constexpr std::size_t MiB = 1024 * 1024;

// The Cholesky factor of `a` under analysis `an` by the CPU executor and by a CUDA
// executor for `o`, whose panels are then fetched to the host; returns the CUDA
// executor's statistics.
FactorStats factor_on_cpu_and_gpu(const Analysis& an, const SparseMatrix& a, const Options& o,
                                  numeric::NumericFactor& cpu_f, numeric::NumericFactor& gpu_f) {
  const SparseMatrix c = canonical_values(an, a);
  std::vector<double> arena;
  auto cpu = numeric::make_cpu_executor(2);
  auto gpu = numeric::make_cuda_executor(o);
  numeric::factorize(an, c.values, MatrixType::spd, 0.0, *cpu, cpu_f, arena);
  numeric::factorize(an, c.values, MatrixType::spd, 0.0, *gpu, gpu_f, arena);
  FactorStats fs;
  gpu->report(fs);
  numeric::fetch_panels(an, *gpu, gpu_f);
  return fs;
}

// Cholesky with the device budget far below the factor: contribution blocks spill to
// host memory and the largest fronts are factored slab by slab; the factor equals the
// CPU's entry by entry (no pivoting), as the in-core GPU run does.
TEST_F(CudaMemory, CholeskyUnderATightBudgetEqualsInCore) {
  const SparseMatrix a = generators::laplacian_3d(24, 24, 24);
  for (std::size_t limit : {std::size_t{0}, 8 * MiB, 2 * MiB, MiB / 2}) {
    SCOPED_TRACE("device_memory_limit " + std::to_string(limit));
    Options o;
    o.num_gpus = 1;  // one GPU, whatever the machine has
    o.type = MatrixType::spd;
    o.device_memory_limit = limit;
    Analysis an = analyze_matrix(a, o);
    numeric::NumericFactor cpu_f, gpu_f;
    const FactorStats fs = factor_on_cpu_and_gpu(an, a, o, cpu_f, gpu_f);
    if (limit != 0) EXPECT_FALSE(fs.factor_resident);
    if (limit != 0 && limit <= 2 * MiB) {
      EXPECT_LT(static_cast<double>(limit), 0.2 * an.plan.factor_bytes);
      EXPECT_GT(fs.tiled_fronts, 0);
      EXPECT_TRUE(fs.contribution_blocks_on_host);
    }
    EXPECT_LT(test::relative_difference(gpu_f.panels, cpu_f.panels), 1e-12);
    EXPECT_EQ(cpu_f.rows, gpu_f.rows);
  }
}

// Cholesky fronts over the budget (tiled_llt.cu: pivot columns left-looking by slabs,
// the contribution block by square tiles) on random symmetric scalings D·A·D of a
// Laplacian and of an elasticity stencil, budgets from a quarter of the largest front
// down to a few slabs, the pool as planned and 60% of the budget, earlier columns
// streamed as wide as a slab and in pieces of 48, with and without the next front's host
// assembly beside the device's work (which some fronts get), and the defaults: the factor
// equals the CPU's entry by entry, and a refactorization with other values under the same
// plan equals the CPU's on those.
TEST_F(CudaMemory, TiledCholeskyFrontsMatchCpu) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 2.0);
  for (const SparseMatrix& base :
       {generators::laplacian_3d(22, 21, 20), generators::elasticity_3d(11, 12, 13)}) {
    Options o;
    o.num_gpus = 1;  // one GPU, whatever the machine has
    o.type = MatrixType::spd;
    Analysis an = analyze_matrix(base, o);
    const double largest = static_cast<double>(an.stats.largest_front_rows);
    index_t prefetched = 0;
    // (pool share, streamed piece width, prefetch): the plan's pool, a larger pool, narrow
    // pieces, the next front assembled beside the device's work
    struct Config {
      double pool_share;
      index_t stream;
      bool prefetch;
    };
    for (const Config cfg :
         {Config{0.0, 0, false}, Config{0.6, 0, false}, Config{0.0, 48, false},
          Config{0.0, 0, true}, Config{0.0, 48, true},
          Config{Options{}.gpu_tiled_pool_share, Options{}.gpu_tiled_stream_columns,
                 Options{}.gpu_tiled_prefetch}})
      for (double share : {0.25, 0.1, 0.04}) {
        // at least a pool for three slabs of 16 columns of the largest front (below that
        // the plan refuses the budget: ImpossibleBudgetNamesTheBytes)
        const auto limit = static_cast<std::size_t>(
            std::max(share * largest * largest, 64 * largest) * sizeof(double));
        o.device_memory_limit = limit;
        o.gpu_tiled_pool_share = cfg.pool_share;
        o.gpu_tiled_stream_columns = cfg.stream;
        o.gpu_tiled_prefetch = cfg.prefetch;
        SCOPED_TRACE("n " + std::to_string(base.n_rows) + ", device_memory_limit " +
                     std::to_string(limit) + ", gpu_tiled_pool_share " +
                     std::to_string(cfg.pool_share) + ", gpu_tiled_stream_columns " +
                     std::to_string(cfg.stream) + ", gpu_tiled_prefetch " +
                     std::to_string(cfg.prefetch));
        Analysis ab = analyze_matrix(base, o);
        auto gpu = numeric::make_cuda_executor(o);
        auto cpu = numeric::make_cpu_executor(2);
        for (int round = 0; round < 2; ++round) {  // a factorization, then a refactorization
          SparseMatrix a = base;
          std::vector<double> d(a.n_rows);
          for (double& v : d) v = u(rng);
          for (index_t j = 0; j < a.n_cols; ++j)
            for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
              a.values[p] *= d[j] * d[a.indices[p]];
          SparseMatrix c = canonical_values(ab, a);
          numeric::NumericFactor cpu_f, gpu_f;
          std::vector<double> arena;
          numeric::factorize(ab, c.values, MatrixType::spd, 0.0, *cpu, cpu_f, arena);
          numeric::factorize(ab, c.values, MatrixType::spd, 0.0, *gpu, gpu_f, arena);
          FactorStats fs;
          gpu->report(fs);
          numeric::fetch_panels(ab, *gpu, gpu_f);
          SCOPED_TRACE(std::string("blocks on host ") +
                       (fs.contribution_blocks_on_host ? "yes" : "no") + ", round " +
                       std::to_string(round));
          EXPECT_GT(fs.tiled_fronts, 0);
          EXPECT_FALSE(fs.factor_resident);
          EXPECT_LT(test::relative_difference(gpu_f.panels, cpu_f.panels), 1e-12);
          if (!cfg.prefetch) EXPECT_EQ(fs.tiled_fronts_prefetched, 0);
          prefetched += fs.tiled_fronts_prefetched;
        }
      }
    EXPECT_GT(prefetched, 0) << "no front was assembled beside the device's work";
  }
}

// A Cholesky that fails inside a front over the budget (the Laplacian shifted to one
// negative eigenvalue, as in test_cuda_backend): the failing column is the CPU's, with
// the pivot found in a later slab of the root front, by recursion and by POTRF.
TEST_F(CudaMemory, TiledCholeskyFailureNamesTheCpusColumn) {
  SparseMatrix a = generators::laplacian_3d(20, 20, 20);
  for (index_t j = 0; j < a.n_cols; ++j) a.values[a.offsets[j]] -= 0.1;  // diagonal first
  Options o;
  o.num_gpus = 1;  // one GPU, whatever the machine has
  o.type = MatrixType::spd;
  index_t cpu_column = -1;
  try {
    Solver(o).factorize(a);
    FAIL() << "expected NotPositiveDefinite on the CPU";
  } catch (const NotPositiveDefinite& e) {
    cpu_column = e.column();
  }
  o.backend = Backend::cuda;
  for (std::size_t limit : {256 * std::size_t{1024}, MiB})
    for (auto [recursive, stream] : {std::pair{true, index_t{0}}, std::pair{false, index_t{0}},
                                     std::pair{true, index_t{32}}, std::pair{true, index_t{-1}}}) {
      SCOPED_TRACE("device_memory_limit " + std::to_string(limit) + ", recursive " +
                   std::to_string(recursive) + ", stream " + std::to_string(stream));
      o.device_memory_limit = limit;
      o.gpu_recursive_panel = recursive;
      // -1: pieces as wide as a slab and the next front prefetched (a failure must drop it)
      o.gpu_tiled_stream_columns = std::max<index_t>(stream, 0);
      o.gpu_tiled_prefetch = stream < 0;
      Solver s(o);
      try {
        s.factorize(a);
        ADD_FAILURE() << "expected NotPositiveDefinite";
      } catch (const NotPositiveDefinite& e) {
        EXPECT_EQ(e.column(), cpu_column);
      }
    }
}

// LU under a tight budget: the slab path keeps the in-core pivot candidates, so the
// solution equals the CPU's, with the same determinant.
TEST_F(CudaMemory, LuUnderATightBudgetEqualsInCore) {
  SparseMatrix a = expand_symmetric(generators::laplacian_3d(22, 22, 22));
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 1.5);
  for (double& v : a.values) v *= u(rng);  // unsymmetric values
  std::vector<double> b(a.n_rows);
  std::uniform_real_distribution<double> ub(-1, 1);
  for (double& v : b) v = ub(rng);
  Options o;
  o.num_gpus = 1;  // one GPU, whatever the machine has
  o.type = MatrixType::general;
  Solver cpu(o);
  cpu.factorize(a);
  const auto xc = cpu.solve(b);
  for (std::size_t limit : {std::size_t{0}, 2 * MiB, MiB / 2}) {
    SCOPED_TRACE("device_memory_limit " + std::to_string(limit));
    Options g = o;
    g.backend = Backend::cuda;
    g.device_memory_limit = limit;
    Solver gpu(g);
    gpu.factorize(a);
    if (limit != 0) EXPECT_GT(gpu.stats().factor.tiled_fronts, 0);
    const auto xg = gpu.solve(b);
    EXPECT_LT(test::backward_error(a, xg.data(), b.data()), 1e-14);
    EXPECT_LT(test::relative_difference(xg, xc), 1e-8);
    EXPECT_EQ(gpu.stats().factor.determinant_sign, cpu.stats().factor.determinant_sign);
    EXPECT_NEAR(gpu.stats().factor.log_abs_determinant, cpu.stats().factor.log_abs_determinant,
                1e-8 * std::abs(cpu.stats().factor.log_abs_determinant));
    // refactorization under the same budget reuses the device plan and gives the same
    gpu.refactorize(a);
    EXPECT_EQ(gpu.solve(b), xg);
  }
}

// With the factor resident, the triangular solves run on the device and agree with the
// host solves on the same factor, for one and several right-hand sides.
TEST_F(CudaMemory, DeviceSolveMatchesHostSolve) {
  auto rng = test::fresh_rng();
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::general, MatrixType::general},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite}})
    for (index_t n : {1, 2, 3, 5, 733, 4000}) {
      SCOPED_TRACE(std::string(to_string(type)) + " n=" + std::to_string(n));
      SparseMatrix a = test::random_sparse(n, n > 1000 ? 8 : 3, kind, rng);
      for (index_t nrhs : {1, 3}) {
        std::vector<double> b(static_cast<std::size_t>(n) * nrhs);
        std::uniform_real_distribution<double> u(-1, 1);
        for (double& v : b) v = u(rng);
        Options o;
        o.num_gpus = 1;  // one GPU, whatever the machine has
        o.type = type;
        o.backend = Backend::cuda;
        o.refinement_max_steps = 0;  // compare the plain solves
        o.gmres_max_iterations = 0;
        Solver gpu(o);
        gpu.factorize(a);
        ASSERT_TRUE(gpu.stats().factor.factor_resident);
        std::vector<double> xg(b.size());
        gpu.solve(b.data(), xg.data(), nrhs);
        EXPECT_TRUE(gpu.stats().solve.on_device);
        // the host solve on the same factor: the same solver with the factor off the
        // device is not reachable from the API, so compare with the CPU backend's
        // solution instead, and the residual
        Options c = o;
        c.backend = Backend::cpu;
        Solver cpu(c);
        cpu.factorize(a);
        std::vector<double> xc(b.size());
        cpu.solve(b.data(), xc.data(), nrhs);
        EXPECT_FALSE(cpu.stats().solve.on_device);
        // Unrefined solves: their backward error follows the pivots' growth (Bunch–Kaufman
        // LDLᵀ of a random indefinite matrix of 4000 reached 2.8e-12 once), so the device's
        // is held to the CPU backend's on the same matrix (an index or ordering error gives
        // O(1)), and the solutions to the condition: κ∞(A) ≥ ‖A‖∞‖x‖∞/‖b‖∞ (Higham §7.1).
        std::vector<double> row(n, 0.0);
        for (index_t j = 0; j < n; ++j)
          for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
            row[a.indices[p]] += std::abs(a.values[p]);
            if (a.storage == Storage::lower && a.indices[p] != j) row[j] += std::abs(a.values[p]);
          }
        double anorm = 0, xn = 0, bn = 0;
        for (double v : row) anorm = std::max(anorm, v);
        for (double v : xc) xn = std::max(xn, std::abs(v));
        for (double v : b) bn = std::max(bn, std::abs(v));
        const double kappa = anorm * xn / std::max(bn, 1e-300);
        EXPECT_LT(test::relative_difference(xg, xc),
                  std::max(1e-9, 1e-13 * std::sqrt(double(n)) * kappa));
        for (index_t r = 0; r < nrhs; ++r) {
          const double berr_cpu = test::backward_error(a, xc.data() + r * n, b.data() + r * n);
          EXPECT_LT(test::backward_error(a, xg.data() + r * n, b.data() + r * n),
                    std::max(1e-12, 10 * berr_cpu));
        }
      }
    }
}

// Large fronts (cuSOLVER/cuBLAS factorization path) solved on the device.
TEST_F(CudaMemory, DeviceSolveWithLargeFronts) {
  const SparseMatrix a = generators::elasticity_3d(12, 12, 12);
  std::vector<double> ones(a.n_rows, 1.0), b(a.n_rows);
  multiply(a, ones.data(), b.data());
  Options o;
  o.num_gpus = 1;  // one GPU, whatever the machine has
  o.backend = Backend::cuda;
  Solver gpu(o);
  gpu.factorize(a);
  ASSERT_GT(gpu.stats().analysis.largest_front_rows, 256);
  const auto x = gpu.solve(b);
  EXPECT_TRUE(gpu.stats().solve.on_device);
  EXPECT_LT(test::relative_difference(x, ones), 1e-8);
  EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-14);
}

// A budget with room for the factor, the contribution-block arena and the largest front,
// but not for the factor beside a pool that holds the largest batch of fronts: the pool
// shrinks, the factor stays on the device and the solves run there. The factor equals
// the CPU executor's (Cholesky: no pivoting) and the solution solves A x = b to rounding.
TEST_F(CudaMemory, FactorStaysResidentBesideASmallerPool) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 2.0);
  for (const SparseMatrix& base :
       {generators::laplacian_3d(20, 19, 18), generators::elasticity_3d(9, 10, 11)}) {
    SparseMatrix a = base;  // a random symmetric scaling D·A·D, drawn afresh
    std::vector<double> d(a.n_rows);
    for (double& v : d) v = u(rng);
    for (index_t j = 0; j < a.n_cols; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        a.values[p] *= d[j] * d[a.indices[p]];
    Options o;
    o.num_gpus = 1;  // one GPU, whatever the machine has
    o.type = MatrixType::spd;
    o.backend = Backend::cuda;
    const Analysis unlimited = analyze_matrix(a, o);
    const auto largest = static_cast<std::size_t>(unlimited.stats.largest_front_rows);
    const std::size_t need = unlimited.factor_layout.total + unlimited.cb_layout.arena_size +
                             largest * largest;  // doubles
    o.device_memory_limit = need * sizeof(double) * 21 / 20;
    SCOPED_TRACE("n " + std::to_string(a.n_rows) + ", device_memory_limit " +
                 std::to_string(o.device_memory_limit));
    const Analysis an = analyze_matrix(a, o);
    ASSERT_EQ(an.factor_layout.total, unlimited.factor_layout.total);
    // the premise: a pool for the largest batch would not leave room for the factor
    std::size_t batch = 0;
    for (const BatchInfo& bi : an.plan.batches) {
      std::size_t sum = 0;
      for (index_t q = bi.begin; q < bi.end; ++q) {
        const auto m = static_cast<std::size_t>(an.tree.n_rows(an.schedule.fronts[q]));
        sum += m * m;
      }
      batch = std::max(batch, sum);
    }
    ASSERT_GT(batch + an.factor_layout.total + an.cb_layout.arena_size,
              o.device_memory_limit / sizeof(double));

    numeric::NumericFactor cpu_f, gpu_f;
    const FactorStats fs = factor_on_cpu_and_gpu(an, a, o, cpu_f, gpu_f);
    EXPECT_TRUE(fs.factor_resident);
    EXPECT_EQ(fs.tiled_fronts, 0);
    EXPECT_LT(test::relative_difference(gpu_f.panels, cpu_f.panels), 1e-12);

    Solver solver(o);
    solver.factorize(a);
    ASSERT_TRUE(solver.stats().factor.factor_resident);
    std::vector<double> b(a.n_rows);
    std::uniform_real_distribution<double> v(-1, 1);
    for (double& x : b) x = v(rng);
    const std::vector<double> x = solver.solve(b);
    EXPECT_TRUE(solver.stats().solve.on_device);
    EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-14);
  }
}

// LDLᵀ under a budget that holds two of the largest front but not much more (chunks, and
// typically contribution blocks in host memory and the solve on the host): same solution
// and inertia as the CPU. A budget below the largest front would need slab-by-slab LDLᵀ,
// which is refused with NotSupported.
TEST_F(CudaMemory, LdltUnderABudget) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = test::random_kkt(6000, rng);
  std::vector<double> b(a.n_rows);
  std::uniform_real_distribution<double> u(-1, 1);
  for (double& v : b) v = u(rng);
  Options o;
  o.num_gpus = 1;  // one GPU, whatever the machine has
  o.type = MatrixType::symmetric_indefinite;
  Solver cpu(o);
  cpu.factorize(a);
  const auto xc = cpu.solve(b);
  const double largest = static_cast<double>(cpu.stats().analysis.largest_front_rows);
  ASSERT_GT(largest, 256);
  o.backend = Backend::cuda;
  // six fronts' worth: the largest front's working set (itself, its children's blocks and
  // its own block) fits, so nothing is tiled, yet levels are cut into chunks
  o.device_memory_limit = static_cast<std::size_t>(48 * largest * largest);
  Solver gpu(o);
  gpu.factorize(a);
  const FactorStats& fs = gpu.stats().factor;
  EXPECT_EQ(fs.tiled_fronts, 0);
  SCOPED_TRACE(std::string("blocks on host ") + (fs.contribution_blocks_on_host ? "yes" : "no") +
               ", factor resident " + (fs.factor_resident ? "yes" : "no") + ", batches " +
               std::to_string(fs.device_batches));
  const auto xg = gpu.solve(b);
  EXPECT_LT(test::backward_error(a, xg.data(), b.data()), 1e-14);
  EXPECT_LT(test::relative_difference(xg, xc), 1e-8);
  EXPECT_EQ(fs.inertia_positive, cpu.stats().factor.inertia_positive);
  EXPECT_EQ(fs.inertia_negative, cpu.stats().factor.inertia_negative);
  EXPECT_EQ(fs.perturbed_pivots, cpu.stats().factor.perturbed_pivots);

  o.device_memory_limit = static_cast<std::size_t>(4 * largest * largest);  // half a front
  Solver tight(o);
  try {
    tight.factorize(a);
    FAIL() << "expected NotSupported";
  } catch (const NotSupported& e) {
    EXPECT_NE(std::string(e.what()).find("LDLᵀ"), std::string::npos) << e.what();
  }
}

// The device memory the numeric work holds (pool, the arena's device part, the staging of
// a chunk's panels) stays within the budget whenever the pool leaves room for its own
// staging (a chunk's panels are at most its fronts' entries): the arena gives up the
// staging's share and spills that much more to the host. Budgets from twice the factor
// down to a fraction of it, Cholesky and LU; the solutions stay those of the CPU.
TEST_F(CudaMemory, WorkingMemoryStaysWithinTheBudget) {
  int spilled_with_room = 0;
  for (const MatrixType type : {MatrixType::spd, MatrixType::general}) {
    SparseMatrix a = generators::laplacian_3d(22, 22, 22);
    if (type == MatrixType::general) {
      a = expand_symmetric(a);
      auto rng = test::fresh_rng();
      std::uniform_real_distribution<double> u(0.5, 1.5);
      for (double& v : a.values) v *= u(rng);
    }
    Options o;
    o.num_gpus = 1;  // one GPU, whatever the machine has
    o.type = type;
    Solver cpu(o);
    cpu.factorize(a);
    std::vector<double> b(a.n_rows, 1.0);
    const auto xc = cpu.solve(b);
    const auto factor_bytes = static_cast<double>(cpu.stats().analysis.factor_bytes);
    for (const double share : {2.0, 0.9, 0.5, 0.3, 0.15}) {
      const auto limit = static_cast<std::size_t>(share * factor_bytes);
      SCOPED_TRACE(std::string(to_string(type)) + ", device_memory_limit " + std::to_string(limit));
      Options g = o;
      g.backend = Backend::cuda;
      g.device_memory_limit = limit;
      Solver gpu(g);
      gpu.factorize(a);
      const FactorStats& fs = gpu.stats().factor;
      EXPECT_EQ(fs.device_budget, limit);
      if (2 * fs.device_pool_bytes <= fs.device_budget) {
        EXPECT_LE(fs.device_working_bytes, fs.device_budget)
            << "pool " << fs.device_pool_bytes << ", factor resident " << fs.factor_resident;
        spilled_with_room += fs.contribution_blocks_on_host && !fs.factor_resident;
      }
      const auto xg = gpu.solve(b);
      EXPECT_LT(test::backward_error(a, xg.data(), b.data()), 1e-14);
      EXPECT_LT(test::relative_difference(xg, xc), 1e-8);
    }
  }
  // the case the accounting is for: blocks spilled beside a pool with room for its staging
  EXPECT_GT(spilled_with_room, 0);
}

// The host side of the plan: with the factor going to the host (a device budget below
// it), the page-locked buffers and the host factor stay within Options::host_memory_limit
// (the panels' buffers made smaller: more, smaller chunks) and the solution is unchanged.
// A limit below the host factor itself is refused at analysis with the bytes of the
// smallest plan, leaving no factor to solve with; that many bytes are then enough.
TEST_F(CudaMemory, HostMemoryLimitBoundsThePinnedBuffers) {
  SparseMatrix a = expand_symmetric(generators::laplacian_3d(22, 22, 22));
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(0.5, 1.5);
  for (double& v : a.values) v *= u(rng);
  Options o;
  o.num_gpus = 1;  // one GPU, whatever the machine has
  o.type = MatrixType::general;
  Solver cpu(o);
  cpu.factorize(a);
  std::vector<double> b(a.n_rows);
  for (double& v : b) v = u(rng);
  const auto xc = cpu.solve(b);
  const std::size_t factor = cpu.stats().analysis.factor_bytes;
  for (const std::size_t device : {factor / 3, factor}) {
    Options g = o;
    g.backend = Backend::cuda;
    g.device_memory_limit = device;
    Solver free_host(g);
    free_host.factorize(a);
    const FactorStats& f0 = free_host.stats().factor;
    ASSERT_FALSE(f0.factor_resident);
    EXPECT_GT(f0.host_pinned_bytes, 0u);
    // refused: less than the host factor
    std::size_t smallest = 0;
    {
      Options h = g;
      h.host_memory_limit = factor / 2;
      Solver s(h);
      try {
        s.factorize(a);
        ADD_FAILURE() << "expected OutOfMemory, device_memory_limit " << device;
      } catch (const OutOfMemory& e) {
        smallest = e.bytes_requested();
        EXPECT_GT(smallest, factor);
        EXPECT_NE(std::string(e.what()).find("host memory"), std::string::npos) << e.what();
      }
      EXPECT_THROW(s.solve(b), InvalidState);  // no factor that looks complete
    }
    for (const std::size_t host :
         {smallest, factor + f0.host_pinned_bytes / 2, factor + f0.host_pinned_bytes}) {
      SCOPED_TRACE("factor " + std::to_string(factor) + " bytes, device_memory_limit " +
                   std::to_string(device) + ", host_memory_limit " + std::to_string(host));
      Options h = g;
      h.host_memory_limit = host;
      Solver s(h);
      try {
        s.factorize(a);
      } catch (const OutOfMemory& e) {
        // only a limit below the smallest plan may be refused
        EXPECT_LT(host, smallest) << e.what();
        continue;
      }
      const FactorStats& fs = s.stats().factor;
      EXPECT_LE(fs.host_pinned_bytes + factor, host);
      EXPECT_LE(fs.host_pinned_bytes, f0.host_pinned_bytes);
      const auto x = s.solve(b);
      EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-14);
      EXPECT_LT(test::relative_difference(x, xc), 1e-8);
    }
  }
}

// A budget too small for even one slab of the largest front is refused with the bytes.
TEST_F(CudaMemory, ImpossibleBudgetNamesTheBytes) {
  const SparseMatrix a = generators::laplacian_3d(20, 20, 20);
  Options o;
  o.num_gpus = 1;  // one GPU, whatever the machine has
  o.type = MatrixType::spd;
  o.backend = Backend::cuda;
  o.device_memory_limit = 4096;
  Solver s(o);
  try {
    s.factorize(a);
    FAIL() << "expected OutOfMemory";
  } catch (const OutOfMemory& e) {
    EXPECT_GT(e.bytes_requested(), 4096u);
    EXPECT_NE(std::string(e.what()).find("device_memory_limit"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace strata
