// strata — the lines of a text file that may be gzip-compressed, for the Matrix Market
// reader (sparse/matrix_market.cpp).
//
// Files are read in large blocks with read(2), through zlib's inflate when they start with
// the gzip magic bytes (any name) and unchanged otherwise; lines are cut out of the block
// with memchr and handed out as string_views, so that no line is copied or allocated.
// A truncated ".gz" file (the input ends inside a gzip member) is detected: the partial
// last line it decompressed to is dropped, never parsed, and `truncated()` says so.
// Several gzip members one after the other are read as one stream (RFC 1952); any other
// bytes after the last member are an error (the file is corrupt or two files were joined
// by mistake), where zlib's gzread would ignore them. Errors are ParseError naming the
// file and the line being read.
#pragma once

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

#include "strata/errors.hpp"
#include "strata/types.hpp"

namespace strata::detail {

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

}  // namespace strata::detail
