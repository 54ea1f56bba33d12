/* strata — test of the C interface, compiled as C99.
 *
 * Runs analyze / factorize / solve / refactorize on a small SPD, a symmetric indefinite
 * (KKT) and an unsymmetric matrix, each given in every index convention the interface
 * accepts (CSR and CSC, 0- and 1-based, int32 and int64, full / lower / upper storage for
 * the symmetric ones), checks the backward error of the solutions, the statistics against
 * a dense reference (log|det|, inertia), and the status codes for bad input and calls in
 * the wrong order. Prints "N passed, M failed" last; exits 1 on any failure. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "strata/strata.h"

static int g_passed = 0;
static int g_failed = 0;

#define CHECK(cond, ...)                                              \
  do {                                                                \
    if (cond) {                                                       \
      ++g_passed;                                                     \
    } else {                                                          \
      ++g_failed;                                                     \
      fprintf(stderr, "FAIL %s:%d: %s: ", __FILE__, __LINE__, #cond); \
      fprintf(stderr, __VA_ARGS__);                                   \
      fprintf(stderr, "\n");                                          \
    }                                                                 \
  } while (0)

#define CHECK_STATUS(call, expected, solver)                                                       \
  do {                                                                                             \
    strata_status st_ = (call);                                                                    \
    CHECK(st_ == (expected), "%s returned %s, expected %s (%s)", #call, strata_status_string(st_), \
          strata_status_string(expected), strata_last_error(solver));                              \
  } while (0)

/* ------------------------------------------------------------------------------------ */
/* Dense test matrices (row-major n×n) and conversion to every sparse convention         */
/* ------------------------------------------------------------------------------------ */

static uint64_t g_rng = 88172645463325252ull;
static double rnd(void) { /* uniform in [-1, 1) */
  g_rng ^= g_rng << 13;
  g_rng ^= g_rng >> 7;
  g_rng ^= g_rng << 17;
  return (double)(g_rng >> 11) / 9007199254740992.0 * 2.0 - 1.0;
}

/* Symmetric positive definite: random symmetric sparse pattern, diagonally dominant. */
static double* make_spd(int n) {
  double* a = calloc((size_t)n * n, sizeof(double));
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < i; ++j)
      if (j == i - 1 || rnd() > 0.8) a[i * n + j] = a[j * n + i] = rnd();
  for (int i = 0; i < n; ++i) {
    double s = 1.0;
    for (int j = 0; j < n; ++j) s += fabs(a[i * n + j]);
    a[i * n + i] = s;
  }
  return a;
}

/* KKT matrix [H Bᵀ; B 0] with H (nh×nh) SPD and B (m×nh) of full rank: inertia
 * (nh, m, 0). */
static double* make_kkt(int nh, int m) {
  const int n = nh + m;
  double* a = calloc((size_t)n * n, sizeof(double));
  double* h = make_spd(nh);
  for (int i = 0; i < nh; ++i)
    for (int j = 0; j < nh; ++j) a[i * n + j] = h[i * nh + j];
  free(h);
  for (int r = 0; r < m; ++r)
    for (int j = 0; j < nh; ++j) {
      double v = (j == 2 * r) ? 1.0 + fabs(rnd()) : (rnd() > 0.7 ? rnd() : 0.0);
      a[(nh + r) * n + j] = a[j * n + nh + r] = v;
    }
  return a;
}

/* Unsymmetric: random unsymmetric pattern, a few small diagonal entries. */
static double* make_general(int n) {
  double* a = calloc((size_t)n * n, sizeof(double));
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (i != j && (j == i + 1 || rnd() > 0.75)) a[i * n + j] = rnd();
  for (int i = 0; i < n; ++i) a[i * n + i] = (i % 4 == 0) ? 0.01 * rnd() : 3.0 + rnd();
  return a;
}

/* Sparse arrays in one convention. */
typedef struct {
  strata_matrix m;
  void* offsets;
  void* indices;
  double* values;
} sparse;

static void store_index(void* arr, strata_index_type t, int64_t k, int64_t v) {
  if (t == STRATA_INT32)
    ((int32_t*)arr)[k] = (int32_t)v;
  else
    ((int64_t*)arr)[k] = v;
}

/* Dense row-major a (n×n) to `layout`, `storage`, index type and base. Within each
 * compressed vector entries are written in reverse order (unsorted input). */
static sparse to_sparse(const double* a, int n, strata_layout layout, strata_storage storage,
                        strata_index_type itype, int base) {
  sparse s;
  const size_t isz = itype == STRATA_INT32 ? sizeof(int32_t) : sizeof(int64_t);
  s.offsets = malloc((size_t)(n + 1) * isz);
  s.indices = malloc((size_t)n * n * isz + 1);
  s.values = malloc((size_t)n * n * sizeof(double) + 1);
  int64_t nnz = 0;
  store_index(s.offsets, itype, 0, base);
  for (int major = 0; major < n; ++major) {
    for (int minor = n - 1; minor >= 0; --minor) {
      const int row = layout == STRATA_CSR ? major : minor;
      const int col = layout == STRATA_CSR ? minor : major;
      const double v = a[row * n + col];
      if (v == 0.0 && row != col) continue;
      if (storage == STRATA_STORAGE_LOWER && row < col) continue;
      if (storage == STRATA_STORAGE_UPPER && row > col) continue;
      store_index(s.indices, itype, nnz, minor + base);
      s.values[nnz] = v;
      ++nnz;
    }
    store_index(s.offsets, itype, major + 1, nnz + base);
  }
  s.m.n_rows = n;
  s.m.n_cols = n;
  s.m.layout = layout;
  s.m.storage = storage;
  s.m.index_type = itype;
  s.m.index_base = base;
  s.m.offsets = s.offsets;
  s.m.indices = s.indices;
  s.m.values = s.values;
  return s;
}

/* Entries of s (n columns or rows). */
static int64_t sparse_nnz(const sparse* s, int n) {
  const int64_t end = s->m.index_type == STRATA_INT32 ? ((const int32_t*)s->offsets)[n]
                                                      : ((const int64_t*)s->offsets)[n];
  return end - s->m.index_base;
}

static void free_sparse(sparse* s) {
  free(s->offsets);
  free(s->indices);
  free(s->values);
}

/* ‖b − A x‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) for dense row-major A. */
static double backward_error(const double* a, int n, const double* x, const double* b) {
  double rmax = 0, anorm = 0, xmax = 0, bmax = 0;
  for (int i = 0; i < n; ++i) {
    double r = b[i], row = 0;
    for (int j = 0; j < n; ++j) {
      r -= a[i * n + j] * x[j];
      row += fabs(a[i * n + j]);
    }
    if (fabs(r) > rmax) rmax = fabs(r);
    if (row > anorm) anorm = row;
    if (fabs(x[i]) > xmax) xmax = fabs(x[i]);
    if (fabs(b[i]) > bmax) bmax = fabs(b[i]);
  }
  return rmax / (anorm * xmax + bmax);
}

/* log|det A| and its sign by dense LU with partial pivoting. */
static double dense_logdet(const double* a0, int n, int* sign) {
  double* a = malloc((size_t)n * n * sizeof(double));
  memcpy(a, a0, (size_t)n * n * sizeof(double));
  double ld = 0;
  int sg = 1;
  for (int k = 0; k < n; ++k) {
    int p = k;
    for (int i = k + 1; i < n; ++i)
      if (fabs(a[i * n + k]) > fabs(a[p * n + k])) p = i;
    if (p != k) {
      sg = -sg;
      for (int j = 0; j < n; ++j) {
        double t = a[k * n + j];
        a[k * n + j] = a[p * n + j];
        a[p * n + j] = t;
      }
    }
    const double d = a[k * n + k];
    if (d < 0) sg = -sg;
    ld += log(fabs(d));
    for (int i = k + 1; i < n; ++i) {
      const double f = a[i * n + k] / d;
      for (int j = k; j < n; ++j) a[i * n + j] -= f * a[k * n + j];
    }
  }
  free(a);
  *sign = sg;
  return ld;
}

/* ------------------------------------------------------------------------------------ */
/* Full phase sequence on one matrix in one convention                                   */
/* ------------------------------------------------------------------------------------ */

static const char* layout_name(strata_layout l) { return l == STRATA_CSR ? "csr" : "csc"; }
static const char* storage_name(strata_storage s) {
  return s == STRATA_STORAGE_FULL ? "full" : s == STRATA_STORAGE_LOWER ? "lower" : "upper";
}

static void run_case(const char* name, const double* a, int n, strata_layout layout,
                     strata_storage storage, strata_index_type itype, int base,
                     strata_matrix_type expect_type, int64_t expect_negative) {
  char label[160];
  snprintf(label, sizeof label, "%s %s %s int%d %d-based", name, layout_name(layout),
           storage_name(storage), itype == STRATA_INT32 ? 32 : 64, base);
  strata_solver* s = NULL;
  CHECK_STATUS(strata_create(&s), STRATA_OK, s);
  sparse sp = to_sparse(a, n, layout, storage, itype, base);
  const int nrhs = 3;
  double* b = malloc((size_t)n * nrhs * sizeof(double));
  double* x = malloc((size_t)n * nrhs * sizeof(double));
  for (int i = 0; i < n * nrhs; ++i) b[i] = rnd();

  CHECK_STATUS(strata_set_num_threads(s, 2), STRATA_OK, s);
  CHECK_STATUS(strata_analyze(s, &sp.m), STRATA_OK, s);
  int64_t size = -1;
  CHECK_STATUS(strata_size(s, &size), STRATA_OK, s);
  CHECK(size == n, "%s: strata_size %lld", label, (long long)size);
  CHECK_STATUS(strata_factorize(s, &sp.m), STRATA_OK, s);
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
  double be = backward_error(a, n, x, b);
  CHECK(be < 1e-13, "%s: backward error %.3g (one rhs)", label, be);

  /* several right-hand sides, column-major */
  CHECK_STATUS(strata_solve(s, nrhs, b, x), STRATA_OK, s);
  for (int r = 0; r < nrhs; ++r) {
    be = backward_error(a, n, x + r * n, b + r * n);
    CHECK(be < 1e-13, "%s: backward error %.3g (rhs %d of %d)", label, be, r, nrhs);
  }

  strata_stats st;
  CHECK_STATUS(strata_get_stats(s, &st), STRATA_OK, s);
  CHECK(st.analyzed && st.factorized && st.solved, "%s: phase flags %d %d %d", label, st.analyzed,
        st.factorized, st.solved);
  CHECK(st.n == n, "%s: stats.n %lld", label, (long long)st.n);
  CHECK(st.nnz_l >= n && st.factor_flops > 0 && st.n_fronts > 0, "%s: analysis stats", label);
  CHECK(st.type == expect_type, "%s: type %d, expected %d", label, (int)st.type, (int)expect_type);
  CHECK(st.backward_error < 1e-13, "%s: stats.backward_error %.3g", label, st.backward_error);
  CHECK(st.refinement_steps >= 0, "%s: refinement steps", label);

  /* the same figures as JSON: needed size, whole text, a cut copy */
  size_t need = 0;
  CHECK_STATUS(strata_get_stats_json(s, NULL, 0, &need), STRATA_OK, s);
  char* text = malloc(need);
  size_t again = 0;
  CHECK_STATUS(strata_get_stats_json(s, text, need, &again), STRATA_OK, s);
  CHECK(again == need && strlen(text) + 1 == need, "%s: JSON size %zu, %zu, text %zu", label, need,
        again, strlen(text));
  char expect_n[64];
  snprintf(expect_n, sizeof expect_n, "\"n\":%lld,", (long long)n);
  CHECK(text[0] == '{' && strstr(text, expect_n) && strstr(text, "\"factor\":{") &&
            strstr(text, "\"solve\":{") && strstr(text, "\"backward_error\":"),
        "%s: JSON %.120s", label, text);
  char cut[8];
  CHECK_STATUS(strata_get_stats_json(s, cut, sizeof cut, NULL), STRATA_OK, s);
  CHECK(strlen(cut) == sizeof cut - 1 && strncmp(cut, text, sizeof cut - 1) == 0,
        "%s: cut JSON '%s'", label, cut);
  CHECK_STATUS(strata_get_stats_json(s, NULL, 4, NULL), STRATA_ERROR_INVALID_INPUT, s);
  free(text);
  int sign = 0;
  const double ld = dense_logdet(a, n, &sign);
  CHECK(fabs(st.log_abs_determinant - ld) < 1e-8 * (1 + fabs(ld)),
        "%s: log|det| %.15g, dense %.15g", label, st.log_abs_determinant, ld);
  CHECK(st.determinant_sign == sign, "%s: det sign %d, dense %d", label, st.determinant_sign, sign);
  if (expect_type != STRATA_TYPE_GENERAL) {
    CHECK(st.inertia_negative == expect_negative && st.inertia_zero == 0 &&
              st.inertia_positive == n - expect_negative,
          "%s: inertia (%lld, %lld, %lld)", label, (long long)st.inertia_positive,
          (long long)st.inertia_negative, (long long)st.inertia_zero);
  }
  int64_t* perm = malloc((size_t)n * sizeof(int64_t));
  char* seen = calloc((size_t)n, 1);
  CHECK_STATUS(strata_get_permutation(s, perm), STRATA_OK, s);
  int is_perm = 1;
  for (int k = 0; k < n; ++k) {
    if (perm[k] < 0 || perm[k] >= n || seen[perm[k]])
      is_perm = 0;
    else
      seen[perm[k]] = 1;
  }
  CHECK(is_perm, "%s: permutation", label);
  free(perm);
  free(seen);

  /* refactorize with new values on the same pattern: A2 = 2A + diag(0.5) for SPD (still
   * SPD), 2A otherwise; then solve in place */
  double* a2 = malloc((size_t)n * n * sizeof(double));
  for (int i = 0; i < n * n; ++i) a2[i] = 2.0 * a[i];
  if (expect_type == STRATA_TYPE_SPD)
    for (int i = 0; i < n; ++i) a2[i * n + i] += 0.5;
  sparse sp2 = to_sparse(a2, n, layout, storage, itype, base);
  CHECK_STATUS(strata_refactorize(s, &sp2.m), STRATA_OK, s);
  memcpy(x, b, (size_t)n * nrhs * sizeof(double));
  CHECK_STATUS(strata_solve(s, nrhs, x, x), STRATA_OK, s);
  for (int r = 0; r < nrhs; ++r) {
    be = backward_error(a2, n, x + r * n, b + r * n);
    CHECK(be < 1e-13, "%s: backward error %.3g after refactorize (rhs %d)", label, be, r);
  }
  /* the values alone, in the order of the matrix given to strata_analyze: the same
   * factor, so the same solution to the bit */
  const int64_t nnz2 = sparse_nnz(&sp2, n);
  double* y = malloc((size_t)n * nrhs * sizeof(double));
  CHECK_STATUS(strata_refactorize_values(s, nnz2, sp2.values), STRATA_OK, s);
  memcpy(y, b, (size_t)n * nrhs * sizeof(double));
  CHECK_STATUS(strata_solve(s, nrhs, y, y), STRATA_OK, s);
  CHECK(memcmp(x, y, (size_t)n * nrhs * sizeof(double)) == 0,
        "%s: refactorize_values solves as refactorize", label);
  CHECK_STATUS(strata_refactorize_values(s, nnz2 + 1, sp2.values), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_refactorize_values(s, nnz2, NULL), STRATA_ERROR_INVALID_INPUT, s);
  free(y);
  free_sparse(&sp2);
  free(a2);

  free_sparse(&sp);
  free(b);
  free(x);
  strata_destroy(s);
}

static void run_all_conventions(const char* name, const double* a, int n, int symmetric,
                                strata_matrix_type expect_type, int64_t expect_negative) {
  const strata_layout layouts[] = {STRATA_CSR, STRATA_CSC};
  const strata_storage storages[] = {STRATA_STORAGE_FULL, STRATA_STORAGE_LOWER,
                                     STRATA_STORAGE_UPPER};
  const strata_index_type itypes[] = {STRATA_INT32, STRATA_INT64};
  for (int l = 0; l < 2; ++l)
    for (int st = 0; st < (symmetric ? 3 : 1); ++st)
      for (int t = 0; t < 2; ++t)
        for (int base = 0; base <= 1; ++base)
          run_case(name, a, n, layouts[l], storages[st], itypes[t], base, expect_type,
                   expect_negative);
}

/* ------------------------------------------------------------------------------------ */
/* Options and types                                                                     */
/* ------------------------------------------------------------------------------------ */

static void test_options(const double* spd, const double* kkt, int n_spd, int n_kkt) {
  strata_solver* s = NULL;
  CHECK_STATUS(strata_create(&s), STRATA_OK, s);
  /* every ordering, explicit types, small blocks, no refinement */
  const strata_ordering orderings[] = {STRATA_ORDERING_ND, STRATA_ORDERING_METIS,
                                       STRATA_ORDERING_AMD, STRATA_ORDERING_NATURAL,
                                       STRATA_ORDERING_AUTO};
  sparse sp = to_sparse(spd, n_spd, STRATA_CSC, STRATA_STORAGE_LOWER, STRATA_INT64, 0);
  double* b = malloc((size_t)n_kkt * sizeof(double));
  double* x = malloc((size_t)n_kkt * sizeof(double));
  for (int i = 0; i < n_kkt; ++i) b[i] = 1.0 + i;
  for (int o = 0; o < 5; ++o) {
    CHECK_STATUS(strata_set_ordering(s, orderings[o]), STRATA_OK, s);
    CHECK_STATUS(strata_set_type(s, STRATA_TYPE_SPD), STRATA_OK, s);
    CHECK_STATUS(strata_set_max_block_size(s, 4), STRATA_OK, s);
    CHECK_STATUS(strata_set_refinement_steps(s, o), STRATA_OK, s);
    CHECK_STATUS(strata_set_refinement_tolerance(s, 1e-15), STRATA_OK, s);
    CHECK_STATUS(strata_set_backend(s, STRATA_BACKEND_CPU), STRATA_OK, s);
    CHECK_STATUS(strata_analyze(s, &sp.m), STRATA_OK, s);
    CHECK_STATUS(strata_factorize(s, &sp.m), STRATA_OK, s);
    CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
    double be = backward_error(spd, n_spd, x, b);
    CHECK(be < 1e-12, "ordering %d: backward error %.3g", o, be);
  }
  /* any option by name: set, read back, refused names and values leave it unchanged, and
     it reaches the analysis (natural ordering: the stats say so) */
  char text[32];
  size_t need = 0;
  CHECK_STATUS(strata_set_option(s, "ordering", "natural"), STRATA_OK, s);
  CHECK_STATUS(strata_set_option(s, "pivot_threshold", "0.25"), STRATA_OK, s);
  CHECK_STATUS(strata_get_option(s, "pivot_threshold", text, sizeof text, &need), STRATA_OK, s);
  CHECK(strcmp(text, "0.25") == 0 && need == 5, "pivot_threshold read back '%s'", text);
  CHECK_STATUS(strata_set_option(s, "pivot_threshold", "2"), STRATA_ERROR_INVALID_INPUT, s);
  CHECK(strstr(strata_last_error(s), "pivot_threshold") != NULL, "message: %s",
        strata_last_error(s));
  CHECK_STATUS(strata_get_option(s, "pivot_threshold", text, sizeof text, NULL), STRATA_OK, s);
  CHECK(strcmp(text, "0.25") == 0, "pivot_threshold after a refused value '%s'", text);
  CHECK_STATUS(strata_set_option(s, "pivot_treshold", "0.5"), STRATA_ERROR_INVALID_INPUT, s);
  CHECK(strstr(strata_last_error(s), "unknown option 'pivot_treshold'") != NULL, "message: %s",
        strata_last_error(s));
  CHECK_STATUS(strata_set_option(s, "ordering", NULL), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_get_option(s, NULL, text, sizeof text, NULL), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_get_option(s, "ordering", text, sizeof text, NULL), STRATA_OK, s);
  CHECK(strcmp(text, "natural") == 0, "ordering read back '%s'", text);
  CHECK_STATUS(strata_analyze(s, &sp.m), STRATA_OK, s);
  char doc[8192];
  CHECK_STATUS(strata_get_stats_json(s, doc, sizeof doc, NULL), STRATA_OK, s);
  CHECK(strstr(doc, "\"ordering\":\"natural\"") != NULL, "JSON ordering: %.200s", doc);
  free_sparse(&sp);

  /* the KKT matrix as general (LU) and as symmetric indefinite */
  sparse kp = to_sparse(kkt, n_kkt, STRATA_CSR, STRATA_STORAGE_FULL, STRATA_INT32, 1);
  const strata_matrix_type types[] = {STRATA_TYPE_GENERAL, STRATA_TYPE_SYMMETRIC_INDEFINITE};
  for (int t = 0; t < 2; ++t) {
    CHECK_STATUS(strata_set_ordering(s, STRATA_ORDERING_ND), STRATA_OK, s);
    CHECK_STATUS(strata_set_type(s, types[t]), STRATA_OK, s);
    CHECK_STATUS(strata_set_refinement_steps(s, 10), STRATA_OK, s);
    /* factorize does not re-analyze: the held analysis is of another matrix */
    if (t == 0) CHECK_STATUS(strata_factorize(s, &kp.m), STRATA_ERROR_INVALID_INPUT, s);
    CHECK_STATUS(strata_analyze(s, &kp.m), STRATA_OK, s);
    CHECK_STATUS(strata_factorize(s, &kp.m), STRATA_OK, s);
    CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
    double be = backward_error(kkt, n_kkt, x, b);
    CHECK(be < 1e-13, "kkt type %d: backward error %.3g", (int)types[t], be);
    strata_stats st;
    strata_get_stats(s, &st);
    CHECK(st.type == types[t], "kkt type %d: factor type %d", (int)types[t], (int)st.type);
  }
  free_sparse(&kp);

  /* the CUDA backend: works on a GPU build and machine, else NOT_SUPPORTED (or DEVICE)
   * with a message; never a crash */
  CHECK_STATUS(strata_set_type(s, STRATA_TYPE_SPD), STRATA_OK, s);
  CHECK_STATUS(strata_set_backend(s, STRATA_BACKEND_CUDA), STRATA_OK, s);
  sp = to_sparse(spd, n_spd, STRATA_CSC, STRATA_STORAGE_LOWER, STRATA_INT64, 0);
  strata_status st = strata_analyze(s, &sp.m);
  if (st == STRATA_OK) st = strata_factorize(s, &sp.m);
  CHECK(st == STRATA_OK || ((st == STRATA_ERROR_NOT_SUPPORTED || st == STRATA_ERROR_DEVICE) &&
                            strata_last_error(s)[0] != '\0'),
        "cuda backend: %s (%s)", strata_status_string(st), strata_last_error(s));
  printf("cuda backend: %s%s%s\n", strata_status_string(st), st ? ": " : "",
         st ? strata_last_error(s) : "");
  if (st == STRATA_OK) {
    CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
    double be = backward_error(spd, n_spd, x, b);
    CHECK(be < 1e-12, "cuda backend: backward error %.3g", be);
  } else {
    CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_ERROR_INVALID_STATE, s);
  }
  free_sparse(&sp);
  free(b);
  free(x);
  strata_destroy(s);
}

/* ------------------------------------------------------------------------------------ */
/* Errors                                                                                */
/* ------------------------------------------------------------------------------------ */

static void test_errors(const double* spd, const double* kkt, int n, int n_kkt) {
  strata_solver* s = NULL;
  double b[64], x[64];
  for (int i = 0; i < 64; ++i) b[i] = 1.0;

  /* NULL handles and pointers */
  CHECK_STATUS(strata_create(NULL), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_analyze(NULL, NULL), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_solve(NULL, 1, b, x), STRATA_ERROR_INVALID_INPUT, s);
  CHECK(strata_last_error(NULL)[0] != '\0', "message for a NULL solver");
  strata_destroy(NULL);
  CHECK_STATUS(strata_create(&s), STRATA_OK, s);
  CHECK_STATUS(strata_analyze(s, NULL), STRATA_ERROR_INVALID_INPUT, s);
  CHECK(strlen(strata_last_error(s)) > 0, "message after NULL matrix");

  /* wrong order of calls */
  sparse sp = to_sparse(spd, n, STRATA_CSR, STRATA_STORAGE_FULL, STRATA_INT32, 0);
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_ERROR_INVALID_STATE, s);
  CHECK(strstr(strata_last_error(s), "factorize") != NULL, "message: %s", strata_last_error(s));
  CHECK_STATUS(strata_refactorize(s, &sp.m), STRATA_ERROR_INVALID_STATE, s);
  CHECK_STATUS(strata_refactorize_values(s, 1, sp.values), STRATA_ERROR_INVALID_STATE, s);
  int64_t perm[64];
  CHECK_STATUS(strata_get_permutation(s, perm), STRATA_ERROR_INVALID_STATE, s);
  char empty[8] = "xxxxxxx";
  size_t empty_need = 0;
  CHECK_STATUS(strata_get_stats_json(s, empty, sizeof empty, &empty_need), STRATA_OK, s);
  CHECK(strcmp(empty, "{}") == 0 && empty_need == 3, "JSON before analyze: '%s' (%zu)", empty,
        empty_need);
  CHECK_STATUS(strata_get_stats_json(NULL, empty, sizeof empty, NULL), STRATA_ERROR_INVALID_INPUT,
               s);
  CHECK_STATUS(strata_analyze(s, &sp.m), STRATA_OK, s);
  CHECK(strata_last_error(s)[0] == '\0', "message cleared after success: %s", strata_last_error(s));
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_ERROR_INVALID_STATE, s);
  strata_stats st;
  CHECK_STATUS(strata_get_stats(s, &st), STRATA_OK, s);
  CHECK(st.analyzed == 1 && st.factorized == 0, "flags after analyze only");
  char analysis_json[4096];
  CHECK_STATUS(strata_get_stats_json(s, analysis_json, sizeof analysis_json, NULL), STRATA_OK, s);
  CHECK(strstr(analysis_json, "\"nnz_l\":") && !strstr(analysis_json, "\"factor\":"),
        "JSON after analyze only: %.120s", analysis_json);
  CHECK_STATUS(strata_factorize(s, &sp.m), STRATA_OK, s);
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
  CHECK_STATUS(strata_solve(s, -1, b, x), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_solve(s, 1, NULL, x), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_solve(s, 0, NULL, NULL), STRATA_OK, s);

  /* NaN in the right-hand side */
  b[3] = NAN;
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_ERROR_INVALID_INPUT, s);
  b[3] = 1.0;

  /* NaN in the values: rejected, the previous factor stays usable */
  sparse bad = to_sparse(spd, n, STRATA_CSR, STRATA_STORAGE_FULL, STRATA_INT32, 0);
  bad.values[2] = NAN;
  CHECK_STATUS(strata_refactorize(s, &bad.m), STRATA_ERROR_INVALID_INPUT, s);
  CHECK(strstr(strata_last_error(s), "finite") != NULL, "NaN message: %s", strata_last_error(s));
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
  bad.values[2] = INFINITY;
  CHECK_STATUS(strata_factorize(s, &bad.m), STRATA_ERROR_INVALID_INPUT, s);
  free_sparse(&bad);

  /* a different pattern at refactorize */
  double* a2 = malloc((size_t)n * n * sizeof(double));
  memcpy(a2, spd, (size_t)n * n * sizeof(double));
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      if (a2[i * n + j] == 0.0) {
        a2[i * n + j] = a2[j * n + i] = 1e-3;
        i = j = n; /* one pair */
      }
  sparse other = to_sparse(a2, n, STRATA_CSR, STRATA_STORAGE_FULL, STRATA_INT32, 0);
  CHECK_STATUS(strata_refactorize(s, &other.m), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
  free_sparse(&other);
  free(a2);

  /* values missing at factorize (pattern-only analysis is allowed) */
  strata_matrix pattern = sp.m;
  pattern.values = NULL;
  CHECK_STATUS(strata_refactorize(s, &pattern), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_analyze(s, &pattern), STRATA_OK, s);
  CHECK_STATUS(strata_factorize(s, &sp.m), STRATA_OK, s);
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);

  /* non-square */
  strata_matrix rect = sp.m;
  rect.n_cols = n + 1; /* CSR: n rows of column indices < n, n+1 columns */
  CHECK_STATUS(strata_analyze(s, &rect), STRATA_ERROR_INVALID_INPUT, s);
  CHECK(strstr(strata_last_error(s), "square") != NULL, "non-square message: %s",
        strata_last_error(s));
  /* a failed analyze leaves no analysis */
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_ERROR_INVALID_STATE, s);
  CHECK_STATUS(strata_refactorize(s, &sp.m), STRATA_ERROR_INVALID_STATE, s);

  /* malformed arrays */
  strata_matrix m = sp.m;
  m.index_base = 1; /* offsets[0] is 0, not 1 */
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  m = sp.m;
  m.index_base = 2;
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  m = sp.m;
  m.n_rows = -1;
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  m = sp.m;
  m.layout = (strata_layout)7;
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  m = sp.m;
  m.index_type = (strata_index_type)9;
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  m = sp.m;
  m.offsets = NULL;
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  m = sp.m;
  m.indices = NULL;
  CHECK_STATUS(strata_analyze(s, &m), STRATA_ERROR_INVALID_INPUT, s);
  {
    sparse oob = to_sparse(spd, n, STRATA_CSC, STRATA_STORAGE_FULL, STRATA_INT64, 0);
    ((int64_t*)oob.indices)[1] = n; /* row index out of range */
    CHECK_STATUS(strata_analyze(s, &oob.m), STRATA_ERROR_INVALID_INPUT, s);
    CHECK(strstr(strata_last_error(s), "range") != NULL, "out of range message: %s",
          strata_last_error(s));
    ((int64_t*)oob.indices)[1] = 0;
    ((int64_t*)oob.offsets)[2] = ((int64_t*)oob.offsets)[1] - 1; /* decreasing offsets */
    CHECK_STATUS(strata_analyze(s, &oob.m), STRATA_ERROR_INVALID_INPUT, s);
    free_sparse(&oob);
  }
  {
    /* full matrix declared lower: entries above the diagonal */
    sparse wrong = to_sparse(spd, n, STRATA_CSR, STRATA_STORAGE_FULL, STRATA_INT32, 0);
    wrong.m.storage = STRATA_STORAGE_LOWER;
    CHECK_STATUS(strata_analyze(s, &wrong.m), STRATA_ERROR_INVALID_INPUT, s);
    free_sparse(&wrong);
  }

  /* bad option values leave the option unchanged */
  CHECK_STATUS(strata_set_type(s, (strata_matrix_type)42), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_ordering(s, (strata_ordering)-1), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_backend(s, (strata_backend)5), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_max_block_size(s, -1), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_num_threads(s, -2), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_refinement_steps(s, -1), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_refinement_tolerance(s, NAN), STRATA_ERROR_INVALID_INPUT, s);
  CHECK_STATUS(strata_set_type(NULL, STRATA_TYPE_SPD), STRATA_ERROR_INVALID_INPUT, s);

  /* an indefinite matrix declared SPD: NOT_POSITIVE_DEFINITE, then no factor */
  sparse kp = to_sparse(kkt, n_kkt, STRATA_CSC, STRATA_STORAGE_LOWER, STRATA_INT32, 0);
  CHECK_STATUS(strata_set_type(s, STRATA_TYPE_SPD), STRATA_OK, s);
  CHECK_STATUS(strata_analyze(s, &kp.m), STRATA_OK, s);
  CHECK_STATUS(strata_factorize(s, &kp.m), STRATA_ERROR_NOT_POSITIVE_DEFINITE, s);
  CHECK(strstr(strata_last_error(s), "positive definite") != NULL, "message: %s",
        strata_last_error(s));
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_ERROR_INVALID_STATE, s);
  CHECK_STATUS(strata_get_stats(s, &st), STRATA_OK, s);
  CHECK(st.factorized == 0, "no factor after a failed factorization");
  /* recovers with the right type */
  CHECK_STATUS(strata_set_type(s, STRATA_TYPE_SYMMETRIC_INDEFINITE), STRATA_OK, s);
  CHECK_STATUS(strata_analyze(s, &kp.m), STRATA_OK, s);
  CHECK_STATUS(strata_factorize(s, &kp.m), STRATA_OK, s);
  CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
  CHECK(backward_error(kkt, n_kkt, x, b) < 1e-13, "recovered solve");
  free_sparse(&kp);

  /* an empty matrix */
  {
    int32_t off0 = 0;
    strata_matrix e = {0, 0, STRATA_CSC, STRATA_STORAGE_FULL, STRATA_INT32, 0, &off0, NULL, NULL};
    CHECK_STATUS(strata_set_type(s, STRATA_TYPE_AUTO), STRATA_OK, s);
    CHECK_STATUS(strata_analyze(s, &e), STRATA_OK, s);
    CHECK_STATUS(strata_factorize(s, &e), STRATA_OK, s);
    CHECK_STATUS(strata_solve(s, 1, b, x), STRATA_OK, s);
  }

  free_sparse(&sp);
  strata_destroy(s);
  CHECK(strcmp(strata_status_string(STRATA_ERROR_DEVICE), "STRATA_ERROR_DEVICE") == 0,
        "status string");
}

int main(void) {
  const int n = 40, nh = 30, m = 10;
  double* spd = make_spd(n);
  double* kkt = make_kkt(nh, m);
  double* gen = make_general(n);
  printf("strata %s C interface\n", strata_version());

  run_all_conventions("spd", spd, n, 1, STRATA_TYPE_SPD, 0);
  run_all_conventions("kkt", kkt, nh + m, 1, STRATA_TYPE_SYMMETRIC_INDEFINITE, m);
  run_all_conventions("general", gen, n, 0, STRATA_TYPE_GENERAL, 0);
  test_options(spd, kkt, n, nh + m);
  test_errors(spd, kkt, n, nh + m);

  free(spd);
  free(kkt);
  free(gen);
  printf("%d passed, %d failed\n", g_passed, g_failed);
  return g_failed == 0 ? 0 : 1;
}
