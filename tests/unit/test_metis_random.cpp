// strata tests — METIS's random numbers per thread (src/ordering/metis_random.hpp): inside
// a MetisRandomScope rand()/srand() draw the numbers glibc's process-wide rand() would
// draw, from a state of the calling thread; outside one they are the process's rand().
#include <gtest/gtest.h>
#include <stdlib.h>

#include <random>
#include <thread>
#include <vector>

#include "ordering/metis_random.hpp"

namespace strata::ordering {
namespace {

// The reference: glibc's own generator on the process's state (rand() is (int) random(),
// srand(s) is srandom(s)), drawn outside any scope.
std::vector<int> process_sequence(unsigned seed, int count) {
  srandom(seed);
  std::vector<int> out(count);
  for (int& x : out) x = static_cast<int>(random());
  return out;
}

std::vector<int> scoped_sequence(unsigned seed, int count, bool* seeded = nullptr) {
  const MetisRandomScope scope;
  srand(seed);
  std::vector<int> out(count);
  for (int& x : out) x = rand();
  if (seeded) *seeded = scope.seeded();
  return out;
}

TEST(MetisRandom, ScopeDrawsTheProcessSequence) {
  std::mt19937 rng(std::random_device{}());
  for (const unsigned seed : {0u, 1u, 2u, 4321u, static_cast<unsigned>(rng())}) {
    for (const int count : {1, 2, 3, 5, 733}) {
      bool seeded = false;
      const std::vector<int> scoped = scoped_sequence(seed, count, &seeded);
      EXPECT_TRUE(seeded);
      EXPECT_EQ(scoped, process_sequence(seed, count)) << "seed " << seed << ", " << count;
    }
  }
}

TEST(MetisRandom, OutsideAScopeRandIsTheProcesssAndIsLeftAlone) {
  const std::vector<int> expected = process_sequence(99, 4);
  srand(99);
  std::vector<int> got;
  got.push_back(rand());
  got.push_back(rand());
  (void)scoped_sequence(7, 50);  // draws from the thread's state, not the process's
  got.push_back(rand());
  got.push_back(rand());
  EXPECT_EQ(got, expected);
  const MetisRandomScope outer;
  EXPECT_FALSE(outer.seeded());
  {
    const MetisRandomScope inner;  // nested: a no-op, the outer scope stays active
  }
  srand(3);
  EXPECT_TRUE(outer.seeded());
  EXPECT_EQ(rand(), process_sequence(3, 1)[0]);
}

TEST(MetisRandom, ThreadsDrawTheirOwnSequencesSideBySide) {
  const int threads = 4, count = 20000;
  std::vector<std::vector<int>> got(threads);
  std::vector<std::thread> pool;
  for (int t = 0; t < threads; ++t)
    pool.emplace_back([&, t] {
      for (int round = 0; round < 5; ++round) got[t] = scoped_sequence(100 + t, count);
    });
  for (auto& th : pool) th.join();
  for (int t = 0; t < threads; ++t)
    EXPECT_EQ(got[t], process_sequence(100 + t, count)) << "thread " << t;
}

}  // namespace
}  // namespace strata::ordering
