// strata tests — host allocation failure injection (a test-only facility, never linked
// into the library).
//
// alloc_hook.cpp replaces the global operator new / new[] (plain, aligned and nothrow
// forms) and their deletes with malloc/free plus a counter. Disarmed, it only counts.
// Armed with fail_after(n), the n-th counted allocation from then on (n = 1: the next one,
// on any thread) fails once: the throwing forms throw std::bad_alloc, the nothrow forms
// return nullptr; the hook then disarms itself, so the code that handles the failure
// (building an error message, unwinding) can allocate again — the situation of a large
// buffer that does not fit while small allocations still succeed. Only executables that
// link strata_alloc_hook get the replacement (tests/fault/).
#pragma once

#include <cstddef>
#include <cstdint>

namespace strata::test::alloc {

/// Arms the hook: the n-th counted allocation from now fails (n ≥ 1).
void fail_after(std::uint64_t n);
/// Disarms the hook (no failure pending).
void disarm();
/// True when an injected failure happened since the last fail_after.
bool fired();
/// Size in bytes of the request the injected failure refused (0 if none).
std::size_t failed_bytes();
/// Counted allocations (operator new of every form) since the last reset_count().
std::uint64_t count();
void reset_count();

/// Disarms on scope exit, so that a failing test assertion cannot leave the hook armed.
class Armed {
 public:
  explicit Armed(std::uint64_t n) { fail_after(n); }
  ~Armed() { disarm(); }
  Armed(const Armed&) = delete;
  Armed& operator=(const Armed&) = delete;
};

}  // namespace strata::test::alloc
