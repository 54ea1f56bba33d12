// Failure injection: host allocations that fail (tests/alloc_hook) at every allocation
// point of analyze / factorize / refactorize / solve, of the C interface, and of a
// simulation. Every outcome must be success or strata::OutOfMemory (C: its status code)
// naming the phase — never a crash, another exception, or a solver left broken: after
// each injected failure the same Solver object factorizes and solves again, checked
// against a dense LAPACK solution. Leaks: these tests are plain ctest tests, so an
// AddressSanitizer/LeakSanitizer build runs them with leak checking at exit.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "alloc_hook/alloc_hook.hpp"
#include "analysis/analysis.hpp"
#include "mbd/generators.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"
#include "strata/strata.h"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

namespace alloc = test::alloc;

TEST(AllocHook, FailsTheNthAllocationOnceThenDisarms) {
  {
    alloc::Armed armed(3);
    auto* a = new int(1);
    auto* b = new int(2);
    EXPECT_THROW((void)new int(3), std::bad_alloc);
    EXPECT_TRUE(alloc::fired());
    EXPECT_EQ(alloc::failed_bytes(), sizeof(int));
    auto* d = new int(4);  // one failure only
    delete a;
    delete b;
    delete d;
  }
  alloc::Armed armed(1);
  EXPECT_EQ(new (std::nothrow) double[7], nullptr);
  EXPECT_EQ(alloc::failed_bytes(), 7 * sizeof(double));
}

struct Problem {
  const char* name;
  SparseMatrix a;
  MatrixType type;
};

std::vector<Problem> problems(std::mt19937_64& rng) {
  std::vector<Problem> p;
  p.push_back({"spd", test::random_sparse(40, 3, test::RandomKind::spd, rng), MatrixType::spd});
  p.push_back(
      {"symmetric_indefinite", test::random_kkt(45, rng), MatrixType::symmetric_indefinite});
  p.push_back(
      {"general", test::random_sparse(40, 3, test::RandomKind::general, rng), MatrixType::general});
  // automatic on an indefinite matrix: a failed Cholesky attempt, then LDLᵀ
  p.push_back({"automatic", test::random_sparse(33, 3, test::RandomKind::symmetric_indefinite, rng),
               MatrixType::automatic});
  return p;
}

// x solves A x = b to a small backward error and agrees with dense LAPACK.
void expect_solution(const SparseMatrix& a, const std::vector<double>& b,
                     const std::vector<double>& x, const std::string& where) {
  std::vector<double> ref = b;
  ASSERT_TRUE(test::dense_solve(test::to_dense(a), a.n_rows, ref, 1)) << where;
  EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-13) << where;
  EXPECT_LT(test::relative_difference(x, ref), 1e-8) << where;
}

// One armed run of every phase; returns the message of the OutOfMemory it threw ("" for
// success). Any other exception fails the test.
std::string armed_run(Solver& s, const SparseMatrix& a, const std::vector<double>& b,
                      std::vector<double>& x, std::uint64_t n) {
  alloc::Armed armed(n);
  try {
    s.analyze(a);
    s.factorize(a);
    s.refactorize(a);
    x = s.solve(b);
  } catch (const OutOfMemory& e) {
    alloc::disarm();
    EXPECT_TRUE(alloc::fired()) << "OutOfMemory without an injected failure: " << e.what();
    const std::string msg = e.what();
    EXPECT_TRUE(msg.find("analyze") != std::string::npos ||
                msg.find("factorize") != std::string::npos ||
                msg.find("solve") != std::string::npos)
        << "the message names no phase: " << msg;
    if (e.bytes_requested() > 0) {
      EXPECT_NE(msg.find(std::to_string(e.bytes_requested()) + " bytes"), std::string::npos) << msg;
      // the vector asked for at least what the message says
      EXPECT_GE(alloc::failed_bytes(), e.bytes_requested()) << msg;
    }
    return msg.empty() ? std::string("?") : msg;
  } catch (const std::exception& e) {
    alloc::disarm();
    ADD_FAILURE() << "allocation " << n
                  << " failed with something else than OutOfMemory: " << typeid(e).name() << ": "
                  << e.what();
    return "other";
  }
  return "";
}

// Sweep: fail allocation N for N = 1, 2, ... until the run succeeds untouched.
void sweep(const Problem& p, int threads, std::uint64_t stride) {
  Options o;
  o.type = p.type;
  o.num_threads = threads;
  std::vector<double> b(p.a.n_rows);
  for (std::size_t i = 0; i < b.size(); ++i) b[i] = 1.0 + static_cast<double>(i % 7);
  std::uint64_t failures = 0, sized = 0, n = 1;
  for (;; n += stride) {
    SCOPED_TRACE(std::string(p.name) + ", failing allocation " + std::to_string(n));
    Solver s(o);
    std::vector<double> x;
    const std::string msg = armed_run(s, p.a, b, x, n);
    const bool fired = alloc::fired();
    if (!msg.empty()) {
      ++failures;
      if (msg.find(" bytes") != std::string::npos && msg.find("not known") == std::string::npos)
        ++sized;
      // the same solver recovers: factorize (analyzing again if needed) and solve
      s.factorize(p.a);
      x = s.solve(b);
    }
    expect_solution(p.a, b, x, p.name);
    if (::testing::Test::HasFailure()) return;
    if (!fired) break;  // no allocation point left
  }
  EXPECT_GT(failures, 10u) << "the sweep met almost no allocation";
  std::printf(
      "%s (threads %d): %llu allocation points tried, %llu OutOfMemory (%llu with a size)\n",
      p.name, threads, static_cast<unsigned long long>(n),
      static_cast<unsigned long long>(failures), static_cast<unsigned long long>(sized));
}

TEST(FaultInjection, EveryAllocationOfEveryPhaseOneThread) {
  auto rng = test::fresh_rng();
  for (const Problem& p : problems(rng)) sweep(p, 1, 1);
}

// With worker threads the allocation order varies from run to run; a sample of points
// (every 7th) must still end in success or OutOfMemory.
TEST(FaultInjection, AllocationFailuresWithWorkerThreads) {
  auto rng = test::fresh_rng();
  SparseMatrix a = test::random_sparse(300, 4, test::RandomKind::general, rng);
  sweep({"general, 3 threads", a, MatrixType::general}, 3, 7);
}

// The large buffers report their size: a factor panel array that cannot be allocated
// names the factor panels and the bytes. The failing allocation is found by counting.
TEST(FaultInjection, LargeBufferNamesItsSize) {
  auto rng = test::fresh_rng();
  SparseMatrix a = test::random_sparse(200, 4, test::RandomKind::spd, rng);
  Options o;
  o.type = MatrixType::spd;
  o.num_threads = 1;
  const std::size_t panel_bytes = analyze_matrix(a, o).factor_layout.total * sizeof(double);
  bool seen = false;
  for (std::uint64_t n = 1; n < 100000 && !seen; ++n) {
    Solver s(o);
    s.analyze(a);
    alloc::Armed armed(n);
    try {
      s.factorize(a);
      break;
    } catch (const OutOfMemory& e) {
      if (std::string(e.what()).find("factor panels") != std::string::npos) {
        seen = true;
        EXPECT_EQ(e.bytes_requested(), panel_bytes) << e.what();
      }
    }
  }
  EXPECT_TRUE(seen) << "no failure of the factor panel allocation was met";
}

// The C interface returns STRATA_ERROR_OUT_OF_MEMORY with a message, then works again.
TEST(FaultInjection, CInterfaceReturnsOutOfMemory) {
  auto rng = test::fresh_rng();
  SparseMatrix a = test::random_sparse(30, 3, test::RandomKind::general, rng);
  strata_matrix m{};
  m.n_rows = m.n_cols = a.n_rows;
  m.layout = STRATA_CSC;
  m.storage = STRATA_STORAGE_FULL;
  m.index_type = STRATA_INT64;
  m.index_base = 0;
  m.offsets = a.offsets.data();
  m.indices = a.indices.data();
  m.values = a.values.data();
  std::vector<double> b(a.n_rows, 1.0), x(a.n_rows);
  std::uint64_t ooms = 0;
  for (std::uint64_t n = 1;; ++n) {
    SCOPED_TRACE("failing allocation " + std::to_string(n));
    strata_solver* s = nullptr;
    strata_status st;
    bool fired;
    {
      alloc::Armed armed(n);
      st = strata_create(&s);
      if (st == STRATA_OK) st = strata_set_num_threads(s, 1);
      if (st == STRATA_OK) st = strata_analyze(s, &m);
      if (st == STRATA_OK) st = strata_factorize(s, &m);
      if (st == STRATA_OK) st = strata_solve(s, 1, b.data(), x.data());
      fired = alloc::fired();
    }
    ASSERT_TRUE(st == STRATA_OK || st == STRATA_ERROR_OUT_OF_MEMORY)
        << strata_status_string(st) << ": " << (s ? strata_last_error(s) : "");
    if (st == STRATA_ERROR_OUT_OF_MEMORY) {
      ++ooms;
      if (s) {
        EXPECT_NE(std::string(strata_last_error(s)).find("out of memory"), std::string::npos)
            << strata_last_error(s);
        // the handle still works: analyze, factorize, solve
        ASSERT_EQ(strata_analyze(s, &m), STRATA_OK) << strata_last_error(s);
        ASSERT_EQ(strata_factorize(s, &m), STRATA_OK) << strata_last_error(s);
        ASSERT_EQ(strata_solve(s, 1, b.data(), x.data()), STRATA_OK) << strata_last_error(s);
      } else {
        EXPECT_EQ(n, 1u);  // only the handle itself can fail to be created
      }
    }
    if (s) EXPECT_LT(test::backward_error(a, x.data(), b.data()), 1e-13);
    strata_destroy(s);
    if (!fired) break;
  }
  EXPECT_GT(ooms, 10u);
}

std::string slurp(const std::string& path) {
  std::ifstream in(path);
  std::stringstream ss;
  ss << in.rdbuf();
  return ss.str();
}

// A simulation whose allocations fail at sampled points: it either completes, or stops
// with its reason "out of memory" and its files named partial, or (before the first step,
// or while writing its final files) throws OutOfMemory — never another exception, never
// a file that passes for a complete run.
TEST(FaultInjection, SimulationStopsWithOutOfMemoryAndPartialFiles) {
  using namespace mbd;
  const Model model = build_model(generate("chain:3"), "chain:3");
  SimulationOptions o;
  o.integrator.t_end = 0.02;
  o.integrator.step = 1e-3;
  o.integrator.solver.num_threads = 1;
  o.output_dir = strata::test::unique_temp_path("strata_fault_sim");
  std::filesystem::remove_all(o.output_dir);
  alloc::reset_count();
  ASSERT_TRUE(simulate(model, o).complete);
  const std::uint64_t total = alloc::count();
  ASSERT_GT(total, 100u);
  int stopped = 0, thrown = 0;
  // the first 200 allocation points, then 300 spread over the whole run
  std::vector<std::uint64_t> points;
  for (std::uint64_t n = 1; n <= 200; ++n) points.push_back(n);
  for (std::uint64_t k = 1; k <= 300; ++k) points.push_back(200 + k * (total - 200) / 300);
  for (std::uint64_t n : points) {
    SCOPED_TRACE("failing allocation " + std::to_string(n) + " of " + std::to_string(total));
    std::filesystem::remove_all(o.output_dir);
    SimulationResult r;
    bool threw = false;
    {
      alloc::Armed armed(n);
      try {
        r = simulate(model, o);
      } catch (const OutOfMemory& e) {
        threw = true;
        // the simulation's own set-up, or a solver phase of the initial conditions
        const std::string msg = e.what();
        EXPECT_TRUE(msg.find("simulation") != std::string::npos ||
                    msg.find("analyze") != std::string::npos ||
                    msg.find("factorize") != std::string::npos ||
                    msg.find("solve") != std::string::npos)
            << msg;
      } catch (const std::exception& e) {
        ADD_FAILURE() << "not OutOfMemory: " << typeid(e).name() << ": " << e.what();
        continue;
      }
    }
    const std::string status = slurp(o.output_dir + "/status.json");
    if (threw) {
      ++thrown;
      EXPECT_FALSE(std::filesystem::exists(o.output_dir + "/positions.csv") &&
                   status.find("\"complete\": true") != std::string::npos)
          << "a failed run left files that pass for a complete one";
      continue;
    }
    if (r.complete) {
      EXPECT_NE(status.find("\"complete\": true"), std::string::npos) << status;
      continue;
    }
    ++stopped;
    EXPECT_NE(r.message.find("out of memory"), std::string::npos) << r.message;
    EXPECT_EQ(r.state, "failed");
    EXPECT_NE(status.find("\"partial\": true"), std::string::npos) << status;
    EXPECT_NE(status.find("out of memory"), std::string::npos) << status;
    EXPECT_FALSE(std::filesystem::exists(o.output_dir + "/positions.csv"));
    EXPECT_TRUE(std::filesystem::exists(o.output_dir + "/positions.partial.csv"));
    if (::testing::Test::HasFailure()) break;
  }
  std::printf(
      "simulation: %llu allocations per run; %zu points tried: %d stopped partial, %d threw\n",
      static_cast<unsigned long long>(total), points.size(), stopped, thrown);
  EXPECT_GT(stopped, 0);
  EXPECT_GT(thrown, 0);
  std::filesystem::remove_all(o.output_dir);
}

}  // namespace
}  // namespace strata
