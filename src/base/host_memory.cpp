// strata — how much host memory the process may still take (see host_memory.hpp).
#include "base/host_memory.hpp"

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>

namespace strata {

namespace {

// The value of `key` (kB) in /proc/meminfo, in bytes; 0 when absent.
std::size_t meminfo_bytes(const std::string& key) {
  std::ifstream in("/proc/meminfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.compare(0, key.size(), key) != 0 || line.size() <= key.size() ||
        line[key.size()] != ':')
      continue;
    std::istringstream fields(line.substr(key.size() + 1));
    unsigned long long kb = 0;
    if (fields >> kb) return static_cast<std::size_t>(kb) * 1024;
    return 0;
  }
  return 0;
}

// A single number read from a cgroup file; false for "max", a missing file or text.
bool read_number(const std::string& path, unsigned long long& value) {
  std::ifstream in(path);
  std::string word;
  if (!(in >> word) || word.empty() || word.find_first_not_of("0123456789") != std::string::npos)
    return false;
  value = std::stoull(word);
  return true;
}

// The room under this process's cgroup v2 memory.max (0 when none is set or readable).
std::size_t cgroup_room() {
  std::ifstream in("/proc/self/cgroup");
  std::string line;
  while (std::getline(in, line)) {
    if (line.compare(0, 3, "0::") != 0) continue;  // the v2 hierarchy's line
    const std::string dir = "/sys/fs/cgroup" + line.substr(3);
    unsigned long long limit = 0, used = 0;
    if (!read_number(dir + "/memory.max", limit) || !read_number(dir + "/memory.current", used))
      return 0;
    return limit > used ? static_cast<std::size_t>(limit - used) : 1;
  }
  return 0;
}

}  // namespace

std::size_t available_host_memory() {
  const std::size_t avail = meminfo_bytes("MemAvailable");
  const std::size_t room = cgroup_room();
  if (avail == 0) return room;
  return room == 0 ? avail : std::min(avail, room);
}

}  // namespace strata
