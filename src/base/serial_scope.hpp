// strata — a scope in which the host passes that split over TBB threads run on the calling
// thread alone.
//
// Why: the analysis's passes over a pattern (sparse/bucket_entries.hpp,
// analysis/patterns.cpp) run over the threads of the calling TBB arena. For a small matrix
// they take microseconds, while entering TBB — its scheduler and worker threads, started
// the first time a process uses it — takes a few tenths of a millisecond, more than the
// whole analysis of such a matrix saves. Inside a SerialScope those passes run their
// sequential form (the same result: they do not depend on the thread count) and do not
// enter TBB at all.
#pragma once

namespace strata::detail {

/// True while a SerialScope(true) is open on the calling thread.
bool serial_passes() noexcept;

/// Makes serial_passes() `on` on the calling thread until the scope ends (scopes nest;
/// the previous setting comes back).
class SerialScope {
 public:
  explicit SerialScope(bool on) noexcept;
  ~SerialScope();
  SerialScope(const SerialScope&) = delete;
  SerialScope& operator=(const SerialScope&) = delete;

 private:
  bool previous_;
};

}  // namespace strata::detail
