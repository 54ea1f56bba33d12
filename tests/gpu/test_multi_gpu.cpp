// strata — multi-GPU tests (ctest label `gpu`): the tree split over 2 and 4 GPUs, one
// CUDA executor per GPU (numeric/multi_device.cpp), checked against one GPU and the CPU on
// the same analysis, through the Solver (solve, refactorization, per-GPU statistics),
// with a slowed GPU whose subtrees are stolen, with the top part split into upper layers
// (on by default; one test asserts it and compares with the split off), for spd,
// symmetric indefinite and general matrices, with large fronts' updates split over the
// idle GPUs and with top fronts factored over all GPUs (both forced onto small fronts), and
// the solve run part by part on the GPUs that hold the parts' panels. Each test
// skips, with a message, where fewer GPUs are visible than it needs (or the build has no CUDA
// backend).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "analysis/analysis.hpp"
#include "numeric/driver.hpp"
#include "numeric/factor.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

#define REQUIRE_GPUS(k)                                                        \
  if (numeric::cuda_device_count() < (k))                                      \
  GTEST_SKIP() << (k) << " CUDA GPUs needed, " << numeric::cuda_device_count() \
               << " visible (or this build has no CUDA backend): multi-GPU test skipped"

using Problem = test::NamedMatrix;

// The references of a multi-GPU factor of `an`: the CPU's (2 threads) and GPU 0's alone
// (its panels fetched to the host).
void reference_factors(const Analysis& an, const std::vector<double>& v, MatrixType type,
                       double pivot, const Options& o, numeric::NumericFactor& cpu_f,
                       numeric::NumericFactor& gpu1_f) {
  std::vector<double> arena;
  numeric::factorize(an, v, type, pivot, *numeric::make_cpu_executor(2), cpu_f, arena);
  auto gpu1 = numeric::make_cuda_executor(o, 0);
  numeric::factorize(an, v, type, pivot, *gpu1, gpu1_f, arena);
  numeric::fetch_panels(an, *gpu1, gpu1_f);
}

// A right-hand side of n entries drawn afresh from U(−1, 1).
std::vector<double> random_rhs(index_t n, std::mt19937_64& rng) {
  std::vector<double> b(static_cast<std::size_t>(n));
  std::uniform_real_distribution<double> u(-1, 1);
  for (double& x : b) x = u(rng);
  return b;
}

// Through the Solver on `gpus` GPUs with options o: factorize, refactorize, then a solve
// with b whose backward error must be at most 1e-14. Returns the per-GPU statistics of
// the refactorization.
std::vector<DeviceStats> refactorize_and_solve(const test::NamedMatrix& pr, Options o, int gpus,
                                               const std::vector<double>& b) {
  o.backend = Backend::cuda;
  o.num_gpus = gpus;
  Solver s(o);
  s.factorize(pr.a);
  s.refactorize(pr.a);
  const auto x = s.solve(b);
  EXPECT_LE(test::backward_error(pr.a, x.data(), b.data()), 1e-14);
  return s.stats().factor.devices;
}

// One CUDA executor on each of GPUs 0 .. gpus − 1.
struct GpuExecutors {
  std::vector<std::unique_ptr<numeric::Executor>> owned;
  std::vector<numeric::Executor*> execs;
  GpuExecutors(const Options& o, int gpus) {
    for (int d = 0; d < gpus; ++d) {
      owned.push_back(numeric::make_cuda_executor(o, d));
      execs.push_back(owned.back().get());
    }
  }
};

std::vector<Problem> problems(std::mt19937_64& rng) {
  std::vector<Problem> p;
  p.push_back({"lap3d 22", generators::laplacian_3d(22, 22, 22), MatrixType::spd});
  p.push_back({"elasticity 10", generators::elasticity_3d(10, 10, 10), MatrixType::spd});
  p.push_back(
      {"bcsstk16", read_matrix_market(test::matrix_path("bcsstk16")).matrix, MatrixType::spd});
  p.push_back(
      {"random spd 733", test::random_sparse(733, 3, test::RandomKind::spd, rng), MatrixType::spd});
  p.push_back({"hangGlider_2", read_matrix_market(test::matrix_path("hangGlider_2")).matrix,
               MatrixType::symmetric_indefinite});
  p.push_back({"random kkt 733", test::random_kkt(733, rng), MatrixType::symmetric_indefinite});
  {  // shifted Laplacian: indefinite with a positive diagonal, large LDLᵀ fronts
    SparseMatrix a = generators::laplacian_3d(18, 18, 18);
    for (index_t j = 0; j < a.n_cols; ++j)
      for (index_t q = a.offsets[j]; q < a.offsets[j + 1]; ++q)
        if (a.indices[q] == j) a.values[q] -= 2.5;
    p.push_back({"shifted lap3d 18", std::move(a), MatrixType::symmetric_indefinite});
  }
  {
    SparseMatrix a = expand_symmetric(generators::elasticity_3d(8, 8, 8));
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& v : a.values) v *= u(rng);  // unsymmetric values: large LU fronts
    p.push_back({"unsymmetric elasticity 8", std::move(a), MatrixType::general});
  }
  p.push_back(
      {"watt_2", read_matrix_market(test::matrix_path("watt_2")).matrix, MatrixType::general});
  p.push_back({"random general 1500", test::random_sparse(1500, 4, test::RandomKind::general, rng),
               MatrixType::general});
  return p;
}

// x (tree numbering) = A⁻¹ b from a factor, without refinement: the scaling and
// permutations the Solver applies, then solve_in_place.
std::vector<double> solve_with(const Analysis& an, const numeric::NumericFactor& f,
                               const std::vector<double>& b) {
  const index_t n = an.n;
  const bool scale = !an.row_scaling.empty(), match = !an.matching_perm.empty();
  std::vector<double> w(n), x(n);
  for (index_t k = 0; k < n; ++k) {
    const index_t i = an.perm[k];
    w[k] = b[i] * (scale ? an.row_scaling[i] : 1.0);
  }
  numeric::solve_in_place(an, f, w.data(), 1);
  for (index_t k = 0; k < n; ++k) {
    const index_t col = match ? an.matching_perm[an.perm[k]] : an.perm[k];
    x[col] = w[k] * (scale ? an.col_scaling[col] : 1.0);
  }
  return x;
}

void factor_on_gpus(int gpus) {
  auto rng = test::fresh_rng();
  for (const Problem& pr : problems(rng)) {
    SCOPED_TRACE(pr.name + ", " + std::to_string(gpus) + " GPUs");
    Options o;
    o.type = pr.type;
    const Analysis an = analyze_matrix(pr.a, o, gpus);
    ASSERT_EQ(an.partition.workers, gpus);
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
    numeric::NumericFactor cpu_f, gpu1_f, multi_f;
    reference_factors(an, v, pr.type, pivot, o, cpu_f, gpu1_f);
    const GpuExecutors gpu(o, gpus);
    const std::vector<numeric::Executor*>& execs = gpu.execs;
    std::vector<std::vector<double>> arenas;
    std::vector<DeviceStats> dev;
    numeric::factorize_multi(an, v, pr.type, pivot, execs, multi_f, arenas, {}, &dev);
    // every front was factored by one GPU as on one GPU alone, or (a top front of at
    // least distributed_front_min_rows rows) over all of them, which sums in another order
    EXPECT_LT(test::relative_difference(multi_f.panels, gpu1_f.panels), 1e-13);
    {  // the parts' panels kept on the GPUs, then fetched: the same factor
      numeric::NumericFactor kept_f;
      numeric::MultiWorkerConfig keep;
      keep.keep_panels_on_devices = true;
      numeric::factorize_multi(an, v, pr.type, pivot, execs, kept_f, arenas, keep, nullptr);
      // LDLᵀ's bookkeeping reads the host panels: no part is kept then
      EXPECT_EQ(kept_f.held.empty(), pr.type == MatrixType::symmetric_indefinite);
      for (const numeric::HeldPanels& h : kept_f.held) {
        EXPECT_GE(h.part, 0);
        EXPECT_LT(h.worker, static_cast<int>(execs.size()));
      }
      numeric::fetch_panels(an, execs, kept_f);
      EXPECT_LT(test::relative_difference(kept_f.panels, gpu1_f.panels), 1e-13);
      EXPECT_EQ(kept_f.rows, multi_f.rows);
    }
    {  // the multi-worker driver: every part solved on the GPU holding it, 1 and 3
       // right-hand sides, against the host solve with GPU 0's factor
      numeric::MultiWorkerConfig keep;
      keep.keep_panels_on_devices = true;
      auto driver = numeric::make_multi_worker_driver(o, gpus, 0, keep);
      numeric::NumericFactor f;
      driver->factorize(an, v, false, pr.type, pivot, f);
      const bool held = pr.type != MatrixType::symmetric_indefinite;
      for (int id = 0; id < an.partition.n_parts(); ++id) {  // every part with fronts, on its GPU
        const bool listed =
            std::any_of(f.held.begin(), f.held.end(),
                        [id](const numeric::HeldPanels& h) { return h.part == id; });
        if (!an.partition.part(id).fronts.empty()) EXPECT_EQ(listed, held) << "part " << id;
      }
      for (index_t nrhs : {1, 3}) {
        std::vector<double> x(static_cast<std::size_t>(an.n * nrhs));
        std::uniform_real_distribution<double> u(-1, 1);
        for (double& e : x) e = u(rng);
        std::vector<double> ref = x;
        numeric::solve_in_place(an, gpu1_f, ref.data(), nrhs);
        EXPECT_EQ(driver->solve(an, f, x.data(), nrhs), held) << nrhs << " right-hand sides";
        EXPECT_LT(test::relative_difference(x, ref), 1e-8) << nrhs << " right-hand sides";
      }
    }
    EXPECT_EQ(multi_f.rows, gpu1_f.rows);
    if (pr.type == MatrixType::spd) {  // no pivoting: entrywise against the CPU
      EXPECT_LT(test::relative_difference(multi_f.panels, cpu_f.panels), 1e-12);
      EXPECT_EQ(multi_f.rows, cpu_f.rows);
    }
    const std::vector<double> b = random_rhs(pr.a.n_rows, rng);
    const auto xm = solve_with(an, multi_f, b), xc = solve_with(an, cpu_f, b);
    EXPECT_LT(test::relative_difference(xm, xc), 1e-8);
    ASSERT_EQ(dev.size(), static_cast<std::size_t>(gpus));
    index_t run = 0, upper_run = 0;
    for (int d = 0; d < gpus; ++d) {
      EXPECT_EQ(dev[d].device, "cuda:" + std::to_string(d));
      run += dev[d].subtrees_run;
      upper_run += dev[d].upper_parts_run;
    }
    EXPECT_EQ(run, static_cast<index_t>(an.partition.subtrees.size()));
    EXPECT_EQ(upper_run, static_cast<index_t>(an.partition.upper.size()));
  }
}

TEST(MultiGpu, TwoGpusMatchOneGpuAndCpu) {
  REQUIRE_GPUS(2);
  factor_on_gpus(2);
}

TEST(MultiGpu, FourGpusMatchOneGpuAndCpu) {
  REQUIRE_GPUS(4);
  factor_on_gpus(4);
}

// Through the Solver: num_gpus 2 and 4 against the CPU backend; refactorization with new
// values agrees with a fresh factorization on the same analysis; per-GPU statistics.
TEST(MultiGpu, SolverSolutionsAndRefactorization) {
  REQUIRE_GPUS(2);
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1), scale(0.8, 1.2);
  for (int gpus : {2, 4}) {
    if (numeric::cuda_device_count() < gpus) continue;
    for (const Problem& pr : problems(rng)) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(gpus) + " GPUs");
      const SparseMatrix& a = pr.a;
      std::vector<double> b(a.n_rows);
      for (double& x : b) x = u(rng);
      Options o;
      o.type = pr.type;
      Solver cpu(o);
      o.backend = Backend::cuda;
      o.num_gpus = gpus;
      Solver gpu(o);
      cpu.factorize(a);
      gpu.factorize(a);
      const auto xc = cpu.solve(b), xg = gpu.solve(b);
      const Stats& st = gpu.stats();
      EXPECT_EQ(st.analysis.workers, gpus);
      EXPECT_EQ(st.factor.backend, Backend::cuda);
      EXPECT_FALSE(st.factor.factor_resident);
      ASSERT_EQ(st.factor.devices.size(), static_cast<std::size_t>(gpus));
      index_t run = 0;
      for (const auto& d : st.factor.devices) run += d.subtrees_run;
      EXPECT_EQ(run, st.analysis.subtrees);
      EXPECT_LE(test::backward_error(a, xg.data(), b.data()), 1e-14);
      EXPECT_LT(test::relative_difference(xg, xc), 1e-8);
      // each part solved on the GPU that holds its panels (not LDLᵀ, whose parts go to the
      // host; nor a factor whose pivots were delayed on the host)
      if (!st.factor.delayed_pivoting)
        EXPECT_EQ(st.solve.on_device, pr.type != MatrixType::symmetric_indefinite);
      SparseMatrix a2 = a;
      std::vector<double> d(a.n_rows);
      for (double& x : d) x = scale(rng);
      for (index_t j = 0; j < a2.n_cols; ++j)
        for (index_t p = a2.offsets[j]; p < a2.offsets[j + 1]; ++p)
          a2.values[p] *= d[a2.indices[p]] * d[j];
      gpu.refactorize(a2);
      const auto x2 = gpu.solve(b);
      if (!gpu.stats().factor.delayed_pivoting)  // the refactorization's rows and panels
        EXPECT_EQ(gpu.stats().solve.on_device, pr.type != MatrixType::symmetric_indefinite);
      Solver fresh(o);
      fresh.analyze(a);
      fresh.factorize(a2);
      EXPECT_LT(test::relative_difference(x2, fresh.solve(b)), 1e-12);
      EXPECT_LE(test::backward_error(a2, x2.data(), b.data()), 1e-14);
    }
  }
}

// The value pass with two GPUs: the first GPU checks and scales the values, the other
// copies its result (MultiWorkerDriver::scale_values_on_device). For LU, LLᵀ/LDLᵀ
// (automatic) and LDLᵀ, sizes 1 to 733, a factorization and a refactorization in the
// analyzed pattern take it, the same matrices given with explicit zeros (not the analyzed
// pattern) take the host's pass; the scaled values are the same bits, so the factors
// agree: the same static pivots and determinant sign, log |det| and the unrefined
// solutions to rounding (the two factorizations may assemble a front's children in
// another order), ‖B‖₁ to rounding.
TEST(MultiGpu, ValuePassOnTheFirstGpuGivesTheHostsFactor) {
  REQUIRE_GPUS(2);
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  std::uniform_real_distribution<double> rhs(-1.0, 1.0);
  for (const test::ValueChange& c : test::value_changes(rng)) {
    SCOPED_TRACE("type " + std::string(to_string(c.type)) + ", n = " + std::to_string(c.n));
    Options o;
    o.backend = Backend::cuda;
    o.num_gpus = 2;
    o.type = c.type;
    o.refinement_max_steps = 0;  // one application of the factor
    o.gmres_max_iterations = 0;
    o.solve_check = SolveCheck::after_perturbed_pivots;
    Solver dev(o), host(o);
    dev.analyze(c.a);
    host.analyze(c.a);
    dev.factorize(c.a);
    host.factorize(test::with_duplicate_zeros(c.a));
    EXPECT_TRUE(dev.stats().factor.values_scaled_on_device);
    EXPECT_FALSE(host.stats().factor.values_scaled_on_device);
    EXPECT_EQ(dev.stats().factor.devices.size(), 2u);
    dev.refactorize(c.next);
    host.refactorize(test::with_duplicate_zeros(c.next));
    const FactorStats& fd = dev.stats().factor;
    const FactorStats& fh = host.stats().factor;
    EXPECT_TRUE(fd.values_scaled_on_device);
    EXPECT_FALSE(fh.values_scaled_on_device);
    EXPECT_EQ(fd.type, fh.type);
    EXPECT_EQ(fd.perturbed_pivots, fh.perturbed_pivots);
    EXPECT_EQ(fd.determinant_sign, fh.determinant_sign);
    EXPECT_NEAR(fd.matrix_norm, fh.matrix_norm, 1e-14 * fh.matrix_norm);
    EXPECT_NEAR(fd.log_abs_determinant, fh.log_abs_determinant,
                1e-12 * std::max(1.0, std::abs(fh.log_abs_determinant)));
    std::vector<double> b(c.n);
    for (double& v : b) v = rhs(rng);
    const std::vector<double> xd = dev.solve(b), xh = host.solve(b);
    if (fh.perturbed_pivots == 0) {
      EXPECT_LT(test::relative_difference(xd, xh), 1e-10);
      EXPECT_LE(test::backward_error(c.next, xd.data(), b.data()), 1e-12);
    }
  }
}

// GPU 0 slowed by an injected delay: the other GPUs steal its subtrees; same factor.
TEST(MultiGpu, SlowGpuHasItsSubtreesStolen) {
  REQUIRE_GPUS(2);
  for (int gpus : {2, 4}) {
    if (numeric::cuda_device_count() < gpus) continue;
    SCOPED_TRACE(std::to_string(gpus) + " GPUs");
    const SparseMatrix a = generators::laplacian_3d(24, 24, 24);
    Options o;
    o.type = MatrixType::spd;
    o.subtrees_per_gpu = 4;  // several subtrees per GPU, to steal
    const Analysis an = analyze_matrix(a, o, gpus);
    std::vector<int> own(gpus, 0);
    for (int w : an.partition.owner) ++own[w];
    // slow the GPU with the most subtrees: largest-first may give GPU 0 a single large one
    const int slow = static_cast<int>(std::max_element(own.begin(), own.end()) - own.begin());
    ASSERT_GE(own[slow], 2);
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, a, &pivot);
    const GpuExecutors gpu(o, gpus);
    const std::vector<numeric::Executor*>& execs = gpu.execs;
    numeric::NumericFactor plain, slowed;
    std::vector<std::vector<double>> arenas;
    std::vector<DeviceStats> dev;
    numeric::factorize_multi(an, v, MatrixType::spd, pivot, execs, plain, arenas, {}, nullptr);
    numeric::MultiWorkerConfig cfg;
    cfg.before_subtree = [slow](int w, int) { test::sleep_if(w == slow, 0.5); };
    numeric::factorize_multi(an, v, MatrixType::spd, pivot, execs, slowed, arenas, cfg, &dev);
    index_t stolen = 0;
    for (int d = 0; d < gpus; ++d)
      if (d != slow) stolen += dev[d].subtrees_stolen;
    EXPECT_GT(stolen, 0);
    EXPECT_LT(dev[slow].subtrees_run, own[slow]);
    EXPECT_LT(test::relative_difference(slowed.panels, plain.panels), 1e-13);
  }
}

// The top part split into upper layers (asserted: lap3d 20 and its shifted and
// unsymmetric forms have them; lap3d 30's top is one chain, no layer) on 2 and 4 GPUs, where an
// upper part imports blocks from several GPUs (peer copies or host memory): the factor agrees with
// one GPU on the same analysis and with the split off, also with the panels kept on the GPUs and
// fetched, and the solution with the CPU's; through the Solver, with split_top on and off.
TEST(MultiGpu, UpperLayersMatchOneGpuAndCpu) {
  REQUIRE_GPUS(2);
  auto rng = test::fresh_rng();
  std::vector<Problem> ps;
  const SparseMatrix lap = generators::laplacian_3d(20, 20, 20);
  ps.push_back({"lap3d 20", lap, MatrixType::spd});
  {
    SparseMatrix a = generators::laplacian_3d(20, 20, 20);
    for (index_t j = 0; j < a.n_cols; ++j)
      for (index_t q = a.offsets[j]; q < a.offsets[j + 1]; ++q)
        if (a.indices[q] == j) a.values[q] -= 2.5;
    ps.push_back({"shifted lap3d 20", std::move(a), MatrixType::symmetric_indefinite});
  }
  {
    SparseMatrix a = expand_symmetric(generators::laplacian_3d(20, 20, 20));
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& v : a.values) v *= u(rng);
    ps.push_back({"unsymmetric lap3d 20", std::move(a), MatrixType::general});
  }
  for (int gpus : {2, 4}) {
    if (numeric::cuda_device_count() < gpus) continue;
    for (const Problem& pr : ps) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(gpus) + " GPUs");
      Options o;
      o.type = pr.type;
      o.subtrees_per_gpu = 4;  // upper layers on these grids (asserted)
      const Analysis an = analyze_matrix(pr.a, o, gpus);
      ASSERT_GE(an.partition.n_upper_layers(), 1) << "no upper layer: the test would be vacuous";
      o.split_top = false;
      const Analysis off = analyze_matrix(pr.a, o, gpus);
      ASSERT_EQ(off.partition.n_upper_layers(), 0);
      ASSERT_EQ(off.tree.parent, an.tree.parent);
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
      numeric::NumericFactor cpu_f, gpu1_f, on_f, off_f, kept_f;
      reference_factors(an, v, pr.type, pivot, o, cpu_f, gpu1_f);
      const GpuExecutors gpu(o, gpus);
      const std::vector<numeric::Executor*>& execs = gpu.execs;
      std::vector<std::vector<double>> arenas;
      std::vector<DeviceStats> dev;
      numeric::factorize_multi(an, v, pr.type, pivot, execs, on_f, arenas, {}, &dev);
      EXPECT_LT(test::relative_difference(on_f.panels, gpu1_f.panels), 1e-13);
      EXPECT_EQ(on_f.rows, gpu1_f.rows);
      index_t upper_run = 0;
      for (int d = 0; d < gpus; ++d) {
        index_t own = 0;
        for (int w : an.partition.upper_owner) own += w == d;
        EXPECT_EQ(dev[d].upper_parts_run, own);
        upper_run += dev[d].upper_parts_run;
      }
      EXPECT_EQ(upper_run, static_cast<index_t>(an.partition.upper.size()));
      numeric::MultiWorkerConfig keep;
      keep.keep_panels_on_devices = true;
      numeric::factorize_multi(an, v, pr.type, pivot, execs, kept_f, arenas, keep, nullptr);
      numeric::fetch_panels(an, execs, kept_f);
      EXPECT_LT(test::relative_difference(kept_f.panels, gpu1_f.panels), 1e-13);
      // the executors re-plan their parts for the other analysis
      numeric::factorize_multi(off, v, pr.type, pivot, execs, off_f, arenas, {}, nullptr);
      EXPECT_LT(test::relative_difference(off_f.panels, gpu1_f.panels), 1e-13);
      if (pr.type == MatrixType::spd)
        EXPECT_LT(test::relative_difference(on_f.panels, cpu_f.panels), 1e-12);
      const std::vector<double> b = random_rhs(pr.a.n_rows, rng);
      const auto xc = solve_with(an, cpu_f, b);
      EXPECT_LT(test::relative_difference(solve_with(an, on_f, b), xc), 1e-8);
      EXPECT_LT(test::relative_difference(solve_with(an, kept_f, b), xc), 1e-8);
      for (bool split : {true, false}) {
        Options so;
        so.type = pr.type;
        so.backend = Backend::cuda;
        so.num_gpus = gpus;
        so.subtrees_per_gpu = 4;
        so.split_top = split;
        Solver s(so);
        s.factorize(pr.a);
        EXPECT_EQ(s.stats().analysis.upper_layers > 0, split);
        const auto x = s.solve(b);
        EXPECT_LE(test::backward_error(pr.a, x.data(), b.data()), 1e-14);
        EXPECT_LT(test::relative_difference(x, solve_with(an, cpu_f, b)), 1e-8);
      }
    }
  }
}

// Fronts whose update is split by column strips over the idle GPUs (split_update.cu),
// forced onto every eligible front (split_front_min_cb 1; panel kernels off, so every
// LLᵀ front takes the library path): LLᵀ factors agree entrywise with one GPU and the
// CPU, LU solutions with the CPU's; some fronts were split and helpers computed strips
// (bytes counted); through the Solver the per-GPU statistics show it too.
TEST(MultiGpu, SplitFrontUpdatesMatchOneGpuAndCpu) {
  REQUIRE_GPUS(2);
  auto rng = test::fresh_rng();
  std::vector<Problem> ps;
  ps.push_back({"lap3d 26", generators::laplacian_3d(26, 26, 26), MatrixType::spd});
  ps.push_back({"elasticity 16", generators::elasticity_3d(16, 16, 16), MatrixType::spd});
  {  // top separators of over 256 rows (large fronts) at 2 GPUs already
    SparseMatrix a = expand_symmetric(generators::laplacian_3d(24, 24, 24));
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& v : a.values) v *= u(rng);
    ps.push_back({"unsymmetric lap3d 24", std::move(a), MatrixType::general});
  }
  for (int gpus : {2, 3, 4}) {
    if (numeric::cuda_device_count() < gpus) continue;
    for (const Problem& pr : ps) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(gpus) + " GPUs");
      Options o;
      o.type = pr.type;
      o.split_front_min_cb = 1;
      o.gpu_panel_kernel_max_pivots = 0;
      // Only the top part's fronts are split (upper parts run while other GPUs may be
      // busy), and a root front has no update to split: the top part must hold a separator
      // chain. Without upper layers it is all of the tree above the subtrees; with 512-pivot
      // separator blocks the root separators of these problems are chains (with 1024, lap3d
      // 26's and unsymmetric lap3d 24's root fronts have 10 and 8 children, enough subtrees,
      // and the top part was the root front alone: checked on the analysis on the host).
      o.max_block_size = 512;
      o.split_top = false;
      o.subtrees_per_gpu = 4;
      const Analysis an = analyze_matrix(pr.a, o, gpus);
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
      numeric::NumericFactor cpu_f, gpu1_f, split_f;
      reference_factors(an, v, pr.type, pivot, o, cpu_f, gpu1_f);
      const GpuExecutors gpu(o, gpus);
      std::vector<std::vector<double>> arenas;
      std::vector<DeviceStats> dev;
      numeric::factorize_multi(an, v, pr.type, pivot, gpu.execs, split_f, arenas, {}, &dev);
      index_t split = 0, strips = 0;
      std::size_t bytes = 0;
      for (const DeviceStats& d : dev) {
        split += d.fronts_split;
        strips += d.strips_helped;
        bytes += d.bytes_transferred;
      }
      EXPECT_GT(split, 0) << "no front was split: the test would be vacuous";
      EXPECT_GT(strips, 0);
      EXPECT_GT(bytes, 0u);
      EXPECT_EQ(dev[0].strips_helped, 0) << "GPU 0 factors the top part: it helps nobody there";
      if (pr.type == MatrixType::spd) {
        EXPECT_LT(test::relative_difference(split_f.panels, gpu1_f.panels), 1e-13);
        EXPECT_LT(test::relative_difference(split_f.panels, cpu_f.panels), 1e-12);
        EXPECT_EQ(split_f.rows, cpu_f.rows);
      }
      const std::vector<double> b = random_rhs(pr.a.n_rows, rng);
      EXPECT_LT(test::relative_difference(solve_with(an, split_f, b), solve_with(an, cpu_f, b)),
                1e-8);
      // through the Solver, refactorization included
      index_t solver_split = 0;
      for (const DeviceStats& d : refactorize_and_solve(pr, o, gpus, b))
        solver_split += d.fronts_split;
      EXPECT_GT(solver_split, 0);
    }
  }
}

// Fronts factored whole over the idle GPUs, columns in blocks of 512 dealt out
// cyclically (distributed_front.cu), forced onto every top-part front with enough columns
// (distributed_front_min_rows 1; panel kernels off): the LLᵀ factor agrees entrywise with
// one GPU's and the CPU's, on fronts of several pivot blocks (lap3d 40's root separator
// has 1,600 pivots: 4 blocks, so the lookahead and every GPU's panels are exercised), in
// random-valued SPD matrices of awkward sizes too; the Solver's refactorization and
// statistics show it. A negative pivot placed in the root front's second block (held by
// GPU 1) is reported at the same column as on the CPU: the per-block statuses gathered
// from the GPUs give the front's status as one POTRF would.
TEST(MultiGpu, DistributedFrontsMatchOneGpuAndCpu) {
  REQUIRE_GPUS(2);
  auto rng = test::fresh_rng();
  std::vector<Problem> ps;
  ps.push_back({"lap3d 40", generators::laplacian_3d(40, 40, 40), MatrixType::spd});
  ps.push_back({"elasticity 15", generators::elasticity_3d(15, 15, 15), MatrixType::spd});
  {  // random positive values on lap3d 33's pattern, made diagonally dominant
    SparseMatrix a = generators::laplacian_3d(33, 33, 33);
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (index_t j = 0; j < a.n_cols; ++j)
      for (index_t q = a.offsets[j]; q < a.offsets[j + 1]; ++q)
        a.values[q] = a.indices[q] == j ? 7.0 + u(rng) : -u(rng);
    ps.push_back({"random-valued lap3d 33", std::move(a), MatrixType::spd});
  }
  for (int gpus : {2, 3, 4}) {
    if (numeric::cuda_device_count() < gpus) continue;
    for (const Problem& pr : ps) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(gpus) + " GPUs");
      Options o;
      o.type = pr.type;
      o.distributed_front_min_rows = 1;
      o.gpu_panel_kernel_max_pivots = 0;
      o.max_block_size = 4096;  // the CUDA backend's: separators of up to 4,096 pivots
      o.split_top = false;
      o.subtrees_per_gpu = 2;
      const Analysis an = analyze_matrix(pr.a, o, gpus);
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
      numeric::NumericFactor cpu_f, gpu1_f, dist_f;
      reference_factors(an, v, pr.type, pivot, o, cpu_f, gpu1_f);
      const GpuExecutors gpu(o, gpus);
      std::vector<std::vector<double>> arenas;
      std::vector<DeviceStats> dev;
      numeric::factorize_multi(an, v, pr.type, pivot, gpu.execs, dist_f, arenas, {}, &dev);
      index_t distributed = 0;
      for (const DeviceStats& d : dev) distributed += d.fronts_distributed;
      EXPECT_GT(distributed, 0) << "no front was distributed: the test would be vacuous";
      EXPECT_EQ(dev[0].fronts_distributed, distributed) << "only GPU 0 owns top fronts";
      EXPECT_GT(dev[1].bytes_transferred, 0u);
      EXPECT_LT(test::relative_difference(dist_f.panels, gpu1_f.panels), 1e-12);
      EXPECT_LT(test::relative_difference(dist_f.panels, cpu_f.panels), 1e-12);
      EXPECT_EQ(dist_f.rows, cpu_f.rows);
      const std::vector<double> b = random_rhs(pr.a.n_rows, rng);
      EXPECT_LT(test::relative_difference(solve_with(an, dist_f, b), solve_with(an, cpu_f, b)),
                1e-10);
      // through the Solver, refactorization included
      index_t solver_distributed = 0;
      for (const DeviceStats& d : refactorize_and_solve(pr, o, gpus, b))
        solver_distributed += d.fronts_distributed;
      EXPECT_GT(solver_distributed, 0);
    }
    // not positive definite in the root front's second column block
    SCOPED_TRACE("negative pivot, " + std::to_string(gpus) + " GPUs");
    SparseMatrix a = generators::laplacian_3d(40, 40, 40);
    Options o;
    o.type = MatrixType::spd;
    o.distributed_front_min_rows = 1;
    o.gpu_panel_kernel_max_pivots = 0;
    o.max_block_size = 4096;
    o.split_top = false;
    o.subtrees_per_gpu = 2;
    const Analysis an = analyze_matrix(a, o, gpus);  // the pattern's: values changed below
    const index_t root = an.tree.n_fronts() - 1;
    ASSERT_EQ(an.tree.parent[root], -1);
    ASSERT_GT(an.tree.n_pivots(root), 600) << "the root front has no second block";
    const index_t n = a.n_rows;
    const index_t target = an.perm[n - an.tree.n_pivots(root) + 600];  // its 601st pivot
    for (index_t q = a.offsets[target]; q < a.offsets[target + 1]; ++q)
      if (a.indices[q] == target) a.values[q] = -100.0;
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, a, &pivot);
    index_t cpu_column = -1, gpu_column = -2;
    try {
      numeric::NumericFactor f;
      std::vector<double> arena;
      numeric::factorize(an, v, MatrixType::spd, pivot, *numeric::make_cpu_executor(2), f, arena);
    } catch (const NotPositiveDefinite& e) {
      cpu_column = e.column();
    }
    try {
      const GpuExecutors gpu(o, gpus);
      std::vector<std::vector<double>> arenas;
      numeric::NumericFactor f;
      numeric::factorize_multi(an, v, MatrixType::spd, pivot, gpu.execs, f, arenas, {}, nullptr);
    } catch (const NotPositiveDefinite& e) {
      gpu_column = e.column();
    }
    EXPECT_GE(cpu_column, 0) << "the CPU found no negative pivot";
    EXPECT_EQ(gpu_column, cpu_column);
  }
}

// Solvers one after another in one process, each with the default options on two GPUs
// (distributed top fronts included): the first distributed front grows the work buffers of
// the lanes the plan sized for its own part, while earlier fronts on those lanes may still
// run. Each solution's backward error is checked, and the fronts distributed are counted
// so that the test is not vacuous.
TEST(MultiGpu, SolversOneAfterAnotherWithDistributedFronts) {
  REQUIRE_GPUS(2);
  auto rng = test::fresh_rng();
  const test::NamedMatrix pr{"lap3d 60", generators::laplacian_3d(60, 60, 60), MatrixType::spd};
  const std::vector<double> b = random_rhs(pr.a.n_rows, rng);
  for (int round = 0; round < 3; ++round) {
    SCOPED_TRACE("solver " + std::to_string(round + 1));
    Options o;
    o.type = pr.type;
    index_t distributed = 0;
    for (const DeviceStats& d : refactorize_and_solve(pr, o, 2, b))
      distributed += d.fronts_distributed;
    EXPECT_GT(distributed, 0) << "no front was distributed: the test would be vacuous";
  }
}

// Asking for more GPUs than are visible is refused clearly, at analyze.
TEST(MultiGpu, TooManyGpusIsRefused) {
  REQUIRE_GPUS(1);
  const SparseMatrix a = generators::laplacian_3d(8, 8, 8);
  Options o;
  o.backend = Backend::cuda;
  o.num_gpus = numeric::cuda_device_count() + 1;
  Solver too_many(o);
  EXPECT_THROW(too_many.analyze(a), InvalidInput);
}

}  // namespace
}  // namespace strata
