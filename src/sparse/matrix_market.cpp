// strata — Matrix Market input and output (see include/strata/matrix_market.hpp).
//
// What. The Matrix Market exchange format (NIST, https://math.nist.gov/MatrixMarket/
// formats.html) is the text format of the SuiteSparse Matrix Collection and of most
// sparse test sets. A file is
//
//     %%MatrixMarket matrix <format> <field> <symmetry>     banner, line 1
//     % comment lines ...                                    any number, also blank lines
//     M N NNZ            (coordinate)   or   M N   (array)   size line
//     i j value          (coordinate: NNZ entry lines, 1-based indices; pattern: "i j")
//     value              (array: the values column by column, one per line)
//
// with <format> coordinate | array, <field> real | double | integer | pattern | complex,
// <symmetry> general | symmetric | skew-symmetric | hermitian. Keywords are matched
// case-insensitively. For symmetric and skew-symmetric files only one triangle is given
// (the spec says the lower one; entries given above the diagonal are accepted and moved
// to the lower triangle, where they are summed with any entry already there). A
// skew-symmetric matrix has a zero diagonal, so a diagonal entry in such a file is an
// error. Complex and Hermitian files are NotSupported: strata solves real systems.
//
// Why this shape. Every test matrix, every benchmark and the command line go through
// this reader, so it has to be strict (a malformed file must never turn into a silently
// wrong matrix: every problem is a ParseError naming the file and the 1-based line) and
// fast (the largest shared matrix has 612k entries). Lines come from
// sparse/compressed_lines.hpp (large blocks, gzip or plain, a truncated ".gz" file
// detected) as string_views and numbers are parsed with std::from_chars — no iostreams, no
// per-token allocation. The entries are collected as triplets and turned into canonical
// CSC by one bucket pass plus strata::canonicalize (sorts, sums duplicates, validates).
//
// Memory is bounded by the input: the size line may declare any dimensions, but nothing
// of O(rows + columns) is allocated until the entries are read and, for a matrix that is
// to be factored (MMRead::square_structurally_nonsingular), checked in O(entries) memory:
// a square matrix with fewer distinct rows or columns than its dimension is structurally
// singular and refused, naming the first empty column, before its compressed form exists.
//
// The writers are in matrix_market_write.cpp.
#include "strata/matrix_market.hpp"

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <new>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "sparse/compressed_lines.hpp"
#include "strata/errors.hpp"

namespace strata {
namespace {

using detail::LineReader;

// ---------------------------------------------------------------------------------------
// Small text helpers
// ---------------------------------------------------------------------------------------

// White space inside a line ('\n' ends lines and never reaches the parsers).
inline bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

bool iequals(std::string_view a, std::string_view b) {
  if (a.size() != b.size()) return false;
  for (size_t i = 0; i < a.size(); ++i) {
    char x = a[i], y = b[i];
    if (x >= 'A' && x <= 'Z') x = static_cast<char>(x - 'A' + 'a');
    if (y >= 'A' && y <= 'Z') y = static_cast<char>(y - 'A' + 'a');
    if (x != y) return false;
  }
  return true;
}

// Splits off the next white-space-delimited token of [*p, end); empty at end of line.
inline std::string_view next_token(const char*& p, const char* end) {
  while (p < end && is_space(*p)) ++p;
  const char* b = p;
  while (p < end && !is_space(*p)) ++p;
  return {b, static_cast<size_t>(p - b)};
}

// A token quoted for an error message, shortened if it is long.
std::string quoted(std::string_view tok) {
  constexpr size_t kMax = 40;
  if (tok.size() > kMax) return "'" + std::string(tok.substr(0, kMax)) + "...'";
  return "'" + std::string(tok) + "'";
}

// Drops one leading '+' (which C's strtod/scanf accept and from_chars does not), unless
// it is followed by another sign.
inline std::string_view strip_plus(std::string_view tok) {
  if (tok.size() > 1 && tok[0] == '+' && tok[1] != '+' && tok[1] != '-') tok.remove_prefix(1);
  return tok;
}

// Parses a whole token as a base-10 integer.
inline bool parse_int(std::string_view tok, index_t& out) {
  tok = strip_plus(tok);
  if (tok.empty()) return false;
  const auto [ptr, ec] = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return ec == std::errc() && ptr == tok.data() + tok.size();
}

enum class RealStatus { ok, bad, overflow };

// Parses a whole token as a double (C syntax; a Fortran 'D' exponent is accepted too).
// Values too small for a double underflow to a subnormal or zero as strtod does; values
// too large are `overflow`. NaN and Inf are parsed and left to the caller to reject.
RealStatus parse_real(std::string_view tok, double& out) {
  tok = strip_plus(tok);
  if (tok.empty()) return RealStatus::bad;
  const char* b = tok.data();
  const char* e = b + tok.size();
  std::from_chars_result r = std::from_chars(b, e, out);
  if (r.ec == std::errc() && r.ptr == e) return RealStatus::ok;
  // Slow paths on a NUL-terminated copy: Fortran exponents and out-of-range values.
  if (r.ec == std::errc::invalid_argument) return RealStatus::bad;
  std::string copy(tok);
  if (r.ec == std::errc() && (*r.ptr == 'd' || *r.ptr == 'D')) {
    copy[r.ptr - b] = 'e';
    r = std::from_chars(copy.data(), copy.data() + copy.size(), out);
    if (r.ptr != copy.data() + copy.size()) return RealStatus::bad;
    if (r.ec == std::errc()) return RealStatus::ok;
    if (r.ec != std::errc::result_out_of_range) return RealStatus::bad;
  } else if (r.ec == std::errc() || r.ptr != e) {
    return RealStatus::bad;  // a number followed by other characters
  }
  // result_out_of_range: let strtod decide between underflow (accepted) and overflow.
  char* stop = nullptr;
  errno = 0;
  out = std::strtod(copy.c_str(), &stop);
  if (stop != copy.c_str() + copy.size()) return RealStatus::bad;
  if (std::isinf(out)) return RealStatus::overflow;
  return RealStatus::ok;
}

// ---------------------------------------------------------------------------------------
// The parser: banner, size line, entries
// ---------------------------------------------------------------------------------------

// The largest row or column count accepted: the compressed offsets of a matrix hold
// dimension + 1 index_t values, and a std::vector<index_t> holds at most about 2^60
// (PTRDIFF_MAX / 8); below this bound dimension + 1 and the bucket counts never
// overflow.
constexpr index_t kMaxDimension = (index_t{1} << 60) - 1;

enum class Format { coordinate, array };
enum class Field { real, integer, pattern };

// Everything read from a file, before it becomes a SparseMatrix or a dense array.
struct Contents {
  Format format = Format::coordinate;
  Field field = Field::real;
  MMSymmetry symmetry = MMSymmetry::general;
  index_t rows = 0, cols = 0;
  index_t declared = 0;  // entries (coordinate) or values (array) the size line promises
  // coordinate: 0-based row and column of each entry as given, value (none for pattern)
  std::vector<index_t> row, col;
  // coordinate: the values; array: the values in file order (column by column)
  std::vector<double> val;
};

const char* symmetry_name(MMSymmetry s) {
  switch (s) {
    case MMSymmetry::general:
      return "general";
    case MMSymmetry::symmetric:
      return "symmetric";
    case MMSymmetry::skew_symmetric:
      return "skew-symmetric";
  }
  return "?";
}

// Parses the banner (line 1) into c.format, c.field, c.symmetry.
void parse_banner(const std::string& path, std::string_view line, bool have_line, Contents& c) {
  const char* usage = "expected '%%MatrixMarket matrix FORMAT FIELD SYMMETRY'";
  if (!have_line) throw ParseError(path, 1, std::string("empty file: ") + usage);
  // A UTF-8 byte order mark is not part of the banner.
  if (line.size() >= 3 && line.substr(0, 3) == "\xEF\xBB\xBF") line.remove_prefix(3);
  const char* p = line.data();
  const char* e = p + line.size();
  std::string_view tok[6];
  int ntok = 0;
  for (; ntok < 6; ++ntok) {
    tok[ntok] = next_token(p, e);
    if (tok[ntok].empty()) break;
  }
  if (ntok == 0 || !iequals(tok[0], "%%MatrixMarket"))
    throw ParseError(path, 1, std::string("missing %%MatrixMarket banner: ") + usage);
  if (ntok < 5)
    throw ParseError(
        path, 1, "incomplete banner (" + std::to_string(ntok - 1) + " of 4 keywords): " + usage);
  if (ntok > 5) throw ParseError(path, 1, "unexpected text " + quoted(tok[5]) + " in the banner");
  if (!iequals(tok[1], "matrix"))
    throw ParseError(path, 1, "unknown object " + quoted(tok[1]) + " (expected 'matrix')");
  if (iequals(tok[2], "coordinate")) {
    c.format = Format::coordinate;
  } else if (iequals(tok[2], "array")) {
    c.format = Format::array;
  } else {
    throw ParseError(path, 1,
                     "unknown format " + quoted(tok[2]) + " (expected 'coordinate' or 'array')");
  }
  const bool complex = iequals(tok[3], "complex");
  if (iequals(tok[3], "real") || iequals(tok[3], "double")) {
    c.field = Field::real;
  } else if (iequals(tok[3], "integer")) {
    c.field = Field::integer;
  } else if (iequals(tok[3], "pattern")) {
    c.field = Field::pattern;
  } else if (!complex) {
    throw ParseError(path, 1,
                     "unknown field " + quoted(tok[3]) +
                         " (expected 'real', 'double', 'integer', 'pattern' or 'complex')");
  }
  const bool hermitian = iequals(tok[4], "hermitian");
  if (iequals(tok[4], "general")) {
    c.symmetry = MMSymmetry::general;
  } else if (iequals(tok[4], "symmetric")) {
    c.symmetry = MMSymmetry::symmetric;
  } else if (iequals(tok[4], "skew-symmetric")) {
    c.symmetry = MMSymmetry::skew_symmetric;
  } else if (!hermitian) {
    throw ParseError(path, 1,
                     "unknown symmetry " + quoted(tok[4]) +
                         " (expected 'general', 'symmetric', 'skew-symmetric' or 'hermitian')");
  }
  if (complex || hermitian)
    throw NotSupported(path + ":1: " + (complex ? "complex" : "Hermitian") +
                       " Matrix Market files are not supported (strata solves real systems)");
  if (c.format == Format::array && c.field == Field::pattern)
    throw ParseError(path, 1, "an 'array' file cannot be 'pattern'");
  if (c.field == Field::pattern && c.symmetry == MMSymmetry::skew_symmetric)
    throw ParseError(path, 1, "a 'pattern' file cannot be 'skew-symmetric'");
}

// Reads the size line (the first line after the banner that is neither blank nor a
// comment) into c.rows, c.cols, c.declared.
void parse_size_line(const std::string& path, LineReader& in, Contents& c) {
  std::string_view line;
  const char* p = nullptr;
  const char* e = nullptr;
  for (;;) {
    if (!in.next(line)) {
      std::string msg = c.format == Format::coordinate ? "missing size line 'ROWS COLS ENTRIES'"
                                                       : "missing size line 'ROWS COLS'";
      if (in.truncated()) msg += " (compressed data ends early: the file is truncated)";
      throw ParseError(path, in.line_no() + 1, msg);
    }
    p = line.data();
    e = p + line.size();
    while (p < e && is_space(*p)) ++p;
    if (p < e && *p != '%') break;
  }
  const index_t ln = in.line_no();
  const int want = c.format == Format::coordinate ? 3 : 2;
  const char* names[3] = {"row count", "column count", "entry count"};
  index_t v[3] = {0, 0, 0};
  for (int k = 0; k < want; ++k) {
    const std::string_view tok = next_token(p, e);
    if (tok.empty())
      throw ParseError(path, ln,
                       std::string("bad size line: expected ") +
                           (want == 3 ? "'ROWS COLS ENTRIES'" : "'ROWS COLS'") + ", missing the " +
                           names[k]);
    if (!parse_int(tok, v[k]))
      throw ParseError(
          path, ln,
          "bad size line: " + std::string(names[k]) + " " + quoted(tok) + " is not an integer");
    if (v[k] < 0)
      throw ParseError(
          path, ln,
          "bad size line: negative " + std::string(names[k]) + " " + std::to_string(v[k]));
    if (k < 2 && v[k] > kMaxDimension)
      throw ParseError(path, ln,
                       "bad size line: " + std::string(names[k]) + " " + std::to_string(v[k]) +
                           " exceeds the largest supported dimension 2^60 - 1");
  }
  const std::string_view extra = next_token(p, e);
  if (!extra.empty()) throw ParseError(path, ln, "bad size line: unexpected text " + quoted(extra));
  c.rows = v[0];
  c.cols = v[1];
  if (c.symmetry != MMSymmetry::general && c.rows != c.cols)
    throw ParseError(path, ln,
                     std::string("a ") + symmetry_name(c.symmetry) +
                         " matrix must be square, not " + std::to_string(c.rows) + "x" +
                         std::to_string(c.cols));
  if (c.format == Format::coordinate) {
    c.declared = v[2];
  } else {
    // An array gives every entry (general), the lower triangle (symmetric) or the
    // strictly lower triangle (skew-symmetric), column by column.
    index_t count = 0;
    const index_t n = c.rows;
    bool overflow = false;
    if (c.symmetry == MMSymmetry::general) {
      overflow = __builtin_mul_overflow(c.rows, c.cols, &count);
    } else if (n > (index_t{1} << 31)) {
      overflow = true;  // n(n±1)/2 values would not fit in memory anyway
    } else {
      count = n * (c.symmetry == MMSymmetry::symmetric ? n + 1 : std::max<index_t>(n - 1, 0)) / 2;
    }
    if (overflow)
      throw ParseError(path, ln,
                       "array dimensions " + std::to_string(c.rows) + "x" + std::to_string(c.cols) +
                           " are too large");
    c.declared = count;
  }
}

// "expected N entries, found M" at the line after the last one read.
[[noreturn]] void throw_too_few(const std::string& path, const LineReader& in, const Contents& c,
                                index_t found) {
  std::string msg =
      "expected " + std::to_string(c.declared) + " entries, found " + std::to_string(found);
  msg += in.truncated() ? " (compressed data ends early: the file is truncated)"
                        : " (the file ends early)";
  throw ParseError(path, in.line_no() + 1, msg);
}

// Parses one value token of an entry line (real or integer field).
inline double parse_value(const std::string& path, index_t ln, std::string_view tok, Field field) {
  double v = 0.0;
  if (field == Field::integer) {
    index_t k = 0;
    if (!parse_int(tok, k))
      throw ParseError(path, ln,
                       "value " + quoted(tok) + " is not an integer (the field is 'integer')");
    return static_cast<double>(k);
  }
  switch (parse_real(tok, v)) {
    case RealStatus::ok:
      break;
    case RealStatus::bad:
      throw ParseError(path, ln, "non-numeric value " + quoted(tok));
    case RealStatus::overflow:
      throw ParseError(path, ln, "value " + quoted(tok) + " is out of the range of a double");
  }
  if (!std::isfinite(v)) throw ParseError(path, ln, "value " + quoted(tok) + " is NaN or Inf");
  return v;
}

// Parses a 1-based index token, checking 1 <= index <= bound; returns it 0-based.
inline index_t parse_index(const std::string& path, index_t ln, std::string_view tok, index_t bound,
                           const char* what) {
  index_t k = 0;
  if (!parse_int(tok, k))
    throw ParseError(path, ln, std::string("bad ") + what + " index " + quoted(tok));
  if (k < 1 || k > bound)
    throw ParseError(path, ln,
                     std::string(what) + " index " + std::to_string(k) + " is out of range 1.." +
                         std::to_string(bound));
  return k - 1;
}

// Reads a whole file. Throws ParseError / NotSupported.
Contents parse_file(const std::string& path) {
  LineReader in(path);
  Contents c;
  std::string_view line;
  const bool have = in.next(line);
  if (!have && in.truncated())
    throw ParseError(path, 1, "compressed data ends early: the file is truncated");
  parse_banner(path, line, have, c);
  parse_size_line(path, in, c);

  // Reserve what the size line promises, within reason: a corrupt size line must not
  // allocate terabytes before the entry count check catches it.
  const size_t reserve = static_cast<size_t>(std::min<index_t>(c.declared, index_t{1} << 22));
  const bool coord = c.format == Format::coordinate;
  const bool values = c.field != Field::pattern;
  if (coord) {
    c.row.reserve(reserve);
    c.col.reserve(reserve);
  }
  if (values) c.val.reserve(reserve);

  const bool skew = c.symmetry == MMSymmetry::skew_symmetric;
  index_t found = 0;
  while (in.next(line)) {
    const char* p = line.data();
    const char* e = p + line.size();
    const std::string_view first = next_token(p, e);
    if (first.empty() || first[0] == '%') continue;  // blank line or comment
    const index_t ln = in.line_no();
    if (found == c.declared)
      throw ParseError(path, ln,
                       "more entries than the " + std::to_string(c.declared) + " declared");
    if (coord) {
      const std::string_view jtok = next_token(p, e);
      const std::string_view vtok = values ? next_token(p, e) : std::string_view("-");
      if (jtok.empty() || vtok.empty())
        throw ParseError(path, ln,
                         std::string("entry has too few fields: expected ") +
                             (values ? "'ROW COLUMN VALUE'" : "'ROW COLUMN'"));
      const index_t i = parse_index(path, ln, first, c.rows, "row");
      const index_t j = parse_index(path, ln, jtok, c.cols, "column");
      if (skew && i == j)
        throw ParseError(path, ln,
                         "diagonal entry (" + std::to_string(i + 1) +
                             ") in a skew-symmetric matrix, whose diagonal is zero");
      c.row.push_back(i);
      c.col.push_back(j);
      if (values) c.val.push_back(parse_value(path, ln, vtok, c.field));
    } else {
      c.val.push_back(parse_value(path, ln, first, c.field));
    }
    const std::string_view extra = next_token(p, e);
    if (!extra.empty())
      throw ParseError(path, ln, "unexpected text " + quoted(extra) + " after the entry");
    ++found;
  }
  if (found < c.declared) throw_too_few(path, in, c, found);
  if (in.truncated())
    throw ParseError(path, in.line_no() + 1,
                     "compressed data ends early after the last entry: the file is truncated");
  return c;
}

// ---------------------------------------------------------------------------------------
// Contents -> SparseMatrix / dense array
// ---------------------------------------------------------------------------------------

// Canonical CSC of the entries in c (coordinate files): symmetric entries moved to the
// lower triangle (Storage::lower), skew-symmetric ones expanded (Storage::full).
SparseMatrix coordinate_to_csc(const Contents& c) {
  const bool values = c.field != Field::pattern;
  const bool sym = c.symmetry == MMSymmetry::symmetric;
  const bool skew = c.symmetry == MMSymmetry::skew_symmetric;
  const size_t m = c.row.size();
  SparseMatrix a;
  a.n_rows = c.rows;
  a.n_cols = c.cols;
  a.layout = Layout::csc;
  a.storage = sym ? Storage::lower : Storage::full;
  // Bucket the entries by column (counting sort); canonicalize sorts and sums.
  std::vector<index_t> count(static_cast<size_t>(c.cols) + 1, 0);
  for (size_t k = 0; k < m; ++k) {
    index_t i = c.row[k], j = c.col[k];
    if (sym && i < j) std::swap(i, j);
    ++count[j + 1];
    if (skew) ++count[i + 1];
  }
  for (index_t j = 0; j < c.cols; ++j) count[j + 1] += count[j];
  a.offsets = count;
  a.indices.resize(count.back());
  if (values) a.values.resize(count.back());
  for (size_t k = 0; k < m; ++k) {
    index_t i = c.row[k], j = c.col[k];
    if (sym && i < j) std::swap(i, j);
    index_t q = count[j]++;
    a.indices[q] = i;
    if (values) a.values[q] = c.val[k];
    if (skew) {
      q = count[i]++;
      a.indices[q] = j;
      a.values[q] = -c.val[k];
    }
  }
  SparseMatrix out = canonicalize(a);
  if (!values) out.values.assign(out.indices.size(), 1.0);  // pattern: duplicates merged
  return out;
}

// Duplicate entries (and, in symmetric files, an entry given in both triangles) are
// summed; each value is finite, but their sum can overflow. Such a matrix is refused
// like a file holding Inf; the message names the entry (no single line is to blame).
[[noreturn]] void throw_sum_overflow(const std::string& path, index_t i, index_t j) {
  throw ParseError(path, 0,
                   "the entries at (" + std::to_string(i + 1) + ", " + std::to_string(j + 1) +
                       ") (1-based) sum past the range of a double (duplicates are summed)");
}

void check_sums(const std::string& path, const SparseMatrix& a) {
  for (index_t j = 0; j < a.n_cols; ++j)
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
      if (!std::isfinite(a.values[p])) throw_sum_overflow(path, a.indices[p], j);
}

// Calls f(i, j, v) for every entry of an array file, in file order (0-based i, j).
template <class F>
void for_each_array_value(const Contents& c, F&& f) {
  index_t k = 0;
  for (index_t j = 0; j < c.cols; ++j) {
    index_t first = 0;
    if (c.symmetry == MMSymmetry::symmetric) first = j;
    if (c.symmetry == MMSymmetry::skew_symmetric) first = j + 1;
    for (index_t i = first; i < c.rows; ++i) f(i, j, c.val[k++]);
  }
}

// Sparse form of an array file: its nonzero values (an array does not distinguish
// structural zeros), lower triangle for symmetric files, expanded for skew-symmetric.
SparseMatrix array_to_csc(const Contents& c) {
  Contents t;
  t.format = Format::coordinate;
  t.field = Field::real;
  t.symmetry = c.symmetry;
  t.rows = c.rows;
  t.cols = c.cols;
  for_each_array_value(c, [&](index_t i, index_t j, double v) {
    if (v == 0.0) return;
    t.row.push_back(i);
    t.col.push_back(j);
    t.val.push_back(v);
  });
  return coordinate_to_csc(t);
}

std::vector<double> to_dense(const std::string& path, const Contents& c) {
  index_t size = 0;
  if (__builtin_mul_overflow(c.rows, c.cols, &size) ||
      size > static_cast<index_t>(std::vector<double>().max_size()))
    throw InvalidInput(path + ": a dense " + std::to_string(c.rows) + "x" + std::to_string(c.cols) +
                       " array is too large");
  std::vector<double> d;
  try {
    d.assign(static_cast<size_t>(size), 0.0);
  } catch (const std::bad_alloc&) {
    throw OutOfMemory(static_cast<size_t>(size) * sizeof(double),
                      "read_dense_matrix_market(" + path + ")");
  }
  const index_t ld = c.rows;
  const bool sym = c.symmetry == MMSymmetry::symmetric;
  const bool skew = c.symmetry == MMSymmetry::skew_symmetric;
  auto put = [&](index_t i, index_t j, double v, bool add) {
    double& x = d[i + j * ld];
    x = add ? x + v : v;
    if (i != j && (sym || skew)) {
      double& y = d[j + i * ld];
      const double w = skew ? -v : v;
      y = add ? y + w : w;
    }
  };
  if (c.format == Format::array) {
    for_each_array_value(c, [&](index_t i, index_t j, double v) { put(i, j, v, false); });
  } else if (c.field == Field::pattern) {
    for (size_t k = 0; k < c.row.size(); ++k) put(c.row[k], c.col[k], 1.0, false);
  } else {
    for (size_t k = 0; k < c.row.size(); ++k) put(c.row[k], c.col[k], c.val[k], true);
    for (index_t k = 0; k < size; ++k)
      if (!std::isfinite(d[k])) throw_sum_overflow(path, k % ld, k / ld);
  }
  return d;
}

// MMCheck::factorable: square, every row and column holding an entry. Works on the
// entries alone (sorted copies of their indices, O(entries) memory), so that a file of a
// few bytes declaring a 10^8 x 10^8 matrix is refused before 10^8 offsets are allocated.
void check_factorable(const std::string& path, const Contents& c) {
  if (c.rows != c.cols)
    throw InvalidInput(path + ": matrix is " + std::to_string(c.rows) + "x" +
                       std::to_string(c.cols) + ", not square");
  const bool mirrored = c.symmetry != MMSymmetry::general;
  // The first index in 0..n-1 missing from `seen` (n when none is).
  auto first_missing = [&](std::vector<index_t>& seen) {
    std::sort(seen.begin(), seen.end());
    seen.erase(std::unique(seen.begin(), seen.end()), seen.end());
    for (std::size_t k = 0; k < seen.size(); ++k)
      if (seen[k] != static_cast<index_t>(k)) return static_cast<index_t>(k);
    return static_cast<index_t>(seen.size());
  };
  auto refuse = [&](const char* what, index_t k) {
    throw InvalidInput(path + ": matrix is structurally singular: " + what + " " +
                       std::to_string(k + 1) + " (1-based) has no entries");
  };
  if (c.format == Format::array) {
    // an array gives every value; only its nonzeros count as entries
    std::vector<index_t> rows, cols;
    for_each_array_value(c, [&](index_t i, index_t j, double v) {
      if (v == 0.0) return;
      rows.push_back(i);
      cols.push_back(j);
      if (mirrored) {
        rows.push_back(j);
        cols.push_back(i);
      }
    });
    if (const index_t j = first_missing(cols); j < c.cols) refuse("column", j);
    if (const index_t i = first_missing(rows); i < c.rows) refuse("row", i);
    return;
  }
  std::vector<index_t> seen(c.col);
  if (mirrored) seen.insert(seen.end(), c.row.begin(), c.row.end());
  if (const index_t j = first_missing(seen); j < c.cols) refuse("column", j);
  seen.assign(c.row.begin(), c.row.end());
  if (mirrored) seen.insert(seen.end(), c.col.begin(), c.col.end());
  if (const index_t i = first_missing(seen); i < c.rows) refuse("row", i);
}

}  // namespace

// ---------------------------------------------------------------------------------------
// Public API
// ---------------------------------------------------------------------------------------

MMMatrix read_matrix_market(const std::string& path, MMCheck check) {
  const Contents c = parse_file(path);
  if (check == MMCheck::factorable) check_factorable(path, c);
  MMMatrix out;
  out.symmetry = c.symmetry;
  out.pattern = c.field == Field::pattern;
  try {
    out.matrix = c.format == Format::coordinate ? coordinate_to_csc(c) : array_to_csc(c);
  } catch (const std::bad_alloc&) {
    // a size line may declare any dimensions up to kMaxDimension, and the compressed
    // form needs dimension + 1 offsets whatever the entries: bytes of the CSC arrays
    const double bytes = 8.0 * (static_cast<double>(c.rows) + static_cast<double>(c.cols) + 2) +
                         16.0 * static_cast<double>(c.row.size());
    throw OutOfMemory(bytes < 1.8e19 ? static_cast<size_t>(bytes) : SIZE_MAX,
                      "read_matrix_market(" + path + "): a " + std::to_string(c.rows) + "x" +
                          std::to_string(c.cols) + " matrix with " + std::to_string(c.row.size()) +
                          " entries");
  }
  if (c.format == Format::coordinate && c.field != Field::pattern) check_sums(path, out.matrix);
  return out;
}

std::vector<double> read_dense_matrix_market(const std::string& path, index_t* rows,
                                             index_t* cols) {
  if (!rows || !cols)
    throw InvalidInput("read_dense_matrix_market: rows and cols must not be null");
  const Contents c = parse_file(path);
  std::vector<double> d = to_dense(path, c);
  *rows = c.rows;
  *cols = c.cols;
  return d;
}

}  // namespace strata
