// strata — the extend-add map of an assembly tree (symbolic.hpp, ChildRowMap).
//
// A front's contribution block is indexed by its non-pivot rows, a subset of its parent's
// rows (the rows of a front are the union of its pivots' column structures, and the
// parent's contain every non-pivot row of its children). Assembling the block into the
// parent needs the position of each such row in the parent's list. One pass per parent:
// mark its rows' positions in a map of size n, read them off for each child's
// contribution rows, clear the marks. The result depends on the tree alone, so it is
// made once per analysis and shared by every executor and the device solve.
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {

ChildRowMap child_row_map(const AssemblyTree& t) {
  const index_t nf = t.n_fronts();
  ChildRowMap map;
  map.offsets.assign(nf + 1, 0);
  for (index_t f = 0; f < nf; ++f) map.offsets[f + 1] = map.offsets[f] + t.cb_size(f);
  map.rel.assign(map.offsets[nf], -1);
  std::vector<index_t> position(t.n, -1);
  for (index_t f = 0; f < nf; ++f) {
    const index_t* rows = t.rows_of(f);
    for (index_t i = 0; i < t.n_rows(f); ++i) position[rows[i]] = i;
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      const index_t* crow = t.rows_of(c) + t.n_pivots(c);
      index_t* rel = map.rel.data() + map.offsets[c];
      for (index_t i = 0; i < t.cb_size(c); ++i) rel[i] = position[crow[i]];
    }
    for (index_t i = 0; i < t.n_rows(f); ++i) position[rows[i]] = -1;
  }
  return map;
}

}  // namespace strata::symbolic
