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

#include <cstdint>
#include <cstdio>
#include <cstdlib>
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

}  // namespace strata::fuzz
