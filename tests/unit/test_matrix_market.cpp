// strata tests — Matrix Market reader and writers (src/sparse/matrix_market.cpp).
//
// Covers: every shared SuiteSparse/CalculiX matrix reads with the n and nnz of the shared
// README table and passes validate; write/read round trips are bitwise for sparse
// (general, symmetric lower and upper, pattern) and dense matrices; a table of malformed
// files each raises ParseError at the right line with the right message (including a
// truncated and a corrupted .gz file); duplicates, symmetric upper-triangle entries,
// skew-symmetric expansion, pattern and integer files, dense arrays; the writers are
// atomic and leave nothing behind when they fail.
#include <gtest/gtest.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <iterator>
#include <limits>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "base/timer.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"
#include "strata/sparse_matrix.hpp"
#include "support/test_support.hpp"

namespace strata {
namespace {

namespace fs = std::filesystem;

// ---------------------------------------------------------------------------------------
// Fixture: a fresh temporary folder per test, removed afterwards
// ---------------------------------------------------------------------------------------

class MatrixMarketTest : public ::testing::Test {
 protected:
  void SetUp() override {
    unsigned long long seed = 0;
    auto rng = test::fresh_rng(&seed);
    dir_ = fs::temp_directory_path() /
           ("strata_mm_test_" + std::to_string(::getpid()) + "_" + std::to_string(rng()));
    fs::create_directories(dir_);
  }
  void TearDown() override {
    std::error_code ec;
    fs::remove_all(dir_, ec);
  }

  std::string path(const std::string& name) const { return (dir_ / name).string(); }

  // Writes TEXT to a file NAME in the temporary folder; returns its path.
  std::string write_text(const std::string& name, const std::string& text) const {
    const std::string p = path(name);
    std::ofstream out(p, std::ios::binary);
    out << text;
    EXPECT_TRUE(out.good()) << p;
    return p;
  }

  // Writes TEXT gzip-compressed through zlib; returns its path.
  std::string write_gz(const std::string& name, const std::string& text) const {
    const std::string p = path(name);
    gzFile f = gzopen(p.c_str(), "wb");
    EXPECT_NE(f, nullptr) << p;
    EXPECT_EQ(gzwrite(f, text.data(), static_cast<unsigned>(text.size())),
              static_cast<int>(text.size()));
    EXPECT_EQ(gzclose(f), Z_OK);
    return p;
  }

  // Names of the files in the temporary folder (sorted).
  std::vector<std::string> listing() const {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir_)) names.push_back(e.path().filename());
    std::sort(names.begin(), names.end());
    return names;
  }

  fs::path dir_;
};

std::string read_bytes(const std::string& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

void write_bytes(const std::string& p, const std::string& bytes) {
  std::ofstream out(p, std::ios::binary | std::ios::trunc);
  out << bytes;
}

// Checks that reading P (sparse and dense readers alike) raises ParseError at LINE with a
// message containing WHAT, and that what() reads "P:LINE: ...".
void expect_parse_error(const std::string& p, index_t line, const std::string& what) {
  for (int dense = 0; dense < 2; ++dense) {
    SCOPED_TRACE(dense ? "read_dense_matrix_market" : "read_matrix_market");
    try {
      if (dense) {
        index_t r = -1, c = -1;
        (void)read_dense_matrix_market(p, &r, &c);
      } else {
        (void)read_matrix_market(p);
      }
      ADD_FAILURE() << p << ": no ParseError (expected line " << line << ", '" << what << "')";
    } catch (const ParseError& e) {
      EXPECT_EQ(e.file(), p);
      EXPECT_EQ(e.line(), line) << e.what();
      EXPECT_NE(std::string(e.what()).find(what), std::string::npos)
          << "message '" << e.what() << "' lacks '" << what << "'";
      EXPECT_EQ(std::string(e.what()).rfind(p + ":" + std::to_string(line) + ": ", 0), 0u)
          << e.what();
    } catch (const std::exception& e) {
      ADD_FAILURE() << p << ": expected ParseError, got: " << e.what();
    }
  }
}

bool bitwise_equal(const std::vector<double>& a, const std::vector<double>& b) {
  if (a.size() != b.size()) return false;
  for (size_t k = 0; k < a.size(); ++k)
    if (std::bit_cast<std::uint64_t>(a[k]) != std::bit_cast<std::uint64_t>(b[k])) return false;
  return true;
}

void expect_same_matrix(const SparseMatrix& got, const SparseMatrix& want) {
  EXPECT_EQ(got.n_rows, want.n_rows);
  EXPECT_EQ(got.n_cols, want.n_cols);
  EXPECT_EQ(got.layout, Layout::csc);
  EXPECT_EQ(got.storage, want.storage);
  EXPECT_EQ(got.offsets, want.offsets);
  EXPECT_EQ(got.indices, want.indices);
  EXPECT_TRUE(bitwise_equal(got.values, want.values));
}

// A finite double with random bits (all exponents, subnormals, signed zeros).
double random_bits_double(std::mt19937_64& rng) {
  for (;;) {
    const double v = std::bit_cast<double>(rng());
    if (std::isfinite(v)) return v;
  }
}

// ---------------------------------------------------------------------------------------
// The shared matrices
// ---------------------------------------------------------------------------------------

struct Expected {
  index_t n = 0, nnz = 0;
  bool symmetric = false;
};

// Leading integer of a README cell, commas removed ("49,533 (incl. ...)" -> 49533).
index_t readme_number(const std::string& cell) {
  index_t v = 0;
  bool any = false;
  for (char ch : cell) {
    if (ch == ',') continue;
    if (ch < '0' || ch > '9') break;
    v = v * 10 + (ch - '0');
    any = true;
  }
  return any ? v : -1;
}

// The matrix tables of the shared README: name -> n, stored nnz, symmetric. Each table
// has a header row naming its columns ("n", "nnz ...", optionally "storage").
std::map<std::string, Expected> parse_readme(const std::string& p) {
  std::map<std::string, Expected> table;
  std::ifstream in(p);
  std::string line;
  std::vector<std::string> header;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] != '|') {
      header.clear();
      continue;
    }
    std::vector<std::string> cells;
    std::stringstream ss(line.substr(1));
    std::string cell;
    while (std::getline(ss, cell, '|')) {
      const auto b = cell.find_first_not_of(' ');
      const auto e = cell.find_last_not_of(' ');
      cells.push_back(b == std::string::npos ? "" : cell.substr(b, e - b + 1));
    }
    if (cells.empty()) continue;
    if (cells[0] == "name") {
      header = cells;
      continue;
    }
    if (header.empty() || cells[0].rfind("---", 0) == 0) continue;
    int col_n = -1, col_nnz = -1, col_storage = -1;
    for (int k = 0; k < static_cast<int>(header.size()); ++k) {
      if (header[k] == "n") col_n = k;
      if (header[k].rfind("nnz", 0) == 0 && col_nnz < 0) col_nnz = k;
      if (header[k] == "storage") col_storage = k;
    }
    if (col_n < 0 || col_nnz < 0 || col_nnz >= static_cast<int>(cells.size())) continue;
    Expected x;
    x.n = readme_number(cells[col_n]);
    x.nnz = readme_number(cells[col_nnz]);
    x.symmetric = col_storage >= 0 ? cells[col_storage].find("symmetric") != std::string::npos
                                   : header[col_nnz].find("lower") != std::string::npos;
    table[cells[0]] = x;
  }
  return table;
}

TEST(MatrixMarketShared, EveryFileReadsWithReadmeSizes) {
  const auto names = test::shared_matrix_names();
  if (names.empty()) GTEST_SKIP() << "no shared matrices in " << STRATA_MATRIX_DIR;
  const auto table = parse_readme(std::string(STRATA_MATRIX_DIR) + "/README.md");
  ASSERT_FALSE(table.empty()) << "could not read the README table";
  for (const auto& name : names) {
    SCOPED_TRACE(name);
    const auto it = table.find(name);
    ASSERT_NE(it, table.end()) << name << " is not in the README table";
    const MMMatrix m = read_matrix_market(test::matrix_path(name));
    EXPECT_NO_THROW(validate(m.matrix));
    EXPECT_EQ(m.matrix.n_rows, it->second.n);
    EXPECT_EQ(m.matrix.n_cols, it->second.n);
    EXPECT_EQ(m.matrix.nnz(), it->second.nnz);
    EXPECT_FALSE(m.pattern);
    EXPECT_EQ(static_cast<index_t>(m.matrix.values.size()), m.matrix.nnz());
    if (it->second.symmetric) {
      EXPECT_EQ(m.symmetry, MMSymmetry::symmetric);
      EXPECT_EQ(m.matrix.storage, Storage::lower);
    } else {
      EXPECT_EQ(m.symmetry, MMSymmetry::general);
      EXPECT_EQ(m.matrix.storage, Storage::full);
    }
  }
}

TEST(MatrixMarketShared, Ex6KeepsExplicitZeros) {
  const std::string p = test::matrix_path("ex6");
  if (!fs::exists(p)) GTEST_SKIP() << p << " not found";
  const MMMatrix m = read_matrix_market(p);
  index_t zeros = 0;
  for (double v : m.matrix.values) zeros += v == 0.0;
  EXPECT_EQ(zeros, 471);  // README: "49,533 (incl. 471 explicit zeros)"
}

TEST(MatrixMarketShared, LargestReadsQuickly) {
  const std::string p = test::matrix_path("ccx_cubef2f3_K");
  if (!fs::exists(p)) GTEST_SKIP() << p << " not found";
  double best = 1e300;
  MMMatrix m;
  for (int rep = 0; rep < 3; ++rep) {
    Timer t;
    m = read_matrix_market(p);
    best = std::min(best, t.seconds());
  }
  EXPECT_EQ(m.matrix.nnz(), 612672);
  std::cout << "[ timing   ] read_matrix_market(ccx_cubef2f3_K): " << best * 1e3
            << " ms (best of 3)\n";
  ::testing::Test::RecordProperty("ccx_cubef2f3_K_read_ms", std::to_string(best * 1e3));
  // Generous: the target is well under a second; this only catches gross regressions on
  // a loaded machine.
  EXPECT_LT(best, 5.0);
}

// ---------------------------------------------------------------------------------------
// Round trips
// ---------------------------------------------------------------------------------------

TEST_F(MatrixMarketTest, SparseRoundTripIsBitwise) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (index_t n : {1, 2, 3, 5, 733}) {
    for (auto kind : {test::RandomKind::general, test::RandomKind::spd,
                      test::RandomKind::symmetric_indefinite}) {
      for (const char* ext : {".mtx", ".mtx.gz"}) {
        SCOPED_TRACE("n " + std::to_string(n) + " kind " + std::to_string(static_cast<int>(kind)) +
                     " " + ext);
        const SparseMatrix a = test::random_sparse(n, 4, kind, rng);
        const std::string p = path("a" + std::string(ext));
        write_matrix_market(p, a);
        const MMMatrix m = read_matrix_market(p);
        expect_same_matrix(m.matrix, a);
        EXPECT_EQ(m.symmetry,
                  kind == test::RandomKind::general ? MMSymmetry::general : MMSymmetry::symmetric);
        EXPECT_FALSE(m.pattern);
      }
    }
  }
  EXPECT_EQ(listing(), std::vector<std::string>({"a.mtx", "a.mtx.gz"}));  // no temporaries
}

TEST_F(MatrixMarketTest, SparseRoundTripOfExtremeValues) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  SparseMatrix a = test::random_sparse(200, 6, test::RandomKind::general, rng);
  for (double& v : a.values) v = random_bits_double(rng);
  a.values[0] = std::numeric_limits<double>::denorm_min();
  a.values[1] = -0.0;
  a.values[2] = std::numeric_limits<double>::max();
  a.values[3] = -std::numeric_limits<double>::min();
  write_matrix_market(path("x.mtx"), a);
  expect_same_matrix(read_matrix_market(path("x.mtx")).matrix, a);
}

TEST_F(MatrixMarketTest, UpperAndCsrStorageWriteAsLowerTriangle) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const SparseMatrix lower = test::random_sparse(57, 5, test::RandomKind::spd, rng);
  // CSC lower read as CSR is the transpose: the same symmetric matrix, upper storage.
  SparseMatrix upper_csr = lower;
  upper_csr.layout = Layout::csr;
  upper_csr.storage = Storage::upper;
  const SparseMatrix upper_csc = canonicalize(upper_csr);
  ASSERT_EQ(upper_csc.storage, Storage::upper);
  SparseMatrix lower_csr = upper_csc;  // and CSC upper read as CSR is lower storage again
  lower_csr.layout = Layout::csr;
  lower_csr.storage = Storage::lower;
  int k = 0;
  for (const SparseMatrix* a :
       std::vector<const SparseMatrix*>{&upper_csr, &upper_csc, &lower_csr}) {
    SCOPED_TRACE(k);
    const std::string p = path("u" + std::to_string(k++) + ".mtx");
    write_matrix_market(p, *a);
    const MMMatrix m = read_matrix_market(p);
    EXPECT_EQ(m.symmetry, MMSymmetry::symmetric);
    expect_same_matrix(m.matrix, lower);
    EXPECT_NE(read_bytes(p).find("coordinate real symmetric"), std::string::npos);
  }
}

TEST_F(MatrixMarketTest, WriterSumsDuplicatesAndSortsUnsortedInput) {
  SparseMatrix a;
  a.n_rows = 3;
  a.n_cols = 2;
  a.offsets = {0, 3, 4};
  a.indices = {2, 0, 2, 1};
  a.values = {1.0, 2.0, 0.5, -3.0};
  write_matrix_market(path("d.mtx"), a);
  const SparseMatrix b = read_matrix_market(path("d.mtx")).matrix;
  EXPECT_EQ(b.offsets, (std::vector<index_t>{0, 2, 3}));
  EXPECT_EQ(b.indices, (std::vector<index_t>{0, 2, 1}));
  EXPECT_EQ(b.values, (std::vector<double>{2.0, 1.5, -3.0}));
}

TEST_F(MatrixMarketTest, PatternRoundTrip) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (auto kind : {test::RandomKind::general, test::RandomKind::spd}) {
    SparseMatrix a = test::random_sparse(40, 3, kind, rng);
    a.values.clear();
    write_matrix_market(path("p.mtx"), a);
    EXPECT_NE(read_bytes(path("p.mtx")).find("coordinate pattern"), std::string::npos);
    const MMMatrix m = read_matrix_market(path("p.mtx"));
    EXPECT_TRUE(m.pattern);
    EXPECT_EQ(m.matrix.offsets, a.offsets);
    EXPECT_EQ(m.matrix.indices, a.indices);
    EXPECT_EQ(m.matrix.values, std::vector<double>(a.indices.size(), 1.0));
    EXPECT_EQ(m.matrix.storage, a.storage);
  }
}

TEST_F(MatrixMarketTest, EmptyMatrixRoundTrip) {
  SparseMatrix a;
  a.n_rows = 4;
  a.n_cols = 3;
  a.offsets.assign(4, 0);
  write_matrix_market(path("e.mtx"), a);
  const MMMatrix m = read_matrix_market(path("e.mtx"));
  EXPECT_EQ(m.matrix.n_rows, 4);
  EXPECT_EQ(m.matrix.n_cols, 3);
  EXPECT_EQ(m.matrix.nnz(), 0);
  SparseMatrix z;  // 0 x 0
  write_matrix_market(path("z.mtx"), z);
  EXPECT_EQ(read_matrix_market(path("z.mtx")).matrix.n_rows, 0);
}

TEST_F(MatrixMarketTest, DenseRoundTripIsBitwise) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const std::pair<index_t, index_t> shapes[] = {{1, 1}, {2, 1}, {3, 2}, {5, 5}, {733, 3}, {0, 0}};
  for (auto [r, c] : shapes) {
    for (const char* ext : {".mtx", ".mtx.gz"}) {
      SCOPED_TRACE(std::to_string(r) + "x" + std::to_string(c) + ext);
      std::vector<double> v(static_cast<size_t>(r * c));
      for (double& x : v) x = random_bits_double(rng);
      const std::string p = path("b" + std::string(ext));
      write_dense_matrix_market(p, v.data(), r, c);
      index_t rows = -1, cols = -1;
      const std::vector<double> w = read_dense_matrix_market(p, &rows, &cols);
      EXPECT_EQ(rows, r);
      EXPECT_EQ(cols, c);
      EXPECT_TRUE(bitwise_equal(w, v));
    }
  }
  EXPECT_NE(read_bytes(path("b.mtx")).find("%%MatrixMarket matrix array real general"),
            std::string::npos);
}

// ---------------------------------------------------------------------------------------
// Semantics of the reader
// ---------------------------------------------------------------------------------------

TEST_F(MatrixMarketTest, DuplicatesAreSummed) {
  const std::string p = write_text("dup.mtx",
                                   "%%MatrixMarket matrix coordinate real general\n"
                                   "3 3 5\n2 1 1.5\n3 3 1\n2 1 2.25\n1 1 -1\n2 1 0.25\n");
  const SparseMatrix a = read_matrix_market(p).matrix;
  EXPECT_EQ(a.storage, Storage::full);
  EXPECT_EQ(a.offsets, (std::vector<index_t>{0, 2, 2, 3}));
  EXPECT_EQ(a.indices, (std::vector<index_t>{0, 1, 2}));
  EXPECT_EQ(a.values, (std::vector<double>{-1.0, 4.0, 1.0}));
  index_t r = 0, c = 0;
  const std::vector<double> d = read_dense_matrix_market(p, &r, &c);
  EXPECT_EQ(d, (std::vector<double>{-1, 4, 0, 0, 0, 0, 0, 0, 1}));
}

TEST_F(MatrixMarketTest, SymmetricUpperEntriesMoveToLower) {
  const std::string p = write_text("sym.mtx",
                                   "%%MatrixMarket matrix coordinate real symmetric\n"
                                   "3 3 4\n1 2 5.0\n2 1 1.0\n3 3 2.0\n1 3 7\n");
  const MMMatrix m = read_matrix_market(p);
  EXPECT_EQ(m.symmetry, MMSymmetry::symmetric);
  EXPECT_EQ(m.matrix.storage, Storage::lower);
  EXPECT_EQ(m.matrix.offsets, (std::vector<index_t>{0, 2, 2, 3}));
  EXPECT_EQ(m.matrix.indices, (std::vector<index_t>{1, 2, 2}));
  EXPECT_EQ(m.matrix.values, (std::vector<double>{6.0, 7.0, 2.0}));
  index_t r = 0, c = 0;
  const std::vector<double> d = read_dense_matrix_market(p, &r, &c);
  EXPECT_EQ(d, (std::vector<double>{0, 6, 7, 6, 0, 0, 7, 0, 2}));
}

TEST_F(MatrixMarketTest, SkewSymmetricIsExpanded) {
  const std::string p = write_text("skew.mtx",
                                   "%%MatrixMarket matrix coordinate real skew-symmetric\n"
                                   "3 3 2\n2 1 4.0\n1 3 -2.0\n");
  const MMMatrix m = read_matrix_market(p);
  EXPECT_EQ(m.symmetry, MMSymmetry::skew_symmetric);
  EXPECT_EQ(m.matrix.storage, Storage::full);
  EXPECT_EQ(test::to_dense(m.matrix), (std::vector<double>{0, 4, 2, -4, 0, 0, -2, 0, 0}));
  index_t r = 0, c = 0;
  EXPECT_EQ(read_dense_matrix_market(p, &r, &c), test::to_dense(m.matrix));
}

TEST_F(MatrixMarketTest, PatternFiles) {
  const std::string p = write_text("pat.mtx",
                                   "%%MatrixMarket matrix coordinate pattern general\n"
                                   "3 2 4\n1 1\n3 2\n3 2\n2 1\n");
  const MMMatrix m = read_matrix_market(p);
  EXPECT_TRUE(m.pattern);
  EXPECT_EQ(m.matrix.offsets, (std::vector<index_t>{0, 2, 3}));
  EXPECT_EQ(m.matrix.indices, (std::vector<index_t>{0, 1, 2}));
  EXPECT_EQ(m.matrix.values, (std::vector<double>{1, 1, 1}));  // duplicates merged, not 2
  index_t r = 0, c = 0;
  EXPECT_EQ(read_dense_matrix_market(p, &r, &c), (std::vector<double>{1, 1, 0, 0, 0, 1}));

  const std::string q = write_text("patsym.mtx",
                                   "%%MatrixMarket matrix coordinate pattern symmetric\n"
                                   "2 2 2\n1 2\n2 2\n");
  const MMMatrix s = read_matrix_market(q);
  EXPECT_TRUE(s.pattern);
  EXPECT_EQ(s.matrix.storage, Storage::lower);
  EXPECT_EQ(s.matrix.indices, (std::vector<index_t>{1, 1}));
  EXPECT_EQ(read_dense_matrix_market(q, &r, &c), (std::vector<double>{0, 1, 1, 1}));
}

TEST_F(MatrixMarketTest, IntegerField) {
  const std::string p = write_text("int.mtx",
                                   "%%MatrixMarket matrix coordinate integer general\n"
                                   "2 2 2\n1 2 -7\n2 2 +3\n");
  const SparseMatrix a = read_matrix_market(p).matrix;
  EXPECT_EQ(a.values, (std::vector<double>{-7.0, 3.0}));
}

TEST_F(MatrixMarketTest, LenientLayout) {
  // Upper-case keywords, "double", comments and blank lines before the size line and
  // among the entries, tabs, CRLF line ends, leading '+', Fortran 'D' exponents, leading
  // white space, no final newline, a value that underflows to zero.
  const std::string p = write_text("lenient.mtx",
                                   "%%MATRIXMARKET Matrix COORDINATE Double GENERAL\r\n"
                                   "% a comment\r\n"
                                   "\r\n"
                                   "   %   an indented comment\r\n"
                                   "  3\t3   5  \r\n"
                                   "1 1 +1.5\r\n"
                                   "\r\n"
                                   "% comment among the entries\r\n"
                                   "\t2\t2\t2.5D+01\r\n"
                                   "3 3 -1.25d-1\r\n"
                                   "3 1 1e-400\r\n"
                                   "1 3 4.9406564584124654e-324");
  const SparseMatrix a = read_matrix_market(p).matrix;
  EXPECT_EQ(a.indices, (std::vector<index_t>{0, 2, 1, 0, 2}));
  EXPECT_EQ(a.values[0], 1.5);
  EXPECT_EQ(a.values[1], 0.0);
  EXPECT_EQ(a.values[2], 25.0);
  EXPECT_EQ(a.values[3], std::numeric_limits<double>::denorm_min());
  EXPECT_EQ(a.values[4], -0.125);
}

// Lines longer than the reader's block buffer (1 MiB) make it grow; lines that straddle
// block boundaries are covered by the shared matrices (18 MB decompressed).
TEST_F(MatrixMarketTest, VeryLongLines) {
  const std::string comment = "%" + std::string(3 << 20, 'c') + "\n";
  const std::string text = "%%MatrixMarket matrix coordinate real general\n" + comment + "2 2 2\n" +
                           comment + "1 1 " + std::string(2 << 20, ' ') + "0.5\n2 2 2\n";
  for (const std::string& p : {write_text("long.mtx", text), write_gz("long.mtx.gz", text)}) {
    const SparseMatrix a = read_matrix_market(p).matrix;
    EXPECT_EQ(a.values, (std::vector<double>{0.5, 2.0}));
  }
  expect_parse_error(write_text("long_bad.mtx", text + "1 1 1\n"), 7, "more entries");
}

TEST_F(MatrixMarketTest, DenseArrays) {
  index_t r = 0, c = 0;
  const std::string g = write_text("g.mtx",
                                   "%%MatrixMarket matrix array real general\n"
                                   "% right-hand sides\n3 2\n1\n2\n3\n4\n5\n6\n");
  EXPECT_EQ(read_dense_matrix_market(g, &r, &c), (std::vector<double>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(r, 3);
  EXPECT_EQ(c, 2);
  // A sparse read of an array keeps the nonzero values.
  const std::string z = write_text("z.mtx",
                                   "%%MatrixMarket matrix array integer general\n"
                                   "2 2\n1\n0\n0\n4\n");
  const MMMatrix m = read_matrix_market(z);
  EXPECT_EQ(m.matrix.indices, (std::vector<index_t>{0, 1}));
  EXPECT_EQ(m.matrix.values, (std::vector<double>{1, 4}));
  // Symmetric and skew-symmetric arrays give a triangle, column by column.
  const std::string s = write_text("s.mtx",
                                   "%%MatrixMarket matrix array real symmetric\n"
                                   "2 2\n1\n2\n3\n");
  EXPECT_EQ(read_dense_matrix_market(s, &r, &c), (std::vector<double>{1, 2, 2, 3}));
  EXPECT_EQ(read_matrix_market(s).matrix.storage, Storage::lower);
  const std::string k = write_text("k.mtx",
                                   "%%MatrixMarket matrix array real skew-symmetric\n"
                                   "3 3\n1\n2\n3\n");
  EXPECT_EQ(read_dense_matrix_market(k, &r, &c),
            (std::vector<double>{0, 1, 2, -1, 0, 3, -2, -3, 0}));
  EXPECT_EQ(test::to_dense(read_matrix_market(k).matrix),
            (std::vector<double>{0, 1, 2, -1, 0, 3, -2, -3, 0}));
}

TEST_F(MatrixMarketTest, ComplexAndHermitianAreNotSupported) {
  const std::string c = write_text("c.mtx",
                                   "%%MatrixMarket matrix coordinate complex general\n"
                                   "1 1 1\n1 1 1.0 2.0\n");
  const std::string h = write_text("h.mtx",
                                   "%%MatrixMarket matrix coordinate real hermitian\n"
                                   "1 1 1\n1 1 1.0\n");
  for (const auto& p : {c, h}) {
    try {
      (void)read_matrix_market(p);
      ADD_FAILURE() << p << ": no NotSupported";
    } catch (const NotSupported& e) {
      EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
    }
    index_t r = 0, cc = 0;
    EXPECT_THROW((void)read_dense_matrix_market(p, &r, &cc), NotSupported);
  }
}

// ---------------------------------------------------------------------------------------
// Malformed files
// ---------------------------------------------------------------------------------------

struct BadCase {
  const char* name;
  std::string text;
  index_t line;
  const char* message;
};

TEST_F(MatrixMarketTest, MalformedFilesRaiseParseErrorAtTheLine) {
  const std::string G = "%%MatrixMarket matrix coordinate real general\n";
  const std::string S = "%%MatrixMarket matrix coordinate real symmetric\n";
  const std::string K = "%%MatrixMarket matrix coordinate real skew-symmetric\n";
  const std::string A = "%%MatrixMarket matrix array real general\n";
  const std::vector<BadCase> cases = {
      // banner
      {"empty", "", 1, "empty file"},
      {"no_banner", "3 3 1\n1 1 1.0\n", 1, "missing %%MatrixMarket banner"},
      {"banner_typo", "%%MatrixMarkt matrix coordinate real general\n3 3 0\n", 1,
       "missing %%MatrixMarket banner"},
      {"banner_not_first", "% comment\n" + G + "3 3 0\n", 1, "missing %%MatrixMarket banner"},
      {"banner_short", "%%MatrixMarket matrix coordinate real\n3 3 0\n", 1, "incomplete banner"},
      {"banner_extra", "%%MatrixMarket matrix coordinate real general x\n3 3 0\n", 1,
       "unexpected text 'x' in the banner"},
      {"object", "%%MatrixMarket vector coordinate real general\n3 3 0\n", 1,
       "unknown object 'vector'"},
      {"format", "%%MatrixMarket matrix sparse real general\n3 3 0\n", 1,
       "unknown format 'sparse'"},
      {"field", "%%MatrixMarket matrix coordinate float general\n3 3 0\n", 1,
       "unknown field 'float'"},
      {"symmetry", "%%MatrixMarket matrix coordinate real diagonal\n3 3 0\n", 1,
       "unknown symmetry 'diagonal'"},
      {"array_pattern", "%%MatrixMarket matrix array pattern general\n2 2\n", 1,
       "cannot be 'pattern'"},
      {"pattern_skew", "%%MatrixMarket matrix coordinate pattern skew-symmetric\n2 2 0\n", 1,
       "cannot be 'skew-symmetric'"},
      // size line
      {"no_size_line", G + "% only comments\n\n", 4, "missing size line"},
      {"size_non_numeric", G + "% c\n3 x 4\n", 3, "column count 'x' is not an integer"},
      {"size_float", G + "3.0 3 1\n", 2, "row count '3.0' is not an integer"},
      {"size_negative", G + "-3 3 1\n", 2, "negative row count -3"},
      {"size_negative_nnz", G + "3 3 -1\n", 2, "negative entry count -1"},
      {"size_too_few", G + "3 3\n1 1 1.0\n", 2, "missing the entry count"},
      {"size_trailing", G + "3 3 1 7\n1 1 1.0\n", 2, "unexpected text '7'"},
      {"array_size_trailing", A + "2 2 4\n", 2, "unexpected text '4'"},
      {"symmetric_not_square", S + "3 4 1\n1 1 1.0\n", 2, "must be square, not 3x4"},
      {"skew_not_square", K + "4 3 0\n", 2, "must be square"},
      // entries
      {"too_few_fields", G + "3 3 2\n1 1 1.0\n2 1\n", 4, "too few fields"},
      {"only_one_field", G + "3 3 1\n2\n", 3, "too few fields"},
      {"non_numeric_value", G + "3 3 1\n1 1 abc\n", 3, "non-numeric value 'abc'"},
      {"value_with_junk", G + "3 3 1\n1 1 1.5x\n", 3, "non-numeric value '1.5x'"},
      {"hex_value", G + "3 3 1\n1 1 0x1p3\n", 3, "non-numeric value '0x1p3'"},
      {"trailing_garbage", G + "3 3 1\n1 1 1.0 2.0\n", 3, "unexpected text '2.0' after the entry"},
      {"trailing_comment", G + "3 3 1\n1 1 1.0 % note\n", 3, "unexpected text '%'"},
      {"row_zero", G + "3 3 1\n0 1 1.0\n", 3, "row index 0 is out of range 1..3"},
      {"row_negative", G + "3 3 1\n-1 1 1.0\n", 3, "row index -1 is out of range 1..3"},
      {"row_too_big", G + "3 4 1\n4 1 1.0\n", 3, "row index 4 is out of range 1..3"},
      {"column_too_big", G + "3 4 2\n1 1 1.0\n1 5 1.0\n", 4, "column index 5 is out of range 1..4"},
      {"index_float", G + "3 3 1\n1.5 1 1.0\n", 3, "bad row index '1.5'"},
      {"index_overflow", G + "3 3 1\n1 99999999999999999999 1.0\n", 3, "bad column index"},
      {"nan", G + "3 3 2\n1 1 1.0\n2 2 nan\n", 4, "'nan' is NaN or Inf"},
      {"inf", G + "3 3 1\n1 1 -Inf\n", 3, "is NaN or Inf"},
      {"overflow", G + "3 3 1\n1 1 1e999\n", 3, "out of the range of a double"},
      {"fewer_entries", G + "3 3 3\n1 1 1.0\n2 2 2.0\n", 5, "expected 3 entries, found 2"},
      {"fewer_with_blank_end", G + "3 3 3\n1 1 1.0\n\n", 5, "expected 3 entries, found 1"},
      {"fewer_no_newline", G + "3 3 2\n1 1 1.0", 4, "expected 2 entries, found 1"},
      {"more_entries", G + "3 3 1\n1 1 1.0\n2 2 2.0\n", 4, "more entries than the 1 declared"},
      {"skew_diagonal", K + "3 3 2\n2 1 1.0\n2 2 1.0\n", 4, "diagonal entry (2)"},
      {"integer_field_real_value",
       "%%MatrixMarket matrix coordinate integer general\n3 3 1\n1 1 1.5\n", 3,
       "'1.5' is not an integer"},
      {"pattern_with_value", "%%MatrixMarket matrix coordinate pattern general\n3 3 1\n1 1 1.0\n",
       3, "unexpected text '1.0'"},
      {"crlf_line_count",
       "%%MatrixMarket matrix coordinate real general\r\n% c\r\n3 3 2\r\n"
       "1 1 1.0\r\n1 2 x\r\n",
       5, "non-numeric value 'x'"},
      // arrays
      {"array_fewer", A + "2 2\n1\n2\n3\n", 6, "expected 4 entries, found 3"},
      {"array_more", A + "2 1\n1\n2\n3\n", 5, "more entries than the 2 declared"},
      {"array_two_per_line", A + "2 1\n1 2\n", 3, "unexpected text '2'"},
      {"array_nan", A + "1 1\nNaN\n", 3, "is NaN or Inf"},
      {"array_symmetric_not_square", "%%MatrixMarket matrix array real symmetric\n2 3\n", 2,
       "must be square"},
      // found by fuzzing (docs/reliability.md): dimensions whose offsets cannot exist;
      // INT64_MAX used to overflow `n + 1` (UBSan) on its way to a length_error
      {"rows_int64_max", G + "9223372036854775807 1 0\n", 2,
       "row count 9223372036854775807 exceeds the largest supported dimension"},
      {"cols_2_60", G + "1 1152921504606846976 0\n", 2,
       "column count 1152921504606846976 exceeds the largest supported dimension"},
      // duplicates (or both triangles of a symmetric file) summing past DBL_MAX used to
      // give a matrix holding Inf; no single line is to blame (line 0)
      {"duplicates_overflow", G + "2 2 2\n1 1 1e308\n1 1 1e308\n", 0,
       "entries at (1, 1) (1-based) sum past the range of a double"},
      {"symmetric_both_triangles_overflow", S + "2 2 2\n2 1 -1.7e308\n1 2 -1.7e308\n", 0,
       "entries at (2, 1) (1-based) sum past the range of a double"},
  };
  for (const BadCase& c : cases) {
    SCOPED_TRACE(c.name);
    expect_parse_error(write_text(std::string(c.name) + ".mtx", c.text), c.line, c.message);
  }
  // The same errors come through the gzip path.
  expect_parse_error(write_gz("nan.mtx.gz", G + "3 3 2\n1 1 1.0\n2 2 nan\n"), 4, "NaN or Inf");
  expect_parse_error(write_gz("short.mtx.gz", G + "3 3 3\n1 1 1.0\n"), 4,
                     "expected 3 entries, found 1");
}

// Found by fuzzing: a size line may declare dimensions whose compressed offsets alone
// need more memory than any machine has (1e15 columns: 8 PB, beyond the address space).
// The reader raises OutOfMemory naming the file, not std::bad_alloc.
TEST_F(MatrixMarketTest, HugeDeclaredDimensionsAreOutOfMemory) {
#if STRATA_TEST_HAS_ASAN
  GTEST_SKIP() << "under AddressSanitizer, operator new aborts on an allocation it cannot "
                  "satisfy instead of throwing std::bad_alloc";
#endif
  const std::string file = write_text(
      "huge.mtx", "%%MatrixMarket matrix coordinate real general\n1 1000000000000000 0\n");
  try {
    read_matrix_market(file);
    FAIL() << "expected OutOfMemory";
  } catch (const OutOfMemory& e) {
    EXPECT_NE(std::string(e.what()).find("huge.mtx"), std::string::npos) << e.what();
    EXPECT_GE(e.bytes_requested(), size_t{8000000000000000});
  }
}

TEST_F(MatrixMarketTest, MissingFileIsParseErrorAtLineZero) {
  expect_parse_error(path("no_such_file.mtx.gz"), 0, "cannot open");
}

// A valid .gz file cut short: the partial last line must not be parsed (a number could be
// cut in half); the error names the line after the last complete one.
TEST_F(MatrixMarketTest, TruncatedGzipFile) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  const index_t declared = 3000;
  std::string text = "%%MatrixMarket matrix coordinate real general\n% header\n300 300 " +
                     std::to_string(declared) + "\n";
  std::uniform_int_distribution<int> idx(1, 300);
  for (index_t k = 0; k < declared; ++k) {
    char buf[96];
    std::snprintf(buf, sizeof buf, "%d %d %.17g\n", idx(rng), idx(rng), random_bits_double(rng));
    text += buf;
  }
  const std::string p = write_gz("t.mtx.gz", text);
  const std::string full = read_bytes(p);
  ASSERT_NO_THROW((void)read_matrix_market(p));

  for (const size_t keep : {full.size() / 2, full.size() / 5, full.size() - 4}) {
    SCOPED_TRACE("keep " + std::to_string(keep) + " of " + std::to_string(full.size()) + " bytes");
    write_bytes(p, full.substr(0, keep));
    // What zlib can still decompress: count its complete lines.
    std::string partial;
    gzFile f = gzopen(p.c_str(), "rb");
    ASSERT_NE(f, nullptr);
    char buf[1 << 16];
    int got;
    while ((got = gzread(f, buf, sizeof buf)) > 0) partial.append(buf, got);
    gzclose(f);
    const index_t complete = std::count(partial.begin(), partial.end(), '\n');
    const index_t entries = complete - 3;
    if (entries < declared) {
      expect_parse_error(p, complete + 1,
                         "expected " + std::to_string(declared) + " entries, found " +
                             std::to_string(entries) + " (compressed data ends early");
    } else {
      // Only the gzip trailer is missing: every entry is there, but the file is still
      // reported as truncated.
      expect_parse_error(p, complete + 1, "truncated");
    }
  }
}

TEST_F(MatrixMarketTest, CorruptGzipFile) {
  const std::string p =
      write_gz("bad.mtx.gz", "%%MatrixMarket matrix coordinate real general\n2 2 1\n1 1 1\n");
  std::string bytes = read_bytes(p);
  bytes[bytes.size() - 6] ^= 0x5a;  // inside the CRC-32 of the trailer
  write_bytes(p, bytes);
  EXPECT_THROW((void)read_matrix_market(p), ParseError);
  try {
    (void)read_matrix_market(p);
  } catch (const ParseError& e) {
    EXPECT_NE(std::string(e.what()).find("corrupt compressed data"), std::string::npos) << e.what();
  }
}

// Several gzip members read as one stream (RFC 1952); anything else after the last
// member is an error naming the file (zlib's gzread would skip it).
TEST_F(MatrixMarketTest, GzipMembersAndTrailingData) {
  const std::string head = "%%MatrixMarket matrix coordinate real general\n2 2 2\n";
  const std::string a = write_gz("a.gz", head + "1 1 1.5\n");
  const std::string b = write_gz("b.gz", "2 2 2.5\n");
  const std::string both = path("both.mtx.gz");
  write_bytes(both, read_bytes(a) + read_bytes(b));
  const MMMatrix m = read_matrix_market(both);
  ASSERT_EQ(m.matrix.nnz(), 2);
  EXPECT_EQ(m.matrix.values[1], 2.5);
  for (const std::string& tail :
       {std::string("garbage"), std::string(4, '\0'), std::string("\x1f"), std::string("\n")}) {
    SCOPED_TRACE("tail of " + std::to_string(tail.size()) + " bytes");
    const std::string p = path("trail.mtx.gz");
    write_bytes(p, read_bytes(both) + tail);
    expect_parse_error(p, 0, "trailing data after the end of the compressed stream");
  }
  // a plain file is read as it is, whatever its name
  const std::string plain = write_text("plain.mtx.gz", head + "1 1 1\n2 2 2\n");
  EXPECT_EQ(read_matrix_market(plain).matrix.nnz(), 2);
}

// MMCheck::factorable: square, no empty row or column (named 1-based, the file named),
// decided from the entries before the O(n) compressed form exists.
TEST_F(MatrixMarketTest, FactorableCheck) {
  auto refused = [&](const std::string& name, const std::string& text, const std::string& what) {
    const std::string p = write_text(name, text);
    EXPECT_NO_THROW((void)read_matrix_market(p));  // any matrix, unchecked
    try {
      (void)read_matrix_market(p, MMCheck::factorable);
      ADD_FAILURE() << name << ": not refused";
    } catch (const ParseError& e) {
      ADD_FAILURE() << "not a parse error: " << e.what();
    } catch (const InvalidInput& e) {
      EXPECT_EQ(std::string(e.what()), p + ": " + what);
    }
  };
  const std::string G = "%%MatrixMarket matrix coordinate real general\n";
  const std::string S = "%%MatrixMarket matrix coordinate real symmetric\n";
  refused("rect.mtx", G + "2 3 2\n1 1 1\n2 2 1\n", "matrix is 2x3, not square");
  refused("col.mtx", G + "3 3 3\n1 1 1\n2 1 1\n3 3 1\n",
          "matrix is structurally singular: column 2 (1-based) has no entries");
  refused("row.mtx", G + "3 3 3\n1 1 1\n1 2 1\n3 3 1\n",
          "matrix is structurally singular: row 2 (1-based) has no entries");
  refused("sym.mtx", S + "4 4 2\n2 1 1\n4 4 1\n",
          "matrix is structurally singular: column 3 (1-based) has no entries");
  refused("arr.mtx", "%%MatrixMarket matrix array real general\n2 2\n1\n0\n0\n0\n",
          "matrix is structurally singular: column 2 (1-based) has no entries");
  // a symmetric entry covers its mirror: rows/columns 1 and 2 both have entries
  const std::string ok = write_text("ok.mtx", S + "2 2 1\n2 1 1\n");
  EXPECT_EQ(read_matrix_market(ok, MMCheck::factorable).matrix.nnz(), 1);
  for (index_t n : {1, 2, 3, 5, 733}) {
    std::string text =
        G + std::to_string(n) + " " + std::to_string(n) + " " + std::to_string(n) + "\n";
    for (index_t i = n; i >= 1; --i)  // an anti-diagonal: a permutation, nonsingular
      text += std::to_string(i) + " " + std::to_string(n + 1 - i) + " 1\n";
    EXPECT_EQ(read_matrix_market(write_text("perm.mtx", text), MMCheck::factorable).matrix.nnz(),
              n);
  }
}

// A file of a few bytes declaring a 2·10⁸ × 2·10⁸ matrix is refused at once, in O(entries)
// memory: the growth of a child process's peak resident set (getrusage) stays far below
// the 1.6 GB that 2·10⁸ offsets would take.
TEST_F(MatrixMarketTest, HugeDeclaredSizeRefusedInSmallMemory) {
  const std::string p =
      write_text("huge.mtx",
                 "%%MatrixMarket matrix coordinate real general\n200000000 200000000 1\n1 1 1.0\n");
  auto resident_kb = [] {  // the current resident set, from /proc/self/statm
    std::ifstream in("/proc/self/statm");
    long size = 0, resident = 0;
    in >> size >> resident;
    return resident * (sysconf(_SC_PAGESIZE) / 1024);
  };
  const long before_kb = resident_kb();
  const pid_t child = fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    int code = 3;
    try {
      (void)read_matrix_market(p, MMCheck::factorable);
      code = 1;
    } catch (const InvalidInput& e) {
      code = std::string(e.what()).find("structurally singular") != std::string::npos ? 0 : 2;
    } catch (...) {
    }
    _exit(code);
  }
  int status = 0;
  struct rusage ru {};
  ASSERT_EQ(wait4(child, &status, 0, &ru), child);
  ASSERT_TRUE(WIFEXITED(status));
  EXPECT_EQ(WEXITSTATUS(status), 0) << "1: accepted, 2: another message, 3: another error";
  const long growth_kb = ru.ru_maxrss - before_kb;
  EXPECT_LT(growth_kb, 100 * 1024)
      << "peak " << ru.ru_maxrss << " kB, " << before_kb << " kB before";
}

// ---------------------------------------------------------------------------------------
// The atomic writers
// ---------------------------------------------------------------------------------------

TEST_F(MatrixMarketTest, WriterIntoMissingFolderThrowsAndLeavesNothing) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = test::random_sparse(10, 2, test::RandomKind::general, rng);
  const std::string p = path("no_such_dir/a.mtx");
  try {
    write_matrix_market(p, a);
    ADD_FAILURE() << "no exception";
  } catch (const ParseError& e) {
    ADD_FAILURE() << "a write failure is not a ParseError: " << e.what();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(p), std::string::npos) << e.what();
  }
  const double v[2] = {1.0, 2.0};
  EXPECT_THROW(write_dense_matrix_market(p, v, 2, 1), Error);
  EXPECT_FALSE(fs::exists(path("no_such_dir")));
  EXPECT_TRUE(listing().empty());
}

TEST_F(MatrixMarketTest, WriterOntoADirectoryThrowsAndRemovesItsTemporary) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = test::random_sparse(10, 2, test::RandomKind::general, rng);
  fs::create_directory(path("target.mtx"));
  try {
    write_matrix_market(path("target.mtx"), a);
    ADD_FAILURE() << "no exception";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find(path("target.mtx")), std::string::npos) << e.what();
  }
  const double v[1] = {1.0};
  EXPECT_THROW(write_dense_matrix_market(path("target.mtx"), v, 1, 1), Error);
  EXPECT_EQ(listing(), std::vector<std::string>({"target.mtx"}));
  EXPECT_TRUE(fs::is_directory(path("target.mtx")));
}

TEST_F(MatrixMarketTest, WriterReplacesAnExistingFile) {
  auto rng = test::fresh_rng();
  const SparseMatrix a = test::random_sparse(30, 3, test::RandomKind::general, rng);
  const SparseMatrix b = test::random_sparse(7, 2, test::RandomKind::spd, rng);
  write_text("m.mtx", "old contents\n");
  write_matrix_market(path("m.mtx"), a);
  expect_same_matrix(read_matrix_market(path("m.mtx")).matrix, a);
  write_matrix_market(path("m.mtx"), b);
  expect_same_matrix(read_matrix_market(path("m.mtx")).matrix, b);
  EXPECT_EQ(listing(), std::vector<std::string>({"m.mtx"}));
}

TEST_F(MatrixMarketTest, WritersRejectInvalidInputWithoutCreatingAFile) {
  SparseMatrix a;
  a.n_rows = a.n_cols = 2;
  a.offsets = {0, 1, 2};
  a.indices = {0, 5};  // out of range
  a.values = {1.0, 2.0};
  EXPECT_THROW(write_matrix_market(path("bad.mtx"), a), InvalidInput);
  a.indices = {0, 1};
  a.values[1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(write_matrix_market(path("bad.mtx"), a), InvalidInput);
  const double v[2] = {1.0, std::numeric_limits<double>::infinity()};
  EXPECT_THROW(write_dense_matrix_market(path("bad.mtx"), v, 2, 1), InvalidInput);
  EXPECT_THROW(write_dense_matrix_market(path("bad.mtx"), v, -1, 1), InvalidInput);
  EXPECT_TRUE(listing().empty());
}

}  // namespace
}  // namespace strata
