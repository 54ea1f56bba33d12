// strata::mbd on the CUDA backend: the engine's Newton loop on a GPU factors in the
// analysis's order until a refactorization needs static pivots, then delays pivots on the
// host until the next analysis (mbd/linear_solver.hpp). No analysis is made for perturbed
// pivots, none are left, and the trajectory equals the CPU backend's (which delays pivots
// at every refactorization).
#include <gtest/gtest.h>

#include <string>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "numeric/factor.hpp"
#include "support/mbd_test_support.hpp"

namespace strata::mbd {
namespace {

TEST(CudaMbd, PerturbedPivotsAreDelayedAndTheTrajectoryEqualsTheCpus) {
  if (!numeric::cuda_available())
    GTEST_SKIP() << "no CUDA GPU present (or this build has no CUDA backend): GPU test skipped";
  const Model m = build_model(generate("tracked:100"), "tracked:100");
  IntegratorOptions o;
  o.t_end = 0.1;
  o.newton_rtol = 1e-10;
  o.newton_atol = 1e-12;
  IntegratorOptions on_gpu = o, on_cpu = o;
  on_gpu.solver.backend = Backend::cuda;
  on_cpu.solver.backend = Backend::cpu;
  Integrator gpu(m, on_gpu), cpu(m, on_cpu);
  double worst = 0;
  test::step_side_by_side(gpu, cpu, 1e-8, &worst);
  const IntegratorStats& s = gpu.stats();
  EXPECT_EQ(s.reanalyses, 0);
  EXPECT_EQ(s.perturbed_pivots, 0);
  EXPECT_NE(s.solver.find("cuda"), std::string::npos) << s.solver;
  RecordProperty("largest position difference", test::scientific(worst));
  RecordProperty("delayed factorizations", std::to_string(s.delayed_factorizations) + " of " +
                                               std::to_string(s.factorizations));
}

}  // namespace
}  // namespace strata::mbd
