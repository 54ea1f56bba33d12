// strata — the sparse matrix type of the public API.
#pragma once

#include <vector>

#include "strata/types.hpp"

namespace strata {

/// Compressed-row or compressed-column layout.
enum class Layout { csr, csc };

/// Which part of a symmetric matrix is stored. `full` means every entry is stored
/// (the only valid choice for unsymmetric matrices); `lower` / `upper` mean only the
/// lower / upper triangle (diagonal included) is stored and the other is implied.
enum class Storage { full, lower, upper };

/// A sparse matrix in CSR or CSC form, 0-based.
///
/// For Layout::csc: `offsets` has n_cols+1 entries, column j holds the entries
/// offsets[j] .. offsets[j+1]-1 of `indices` (row indices) and `values`.
/// For Layout::csr the roles of rows and columns are exchanged.
/// `values` is either empty (a pattern-only matrix) or has offsets.back() entries.
/// Indices within a column (row) need not be sorted and may repeat: duplicates are
/// summed when strata canonicalizes the matrix (see strata::canonicalize).
struct SparseMatrix {
  index_t n_rows = 0;
  index_t n_cols = 0;
  Layout layout = Layout::csc;
  Storage storage = Storage::full;
  std::vector<index_t> offsets{0};
  std::vector<index_t> indices;
  std::vector<double> values;

  /// Number of stored entries (offsets.back()).
  index_t nnz() const { return offsets.empty() ? 0 : offsets.back(); }
  /// Number of compressed vectors: n_cols for CSC, n_rows for CSR.
  index_t n_major() const { return layout == Layout::csc ? n_cols : n_rows; }
  bool has_values() const { return !values.empty() || nnz() == 0; }
};

/// Checks the structural validity of A: offsets monotone with offsets[0] == 0 and the
/// right length, every index in range, values empty or of length nnz, every value
/// finite, and a `lower`/`upper` storage holding no entry of the other triangle.
/// Throws InvalidInput naming the first problem found (vector and position).
void validate(const SparseMatrix& a);

/// Returns A in canonical CSC form: Layout::csc, indices sorted within each column,
/// duplicates summed, same storage (lower/upper/full). Validates first (see validate).
SparseMatrix canonicalize(const SparseMatrix& a);

/// Returns the full (both triangles) canonical CSC form of A. A symmetric `lower` or
/// `upper` matrix is expanded; a `full` matrix is only canonicalized.
SparseMatrix expand_symmetric(const SparseMatrix& a);

/// y = A x for a matrix of any layout and storage (symmetric storage is expanded on
/// the fly). x has n_cols entries, y has n_rows entries.
void multiply(const SparseMatrix& a, const double* x, double* y);

/// True when A (full or expanded) equals its transpose in pattern and values.
bool is_numerically_symmetric(const SparseMatrix& a);

}  // namespace strata
