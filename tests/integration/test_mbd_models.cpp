// strata::mbd — every bundled model file loads and integrates a few steps, and the
// generators' models agree with their files; --dump-matrix output is a valid Matrix
// Market pair of the Newton system's size.
#include <gtest/gtest.h>

#include <filesystem>

#include "mbd/generators.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"
#include "strata/matrix_market.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

TEST(MbdModels, BundledModelsRunAFewSteps) {
  int count = 0;
  for (const auto& entry : std::filesystem::directory_iterator(STRATA_MODELS_DIR)) {
    if (entry.path().extension() != ".json") continue;
    SCOPED_TRACE(entry.path().string());
    const Model m = load_model(entry.path().string());
    SimulationOptions o;
    o.integrator.t_end = 5 * m.step;
    o.integrator.step = m.step;
    o.integrator.order = m.order;
    const SimulationResult r = simulate(m, o);
    EXPECT_TRUE(r.complete) << r.message;
    EXPECT_LT(r.max_position_violation, 1e-6);
    ++count;
  }
  EXPECT_GE(count, 5);
}

TEST(MbdModels, DumpMatrixWritesTheNewtonSystem) {
  const Model m = build_model(generate("lattice:2"), "lattice");
  SimulationOptions o;
  o.integrator.t_end = 3 * m.step;
  o.integrator.step = m.step;
  o.integrator.dump_step = 2;
  o.integrator.dump_dir = strata::test::unique_temp_path("strata_mbd_dump");
  std::filesystem::remove_all(o.integrator.dump_dir);
  const SimulationResult r = simulate(m, o);
  ASSERT_TRUE(r.complete) << r.message;
  const MMMatrix a = read_matrix_market(o.integrator.dump_dir + "/jacobian_step2.mtx");
  index_t rows = 0, cols = 0;
  const auto b = read_dense_matrix_market(o.integrator.dump_dir + "/rhs_step2.mtx", &rows, &cols);
  const index_t size = 3 * m.n + m.n_constraints();
  EXPECT_EQ(a.matrix.n_rows, size);
  EXPECT_EQ(a.matrix.n_cols, size);
  EXPECT_EQ(rows, size);
  EXPECT_EQ(cols, 1);
  EXPECT_EQ(a.matrix.nnz(), r.stats.jacobian_nnz);
  std::filesystem::remove_all(o.integrator.dump_dir);
}

}  // namespace
}  // namespace strata::mbd
