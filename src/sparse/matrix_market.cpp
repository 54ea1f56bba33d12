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
// fast (the largest shared matrix has 612k entries). Files are read in large blocks,
// through zlib's inflate when they start with the gzip magic bytes (any name) and
// unchanged otherwise; lines are cut out of the block with memchr and numbers are parsed with
// std::from_chars — no iostreams, no per-token allocation. The entries are collected as
// triplets and turned into canonical CSC by one bucket pass plus strata::canonicalize
// (sorts, sums duplicates, validates).
//
// A truncated ".gz" file (the input ends inside a gzip member) is detected; the partial
// last line it decompressed to is dropped, never parsed, and the file is reported as
// truncated. Several gzip members one after the other are read as one stream (RFC 1952);
// any other bytes after the last member are an error (the file is corrupt or two files
// were joined by mistake), where zlib's gzread would ignore them.
//
// Memory is bounded by the input: the size line may declare any dimensions, but nothing
// of O(rows + columns) is allocated until the entries are read and, for a matrix that is
// to be factored (MMRead::square_structurally_nonsingular), checked in O(entries) memory:
// a square matrix with fewer distinct rows or columns than its dimension is structurally
// singular and refused, naming the first empty column, before its compressed form exists.
//
// Writers produce `coordinate real|pattern general|symmetric` and `array real general`
// with 17 significant digits (%.17g, so every double reads back bitwise). They follow the
// output rules of core/atomic_file.hpp: a temporary beside the target renamed onto it once
// complete, so the target is either the old file or the complete new one, never a partial
// file (a symbolic link is followed, a device or FIFO written in place); on failure the
// temporary is removed and strata::Error names PATH. A PATH ending in ".gz" is written
// compressed.
#include "strata/matrix_market.hpp"

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

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

#include "core/atomic_file.hpp"
#include "strata/errors.hpp"

namespace strata {
namespace {

// ---------------------------------------------------------------------------------------
// Small text helpers
// ---------------------------------------------------------------------------------------

// White space inside a line ('\n' ends lines and never reaches the parsers).
inline bool is_space(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}

inline bool ends_with(std::string_view s, std::string_view suffix) {
  return s.size() >= suffix.size() && s.substr(s.size() - suffix.size()) == suffix;
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
// Line reader over zlib
// ---------------------------------------------------------------------------------------

// The bytes of a file, decompressed when it is gzip (RFC 1952: it starts with the magic
// bytes 1f 8b), passed through unchanged otherwise. A gzip file may hold several members
// one after the other (as `cat a.gz b.gz` makes); anything else after the last member is
// an error (zlib's gzread would skip it silently), as is a stream that ends inside a
// member (`truncated()`, reported by the caller with the line it stopped at).
class ByteSource {
 public:
  explicit ByteSource(const std::string& path) : path_(path) {
    errno = 0;
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) {
      const int err = errno;
      throw ParseError(path, 0, std::string("cannot open file: ") + std::strerror(err));
    }
    in_.resize(1 << 18);
    refill();
    gzip_ = avail_ >= 2 && static_cast<unsigned char>(in_[0]) == 0x1f &&
            static_cast<unsigned char>(in_[1]) == 0x8b;
    if (gzip_) start_member();
  }
  ~ByteSource() {
    if (inflating_) inflateEnd(&z_);
    if (fd_ >= 0) ::close(fd_);
  }
  ByteSource(const ByteSource&) = delete;
  ByteSource& operator=(const ByteSource&) = delete;

  /// Up to `want` bytes into `out`; 0 at the end of the file. `line` (the number of the
  /// line being read) goes into the messages of read errors and corrupt data.
  std::size_t read(char* out, std::size_t want, index_t line) {
    if (!gzip_) {
      if (avail_ == 0 && !eof_) refill(line);
      const std::size_t n = std::min(want, avail_);
      std::memcpy(out, in_.data() + pos_, n);
      pos_ += n;
      avail_ -= n;
      return n;
    }
    std::size_t got = 0;
    while (got < want && !done_) {
      if (avail_ == 0 && !eof_) refill(line);
      if (avail_ == 0 && eof_) {  // the input ended inside a member
        truncated_ = true;
        done_ = true;
        break;
      }
      z_.next_in = reinterpret_cast<Bytef*>(in_.data() + pos_);
      z_.avail_in = static_cast<uInt>(avail_);
      z_.next_out = reinterpret_cast<Bytef*>(out + got);
      z_.avail_out = static_cast<uInt>(std::min<std::size_t>(want - got, 1u << 30));
      const int rc = inflate(&z_, Z_NO_FLUSH);
      got = static_cast<std::size_t>(reinterpret_cast<char*>(z_.next_out) - out);
      pos_ = static_cast<std::size_t>(reinterpret_cast<char*>(z_.next_in) - in_.data());
      avail_ = z_.avail_in;
      if (rc == Z_STREAM_END) {
        next_member(line);
      } else if (rc == Z_DATA_ERROR || rc == Z_NEED_DICT) {
        throw ParseError(
            path_, line,
            std::string("corrupt compressed data: ") + (z_.msg ? z_.msg : "invalid gzip stream"));
      } else if (rc == Z_MEM_ERROR) {
        throw OutOfMemory(0, "decompressing " + path_);
      } else if (rc != Z_OK && rc != Z_BUF_ERROR) {
        throw ParseError(path_, line,
                         "corrupt compressed data (zlib error " + std::to_string(rc) + ")");
      }
    }
    return got;
  }

  /// True when the compressed stream ended early (a truncated .gz file).
  bool truncated() const { return truncated_; }

 private:
  void refill(index_t line = 0) {
    if (avail_ > 0 && pos_ > 0) std::memmove(in_.data(), in_.data() + pos_, avail_);
    pos_ = 0;
    while (avail_ < in_.size()) {
      const ssize_t r = ::read(fd_, in_.data() + avail_, in_.size() - avail_);
      if (r < 0) {
        if (errno == EINTR) continue;
        const int err = errno;
        throw ParseError(path_, line, std::string("read error: ") + std::strerror(err));
      }
      if (r == 0) {
        eof_ = true;
        break;
      }
      avail_ += static_cast<std::size_t>(r);
      if (gzip_) break;  // inflate takes what there is
    }
  }
  void start_member() {
    z_ = z_stream{};
    if (inflateInit2(&z_, 16 + MAX_WBITS) != Z_OK) throw OutOfMemory(0, "decompressing " + path_);
    inflating_ = true;
  }
  // A member ended: another one follows, or nothing may.
  void next_member(index_t line) {
    if (avail_ < 2 && !eof_) refill(line);
    if (avail_ == 0 && eof_) {
      done_ = true;
      return;
    }
    if (avail_ >= 2 && static_cast<unsigned char>(in_[pos_]) == 0x1f &&
        static_cast<unsigned char>(in_[pos_ + 1]) == 0x8b) {
      inflateReset(&z_);
      return;
    }
    throw ParseError(path_, 0,
                     "trailing data after the end of the compressed stream (" +
                         std::to_string(avail_) + (eof_ ? "" : "+") +
                         " bytes that are not a gzip member): the file is corrupt");
  }

  std::string path_;
  int fd_ = -1;
  std::vector<char> in_;
  std::size_t pos_ = 0, avail_ = 0;
  bool eof_ = false, gzip_ = false, inflating_ = false, done_ = false, truncated_ = false;
  z_stream z_{};
};

// Hands out the lines of a (possibly gzip-compressed) file as string_views into an
// internal block buffer, without the trailing "\n" or "\r\n". Counts lines from 1.
class LineReader {
 public:
  explicit LineReader(const std::string& path) : path_(path), src_(path) { buf_.resize(1 << 20); }
  LineReader(const LineReader&) = delete;
  LineReader& operator=(const LineReader&) = delete;

  /// The next line, or false at the end of the file.
  bool next(std::string_view& line) {
    for (;;) {
      const char* base = buf_.data();
      if (const void* nl = std::memchr(base + begin_, '\n', end_ - begin_)) {
        const size_t stop = static_cast<const char*>(nl) - base;
        line = trim_cr(std::string_view(base + begin_, stop - begin_));
        begin_ = stop + 1;
        ++line_no_;
        return true;
      }
      if (eof_) {
        if (begin_ == end_) return false;
        line = trim_cr(std::string_view(base + begin_, end_ - begin_));  // no final '\n'
        begin_ = end_;
        ++line_no_;
        return true;
      }
      fill();
    }
  }

  /// Number of the last line returned (0 before the first).
  index_t line_no() const { return line_no_; }
  /// True when the compressed stream ended early (a truncated .gz file).
  bool truncated() const { return truncated_; }

 private:
  static std::string_view trim_cr(std::string_view s) {
    if (!s.empty() && s.back() == '\r') s.remove_suffix(1);
    return s;
  }

  // Moves the unread tail to the front (growing the buffer if one line fills it) and
  // reads the next block.
  void fill() {
    if (begin_ > 0) {
      std::memmove(buf_.data(), buf_.data() + begin_, end_ - begin_);
      end_ -= begin_;
      begin_ = 0;
    }
    if (end_ == buf_.size()) buf_.resize(buf_.size() * 2);
    const size_t want = std::min<size_t>(buf_.size() - end_, 1u << 30);
    const size_t got = src_.read(buf_.data() + end_, want, line_no_ + 1);
    if (got == 0) {
      eof_ = true;
      if (src_.truncated()) {
        // The input ended inside the gzip stream: whatever follows the last complete
        // line is a fragment of a line (a number could be cut short), so drop it.
        truncated_ = true;
        end_ = begin_;
      }
      return;
    }
    end_ += got;
  }

  std::string path_;
  ByteSource src_;
  std::vector<char> buf_;
  size_t begin_ = 0, end_ = 0;
  index_t line_no_ = 0;
  bool eof_ = false;
  bool truncated_ = false;
};

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

// ---------------------------------------------------------------------------------------
// Atomic writer
// ---------------------------------------------------------------------------------------

// Writes PATH by the rules of core/atomic_file.hpp: through a temporary file in the
// target's folder, renamed onto the target by commit() (the final target of a symbolic
// link; an existing device or FIFO is written in place instead). If commit() is not
// reached (an exception), the destructor removes the temporary.
class AtomicWriter {
 public:
  explicit AtomicWriter(std::string path) : path_(std::move(path)) {
    const OutputTarget target = resolve_output(path_);
    target_ = target.path;
    through_ = target.write_through;
    // "T": plain (transparent) output; a ".gz" PATH is compressed.
    const char* mode = ends_with(path_, ".gz") ? "wb6" : "wbT";
    errno = 0;
    if (through_) {
      const int fd = ::open(target_.c_str(), O_WRONLY | O_CLOEXEC);
      if (fd < 0) fail(std::string("cannot open ") + target_ + ": " + errno_text(errno));
      file_ = gzdopen(fd, mode);
      if (!file_) {
        ::close(fd);
        fail("cannot open " + target_ + ": out of memory in zlib");
      }
    } else {
      tmp_ = temporary_name(target_);
      file_ = gzopen(tmp_.c_str(), mode);
      if (!file_) fail(std::string("cannot create ") + tmp_ + ": " + errno_text(errno));
    }
    buf_.reserve(kFlushAt + 256);
  }
  ~AtomicWriter() {
    if (file_) gzclose(file_);
    if (!committed_ && !through_) std::remove(tmp_.c_str());
  }
  AtomicWriter(const AtomicWriter&) = delete;
  AtomicWriter& operator=(const AtomicWriter&) = delete;

  void put(std::string_view s) {
    buf_.append(s);
    if (buf_.size() >= kFlushAt) flush();
  }
  void put_index(index_t k) {
    char tmp[24];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, k);
    buf_.append(tmp, r.ptr);
  }
  // %.17g: 17 significant digits, enough for every double to read back bitwise.
  void put_real(double v) {
    char tmp[40];
    const auto r = std::to_chars(tmp, tmp + sizeof tmp, v, std::chars_format::general, 17);
    buf_.append(tmp, r.ptr);
  }
  void end_line() {
    buf_.push_back('\n');
    if (buf_.size() >= kFlushAt) flush();
  }

  /// Completes the file: flush, close, rename onto the target.
  void commit() {
    flush();
    const int rc = gzclose(file_);
    file_ = nullptr;
    const std::string& name = through_ ? target_ : tmp_;
    if (rc != Z_OK)
      fail("closing " + name + " failed" + (rc == Z_ERRNO ? ": " + errno_text(errno) : ""));
    if (!through_ && std::rename(tmp_.c_str(), target_.c_str()) != 0)
      fail("cannot rename " + tmp_ + " onto " + target_ + ": " + errno_text(errno));
    committed_ = true;
  }

 private:
  static constexpr size_t kFlushAt = 1 << 20;

  static std::string errno_text(int err) { return err ? std::strerror(err) : "unknown error"; }

  void flush() {
    if (buf_.empty()) return;
    const int wrote = gzwrite(file_, buf_.data(), static_cast<unsigned>(buf_.size()));
    if (wrote != static_cast<int>(buf_.size())) {
      int errnum = 0;
      const char* msg = gzerror(file_, &errnum);
      fail("writing " + (through_ ? target_ : tmp_) +
           " failed: " + (errnum == Z_ERRNO ? errno_text(errno) : msg));
    }
    buf_.clear();
  }

  [[noreturn]] void fail(const std::string& why) {
    if (file_) gzclose(file_);
    file_ = nullptr;
    if (!through_) std::remove(tmp_.c_str());
    committed_ = true;  // nothing left to clean up
    throw Error("cannot write Matrix Market file " + path_ + ": " + why);
  }

  std::string path_, target_, tmp_;
  bool through_ = false;
  gzFile file_ = nullptr;
  std::string buf_;
  bool committed_ = false;
};

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

void write_matrix_market(const std::string& path, const SparseMatrix& a) {
  // Canonical CSC (validated, sorted, duplicates summed). An upper-stored matrix is
  // written as the lower triangle of its transpose: read as CSR, CSC upper storage is
  // the transpose in lower storage (and vice versa).
  SparseMatrix c;
  try {
    if (a.storage == Storage::upper) {
      SparseMatrix t = a;
      t.layout = a.layout == Layout::csc ? Layout::csr : Layout::csc;
      t.storage = Storage::lower;
      std::swap(t.n_rows, t.n_cols);
      c = canonicalize(t);
    } else {
      c = canonicalize(a);
    }
  } catch (const InvalidInput& e) {
    throw InvalidInput("cannot write Matrix Market file " + path + ": " + e.what());
  }
  const bool pattern = c.values.empty() && c.nnz() > 0;
  const bool sym = c.storage != Storage::full;

  AtomicWriter w(path);
  w.put("%%MatrixMarket matrix coordinate ");
  w.put(pattern ? "pattern " : "real ");
  w.put(sym ? "symmetric\n" : "general\n");
  w.put("% written by strata\n");
  w.put_index(c.n_rows);
  w.put(" ");
  w.put_index(c.n_cols);
  w.put(" ");
  w.put_index(c.nnz());
  w.end_line();
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      w.put_index(c.indices[p] + 1);
      w.put(" ");
      w.put_index(j + 1);
      if (!pattern) {
        w.put(" ");
        w.put_real(c.values[p]);
      }
      w.end_line();
    }
  w.commit();
}

void write_dense_matrix_market(const std::string& path, const double* values, index_t rows,
                               index_t cols) {
  const std::string what = "cannot write Matrix Market file " + path + ": ";
  if (rows < 0 || cols < 0)
    throw InvalidInput(what + "negative dimensions " + std::to_string(rows) + "x" +
                       std::to_string(cols));
  index_t size = 0;
  if (__builtin_mul_overflow(rows, cols, &size))
    throw InvalidInput(what + "dimensions " + std::to_string(rows) + "x" + std::to_string(cols) +
                       " overflow");
  if (size > 0 && !values) throw InvalidInput(what + "values is null");
  for (index_t k = 0; k < size; ++k)
    if (!std::isfinite(values[k]))
      throw InvalidInput(what + "value (" + std::to_string(k % rows) + ", " +
                         std::to_string(k / rows) + ") is not finite");

  AtomicWriter w(path);
  w.put("%%MatrixMarket matrix array real general\n% written by strata\n");
  w.put_index(rows);
  w.put(" ");
  w.put_index(cols);
  w.end_line();
  for (index_t k = 0; k < size; ++k) {
    w.put_real(values[k]);
    w.end_line();
  }
  w.commit();
}

}  // namespace strata
