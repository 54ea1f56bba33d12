// strata — generated test problems (see generators.hpp).
//
// The matrices are built column by column directly in canonical lower CSC form: for
// column j only neighbours with a larger index are emitted, in increasing order, so no
// sort or duplicate pass is needed.
#include "sparse/generators.hpp"

#include <cmath>
#include <cstdlib>

namespace strata::generators {
namespace {

SparseMatrix lower_csc(index_t n) {
  SparseMatrix a;
  a.n_rows = a.n_cols = n;
  a.layout = Layout::csc;
  a.storage = Storage::lower;
  a.offsets.assign(1, 0);
  a.offsets.reserve(n + 1);
  return a;
}

}  // namespace

SparseMatrix laplacian_2d(index_t nx, index_t ny) { return laplacian_3d(nx, ny, 1); }

SparseMatrix laplacian_3d(index_t nx, index_t ny, index_t nz) {
  const index_t n = nx * ny * nz;
  SparseMatrix a = lower_csc(n);
  a.indices.reserve(4 * n);
  a.values.reserve(4 * n);
  const double diag = (nz > 1) ? 6.0 : 4.0;
  for (index_t z = 0; z < nz; ++z)
    for (index_t y = 0; y < ny; ++y)
      for (index_t x = 0; x < nx; ++x) {
        const index_t j = x + nx * (y + ny * z);
        a.indices.push_back(j);
        a.values.push_back(diag);
        if (x + 1 < nx) {
          a.indices.push_back(j + 1);
          a.values.push_back(-1.0);
        }
        if (y + 1 < ny) {
          a.indices.push_back(j + nx);
          a.values.push_back(-1.0);
        }
        if (z + 1 < nz) {
          a.indices.push_back(j + nx * ny);
          a.values.push_back(-1.0);
        }
        a.offsets.push_back(static_cast<index_t>(a.indices.size()));
      }
  return a;
}

SparseMatrix elasticity_3d(index_t nx, index_t ny, index_t nz) {
  const index_t nodes = nx * ny * nz;
  const index_t n = 3 * nodes;
  SparseMatrix a = lower_csc(n);
  a.indices.reserve(n * 42);
  a.values.reserve(n * 42);
  auto node_id = [&](index_t x, index_t y, index_t z) { return x + nx * (y + ny * z); };
  for (index_t z = 0; z < nz; ++z)
    for (index_t y = 0; y < ny; ++y)
      for (index_t x = 0; x < nx; ++x) {
        const index_t p = node_id(x, y, z);
        for (int dp = 0; dp < 3; ++dp) {
          const index_t j = 3 * p + dp;
          // Off-diagonal couplings: -1 between equal dofs, -0.25·sign between others,
          // so that Σ|off-diagonal| per row is at most 26·(1 + 2·0.25) = 39 < diag.
          // Neighbours with a larger node index, and the node's own later dofs.
          a.indices.push_back(j);
          a.values.push_back(40.0);
          for (int dq = dp + 1; dq < 3; ++dq) {
            a.indices.push_back(3 * p + dq);
            a.values.push_back(0.25);
          }
          for (index_t dz = -1; dz <= 1; ++dz)
            for (index_t dy = -1; dy <= 1; ++dy)
              for (index_t dx = -1; dx <= 1; ++dx) {
                const index_t qx = x + dx, qy = y + dy, qz = z + dz;
                if (qx < 0 || qy < 0 || qz < 0 || qx >= nx || qy >= ny || qz >= nz) continue;
                const index_t q = node_id(qx, qy, qz);
                if (q <= p) continue;
                for (int dq = 0; dq < 3; ++dq) {
                  a.indices.push_back(3 * q + dq);
                  const double s = ((dx + dy + dz) & 1) ? 0.25 : -0.25;
                  a.values.push_back(dq == dp ? -1.0 : s);
                }
              }
          a.offsets.push_back(static_cast<index_t>(a.indices.size()));
        }
      }
  return a;
}

}  // namespace strata::generators
