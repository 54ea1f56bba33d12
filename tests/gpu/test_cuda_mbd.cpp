// strata::mbd on the CUDA backend: the engine's Newton loop on a GPU factors in the
// analysis's order until a refactorization needs static pivots, then delays pivots on the
// host (mbd/linear_solver.hpp); with Pivoting::corrected it keeps the GPU and corrects
// those pivots in the solve, delaying only where a correction cannot be made accurately.
// Either way no analysis is made for perturbed pivots, none are left, and the trajectory
// equals the CPU backend's (which delays pivots at every refactorization).
#include <gtest/gtest.h>

#include <string>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "numeric/factor.hpp"
#include "support/mbd_test_support.hpp"

namespace strata::mbd {
namespace {

// tracked:100 to t = 0.1 on the GPU with `pivoting` and on the CPU, side by side (positions
// within 1e-8 at every step); returns the GPU run's statistics.
IntegratorStats gpu_against_cpu(Pivoting pivoting) {
  const Model m = build_model(generate("tracked:100"), "tracked:100");
  IntegratorOptions o;
  o.t_end = 0.1;
  o.newton_rtol = 1e-10;
  o.newton_atol = 1e-12;
  IntegratorOptions on_gpu = o, on_cpu = o;
  on_gpu.solver.backend = Backend::cuda;
  on_gpu.solver.pivoting = pivoting;
  on_cpu.solver.backend = Backend::cpu;
  Integrator gpu(m, on_gpu), cpu(m, on_cpu);
  double worst = 0;
  test::step_side_by_side(gpu, cpu, 1e-8, &worst);
  const IntegratorStats& s = gpu.stats();
  EXPECT_EQ(s.reanalyses, 0);
  EXPECT_EQ(s.perturbed_pivots, 0);
  EXPECT_NE(s.solver.find("cuda"), std::string::npos) << s.solver;
  // the solves after factorizations in the analysis's order (corrected or not) run on the
  // GPU, those after delayed ones on the host; the CPU backend's never on a GPU
  EXPECT_GT(s.device_solves, 0);
  EXPECT_LE(s.device_solves, s.solves);
  EXPECT_LE(s.device_solve_seconds, s.solve_seconds);
  EXPECT_EQ(cpu.stats().device_solves, 0);
  EXPECT_EQ(cpu.stats().corrected_factorizations, 0);
  ::testing::Test::RecordProperty("largest position difference", test::scientific(worst));
  ::testing::Test::RecordProperty(
      "solves on the GPU", std::to_string(s.device_solves) + " of " + std::to_string(s.solves));
  ::testing::Test::RecordProperty(
      "delayed factorizations",
      std::to_string(s.delayed_factorizations) + " of " + std::to_string(s.factorizations));
  ::testing::Test::RecordProperty("corrected factorizations",
                                  std::to_string(s.corrected_factorizations) + " (" +
                                      std::to_string(s.corrected_pivots) + " pivots)");
  return s;
}

TEST(CudaMbd, StaticPivotsAreDelayedAndTheTrajectoryEqualsTheCpus) {
  if (!numeric::cuda_available())
    GTEST_SKIP() << "no CUDA GPU present (or this build has no CUDA backend): GPU test skipped";
  const IntegratorStats s = gpu_against_cpu(Pivoting::automatic);
  EXPECT_EQ(s.corrected_factorizations, 0);
  EXPECT_GT(s.delayed_factorizations, 0);  // the drifting values need static pivots
}

TEST(CudaMbd, StaticPivotsAreCorrectedAndTheTrajectoryEqualsTheCpus) {
  if (!numeric::cuda_available())
    GTEST_SKIP() << "no CUDA GPU present (or this build has no CUDA backend): GPU test skipped";
  const IntegratorStats s = gpu_against_cpu(Pivoting::corrected);
  EXPECT_GT(s.corrected_factorizations, 0);
}

// The set-up's solves of matrices below 50,000 rows run on the host even when the Newton
// matrix goes to the GPU: the consistent initial state is then the CPU backend's bit for
// bit (the device's LU would differ from the host's L D Lᵀ in the last bits), while the
// Newton matrix is still factored on the device.
TEST(CudaMbd, SmallSetUpSolvesRunOnTheHost) {
  if (!numeric::cuda_available())
    GTEST_SKIP() << "no CUDA GPU present (or this build has no CUDA backend): GPU test skipped";
  for (const char* spec : {"tracked:20", "lattice:3", "flexible:6x2x2"}) {
    SCOPED_TRACE(spec);
    const Model m = build_model(generate(spec), spec);
    IntegratorOptions on_gpu, on_cpu;
    on_gpu.t_end = on_cpu.t_end = 0.002;
    on_gpu.solver.backend = Backend::cuda;
    on_cpu.solver.backend = Backend::cpu;
    Integrator gpu(m, on_gpu), cpu(m, on_cpu);
    gpu.initialize();
    cpu.initialize();
    EXPECT_EQ(gpu.q(), cpu.q());
    EXPECT_EQ(gpu.v(), cpu.v());
    EXPECT_EQ(gpu.a(), cpu.a());
    EXPECT_EQ(gpu.lambda(), cpu.lambda());
    gpu.advance();
    EXPECT_NE(gpu.stats().solver.find("cuda"), std::string::npos) << gpu.stats().solver;
  }
}

}  // namespace
}  // namespace strata::mbd
