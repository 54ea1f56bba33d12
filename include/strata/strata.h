/* strata — C interface (C99) of the sparse direct solver.
 *
 * The same four phases as the C++ API (strata/solver.hpp), on an opaque handle:
 *
 *   strata_solver* s = NULL;
 *   strata_create(&s);
 *   strata_set_type(s, STRATA_TYPE_SPD);            // options: before strata_analyze
 *   strata_matrix A = {...};                        // CSR or CSC view of the caller's arrays
 *   strata_analyze(s, &A);                          // ordering, assembly tree, schedule
 *   strata_factorize(s, &A);                        // values
 *   strata_solve(s, 1, b, x);                       // x = A⁻¹ b with iterative refinement
 *   strata_refactorize(s, &A2);                     // same pattern, new values
 *   strata_refactorize_values(s, nnz, values);      // the same with the values alone
 *   strata_stats st; strata_get_stats(s, &st);      // nnz(L), flops, inertia, ...
 *   strata_destroy(s);
 *
 * Errors: every function returns a strata_status. STRATA_OK (0) is success; any other
 * value leaves the solver usable and strata_last_error(s) gives a message naming the
 * problem. A factorize rejected for its input (INVALID_INPUT) keeps the previous factor;
 * one that fails while factoring leaves no valid factor, so a later solve returns
 * STRATA_ERROR_INVALID_STATE. No C++ exception crosses this interface.
 *
 * Threads: a solver is not thread-safe; use one solver per thread. Different solvers
 * may be used concurrently.
 *
 * Method: multifrontal Cholesky (LLᵀ), LDLᵀ with Bunch–Kaufman pivots, or LU on the
 * pattern of A+Aᵀ, on a level-scheduled assembly tree (Jung & Bae 2018).
 */
#ifndef STRATA_STRATA_H
#define STRATA_STRATA_H

#include <stddef.h>
#include <stdint.h>

#ifdef __cplusplus
extern "C" {
#endif

/* ---------------------------------------------------------------------------------- */
/* Status codes                                                                        */
/* ---------------------------------------------------------------------------------- */

/** Result of every call. */
typedef enum strata_status {
  STRATA_OK = 0,
  /** Malformed input: non-square matrix, index out of range, NaN/Inf value, NULL
   *  pointer, bad enum value, wrong index base, a pattern that differs from the
   *  analyzed one, a right-hand side with a NaN. */
  STRATA_ERROR_INVALID_INPUT = 1,
  /** Valid request this build or machine cannot do (e.g. the CUDA backend in a build
   *  without CUDA or on a machine without a GPU). */
  STRATA_ERROR_NOT_SUPPORTED = 2,
  /** An allocation failed. */
  STRATA_ERROR_OUT_OF_MEMORY = 3,
  /** A CUDA, cuBLAS or cuSOLVER call failed. */
  STRATA_ERROR_DEVICE = 4,
  /** STRATA_TYPE_SPD was requested and Cholesky met a pivot that is not positive. */
  STRATA_ERROR_NOT_POSITIVE_DEFINITE = 5,
  /** Calls in the wrong order: solve before factorize, refactorize before analyze,
   *  the permutation before analyze. */
  STRATA_ERROR_INVALID_STATE = 6,
  /** Anything else (a bug: please report the message). */
  STRATA_ERROR_INTERNAL = 7
} strata_status;

/** Static name of a status code, e.g. "STRATA_ERROR_INVALID_INPUT". Never NULL. */
const char* strata_status_string(strata_status status);

/** Version of the library, e.g. "0.1.0". Never NULL. */
const char* strata_version(void);

/* ---------------------------------------------------------------------------------- */
/* Solver handle                                                                       */
/* ---------------------------------------------------------------------------------- */

/** Opaque solver: options, the analysis of one pattern, the factor, statistics. */
typedef struct strata_solver strata_solver;

/** Creates a solver with default options and stores it in *solver.
 *  Errors: INVALID_INPUT (solver is NULL), OUT_OF_MEMORY (*solver is set to NULL). */
strata_status strata_create(strata_solver** solver);

/** Frees the solver and everything it holds. NULL is allowed (no-op). */
void strata_destroy(strata_solver* solver);

/** Message of the last failed call on this solver ("" when the last call succeeded).
 *  The string belongs to the solver and is valid until its next call. Never NULL
 *  (for a NULL solver: a static message). */
const char* strata_last_error(const strata_solver* solver);

/* ---------------------------------------------------------------------------------- */
/* Options                                                                             */
/* ---------------------------------------------------------------------------------- */

/** Factorization type. */
typedef enum strata_matrix_type {
  STRATA_TYPE_AUTO = 0,                 /**< symmetric: try Cholesky, else LDLᵀ; else LU */
  STRATA_TYPE_SPD = 1,                  /**< Cholesky LLᵀ */
  STRATA_TYPE_SYMMETRIC_INDEFINITE = 2, /**< LDLᵀ with 1×1 and 2×2 pivots */
  STRATA_TYPE_GENERAL = 3               /**< LU on the pattern of A+Aᵀ */
} strata_matrix_type;

/** Fill-reducing ordering. */
typedef enum strata_ordering {
  STRATA_ORDERING_ND = 0,      /**< strata's nested dissection (default) */
  STRATA_ORDERING_METIS = 1,   /**< METIS_NodeND on the whole graph */
  STRATA_ORDERING_AMD = 2,     /**< approximate minimum degree */
  STRATA_ORDERING_NATURAL = 3, /**< identity permutation */
  STRATA_ORDERING_AUTO = 4     /**< AMD when its factor is cheap, else nested dissection
                                    (CHOLMOD's rule; strata::OrderingMethod::automatic) */
} strata_ordering;

/** Where the numeric phases run. */
typedef enum strata_backend {
  STRATA_BACKEND_CPU = 0,  /**< BLAS/LAPACK on host threads (default) */
  STRATA_BACKEND_CUDA = 1, /**< a CUDA GPU; NOT_SUPPORTED without CUDA or a GPU */
  STRATA_BACKEND_AUTO = 2  /**< the GPU when the build and the machine have one (and the factor
                               needs at least the option gpu_min_flops flops), else CPU */
} strata_backend;

/* Options are read by strata_analyze: an option set after strata_analyze takes effect
 * at the next strata_analyze (the current analysis and factor are kept until then).
 * Every setter returns INVALID_INPUT for a NULL solver or a value out of range and then
 * leaves the option unchanged. */

/** Factorization type (default STRATA_TYPE_AUTO). */
strata_status strata_set_type(strata_solver* solver, strata_matrix_type type);
/** Fill-reducing ordering (default STRATA_ORDERING_ND). */
strata_status strata_set_ordering(strata_solver* solver, strata_ordering ordering);
/** Backend (default STRATA_BACKEND_CPU). */
strata_status strata_set_backend(strata_solver* solver, strata_backend backend);
/** Most pivot columns in one front; larger separators are split into a chain of
 *  blocks (≥ 0; default 0: 4096 for Cholesky on the CUDA backend, else 1024). */
strata_status strata_set_max_block_size(strata_solver* solver, int64_t max_block_size);
/** Host threads of the CPU backend (≥ 0; 0 = all hardware threads, the default). */
strata_status strata_set_num_threads(strata_solver* solver, int num_threads);
/** Most iterative refinement steps after the first solve (≥ 0; 0 disables; default
 *  10). */
strata_status strata_set_refinement_steps(strata_solver* solver, int max_steps);
/** Refinement stops at this backward error (≥ 0; default 1e-15). */
strata_status strata_set_refinement_tolerance(strata_solver* solver, double tolerance);
/** Device memory budget in bytes for the memory plan (0 = the whole device; default 0). */
strata_status strata_set_device_memory_limit(strata_solver* solver, uint64_t bytes);
/** Any option by its name and text, as the C++ API's strata::set_option reads them:
 *  the names of strata::Options' fields ("ordering", "pivot_threshold", "pivoting",
 *  "num_gpus", ...; "device" for "backend"), values as text ("amd", "0.1", "true").
 *  INVALID_INPUT for a NULL argument, an unknown name, a value that does not parse or is
 *  out of range (the message names the option); the option is then unchanged. */
strata_status strata_set_option(strata_solver* solver, const char* name, const char* value);
/** The text of the option called `name`, as strata_set_option reads it, NUL-terminated
 *  into buffer[0..size) and cut to fit (as snprintf; *needed, when not NULL, gets the
 *  bytes the whole text needs). INVALID_INPUT for a NULL solver or name, an unknown name,
 *  or a NULL buffer with size > 0. */
strata_status strata_get_option(const strata_solver* solver, const char* name, char* buffer,
                                size_t size, size_t* needed);

/* ---------------------------------------------------------------------------------- */
/* Matrices                                                                            */
/* ---------------------------------------------------------------------------------- */

/** Compressed layout. */
typedef enum strata_layout {
  STRATA_CSR = 0, /**< compressed rows: offsets has n_rows+1 entries, indices are columns */
  STRATA_CSC = 1  /**< compressed columns: offsets has n_cols+1 entries, indices are rows */
} strata_layout;

/** Which entries of a symmetric matrix are stored. */
typedef enum strata_storage {
  STRATA_STORAGE_FULL = 0,  /**< every entry (the only choice for unsymmetric matrices) */
  STRATA_STORAGE_LOWER = 1, /**< lower triangle with diagonal; the upper is implied */
  STRATA_STORAGE_UPPER = 2  /**< upper triangle with diagonal; the lower is implied */
} strata_storage;

/** Integer type of `offsets` and `indices`. */
typedef enum strata_index_type {
  STRATA_INT32 = 0, /**< int32_t */
  STRATA_INT64 = 1  /**< int64_t */
} strata_index_type;

/** A read-only view of a sparse matrix held by the caller (strata copies what it needs:
 *  the arrays may be freed when the call returns).
 *
 *  offsets: n_major+1 entries (n_major = n_rows for CSR, n_cols for CSC), non-decreasing,
 *           offsets[0] == index_base; vector j holds entries offsets[j]-index_base ..
 *           offsets[j+1]-index_base-1 of indices/values.
 *  indices: nnz = offsets[n_major]-index_base entries, each in [index_base,
 *           n_minor+index_base); unsorted and repeated indices are allowed (duplicates
 *           are summed).
 *  values:  nnz doubles, all finite, or NULL for a pattern-only matrix (allowed by
 *           strata_analyze only; the analysis then cannot use values for scaling).
 *  Storage lower/upper must hold no entry of the other triangle. */
typedef struct strata_matrix {
  int64_t n_rows;
  int64_t n_cols;
  strata_layout layout;
  strata_storage storage;
  strata_index_type index_type;
  int index_base; /**< 0 (C) or 1 (Fortran) */
  const void* offsets;
  const void* indices;
  const double* values;
} strata_matrix;

/* ---------------------------------------------------------------------------------- */
/* Phases                                                                              */
/* ---------------------------------------------------------------------------------- */

/** Analysis (pattern; values, when given, for scaling and type detection): validates A
 *  (square, indices in range, finite values), resolves the matrix type, computes the
 *  ordering, the assembly tree, the level schedule and the memory plan. Discards any
 *  previous analysis and factor. Errors: INVALID_INPUT, NOT_SUPPORTED, OUT_OF_MEMORY. */
strata_status strata_analyze(strata_solver* solver, const strata_matrix* a);

/** Numeric factorization of A (values required) with the analyzed pattern; analyzes A
 *  first when strata_analyze was not called. Errors: INVALID_INPUT (NaN/Inf, changed
 *  pattern), NOT_POSITIVE_DEFINITE (STRATA_TYPE_SPD and a pivot ≤ 0), OUT_OF_MEMORY,
 *  DEVICE, NOT_SUPPORTED. Tiny pivots are perturbed and counted, not errors. */
strata_status strata_factorize(strata_solver* solver, const strata_matrix* a);

/** Factorization of new values on the analyzed pattern, reusing the analysis and all
 *  workspace. Errors: INVALID_STATE (no analysis), and those of strata_factorize. */
strata_status strata_refactorize(strata_solver* solver, const strata_matrix* a);

/** strata_refactorize for values alone, as cuDSS's cudssMatrixSetValues: values[p] is the
 *  value of entry p of the strata_matrix given to strata_analyze (its values array: the
 *  same layout, storage and entry order; nnz of them). The pattern is not read again.
 *  `values` may lie in GPU memory (cudaMalloc) or page-locked host memory, which the CUDA
 *  backend copies to the device directly (Solver::refactorize). Errors: INVALID_STATE
 *  (no analysis), INVALID_INPUT (values NULL, nnz not that matrix's number of entries, a
 *  value NaN/Inf), and those of strata_factorize. */
strata_status strata_refactorize_values(strata_solver* solver, int64_t nnz, const double* values);

/** Solves A X = B for nrhs ≥ 0 right-hand sides. b and x are column-major n×nrhs
 *  arrays with leading dimension n (n = strata_size). x may equal b (in place);
 *  otherwise they must not overlap. Iterative refinement follows the options. b and x may
 *  lie in GPU memory (cudaMalloc), which the CUDA backend reads and writes there when the
 *  factor stays on that GPU (Solver::solve).
 *  Errors: INVALID_STATE (no valid factor), INVALID_INPUT (NULL array with nrhs > 0,
 *  nrhs < 0, a NaN/Inf in b). */
strata_status strata_solve(strata_solver* solver, int64_t nrhs, const double* b, double* x);

/** Order n of the analyzed matrix (0 before strata_analyze). */
strata_status strata_size(const strata_solver* solver, int64_t* n);

/* ---------------------------------------------------------------------------------- */
/* Statistics                                                                          */
/* ---------------------------------------------------------------------------------- */

/** Statistics of the last call of each phase. Fields of a phase that has not run are 0;
 *  `analyzed` / `factorized` / `solved` say which phases have. Units: seconds, flops,
 *  bytes. */
typedef struct strata_stats {
  /* analysis */
  int analyzed;                     /**< 1 after a successful strata_analyze */
  int64_t n;                        /**< order of A */
  int64_t nnz_a;                    /**< entries of A, both triangles */
  int64_t nnz_l;                    /**< exact nnz(L), diagonal included */
  int64_t nnz_l_fronts;             /**< entries of L as stored in fronts (with padding) */
  double factor_flops;              /**< flops of a Cholesky of the fronts (LU: about 2×) */
  int64_t n_fronts;                 /**< fronts in the assembly tree */
  int64_t largest_front_rows;       /**< rows of the largest front */
  int64_t tree_height;              /**< levels of the assembly tree */
  uint64_t peak_working_bytes;      /**< in-core multifrontal working memory peak */
  uint64_t factor_bytes;            /**< bytes of the factor */
  int64_t n_batches;                /**< batches of the memory plan */
  strata_matrix_type analysis_type; /**< type resolved by the analysis (AUTO: decided
                                         by the factorization) */
  double analysis_seconds;
  /* factorization */
  int factorized;          /**< 1 while a valid factor is held */
  strata_matrix_type type; /**< factorization computed (SPD, SYMMETRIC_INDEFINITE or
                                GENERAL) */
  int backend_is_cuda;     /**< 1 when the factor was computed on a GPU */
  double factor_seconds;
  double factor_gflops;
  int64_t perturbed_pivots;  /**< tiny pivots replaced by ±ε‖A‖ (static pivoting) */
  int64_t two_by_two_pivots; /**< LDLᵀ: 2×2 pivot blocks */
  int64_t inertia_positive;  /**< symmetric: signs of the eigenvalues of D */
  int64_t inertia_negative;
  int64_t inertia_zero;
  double log_abs_determinant; /**< log|det A| */
  int determinant_sign;       /**< sign of det A: -1, 0 or 1 */
  int inertia_valid;          /**< 1 when inertia and determinant are A's; 0 when static
                                   pivoting perturbed pivots (they are then those of the
                                   nearby matrix factored, not A's) */
  /* solve */
  int solved; /**< 1 after a successful strata_solve */
  double solve_seconds;
  int refinement_steps; /**< refinement steps of the last solve */
  int gmres_iterations; /**< GMRES iterations after stalled refinement */
  double backward_error; /**< max over columns of ‖b−Ax‖∞/(‖A‖∞‖x‖∞+‖b‖∞) */
  int refinement_converged;    /**< 1 when the refinement tolerance, or the rounding floor
                                    when larger, was reached */
  double backward_error_floor; /**< (m+1)·u, m the most entries in a row of A */
  double condition_lower_bound; /**< max ‖A‖∞‖x‖∞/‖b‖∞ ≤ κ∞(A); ≥ ~1e15: A singular
                                     to working precision */
  double relative_residual; /**< with perturbed pivots: max ‖b−Ax‖∞/‖b‖∞, at least b's
                                 distance from A's range (0 otherwise) */
  int singular_consistent;  /**< 1 when pivots were perturbed (A numerically singular), the
                                 solve converged and relative_residual ≤ √u: x is one of
                                 A's solutions */
} strata_stats;

/** Copies the statistics into *stats. Errors: INVALID_INPUT (NULL pointer). */
strata_status strata_get_stats(const strata_solver* solver, strata_stats* stats);

/** The statistics as JSON text (UTF-8, NUL-terminated): the document `strata solve --json`
 *  prints and Python's Solver.stats returns, with the same names (the analysis's figures
 *  at the top level, "factor" after a factorization, "solve" after a solve; "{}" before
 *  an analysis). As snprintf: at most `size` bytes are written to `buffer` (NULL allowed
 *  when size is 0), cut and NUL-terminated when it is too small, and *needed (when not
 *  NULL) gets the bytes the whole text needs, its NUL included. Errors: INVALID_INPUT
 *  (NULL solver, or NULL buffer with size > 0). */
strata_status strata_get_stats_json(const strata_solver* solver, char* buffer, size_t size,
                                    size_t* needed);

/** Copies the fill-reducing permutation (new to old, 0-based; perm[k] is the original
 *  index of the k-th pivot) into perm[0..n). Errors: INVALID_STATE before analyze,
 *  INVALID_INPUT (NULL pointer). */
strata_status strata_get_permutation(const strata_solver* solver, int64_t* perm);

#ifdef __cplusplus
} /* extern "C" */
#endif

#endif /* STRATA_STRATA_H */
