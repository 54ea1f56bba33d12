// strata — whether a matrix is already in the canonical form the analysis reads (see
// sparse_matrix.cpp), for callers that would otherwise copy it through expand_symmetric.
#pragma once

#include "strata/sparse_matrix.hpp"

namespace strata::detail {

/// True when A has full storage and is canonical CSC (rows strictly increasing in every
/// column): expand_symmetric(A) would return a copy of A. Validates A first (throws
/// InvalidInput as strata::validate).
bool is_canonical_full(const SparseMatrix& a);

}  // namespace strata::detail
