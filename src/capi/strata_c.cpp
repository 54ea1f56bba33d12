// strata — the C interface (include/strata/strata.h) over the C++ Solver.
//
// The handle owns the Options and a strata::Solver created by every strata_analyze (the
// C++ Solver reads its options at construction). Every entry point catches every
// exception and turns it into a status code and a message kept in the handle.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <exception>
#include <memory>
#include <new>
#include <span>
#include <string>
#include <vector>

#include "core/stats_json.hpp"
#include "numeric/factor.hpp"
#include "strata/strata.h"
#include "strata/strata.hpp"

struct strata_solver {
  strata::Options options;
  std::unique_ptr<strata::Solver> solver;  // null until the first (successful) analyze
  bool analyzed = false;
  bool factorized = false;
  bool solved = false;
  mutable std::string last_error;  // also set by the const getters
};

namespace {

using strata::index_t;

// Runs f, mapping exceptions to status codes; sets the solver's message (or clears it).
template <class F>
strata_status guarded(const strata_solver* s, F&& f) {
  strata_status st = STRATA_OK;
  std::string msg;
  try {
    f();
  } catch (const strata::InvalidInput& e) {
    st = STRATA_ERROR_INVALID_INPUT;
    msg = e.what();
  } catch (const strata::NotSupported& e) {
    st = STRATA_ERROR_NOT_SUPPORTED;
    msg = e.what();
  } catch (const strata::OutOfMemory& e) {
    st = STRATA_ERROR_OUT_OF_MEMORY;
    msg = e.what();
  } catch (const strata::DeviceError& e) {
    st = STRATA_ERROR_DEVICE;
    msg = e.what();
  } catch (const strata::NotPositiveDefinite& e) {
    st = STRATA_ERROR_NOT_POSITIVE_DEFINITE;
    msg = e.what();
  } catch (const strata::InvalidState& e) {
    st = STRATA_ERROR_INVALID_STATE;
    msg = e.what();
  } catch (const strata::InternalError& e) {
    st = STRATA_ERROR_INTERNAL;
    msg = e.what();
  } catch (const std::bad_alloc&) {
    st = STRATA_ERROR_OUT_OF_MEMORY;
    msg = "out of memory";
  } catch (const std::exception& e) {
    st = STRATA_ERROR_INTERNAL;
    msg = std::string("internal error: ") + e.what();
  } catch (...) {
    st = STRATA_ERROR_INTERNAL;
    msg = "internal error: unknown exception";
  }
  try {
    s->last_error = std::move(msg);
  } catch (...) {  // cannot store the message: keep the code
  }
  return st;
}

// Converts one index array entry to index_t.
template <class I>
index_t load(const void* p, index_t k) {
  return static_cast<index_t>(static_cast<const I*>(p)[k]);
}

template <class I>
strata::SparseMatrix convert_typed(const strata_matrix& m, bool need_values) {
  strata::SparseMatrix a;
  a.n_rows = m.n_rows;
  a.n_cols = m.n_cols;
  a.layout = m.layout == STRATA_CSR ? strata::Layout::csr : strata::Layout::csc;
  a.storage = m.storage == STRATA_STORAGE_LOWER   ? strata::Storage::lower
              : m.storage == STRATA_STORAGE_UPPER ? strata::Storage::upper
                                                  : strata::Storage::full;
  const index_t base = m.index_base;
  const index_t nmaj = a.n_major();
  const char* what = m.layout == STRATA_CSR ? "row" : "column";
  a.offsets.resize(static_cast<std::size_t>(nmaj) + 1);
  for (index_t j = 0; j <= nmaj; ++j) a.offsets[j] = load<I>(m.offsets, j) - base;
  if (a.offsets[0] != 0)
    throw strata::InvalidInput("offsets[0] is " + std::to_string(a.offsets[0] + base) +
                               ", expected the index base " + std::to_string(base));
  for (index_t j = 0; j < nmaj; ++j)
    if (a.offsets[j + 1] < a.offsets[j])
      throw strata::InvalidInput("offsets decrease at " + std::string(what) + " " +
                                 std::to_string(j) + " (offsets[" + std::to_string(j + 1) +
                                 "] < offsets[" + std::to_string(j) + "])");
  const index_t nnz = a.offsets[nmaj];
  if (nnz > 0 && m.indices == nullptr)
    throw strata::InvalidInput("indices is NULL but the matrix has " + std::to_string(nnz) +
                               " entries");
  a.indices.resize(static_cast<std::size_t>(nnz));
  for (index_t p = 0; p < nnz; ++p) a.indices[p] = load<I>(m.indices, p) - base;
  if (m.values == nullptr) {
    if (need_values && nnz > 0)
      throw strata::InvalidInput("values is NULL: this phase needs values");
  } else {
    a.values.assign(m.values, m.values + nnz);
  }
  strata::validate(a);  // ranges, finite values, triangle of lower/upper storage
  return a;
}

// The value of an enum object that came from C. A C enum object may hold any int; in C++
// loading a value that is not an enumerator is undefined behaviour (UBSan's enum check:
// "load of value 7, which is not a valid value for type 'strata_layout'", found by the
// sanitizer build on the C API test), so the bytes are copied out as an int instead.
template <class E>
int enum_value(const E& field) {
  static_assert(sizeof(E) == sizeof(int), "C enums are int-sized");
  int v = 0;
  std::memcpy(&v, &field, sizeof v);
  return v;
}

strata::SparseMatrix convert(const strata_matrix* m, bool need_values) {
  if (m == nullptr) throw strata::InvalidInput("matrix is NULL");
  if (m->n_rows < 0 || m->n_cols < 0)
    throw strata::InvalidInput("matrix has negative dimensions " + std::to_string(m->n_rows) + "x" +
                               std::to_string(m->n_cols));
  const int layout = enum_value(m->layout), storage = enum_value(m->storage),
            index_type = enum_value(m->index_type);
  if (layout != STRATA_CSR && layout != STRATA_CSC)
    throw strata::InvalidInput("layout " + std::to_string(layout) +
                               " is neither STRATA_CSR nor STRATA_CSC");
  if (storage != STRATA_STORAGE_FULL && storage != STRATA_STORAGE_LOWER &&
      storage != STRATA_STORAGE_UPPER)
    throw strata::InvalidInput("storage " + std::to_string(storage) +
                               " is not a strata_storage value");
  if (index_type != STRATA_INT32 && index_type != STRATA_INT64)
    throw strata::InvalidInput("index_type " + std::to_string(index_type) +
                               " is neither STRATA_INT32 nor STRATA_INT64");
  if (m->index_base != 0 && m->index_base != 1)
    throw strata::InvalidInput("index_base is " + std::to_string(m->index_base) +
                               ", must be 0 or 1");
  if (m->offsets == nullptr) throw strata::InvalidInput("offsets is NULL");
  return m->index_type == STRATA_INT32 ? convert_typed<std::int32_t>(*m, need_values)
                                       : convert_typed<std::int64_t>(*m, need_values);
}

void do_analyze(strata_solver* s, const strata::SparseMatrix& a) {
  // a failed analysis leaves no analysis behind (not the previous one)
  s->analyzed = s->factorized = s->solved = false;
  s->solver.reset();
  auto fresh = std::make_unique<strata::Solver>(s->options);
  fresh->analyze(a);
  s->solver = std::move(fresh);
  s->analyzed = true;
}

// factorize / refactorize: INVALID_INPUT keeps the previous factor (the C++ Solver
// validates before touching it); any other failure leaves none.
template <class F>
void factor_phase(strata_solver* s, F&& f) {
  try {
    f();
  } catch (const strata::InvalidInput&) {
    throw;
  } catch (...) {
    s->factorized = s->solved = false;
    throw;
  }
  s->factorized = true;
  s->solved = false;
}

constexpr const char* kNullSolver = "strata: the solver handle is NULL";

// Text out as snprintf: at most `size` bytes (cut, NUL-terminated), *needed the whole.
void copy_text(const std::string& text, char* buffer, std::size_t size, std::size_t* needed) {
  if (needed) *needed = text.size() + 1;
  if (size == 0) return;
  const std::size_t n = std::min(size - 1, text.size());
  std::memcpy(buffer, text.data(), n);
  buffer[n] = '\0';
}

// Sets one option on a copy, checks the copy with the vocabulary every interface shares
// (strata::validate: the same ranges and messages as the C++ API, the CLI and Python) and
// keeps it only when it passes: a refused value leaves the solver's options unchanged.
template <class F>
void set_checked(strata_solver* s, F&& set) {
  strata::Options o = s->options;
  set(o);
  strata::validate(o);
  s->options = std::move(o);
}

}  // namespace

extern "C" {

const char* strata_status_string(strata_status status) {
  switch (status) {
    case STRATA_OK:
      return "STRATA_OK";
    case STRATA_ERROR_INVALID_INPUT:
      return "STRATA_ERROR_INVALID_INPUT";
    case STRATA_ERROR_NOT_SUPPORTED:
      return "STRATA_ERROR_NOT_SUPPORTED";
    case STRATA_ERROR_OUT_OF_MEMORY:
      return "STRATA_ERROR_OUT_OF_MEMORY";
    case STRATA_ERROR_DEVICE:
      return "STRATA_ERROR_DEVICE";
    case STRATA_ERROR_NOT_POSITIVE_DEFINITE:
      return "STRATA_ERROR_NOT_POSITIVE_DEFINITE";
    case STRATA_ERROR_INVALID_STATE:
      return "STRATA_ERROR_INVALID_STATE";
    case STRATA_ERROR_INTERNAL:
      return "STRATA_ERROR_INTERNAL";
  }
  return "STRATA_ERROR_UNKNOWN";
}

const char* strata_version(void) { return STRATA_VERSION; }

strata_status strata_create(strata_solver** solver) {
  if (solver == nullptr) return STRATA_ERROR_INVALID_INPUT;
  *solver = new (std::nothrow) strata_solver();
  return *solver ? STRATA_OK : STRATA_ERROR_OUT_OF_MEMORY;
}

void strata_destroy(strata_solver* solver) { delete solver; }

const char* strata_last_error(const strata_solver* solver) {
  return solver ? solver->last_error.c_str() : kNullSolver;
}

#define STRATA_CHECK_SOLVER(s) \
  if ((s) == nullptr) return STRATA_ERROR_INVALID_INPUT

strata_status strata_set_type(strata_solver* s, strata_matrix_type type) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    switch (enum_value(type)) {
      case STRATA_TYPE_AUTO:
        s->options.type = strata::MatrixType::automatic;
        return;
      case STRATA_TYPE_SPD:
        s->options.type = strata::MatrixType::spd;
        return;
      case STRATA_TYPE_SYMMETRIC_INDEFINITE:
        s->options.type = strata::MatrixType::symmetric_indefinite;
        return;
      case STRATA_TYPE_GENERAL:
        s->options.type = strata::MatrixType::general;
        return;
    }
    throw strata::InvalidInput("matrix type " + std::to_string(enum_value(type)) +
                               " is not a strata_matrix_type value");
  });
}

strata_status strata_set_ordering(strata_solver* s, strata_ordering ordering) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    switch (enum_value(ordering)) {
      case STRATA_ORDERING_ND:
        s->options.ordering = strata::OrderingMethod::nested_dissection;
        return;
      case STRATA_ORDERING_METIS:
        s->options.ordering = strata::OrderingMethod::metis;
        return;
      case STRATA_ORDERING_AMD:
        s->options.ordering = strata::OrderingMethod::amd;
        return;
      case STRATA_ORDERING_NATURAL:
        s->options.ordering = strata::OrderingMethod::natural;
        return;
      case STRATA_ORDERING_AUTO:
        s->options.ordering = strata::OrderingMethod::automatic;
        return;
    }
    throw strata::InvalidInput("ordering " + std::to_string(enum_value(ordering)) +
                               " is not a strata_ordering value");
  });
}

strata_status strata_set_backend(strata_solver* s, strata_backend backend) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    switch (enum_value(backend)) {
      case STRATA_BACKEND_CPU:
        s->options.backend = strata::Backend::cpu;
        return;
      case STRATA_BACKEND_CUDA:
        s->options.backend = strata::Backend::cuda;
        return;
      case STRATA_BACKEND_AUTO:
        s->options.backend = strata::Backend::automatic;
        return;
    }
    throw strata::InvalidInput("backend " + std::to_string(enum_value(backend)) +
                               " is not a strata_backend value");
  });
}

strata_status strata_set_max_block_size(strata_solver* s, int64_t max_block_size) {
  STRATA_CHECK_SOLVER(s);
  return guarded(
      s, [&] { set_checked(s, [&](strata::Options& o) { o.max_block_size = max_block_size; }); });
}

strata_status strata_set_num_threads(strata_solver* s, int num_threads) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s,
                 [&] { set_checked(s, [&](strata::Options& o) { o.num_threads = num_threads; }); });
}

strata_status strata_set_refinement_steps(strata_solver* s, int max_steps) {
  STRATA_CHECK_SOLVER(s);
  return guarded(
      s, [&] { set_checked(s, [&](strata::Options& o) { o.refinement_max_steps = max_steps; }); });
}

strata_status strata_set_refinement_tolerance(strata_solver* s, double tolerance) {
  STRATA_CHECK_SOLVER(s);
  return guarded(
      s, [&] { set_checked(s, [&](strata::Options& o) { o.refinement_tolerance = tolerance; }); });
}

strata_status strata_set_device_memory_limit(strata_solver* s, uint64_t bytes) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] { s->options.device_memory_limit = static_cast<std::size_t>(bytes); });
}

strata_status strata_set_option(strata_solver* s, const char* name, const char* value) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    if (name == nullptr || value == nullptr)
      throw strata::InvalidInput(name == nullptr ? "option name is NULL" : "option value is NULL");
    set_checked(s, [&](strata::Options& o) { strata::set_option(o, name, value); });
  });
}

strata_status strata_get_option(const strata_solver* s, const char* name, char* buffer, size_t size,
                                size_t* needed) {
  if (s == nullptr) return STRATA_ERROR_INVALID_INPUT;
  return guarded(s, [&] {
    if (name == nullptr) throw strata::InvalidInput("option name is NULL");
    if (buffer == nullptr && size > 0)
      throw strata::InvalidInput("buffer is NULL but size is " + std::to_string(size));
    copy_text(strata::get_option(s->options, name), buffer, size, needed);
  });
}

strata_status strata_analyze(strata_solver* s, const strata_matrix* a) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    strata::SparseMatrix m;
    try {
      m = convert(a, false);
    } catch (...) {
      s->analyzed = s->factorized = s->solved = false;
      s->solver.reset();
      throw;
    }
    do_analyze(s, m);
  });
}

strata_status strata_factorize(strata_solver* s, const strata_matrix* a) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    const strata::SparseMatrix m = convert(a, true);
    if (!s->analyzed) do_analyze(s, m);
    factor_phase(s, [&] { s->solver->factorize(m); });
  });
}

strata_status strata_refactorize(strata_solver* s, const strata_matrix* a) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    if (!s->analyzed) throw strata::InvalidState("refactorize called before analyze");
    const strata::SparseMatrix m = convert(a, true);
    factor_phase(s, [&] { s->solver->refactorize(m); });
  });
}

strata_status strata_refactorize_values(strata_solver* s, int64_t nnz, const double* values) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    if (!s->analyzed) throw strata::InvalidState("refactorize called before analyze");
    if (nnz < 0) throw strata::InvalidInput("nnz is negative (" + std::to_string(nnz) + ")");
    if (values == nullptr && nnz > 0) throw strata::InvalidInput("values is NULL");
    const std::span<const double> v(values, static_cast<std::size_t>(nnz));
    factor_phase(s, [&] { s->solver->refactorize(v); });
  });
}

strata_status strata_solve(strata_solver* s, int64_t nrhs, const double* b, double* x) {
  STRATA_CHECK_SOLVER(s);
  return guarded(s, [&] {
    if (!s->analyzed || !s->factorized) throw strata::InvalidState("solve called before factorize");
    if (nrhs < 0) throw strata::InvalidInput("nrhs must be >= 0, got " + std::to_string(nrhs));
    const index_t n = s->solver->size();
    if (nrhs == 0 || n == 0) {
      s->solved = true;
      return;
    }
    if (b == nullptr || x == nullptr)
      throw strata::InvalidInput(b == nullptr ? "b is NULL" : "x is NULL");
    if (b == x) {  // in place: the C++ solver needs separate arrays (b in GPU memory: fetched)
      std::vector<double> copy(static_cast<std::size_t>(n * nrhs));
      if (strata::numeric::device_memory_of(b) >= 0)
        strata::numeric::copy_from_device(copy.data(), b, copy.size());
      else
        std::copy(b, b + n * nrhs, copy.begin());
      s->solver->solve(copy.data(), x, nrhs);
    } else {
      s->solver->solve(b, x, nrhs);
    }
    s->solved = true;
  });
}

strata_status strata_size(const strata_solver* s, int64_t* n) {
  if (s == nullptr) return STRATA_ERROR_INVALID_INPUT;
  if (n == nullptr) {
    s->last_error = "n is NULL";
    return STRATA_ERROR_INVALID_INPUT;
  }
  s->last_error.clear();
  *n = s->analyzed ? s->solver->size() : 0;
  return STRATA_OK;
}

strata_status strata_get_stats(const strata_solver* s, strata_stats* out) {
  if (s == nullptr) return STRATA_ERROR_INVALID_INPUT;
  if (out == nullptr) {
    s->last_error = "stats is NULL";
    return STRATA_ERROR_INVALID_INPUT;
  }
  s->last_error.clear();
  std::memset(out, 0, sizeof(*out));
  auto to_c = [](strata::MatrixType t) {
    switch (t) {
      case strata::MatrixType::spd:
        return STRATA_TYPE_SPD;
      case strata::MatrixType::symmetric_indefinite:
        return STRATA_TYPE_SYMMETRIC_INDEFINITE;
      case strata::MatrixType::general:
        return STRATA_TYPE_GENERAL;
      default:
        return STRATA_TYPE_AUTO;
    }
  };
  if (!s->analyzed) return STRATA_OK;
  const strata::Stats& st = s->solver->stats();
  const strata::AnalysisStats& an = st.analysis;
  out->analyzed = 1;
  out->n = an.n;
  out->nnz_a = an.nnz_a;
  out->nnz_l = an.nnz_l;
  out->nnz_l_fronts = an.nnz_l_fronts;
  out->factor_flops = an.factor_flops;
  out->n_fronts = an.n_fronts;
  out->largest_front_rows = an.largest_front_rows;
  out->tree_height = an.tree_height;
  out->peak_working_bytes = an.peak_working_bytes;
  out->factor_bytes = an.factor_bytes;
  out->n_batches = static_cast<int64_t>(an.batches.size());
  out->analysis_type = to_c(an.type);
  out->analysis_seconds = an.total_seconds;
  if (s->factorized) {
    const strata::FactorStats& f = st.factor;
    out->factorized = 1;
    out->type = to_c(f.type);
    out->backend_is_cuda = f.backend == strata::Backend::cuda ? 1 : 0;
    out->factor_seconds = f.seconds;
    out->factor_gflops = f.gflops;
    out->perturbed_pivots = f.perturbed_pivots;
    out->two_by_two_pivots = f.two_by_two_pivots;
    out->inertia_positive = f.inertia_positive;
    out->inertia_negative = f.inertia_negative;
    out->inertia_zero = f.inertia_zero;
    out->log_abs_determinant = f.log_abs_determinant;
    out->determinant_sign = f.determinant_sign;
    out->inertia_valid = f.inertia_valid ? 1 : 0;
  }
  if (s->solved) {
    const strata::SolveStats& so = st.solve;
    out->solved = 1;
    out->solve_seconds = so.seconds;
    out->refinement_steps = so.refinement_steps;
    out->gmres_iterations = so.gmres_iterations;
    out->backward_error = so.backward_error;
    out->refinement_converged = so.refinement_converged ? 1 : 0;
    out->backward_error_floor = so.backward_error_floor;
    out->condition_lower_bound = so.condition_lower_bound;
    out->relative_residual = so.relative_residual;
    out->singular_consistent = so.singular_consistent ? 1 : 0;
  }
  return STRATA_OK;
}

strata_status strata_get_stats_json(const strata_solver* s, char* buffer, size_t size,
                                    size_t* needed) {
  if (s == nullptr) return STRATA_ERROR_INVALID_INPUT;
  if (buffer == nullptr && size > 0) {
    s->last_error = "buffer is NULL but size is " + std::to_string(size);
    return STRATA_ERROR_INVALID_INPUT;
  }
  return guarded(s, [&] {
    copy_text(s->analyzed
                  ? strata::stats_document(s->solver->stats(), s->factorized, s->solved).dump()
                  : std::string("{}"),
              buffer, size, needed);
  });
}

strata_status strata_get_permutation(const strata_solver* s, int64_t* perm) {
  if (s == nullptr) return STRATA_ERROR_INVALID_INPUT;
  if (perm == nullptr) {
    s->last_error = "perm is NULL";
    return STRATA_ERROR_INVALID_INPUT;
  }
  if (!s->analyzed) {
    s->last_error = "permutation asked before analyze";
    return STRATA_ERROR_INVALID_STATE;
  }
  s->last_error.clear();
  const std::vector<index_t>& p = s->solver->permutation();
  std::copy(p.begin(), p.end(), perm);
  return STRATA_OK;
}

}  // extern "C"
