// strata — generated test problems: grid Laplacians and an elasticity-like stencil.
#pragma once

#include "strata/sparse_matrix.hpp"

namespace strata::generators {

/// 5-point Laplacian on an nx×ny grid (Dirichlet boundary), SPD, order nx·ny.
/// Returned as Storage::lower canonical CSC.
SparseMatrix laplacian_2d(index_t nx, index_t ny);

/// 7-point Laplacian on an nx×ny×nz grid (Dirichlet boundary), SPD, Storage::lower.
SparseMatrix laplacian_3d(index_t nx, index_t ny, index_t nz);

/// A 3-dof-per-node, 27-point stencil on an nx×ny×nz grid: each node couples all three
/// dofs with its 26 neighbours, like a trilinear-hex elasticity stiffness. Entries are
/// chosen so the matrix is SPD (strictly diagonally dominant with a positive diagonal).
/// Order 3·nx·ny·nz, Storage::lower.
SparseMatrix elasticity_3d(index_t nx, index_t ny, index_t nz);

}  // namespace strata::generators
