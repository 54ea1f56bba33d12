// strata — symmetric permutation of a sparsity pattern (see symbolic.hpp).
//
// B = P A Pᵀ with perm new→old: B(r, c) = A(perm[r], perm[c]). Because the pattern is
// symmetric, row r of B has the same column indices as column r, which are
// iperm[A(:, perm[r])]. Emitting the rows of B in increasing r into column buckets
// therefore fills every column with sorted row indices: one counting pass and one fill
// pass, O(n + nnz), no sort (the bucket transpose of Gustavson, ACM TOMS 4(3), 1978).
#include <string>

#include "strata/errors.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {

SparseMatrix permute_symmetric_pattern(const SparseMatrix& full, const std::vector<index_t>& perm) {
  // Canonical full CSC first (expands a lower/upper matrix, sorts, removes duplicates).
  const bool canonical_full = full.layout == Layout::csc && full.storage == Storage::full;
  const SparseMatrix a = canonical_full ? full : expand_symmetric(full);
  const index_t n = a.n_cols;
  if (a.n_rows != n) throw InvalidInput("permute_symmetric_pattern needs a square matrix");
  if (static_cast<index_t>(perm.size()) != n)
    throw InvalidInput("permute_symmetric_pattern: permutation has " + std::to_string(perm.size()) +
                       " entries, expected " + std::to_string(n));
  std::vector<index_t> iperm(n, -1);
  for (index_t k = 0; k < n; ++k) {
    const index_t o = perm[k];
    if (o < 0 || o >= n || iperm[o] != -1)
      throw InvalidInput("permute_symmetric_pattern: perm[" + std::to_string(k) +
                         "] = " + std::to_string(o) + " is out of range or repeated");
    iperm[o] = k;
  }
  SparseMatrix b;
  b.n_rows = b.n_cols = n;
  b.layout = Layout::csc;
  b.storage = Storage::full;
  b.offsets.assign(n + 1, 0);
  for (index_t r = 0; r < n; ++r) {
    const index_t col = perm[r];
    for (index_t p = a.offsets[col]; p < a.offsets[col + 1]; ++p)
      ++b.offsets[iperm[a.indices[p]] + 1];
  }
  for (index_t c = 0; c < n; ++c) b.offsets[c + 1] += b.offsets[c];
  b.indices.resize(b.offsets[n]);
  std::vector<index_t> next(b.offsets.begin(), b.offsets.end() - 1);
  for (index_t r = 0; r < n; ++r) {
    const index_t col = perm[r];
    for (index_t p = a.offsets[col]; p < a.offsets[col + 1]; ++p)
      b.indices[next[iperm[a.indices[p]]]++] = r;
  }
  return b;
}

}  // namespace strata::symbolic
