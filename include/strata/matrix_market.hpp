// strata — Matrix Market input and output (NIST format, https://math.nist.gov/MatrixMarket).
//
// Read: `coordinate` real / integer / pattern with general / symmetric / skew-symmetric
// symmetry, and `array` real / integer general (dense right-hand sides). gzip files
// (any name; several members allowed, nothing after the last) are decompressed with zlib. Complex
// and Hermitian files are NotSupported. Every malformed file raises ParseError naming the file and
// 1-based line: bad banner, bad size line, wrong entry count, index out of range, non-numeric
// value, NaN/Inf, truncated file, trailing data after a gzip stream; also duplicate entries whose
// sum overflows (line 0: no single line) and dimensions above 2^60 - 1 (the most a std::vector of
// offsets can hold). A file whose declared dimensions need more memory than there is raises
// OutOfMemory.
#pragma once

#include <string>
#include <vector>

#include "strata/sparse_matrix.hpp"

namespace strata {

/// Symmetry declared in a Matrix Market banner.
enum class MMSymmetry { general, symmetric, skew_symmetric };

/// A coordinate matrix as read: CSC, 0-based, duplicates summed, indices sorted.
/// `symmetric`: storage is Storage::lower, holding the entries as the file gives them
/// (upper-triangle entries of a symmetric file are moved to the lower triangle).
/// `skew_symmetric`: expanded to Storage::full (a_ji = -a_ij). `pattern` files get
/// values 1.0.
struct MMMatrix {
  SparseMatrix matrix;
  MMSymmetry symmetry = MMSymmetry::general;
  bool pattern = false;  ///< the file had no values
};

/// What read_matrix_market checks beyond the format.
enum class MMCheck {
  none,  ///< any matrix the file holds (rectangular, empty rows and columns allowed)
  /// A matrix to be factored: square, and every row and column holding an entry (a
  /// matrix with an empty row or column is structurally singular). Checked from the
  /// entries in O(entries) memory, before the O(rows + columns) compressed form is
  /// allocated, so a small file declaring huge dimensions is refused at once.
  factorable,
};

/// Reads a sparse coordinate matrix from PATH (gzip-compressed or plain, told by its
/// first bytes). Throws ParseError, NotSupported, OutOfMemory (naming the bytes of the
/// compressed form), and with MMCheck::factorable InvalidInput "PATH: matrix is RxC, not
/// square" or "PATH: matrix is structurally singular: column J (1-based) has no entries"
/// (or row I).
MMMatrix read_matrix_market(const std::string& path, MMCheck check = MMCheck::none);

/// Reads a dense `array` (or a coordinate file, densified) into a column-major
/// rows×cols array. Throws ParseError, NotSupported, OutOfMemory.
std::vector<double> read_dense_matrix_market(const std::string& path, index_t* rows, index_t* cols);

/// Writes A as `coordinate real general` (or `symmetric` when A.storage is lower or
/// upper; an upper-stored matrix is written as its transpose's lower triangle).
/// Values are written with 17 significant digits. The file is written under a
/// temporary name and renamed when complete, so PATH is never left partial.
/// Throws Error when the file cannot be written.
void write_matrix_market(const std::string& path, const SparseMatrix& a);

/// Writes a column-major rows×cols dense array as `array real general`, atomically
/// (temporary file, then rename).
void write_dense_matrix_market(const std::string& path, const double* values, index_t rows,
                               index_t cols);

}  // namespace strata
