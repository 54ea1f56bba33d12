// strata — random numbers of METIS per thread, so that bisections can run side by side.
//
// Why: METIS 5.1 as Debian builds it (GKlib without its own generator) draws its random
// numbers from the C library's rand(), seeded by srand(METIS_OPTION_SEED) at the start of
// every API call. rand() keeps one state per process, so two METIS calls running at once on
// different threads would interleave their draws and the separators — hence the ordering —
// would depend on the timing.
//
// What: strata defines rand() and srand() itself. On a thread inside a MetisRandomScope
// they draw from a state of that thread, by the C library's own algorithm (glibc's
// random_r on a TYPE_3 state of 128 bytes, which is what srand/rand use for the process's
// state): the numbers a lone METIS call would have drawn, so the ordering is the same
// whether bisections run one after another or side by side. Anywhere else they are
// srandom/random on the process's state, exactly what glibc's srand/rand are, so a
// program's own use of rand() is unchanged.
//
// Where it takes effect: where the dynamic linker binds METIS's rand to these definitions,
// i.e. in programs linked with strata's static library (the executable's symbols come
// before the C library's). A strata loaded as a shared module after the C library (the
// Python extension) leaves METIS bound to the C library's rand; MetisRandomScope::seeded()
// then stays false after a METIS call, and the nested-dissection driver keeps its
// bisections on one thread.
#pragma once

namespace strata::ordering {

/// On the calling thread, METIS's rand()/srand() use a state of this thread while the scope
/// is open (scopes on one thread do not nest: the inner one is a no-op).
class MetisRandomScope {
 public:
  MetisRandomScope() noexcept;
  ~MetisRandomScope();
  MetisRandomScope(const MetisRandomScope&) = delete;
  MetisRandomScope& operator=(const MetisRandomScope&) = delete;

  /// Whether srand() reached strata's definition on this thread since the scope opened
  /// (every METIS call seeds first): true after a METIS call exactly when METIS's random
  /// numbers are this thread's own.
  bool seeded() const noexcept;

 private:
  bool owner_;
};

}  // namespace strata::ordering
