// strata — tests of SparseMatrix validation, canonical forms and SpMV, against dense
// copies built independently from the raw triplets.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <string>

#include "sparse/generators.hpp"
#include "strata/errors.hpp"
#include "strata/sparse_matrix.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

// A random matrix with unsorted, duplicated entries in the given layout/storage, and the
// dense matrix it represents (duplicates summed, symmetric storage mirrored).
SparseMatrix messy(index_t m, index_t n, Layout layout, Storage storage, std::mt19937_64& rng,
                   std::vector<double>& dense) {
  dense.assign(m * n, 0.0);
  SparseMatrix a;
  a.n_rows = m;
  a.n_cols = n;
  a.layout = layout;
  a.storage = storage;
  const index_t nmaj = layout == Layout::csc ? n : m;
  const index_t nmin = layout == Layout::csc ? m : n;
  std::uniform_int_distribution<index_t> pick(0, std::max<index_t>(nmin - 1, 0));
  std::uniform_int_distribution<int> cnt(0, 4);
  std::uniform_real_distribution<double> val(-1, 1);
  a.offsets.assign(1, 0);
  for (index_t j = 0; j < nmaj; ++j) {
    const int c = nmin ? cnt(rng) : 0;
    for (int t = 0; t < c; ++t) {
      index_t i = pick(rng);
      index_t r = layout == Layout::csc ? i : j, col = layout == Layout::csc ? j : i;
      if (storage == Storage::lower && r < col) std::swap(r, col);
      if (storage == Storage::upper && r > col) std::swap(r, col);
      const double v = val(rng);
      a.indices.push_back(layout == Layout::csc ? r : col);
      // keep the major index consistent after a swap: re-derive
      if ((layout == Layout::csc ? col : r) != j) {
        a.indices.pop_back();
        continue;
      }
      a.values.push_back(v);
      dense[r + col * m] += v;
      if (storage != Storage::full && r != col) dense[col + r * m] += v;
    }
    a.offsets.push_back(static_cast<index_t>(a.indices.size()));
  }
  return a;
}

TEST(SparseMatrix, CanonicalizeAndExpandMatchDense) {
  auto rng = test::fresh_rng();
  for (index_t n : {0, 1, 2, 3, 5, 733})
    for (Layout layout : {Layout::csc, Layout::csr})
      for (Storage storage : {Storage::full, Storage::lower, Storage::upper}) {
        std::vector<double> dense;
        SparseMatrix a = messy(n, n, layout, storage, rng, dense);
        SparseMatrix c = canonicalize(a);
        EXPECT_EQ(c.layout, Layout::csc);
        EXPECT_EQ(c.storage, storage);
        for (index_t j = 0; j < n; ++j)
          for (index_t p = c.offsets[j] + 1; p < c.offsets[j + 1]; ++p)
            EXPECT_LT(c.indices[p - 1], c.indices[p]) << "not sorted or duplicated";
        EXPECT_EQ(test::to_dense(c), test::to_dense(a));
        // an already canonical matrix comes back unchanged (the copy, not a re-sort)
        const SparseMatrix cc = canonicalize(c);
        EXPECT_EQ(cc.offsets, c.offsets);
        EXPECT_EQ(cc.indices, c.indices);
        EXPECT_EQ(cc.values, c.values);
        EXPECT_EQ(cc.storage, c.storage);
        SparseMatrix e = expand_symmetric(a);
        EXPECT_EQ(e.storage, Storage::full);
        const SparseMatrix ee = expand_symmetric(e);
        EXPECT_EQ(ee.indices, e.indices);
        EXPECT_EQ(ee.values, e.values);
        std::vector<double> de = test::to_dense(e);
        for (index_t k = 0; k < n * n; ++k) EXPECT_NEAR(de[k], dense[k], 1e-15);
        // SpMV against the dense product
        std::vector<double> x(n), y(n);
        std::uniform_real_distribution<double> u(-1, 1);
        for (double& v : x) v = u(rng);
        multiply(a, x.data(), y.data());
        for (index_t i = 0; i < n; ++i) {
          double s = 0;
          for (index_t j = 0; j < n; ++j) s += dense[i + j * n] * x[j];
          EXPECT_NEAR(y[i], s, 1e-13);
        }
      }
}

TEST(SparseMatrix, RectangularCanonicalize) {
  auto rng = test::fresh_rng();
  std::vector<double> dense;
  SparseMatrix a = messy(7, 3, Layout::csr, Storage::full, rng, dense);
  SparseMatrix c = canonicalize(a);
  EXPECT_EQ(test::to_dense(c), test::to_dense(a));
}

TEST(SparseMatrix, ValidateNamesTheProblem) {
  SparseMatrix a;
  a.n_rows = a.n_cols = 3;
  a.offsets = {0, 1, 2, 3};
  a.indices = {0, 5, 2};
  a.values = {1, 2, 3};
  try {
    validate(a);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_NE(std::string(e.what()).find("indices[1] = 5"), std::string::npos) << e.what();
  }
  a.indices = {0, 1, 2};
  a.values[2] = std::nan("");
  EXPECT_THROW(validate(a), InvalidInput);
  a.values[2] = 3;
  a.offsets = {0, 2, 1, 3};
  EXPECT_THROW(validate(a), InvalidInput);
  a.offsets = {0, 1, 2, 3};
  a.storage = Storage::lower;
  a.indices = {0, 0, 2};  // (0,1) is above the diagonal
  EXPECT_THROW(validate(a), InvalidInput);
  a.indices = {0, 1, 2};
  EXPECT_NO_THROW(validate(a));
  a.values.resize(2);
  EXPECT_THROW(validate(a), InvalidInput);
}

// A matrix large enough for the checks to run over the threads (2^16 entries or more):
// the message still names the first bad entry, wherever the others lie; an unsorted
// column is still found and sorted.
TEST(SparseMatrix, ValidateALargeMatrixNamesTheFirstBadEntry) {
  std::mt19937_64 rng(std::random_device{}());
  const SparseMatrix good = generators::laplacian_3d(31, 29, 27);
  const auto nnz = static_cast<index_t>(good.nnz());
  ASSERT_GE(nnz, index_t{1} << 16);
  EXPECT_NO_THROW(validate(good));
  auto message = [](const SparseMatrix& m) {
    try {
      validate(m);
    } catch (const InvalidInput& e) {
      return std::string(e.what());
    }
    return std::string("no error");
  };
  for (int trial = 0; trial < 5; ++trial) {
    std::uniform_int_distribution<index_t> at(0, nnz - 1);
    index_t p1 = at(rng), p2 = at(rng);
    while (p2 == p1) p2 = at(rng);
    if (p2 < p1) std::swap(p1, p2);
    SparseMatrix a = good;
    a.values[p1] = std::nan("");
    a.indices[p2] = good.n_rows + 7;
    EXPECT_NE(message(a).find("values[" + std::to_string(p1) + "] is not finite"),
              std::string::npos)
        << message(a);
    a = good;
    a.indices[p1] = -1;
    a.values[p2] = INFINITY;
    EXPECT_NE(message(a).find("indices[" + std::to_string(p1) + "] = -1"), std::string::npos)
        << message(a);
  }
  SparseMatrix unsorted = good;
  const index_t j = good.n_cols / 2;
  std::swap(unsorted.indices[unsorted.offsets[j]], unsorted.indices[unsorted.offsets[j] + 1]);
  std::swap(unsorted.values[unsorted.offsets[j]], unsorted.values[unsorted.offsets[j] + 1]);
  const SparseMatrix sorted = expand_symmetric(unsorted), reference = expand_symmetric(good);
  EXPECT_EQ(sorted.offsets, reference.offsets);
  EXPECT_EQ(sorted.indices, reference.indices);
  EXPECT_EQ(sorted.values, reference.values);
  SparseMatrix full_unsorted = reference;  // full storage: only the sortedness check differs
  std::swap(full_unsorted.indices[full_unsorted.offsets[j]],
            full_unsorted.indices[full_unsorted.offsets[j] + 1]);
  EXPECT_EQ(expand_symmetric(full_unsorted).indices, reference.indices);
}

TEST(SparseMatrix, NumericalSymmetry) {
  auto rng = test::fresh_rng();
  SparseMatrix s = test::random_sparse(50, 3, test::RandomKind::spd, rng);
  SparseMatrix full = expand_symmetric(s);
  EXPECT_TRUE(is_numerically_symmetric(full));
  SparseMatrix g = test::random_sparse(50, 3, test::RandomKind::general, rng);
  EXPECT_FALSE(is_numerically_symmetric(g));
}

// Against the dense definition A = Aᵀ: symmetric matrices, one value changed, and one entry
// without its mirror (anywhere, the last entry of the last column included), in messy
// (unsorted, duplicated) and canonical forms.
TEST(SparseMatrix, NumericalSymmetryMatchesDense) {
  auto rng = test::fresh_rng();
  auto dense_symmetric = [](const SparseMatrix& a) {
    const std::vector<double> d = test::to_dense(a);
    const index_t n = a.n_rows;
    for (index_t j = 0; j < n; ++j)
      for (index_t i = 0; i < n; ++i)
        if (d[i + j * n] != d[j + i * n]) return false;
    return true;
  };
  for (index_t n : {1, 2, 3, 5, 733}) {
    std::vector<double> dense;
    SparseMatrix low = messy(n, n, Layout::csc, Storage::lower, rng, dense);
    const SparseMatrix sym = expand_symmetric(low);  // full, symmetric by construction
    EXPECT_TRUE(is_numerically_symmetric(sym)) << "n = " << n;
    EXPECT_TRUE(dense_symmetric(sym));
    std::uniform_int_distribution<index_t> pick(0, n - 1);
    for (int trial = 0; trial < 20; ++trial) {
      // one off-diagonal value changed
      SparseMatrix v = sym;
      if (v.nnz() > 0) {
        std::uniform_int_distribution<index_t> entry(0, v.nnz() - 1);
        v.values[entry(rng)] += 0.5;
        EXPECT_EQ(is_numerically_symmetric(v), dense_symmetric(v)) << "n = " << n;
      }
      // one entry (i, j) added in messy form (appended to column j, unsorted)
      SparseMatrix x = sym;
      const index_t i = trial == 0 ? n - 1 : pick(rng), j = trial == 0 ? n - 1 : pick(rng);
      x.indices.insert(x.indices.begin() + x.offsets[j + 1], i);
      x.values.insert(x.values.begin() + x.offsets[j + 1], 1.0);
      for (index_t k = j + 1; k <= n; ++k) ++x.offsets[k];
      EXPECT_EQ(is_numerically_symmetric(x), dense_symmetric(x))
          << "n = " << n << ", entry (" << i << ", " << j << ")";
    }
  }
}

TEST(Generators, GridLaplaciansAndElasticityAreSpdStencils) {
  SparseMatrix l2 = generators::laplacian_2d(4, 3);
  EXPECT_NO_THROW(validate(l2));
  EXPECT_EQ(l2.n_rows, 12);
  // 2D 5-point: nnz(lower) = n + edges = 12 + (3*3 + 4*2)
  EXPECT_EQ(l2.nnz(), 12 + 9 + 8);
  SparseMatrix l3 = generators::laplacian_3d(3, 3, 3);
  EXPECT_EQ(l3.nnz(), 27 + 3 * 18);
  std::vector<double> ones(27, 1.0), y(27);
  multiply(l3, ones.data(), y.data());
  EXPECT_EQ(y[13], 0.0);  // interior row sums to zero
  SparseMatrix e = generators::elasticity_3d(3, 3, 3);
  EXPECT_NO_THROW(validate(e));
  EXPECT_EQ(e.n_rows, 81);
  // strict diagonal dominance (hence SPD)
  std::vector<double> d = test::to_dense(e);
  for (index_t i = 0; i < 81; ++i) {
    double off = 0;
    for (index_t j = 0; j < 81; ++j)
      if (j != i) off += std::abs(d[i + j * 81]);
    EXPECT_GT(d[i + i * 81], off);
  }
  // the center node couples with all 26 neighbours: 27 nodes × 3 dofs per row
  index_t row_nnz = 0;
  for (index_t j = 0; j < 81; ++j) row_nnz += d[3 * 13 + j * 81] != 0;
  EXPECT_EQ(row_nnz, 81);
}

}  // namespace
}  // namespace strata
