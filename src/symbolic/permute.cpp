// strata — symmetric permutation of a sparsity pattern (see symbolic.hpp).
//
// B = P A Pᵀ with perm new→old: B(r, c) = A(perm[r], perm[c]). Because the pattern is
// symmetric, row r of B has the same column indices as column r, which are
// iperm[A(:, perm[r])]. Emitting the rows of B in increasing r into column buckets
// therefore fills every column with sorted row indices: one counting pass and one fill
// pass, O(n + nnz), no sort (the bucket transpose of Gustavson, ACM TOMS 4(3), 1978), in
// chunks of rows over the calling arena's threads (sparse/bucket_entries.hpp; the same
// result for every thread count).
#include <string>
#include <utility>

#include "sparse/bucket_entries.hpp"
#include "strata/errors.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {

std::vector<index_t> checked_inverse(index_t n, std::size_t offsets_size,
                                     const std::vector<index_t>& perm, const char* who) {
  if (static_cast<index_t>(offsets_size) != n + 1)
    throw InvalidInput(std::string(who) + ": offsets has " + std::to_string(offsets_size) +
                       " entries, expected " + std::to_string(n + 1));
  if (static_cast<index_t>(perm.size()) != n)
    throw InvalidInput(std::string(who) + ": permutation has " + std::to_string(perm.size()) +
                       " entries, expected " + std::to_string(n));
  std::vector<index_t> iperm(n, -1);
  for (index_t k = 0; k < n; ++k) {
    const index_t o = perm[k];
    if (o < 0 || o >= n || iperm[o] != -1)
      throw InvalidInput(std::string(who) + ": perm[" + std::to_string(k) +
                         "] = " + std::to_string(o) + " is out of range or repeated");
    iperm[o] = k;
  }
  return iperm;
}

SparseMatrix permute_symmetric_pattern(index_t n, const std::vector<index_t>& offsets,
                                       const index_t* indices, const std::vector<index_t>& perm) {
  const std::vector<index_t> iperm =
      checked_inverse(n, offsets.size(), perm, "permute_symmetric_pattern");
  SparseMatrix b;
  b.n_rows = b.n_cols = n;
  b.layout = Layout::csc;
  b.storage = Storage::full;
  b.indices.resize(offsets[n]);
  // row r of B (= column r, by symmetry) is iperm[A(:, perm[r])]: rows of B emitted in
  // increasing r into column buckets, in parallel chunks of rows
  index_t* out = b.indices.data();
  b.offsets = detail::bucket_entries(
      n, n,
      [&](index_t r) {
        return std::pair<index_t, index_t>{offsets[perm[r]], offsets[perm[r] + 1]};
      },
      [&](index_t, index_t p) { return iperm[indices[p]]; },
      [&](index_t slot, index_t r, index_t) { out[slot] = r; });
  return b;
}

SparseMatrix permute_symmetric_pattern(const SparseMatrix& full, const std::vector<index_t>& perm) {
  // Canonical full CSC first (expands a lower/upper matrix, sorts, removes duplicates).
  const bool canonical_full = full.layout == Layout::csc && full.storage == Storage::full;
  SparseMatrix expanded;
  if (!canonical_full) expanded = expand_symmetric(full);
  const SparseMatrix& a = canonical_full ? full : expanded;  // no copy of a canonical one
  if (a.n_rows != a.n_cols) throw InvalidInput("permute_symmetric_pattern needs a square matrix");
  return permute_symmetric_pattern(a.n_cols, a.offsets, a.indices.data(), perm);
}

}  // namespace strata::symbolic
