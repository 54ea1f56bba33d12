// strata::mbd — redundant constraint equations: which rows of Φ_q are linear combinations
// of earlier rows, found by the rank-revealing sparse QR factorization of Φ_qᵀ
// (SuiteSparseQR: Davis, ACM TOMS 38(1), 2011; its rank detection is Heath's: a column
// whose remaining norm after the earlier Householder reflections is below the tolerance is
// "dead", and R is squeezed so that its rows belong to the live columns).
//
// The columns are taken in their given order (no fill-reducing permutation), so the
// equations kept are the earliest independent ones and the ones removed are those that
// repeat earlier equations: the same choice Gaussian elimination of the rows in order
// makes, and the natural one for a user (the model reader adds the Euler-parameter
// normalisations first, then the joints in file order).
#pragma once

#include <vector>

#include "mbd/partition.hpp"

namespace strata::mbd {

/// Indices (ascending, 0-based) of the rows of `jac` (m rows, n_cols columns) that depend
/// linearly on the rows before them: a row is dependent when the norm of its part
/// orthogonal to the earlier rows is at most rel_tol times the largest row norm. The
/// number of independent rows is the numerical rank, m minus the size of the result.
/// Throws Error if the factorization fails (out of memory inside SuiteSparse).
std::vector<index_t> dependent_rows(const SparseRows& jac, double rel_tol);

}  // namespace strata::mbd
