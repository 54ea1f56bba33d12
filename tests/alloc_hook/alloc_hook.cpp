// strata tests — replaceable global allocation functions with failure injection (see
// alloc_hook.hpp). C++20 [new.delete]: a program may replace operator new/delete of every
// form; all replaced forms here allocate with malloc (aligned: posix_memalign) and free
// with free, so every new/delete pair matches, also under AddressSanitizer.
#include "alloc_hook/alloc_hook.hpp"

#include <atomic>
#include <cstdlib>
#include <new>

namespace strata::test::alloc {
namespace {

std::atomic<std::uint64_t> g_count{0};
// 0: disarmed; otherwise the number of allocations until (and including) the failing one
std::atomic<std::uint64_t> g_countdown{0};
std::atomic<bool> g_fired{false};
std::atomic<std::size_t> g_failed_bytes{0};

// True when this allocation is the one to fail.
bool should_fail(std::size_t bytes) noexcept {
  g_count.fetch_add(1, std::memory_order_relaxed);
  std::uint64_t c = g_countdown.load(std::memory_order_relaxed);
  while (c != 0) {
    if (g_countdown.compare_exchange_weak(c, c - 1, std::memory_order_acq_rel)) {
      if (c != 1) return false;
      g_failed_bytes.store(bytes);
      g_fired.store(true);
      return true;
    }
  }
  return false;
}

void* allocate(std::size_t bytes, std::size_t align) noexcept {
  if (should_fail(bytes)) return nullptr;
  if (bytes == 0) bytes = 1;
  if (align <= alignof(std::max_align_t)) return std::malloc(bytes);
  void* p = nullptr;
  return posix_memalign(&p, align, bytes) == 0 ? p : nullptr;
}

void* allocate_or_throw(std::size_t bytes, std::size_t align) {
  void* p = allocate(bytes, align);
  if (!p) throw std::bad_alloc();
  return p;
}

}  // namespace

void fail_after(std::uint64_t n) {
  g_fired.store(false);
  g_failed_bytes.store(0);
  g_countdown.store(n == 0 ? 1 : n);
}
void disarm() { g_countdown.store(0); }
bool fired() { return g_fired.load(); }
std::size_t failed_bytes() { return g_failed_bytes.load(); }
std::uint64_t count() { return g_count.load(); }
void reset_count() { g_count.store(0); }

}  // namespace strata::test::alloc

using strata::test::alloc::allocate;
using strata::test::alloc::allocate_or_throw;
constexpr std::size_t kPlain = alignof(std::max_align_t);

void* operator new(std::size_t n) { return allocate_or_throw(n, kPlain); }
void* operator new[](std::size_t n) { return allocate_or_throw(n, kPlain); }
void* operator new(std::size_t n, std::align_val_t a) {
  return allocate_or_throw(n, static_cast<std::size_t>(a));
}
void* operator new[](std::size_t n, std::align_val_t a) {
  return allocate_or_throw(n, static_cast<std::size_t>(a));
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, kPlain); }
void* operator new[](std::size_t n, const std::nothrow_t&) noexcept { return allocate(n, kPlain); }
void* operator new(std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return allocate(n, static_cast<std::size_t>(a));
}
void* operator new[](std::size_t n, std::align_val_t a, const std::nothrow_t&) noexcept {
  return allocate(n, static_cast<std::size_t>(a));
}

void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
