// strata — device memory exhaustion on the CUDA backend (ctest label `gpu`): the internal
// allocation cap (numeric/device_cap.hpp) makes a device allocation fail as cudaMalloc
// would. The factorization must stop with OutOfMemory naming the bytes asked for, give
// back its device buffers, and the same Solver must factorize and solve correctly once the
// cap is lifted; an allocation the factorization can do without (the copy of A kept for
// checked solves) is left out instead. Skipped where no CUDA GPU is present.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "numeric/device_cap.hpp"
#include "numeric/factor.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

struct Uncap {
  ~Uncap() { numeric::clear_device_allocation_cap(); }
};

TEST(CudaFaults, DeviceAllocationFailureIsOutOfMemoryAndRecoverable) {
  if (!numeric::cuda_available())
    GTEST_SKIP() << "no CUDA GPU present (or this build has no CUDA backend): GPU test skipped";
  Uncap uncap;
  auto rng = test::fresh_rng();
  struct Case {
    SparseMatrix a;
    MatrixType type;
  };
  std::vector<Case> cases{
      {test::random_sparse(733, 3, test::RandomKind::spd, rng), MatrixType::spd},
      {test::random_sparse(300, 3, test::RandomKind::general, rng), MatrixType::general},
      {generators::laplacian_3d(16, 16, 16), MatrixType::spd}};
  for (const Case& c : cases) {
    SCOPED_TRACE("n=" + std::to_string(c.a.n_rows));
    Options o;
    o.type = c.type;
    o.backend = Backend::cuda;
    // one GPU: with several, work stealing decides which GPU holds which subtree's panels,
    // so what a factorization allocates differs from run to run (on two H200s a capped run
    // then fitted under a cap set below the measured total)
    o.num_gpus = 1;
    // solves checked only after perturbed pivots: every device allocation of a
    // factorization is then one it needs (with checks always, the value pass also keeps a
    // copy of A for the checks' residuals where there is room: below)
    o.solve_check = SolveCheck::after_perturbed_pivots;
    std::vector<double> b(c.a.n_rows);
    for (std::size_t i = 0; i < b.size(); ++i) b[i] = std::sin(1.0 + i);
    // how much an analysis and its first factorization allocate on the device (the
    // analysis' device set-up, Executor::prepare, sizes nearly all of it, so that the
    // factorization allocates nothing; a failure in that set-up is left for the
    // factorization, which allocates afresh and reports it)
    const auto charged = [&c](const Options& options) {
      Solver s(options);
      numeric::set_device_allocation_cap(std::numeric_limits<std::size_t>::max() - 1);
      s.analyze(c.a);
      s.factorize(c.a);
      const std::size_t bytes = numeric::device_bytes_charged();
      numeric::clear_device_allocation_cap();
      return bytes;
    };
    const std::size_t total = charged(o);
    ASSERT_GT(total, 0u);
    int failures = 0;
    for (int k = 0; k <= 16; ++k) {
      const std::size_t cap = total / 16 * k - (k == 16 ? 1 : 0);
      SCOPED_TRACE("cap " + std::to_string(cap) + " of " + std::to_string(total));
      Solver s(o);
      numeric::set_device_allocation_cap(cap);
      s.analyze(c.a);
      try {
        s.factorize(c.a);
        ADD_FAILURE() << "the factorization fitted under a cap below what it allocates";
      } catch (const OutOfMemory& e) {
        ++failures;
        const std::string msg = e.what();
        EXPECT_GT(e.bytes_requested(), 0u) << msg;
        EXPECT_GT(numeric::device_bytes_charged() + e.bytes_requested(), cap) << msg;
        EXPECT_NE(msg.find(std::to_string(e.bytes_requested()) + " bytes"), std::string::npos)
            << msg;
        EXPECT_NE(msg.find("device memory"), std::string::npos) << msg;
      }
      numeric::clear_device_allocation_cap();
      EXPECT_THROW(s.solve(b), InvalidState);  // no factor after the failure
      s.factorize(c.a);
      const std::vector<double> x = s.solve(b);
      EXPECT_LT(test::backward_error(c.a, x.data(), b.data()), 1e-12);
      EXPECT_EQ(s.stats().factor.backend, Backend::cuda);
    }
    EXPECT_EQ(failures, 17);
    // checks always: the copy of A that the value pass keeps for the residuals on the
    // device is charged too, and is left out where the cap leaves no room for it: the
    // factorization under the cap of the one without it succeeds, and its checked solve
    // (residuals from the host's values, or on the host) reaches its backward error
    Options checked = o;
    checked.solve_check = SolveCheck::always;
    const std::size_t with_copy = charged(checked);
    Solver s(checked);
    numeric::set_device_allocation_cap(total);
    s.analyze(c.a);
    if (with_copy > total) {
      EXPECT_NO_THROW(s.factorize(c.a)) << "the copy of A is not optional";
    } else {  // no copy taken (the value pass ran on the host)
      s.factorize(c.a);
    }
    numeric::clear_device_allocation_cap();
    const std::vector<double> x = s.solve(b);
    EXPECT_LT(test::backward_error(c.a, x.data(), b.data()), 1e-14);
    EXPECT_LE(s.stats().solve.backward_error, 1e-14);
  }
}

}  // namespace
}  // namespace strata
