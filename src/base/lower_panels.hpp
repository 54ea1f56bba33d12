// strata — the lower triangle of a symmetric matrix stored in column panels.
//
// An n × n symmetric matrix whose lower triangle alone is needed (a Cholesky front's
// contribution block) is stored as column panels of `width` columns: panel p holds columns
// [p·width, min(n, (p+1)·width)) from row p·width down, column-major with leading dimension
// n − p·width, and the panels follow each other. That is about n²/2 + n·width/2 doubles
// instead of n², and every panel is a plain BLAS matrix (the diagonal block a SYRK target,
// the rows below it a GEMM target). With width ≥ n it is one panel: the plain column-major
// square, whose leading dimension may then exceed n (a block inside a larger front).
// The idea is that of LAPACK's blocked packed formats (Gustavson, Karlsson & Kågström,
// "Three algorithms for Cholesky factorization on distributed memory using packed
// storage", PARA 2006).
#pragma once

#include <cstddef>

#include "strata/types.hpp"

namespace strata {

/// Panel width of the CPU executor's stored contribution blocks.
constexpr index_t kLowerPanelWidth = 128;

/// A view of such a matrix (see the file header). Element (i, j), j ≤ i < n, is
/// diag(j)[i − j].
struct LowerPanels {
  double* data = nullptr;
  index_t n = 0;
  index_t width = 1;  ///< columns per panel (≥ 1); ≥ n: one panel
  index_t ld = 0;     ///< leading dimension of the one panel when width ≥ n (≥ n)

  /// Doubles taken by an n × n matrix in panels of `width` columns (width ≥ n: n²).
  static std::size_t size(index_t n, index_t width) {
    if (n <= 0) return 0;
    if (width >= n) return static_cast<std::size_t>(n) * static_cast<std::size_t>(n);
    const index_t last = (n - 1) / width;
    const auto rest = static_cast<std::size_t>(n - last * width);
    return panel_start(n, width, last) + rest * rest;
  }
  /// Offset (doubles) of panel p of an n × n matrix in panels of `width` < n columns.
  static std::size_t panel_start(index_t n, index_t width, index_t p) {
    const auto w = static_cast<std::size_t>(width), pp = static_cast<std::size_t>(p);
    return w * (pp * static_cast<std::size_t>(n) - w * pp * (pp - (pp > 0 ? 1 : 0)) / 2);
  }

  index_t panels() const { return width >= n ? (n > 0 ? 1 : 0) : (n + width - 1) / width; }
  index_t panel_first(index_t p) const { return width >= n ? 0 : p * width; }
  index_t panel_columns(index_t p) const {
    const index_t j0 = panel_first(p);
    return width >= n ? n : (n - j0 < width ? n - j0 : width);
  }
  index_t panel_ld(index_t p) const { return width >= n ? ld : n - p * width; }
  double* panel(index_t p) const { return width >= n ? data : data + panel_start(n, width, p); }
  double* diag(index_t j) const {
    if (width >= n) return data + static_cast<std::size_t>(j) * (static_cast<std::size_t>(ld) + 1);
    const index_t p = j / width, c = j - p * width;
    return panel(p) + static_cast<std::size_t>(c) * (static_cast<std::size_t>(n - p * width) + 1);
  }
};

}  // namespace strata
