// strata — validation and canonical forms of SparseMatrix (see sparse_matrix.hpp).
//
// Canonicalization is a two-pass bucket transpose (Gustavson 1978): transposing twice
// sorts indices in linear time, and duplicates are summed on the way.
#include "strata/sparse_matrix.hpp"

#include <atomic>
#include <cmath>
#include <string>

#include "base/parallel_ranges.hpp"
#include "sparse/canonical.hpp"
#include "strata/errors.hpp"

namespace strata {
namespace {

std::string at(const char* what, index_t pos) {
  return std::string(what) + "[" + std::to_string(pos) + "]";
}

// Entry (row, col) of the k-th stored entry of major vector j.
inline void row_col(const SparseMatrix& a, index_t j, index_t p, index_t& r, index_t& c) {
  if (a.layout == Layout::csc) {
    r = a.indices[p];
    c = j;
  } else {
    r = j;
    c = a.indices[p];
  }
}

// Compressed-column copy of a (any layout), entries in the order they are met, possibly
// unsorted and duplicated. Pattern-only matrices get empty values.
SparseMatrix gather_csc(const SparseMatrix& a, bool mirror) {
  const bool vals = !a.values.empty();
  SparseMatrix t;
  t.n_rows = a.n_rows;
  t.n_cols = a.n_cols;
  t.layout = Layout::csc;
  t.storage = mirror ? Storage::full : a.storage;
  std::vector<index_t> count(a.n_cols + 1, 0);
  for (index_t j = 0; j < a.n_major(); ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      index_t r, c;
      row_col(a, j, p, r, c);
      ++count[c + 1];
      if (mirror && r != c) ++count[r + 1];
    }
  for (index_t j = 0; j < a.n_cols; ++j) count[j + 1] += count[j];
  t.offsets = count;
  t.indices.resize(count.back());
  if (vals) t.values.resize(count.back());
  for (index_t j = 0; j < a.n_major(); ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      index_t r, c;
      row_col(a, j, p, r, c);
      index_t q = count[c]++;
      t.indices[q] = r;
      if (vals) t.values[q] = a.values[p];
      if (mirror && r != c) {
        q = count[r]++;
        t.indices[q] = c;
        if (vals) t.values[q] = a.values[p];
      }
    }
  return t;
}

// Sorts indices within each column and sums duplicates, by a transpose to CSR and back.
SparseMatrix sort_and_sum(const SparseMatrix& a) {
  const bool vals = !a.values.empty();
  const index_t m = a.n_rows, n = a.n_cols;
  // transpose: column-major -> row-major buckets (rows sorted by column automatically)
  std::vector<index_t> rp(m + 1, 0);
  for (index_t p = 0; p < a.nnz(); ++p) ++rp[a.indices[p] + 1];
  for (index_t i = 0; i < m; ++i) rp[i + 1] += rp[i];
  std::vector<index_t> ci(a.nnz());
  std::vector<double> cv(vals ? a.nnz() : 0);
  std::vector<index_t> next(rp.begin(), rp.end() - 1);
  for (index_t j = 0; j < n; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      index_t q = next[a.indices[p]]++;
      ci[q] = j;
      if (vals) cv[q] = a.values[p];
    }
  // transpose back, summing duplicates: within row i the columns arrive sorted, so a
  // duplicate (i, j) is the last entry written to column j.
  SparseMatrix t;
  t.n_rows = m;
  t.n_cols = n;
  t.layout = Layout::csc;
  t.storage = a.storage;
  std::vector<index_t> cp(n + 1, 0);
  for (index_t p = 0; p < a.nnz(); ++p) ++cp[ci[p] + 1];
  for (index_t j = 0; j < n; ++j) cp[j + 1] += cp[j];
  std::vector<index_t> pos(cp.begin(), cp.end() - 1), start(cp.begin(), cp.end() - 1);
  std::vector<index_t> idx(a.nnz());
  std::vector<double> val(vals ? a.nnz() : 0);
  for (index_t i = 0; i < m; ++i)
    for (index_t p = rp[i]; p < rp[i + 1]; ++p) {
      const index_t j = ci[p];
      if (pos[j] > start[j] && idx[pos[j] - 1] == i) {
        if (vals) val[pos[j] - 1] += cv[p];
      } else {
        idx[pos[j]] = i;
        if (vals) val[pos[j]] = cv[p];
        ++pos[j];
      }
    }
  // compact
  t.offsets.assign(n + 1, 0);
  index_t w = 0;
  for (index_t j = 0; j < n; ++j) {
    for (index_t p = start[j]; p < pos[j]; ++p) {
      idx[w] = idx[p];
      if (vals) val[w] = val[p];
      ++w;
    }
    t.offsets[j + 1] = w;
  }
  idx.resize(w);
  if (vals) val.resize(w);
  t.indices = std::move(idx);
  t.values = std::move(val);
  return t;
}

// True when a (validated) is compressed-column with strictly increasing row indices in
// every column: already canonical, so sorting and summing would only copy it.
// The O(nnz) checks of a matrix with at least this many entries run in ranges of columns
// over the calling TBB arena's threads (base/parallel_ranges.hpp).
constexpr std::size_t kParallelCheckEntries = std::size_t{1} << 16;

// Whether ok(j0, j1) holds for every range of the major index: over the threads for a
// large matrix, else on the calling thread.
template <class Ok>
bool every_range(const SparseMatrix& a, const Ok& ok) {
  const index_t nmaj = a.n_major();
  if (a.indices.size() < kParallelCheckEntries) return ok(index_t{0}, nmaj);
  std::atomic<bool> all{true};
  detail::parallel_ranges(nmaj, 256, [&](index_t j0, index_t j1) {
    if (all.load(std::memory_order_relaxed) && !ok(j0, j1)) all = false;
  });
  return all;
}

bool sorted_csc(const SparseMatrix& a) {
  if (a.layout != Layout::csc) return false;
  return every_range(a, [&](index_t j0, index_t j1) {
    for (index_t j = j0; j < j1; ++j)
      for (index_t p = a.offsets[j] + 1; p < a.offsets[j + 1]; ++p)
        if (a.indices[p] <= a.indices[p - 1]) return false;
    return true;
  });
}

// validate's checks of the entries of major indices [j0, j1) (offsets already checked):
// false at the first entry out of range, not finite, or outside the stored triangle, or
// (report) InvalidInput naming it. With `sorted`, also clears *sorted where a line's
// indices do not strictly increase (the same pass: is_canonical_full).
bool entries_valid(const SparseMatrix& a, index_t j0, index_t j1, bool report,
                   bool* sorted = nullptr) {
  const index_t nmin = a.layout == Layout::csc ? a.n_rows : a.n_cols;
  bool increasing = true;
  for (index_t j = j0; j < j1; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      increasing &= p == a.offsets[j] || a.indices[p - 1] < i;
      if (i < 0 || i >= nmin) {
        if (!report) return false;
        throw InvalidInput(at("indices", p) + " = " + std::to_string(i) + " is out of range [0, " +
                           std::to_string(nmin) + ")");
      }
      if (!a.values.empty() && !std::isfinite(a.values[p])) {
        if (!report) return false;
        throw InvalidInput(at("values", p) + " is not finite (row " +
                           std::to_string(a.layout == Layout::csc ? i : j) + ", column " +
                           std::to_string(a.layout == Layout::csc ? j : i) + ")");
      }
      if (a.storage != Storage::full) {
        index_t r, c;
        row_col(a, j, p, r, c);
        if ((a.storage == Storage::lower && r < c) || (a.storage == Storage::upper && r > c)) {
          if (!report) return false;
          throw InvalidInput("entry (" + std::to_string(r) + ", " + std::to_string(c) +
                             ") lies outside the stored " +
                             (a.storage == Storage::lower ? "lower" : "upper") + " triangle");
        }
      }
    }
  if (sorted && !increasing) *sorted = false;
  return true;
}

}  // namespace

namespace {

// validate(a); with `sorted`, also whether every line's indices strictly increase, found
// in the same pass over the entries.
void validate_lines(const SparseMatrix& a, bool* sorted) {
  if (a.n_rows < 0 || a.n_cols < 0)
    throw InvalidInput("matrix has negative dimensions " + std::to_string(a.n_rows) + "x" +
                       std::to_string(a.n_cols));
  const index_t nmaj = a.n_major();
  // (compared as offsets.size() - 1 == nmaj: nmaj + 1 overflows for nmaj = INT64_MAX)
  if (a.offsets.empty() || static_cast<index_t>(a.offsets.size() - 1) != nmaj)
    throw InvalidInput("offsets has " + std::to_string(a.offsets.size()) + " entries, expected " +
                       std::to_string(static_cast<unsigned long long>(nmaj) + 1));
  if (a.offsets[0] != 0)
    throw InvalidInput("offsets[0] is " + std::to_string(a.offsets[0]) + ", not 0");
  for (index_t j = 0; j < nmaj; ++j)
    if (a.offsets[j + 1] < a.offsets[j]) throw InvalidInput(at("offsets", j + 1) + " decreases");
  const index_t nnz = a.offsets[nmaj];
  if (static_cast<index_t>(a.indices.size()) != nnz)
    throw InvalidInput("indices has " + std::to_string(a.indices.size()) +
                       " entries, offsets say " + std::to_string(nnz));
  if (!a.values.empty() && static_cast<index_t>(a.values.size()) != nnz)
    throw InvalidInput("values has " + std::to_string(a.values.size()) + " entries, offsets say " +
                       std::to_string(nnz));
  if (a.storage != Storage::full && a.n_rows != a.n_cols)
    throw InvalidInput("symmetric (lower/upper) storage needs a square matrix");
  // the entries over the threads; where one is bad, again in order for the first one's
  // message
  if (sorted) *sorted = true;
  std::atomic<bool> increasing{true};
  const bool valid = every_range(a, [&](index_t j0, index_t j1) {
    bool in_order = true;
    const bool ok = entries_valid(a, j0, j1, false, sorted ? &in_order : nullptr);
    if (!in_order) increasing.store(false, std::memory_order_relaxed);
    return ok;
  });
  if (!valid) entries_valid(a, 0, nmaj, true);
  if (sorted) *sorted = increasing.load();
}

}  // namespace

void validate(const SparseMatrix& a) { validate_lines(a, nullptr); }

SparseMatrix canonicalize(const SparseMatrix& a) {
  validate(a);
  // the multibody engine and most callers hand over canonical matrices: one O(nnz) check
  // instead of two bucket transposes
  if (sorted_csc(a)) return a;
  return sort_and_sum(gather_csc(a, false));
}

bool detail::is_canonical_full(const SparseMatrix& a) {
  bool sorted = false;
  validate_lines(a, &sorted);  // one pass over the entries for both
  return a.storage == Storage::full && a.layout == Layout::csc && sorted;
}

SparseMatrix expand_symmetric(const SparseMatrix& a) {
  if (detail::is_canonical_full(a)) return a;
  return sort_and_sum(gather_csc(a, a.storage != Storage::full));
}

void multiply(const SparseMatrix& a, const double* x, double* y) {
  for (index_t i = 0; i < a.n_rows; ++i) y[i] = 0.0;
  const bool sym = a.storage != Storage::full;
  for (index_t j = 0; j < a.n_major(); ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      index_t r, c;
      row_col(a, j, p, r, c);
      const double v = a.values.empty() ? 1.0 : a.values[p];
      y[r] += v * x[c];
      if (sym && r != c) y[c] += v * x[r];
    }
}

bool is_numerically_symmetric(const SparseMatrix& a) {
  if (a.n_rows != a.n_cols) return false;
  if (a.storage != Storage::full) return true;
  const SparseMatrix c = canonicalize(a);
  // Visiting the columns in increasing j meets the entries (i, j) of row i in increasing
  // j, the order of column i's own (sorted) rows: A equals Aᵀ exactly when each (i, j)
  // met is the next unvisited entry of column i, with the same value (nnz visits consume
  // nnz entries, none twice, so none is left over). One pass; stops at the first
  // difference.
  const index_t n = c.n_cols;
  std::vector<index_t> next(c.offsets.begin(), c.offsets.end() - 1);
  const bool vals = !c.values.empty();
  for (index_t j = 0; j < n; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      const index_t i = c.indices[p], q = next[i]++;
      if (q >= c.offsets[i + 1] || c.indices[q] != j) return false;
      if (vals && c.values[q] != c.values[p]) return false;
    }
  return true;
}

}  // namespace strata
