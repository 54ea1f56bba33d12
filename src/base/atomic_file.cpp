// strata — output files (see atomic_file.hpp): symbolic links followed, non-regular
// targets written through in place, regular ones replaced atomically by a temporary in the
// same folder, fsync and rename(2) (POSIX guarantees that the rename replaces the target
// atomically).
#include "base/atomic_file.hpp"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <vector>

#include "strata/errors.hpp"

namespace strata {
namespace {

std::string folder_of(const std::string& path) {
  const std::size_t slash = path.find_last_of('/');
  if (slash == std::string::npos) return ".";
  if (slash == 0) return "/";
  return path.substr(0, slash);
}

[[noreturn]] void refuse(const std::string& path, const std::string& why) {
  throw Error("cannot write " + path + ": " + why);
}

// Writes all of [p, p + n) to fd; returns 0 or the errno of the failure.
int write_all(int fd, const char* p, std::size_t n) {
  while (n > 0) {
    const ssize_t w = ::write(fd, p, n);
    if (w < 0) {
      if (errno == EINTR) continue;
      return errno;
    }
    p += w;
    n -= static_cast<std::size_t>(w);
  }
  return 0;
}

void write_through(const std::string& shown, const OutputTarget& t, std::string_view contents) {
  const int fd = ::open(t.path.c_str(), O_WRONLY | O_CLOEXEC);
  if (fd < 0) refuse(shown, std::string("opening ") + t.path + " failed: " + std::strerror(errno));
  const int err = write_all(fd, contents.data(), contents.size());
  const int closed = ::close(fd);
  if (err != 0) refuse(shown, std::strerror(err));
  if (closed != 0) refuse(shown, std::string("closing failed: ") + std::strerror(errno));
}

}  // namespace

OutputTarget resolve_output(const std::string& path) {
  if (path.empty()) throw Error("cannot write a file with an empty name");
  OutputTarget t;
  t.path = path;
  for (int hops = 0;; ++hops) {
    struct stat st {};
    if (::lstat(t.path.c_str(), &st) != 0) {
      if (errno == ENOENT) return t;  // a new file (its folder is checked when it is created)
      refuse(path, std::string(t.path == path ? "" : t.path + ": ") + std::strerror(errno));
    }
    if (S_ISLNK(st.st_mode)) {
      if (hops == 40) refuse(path, "too many levels of symbolic links");
      std::vector<char> buf(static_cast<std::size_t>(st.st_size > 0 ? st.st_size : 255) + 1);
      const ssize_t len = ::readlink(t.path.c_str(), buf.data(), buf.size());
      if (len < 0 || static_cast<std::size_t>(len) >= buf.size())
        refuse(path, "cannot read the symbolic link " + t.path);
      std::string target(buf.data(), static_cast<std::size_t>(len));
      if (target.empty()) refuse(path, "the symbolic link " + t.path + " is empty");
      t.path = target[0] == '/' ? target : folder_of(t.path) + "/" + target;
      continue;
    }
    if (S_ISREG(st.st_mode)) return t;
    if (S_ISDIR(st.st_mode)) refuse(path, (t.path == path ? "" : t.path + " ") + "is a directory");
    if (S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode)) {
      t.write_through = true;
      return t;
    }
    refuse(path, (t.path == path ? std::string("it") : t.path) +
                     " is a socket or a block device, not a file strata writes");
  }
}

std::string temporary_name(const std::string& target) {
  static std::atomic<unsigned long> counter{0};
  return target + ".tmp." + std::to_string(static_cast<long>(::getpid())) + "." +
         std::to_string(counter++);
}

void check_output_path(const std::string& path) {
  const OutputTarget t = resolve_output(path);
  if (t.write_through) {
    // permission only: opening a FIFO's write end and closing it would end its reader's
    // input (it reads end-of-file) before the real write
    if (::access(t.path.c_str(), W_OK) != 0) refuse(path, std::strerror(errno));
    return;
  }
  const std::string dir = folder_of(t.path);
  struct stat st {};
  if (::stat(dir.c_str(), &st) != 0)
    refuse(path, "the folder " + dir + " " +
                     (errno == ENOENT ? std::string("does not exist") : std::strerror(errno)));
  if (!S_ISDIR(st.st_mode)) refuse(path, dir + " is not a folder");
  if (::access(t.path.c_str(), F_OK) == 0 && ::access(t.path.c_str(), W_OK) != 0)
    refuse(path, (t.path == path ? std::string("the file") : t.path) + " is not writable (" +
                     std::strerror(errno) + ")");
  const std::string probe = temporary_name(t.path);
  const int fd = ::open(probe.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) refuse(path, "cannot create a file in " + dir + ": " + std::strerror(errno));
  ::close(fd);
  ::unlink(probe.c_str());
}

void write_file_atomically(const std::string& path, std::string_view contents, bool durable) {
  const OutputTarget t = resolve_output(path);
  if (t.write_through) return write_through(path, t, contents);
  const std::string tmp = temporary_name(t.path);
  auto fail = [&](const char* what, int err) {
    std::remove(tmp.c_str());
    refuse(path, std::string(what) + " " + tmp + " failed: " + std::strerror(err));
  };
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) fail("creating", errno);
  if (const int err = write_all(fd, contents.data(), contents.size()); err != 0) {
    ::close(fd);
    fail("writing", err);
  }
  if (durable && ::fsync(fd) != 0) {
    const int err = errno;
    ::close(fd);
    fail("flushing", err);
  }
  if (::close(fd) != 0) fail("closing", errno);
  if (std::rename(tmp.c_str(), t.path.c_str()) != 0) fail("renaming", errno);
}

void rename_file(const std::string& from, const std::string& to) {
  const OutputTarget t = resolve_output(to);
  if (t.write_through) {
    std::FILE* in = std::fopen(from.c_str(), "rb");
    if (!in) throw Error("cannot read " + from + ": " + std::strerror(errno));
    std::string contents;
    char buf[1 << 16];
    std::size_t got = 0;
    while ((got = std::fread(buf, 1, sizeof buf, in)) > 0) contents.append(buf, got);
    const bool bad = std::ferror(in) != 0;
    std::fclose(in);
    if (bad) throw Error("cannot read " + from);
    write_through(to, t, contents);
    std::remove(from.c_str());
    return;
  }
  if (std::rename(from.c_str(), t.path.c_str()) != 0)
    throw Error("cannot rename " + from + " to " + to + ": " + std::strerror(errno));
}

}  // namespace strata
