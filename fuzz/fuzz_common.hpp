// strata fuzz targets — shared pieces: a scratch file for readers that take a path, and
// the rule for which exceptions count as a defined outcome.
//
// Why a file: the Matrix Market reader takes a path (it reads through zlib's gzread,
// which decompresses gzip data and passes other bytes through), so every input is
// written to one scratch file per process, overwritten in place, in /dev/shm when it
// exists (no disk traffic).
#pragma once

#include <fcntl.h>
#include <unistd.h>
#include <zlib.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>

namespace strata::fuzz {

/// A scratch file (created once, removed at exit) that holds the bytes of one input.
class ScratchFile {
 public:
  explicit ScratchFile(const char* suffix = ".mtx") {
    const char* dir = access("/dev/shm", W_OK) == 0 ? "/dev/shm" : P_tmpdir;
    path_ = std::string(dir) + "/strata_fuzz_" + std::to_string(getpid()) + suffix;
    fd_ = open(path_.c_str(), O_RDWR | O_CREAT | O_TRUNC, 0600);
    if (fd_ < 0) {
      std::perror(path_.c_str());
      std::abort();
    }
  }
  ~ScratchFile() {
    close(fd_);
    unlink(path_.c_str());
  }
  ScratchFile(const ScratchFile&) = delete;
  ScratchFile& operator=(const ScratchFile&) = delete;

  const std::string& path() const { return path_; }

  /// Replaces the contents with data[0..size) and returns the path.
  const std::string& write(const uint8_t* data, size_t size) {
    if (ftruncate(fd_, 0) != 0 || pwrite(fd_, data, size, 0) != static_cast<ssize_t>(size)) {
      std::perror(path_.c_str());
      std::abort();
    }
    return path_;
  }

 private:
  std::string path_;
  int fd_ = -1;
};

/// Largest row or column count a fuzz input may declare. A size line may legitimately
/// declare any dimensions, and the reader then allocates dimension + 1 offsets whatever
/// the entries; under ASan an allocation that cannot be satisfied aborts (operator new
/// does not throw there) and libFuzzer counts > 2 GB of memory as a crash, so such
/// inputs would be false findings. The OutOfMemory outcome is tested in the normal suite
/// (MatrixMarketTest.HugeDeclaredDimensionsAreOutOfMemory).
constexpr long long kMaxFuzzDimension = 1 << 20;

/// False when the Matrix Market file at PATH (plain or gzip) declares more than
/// kMaxFuzzDimension rows or columns on its size line: the first line after the banner
/// that is neither blank nor a comment. Anything unparsable is left to the reader (true).
inline bool small_dimensions(const std::string& path) {
  gzFile f = gzopen(path.c_str(), "rb");
  if (!f) return true;
  char line[1 << 16];
  bool ok = true, banner = true;
  while (gzgets(f, line, sizeof line)) {
    if (banner) {  // line 1, whatever it holds
      banner = false;
      continue;
    }
    const char* p = line + std::strspn(line, " \t\r\v\f");
    if (*p == '\0' || *p == '\n' || *p == '%') continue;
    for (int k = 0; k < 2 && ok; ++k) {
      char* end = nullptr;
      const long long v = std::strtoll(p, &end, 10);
      if (end == p) break;
      ok = v <= kMaxFuzzDimension;
      p = end;
    }
    break;
  }
  gzclose(f);
  return ok;
}

}  // namespace strata::fuzz
