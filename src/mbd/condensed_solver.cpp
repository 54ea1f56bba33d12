// strata::mbd — the Newton matrix condensed by its rows of two entries (see
// condensed_solver.hpp for the algebra).
#include "mbd/condensed_solver.hpp"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>

#include "base/timer.hpp"
#include "strata/errors.hpp"

namespace strata::mbd {

namespace {

std::string where(const RowElimination& e) {
  return "row " + std::to_string(e.row) + ", column " + std::to_string(e.column) + ", partner " +
         std::to_string(e.partner);
}

// body(i0, i1) over [0, n) in ranges on the calling arena's threads when n is large
// enough to pay for them (each range writes only its own entries: the same result for
// any number of threads).
constexpr index_t kGrain = 16384;  // for_ranges' least range

template <class Body>
void for_ranges(index_t n, const Body& body, index_t grain = kGrain) {
  if (n <= 2 * grain) {
    if (n > 0) body(index_t{0}, n);
    return;
  }
  tbb::parallel_for(tbb::blocked_range<index_t>(0, n, grain),
                    [&](const tbb::blocked_range<index_t>& r) { body(r.begin(), r.end()); });
}

// The position of entry (row, column) of a CSC matrix with sorted rows, or −1.
index_t find_entry(const SparseMatrix& a, index_t row, index_t column) {
  const index_t* b = a.indices.data() + a.offsets[column];
  const index_t* e = a.indices.data() + a.offsets[column + 1];
  const index_t* f = std::lower_bound(b, e, row);
  return f != e && *f == row ? static_cast<index_t>(f - a.indices.data()) : -1;
}

}  // namespace

void CondensedSystem::build(const SparseMatrix& a, const std::vector<RowElimination>& eliminations,
                            SparseMatrix& reduced) {
  const index_t n = a.n_cols;
  if (a.n_rows != n || a.layout != Layout::csc || a.storage != Storage::full ||
      static_cast<index_t>(a.offsets.size()) != n + 1)
    throw InvalidInput("condensed system: the matrix must be square CSC with both triangles, got " +
                       std::to_string(a.n_rows) + "x" + std::to_string(a.n_cols));
  const index_t ne = static_cast<index_t>(eliminations.size());
  std::vector<index_t> elim_of_row(n, -1), elim_of_col(n, -1);
  for (index_t e = 0; e < ne; ++e) {
    const RowElimination& el = eliminations[e];
    if (el.row < 0 || el.row >= n || el.column < 0 || el.column >= n || el.partner < 0 ||
        el.partner >= n || el.partner == el.column)
      throw InvalidInput("condensed system: elimination " + std::to_string(e) + " (" + where(el) +
                         ") is out of range for order " + std::to_string(n));
    if (elim_of_row[el.row] >= 0 || elim_of_col[el.column] >= 0)
      throw InvalidInput("condensed system: elimination " + std::to_string(e) + " (" + where(el) +
                         ") names a row or column that another elimination names");
    elim_of_row[el.row] = e;
    elim_of_col[el.column] = e;
  }
  // dependency order: an elimination after that of its partner (depth: the number of
  // eliminated columns between it and the column that stays)
  std::vector<index_t> depth(ne, -1);
  for (index_t e = 0; e < ne; ++e) {
    index_t d = 0;
    for (index_t c = eliminations[e].partner; elim_of_col[c] >= 0;
         c = eliminations[elim_of_col[c]].partner)
      if (++d > ne)
        throw InvalidInput("condensed system: the partners of elimination " + std::to_string(e) +
                           " (" + where(eliminations[e]) + ") form a cycle");
    depth[e] = d;
  }
  std::vector<index_t> order(ne);
  for (index_t e = 0; e < ne; ++e) order[e] = e;
  std::stable_sort(order.begin(), order.end(),
                   [&](index_t x, index_t y) { return depth[x] < depth[y]; });
  n_ = n;
  given_ = eliminations;
  elim_.resize(ne);
  for (index_t k = 0; k < ne; ++k) elim_[k] = eliminations[order[k]];
  elim_of_col_.assign(n, -1);
  std::vector<index_t> elim_of_row_sorted(n, -1);
  for (index_t k = 0; k < ne; ++k) {
    elim_of_col_[elim_[k].column] = k;
    elim_of_row_sorted[elim_[k].row] = k;
  }
  pivot_pos_.resize(ne);
  partner_pos_.resize(ne);
  partner_elim_.resize(ne);
  for (index_t k = 0; k < ne; ++k) {
    const RowElimination& el = elim_[k];
    pivot_pos_[k] = find_entry(a, el.row, el.column);
    partner_pos_[k] = find_entry(a, el.row, el.partner);
    if (pivot_pos_[k] < 0 || partner_pos_[k] < 0)
      throw InvalidInput("condensed system: elimination " + where(el) +
                         ": the pivot or the partner is not an entry of the matrix");
    partner_elim_[k] = elim_of_col_[el.partner];
  }
  // R's rows and columns: those no elimination names, in their order
  new_row_.assign(n, -1);
  std::vector<index_t> new_col(n, -1);
  index_t nr = 0, nc = 0;
  for (index_t i = 0; i < n; ++i)
    if (elim_of_row_sorted[i] < 0) new_row_[i] = nr++;
  for (index_t j = 0; j < n; ++j)
    if (elim_of_col_[j] < 0) new_col[j] = nc++;
  final_col_.resize(ne);
  for (index_t k = 0; k < ne; ++k) {  // dependency order: a partner's K is known
    const index_t d = elim_[k].partner;
    final_col_[k] = partner_elim_[k] < 0 ? new_col[d] : final_col_[partner_elim_[k]];
  }
  kept_col_.clear();
  kept_col_.reserve(nc);
  for (index_t j = 0; j < n; ++j)
    if (new_col[j] >= 0) kept_col_.push_back(j);
  // the other entries of the pivot rows (explicit zeros), and the entries of eliminated
  // columns in rows that stay (for the right-hand side)
  zero_pos_.clear();
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      if (const index_t k = elim_of_row_sorted[i]; k >= 0) {
        if (j != elim_[k].column && j != elim_[k].partner) zero_pos_.push_back(p);
      }
    }
  // by row of R (each row's sum in a fixed order, the rows independent of each other):
  // counted, then filled column by column
  kept_row_.assign(nr, 0);
  for (index_t i = 0; i < n; ++i)
    if (new_row_[i] >= 0) kept_row_[new_row_[i]] = i;
  rhs_ptr_.assign(nr + 1, 0);
  for (index_t k = 0; k < ne; ++k) {
    const index_t c = elim_[k].column;
    for (index_t p = a.offsets[c]; p < a.offsets[c + 1]; ++p)
      if (const index_t ri = new_row_[a.indices[p]]; ri >= 0) ++rhs_ptr_[ri + 1];
  }
  for (index_t r = 0; r < nr; ++r) rhs_ptr_[r + 1] += rhs_ptr_[r];
  rhs_pos_.resize(rhs_ptr_[nr]);
  rhs_elim_.resize(rhs_ptr_[nr]);
  // and the same entries by elimination (col_ptr_: their positions and rows; their values
  // kept in that order too), for a right-hand side with few S_c ≠ 0
  col_ptr_.assign(ne + 1, 0);
  col_pos_.resize(rhs_ptr_[nr]);
  col_row_.resize(rhs_ptr_[nr]);
  {
    std::vector<index_t> at(rhs_ptr_.begin(), rhs_ptr_.end() - 1);
    index_t u = 0;
    for (index_t k = 0; k < ne; ++k) {
      const index_t c = elim_[k].column;
      for (index_t p = a.offsets[c]; p < a.offsets[c + 1]; ++p)
        if (const index_t ri = new_row_[a.indices[p]]; ri >= 0) {
          col_pos_[u] = p;
          col_row_[u++] = ri;
          rhs_pos_[at[ri]] = p;
          rhs_elim_[at[ri]++] = k;
        }
      col_ptr_[k + 1] = u;
    }
  }
  rhs_val_.assign(rhs_pos_.size(), 0.0);
  col_val_.assign(col_pos_.size(), 0.0);
  // R's columns: column K's entries are the union of the rows that stay of K and of every
  // column eliminated into K, each entry summing its contributions
  std::vector<index_t> source_ptr(nc + 1, 0), sources(n);
  for (index_t j = 0; j < n; ++j) {
    const index_t K = new_col[j] >= 0 ? new_col[j] : final_col_[elim_of_col_[j]];
    ++source_ptr[K + 1];
  }
  for (index_t K = 0; K < nc; ++K) source_ptr[K + 1] += source_ptr[K];
  {
    std::vector<index_t> at(source_ptr.begin(), source_ptr.end() - 1);
    for (index_t j = 0; j < n; ++j) {
      const index_t K = new_col[j] >= 0 ? new_col[j] : final_col_[elim_of_col_[j]];
      sources[at[K]++] = j;
    }
  }
  reduced = SparseMatrix{};
  reduced.n_rows = reduced.n_cols = nc;
  reduced.layout = a.layout;
  reduced.storage = a.storage;
  reduced.offsets.assign(nc + 1, 0);
  reduced.indices.clear();
  contrib_ptr_.assign(1, 0);
  contrib_pos_.clear();
  contrib_elim_.clear();
  std::vector<index_t> mark(nr, -1), slot(nr, 0), rows, count;
  for (index_t K = 0; K < nc; ++K) {
    rows.clear();
    for (index_t s = source_ptr[K]; s < source_ptr[K + 1]; ++s) {
      const index_t c = sources[s];
      for (index_t p = a.offsets[c]; p < a.offsets[c + 1]; ++p) {
        const index_t ri = new_row_[a.indices[p]];
        if (ri < 0 || mark[ri] == K) continue;
        mark[ri] = K;
        rows.push_back(ri);
      }
    }
    // one source: its rows that stay, in their order already (new_row_ is increasing)
    if (source_ptr[K + 1] - source_ptr[K] > 1) std::sort(rows.begin(), rows.end());
    const index_t first = static_cast<index_t>(reduced.indices.size());
    count.assign(rows.size() + 1, 0);
    for (std::size_t t = 0; t < rows.size(); ++t) slot[rows[t]] = static_cast<index_t>(t);
    for (index_t s = source_ptr[K]; s < source_ptr[K + 1]; ++s) {
      const index_t c = sources[s];
      for (index_t p = a.offsets[c]; p < a.offsets[c + 1]; ++p)
        if (const index_t ri = new_row_[a.indices[p]]; ri >= 0) ++count[slot[ri] + 1];
    }
    for (std::size_t t = 0; t < rows.size(); ++t) count[t + 1] += count[t];
    const index_t base = static_cast<index_t>(contrib_pos_.size());
    contrib_pos_.resize(base + count[rows.size()]);
    contrib_elim_.resize(base + count[rows.size()]);
    for (index_t s = source_ptr[K]; s < source_ptr[K + 1]; ++s) {
      const index_t c = sources[s];
      const index_t e = elim_of_col_[c];
      for (index_t p = a.offsets[c]; p < a.offsets[c + 1]; ++p)
        if (const index_t ri = new_row_[a.indices[p]]; ri >= 0) {
          const index_t t = base + count[slot[ri]]++;
          contrib_pos_[t] = p;
          contrib_elim_[t] = e;
        }
    }
    // count[t] is now the end of entry t's contributions
    for (std::size_t t = 0; t < rows.size(); ++t) contrib_ptr_.push_back(base + count[t]);
    reduced.indices.insert(reduced.indices.end(), rows.begin(), rows.end());
    reduced.offsets[K + 1] = first + static_cast<index_t>(rows.size());
  }
  reduced.values.assign(reduced.indices.size(), 0.0);
  pivot_.assign(ne, 0.0);
  m_.assign(ne, 0.0);
  w_.assign(ne, 0.0);
  s_.assign(ne, 0.0);
  have_values_ = false;
}

void CondensedSystem::values(const std::vector<double>& full, std::vector<double>& reduced) {
  const index_t ne = static_cast<index_t>(elim_.size());
  for (index_t k = 0; k < ne; ++k) {  // dependency order: the partner's w first
    const double pivot = full[pivot_pos_[k]];
    if (!(pivot != 0.0) || !std::isfinite(pivot))
      throw InvalidInput("condensed system: the pivot of row " + std::to_string(elim_[k].row) +
                         " (column " + std::to_string(elim_[k].column) + ") is " +
                         std::to_string(pivot));
    pivot_[k] = pivot;
    m_[k] = -full[partner_pos_[k]] / pivot;
    w_[k] = m_[k] * (partner_elim_[k] < 0 ? 1.0 : w_[partner_elim_[k]]);
  }
  for_ranges(static_cast<index_t>(rhs_pos_.size()), [&](index_t t0, index_t t1) {
    for (index_t t = t0; t < t1; ++t) {
      rhs_val_[t] = full[rhs_pos_[t]];
      col_val_[t] = full[col_pos_[t]];
    }
  });
  for (const index_t p : zero_pos_)
    if (full[p] != 0.0)
      throw InternalError("condensed system: entry " + std::to_string(p) +
                          " of a pivot row is not zero");
  const index_t nq = static_cast<index_t>(contrib_ptr_.size()) - 1;
  reduced.resize(nq);
  for_ranges(nq, [&](index_t q0, index_t q1) {
    for (index_t q = q0; q < q1; ++q) {
      double v = 0.0;
      for (index_t t = contrib_ptr_[q]; t < contrib_ptr_[q + 1]; ++t) {
        const index_t e = contrib_elim_[t];
        v += e < 0 ? full[contrib_pos_[t]] : full[contrib_pos_[t]] * w_[e];
      }
      reduced[q] = v;
    }
  });
  have_values_ = true;
}

void CondensedSystem::reduce_rhs(const double* b, double* reduced_b) {
  if (!have_values_) throw InvalidState("condensed system: reduce_rhs before values()");
  const index_t ne = static_cast<index_t>(elim_.size());
  index_t nonzero = 0;  // S_c ≠ 0: where b is not 0 on the relations' rows
  for (index_t k = 0; k < ne; ++k) {
    s_[k] =
        b[elim_[k].row] / pivot_[k] + m_[k] * (partner_elim_[k] < 0 ? 0.0 : s_[partner_elim_[k]]);
    nonzero += s_[k] != 0.0;
  }
  // b_k − Σ_c J(k, c) S_c, each row's terms subtracted in the order of the eliminations
  // either way: by row over every term, the rows in ranges of about kGrain terms over the
  // threads (many S_c ≠ 0: a step's first iteration, whose predictor does not satisfy the
  // relations), or by elimination over those with S_c ≠ 0 only (Newton's updates satisfy
  // them, their rows then read 0: newton_system.cpp); the same result, the terms left out
  // being zero
  const index_t nr = static_cast<index_t>(kept_row_.size());
  const bool by_row = 8 * nonzero >= ne;
  const index_t terms = rhs_ptr_.empty() ? 0 : rhs_ptr_[nr];
  const index_t grain =
      by_row ? std::max<index_t>(64, static_cast<index_t>(static_cast<double>(nr) * kGrain /
                                                          std::max<index_t>(terms, 1)))
             : kGrain;
  for_ranges(
      nr,
      [&](index_t r0, index_t r1) {
        for (index_t r = r0; r < r1; ++r) {
          double v = b[kept_row_[r]];
          if (by_row)
            for (index_t t = rhs_ptr_[r]; t < rhs_ptr_[r + 1]; ++t)
              v -= rhs_val_[t] * s_[rhs_elim_[t]];
          reduced_b[r] = v;
        }
      },
      grain);
  if (by_row || nonzero == 0) return;
  for (index_t k = 0; k < ne; ++k) {
    const double sk = s_[k];
    if (sk == 0.0) continue;
    for (index_t u = col_ptr_[k]; u < col_ptr_[k + 1]; ++u)
      reduced_b[col_row_[u]] -= col_val_[u] * sk;
  }
}

void CondensedSystem::expand(const double* reduced_x, double* x) const {
  for_ranges(static_cast<index_t>(kept_col_.size()), [&](index_t k0, index_t k1) {
    for (index_t K = k0; K < k1; ++K) x[kept_col_[K]] = reduced_x[K];
  });
  for_ranges(static_cast<index_t>(elim_.size()), [&](index_t k0, index_t k1) {
    for (index_t k = k0; k < k1; ++k) x[elim_[k].column] = s_[k] + w_[k] * reduced_x[final_col_[k]];
  });
}

namespace {

// FNV-1a over a pattern's arrays: whether factorize() got the pattern already mapped.
std::uint64_t pattern_hash(const SparseMatrix& a) {
  std::uint64_t h = 1469598103934665603ull;
  auto mix = [&](index_t v) {
    h ^= static_cast<std::uint64_t>(v);
    h *= 1099511628211ull;
  };
  mix(a.n_rows);
  mix(a.n_cols);
  for (const index_t v : a.offsets) mix(v);
  for (const index_t v : a.indices) mix(v);
  return h;
}

class CondensedSolver : public LinearSolver {
 public:
  CondensedSolver(std::unique_ptr<LinearSolver> inner,
                  std::function<std::vector<RowElimination>()> eliminations,
                  std::function<tbb::task_arena*()> arena)
      : inner_(std::move(inner)), eliminations_(std::move(eliminations)), arena_(std::move(arena)) {
    if (!inner_ || !eliminations_)
      throw InvalidInput("make_condensed_solver: a solver and a list of eliminations are needed");
  }

  void analyze(const SparseMatrix& a) override {
    map(a, eliminations_(), true);
    inner_analysis([&] { inner_->analyze(system_of(a)); });
  }
  void analyze_from(const SparseMatrix& a, const MatchingStart& start) override {
    map(a, eliminations_(), true);
    inner_analysis([&] { inner_->analyze_from(system_of(a), start); });
  }
  MatchingStart matching_start() const override { return inner_->matching_start(); }
  index_t system_order(const SparseMatrix& a) const override {
    return inner_->system_order(a) - static_cast<index_t>(eliminations_().size());
  }
  // The analyses that keep the matching read the pattern alone: a grown pattern's new
  // entries may not hold values yet, so R's values are left for the factorization.
  void analyze_keeping_order(const SparseMatrix& a) override {
    map(a, eliminations_(), false);
    inner_analysis([&] { inner_->analyze_keeping_order(system_of(a)); });
  }
  index_t factor_entries_keeping_order(const SparseMatrix& a) const override {
    const std::vector<RowElimination> el = eliminations_();
    if (el.empty()) return inner_->factor_entries_keeping_order(a);
    CondensedSystem cs;
    SparseMatrix r;
    cs.build(a, el, r);
    return inner_->factor_entries_keeping_order(r);
  }
  void analyze_keeping_matching(const SparseMatrix& a) override {
    map(a, eliminations_(), false);
    inner_analysis([&] { inner_->analyze_keeping_matching(system_of(a)); });
  }
  void factorize(const SparseMatrix& a) override {
    seconds_ = 0;
    std::vector<RowElimination> el = eliminations_();
    if (el.empty()) {
      map(a, el, false);
      return inner_->factorize(a);
    }
    if (!mapped_ || identity_ || el != system_.eliminations() || pattern_hash(a) != hash_)
      map(a, std::move(el), true);
    else
      in_arena([&] { system_.values(a.values, reduced_.values); });
    inner_->factorize(reduced_);
  }
  void factorize_analyzed_pattern(const SparseMatrix& a) override {
    seconds_ = 0;
    if (!mapped_) return factorize(a);  // an analysis failed since: map the pattern again
    if (identity_) return inner_->factorize_analyzed_pattern(a);
    if (a.nnz() != mapped_nnz_ || a.n_rows != system_.full_order())
      throw InternalError("condensed solver: the values of another pattern than the analyzed one");
    in_arena([&] { system_.values(a.values, reduced_.values); });  // the values alone
    inner_->factorize_analyzed_pattern(reduced_);
  }
  void solve(const double* b, double* x) override {
    seconds_ = 0;
    if (identity_) return inner_->solve(b, x);
    const index_t r = system_.reduced_order();
    rb_.resize(r);
    rx_.resize(r);
    in_arena([&] { system_.reduce_rhs(b, rb_.data()); });
    inner_->solve(rb_.data(), rx_.data());
    in_arena([&] { system_.expand(rx_.data(), x); });
  }
  index_t factor_entries() const override { return inner_->factor_entries(); }
  index_t perturbed_pivots() const override { return inner_->perturbed_pivots(); }
  double backward_error() const override { return inner_->backward_error(); }
  std::string describe() const override {
    if (identity_) return inner_->describe();
    // first: what follows ends with the device ("… on cuda"), as the summary's readers expect
    return "BDF rows condensed (" + std::to_string(system_.reduced_order()) + " of " +
           std::to_string(system_.full_order()) + " rows), " + inner_->describe();
  }
  const Stats* stats() const override { return inner_->stats(); }
  double condensation_seconds() const override { return seconds_; }
  bool delaying() const override { return inner_->delaying(); }
  void set_delaying(bool on) override { inner_->set_delaying(on); }

 private:
  // An analysis of R by the inner solver; when it throws, R's map no longer matches what
  // the inner solver analyzed, so the next factorization maps the pattern again.
  template <class F>
  void inner_analysis(F&& f) {
    try {
      f();
    } catch (...) {
      mapped_ = false;
      throw;
    }
  }
  // f() on the caller's arena (its threads, as --threads says), on one thread when the
  // caller has none (its work runs on the calling thread alone), else where it is called
  // (its seconds added to seconds_)
  template <class F>
  void in_arena(F&& f) {
    Timer t;
    if (!arena_)
      f();
    else if (tbb::task_arena* a = arena_())
      a->execute(f);
    else
      one_thread_.execute(f);
    seconds_ += t.seconds();
  }
  // What the inner solver is given for a: R, or a itself when nothing is eliminated.
  const SparseMatrix& system_of(const SparseMatrix& a) const { return identity_ ? a : reduced_; }
  // R's pattern for a's (and its values with `values`); none without eliminations
  void map(const SparseMatrix& a, const std::vector<RowElimination>& el, bool values) {
    mapped_ = false;
    identity_ = el.empty();
    if (identity_) {
      reduced_ = SparseMatrix{};
      mapped_ = true;
      return;
    }
    Timer t;
    system_.build(a, el, reduced_);
    seconds_ += t.seconds();
    if (values) in_arena([&] { system_.values(a.values, reduced_.values); });
    hash_ = pattern_hash(a);
    mapped_nnz_ = a.nnz();
    mapped_ = true;
  }

  std::unique_ptr<LinearSolver> inner_;
  std::function<std::vector<RowElimination>()> eliminations_;
  std::function<tbb::task_arena*()> arena_;
  tbb::task_arena one_thread_{1};
  CondensedSystem system_;
  SparseMatrix reduced_;
  std::uint64_t hash_ = 0;
  index_t mapped_nnz_ = 0;
  bool mapped_ = false;
  bool identity_ = false;  // no elimination: the inner solver gets the matrix as it is
  std::vector<double> rb_, rx_;
  double seconds_ = 0;  // condensation_seconds()
};

}  // namespace

bool worth_condensing(index_t order, std::size_t eliminations) {
  return 3 * static_cast<double>(eliminations) >= static_cast<double>(order);
}

std::unique_ptr<LinearSolver> make_condensed_solver(
    std::unique_ptr<LinearSolver> inner, std::function<std::vector<RowElimination>()> eliminations,
    std::function<tbb::task_arena*()> arena) {
  return std::make_unique<CondensedSolver>(std::move(inner), std::move(eliminations),
                                           std::move(arena));
}

}  // namespace strata::mbd
