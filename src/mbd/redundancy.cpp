// strata::mbd — redundant constraint equations by SuiteSparseQR (see redundancy.hpp).
#include "mbd/redundancy.hpp"

#include <SuiteSparseQR.hpp>
#include <algorithm>
#include <cmath>
#include <string>

#include "strata/errors.hpp"

namespace strata::mbd {

std::vector<index_t> dependent_rows(const SparseRows& jac, double rel_tol) {
  const index_t m = jac.n_rows(), n = jac.n_cols;
  if (m == 0) return {};
  cholmod_common cc;
  cholmod_l_start(&cc);
  // A = Φ_qᵀ (n × m): column r of A is row r of Φ_q, already in CSC form
  cholmod_sparse* a = cholmod_l_allocate_sparse(n, m, jac.cols.size(), /*sorted=*/0,
                                                /*packed=*/1, /*stype=*/0, CHOLMOD_REAL, &cc);
  if (!a) {
    cholmod_l_finish(&cc);
    throw Error("redundancy analysis: SuiteSparse could not allocate Φ_qᵀ");
  }
  auto* ap = static_cast<SuiteSparse_long*>(a->p);
  auto* ai = static_cast<SuiteSparse_long*>(a->i);
  auto* ax = static_cast<double*>(a->x);
  double big = 0;
  for (index_t r = 0; r <= m; ++r) ap[r] = jac.ptr[r];
  for (index_t r = 0; r < m; ++r) {
    double s = 0;
    for (index_t p = jac.ptr[r]; p < jac.ptr[r + 1]; ++p) {
      ai[p] = jac.cols[p];
      ax[p] = jac.vals[p];
      s += jac.vals[p] * jac.vals[p];
    }
    big = std::max(big, std::sqrt(s));
  }
  cholmod_l_sort(a, &cc);  // SuiteSparseQR wants sorted row indices
  cholmod_sparse* r = nullptr;
  SuiteSparse_long* e = nullptr;
  const SuiteSparse_long rank = SuiteSparseQR<double>(SPQR_ORDERING_FIXED, rel_tol * big,
                                                      /*econ=*/m, a, &r, &e, &cc);
  if (rank < 0 || !r) {
    cholmod_l_free_sparse(&a, &cc);
    cholmod_l_finish(&cc);
    throw Error("redundancy analysis: SuiteSparseQR failed (status " + std::to_string(cc.status) +
                ")");
  }
  // Squeezed R: a live column has its pivot in the row after the previous live column's;
  // a dead one has entries only above it.
  std::vector<index_t> dead;
  const auto* rp = static_cast<const SuiteSparse_long*>(r->p);
  const auto* ri = static_cast<const SuiteSparse_long*>(r->i);
  const auto* rx = static_cast<const double*>(r->x);
  SuiteSparse_long live = 0;
  for (index_t j = 0; j < m; ++j) {
    bool pivot = false;
    for (SuiteSparse_long p = rp[j]; p < rp[j + 1]; ++p)
      if (ri[p] == live && rx[p] != 0.0) pivot = true;
    const index_t col = e ? static_cast<index_t>(e[j]) : j;
    if (pivot && live < rank)
      ++live;
    else
      dead.push_back(col);
  }
  cholmod_l_free_sparse(&r, &cc);
  cholmod_l_free_sparse(&a, &cc);
  if (e) cholmod_l_free(m, sizeof(SuiteSparse_long), e, &cc);
  cholmod_l_finish(&cc);
  std::sort(dead.begin(), dead.end());
  return dead;
}

}  // namespace strata::mbd
