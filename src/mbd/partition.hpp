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
/// current Jacobian; 0 if a forced pivot vanishes.
double partition_quality(const SparseRows& jac, const std::vector<index_t>& dependent);

}  // namespace strata::mbd
