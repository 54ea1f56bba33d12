// strata — multifrontal LU and LDLᵀ with delayed pivots (see delayed.hpp).
//
// Front f of the assembly tree, with msym symbolic rows (its ksym pivots first) and d rows
// and columns delayed by its children, is assembled as an m×m dense matrix, m = d + msym
// (a symmetric matrix's front whole: each entry of its lower triangle at its mirror
// position too):
//
//   rows    = the children's delayed rows (in child order), then f's symbolic rows,
//   columns = the children's delayed columns (in child order), then f's symbolic rows,
//
// with its first p = d + ksym rows and columns fully summed. The original entries come
// from the analysis's assembly map (made for the msym×msym symbolic front: shifted by d),
// and each child's contribution block is added at the positions of its row and column
// lists (a delayed variable's row and column hold nothing from other children: it is
// coupled only to what was in its own front). The partial factorization
// (cpu::factor_front_lu_delayed, or cpu::factor_front_sym_delayed for a symmetric
// matrix) eliminates npiv ≤ p pivots; the rest of the fully summed
// rows and columns lead the contribution block pushed for the parent. A front without a
// parent (a root) may not delay: what is left there is singular to working precision and
// gets static pivots.
//
// Order and storage: on several threads a front is factored (oneTBB) as soon as its last
// child is, the leaves first; on one, in the analysis's level schedule. Each front
// keeps its own factor and contribution block in vectors that keep their capacity for the
// next factorization; a child's block is released (its size, not its capacity) once the
// parent is assembled. Keeping the capacity trades memory (the blocks of every front, not
// only of a stack's depth) for refactorizations that allocate nothing: the delayed path is
// meant for the multibody Newton matrices, whose fronts are small.
#include "numeric/delayed.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_for_each.h>

#include <algorithm>
#include <atomic>
#include <cstring>
#include <exception>
#include <mutex>
#include <new>
#include <string>

#include "base/blas.hpp"
#include "numeric/cpu/small_dense.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

// Parity (+1 / −1) of a permutation given as a sequence of the indices 0..n-1.
int parity(const std::vector<index_t>& seq, std::vector<char>& seen) {
  const std::size_t n = seq.size();
  seen.assign(n, 0);
  int sign = 1;
  for (std::size_t i = 0; i < n; ++i) {
    if (seen[i]) continue;
    std::size_t len = 0;
    for (std::size_t j = i; !seen[j]; j = static_cast<std::size_t>(seq[j])) {
      seen[j] = 1;
      ++len;
    }
    if (len % 2 == 0) sign = -sign;
  }
  return sign;
}

template <class T, class A>
void sized(std::vector<T, A>& v, std::size_t size, const char* what) {
  try {
    v.resize(size);
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(size * sizeof(T), std::string("factorize (delayed pivots): ") + what);
  }
}

// Assembles, factors and stores front f (see the header above); its children are done.
// With `arena`, the front's panel updates run on its threads.
void factor_front(const Analysis& an, const double* vals, const cpu::DelayPolicy& root_policy,
                  index_t f, DelayedFactor& F, DelayedWorkspace::Thread& w,
                  tbb::task_arena* arena = nullptr) {
  const auto& t = an.tree;
  const auto& am = an.assembly;
  const index_t msym = t.n_rows(f), ksym = t.n_pivots(f);
  const index_t* sym = t.rows_of(f);
  const index_t c0 = t.child_offsets[f], c1 = t.child_offsets[f + 1];
  index_t d = 0;
  for (index_t q = c0; q < c1; ++q) d += F.fronts[t.children[q]].delayed;
  const index_t m = d + msym, p = d + ksym;
  DelayedFront& fr = F.fronts[f];
  fr.m = m;
  sized(fr.rows, m, "row lists");
  sized(fr.cols, m, "column lists");
  index_t* R = fr.rows.data();
  index_t* C = fr.cols.data();
  index_t at = 0;
  for (index_t q = c0; q < c1; ++q) {
    const DelayedFront& ch = F.fronts[t.children[q]];
    for (index_t i = 0; i < ch.delayed; ++i, ++at) {
      R[at] = ch.rows[ch.k + i];
      C[at] = ch.cols[ch.k + i];
    }
  }
  for (index_t i = 0; i < msym; ++i) R[d + i] = C[d + i] = sym[i];
  for (index_t i = 0; i < m; ++i) {
    w.row_pos[R[i]] = i;
    w.col_pos[C[i]] = i;
  }

  // assemble: original entries (shifted past the delayed rows and columns), children
  const std::size_t mm = static_cast<std::size_t>(m) * m;
  if (w.front.size() < mm) sized(w.front, mm, "front workspace");
  double* A = w.front.data();
  std::fill(A, A + mm, 0.0);
  const bool symmetric = F.type == MatrixType::symmetric_indefinite;
  if (d == 0 && !symmetric) {  // no delayed rows: the symbolic front's own layout
    for (index_t e = am.entry_offsets[f]; e < am.entry_offsets[f + 1]; ++e)
      A[am.entry_dst[e]] += vals[am.entry_src[e]];
  } else {
    // shifted past the delayed rows; a symmetric matrix's entries (its lower triangle, in
    // the front's lower triangle) also at their mirror position: its front is held whole
    for (index_t e = am.entry_offsets[f]; e < am.entry_offsets[f + 1]; ++e) {
      const index_t dst = am.entry_dst[e];
      const index_t i = dst % msym, j = dst / msym;
      const double v = vals[am.entry_src[e]];
      A[(d + i) + static_cast<std::size_t>(d + j) * m] += v;
      if (symmetric && i != j) A[(d + j) + static_cast<std::size_t>(d + i) * m] += v;
    }
  }
  for (index_t q = c0; q < c1; ++q) {
    DelayedFront& ch = F.fronts[t.children[q]];
    const index_t s = ch.m - ch.k;
    const index_t* br = ch.rows.data() + ch.k;
    const index_t* bc = ch.cols.data() + ch.k;
    // the block's rows' positions in this front (rel), looked up once for all its
    // columns, and the runs of rows whose positions are consecutive (runs: each run's
    // first row, then s): a child's rows mostly land on consecutive rows of its parent,
    // where a column's sum is contiguous (vectorized)
    sized(w.rel, 2 * static_cast<std::size_t>(s) + 1, "front assembly");
    index_t* rel = w.rel.data();
    index_t* runs = rel + s;
    index_t n_runs = 0;
    for (index_t r = 0; r < s; ++r) {
      rel[r] = w.row_pos[br[r]];
      if (r == 0 || rel[r] != rel[r - 1] + 1) runs[n_runs++] = r;
    }
    runs[n_runs] = s;
    for (index_t c = 0; c < s; ++c) {
      double* dst = A + static_cast<std::size_t>(w.col_pos[bc[c]]) * m;
      const double* src = ch.cb.data() + static_cast<std::size_t>(c) * s;
      for (index_t q = 0; q < n_runs; ++q) {
        const index_t r0 = runs[q], r1 = runs[q + 1], shift = rel[r0] - r0;
        for (index_t r = r0; r < r1; ++r) dst[r + shift] += src[r];
      }
    }
    ch.cb.clear();  // consumed (the capacity stays for the next factorization)
  }
  for (index_t i = 0; i < m; ++i) {
    w.row_pos[R[i]] = -1;
    w.col_pos[C[i]] = -1;
  }

  // factor, then the permuted lists (positions p..m are not moved)
  sized(w.row_perm, p, "front permutation");
  sized(w.col_perm, p, "front permutation");
  cpu::DelayPolicy policy = root_policy;
  policy.may_delay = t.parent[f] >= 0;
  fr.stats = PivotStats{};
  const index_t npiv = symmetric
                           ? cpu::factor_front_sym_delayed(A, m, p, m, policy, w.row_perm.data(),
                                                           w.col_perm.data(), fr.stats, arena)
                           : cpu::factor_front_lu_delayed(A, m, p, m, policy, w.row_perm.data(),
                                                          w.col_perm.data(), fr.stats, arena);
  sized(w.scratch, 2 * static_cast<std::size_t>(p), "front permutation");
  for (index_t i = 0; i < p; ++i) {
    w.scratch[i] = R[w.row_perm[i]];
    w.scratch[p + i] = C[w.col_perm[i]];
  }
  std::copy(w.scratch.begin(), w.scratch.begin() + p, R);
  std::copy(w.scratch.begin() + p, w.scratch.begin() + 2 * p, C);
  fr.k = npiv;
  fr.delayed = p - npiv;

  // store the pivot block, then L21 without its zero rows and U12 without its zero columns:
  // the solve reads only these, and a contact problem's Newton matrix leaves many (pairs in
  // the pattern that are not in contact). NaN is not zero: it stays and reaches the solve.
  const index_t k = npiv, c = m - npiv;
  sized(w.nonzero, static_cast<std::size_t>(2 * c), "factor structure");
  char* row_nz = w.nonzero.data();
  char* col_nz = row_nz + c;
  std::fill(row_nz, row_nz + 2 * c, char{0});
  for (index_t j = 0; j < k; ++j) {
    const double* col = A + static_cast<std::size_t>(j) * m + k;
    for (index_t i = 0; i < c; ++i) row_nz[i] |= col[i] != 0.0;
  }
  index_t cl = 0, cu = 0;
  for (index_t j = 0; j < c; ++j) {
    const double* col = A + static_cast<std::size_t>(k + j) * m;
    bool any = false;
    for (index_t i = 0; i < k; ++i) any |= col[i] != 0.0;
    col_nz[j] = any;
    cl += row_nz[j] != 0;
    cu += any;
  }
  sized(w.kept, static_cast<std::size_t>(cl), "factor structure");
  sized(fr.l21_rows, static_cast<std::size_t>(cl), "factor structure");
  sized(fr.u12_cols, static_cast<std::size_t>(cu), "factor structure");
  for (index_t i = 0, a = 0, b = 0; i < c; ++i) {
    if (row_nz[i]) {
      w.kept[a] = i;
      fr.l21_rows[a++] = R[k + i];
    }
    if (col_nz[i]) fr.u12_cols[b++] = C[k + i];
  }
  const std::size_t kk = static_cast<std::size_t>(k) * k;
  sized(fr.lu, kk + static_cast<std::size_t>(cl + cu) * k, "factor values");
  double* P = fr.lu.data();
  double* L21 = P + kk;
  double* U12 = L21 + static_cast<std::size_t>(cl) * k;
  for (index_t j = 0; j < k; ++j) {
    const double* col = A + static_cast<std::size_t>(j) * m;
    std::copy(col, col + k, P + static_cast<std::size_t>(j) * k);
    double* dst = L21 + static_cast<std::size_t>(j) * cl;
    for (index_t a = 0; a < cl; ++a) dst[a] = col[k + w.kept[a]];
  }
  for (index_t j = 0, b = 0; j < c; ++j)
    if (col_nz[j]) {
      const double* col = A + static_cast<std::size_t>(k + j) * m;
      std::copy(col, col + k, U12 + static_cast<std::size_t>(b++) * k);
    }
  const std::size_t s = static_cast<std::size_t>(m - npiv);
  if (t.parent[f] >= 0 && s > 0) {
    sized(fr.cb, s * s, "contribution blocks");
    for (std::size_t c = 0; c < s; ++c)
      std::memcpy(fr.cb.data() + c * s, A + (npiv + c) * m + npiv, sizeof(double) * s);
  }
}

}  // namespace

void factorize_delayed(const Analysis& an, const double* vals, MatrixType type, double threshold,
                       double static_pivot, DelayedFactor& F, DelayedWorkspace& W,
                       tbb::task_arena& arena) {
  if (type != MatrixType::general && type != MatrixType::symmetric_indefinite)
    throw NotSupported(
        "delayed pivoting is implemented for general and symmetric indefinite matrices only");
  if (!(threshold > 0 && threshold <= 1))
    throw InvalidInput("the pivot threshold must be in (0, 1], got " + std::to_string(threshold));
  const auto& t = an.tree;
  const auto& sched = an.schedule;
  F.type = type;
  F.valid = false;
  F.fronts.resize(t.n_fronts());
  const int threads = std::max(1, arena.max_concurrency());
  W.threads.resize(threads + 1);  // TBB slot indices are < threads; one spare
  for (auto& w : W.threads)
    if (static_cast<index_t>(w.row_pos.size()) != an.n) {
      w.row_pos.assign(an.n, -1);
      w.col_pos.assign(an.n, -1);
    }
  cpu::DelayPolicy policy;
  policy.threshold = threshold;
  policy.tiny = static_pivot;
  policy.static_pivot = static_pivot;
  // one BLAS thread throughout: a front that starts alone splits its panel updates over
  // the arena's threads instead (the BLAS's own threads would spin on after each call,
  // taking cores from the arena's threads)
  openblas_set_num_threads(1);
  if (threads == 1) {
    for (index_t q = 0; q < static_cast<index_t>(sched.fronts.size()); ++q)
      factor_front(an, vals, policy, sched.fronts[q], F, W.threads[threads]);
  } else {
    // a front starts once its last child is done (no barrier between levels): the upper
    // levels of a multibody Newton matrix's tree hold a few fronts each, and a barrier
    // would wait for each level's slowest
    const auto nf = static_cast<std::size_t>(t.n_fronts());
    if (W.pending_size < nf) {
      W.pending = std::make_unique<std::atomic<index_t>[]>(nf);
      W.pending_size = nf;
    }
    std::atomic<index_t>* pending = W.pending.get();
    std::vector<index_t>& leaves = W.leaves;
    leaves.clear();
    for (std::size_t f = 0; f < nf; ++f) {
      const index_t c = t.child_offsets[f + 1] - t.child_offsets[f];
      pending[f].store(c, std::memory_order_relaxed);
      if (c == 0) leaves.push_back(static_cast<index_t>(f));
    }
    std::exception_ptr error;
    std::mutex error_mutex;
    // fronts started or ready and not done: a front that starts alone (the top of the
    // tree) splits its panel updates over the threads, the others take one each (the
    // bits are the same either way)
    std::atomic<std::size_t> open{leaves.size()};
    arena.execute([&] {
      tbb::parallel_for_each(
          leaves.begin(), leaves.end(), [&](index_t f, tbb::feeder<index_t>& feeder) {
            const int slot = tbb::this_task_arena::current_thread_index();
            auto& w = W.threads[slot >= 0 && slot < threads ? slot : threads];
            try {
              factor_front(an, vals, policy, f, F, w, open.load() == 1 ? &arena : nullptr);
            } catch (...) {
              std::lock_guard<std::mutex> lock(error_mutex);
              if (!error) error = std::current_exception();
              return;  // its parent never starts
            }
            const index_t p = t.parent[f];
            if (p >= 0 && pending[p].fetch_sub(1) == 1)
              feeder.add(p);  // this front's place goes to its parent
            else
              open.fetch_sub(1);
          });
    });
    if (error) std::rethrow_exception(error);
  }
  F.delayed = F.fronts_delaying = F.largest_front = 0;
  for (const DelayedFront& fr : F.fronts) {
    F.delayed += fr.delayed;
    F.fronts_delaying += fr.delayed > 0;
    F.largest_front = std::max(F.largest_front, fr.m);
  }
  plan_delayed_solve(an, threads, F);
  F.valid = true;
}

namespace {

constexpr index_t kLoops = 2048;  // below this many multiply-adds, plain loops

// The least work given to a solve bin (Σ m·k over its fronts' symbolic sizes, about the
// factor entries it reads): below it another thread costs more than it saves
// (bench/history.md, "The delayed solve's bins by work").
constexpr double kMinBinWork = 65536;

// Forward step of front fr: L11 w = z(R[0..k)) in place, then the update L21 w of the rows
// l21_rows, which `sink(row, value)` subtracts.
template <class Sink>
void forward_front(const DelayedFront& fr, double* z, std::vector<double>& w,
                   std::vector<double>& g, Sink&& sink) {
  const index_t k = fr.k, cl = static_cast<index_t>(fr.l21_rows.size());
  if (k == 0) return;
  const index_t* R = fr.rows.data();
  const double* P = fr.lu.data();
  const double* L21 = P + static_cast<std::size_t>(k) * k;
  const int one = 1;
  const double m1 = -1.0, zero = 0.0;
  w.resize(k);
  for (index_t i = 0; i < k; ++i) w[i] = z[R[i]];
  const int ik = static_cast<int>(k), icl = static_cast<int>(cl);
  if (k * k <= kLoops)
    cpu::unit_lower_solve(k, P, k, w.data());
  else
    dtrsv_("L", "N", "U", &ik, P, &ik, w.data(), &one);
  for (index_t i = 0; i < k; ++i) z[R[i]] = w[i];
  if (cl == 0) return;
  if (cl * k <= kLoops) {
    g.assign(cl, 0.0);  // −L21 w
    cpu::gemv_subtract(cl, k, L21, cl, w.data(), g.data());
  } else {
    g.resize(cl);
    dgemv_("N", &icl, &ik, &m1, L21, &icl, w.data(), &one, &zero, g.data(), &one);
  }
  const index_t* rows = fr.l21_rows.data();
  for (index_t i = 0; i < cl; ++i) sink(rows[i], -g[i]);
}

// Backward step of front fr: U11 x(C[0..k)) = z(R[0..k)) − U12 x(the columns after k).
void backward_front(const DelayedFront& fr, const double* z, double* x, std::vector<double>& w,
                    std::vector<double>& g) {
  const index_t k = fr.k, cu = static_cast<index_t>(fr.u12_cols.size());
  if (k == 0) return;
  const index_t* R = fr.rows.data();
  const index_t* C = fr.cols.data();
  const double* P = fr.lu.data();
  const double* U12 = P + static_cast<std::size_t>(k) * k + fr.l21_rows.size() * k;
  const int one = 1;
  const double p1 = 1.0, m1 = -1.0;
  const int ik = static_cast<int>(k), icu = static_cast<int>(cu);
  w.resize(k);
  for (index_t i = 0; i < k; ++i) w[i] = z[R[i]];
  if (cu > 0) {
    g.resize(cu);
    const index_t* cols = fr.u12_cols.data();
    for (index_t j = 0; j < cu; ++j) g[j] = x[cols[j]];
    if (cu * k <= kLoops)
      cpu::gemv_subtract(k, cu, U12, k, g.data(), w.data());
    else
      dgemv_("N", &ik, &icu, &m1, U12, &ik, g.data(), &one, &p1, w.data(), &one);
  }
  // DTRSV would divide by a zero pivot (a root without static pivots); upper_solve gives 0
  bool zero_pivot = false;
  if (k * k > kLoops)
    for (index_t j = 0; j < k && !zero_pivot; ++j)
      zero_pivot = P[static_cast<std::size_t>(j) * k + j] == 0.0;
  if (k * k <= kLoops || zero_pivot)
    cpu::upper_solve(k, P, k, w.data());
  else
    dtrsv_("U", "N", "N", &ik, P, &ik, w.data(), &one);
  for (index_t i = 0; i < k; ++i) x[C[i]] = w[i];
}

}  // namespace

void plan_delayed_solve(const Analysis& an, int threads, DelayedFactor& F) {
  DelayedSolvePlan& P = F.solve_plan;
  const auto& t = an.tree;
  const index_t nf = t.n_fronts();
  if (P.analysis_id != an.id || P.threads != threads) {
    P = DelayedSolvePlan{};
    P.analysis_id = an.id;
    P.threads = threads;
    // subtree work (the solve reads each front's m·k factor entries twice) and ranges
    std::vector<double> work(nf, 0.0);
    std::vector<index_t> first(nf);
    double total = 0;
    for (index_t f = 0; f < nf; ++f) {  // postorder: children first
      first[f] = f;
      work[f] += static_cast<double>(t.n_rows(f)) * t.n_pivots(f);
      for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
        const index_t ch = t.children[q];
        work[f] += work[ch];
        first[f] = std::min(first[f], first[ch]);
      }
      if (t.parent[f] < 0) total += work[f];
    }
    // as many bins as threads, but none with less than kMinBinWork: on a small factor
    // the threads' start-up and the top rows' per-bin sums cost more than they save
    const int bins = static_cast<int>(
        std::clamp(total / kMinBinWork, 1.0, static_cast<double>(std::max(threads, 1))));
    // largest first to the least loaded bin (ties: the lower front number first)
    auto by_work = [&](index_t a, index_t b) {
      return work[a] != work[b] ? work[a] > work[b] : a < b;
    };
    std::vector<double> load(bins);
    auto makespan = [&](std::vector<index_t> c) {
      std::sort(c.begin(), c.end(), by_work);
      std::fill(load.begin(), load.end(), 0.0);
      for (index_t f : c) *std::min_element(load.begin(), load.end()) += work[f];
      return *std::max_element(load.begin(), load.end());
    };
    // split the heaviest subtree into its children (its root joins the top part, which one
    // thread solves) up to 16 subtrees per bin, and keep the split with the least estimated
    // time: the top's work plus the most loaded bin's. The upper fronts of a multibody
    // Newton matrix are large: splitting every subtree small would move much of the
    // factor into the top (bench/history.md, "The engine on sixteen threads").
    std::vector<index_t> cand, top;
    for (index_t f = 0; f < nf; ++f)
      if (t.parent[f] < 0) cand.push_back(f);
    double top_work = 0, best = makespan(cand);
    std::vector<index_t> best_cand = cand, best_top;
    while (bins > 1 && !cand.empty() && cand.size() < static_cast<std::size_t>(16 * bins)) {
      const auto heaviest = std::max_element(
          cand.begin(), cand.end(), [&](index_t a, index_t b) { return work[a] < work[b]; });
      const index_t f = *heaviest;
      if (t.child_offsets[f] == t.child_offsets[f + 1]) break;
      cand.erase(heaviest);
      top.push_back(f);
      top_work += static_cast<double>(t.n_rows(f)) * t.n_pivots(f);
      for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q)
        cand.push_back(t.children[q]);
      if (const double estimate = top_work + makespan(cand); estimate < best) {
        best = estimate;
        best_cand = cand;
        best_top = top;
      }
    }
    cand = std::move(best_cand);
    top = std::move(best_top);
    if (bins > 1 && cand.size() > 1) {
      std::sort(cand.begin(), cand.end(), by_work);
      P.bins.resize(bins);
      std::fill(load.begin(), load.end(), 0.0);
      for (index_t f : cand) {
        const int bin = static_cast<int>(std::min_element(load.begin(), load.end()) - load.begin());
        load[bin] += work[f];
        P.bins[bin].push_back({first[f], f});
      }
      std::sort(top.begin(), top.end());
      P.top = std::move(top);
    }
  }
  if (P.bins.empty()) return;
  P.row_bin.assign(an.n, -1);
  for (std::size_t b = 0; b < P.bins.size(); ++b)
    for (const auto& [lo, hi] : P.bins[b])
      for (index_t f = lo; f <= hi; ++f) {
        const DelayedFront& fr = F.fronts[f];
        for (index_t i = 0; i < fr.k; ++i) P.row_bin[fr.rows[i]] = static_cast<index_t>(b);
      }
  P.top_rows.clear();
  for (index_t f : P.top)
    for (index_t i = 0; i < F.fronts[f].k; ++i) {
      const index_t row = F.fronts[f].rows[i];
      P.row_bin[row] = -1 - static_cast<index_t>(P.top_rows.size());
      P.top_rows.push_back(row);
    }
}

void solve_delayed(const Analysis& an, const DelayedFactor& F, double* b, index_t nrhs,
                   tbb::task_arena* arena) {
  // Per front: gather, dense triangular solve and products on the gathered vectors
  // (contiguous), scatter once; DGEMV/DTRSV for the larger ones.
  const index_t n = an.n, nf = static_cast<index_t>(F.fronts.size());
  const DelayedSolvePlan& P = F.solve_plan;
  const bool parallel = arena && !P.bins.empty() && P.analysis_id == an.id;
  std::vector<double> x(static_cast<std::size_t>(n) * nrhs, 0.0), w, g;
  openblas_set_num_threads(1);  // products of a few thousand flops: one thread
  const int nb = static_cast<int>(P.bins.size());
  // per bin: its updates of the top part's rows (row_bin −1 − t: top_rows[t])
  std::vector<std::vector<double>> delta(parallel ? nb : 0);
  for (auto& d : delta) d.assign(P.top_rows.size(), 0.0);
  for (index_t r = 0; r < nrhs; ++r) {
    double* z = b + static_cast<std::size_t>(r) * n;
    double* xr = x.data() + static_cast<std::size_t>(r) * n;
    if (!parallel) {
      // forward: L y = z over the row pivot sequence; backward: U x = y over the columns
      for (index_t f = 0; f < nf; ++f)
        forward_front(F.fronts[f], z, w, g, [&](index_t row, double v) { z[row] -= v; });
      for (index_t f = nf - 1; f >= 0; --f) backward_front(F.fronts[f], z, xr, w, g);
      continue;
    }
    arena->execute([&] {
      tbb::parallel_for(0, nb, [&](int bin) {
        std::vector<double> wb, gb;
        double* d = delta[bin].data();
        for (const auto& [lo, hi] : P.bins[bin])
          for (index_t f = lo; f <= hi; ++f)
            forward_front(F.fronts[f], z, wb, gb, [&](index_t row, double v) {
              const index_t rb = P.row_bin[row];
              (rb == bin ? z[row] : d[-1 - rb]) -= v;
            });
      });
    });
    for (std::size_t t = 0; t < P.top_rows.size(); ++t)
      for (int bin = 0; bin < nb; ++bin) {
        z[P.top_rows[t]] += delta[bin][t];
        delta[bin][t] = 0.0;
      }
    for (index_t f : P.top)
      forward_front(F.fronts[f], z, w, g, [&](index_t row, double v) { z[row] -= v; });
    for (auto it = P.top.rbegin(); it != P.top.rend(); ++it)
      backward_front(F.fronts[*it], z, xr, w, g);
    arena->execute([&] {
      tbb::parallel_for(0, nb, [&](int bin) {
        std::vector<double> wb, gb;
        const auto& ranges = P.bins[bin];
        for (auto it = ranges.rbegin(); it != ranges.rend(); ++it)
          for (index_t f = it->second; f >= it->first; --f)
            backward_front(F.fronts[f], z, xr, wb, gb);
      });
    });
  }
  std::copy(x.begin(), x.end(), b);
}

void delayed_pivot_sequence(const Analysis& an, const DelayedFactor& F, std::vector<index_t>& rows,
                            std::vector<index_t>& cols) {
  rows.clear();
  cols.clear();
  rows.reserve(an.n);
  cols.reserve(an.n);
  for (const auto& fr : F.fronts)
    for (index_t i = 0; i < fr.k; ++i) {
      rows.push_back(fr.rows[i]);
      cols.push_back(fr.cols[i]);
    }
}

int delayed_determinant_sign(const Analysis& an, const DelayedFactor& F) {
  int sign = 1;
  for (const auto& fr : F.fronts) sign *= fr.stats.det_sign;
  if (sign == 0) return 0;
  std::vector<index_t> rseq, cseq;
  delayed_pivot_sequence(an, F, rseq, cseq);
  std::vector<char> seen;
  return sign * parity(rseq, seen) * parity(cseq, seen);
}

}  // namespace strata::numeric
