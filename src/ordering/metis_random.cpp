// strata — random numbers of METIS per thread (see metis_random.hpp).
#include "ordering/metis_random.hpp"

#include <stdlib.h>

#include <cstdint>
#include <cstring>

namespace strata::ordering {
namespace {

// glibc's rand() uses a TYPE_3 additive feedback generator on 128 bytes of state
// (initstate's default); random_r on the same kind of state gives the same numbers.
constexpr std::size_t kStateBytes = 128;

struct ThreadRandom {
  bool active = false;
  bool seeded = false;
  bool initialised = false;
  random_data data;
  alignas(std::int32_t) char state[kStateBytes];
};

ThreadRandom& thread_random() noexcept {
  thread_local ThreadRandom r;
  return r;
}

void seed(ThreadRandom& r, unsigned int s) noexcept {
  if (!r.initialised) {
    std::memset(&r.data, 0, sizeof r.data);
    initstate_r(s, r.state, kStateBytes, &r.data);
    r.initialised = true;
  } else {
    srandom_r(s, &r.data);
  }
  r.seeded = true;
}

}  // namespace

MetisRandomScope::MetisRandomScope() noexcept : owner_(!thread_random().active) {
  ThreadRandom& r = thread_random();
  if (!owner_) return;
  r.active = true;
  r.seeded = false;
}

MetisRandomScope::~MetisRandomScope() {
  if (owner_) thread_random().active = false;
}

bool MetisRandomScope::seeded() const noexcept { return thread_random().seeded; }

}  // namespace strata::ordering

// The C library's rand and srand, per thread inside a MetisRandomScope (file header of
// metis_random.hpp). Outside one they are glibc's own: rand() is (int) random() and
// srand(s) is srandom(s) on the process's state.
extern "C" __attribute__((visibility("default"))) int rand(void) noexcept {
  strata::ordering::ThreadRandom& r = strata::ordering::thread_random();
  if (!r.active) return static_cast<int>(random());
  if (!r.initialised) strata::ordering::seed(r, 1);  // rand() before any srand: seed 1
  int32_t out = 0;
  random_r(&r.data, &out);
  return out;
}

extern "C" __attribute__((visibility("default"))) void srand(unsigned int s) noexcept {
  strata::ordering::ThreadRandom& r = strata::ordering::thread_random();
  if (!r.active) {
    srandom(s);
    return;
  }
  strata::ordering::seed(r, s);
}
