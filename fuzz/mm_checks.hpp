// strata fuzz targets — what a Matrix Market read must satisfy (shared by the plain and
// the gzip target).
//
// A read either throws a strata::Error (ParseError, NotSupported, OutOfMemory: the
// documented outcomes) or returns a matrix that is canonical (validate passes, indices
// strictly increasing in each column, every value finite, lower storage exactly for
// symmetric files, pattern files all ones). For small matrices the dense reader must
// agree with the sparse one entry by entry, and a write/read round trip must give the
// same matrix bitwise. Any other outcome aborts (a finding).
#pragma once

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "fuzz_common.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::fuzz {

[[noreturn]] inline void finding(const std::string& what) {
  std::fprintf(stderr, "FINDING: %s\n", what.c_str());
  std::fflush(stderr);
  std::abort();
}

inline void require(bool ok, const char* what) {
  if (!ok) finding(what);
}

/// Checks the canonical form promised by read_matrix_market.
inline void check_canonical(const MMMatrix& mm) {
  const SparseMatrix& a = mm.matrix;
  try {
    validate(a);
  } catch (const Error& e) {
    finding(std::string("the reader returned an invalid matrix: ") + e.what());
  }
  require(a.layout == Layout::csc, "not CSC");
  require((mm.symmetry == MMSymmetry::symmetric) == (a.storage == Storage::lower),
          "lower storage iff symmetric");
  require(a.storage != Storage::upper, "upper storage");
  require(a.values.size() == a.indices.size(), "values missing");
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j] + 1; p < a.offsets[j + 1]; ++p)
      require(a.indices[p - 1] < a.indices[p], "indices not strictly increasing");
  for (double v : a.values) {
    require(std::isfinite(v), "a value that is not finite");
    if (mm.pattern) require(v == 1.0, "pattern value other than 1");
  }
}

/// Dense column-major copy with symmetric storage expanded.
inline std::vector<double> dense_of(const SparseMatrix& a) {
  std::vector<double> d(static_cast<size_t>(a.n_rows * a.n_cols), 0.0);
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      const index_t i = a.indices[p];
      d[i + j * a.n_rows] += a.values[p];
      if (a.storage == Storage::lower && i != j) d[j + i * a.n_rows] += a.values[p];
    }
  return d;
}

/// Reads PATH both ways and checks every promise; `scratch` is a second file for the
/// round trip. Returns the matrix read, or false when the reader threw (its message in
/// *error when given) or the file declares dimensions above kMaxFuzzDimension (not read;
/// *error = "skipped").
inline bool check_file(const std::string& path, const std::string& scratch, MMMatrix* out = nullptr,
                       std::string* error = nullptr) {
  if (!small_dimensions(path)) {
    if (error) *error = "skipped";
    return false;
  }
  MMMatrix mm;
  try {
    mm = read_matrix_market(path);
  } catch (const Error& e) {
    if (error) *error = e.what();
    return false;
  }
  check_canonical(mm);
  const SparseMatrix& a = mm.matrix;
  if (a.n_rows * a.n_cols <= (1 << 16)) {
    index_t rows = -1, cols = -1;
    std::vector<double> d;
    try {
      d = read_dense_matrix_market(path, &rows, &cols);
    } catch (const Error& e) {
      finding(std::string("the dense reader failed on a file the sparse reader read: ") + e.what());
    }
    require(rows == a.n_rows && cols == a.n_cols, "dense reader: other dimensions");
    const std::vector<double> s = dense_of(a);
    for (size_t k = 0; k < s.size(); ++k) {
      // duplicates may be summed in another order: allow rounding, not a different value
      const double tol = 1e-12 * (std::abs(s[k]) + std::abs(d[k]));
      if (!(std::abs(s[k] - d[k]) <= tol))
        finding("dense and sparse readers disagree at " + std::to_string(k) + ": " +
                std::to_string(d[k]) + " vs " + std::to_string(s[k]));
    }
  }
  if (a.nnz() <= 4096 && a.n_cols <= (1 << 16)) {
    try {
      write_matrix_market(scratch, a);
      const MMMatrix back = read_matrix_market(scratch);
      require(back.matrix.n_rows == a.n_rows && back.matrix.n_cols == a.n_cols &&
                  back.matrix.offsets == a.offsets && back.matrix.indices == a.indices &&
                  back.matrix.values == a.values && back.matrix.storage == a.storage,
              "write/read round trip changed the matrix");
    } catch (const Error& e) {
      finding(std::string("round trip failed: ") + e.what());
    }
  }
  if (out) *out = std::move(mm);
  return true;
}

}  // namespace strata::fuzz
