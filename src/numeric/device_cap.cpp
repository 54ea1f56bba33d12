// strata — the internal device allocation cap (see device_cap.hpp).
#include "numeric/device_cap.hpp"

#include <atomic>
#include <limits>
#include <string>

#include "strata/errors.hpp"

namespace strata::numeric {
namespace {
constexpr std::size_t kNoCap = std::numeric_limits<std::size_t>::max();
std::atomic<std::size_t> g_cap{kNoCap};
std::atomic<std::size_t> g_charged{0};
}  // namespace

void set_device_allocation_cap(std::size_t bytes) {
  g_charged.store(0);
  g_cap.store(bytes);
}

void clear_device_allocation_cap() {
  g_charged.store(0);
  g_cap.store(kNoCap);
}

std::size_t device_bytes_charged() { return g_charged.load(); }

void charge_device_allocation(std::size_t bytes, const char* what) {
  const std::size_t cap = g_cap.load();
  std::size_t now = g_charged.load();
  for (;;) {
    if (cap != kNoCap && (bytes > cap || now > cap - bytes))
      throw OutOfMemory(bytes, std::string(what) + " (over the device allocation cap of " +
                                   std::to_string(cap) + " bytes set by the test hook)");
    if (g_charged.compare_exchange_weak(now, now + bytes)) return;
  }
}

}  // namespace strata::numeric
