// strata::mbd — sparse coordinate partitioning (see partition.hpp).
#include "mbd/partition.hpp"

#include <algorithm>
#include <cmath>
#include <queue>
#include <set>

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
  const index_t m = jac.n_rows(), n = jac.n_cols;
  std::vector<PivotRow> pivots;
  std::vector<index_t> pivot_of_col(n, -1), used;
  Work work(n);
  double quality = 1;
  for (index_t r = 0; r < m; ++r) {
    reduce_row(jac, r, pivots, pivot_of_col, work, used);
    const index_t c = dependent[r];
    double big = 0;
    for (index_t t : work.touched)
      if (pivot_of_col[t] < 0) big = std::max(big, std::abs(work.w[t]));
    const double piv = work.mark[c] ? work.w[c] : 0.0;
    if (big == 0 || piv == 0) return 0;
    quality = std::min(quality, std::abs(piv) / big);
    PivotRow pr{c, piv, {}};
    for (index_t t : work.touched)
      if (t != c && pivot_of_col[t] < 0 && work.w[t] != 0.0) pr.entries.emplace_back(t, work.w[t]);
    pivot_of_col[c] = static_cast<index_t>(pivots.size());
    pivots.push_back(std::move(pr));
    work.clear();
  }
  return quality;
}

}  // namespace strata::mbd
