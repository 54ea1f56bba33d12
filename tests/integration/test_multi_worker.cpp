// strata tests — the multi-worker factorization (numeric/multi_device.cpp) on CPU
// executors, as it runs on several GPUs: the factor is bitwise the one-worker factor on
// the same analysis (every front is factored once, by the same code), solutions through
// the Solver agree with the one-worker CPU solver and have backward error at the unit
// roundoff for spd, symmetric indefinite and general matrices, refactorization works on
// the distributed factor, a slowed worker has its subtrees stolen, and errors propagate.
// The top part is split into upper layers by default (Options::split_top); a dedicated
// test asserts that it is, and compares with the split off and a dense solve; it also
// checks which executors each part is lent as helpers (FactorContext::helpers). Upper
// parts start without waiting for unrelated subtrees (no barrier between layers), and the
// host panels are sized only when some part's panels go there.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <numeric>
#include <string>

#include "analysis/analysis.hpp"
#include "core/solver_internal.hpp"
#include "numeric/driver.hpp"
#include "numeric/factor.hpp"
#include "sparse/generators.hpp"
#include "strata/strata.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

using detail::SolverAccess;

using Problem = test::NamedMatrix;

// spd, symmetric indefinite and general problems: generated 3D grids, shared matrices,
// random matrices of awkward sizes.
std::vector<Problem> problems(std::mt19937_64& rng) {
  std::vector<Problem> p;
  auto shared = [](const char* name) { return read_matrix_market(test::matrix_path(name)).matrix; };
  p.push_back({"lap3d 13", generators::laplacian_3d(13, 13, 13), MatrixType::spd});
  p.push_back({"elasticity 6", generators::elasticity_3d(6, 6, 6), MatrixType::spd});
  p.push_back({"bcsstk16", shared("bcsstk16"), MatrixType::spd});
  for (index_t n : {1, 2, 5, 733})
    p.push_back({"random spd " + std::to_string(n),
                 test::random_sparse(n, 3, test::RandomKind::spd, rng), MatrixType::spd});
  p.push_back({"hangGlider_2", shared("hangGlider_2"), MatrixType::symmetric_indefinite});
  p.push_back({"random kkt 733", test::random_kkt(733, rng), MatrixType::symmetric_indefinite});
  p.push_back({"random indefinite 1500",
               test::random_sparse(1500, 4, test::RandomKind::symmetric_indefinite, rng),
               MatrixType::symmetric_indefinite});
  p.push_back({"random indefinite 3",
               test::random_sparse(3, 2, test::RandomKind::symmetric_indefinite, rng),
               MatrixType::symmetric_indefinite});
  p.push_back({"watt_2", shared("watt_2"), MatrixType::general});
  p.push_back({"nnc1374", shared("nnc1374"), MatrixType::general});
  p.push_back({"random general 1500", test::random_sparse(1500, 4, test::RandomKind::general, rng),
               MatrixType::general});
  {  // a 3D grid with unsymmetric values: large LU fronts
    SparseMatrix a = expand_symmetric(generators::laplacian_3d(11, 11, 11));
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& v : a.values) v *= u(rng);
    p.push_back({"lap3d 11 unsymmetric", std::move(a), MatrixType::general});
  }
  return p;
}

// One clock for every Recording: the order of begin_part and end_part calls over all
// workers.
std::atomic<long> event_clock{0};

// Forwards to a CPU executor, counting the fronts of every batch it factors and stamping
// each part's begin_part and end_part with event_clock, and throws a DeviceError at the
// start of part `fail_part` (a part id: subtree index, P for the top part, above P the
// upper parts), whichever worker runs it, when asked to.
class Recording final : public numeric::Executor {
 public:
  Recording(index_t n_fronts, int fail_part = -2)
      : inner_(numeric::make_cpu_executor(1)), count(n_fronts, 0), fail_part_(fail_part) {}
  const char* name() const override { return "recording"; }
  void begin(const numeric::FactorContext& c) override { inner_->begin(c); }
  void begin_part(const numeric::FactorContext& c) override {
    if (c.part->id == fail_part_) throw DeviceError("injected failure");
    helpers_of[c.part->id] = c.helpers;
    began[c.part->id] = event_clock++;
    inner_->begin_part(c);
  }
  void factor_batch(const numeric::FactorContext& c, const BatchInfo& b) override {
    for (index_t q = b.begin; q < b.end; ++q) ++count[c.part->schedule->fronts[q]];
    inner_->factor_batch(c, b);
  }
  void end_part(const numeric::FactorContext& c) override {
    inner_->end_part(c);
    ended[c.part->id] = event_clock++;
  }
  std::size_t export_cb(const numeric::FactorContext& c, numeric::CbTransfer& t) override {
    return inner_->export_cb(c, t);
  }
  std::size_t import_cb(const numeric::FactorContext& c, const numeric::CbTransfer& t) override {
    return inner_->import_cb(c, t);
  }
  void end(const numeric::FactorContext& c) override { inner_->end(c); }

  std::unique_ptr<numeric::Executor> inner_;
  std::vector<int> count;
  std::map<int, std::vector<numeric::Executor*>> helpers_of;  ///< part id → ctx.helpers
  std::map<int, long> began, ended;                           ///< part id → event_clock

 private:
  int fail_part_;
};

// The depth-first factor x and the level-schedule factor y of the same values agree to
// rounding: entries within 1e-10 of the largest (their pivots are those of one
// factorization computed in two orders).
void expect_close_factors(const numeric::NumericFactor& x, const numeric::NumericFactor& y) {
  ASSERT_EQ(x.panels.size(), y.panels.size());
  double scale = 0, diff = 0;
  for (std::size_t i = 0; i < x.panels.size(); ++i) {
    scale = std::max(scale, std::abs(y.panels[i]));
    diff = std::max(diff, std::abs(x.panels[i] - y.panels[i]));
  }
  EXPECT_LE(diff, 1e-10 * scale);
  EXPECT_EQ(x.rows, y.rows);
  EXPECT_EQ(x.pivot_size, y.pivot_size);
}

// `workers` Recording executors (failing at part fail_part, see Recording) and the
// executor pointers factorize_multi takes.
struct Recorders {
  Recorders(int workers, index_t n_fronts, int fail_part = -2) {
    for (int w = 0; w < workers; ++w) {
      rec.push_back(std::make_unique<Recording>(n_fronts, fail_part));
      execs.push_back(rec.back().get());
    }
  }
  std::vector<std::unique_ptr<Recording>> rec;
  std::vector<numeric::Executor*> execs;
};

// An analysis split for `workers` workers (also for one: then split on demand), with 4
// subtrees per worker at least (not the default 1): more parts, transfers between them
// and subtrees to steal.
Analysis split_analysis(const SparseMatrix& a, MatrixType type, int workers) {
  Options o;
  o.type = type;
  o.subtrees_per_gpu = 4;
  Analysis an = analyze_matrix(a, o, workers);
  if (workers == 1) {
    schedule::PartitionOptions po;
    po.workers = 1;
    po.subtrees_per_worker = o.subtrees_per_gpu;
    po.unsymmetric = type == MatrixType::general;
    an.partition = schedule::partition_tree(an.tree, po);
  }
  return an;
}

void expect_same_factor(const numeric::NumericFactor& x, const numeric::NumericFactor& y) {
  EXPECT_TRUE(x.panels == y.panels) << "factor panels differ";
  EXPECT_EQ(x.rows, y.rows);
  EXPECT_TRUE(x.d_diag == y.d_diag);
  EXPECT_TRUE(x.d_off == y.d_off);
  EXPECT_EQ(x.pivot_size, y.pivot_size);
  ASSERT_EQ(x.front_stats.size(), y.front_stats.size());
  for (std::size_t f = 0; f < x.front_stats.size(); ++f) {
    EXPECT_EQ(x.front_stats[f].perturbed, y.front_stats[f].perturbed);
    EXPECT_EQ(x.front_stats[f].positive, y.front_stats[f].positive);
    EXPECT_EQ(x.front_stats[f].negative, y.front_stats[f].negative);
    EXPECT_EQ(x.front_stats[f].log_abs_det, y.front_stats[f].log_abs_det);
  }
}

// 1, 2, 3 and 4 workers give bitwise the factor of one executor on the whole tree, and
// every front is factored exactly once.
// The workers' part logs (DeviceStats::parts): every part once, on the worker that ran
// it (upper parts on their owners, the top on worker 0), with its work, in time order
// per worker, and each part begun only after every part it imports from had ended.
void expect_part_log(const schedule::TreePartition& part, const std::vector<DeviceStats>& dev) {
  const int n_sub = static_cast<int>(part.subtrees.size());
  std::vector<const PartRun*> by_id(part.n_parts(), nullptr);
  std::vector<int> worker_of(part.n_parts(), -1);
  for (std::size_t w = 0; w < dev.size(); ++w) {
    double last_end = 0;
    index_t stolen = 0;
    for (const PartRun& r : dev[w].parts) {
      const int id = r.kind == PartRun::Kind::subtree ? static_cast<int>(r.index)
                     : r.kind == PartRun::Kind::top   ? n_sub
                                                      : n_sub + 1 + static_cast<int>(r.index);
      ASSERT_GE(id, 0);
      ASSERT_LT(id, part.n_parts());
      EXPECT_EQ(by_id[id], nullptr) << "part " << id << " logged twice";
      by_id[id] = &r;
      worker_of[id] = static_cast<int>(w);
      EXPECT_NEAR(r.flops, part.part(id).work, 1e-9 * std::max(1.0, r.flops));
      EXPECT_LE(last_end, r.start_seconds) << "worker " << w << " ran two parts at once";
      EXPECT_LE(r.start_seconds, r.end_seconds);
      last_end = r.end_seconds;
      stolen += r.stolen ? 1 : 0;
      if (r.stolen) EXPECT_EQ(r.kind, PartRun::Kind::subtree);
    }
    EXPECT_EQ(stolen, dev[w].subtrees_stolen);
  }
  for (int id = 0; id < part.n_parts(); ++id) {
    ASSERT_NE(by_id[id], nullptr) << "part " << id << " not logged";
    if (id == n_sub) EXPECT_EQ(worker_of[id], 0);
    if (id > n_sub) EXPECT_EQ(worker_of[id], part.upper_owner[id - n_sub - 1]);
    for (index_t c : part.part(id).imports) {
      const PartRun* below = by_id[part.part_id[c]];
      ASSERT_NE(below, nullptr);
      EXPECT_LE(below->end_seconds, by_id[id]->start_seconds)
          << "part " << id << " began before part " << part.part_id[c] << " had ended";
    }
  }
}

TEST(MultiWorker, FactorBitwiseEqualsOneExecutorAndEveryFrontOnce) {
  auto rng = test::fresh_rng();
  int with_upper_layers = 0;  // runs whose top part was split (so the test covers them)
  for (const Problem& pr : problems(rng))
    for (int workers : {1, 2, 3, 4}) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(workers) + " workers");
      const Analysis an = split_analysis(pr.a, pr.type, workers);
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
      numeric::NumericFactor depth_first, many;
      std::vector<double> arena;
      auto cpu = numeric::make_cpu_executor(1);
      numeric::factorize(an, v, pr.type, pivot, *cpu, depth_first, arena);
      const numeric::NumericFactor one = test::level_schedule_factor(an, v, pr.type, pivot);
      expect_close_factors(depth_first, one);

      Recorders recorders(workers, an.tree.n_fronts());
      auto& rec = recorders.rec;
      const auto& execs = recorders.execs;
      std::vector<std::vector<double>> arenas;
      std::vector<DeviceStats> dev;
      numeric::factorize_multi(an, v, pr.type, pivot, execs, many, arenas, {}, &dev);
      EXPECT_TRUE(many.valid);
      expect_same_factor(one, many);
      for (index_t f = 0; f < an.tree.n_fronts(); ++f) {
        int c = 0;
        for (const auto& r : rec) c += r->count[f];
        ASSERT_EQ(c, 1) << "front " << f << " factored " << c << " times";
      }
      ASSERT_EQ(dev.size(), static_cast<std::size_t>(workers));
      index_t run = 0, upper_run = 0;
      double flops = 0;
      std::size_t bytes = 0;
      for (const DeviceStats& d : dev) {
        run += d.subtrees_run;
        upper_run += d.upper_parts_run;
        flops += d.flops;
        bytes += d.bytes_transferred;
        EXPECT_LE(d.subtrees_stolen, d.subtrees_run);
        EXPECT_GE(d.busy_seconds, 0.0);
        EXPECT_GE(d.idle_seconds, 0.0);
      }
      const auto& part = an.partition;
      EXPECT_EQ(run, static_cast<index_t>(part.subtrees.size()));
      EXPECT_EQ(upper_run, static_cast<index_t>(part.upper.size()));
      expect_part_log(part, dev);
      // each upper part on its owner
      for (std::size_t k = 0; k < part.upper.size(); ++k)
        for (index_t f : part.upper[k].fronts) EXPECT_EQ(rec[part.upper_owner[k]]->count[f], 1);
      for (index_t f : part.top.fronts) EXPECT_EQ(rec[0]->count[f], 1);
      with_upper_layers += part.n_upper_layers() > 0;
      EXPECT_NEAR(flops, an.stats.factor_flops, 1e-9 * std::max(1.0, flops));
      std::size_t expect_bytes = 0;  // every imported block crosses twice: out and in
      std::vector<const schedule::FactorPart*> importers{&part.top};
      for (const auto& u : part.upper) importers.push_back(&u);
      for (const auto* q : importers)
        for (index_t c : q->imports)
          expect_bytes += 2 * sizeof(double) * an.tree.cb_size(c) * an.tree.cb_size(c);
      EXPECT_EQ(bytes, expect_bytes);
    }
  EXPECT_GT(with_upper_layers, 0) << "no problem had its top part split into upper layers";
}

// Problems whose top part is split into upper layers (asserted), all three types, with
// 2, 3 and 4 workers: bitwise the one-executor factor, with the split on and off, each
// upper part factored by its owner and exactly once; through the Solver the solution
// agrees with a dense LAPACK solve.
TEST(MultiWorker, UpperLayersGiveTheOneWorkerFactor) {
  auto rng = test::fresh_rng();
  std::vector<Problem> ps;
  const SparseMatrix lap = generators::laplacian_3d(12, 12, 12);
  ps.push_back({"lap3d 12", lap, MatrixType::spd});
  {  // shifted: indefinite with a positive diagonal
    SparseMatrix s = lap;
    for (index_t j = 0; j < s.n_cols; ++j)
      for (index_t p = s.offsets[j]; p < s.offsets[j + 1]; ++p)
        if (s.indices[p] == j) s.values[p] -= 2.5;
    ps.push_back({"shifted lap3d 12", std::move(s), MatrixType::symmetric_indefinite});
  }
  {
    SparseMatrix g = expand_symmetric(lap);
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& x : g.values) x *= u(rng);
    ps.push_back({"unsymmetric lap3d 12", std::move(g), MatrixType::general});
  }
  for (const Problem& pr : ps) {
    const index_t n = pr.a.n_rows;
    std::vector<double> b(n);
    std::uniform_real_distribution<double> u(-1, 1);
    for (double& x : b) x = u(rng);
    std::vector<double> xd = b;
    ASSERT_TRUE(test::dense_solve(test::to_dense(pr.a), n, xd, 1));
    for (int workers : {2, 3, 4}) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(workers) + " workers");
      Options o;
      o.type = pr.type;
      o.subtrees_per_gpu = 4;  // upper layers on these small grids (asserted)
      const Analysis an = analyze_matrix(pr.a, o, workers);
      const auto& part = an.partition;
      ASSERT_GE(part.n_upper_layers(), 1)
          << "the top part was not split: the test would be vacuous";
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
      const numeric::NumericFactor one = test::level_schedule_factor(an, v, pr.type, pivot);
      Recorders recorders(workers, an.tree.n_fronts());
      auto& rec = recorders.rec;
      const auto& execs = recorders.execs;
      numeric::NumericFactor many;
      std::vector<std::vector<double>> arenas;
      std::vector<DeviceStats> dev;
      numeric::factorize_multi(an, v, pr.type, pivot, execs, many, arenas, {}, &dev);
      expect_same_factor(one, many);
      for (std::size_t k = 0; k < part.upper.size(); ++k)
        for (index_t f : part.upper[k].fronts) EXPECT_EQ(rec[part.upper_owner[k]]->count[f], 1);
      for (index_t f = 0; f < an.tree.n_fronts(); ++f) {
        int c = 0;
        for (const auto& r : rec) c += r->count[f];
        ASSERT_EQ(c, 1) << "front " << f;
      }
      index_t upper_run = 0;
      for (int w = 0; w < workers; ++w) {
        index_t own = 0;
        for (int x : part.upper_owner) own += x == w;
        EXPECT_EQ(dev[w].upper_parts_run, own);
        upper_run += dev[w].upper_parts_run;
      }
      EXPECT_EQ(upper_run, static_cast<index_t>(part.upper.size()));
      // helpers (FactorContext::helpers): none for subtrees and upper parts (no worker is
      // known to be idle while they run: no barrier between layers); every other worker
      // for the top part, which runs after all of them
      const int n_sub = static_cast<int>(part.subtrees.size());
      for (int w = 0; w < workers; ++w)
        for (const auto& [id, h] : rec[w]->helpers_of)
          if (id != n_sub) EXPECT_TRUE(h.empty()) << "part " << id;
      {
        const auto& top = rec[0]->helpers_of.at(n_sub);
        EXPECT_EQ(top, std::vector<numeric::Executor*>(execs.begin() + 1, execs.end()));
      }
      // the same with the split off (same tree: the ordering does not depend on it)
      o.split_top = false;
      const Analysis off = analyze_matrix(pr.a, o, workers);
      ASSERT_EQ(off.partition.n_upper_layers(), 0);
      ASSERT_EQ(off.tree.parent, an.tree.parent);
      numeric::NumericFactor many_off;
      numeric::factorize_multi(off, v, pr.type, pivot, execs, many_off, arenas, {}, nullptr);
      expect_same_factor(one, many_off);
      // through the Solver, against the dense solve
      Options so;
      so.type = pr.type;
      so.subtrees_per_gpu = 4;
      Solver s(so);
      SolverAccess::use_host_workers(s, workers, 1);
      s.factorize(pr.a);
      EXPECT_GE(s.stats().analysis.upper_layers, 1);
      const auto x = s.solve(b);
      EXPECT_LT(test::relative_difference(x, xd), 1e-8);
      EXPECT_LE(test::backward_error(pr.a, x.data(), b.data()), 1e-14);
    }
  }
}

// No barrier between layers: an upper part starts as soon as the parts it reads from are
// done, while another worker still factors subtrees it does not depend on (slowed by an
// injected delay, stealing off). Found on the 3D grids where the split allows it (at least
// one must, or the test would be vacuous); the factor is still the one-worker factor.
TEST(MultiWorker, UpperPartsDoNotWaitForUnrelatedSubtrees) {
  int checked = 0;
  for (const index_t k : {12, 16})
    for (int workers : {2, 3, 4}) {
      SCOPED_TRACE("lap3d " + std::to_string(k) + ", " + std::to_string(workers) + " workers");
      const SparseMatrix a = generators::laplacian_3d(k, k, k);
      Options o;
      o.type = MatrixType::spd;
      o.subtrees_per_gpu = 4;  // upper parts on these small grids
      const Analysis an = analyze_matrix(a, o, workers);
      const auto& part = an.partition;
      const int n_sub = static_cast<int>(part.subtrees.size());
      // below[id]: the parts part id reads from, directly or not
      std::vector<std::vector<char>> below(part.n_parts(), std::vector<char>(part.n_parts(), 0));
      for (int id = 0; id < part.n_parts(); ++id)  // lower layers have lower ids but the top
        if (id != n_sub)
          for (const index_t c : part.part(id).imports) {
            const auto cid = static_cast<int>(part.part_id[c]);
            below[id][cid] = 1;
            for (int x = 0; x < part.n_parts(); ++x) below[id][x] |= below[cid][x];
          }
      // an upper part and a worker (not its owner) none of whose subtrees it reads from
      int upper = -1, slow = -1;
      for (std::size_t q = 0; q < part.upper.size() && upper < 0; ++q) {
        const int id = n_sub + 1 + static_cast<int>(q);
        for (int w = 0; w < workers && upper < 0; ++w) {
          if (w == part.upper_owner[q]) continue;
          bool has = false, unrelated = true;
          for (int i = 0; i < n_sub; ++i)
            if (part.owner[i] == w) {
              has = true;
              unrelated = unrelated && !below[id][i];
            }
          if (has && unrelated) {
            upper = id;
            slow = w;
          }
        }
      }
      if (upper < 0) continue;
      ++checked;
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, a, &pivot);
      const numeric::NumericFactor one = test::level_schedule_factor(an, v, MatrixType::spd, pivot);
      Recorders recorders(workers, an.tree.n_fronts());
      auto& rec = recorders.rec;
      const auto& execs = recorders.execs;
      numeric::MultiWorkerConfig cfg;
      cfg.work_stealing = false;
      cfg.before_subtree = [slow](int w, int) { test::sleep_if(w == slow, 0.3); };
      numeric::NumericFactor many;
      std::vector<std::vector<double>> arenas;
      numeric::factorize_multi(an, v, MatrixType::spd, pivot, execs, many, arenas, cfg, nullptr);
      expect_same_factor(one, many);
      long last_slow = -1;
      for (const auto& [id, t] : rec[slow]->ended)
        if (id < n_sub) last_slow = std::max(last_slow, t);
      const int owner = part.worker_of(upper);
      ASSERT_TRUE(rec[owner]->began.count(upper));
      EXPECT_LT(rec[owner]->began.at(upper), last_slow)
          << "upper part " << upper << " waited for worker " << slow << "'s subtrees";
    }
  EXPECT_GT(checked, 0) << "no split allowed the check: the test would be vacuous";
}

// Through the Solver (N CPU executors standing for N GPUs): solutions agree with the
// one-worker CPU solver and the backward error is at the unit roundoff; refactorization
// with new values gives bitwise the solution of a fresh factorization.
TEST(MultiWorker, SolverSolutionsAndRefactorization) {
  auto rng = test::fresh_rng();
  std::uniform_real_distribution<double> u(-1, 1), scale(0.8, 1.2);
  for (const Problem& pr : problems(rng)) {
    const SparseMatrix& a = pr.a;
    const index_t n = a.n_rows;
    std::vector<double> b(n);
    for (double& x : b) x = u(rng);
    Options o;
    o.type = pr.type;
    Solver ref(o);
    ref.factorize(a);
    const std::vector<double> xr = ref.solve(b);
    const double berr_ref = test::backward_error(a, xr.data(), b.data());
    for (int workers : {2, 3, 4}) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(workers) + " workers");
      Solver s(o);
      SolverAccess::use_host_workers(s, workers, 1);
      s.factorize(a);
      const auto x = s.solve(b);
      const Stats& st = s.stats();
      EXPECT_EQ(st.analysis.workers, workers);
      ASSERT_EQ(st.factor.devices.size(), static_cast<std::size_t>(workers));
      index_t run = 0;
      for (const auto& d : st.factor.devices) run += d.subtrees_run;
      EXPECT_EQ(run, st.analysis.subtrees);
      EXPECT_LE(test::backward_error(a, x.data(), b.data()), std::max(1e-14, 2 * berr_ref));
      EXPECT_LT(test::relative_difference(x, xr), 1e-8);
      EXPECT_EQ(s.stats().factor.inertia_negative, ref.stats().factor.inertia_negative);
      if (ref.stats().factor.perturbed_pivots == 0 && st.factor.perturbed_pivots == 0)
        EXPECT_NEAR(st.factor.log_abs_determinant, ref.stats().factor.log_abs_determinant,
                    1e-8 * std::max(1.0, std::abs(ref.stats().factor.log_abs_determinant)));
      // new values, same pattern (a symmetric scaling keeps the type)
      SparseMatrix a2 = a;
      std::vector<double> d(n);
      for (double& x2 : d) x2 = scale(rng);
      for (index_t j = 0; j < a2.n_cols; ++j)
        for (index_t p = a2.offsets[j]; p < a2.offsets[j + 1]; ++p)
          a2.values[p] *= d[a2.indices[p]] * d[j];
      s.refactorize(a2);
      const auto x2 = s.solve(b);
      Solver fresh(o);  // same analysis (scaling and pairs come from the analyzed values)
      SolverAccess::use_host_workers(fresh, workers, 1);
      fresh.analyze(a);
      fresh.factorize(a2);
      EXPECT_TRUE(fresh.solve(b) == x2) << "refactorization differs from a fresh factorization";
      EXPECT_LE(test::backward_error(a2, x2.data(), b.data()), std::max(1e-14, 4 * berr_ref));
    }
  }
}

// Small problems against a dense LAPACK solve; workers with two host threads each.
TEST(MultiWorker, SmallProblemsMatchDenseAndThreadedWorkers) {
  auto rng = test::fresh_rng();
  for (auto [kind, type] :
       {std::pair{test::RandomKind::spd, MatrixType::spd},
        std::pair{test::RandomKind::symmetric_indefinite, MatrixType::symmetric_indefinite},
        std::pair{test::RandomKind::general, MatrixType::general}})
    for (index_t n : {1, 2, 3, 5, 200}) {
      SCOPED_TRACE(std::string(to_string(type)) + " n=" + std::to_string(n));
      const SparseMatrix a = test::random_sparse(n, 3, kind, rng);
      std::vector<double> b(n);
      std::uniform_real_distribution<double> u(-1, 1);
      for (double& x : b) x = u(rng);
      std::vector<double> xd = b;
      ASSERT_TRUE(test::dense_solve(test::to_dense(a), n, xd, 1));
      Options o;
      o.type = type;
      Solver s(o);
      SolverAccess::use_host_workers(s, 2, 2);
      s.factorize(a);
      const auto x = s.solve(b);
      EXPECT_LT(test::relative_difference(x, xd), 1e-8);
      EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-14);
    }
}

// A slowed worker 0 (injected delay before each subtree): the other workers steal its
// unstarted subtrees, and the factor is still bitwise the one-executor factor. Without
// stealing every worker runs exactly its own queue.
TEST(MultiWorker, SlowWorkerHasItsSubtreesStolen) {
  auto rng = test::fresh_rng();
  std::vector<Problem> ps;
  const SparseMatrix lap = generators::laplacian_3d(16, 16, 16);
  ps.push_back({"lap3d 16", lap, MatrixType::spd});
  {  // shifted: indefinite with a positive diagonal
    SparseMatrix s = lap;
    for (index_t j = 0; j < s.n_cols; ++j)
      for (index_t p = s.offsets[j]; p < s.offsets[j + 1]; ++p)
        if (s.indices[p] == j) s.values[p] -= 2.5;
    ps.push_back({"shifted lap3d 16", std::move(s), MatrixType::symmetric_indefinite});
  }
  {
    SparseMatrix g = expand_symmetric(lap);
    std::uniform_real_distribution<double> u(0.5, 1.5);
    for (double& x : g.values) x *= u(rng);
    ps.push_back({"unsymmetric lap3d 16", std::move(g), MatrixType::general});
  }
  for (const Problem& pr : ps)
    for (int workers : {2, 4}) {
      SCOPED_TRACE(pr.name + ", " + std::to_string(workers) + " workers");
      const Analysis an = split_analysis(pr.a, pr.type, workers);
      std::vector<int> own(workers, 0);
      for (int w : an.partition.owner) ++own[w];
      ASSERT_GE(own[0], 2) << "worker 0 needs a queue to steal from";
      double pivot = 0;
      const std::vector<double> v = test::scaled_values(an, pr.a, &pivot);
      const numeric::NumericFactor one = test::level_schedule_factor(an, v, pr.type, pivot);
      for (bool stealing : {true, false}) {
        SCOPED_TRACE(stealing ? "stealing" : "no stealing");
        std::vector<std::unique_ptr<numeric::Executor>> ex;
        std::vector<numeric::Executor*> execs;
        for (int w = 0; w < workers; ++w) {
          ex.push_back(numeric::make_cpu_executor(1));
          execs.push_back(ex.back().get());
        }
        numeric::MultiWorkerConfig cfg;
        cfg.work_stealing = stealing;
        cfg.before_subtree = [stealing](int w, int) {
          test::sleep_if(w == 0, stealing ? 0.5 : 0.05);
        };
        numeric::NumericFactor many;
        std::vector<std::vector<double>> arenas;
        std::vector<DeviceStats> dev;
        numeric::factorize_multi(an, v, pr.type, pivot, execs, many, arenas, cfg, &dev);
        expect_same_factor(one, many);
        index_t stolen_by_others = 0;
        for (int w = 1; w < workers; ++w) stolen_by_others += dev[w].subtrees_stolen;
        if (stealing) {
          EXPECT_GT(stolen_by_others, 0);
          EXPECT_LT(dev[0].subtrees_run, own[0]);
        } else {
          for (int w = 0; w < workers; ++w) {
            EXPECT_EQ(dev[w].subtrees_stolen, 0);
            EXPECT_EQ(dev[w].subtrees_run, own[w]);
          }
        }
      }
    }
}

// Executors that keep every part's panels in their own memory (a stand-in for GPUs, which
// factor nothing here) leave factor.panels unsized — sizing it zero-filled the whole
// factor's host copy, seconds for a large one, that no one read — and list each part they
// kept in factor.held; fetch_panels sizes the panels and has each part's holder fill that
// part's fronts; one executor that does not keep its parts' panels (a CPU executor) makes
// the driver size them before that part.
class KeepsPanels final : public numeric::Executor {
 public:
  explicit KeepsPanels(double marker) : marker_(marker) {}
  const char* name() const override { return "keeps-panels"; }
  void factor_batch(const numeric::FactorContext&, const BatchInfo&) override {}
  std::size_t export_cb(const numeric::FactorContext&, numeric::CbTransfer& t) override {
    std::fill_n(t.host_buffer(), t.size, 0.0);  // a block for a host importer
    t.on_host = true;
    return 0;
  }
  std::size_t import_cb(const numeric::FactorContext&, const numeric::CbTransfer&) override {
    return 0;
  }
  bool keeps_panels(const numeric::FactorContext&) const override { return true; }
  void download_panels(const Analysis& an, int part, numeric::NumericFactor& fac) override {
    ASSERT_EQ(fac.panels.size(), static_cast<std::size_t>(an.factor_layout.total));
    for (index_t f = 0; f < an.tree.n_fronts(); ++f) {
      if (an.partition.part_id[f] != part) continue;
      double* p = fac.panels.data() + an.factor_layout.panel_offset[f];
      for (std::size_t i = 0; i < panel_size(an.tree, f, false); ++i) p[i] += marker_;
    }
  }

 private:
  double marker_;
};

TEST(MultiWorker, HostPanelsSizedOnlyWhenAPartWritesThem) {
  const SparseMatrix a = generators::laplacian_3d(10, 10, 10);
  const Analysis an = split_analysis(a, MatrixType::spd, 2);
  double pivot = 0;
  const std::vector<double> v = test::scaled_values(an, a, &pivot);
  const auto total = static_cast<std::size_t>(an.factor_layout.total);
  ASSERT_GT(total, 0u);
  const int n_parts = an.partition.n_parts();
  KeepsPanels k0(1.0), k1(2.0);
  const std::vector<numeric::Executor*> execs{&k0, &k1};
  std::vector<std::vector<double>> arenas;
  {
    numeric::NumericFactor f;
    numeric::factorize_multi(an, v, MatrixType::spd, pivot, execs, f, arenas, {}, nullptr);
    EXPECT_TRUE(f.panels.empty()) << "host panels sized though every part kept its panels";
    // every part once, in part order, held by the worker that factored it
    ASSERT_EQ(f.held.size(), static_cast<std::size_t>(n_parts));
    std::vector<double> marker(n_parts);
    for (int i = 0; i < n_parts; ++i) {
      EXPECT_EQ(f.held[i].part, i);
      ASSERT_TRUE(f.held[i].worker == 0 || f.held[i].worker == 1);
      marker[i] = f.held[i].worker == 0 ? 1.0 : 2.0;
    }
    EXPECT_EQ(f.held[an.partition.subtrees.size()].worker, 0) << "the top part is worker 0's";
    numeric::fetch_panels(an, execs, f);
    ASSERT_EQ(f.panels.size(), total);
    EXPECT_TRUE(f.held.empty());
    // zero-filled by fetch, then each front's panel filled by the holder of its part
    for (index_t fr = 0; fr < an.tree.n_fronts(); ++fr) {
      const double* p = f.panels.data() + an.factor_layout.panel_offset[fr];
      for (std::size_t i = 0; i < panel_size(an.tree, fr, false); ++i)
        ASSERT_EQ(p[i], marker[an.partition.part_id[fr]]) << "front " << fr;
    }
    numeric::fetch_panels(an, execs, f);  // nothing held: nothing added
    // front 0's own panel (panels are laid out in level order: panels[0] may be another
    // front's, of a part that the other worker held)
    EXPECT_EQ(f.panels[an.factor_layout.panel_offset[0]], marker[an.partition.part_id[0]]);
    f.held.push_back({0, 2});  // a worker the list does not have
    EXPECT_THROW(numeric::fetch_panels(an, execs, f), InternalError);
  }
  {  // one CPU executor: its parts' panels go to the host, sized before it writes them
    const auto cpu = numeric::make_cpu_executor(1);
    numeric::NumericFactor f;
    numeric::factorize_multi(an, v, MatrixType::spd, pivot, {cpu.get(), &k1}, f, arenas, {},
                             nullptr);
    EXPECT_EQ(f.panels.size(), total);
    ASSERT_FALSE(f.held.empty());  // k1 holds the panels of its parts
    for (const numeric::HeldPanels& h : f.held) EXPECT_EQ(h.worker, 1);
  }
}

// A worker that fails stops the others, every thread is joined, and the first error
// reaches the caller; a matrix declared spd that is not fails with NotPositiveDefinite
// through the Solver, which stays usable.
TEST(MultiWorker, ErrorsPropagate) {
  const SparseMatrix a = generators::laplacian_3d(12, 12, 12);
  const Analysis an = split_analysis(a, MatrixType::spd, 3);
  const int n_sub = static_cast<int>(an.partition.subtrees.size());
  ASSERT_GE(n_sub, 3);
  ASSERT_GE(an.partition.upper.size(), 2u);
  const int last = an.partition.n_parts() - 1;
  // n_sub: the top part; n_sub + 1 ..: upper parts
  for (int failing : {0, n_sub / 2, n_sub - 1, n_sub, n_sub + 1, last}) {
    SCOPED_TRACE("failing part " + std::to_string(failing));
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, a, &pivot);
    Recorders recorders(3, an.tree.n_fronts(), failing);
    const auto& execs = recorders.execs;
    numeric::NumericFactor f;
    std::vector<std::vector<double>> arenas;
    EXPECT_THROW(
        numeric::factorize_multi(an, v, MatrixType::spd, pivot, execs, f, arenas, {}, nullptr),
        DeviceError);
    EXPECT_FALSE(f.valid);
  }
  // shifted Laplacian: positive diagonal, indefinite
  SparseMatrix s = a;
  for (index_t j = 0; j < s.n_cols; ++j)
    for (index_t p = s.offsets[j]; p < s.offsets[j + 1]; ++p)
      if (s.indices[p] == j) s.values[p] -= 3.0;
  Options o;
  o.type = MatrixType::spd;
  Solver solver(o);
  SolverAccess::use_host_workers(solver, 3, 1);
  EXPECT_THROW(solver.factorize(s), NotPositiveDefinite);
  solver.refactorize(a);
  std::vector<double> b(a.n_rows, 1.0);
  const auto x = solver.solve(b);
  EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-14);
  // automatic: the Cholesky attempt fails on some worker, LDLᵀ follows
  Options oa;
  Solver auto_solver(oa);
  SolverAccess::use_host_workers(auto_solver, 3, 1);
  auto_solver.factorize(s);
  EXPECT_EQ(auto_solver.matrix_type(), MatrixType::symmetric_indefinite);
  const auto xs = auto_solver.solve(b);
  EXPECT_LE(test::backward_error(s, xs.data(), b.data()), 1e-14);
  EXPECT_GT(auto_solver.stats().factor.inertia_negative, 0);
}

// The numeric drivers (numeric/driver.hpp) directly: the tree driver and the multi-worker
// driver of CPU executors give the same factor on one analysis and the same solve with
// it, bitwise (the factor itself is checked against the Solver and dense references by
// the tests above); their kinds are reported as the Solver needs them; bad worker counts
// are refused.
TEST(NumericDrivers, TreeAndMultiWorkerDriversAgree) {
  const SparseMatrix a = generators::laplacian_3d(9, 8, 7);
  Options o;
  o.type = MatrixType::spd;
  const int workers = 3;
  const Analysis an = analyze_matrix(a, o, workers);
  double pivot = 0;
  const std::vector<double> v = test::scaled_values(an, a, &pivot);
  auto tree = numeric::make_tree_driver(o);
  auto multi = numeric::make_multi_worker_driver(o, workers, 1, {});
  EXPECT_EQ(tree->workers(), 1);
  EXPECT_TRUE(tree->in_one_process());
  EXPECT_FALSE(tree->uploads_values());
  EXPECT_EQ(multi->workers(), workers);
  EXPECT_TRUE(multi->in_one_process());
  EXPECT_FALSE(multi->uploads_values());
  numeric::NumericFactor one, many;
  tree->factorize(an, v, false, MatrixType::spd, pivot,
                  one);  // depth-first (see level_schedule_factor)
  multi->factorize(an, v, false, MatrixType::spd, pivot, many);
  numeric::NumericFactor level = test::level_schedule_factor(an, v, MatrixType::spd, pivot);
  expect_same_factor(level, many);
  expect_close_factors(one, many);
  EXPECT_EQ(tree->backend(), Backend::cpu);
  EXPECT_EQ(multi->backend(), Backend::cpu);
  FactorStats fs;
  multi->report(fs);
  ASSERT_EQ(fs.devices.size(), static_cast<std::size_t>(workers));
  // solutions in tree numbering: the same right-hand side through both factors
  std::mt19937_64 rng(std::random_device{}());
  std::normal_distribution<double> g;
  std::vector<double> x1(an.n), x2, x3;
  for (double& e : x1) e = g(rng);
  x3 = x2 = x1;
  EXPECT_FALSE(tree->solve(an, one, x1.data(), 1));
  EXPECT_FALSE(multi->solve(an, many, x2.data(), 1));
  EXPECT_FALSE(tree->solve(an, level, x3.data(), 1));
  EXPECT_EQ(x3, x2);  // the same factor solved by either driver
  EXPECT_LE(test::relative_difference(x1, x2), 1e-12);
  EXPECT_THROW(numeric::make_multi_worker_driver(o, 0, 1, {}), InvalidInput);
  EXPECT_THROW(numeric::make_multi_worker_driver(o, 2, -1, {}), InvalidInput);
}

// One host worker (DistributedSolver's single rank with host workers, bench_distributed
// --backend cpu under `mpirun -n 1`): the analysis for one worker is not split, and the
// multi-worker driver factors the whole tree on its worker — the tree driver's factor
// with an executor of the same threads, bitwise — for every type, through the Solver too,
// against a dense solve. Sizes 1, 2, 3, 5, 733 and a 3D grid.
TEST(NumericDrivers, OneHostWorkerFactorsTheWholeTree) {
  auto rng = test::fresh_rng();
  std::vector<std::pair<std::string, SparseMatrix>> ms;
  for (const index_t n : {1, 2, 3, 5, 733})
    ms.emplace_back("general " + std::to_string(n),
                    test::random_sparse(n, 3, test::RandomKind::general, rng));
  ms.emplace_back("lap3d 9x8x7", generators::laplacian_3d(9, 8, 7));
  for (const auto& [name, a] : ms) {
    SCOPED_TRACE(name);
    const MatrixType type = a.storage == Storage::full ? MatrixType::general : MatrixType::spd;
    Options o;
    o.type = type;
    o.num_threads = 2;
    const Analysis an = analyze_matrix(a, o, 1);
    ASSERT_TRUE(an.partition.part_id.empty());
    double pivot = 0;
    const std::vector<double> v = test::scaled_values(an, a, &pivot);
    auto tree = numeric::make_tree_driver(o);
    auto multi = numeric::make_multi_worker_driver(o, 1, 2, {});
    numeric::NumericFactor one, many;
    tree->factorize(an, v, false, type, pivot, one);
    multi->factorize(an, v, false, type, pivot, many);
    expect_same_factor(one, many);
    Solver s(o);
    SolverAccess::use_host_workers(s, 1, 2);
    s.factorize(a);
    std::vector<double> b(a.n_rows);
    std::uniform_real_distribution<double> u(-1, 1);
    for (double& e : b) e = u(rng);
    const auto x = s.solve(b);
    std::vector<double> xd = b;
    if (!test::dense_solve(test::to_dense(a), a.n_rows, xd, 1)) continue;  // a singular draw
    EXPECT_LE(test::backward_error(a, x.data(), b.data()), 1e-12);
  }
}

// Pivoting::automatic with several workers in one process (GPUs, here CPU executors):
// values whose matching is stale (a dominant diagonal at analysis, a zero one refactorized)
// need static pivots in the analysis's order; the delayed factorization then takes over on
// the host as after one executor's, so no pivot stays perturbed and the solution is
// accurate — the same delayed factor as one executor's when the analysis is the same.
TEST(NumericDrivers, SeveralWorkersDelayPivotsOnTheHost) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed) + " (STRATA_TEST_SEED replays it)");
  const test::StaleAnalysis m = test::stale_analysis(733, rng);
  Options o;
  o.type = MatrixType::general;
  o.pivoting = Pivoting::automatic;
  o.relax_small = 0;  // fundamental supernodes: one-pivot leaf fronts
  o.relax_zeros_1 = o.relax_zeros_2 = o.relax_zeros_3 = 0;
  std::vector<double> x[2];
  FactorStats f[2];
  std::vector<index_t> perm[2];
  for (int w = 0; w < 2; ++w) {
    SCOPED_TRACE(w ? "two workers" : "one executor");
    Solver s(o);
    if (w) detail::SolverAccess::set_driver(s, numeric::make_multi_worker_driver(o, 2, 1, {}));
    s.factorize(m.analyzed);
    EXPECT_EQ(s.stats().analysis.workers, w ? 2 : 1);
    s.refactorize(m.stale);
    f[w] = s.stats().factor;
    x[w] = s.solve(m.b);
    perm[w] = detail::SolverAccess::analysis(s)->perm;
    EXPECT_LE(s.stats().solve.backward_error, 1e-14);
    EXPECT_TRUE(f[w].delayed_pivoting);
    EXPECT_GT(f[w].fixed_order_perturbed_pivots, 0);
    EXPECT_EQ(f[w].perturbed_pivots, 0);
  }
  if (perm[0] == perm[1]) {  // the same order (the split alone differs): the same host code
    EXPECT_EQ(f[1].delayed_pivots, f[0].delayed_pivots);
    EXPECT_EQ(f[1].log_abs_determinant, f[0].log_abs_determinant);
    EXPECT_EQ(x[1], x[0]);
  }
}

}  // namespace
}  // namespace strata
