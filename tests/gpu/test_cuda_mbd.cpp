// strata::mbd on the CUDA backend: the engine's Newton loop on a GPU factors in the
// analysis's order until a refactorization needs static pivots, then delays pivots on the
// host until the next analysis (mbd/linear_solver.hpp). No analysis is made for perturbed
// pivots, none are left, and the trajectory equals the CPU backend's (which delays pivots
// at every refactorization).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "numeric/factor.hpp"

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
  on_gpu.backend = Backend::cuda;
  on_cpu.backend = Backend::cpu;
  Integrator gpu(m, on_gpu), cpu(m, on_cpu);
  gpu.initialize();
  cpu.initialize();
  double worst = 0;
  int steps = 0;
  while (!gpu.done() && !cpu.done()) {
    gpu.advance();
    cpu.advance();
    ++steps;
    ASSERT_EQ(gpu.t(), cpu.t()) << "step " << steps;
    for (std::size_t i = 0; i < gpu.q().size(); ++i)
      worst = std::max(worst, std::abs(gpu.q()[i] - cpu.q()[i]));
    ASSERT_LE(worst, 1e-8) << "step " << steps << " t = " << gpu.t();
  }
  EXPECT_TRUE(gpu.done() && cpu.done());
  const IntegratorStats& s = gpu.stats();
  EXPECT_EQ(s.reanalyses, 0);
  EXPECT_EQ(s.perturbed_pivots, 0);
  EXPECT_NE(s.solver.find("cuda"), std::string::npos) << s.solver;
  char text[32];
  std::snprintf(text, sizeof text, "%.3e", worst);
  RecordProperty("largest position difference", text);
  RecordProperty("delayed factorizations", std::to_string(s.delayed_factorizations) + " of " +
                                               std::to_string(s.factorizations));
}

}  // namespace
}  // namespace strata::mbd
