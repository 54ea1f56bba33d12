// The CUDA LDLᵀ device code (src/numeric/cuda/ldlt_device.cuh) compiled for the host and
// run with one OS thread per CUDA thread of a block, checked against the CPU kernel
// factor_front_ldlt on the same fronts: same pivot sequence (pivot sizes, permutation),
// same perturbed count, same factor entries and contribution block to rounding. This runs
// in CI without a GPU; it checks the index arithmetic, the pivoting rules and that every
// thread reaches every barrier (a thread that skips or adds a __syncthreads() leaves the
// others waiting: the emulated barrier then aborts the test with a message). It cannot
// see what only a GPU shows (memory model, warp scheduling): the gpu-labelled tests
// (tests/gpu/test_cuda_backend.cpp) run the real kernels.
//
// The emulation: threadIdx is thread-local, blockDim global, __shared__ variables are
// function statics (one block runs at a time), __syncthreads() is a barrier of the
// block's threads, __dmul_rn/__dadd_rn are plain IEEE operations. Blocks of 32 threads
// keep the tests fast on a 2-core machine; one case runs the real block size, 256.
#include <gtest/gtest.h>
#include <math.h>

#include <algorithm>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <mutex>
#include <random>
#include <thread>
#include <vector>

#include "numeric/cpu/dense_front.hpp"
#include "support/test_support.hpp"

// --- host stand-ins for the CUDA names the device code uses -----------------------------

namespace {

struct EmuDim {
  unsigned x = 0;
};
thread_local EmuDim threadIdx;
EmuDim blockDim;

// A reusable barrier that aborts, naming the problem, when the block's threads do not all
// arrive within a generous time (a divergent __syncthreads()).
class EmuBarrier {
 public:
  void reset(unsigned n) {
    n_ = n;
    waiting_ = 0;
  }
  void wait() {
    std::unique_lock<std::mutex> lock(mu_);
    const unsigned long long gen = generation_;
    if (++waiting_ == n_) {
      waiting_ = 0;
      ++generation_;
      cv_.notify_all();
      return;
    }
    if (!cv_.wait_for(lock, std::chrono::seconds(60), [&] { return generation_ != gen; })) {
      std::fprintf(stderr,
                   "emulated __syncthreads(): %u of %u threads arrived within 60 s — a barrier "
                   "is not reached by every thread of the block\n",
                   waiting_, n_);
      std::abort();
    }
  }

 private:
  std::mutex mu_;
  std::condition_variable cv_;
  unsigned n_ = 0, waiting_ = 0;
  unsigned long long generation_ = 0;
};
EmuBarrier emu_barrier;

void __syncthreads() { emu_barrier.wait(); }
double __dmul_rn(double a, double b) { return a * b; }
double __dadd_rn(double a, double b) { return a + b; }

// Runs body() as one block of `threads` threads.
template <class Body>
void run_block(unsigned threads, const Body& body) {
  blockDim.x = threads;
  emu_barrier.reset(threads);
  std::vector<std::thread> pool;
  pool.reserve(threads);
  for (unsigned t = 0; t < threads; ++t)
    pool.emplace_back([&body, t] {
      threadIdx.x = t;
      body();
    });
  for (auto& th : pool) th.join();
}

}  // namespace

#define __device__ inline
#define __shared__ static
#include "numeric/cuda/ldlt_device.cuh"
#undef __shared__
#undef __device__

namespace strata {
namespace {

using cuda::ldlt_device::kLdltPanel;

// A dense symmetric front (lower triangle, column-major m×m) and the outputs of a kernel.
struct Front {
  index_t m = 0, k = 0;
  std::vector<double> f;
  std::vector<index_t> perm;
  std::vector<int> psize;
  index_t perturbed = 0;
};

Front random_front(index_t m, index_t k, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  Front fr;
  fr.m = m;
  fr.k = k;
  fr.f.assign(static_cast<std::size_t>(m * m), 0.0);
  for (index_t j = 0; j < m; ++j)
    for (index_t i = j; i < m; ++i) fr.f[i + j * m] = u(rng);
  return fr;
}

// Pivot block with zero diagonals paired by large off-diagonals (a KKT-like pattern that
// needs 2×2 pivots), the pairs placed by a random symmetric permutation of 1..k−1, or in
// order (then 2×2 pivots start at the odd columns, one of them at a panel's last column).
Front paired_front(index_t m, index_t k, bool shuffle, std::mt19937_64& rng) {
  Front fr = random_front(m, k, rng);
  std::uniform_real_distribution<double> big(2.0, 3.0);
  std::vector<index_t> p(k);
  for (index_t i = 0; i < k; ++i) p[i] = i;
  if (shuffle) std::shuffle(p.begin() + 1, p.end(), rng);
  auto at = [&](index_t i, index_t j) -> double& {
    if (i < j) std::swap(i, j);
    return fr.f[i + j * m];
  };
  for (index_t j = 0; j < k; ++j)
    for (index_t i = j; i < k; ++i) at(i, j) *= 0.05;  // small background
  at(0, 0) = 5.0;
  for (index_t q = 1; q + 1 < k; q += 2) {
    at(p[q], p[q]) = 0.0;
    at(p[q + 1], p[q + 1]) = 0.0;
    at(p[q], p[q + 1]) = big(rng);
  }
  return fr;
}

// Zeroes whole rows/columns (within the front) `cols`: exactly zero pivots.
void zero_columns(Front& fr, const std::vector<index_t>& cols) {
  for (index_t z : cols)
    for (index_t i = 0; i < fr.m; ++i) fr.f[std::max(i, z) + std::min(i, z) * fr.m] = 0.0;
}

Front cpu_reference(Front fr, double sp) {
  fr.perm.assign(fr.k, -1);
  fr.psize.assign(fr.k, 0);
  numeric::PivotStats st;
  numeric::cpu::factor_front_ldlt(fr.f.data(), fr.m, fr.k, fr.m, sp, fr.perm.data(),
                                  fr.psize.data(), st);
  fr.perturbed = st.perturbed;
  return fr;
}

Front emulate_small(Front fr, double sp, unsigned threads) {
  fr.perm.assign(fr.k, -1);
  fr.psize.assign(fr.k, 0);
  std::int64_t perturbed = -1;
  run_block(threads, [&] {
    cuda::ldlt_device::ldlt_small_front(fr.f.data(), fr.m, fr.k, sp, fr.perm.data(),
                                        fr.psize.data(), &perturbed);
  });
  fr.perturbed = perturbed;
  return fr;
}

// The large-front driver of kernels_ldlt.cu (LdltLarge::factor), with the cublasDsyrkx
// trailing update done by loops.
Front emulate_large(Front fr, double sp, unsigned threads) {
  const index_t m = fr.m, k = fr.k;
  fr.perm.assign(k, -1);
  fr.psize.assign(k, 0);
  std::vector<double> w(static_cast<std::size_t>(m * (kLdltPanel + 1)), 0.0);
  std::int64_t perturbed = -1, end = -1;
  for (index_t j0 = 0; j0 < k;) {
    run_block(threads, [&] {
      cuda::ldlt_device::ldlt_panel(fr.f.data(), m, k, j0, sp, w.data(), fr.perm.data(),
                                    fr.psize.data(), &perturbed, &end);
    });
    EXPECT_GT(end, j0);
    EXPECT_LE(end, std::min(k, j0 + kLdltPanel + 1));
    if (end <= j0) break;
    // F[e:m, e:m] (lower) −= L(e:m, j0:e) W(e:m, 0:e−j0)ᵀ
    for (index_t j = end; j < m; ++j)
      for (index_t c = 0; c < end - j0; ++c) {
        const double wjc = w[j + c * m];
        const double* l = fr.f.data() + (j0 + c) * m;
        for (index_t i = j; i < m; ++i) fr.f[i + j * m] -= l[i] * wjc;
      }
    j0 = end;
  }
  fr.perturbed = k > 0 ? perturbed : 0;
  return fr;
}

// Same pivots exactly, same lower-triangle entries to rounding. Two summation orders of
// an indefinite factorization differ by about eps·m·g·max|ref| where g = max|ref| / max|A|
// is the element growth: a small pivot d makes entries of size 1/d and turns an
// eps-sized difference in d into one of eps/d² (a fixed 1e-11·max|ref| failed on one
// random 256×200 front in CI with g ≈ 2·10⁴, seed 6673280267404609536, difference
// 1.6e-11·max|ref|). An index or pivoting error gives differences of the order of the
// entries, far above this bound for any growth the fronts here reach.
void expect_same(const Front& got, const Front& ref, const Front& input) {
  ASSERT_EQ(got.psize, ref.psize);
  ASSERT_EQ(got.perm, ref.perm);
  EXPECT_EQ(got.perturbed, ref.perturbed);
  double num = 0, den = 0;
  for (index_t j = 0; j < ref.m; ++j)
    for (index_t i = j; i < ref.m; ++i) {
      const double a = got.f[i + j * ref.m], b = ref.f[i + j * ref.m];
      ASSERT_TRUE(std::isfinite(a)) << "(" << i << "," << j << ")";
      num = std::max(num, std::abs(a - b));
      den = std::max(den, std::abs(b));
    }
  double amax = 0;
  for (index_t j = 0; j < input.m; ++j)
    for (index_t i = j; i < input.m; ++i) amax = std::max(amax, std::abs(input.f[i + j * input.m]));
  const double scale = std::max(den, 1.0);
  const double growth = std::max(1.0, scale / std::max(amax, 1e-300));
  const double bound = 16.0 * std::numeric_limits<double>::epsilon() * ref.m * growth * scale;
  EXPECT_LE(num, bound) << "growth " << growth << ", max |entry| " << den;
  EXPECT_LE(num, 1e-6 * scale) << "a difference this large is an error whatever the growth";
}

struct Case {
  std::string name;
  Front f;
  double sp;
};

std::vector<Case> cases(std::mt19937_64& rng, bool large) {
  std::vector<Case> cs;
  const std::vector<std::pair<index_t, index_t>> shapes =
      large ? std::vector<std::pair<index_t, index_t>>{{1, 1},     {5, 3},     {300, 1},
                                                       {300, 2},   {200, 64},  {200, 65},
                                                       {130, 129}, {300, 200}, {520, 300}}
            : std::vector<std::pair<index_t, index_t>>{{1, 1},   {2, 2},    {2, 1},    {3, 3},
                                                       {3, 1},   {5, 5},    {5, 2},    {40, 25},
                                                       {64, 64}, {100, 71}, {256, 200}};
  for (auto [m, k] : shapes)
    cs.push_back(
        {"random " + std::to_string(m) + "x" + std::to_string(k), random_front(m, k, rng), 1e-10});
  const index_t pm = large ? 300 : 120, pk = large ? 200 : 90;
  cs.push_back({"pairs in order", paired_front(pm, pk, false, rng), 1e-10});
  cs.push_back({"pairs shuffled", paired_front(pm, pk, true, rng), 1e-10});
  Front z = random_front(pm, pk, rng);
  zero_columns(z, {0, 3, pk / 2, pk - 1});
  cs.push_back({"zero columns, static pivots", z, 1e-8});
  cs.push_back({"zero columns, no static pivots", z, 0.0});
  return cs;
}

TEST(LdltKernelEmulation, SmallFrontKernelMatchesCpu) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  for (const Case& c : cases(rng, false)) {
    SCOPED_TRACE(c.name);
    const Front ref = cpu_reference(c.f, c.sp);
    expect_same(emulate_small(c.f, c.sp, 32), ref, c.f);
  }
  // the real block size once
  const Front f = random_front(40, 30, rng);
  expect_same(emulate_small(f, 1e-10, 256), cpu_reference(f, 1e-10), f);
}

TEST(LdltKernelEmulation, LargeFrontPanelsMatchCpu) {
  unsigned long long seed = 0;
  auto rng = test::fresh_rng(&seed);
  SCOPED_TRACE("seed " + std::to_string(seed));
  index_t perturbed = 0, twos = 0;
  bool straddle = false;  // a 2×2 pivot on columns 63, 64 (across the first panel's end)
  for (const Case& c : cases(rng, true)) {
    SCOPED_TRACE(c.name);
    const Front ref = cpu_reference(c.f, c.sp);
    expect_same(emulate_large(c.f, c.sp, 32), ref, c.f);
    perturbed += ref.perturbed;
    for (index_t j = 0; j < ref.k; ++j) twos += ref.psize[j] == 2;
    for (index_t j = 0; j < ref.k; j += ref.psize[j])
      straddle |= ref.psize[j] == 2 && j == kLdltPanel - 1;
  }
  EXPECT_GT(perturbed, 0);
  EXPECT_GT(twos, 0);
  EXPECT_TRUE(straddle) << "no 2×2 pivot across a panel end: that path went untested";
  const Front f = random_front(150, 140, rng);
  expect_same(emulate_large(f, 1e-10, 256), cpu_reference(f, 1e-10), f);
}

}  // namespace
}  // namespace strata
