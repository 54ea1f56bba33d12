// strata::mbd — coordinate partitioning of the constraint Jacobian Φ_q (m × n) into
// dependent and independent coordinates (Wehage & Haug 1982; Haug 1989, §3.6 and
// §11.3), done with sparse Gaussian elimination so that it scales to large models.
//
// Rows are eliminated in order (left-looking: each row is reduced by the earlier pivot
// rows); the pivot column of a row is chosen among its entries of at least
// `threshold` × the largest, preferring the column that occurs in the fewest remaining
// rows (a Markowitz-style choice that keeps fill low). A row that reduces to
// (numerically) zero is redundant: the constraints are not independent, and the error
// names the constraint equations that combine to it.
#pragma once

#include <functional>
#include <string>
#include <vector>

#include "strata/errors.hpp"
#include "strata/types.hpp"

namespace strata::mbd {

/// Redundant (linearly dependent) constraint equations; what() names them.
class RedundantConstraints : public InvalidInput {
 public:
  using InvalidInput::InvalidInput;
};

/// Sparse rows of Φ_q: row r has entries (cols[k], vals[k]) for k in [ptr[r], ptr[r+1]).
struct SparseRows {
  index_t n_cols = 0;
  std::vector<index_t> ptr{0};
  std::vector<index_t> cols;
  std::vector<double> vals;
  index_t n_rows() const { return static_cast<index_t>(ptr.size()) - 1; }
};

struct Partition {
  std::vector<index_t> dependent;    ///< pivot column of each row (size m)
  std::vector<index_t> independent;  ///< the other columns, ascending (size n − m)
  double quality = 1;                ///< min over rows of |pivot| / max |reduced row entry|
};

/// Chooses the dependent coordinates. `row_name(r)` describes row r for messages.
/// Throws RedundantConstraints when a row is (relative to its original size, below
/// `redundancy_tol`) a combination of earlier rows (always the case for some row when
/// m > n).
Partition partition_coordinates(const SparseRows& jac, double threshold, double redundancy_tol,
                                const std::function<std::string(index_t)>& row_name);

/// The quality (see Partition::quality) of a given choice of dependent columns at the
/// current Jacobian; 0 if a forced pivot vanishes. One evaluation of a PartitionMonitor
/// built for `jac`'s pattern.
double partition_quality(const SparseRows& jac, const std::vector<index_t>& dependent);

/// The quality of a fixed choice of dependent columns (`dependent[r]`: the pivot column of
/// row r) for a fixed pattern of Φ_q, evaluated again as the values change (the partition
/// check after every step). The elimination is that of partition_coordinates with the
/// pivots forced: row r is reduced by the earlier pivot rows in increasing order, then
/// |pivot| / max |reduced entry of an unpivoted column| is taken. Its structure — which
/// pivot rows reach each row (through fill), in which order, and which columns each pivot
/// row holds — depends on the pattern alone and is found once by the constructor; an
/// evaluation is then the numeric elimination in flat arrays. Entries that are exactly
/// zero, in the pattern or by cancellation, change no result: the quality is bitwise that
/// of the elimination on the nonzeros alone (a pivot row meeting a zero is skipped there,
/// and adds ±0 here).
class PartitionMonitor {
 public:
  PartitionMonitor() = default;
  /// The structure for `pattern` (its values are not read) and `dependent` (size
  /// pattern.n_rows(), columns in [0, pattern.n_cols)). Throws InvalidInput on sizes or
  /// columns out of range.
  PartitionMonitor(const SparseRows& pattern, const std::vector<index_t>& dependent);
  /// True when `rows` has the pattern and `dependent` the columns this was built for.
  bool matches(const SparseRows& rows, const std::vector<index_t>& dependent) const;
  /// The quality at `rows.vals` (rows with the pattern of the constructor; checked in
  /// size only): in (0, 1], or 0 when a forced pivot vanishes or a row reduces to zero.
  double quality(const SparseRows& rows);

 private:
  index_t n_ = 0;
  std::vector<index_t> row_ptr_, row_cols_, dependent_;
  // per row r: the pivot rows that reduce it, increasing (pivots_[pivot_ptr_[r]..]); the
  // unpivoted columns it touches, in order of first touch (free_[free_ptr_[r]..]; the max
  // is taken over them); of those, all but dependent_[r]: pivot row r's entries
  // (entry_cols_[entry_ptr_[r]..], values entry_vals_ at the last evaluation)
  std::vector<index_t> pivot_ptr_, pivots_, free_ptr_, free_, entry_ptr_, entry_cols_;
  std::vector<double> entry_vals_, pivot_vals_, w_;
  index_t zero_row_ = -1;  // first row whose pivot is structurally zero (quality 0)
};

}  // namespace strata::mbd
