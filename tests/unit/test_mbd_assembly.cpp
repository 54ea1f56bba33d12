// strata::mbd — the Newton system's assembly (NewtonSystem::evaluate): H(x) and H_x are
// bitwise the same on 1, 2, 3 and 4 threads (elements write shared entries to their own
// slots and each entry sums its slots in element order), and H_x is the derivative of H:
// H_x d against central differences of H along random directions d, in both
// formulations, on models whose elements share many entries (the tracked vehicle's
// chassis, wheels and contacts; the flexible plate's nodes; the bushing lattice). States
// and directions are drawn afresh.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model_io.hpp"
#include "support/mbd_test_support.hpp"
#include "support/test_support.hpp"

namespace strata::mbd {
namespace {

struct State {
  std::vector<double> x, zeta1, zeta2, lambda_prev;
  BdfTerms bdf;
};

// A state near the integrator's initial one: positions from it, velocities, accelerations
// and multipliers random, BDF history random.
State random_state(const Integrator& in, const NewtonSystem& sys, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1, 1);
  const index_t n = sys.n(), m = sys.m();
  State s;
  s.x.assign(sys.size(), 0.0);
  for (index_t i = 0; i < n; ++i) {
    s.x[i] = u(rng);
    s.x[n + i] = u(rng);
    s.x[2 * n + i] = in.q()[i] + 1e-3 * u(rng);
  }
  for (index_t k = 3 * n; k < sys.size(); ++k) s.x[k] = u(rng);
  s.zeta1.resize(n);
  s.zeta2.resize(n);
  s.lambda_prev.resize(m);
  for (double& z : s.zeta1) z = u(rng);
  for (double& z : s.zeta2) z = u(rng);
  for (double& l : s.lambda_prev) l = u(rng);
  s.bdf.beta = 1e-3;
  s.bdf.zeta1 = s.zeta1.data();
  s.bdf.zeta2 = s.zeta2.data();
  s.bdf.regularization = 1e-6;
  s.bdf.lambda_prev = s.lambda_prev.data();
  return s;
}

bool bitwise_equal(const std::vector<double>& a, const std::vector<double>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(double)) == 0;
}

void check_assembly(const std::string& name, Formulation formulation, std::mt19937_64& rng) {
  SCOPED_TRACE(name + (formulation == Formulation::stabilized ? " stabilized" : " partitioned"));
  test::InitializedModel im(name);
  Integrator& in = im.in;
  NewtonSystem& sys = in.system();
  if (sys.formulation() != formulation) sys.set_formulation(formulation);
  const State s = random_state(in, sys, rng);
  const double t = 0.01;

  // the same bits on any number of threads (several evaluations each: a race would show)
  // (the residual alone is evaluated by other element functions, without derivatives:
  // its bits are compared with its own one-thread evaluation)
  std::vector<double> h1(sys.size()), r1(sys.size()), h(sys.size());
  sys.set_threads(1);
  sys.evaluate(s.x.data(), t, s.bdf, false, r1.data());
  sys.evaluate(s.x.data(), t, s.bdf, true, h1.data());
  const std::vector<double> j1 = sys.matrix().values;
  double jmax = 0;
  for (double v : j1) jmax = std::max(jmax, std::abs(v));
  ASSERT_GT(jmax, 0.0);
  for (int threads : {2, 3, 4}) {
    sys.set_threads(threads);
    for (int rep = 0; rep < 3; ++rep) {
      sys.evaluate(s.x.data(), t, s.bdf, true, h.data());
      EXPECT_TRUE(bitwise_equal(h, h1)) << threads << " threads: the residual differs";
      EXPECT_TRUE(bitwise_equal(sys.matrix().values, j1))
          << threads << " threads: the Jacobian differs";
      sys.evaluate(s.x.data(), t, s.bdf, false, h.data());
      EXPECT_TRUE(bitwise_equal(h, r1)) << threads << " threads: the residual alone differs";
    }
  }

  // H_x d against central differences of H, the residual-only path
  const SparseMatrix& J = sys.matrix();
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> d(sys.size()), xp, xm, hp(sys.size()), hm(sys.size()), jd;
  for (int dir = 0; dir < 3; ++dir) {
    for (double& v : d) v = u(rng);
    jd.assign(sys.size(), 0.0);
    for (index_t c = 0; c < J.n_cols; ++c)
      for (index_t p = J.offsets[c]; p < J.offsets[c + 1]; ++p)
        jd[J.indices[p]] += J.values[p] * d[c];
    // a small step: the contact forces' curvature along d is large at some states, and
    // they are not differentiable where a pair touches or its slip changes direction (a
    // step that crosses such a point compares nothing); the residual's rounding, about
    // 1e-16 of its entries divided by the step, stays far below the tolerance
    const double eps = 1e-8;
    xp = s.x;
    xm = s.x;
    for (std::size_t k = 0; k < d.size(); ++k) {
      xp[k] += eps * d[k];
      xm[k] -= eps * d[k];
    }
    sys.evaluate(xp.data(), t, s.bdf, false, hp.data());
    sys.evaluate(xm.data(), t, s.bdf, false, hm.data());
    double worst = 0, scale = 0;
    std::size_t at = 0;
    for (std::size_t k = 0; k < jd.size(); ++k) {
      const double fd = (hp[k] - hm[k]) / (2 * eps);
      scale = std::max(scale, std::abs(jd[k]));
      if (std::abs(fd - jd[k]) > worst) worst = std::abs(fd - jd[k]), at = k;
    }
    // the elements' own Jacobians pass 2e-6 against their differences (test_mbd_jacobians);
    // a misplaced or lost slot is an error of the size of an entry
    EXPECT_LT(worst, 1e-5 * scale) << "row " << at << ": H_x d " << jd[at];
  }
}

TEST(MbdAssembly, SameBitsOnAnyThreadsAndTheJacobianIsHsDerivative) {
  unsigned long long seed = 0;
  std::mt19937_64 rng = strata::test::fresh_rng(&seed);
  SCOPED_TRACE("STRATA_TEST_SEED=" + std::to_string(seed));
  for (const char* name : {"tracked:20", "flexible:8x2x2", "lattice:3"})
    for (Formulation f : {Formulation::partitioned, Formulation::stabilized})
      check_assembly(name, f, rng);
}

// The pattern, its element positions and the slot sums are built on the assembly's
// threads (mbd/pattern_builder.hpp): built again on 1 to 4 threads, the matrix has the same
// pattern and the same bits, in both formulations, on models large enough for the
// threaded passes.
TEST(MbdAssembly, PatternBuiltOnAnyThreadsIsTheSame) {
  std::mt19937_64 rng = strata::test::fresh_rng();
  for (const char* name : {"flexible:16x4x4", "tracked:100"})
    for (Formulation f : {Formulation::partitioned, Formulation::stabilized}) {
      SCOPED_TRACE(std::string(name) + (f == Formulation::stabilized ? " stabilized" : ""));
      test::InitializedModel im(name);
      Integrator& in = im.in;
      NewtonSystem& sys = in.system();
      sys.set_threads(1);
      if (sys.formulation() != f)
        sys.set_formulation(f);
      else
        sys.rebuild_pattern();
      const State s = random_state(in, sys, rng);
      std::vector<double> h1(sys.size()), h(sys.size());
      sys.evaluate(s.x.data(), 0.01, s.bdf, true, h1.data());
      const SparseMatrix j1 = sys.matrix();
      for (int threads : {2, 3, 4}) {
        sys.set_threads(threads);
        sys.rebuild_pattern();
        ASSERT_EQ(sys.matrix().offsets, j1.offsets) << threads << " threads";
        ASSERT_EQ(sys.matrix().indices, j1.indices) << threads << " threads";
        sys.evaluate(s.x.data(), 0.01, s.bdf, true, h.data());
        EXPECT_TRUE(bitwise_equal(h, h1)) << threads << " threads: the residual differs";
        EXPECT_TRUE(bitwise_equal(sys.matrix().values, j1.values))
            << threads << " threads: the Jacobian differs";
      }
    }
}

// The BDF rows of a flexible-body node's coordinates share one pattern (each holds the
// node's three coordinates in its v ↔ a or q ↔ v block; the two that are not its own as
// explicit zeros), so that the nested dissection merges the node's rows into one vertex;
// those zeros stay exactly zero after an evaluation at a random state. A rigid body's BDF
// rows keep their two entries. Both formulations (the stabilized one's v ↔ a rows).
TEST(MbdAssembly, FlexibleNodesShareTheirBdfRowPattern) {
  std::mt19937_64 rng = strata::test::fresh_rng();
  for (const char* name : {"flexible:8x2x2", "tracked:20"})
    for (Formulation f : {Formulation::partitioned, Formulation::stabilized}) {
      SCOPED_TRACE(std::string(name) + (f == Formulation::stabilized ? " stabilized" : ""));
      test::InitializedModel im(name);
      NewtonSystem& sys = im.in.system();
      if (sys.formulation() != f) sys.set_formulation(f);
      const State s = random_state(im.in, sys, rng);
      std::vector<double> h(sys.size());
      sys.evaluate(s.x.data(), 0.01, s.bdf, true, h.data());
      const SparseMatrix& jac = sys.matrix();
      const index_t n = sys.n(), m = sys.m(), N = sys.size();
      // the rows' entries (column, value), from the CSC matrix
      std::vector<std::vector<std::pair<index_t, double>>> rows(N);
      for (index_t c = 0; c < N; ++c)
        for (index_t p = jac.offsets[c]; p < jac.offsets[c + 1]; ++p)
          rows[jac.indices[p]].push_back({c, jac.values[p]});
      const bool stab = f == Formulation::stabilized;
      std::vector<index_t> bdf = sys.independent();
      if (stab) {
        bdf.resize(n);
        for (index_t i = 0; i < n; ++i) bdf[i] = i;
      }
      const index_t nb = static_cast<index_t>(bdf.size());
      const index_t ru = stab ? n + 2 * m : n + 3 * m;  // the BDF rows (rebuild_pattern)
      std::vector<index_t> bdf_index(n, -1);
      for (index_t k = 0; k < nb; ++k) bdf_index[bdf[k]] = k;
      int nodes_checked = 0, rigid_checked = 0;
      for (const Body& b : sys.model().bodies) {
        if (b.offset < 0) continue;
        // v ↔ a rows, then q ↔ v rows (partitioned only: the stabilized formulation's
        // hold the constraints' β (Φ_qᵀν)_q too)
        for (int rel = 0; rel < (stab ? 1 : 2); ++rel) {
          std::vector<index_t> first_cols;
          bool all = true;
          for (int c = 0; c < b.n_coords; ++c) {
            const index_t k = bdf_index[b.offset + c];
            if (k < 0) {
              all = false;
              continue;
            }
            const auto& row = rows[ru + rel * nb + k];
            std::vector<index_t> cols;
            for (const auto& [col, val] : row) {
              cols.push_back(col);
              const index_t coord = col % n;  // a, v, q blocks of n columns each
              if (coord != b.offset + c) {
                EXPECT_EQ(val, 0.0) << "a structural zero of " << b.name << " was written";
              }
            }
            if (b.kind == BodyKind::node) {
              EXPECT_EQ(static_cast<int>(cols.size()), 2 * b.n_coords) << b.name;
              // the same blocks for every coordinate of the node
              std::vector<index_t> blocks;
              for (index_t col : cols) blocks.push_back(col - col % n + (col % n - b.offset));
              std::sort(blocks.begin(), blocks.end());
              if (first_cols.empty())
                first_cols = blocks;
              else
                EXPECT_EQ(blocks, first_cols) << b.name << " coordinate " << c;
            } else {
              EXPECT_EQ(cols.size(), 2u) << b.name << ": a rigid body's BDF row grew";
              ++rigid_checked;
            }
          }
          if (b.kind == BodyKind::node && all) ++nodes_checked;
        }
      }
      if (std::string(name).rfind("flexible", 0) == 0)
        EXPECT_GT(nodes_checked, 0);
      else
        EXPECT_GT(rigid_checked, 0);
    }
}

}  // namespace
}  // namespace strata::mbd
