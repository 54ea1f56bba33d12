/* strata — C example: solve the 2D Poisson problem (5-point Laplacian on a k×k grid,
 * Dirichlet boundary) with the C interface, then refactorize with a shifted matrix.
 *
 * The matrix is given as its upper triangle in 1-based CSR with int32 indices (the
 * Fortran-style convention), to show the descriptor; any of CSR/CSC, 0/1-based,
 * int32/int64 and full/lower/upper storage works the same way.
 *
 * Build (installed library):  cc solve.c -lstrata -lstdc++ ... ; in the tree it is the
 * target `strata_example_c`. Usage: strata_example_c [k]   (default k = 50) */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

#include "strata/strata.h"

/* Prints the message of a failed call and exits. */
static void check(strata_status st, strata_solver* s, const char* what) {
  if (st != STRATA_OK) {
    fprintf(stderr, "%s failed: %s: %s\n", what, strata_status_string(st), strata_last_error(s));
    strata_destroy(s);
    exit(1);
  }
}

int main(int argc, char** argv) {
  const int k = argc > 1 ? atoi(argv[1]) : 50;
  if (k < 1) {
    fprintf(stderr, "usage: %s [k >= 1]\n", argv[0]);
    return 1;
  }
  const int n = k * k;

  /* upper triangle of the Laplacian, 1-based CSR: row p = i + k*j holds (p,p)=4,
   * (p,p+1)=-1 when i+1 < k, (p,p+k)=-1 when j+1 < k */
  int32_t* offsets = malloc((size_t)(n + 1) * sizeof(int32_t));
  int32_t* cols = malloc((size_t)3 * n * sizeof(int32_t));
  double* vals = malloc((size_t)3 * n * sizeof(double));
  int32_t nnz = 0;
  offsets[0] = 1;
  for (int j = 0; j < k; ++j)
    for (int i = 0; i < k; ++i) {
      const int p = i + k * j;
      cols[nnz] = p + 1, vals[nnz++] = 4.0;
      if (i + 1 < k) cols[nnz] = p + 2, vals[nnz++] = -1.0;
      if (j + 1 < k) cols[nnz] = p + k + 1, vals[nnz++] = -1.0;
      offsets[p + 1] = nnz + 1;
    }
  strata_matrix a = {n, n, STRATA_CSR, STRATA_STORAGE_UPPER, STRATA_INT32, 1, offsets, cols, vals};

  strata_solver* s = NULL;
  check(strata_create(&s), s, "strata_create");
  check(strata_set_type(s, STRATA_TYPE_SPD), s, "strata_set_type");
  check(strata_set_ordering(s, STRATA_ORDERING_ND), s, "strata_set_ordering");
  check(strata_analyze(s, &a), s, "strata_analyze");
  check(strata_factorize(s, &a), s, "strata_factorize");

  /* two right-hand sides, column-major n×2: all ones, and a point load */
  double* b = calloc((size_t)2 * n, sizeof(double));
  double* x = malloc((size_t)2 * n * sizeof(double));
  for (int p = 0; p < n; ++p) b[p] = 1.0;
  b[n + n / 2] = 1.0;
  check(strata_solve(s, 2, b, x), s, "strata_solve");

  strata_stats st;
  check(strata_get_stats(s, &st), s, "strata_get_stats");
  printf("n = %lld, nnz(L) = %lld, factor flops = %.3g, fronts = %lld\n", (long long)st.n,
         (long long)st.nnz_l, st.factor_flops, (long long)st.n_fronts);
  printf("log|det A| = %.12g, backward error = %.2e after %d refinement steps\n",
         st.log_abs_determinant, st.backward_error, st.refinement_steps);
  printf("u(centre) = %.10g for the unit load, %.10g for the point load\n", x[n / 2], x[n + n / 2]);

  /* refactorize: same pattern, A + 0.5 I, solve in place */
  for (int p = 0; p < n; ++p) vals[offsets[p] - 1] += 0.5; /* the diagonal is first */
  check(strata_refactorize(s, &a), s, "strata_refactorize");
  check(strata_solve(s, 2, b, b), s, "strata_solve (in place)");
  check(strata_get_stats(s, &st), s, "strata_get_stats");
  printf("shifted: u(centre) = %.10g, backward error = %.2e\n", b[n / 2], st.backward_error);

  const int ok = st.backward_error < 1e-12;
  strata_destroy(s);
  free(offsets);
  free(cols);
  free(vals);
  free(b);
  free(x);
  return ok ? 0 : 1;
}
