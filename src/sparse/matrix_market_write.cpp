// strata — Matrix Market output (see include/strata/matrix_market.hpp; the format is
// described in matrix_market.cpp).
//
// The writers produce `coordinate real|pattern general|symmetric` and `array real general`
// with 17 significant digits (%.17g, so every double reads back bitwise). They follow the
// output rules of base/atomic_file.hpp: a temporary beside the target renamed onto it once
// complete, so the target is either the old file or the complete new one, never a partial
// file (a symbolic link is followed, a device or FIFO written in place); on failure the
// temporary is removed and strata::Error names PATH. A PATH ending in ".gz" is written
// compressed.
#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include "base/atomic_file.hpp"
#include "strata/errors.hpp"
#include "strata/matrix_market.hpp"

namespace strata {
namespace {

// Writes PATH by the rules of base/atomic_file.hpp: through a temporary file in the
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
    const char* mode = path_.ends_with(".gz") ? "wb6" : "wbT";
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
