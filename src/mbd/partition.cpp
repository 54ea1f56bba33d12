// strata::mbd — sparse coordinate partitioning (see partition.hpp).
#include "mbd/partition.hpp"

#include <algorithm>
#include <cmath>
#include <queue>
#include <set>
#include <string>

namespace strata::mbd {
namespace {

struct PivotRow {
  index_t col;
  double value;
  std::vector<std::pair<index_t, double>> entries;  // excluding the pivot
};

// Dense accumulator with a touched list: w[c] for the columns of one row.
struct Work {
  std::vector<double> w;
  std::vector<char> mark;
  std::vector<index_t> touched;
  explicit Work(index_t n) : w(n, 0.0), mark(n, 0) {}
  void add(index_t c, double v) {
    if (!mark[c]) {
      mark[c] = 1;
      touched.push_back(c);
      w[c] = 0.0;
    }
    w[c] += v;
  }
  void clear() {
    for (index_t c : touched) {
      mark[c] = 0;
      w[c] = 0.0;
    }
    touched.clear();
  }
};

// Loads row r into the work vector and eliminates the earlier pivots from it, in pivot
// order. Records which pivots were used. Returns the max |entry| of the original row.
double reduce_row(const SparseRows& jac, index_t r, const std::vector<PivotRow>& pivots,
                  const std::vector<index_t>& pivot_of_col, Work& work,
                  std::vector<index_t>& used) {
  double orig = 0;
  std::priority_queue<index_t, std::vector<index_t>, std::greater<>> heap;
  std::set<index_t> in_heap;
  auto note = [&](index_t c) {
    const index_t k = pivot_of_col[c];
    if (k >= 0 && in_heap.insert(k).second) heap.push(k);
  };
  for (index_t p = jac.ptr[r]; p < jac.ptr[r + 1]; ++p) {
    work.add(jac.cols[p], jac.vals[p]);
    orig = std::max(orig, std::abs(jac.vals[p]));
    note(jac.cols[p]);
  }
  used.clear();
  while (!heap.empty()) {
    const index_t k = heap.top();
    heap.pop();
    const PivotRow& pr = pivots[k];
    const double x = work.w[pr.col];
    work.w[pr.col] = 0.0;
    if (x == 0.0) continue;
    const double mult = x / pr.value;
    used.push_back(k);
    for (const auto& [c, v] : pr.entries) {
      work.add(c, -mult * v);
      note(c);
    }
  }
  return orig;
}

}  // namespace

Partition partition_coordinates(const SparseRows& jac, double threshold, double redundancy_tol,
                                const std::function<std::string(index_t)>& row_name) {
  const index_t m = jac.n_rows(), n = jac.n_cols;
  std::vector<index_t> remaining(n, 0);  // rows not yet processed containing each column
  for (index_t c : jac.cols) ++remaining[c];
  std::vector<PivotRow> pivots;
  pivots.reserve(m);
  std::vector<index_t> pivot_of_col(n, -1), pivot_row(m, -1);
  std::vector<std::vector<index_t>> uses(m);  // pivots (by row) that each row combined
  Work work(n);
  Partition part;
  part.dependent.assign(m, -1);
  std::vector<index_t> used;
  for (index_t r = 0; r < m; ++r) {
    for (index_t p = jac.ptr[r]; p < jac.ptr[r + 1]; ++p) --remaining[jac.cols[p]];
    const double orig = reduce_row(jac, r, pivots, pivot_of_col, work, used);
    for (index_t k : used) uses[r].push_back(k);
    double big = 0;
    for (index_t c : work.touched)
      if (pivot_of_col[c] < 0) big = std::max(big, std::abs(work.w[c]));
    if (!(big > redundancy_tol * std::max(orig, 1e-300))) {
      // Name the rows that combine to this one: r and, transitively, the pivot rows used.
      std::set<index_t> involved{r};
      std::vector<index_t> stack(uses[r].begin(), uses[r].end());
      while (!stack.empty()) {
        const index_t k = stack.back();
        stack.pop_back();
        const index_t row = pivot_row[k];
        if (!involved.insert(row).second) continue;
        for (index_t k2 : uses[row]) stack.push_back(k2);
      }
      std::string msg = "redundant constraints: equation " + row_name(r) +
                        " is a linear combination of the others (singular constraint "
                        "Jacobian";
      if (m > n)
        msg += "; " + std::to_string(m) + " equations for " + std::to_string(n) + " coordinates";
      msg += "); involved: ";
      int shown = 0;
      for (index_t row : involved) {
        if (shown == 12) {
          msg += ", ... (" + std::to_string(involved.size() - 12) + " more)";
          break;
        }
        msg += (shown++ ? ", " : "") + row_name(row);
      }
      work.clear();
      throw RedundantConstraints(msg);
    }
    // choose the pivot column
    index_t best = -1;
    for (index_t c : work.touched) {
      if (pivot_of_col[c] >= 0) continue;
      const double a = std::abs(work.w[c]);
      if (a < threshold * big) continue;
      if (best < 0 || remaining[c] < remaining[best] ||
          (remaining[c] == remaining[best] && a > std::abs(work.w[best])))
        best = c;
    }
    PivotRow pr;
    pr.col = best;
    pr.value = work.w[best];
    for (index_t c : work.touched)
      if (c != best && pivot_of_col[c] < 0 && work.w[c] != 0.0)
        pr.entries.emplace_back(c, work.w[c]);
    part.quality = std::min(part.quality, std::abs(pr.value) / big);
    pivot_of_col[best] = static_cast<index_t>(pivots.size());
    pivot_row[pivots.size()] = r;
    part.dependent[r] = best;
    pivots.push_back(std::move(pr));
    work.clear();
  }
  for (index_t c = 0; c < n; ++c)
    if (pivot_of_col[c] < 0) part.independent.push_back(c);
  return part;
}

double partition_quality(const SparseRows& jac, const std::vector<index_t>& dependent) {
  PartitionMonitor monitor(jac, dependent);
  return monitor.quality(jac);
}

PartitionMonitor::PartitionMonitor(const SparseRows& pattern, const std::vector<index_t>& dependent)
    : n_(pattern.n_cols), row_ptr_(pattern.ptr), row_cols_(pattern.cols), dependent_(dependent) {
  const index_t m = pattern.n_rows();
  if (static_cast<index_t>(dependent.size()) != m)
    throw InvalidInput("PartitionMonitor: " + std::to_string(dependent.size()) +
                       " dependent columns for " + std::to_string(m) + " rows");
  if (row_ptr_.empty() || row_ptr_.front() != 0 ||
      row_ptr_.back() != static_cast<index_t>(row_cols_.size()))
    throw InvalidInput("PartitionMonitor: the row pointers do not span the entries");
  for (index_t r = 0; r < m; ++r)
    if (row_ptr_[r + 1] < row_ptr_[r])
      throw InvalidInput("PartitionMonitor: row pointers decrease at row " + std::to_string(r));
  for (const index_t c : row_cols_)
    if (c < 0 || c >= n_)
      throw InvalidInput("PartitionMonitor: column " + std::to_string(c) + " outside [0, " +
                         std::to_string(n_) + ")");
  std::vector<index_t> pivot_of_col(n_, -1), touched_in(n_, -1), queued_in(m, -1), touched;
  std::priority_queue<index_t, std::vector<index_t>, std::greater<>> heap;
  pivot_ptr_.assign(1, 0);
  free_ptr_.assign(1, 0);
  entry_ptr_.assign(1, 0);
  for (index_t r = 0; r < m; ++r) {
    const index_t d = dependent[r];
    if (d < 0 || d >= n_)
      throw InvalidInput("PartitionMonitor: dependent column " + std::to_string(d) + " of row " +
                         std::to_string(r) + " outside [0, " + std::to_string(n_) + ")");
    // the columns in order of first touch, and the pivot rows they call in (a pivot
    // row's entries lie in columns pivoted after it, so the heap yields them in order)
    touched.clear();
    auto touch = [&](index_t c) {
      if (touched_in[c] != r) {
        touched_in[c] = r;
        touched.push_back(c);
      }
      const index_t k = pivot_of_col[c];
      if (k >= 0 && queued_in[k] != r) {
        queued_in[k] = r;
        heap.push(k);
      }
    };
    for (index_t p = row_ptr_[r]; p < row_ptr_[r + 1]; ++p) touch(row_cols_[p]);
    while (!heap.empty()) {
      const index_t k = heap.top();
      heap.pop();
      pivots_.push_back(k);
      for (index_t e = entry_ptr_[k]; e < entry_ptr_[k + 1]; ++e) touch(entry_cols_[e]);
    }
    pivot_ptr_.push_back(static_cast<index_t>(pivots_.size()));
    for (const index_t c : touched)
      if (pivot_of_col[c] < 0) {
        free_.push_back(c);
        if (c != d) entry_cols_.push_back(c);
      }
    free_ptr_.push_back(static_cast<index_t>(free_.size()));
    entry_ptr_.push_back(static_cast<index_t>(entry_cols_.size()));
    if (touched_in[d] != r || pivot_of_col[d] >= 0) {
      if (zero_row_ < 0) zero_row_ = r;  // the forced pivot is zero whatever the values
    } else {
      pivot_of_col[d] = r;
    }
  }
  entry_vals_.assign(entry_cols_.size(), 0.0);
  pivot_vals_.assign(m, 0.0);
  w_.assign(n_, 0.0);
}

bool PartitionMonitor::matches(const SparseRows& rows,
                               const std::vector<index_t>& dependent) const {
  return rows.n_cols == n_ && dependent == dependent_ && rows.ptr == row_ptr_ &&
         rows.cols == row_cols_;
}

double PartitionMonitor::quality(const SparseRows& rows) {
  if (rows.vals.size() != row_cols_.size() || rows.ptr.size() != row_ptr_.size())
    throw InternalError("PartitionMonitor::quality: the rows' pattern is not the monitor's");
  if (zero_row_ >= 0) return 0;
  const index_t m = static_cast<index_t>(dependent_.size());
  double* w = w_.data();  // zero on entry and on exit
  double quality = 1;
  for (index_t r = 0; r < m; ++r) {
    for (index_t p = row_ptr_[r]; p < row_ptr_[r + 1]; ++p) w[row_cols_[p]] += rows.vals[p];
    for (index_t t = pivot_ptr_[r]; t < pivot_ptr_[r + 1]; ++t) {
      const index_t k = pivots_[t];
      const index_t c = dependent_[k];
      const double x = w[c];
      w[c] = 0.0;
      if (x == 0.0) continue;
      const double mult = x / pivot_vals_[k];
      for (index_t e = entry_ptr_[k]; e < entry_ptr_[k + 1]; ++e)
        w[entry_cols_[e]] += -mult * entry_vals_[e];
    }
    double big = 0;
    for (index_t f = free_ptr_[r]; f < free_ptr_[r + 1]; ++f)
      big = std::max(big, std::abs(w[free_[f]]));
    const double piv = w[dependent_[r]];
    const bool vanished = big == 0 || piv == 0;
    if (!vanished) {
      quality = std::min(quality, std::abs(piv) / big);
      pivot_vals_[r] = piv;
      for (index_t e = entry_ptr_[r]; e < entry_ptr_[r + 1]; ++e)
        entry_vals_[e] = w[entry_cols_[e]];
    }
    for (index_t f = free_ptr_[r]; f < free_ptr_[r + 1]; ++f) w[free_[f]] = 0.0;
    if (vanished) return 0;
  }
  return quality;
}

}  // namespace strata::mbd
