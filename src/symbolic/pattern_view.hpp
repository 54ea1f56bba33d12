// strata — column views of a symmetric pattern for the symbolic passes.
//
// The elimination tree, the column counts and the row-structure walks of the fronts visit
// each column's entries once and need them in no particular order (each entry of a column
// is a different row, and what the passes keep per row or per tree node does not depend
// on the order in which a column's rows arrive). So they can read a symmetrically
// permuted pattern P A Pᵀ through the permutation instead of forming it:
// RelabeledColumns gives column k of P A Pᵀ as new_of[i] for the entries i of column
// old_of[k] of A, in A's stored order. CscColumns is a pattern read as it is stored.
#pragma once

#include <vector>

#include "strata/types.hpp"

namespace strata::symbolic {

/// Column k: indices[offsets[k] .. offsets[k+1]).
struct CscColumns {
  const index_t* offsets = nullptr;
  const index_t* indices = nullptr;
  index_t n = 0;
  template <class F>
  void for_each(index_t k, F&& f) const {
    for (index_t p = offsets[k]; p < offsets[k + 1]; ++p) f(indices[p]);
  }
};

/// Column k: new_of[i] for i in column old_of[k] of (offsets, indices). With old_of a
/// new→old permutation and new_of its inverse, the columns of P A Pᵀ, unsorted.
struct RelabeledColumns {
  const index_t* offsets = nullptr;
  const index_t* indices = nullptr;
  const index_t* old_of = nullptr;
  const index_t* new_of = nullptr;
  index_t n = 0;
  template <class F>
  void for_each(index_t k, F&& f) const {
    const index_t c = old_of[k];
    for (index_t p = offsets[c]; p < offsets[c + 1]; ++p) f(new_of[indices[p]]);
  }
};

/// elimination_tree (symbolic.hpp) of the pattern given by `cols`.
template <class Columns>
std::vector<index_t> elimination_tree_of(const Columns& cols);

/// column_counts (symbolic.hpp) of the pattern given by `cols`.
template <class Columns>
std::vector<index_t> column_counts_of(const Columns& cols, const std::vector<index_t>& parent,
                                      const std::vector<index_t>& post);

}  // namespace strata::symbolic
