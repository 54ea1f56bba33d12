// strata — the plan of the triangular solves on the device (cuda_solve.cu), host-only
// code with no CUDA in it, so that the CPU tests can run it
// (tests/unit/test_solve_kernel_emulation.cpp).
//
// What: which subtrees at the bottom of the tree are solved one thread block each, their
// fronts one after another (solve_device.cuh: front_forward/backward); then for each level
// of the schedule, which of the other fronts are solved by one thread block each and which
// by cuBLAS calls, a level's on kSolveLanes streams side by side (large_front_forward/
// backward below); the blocks of the library fronts' gather and scatter kernels; and, for every
// front row, the children's update-vector entries that add into it.
//
// Why: the multibody Newton matrices' trees are a few hundred small fronts on 15 to 40
// levels, where a solve by levels is a chain of launches that each do a few microseconds of
// work; a block that solves a whole subtree replaces all of that subtree's launches with
// one, at the price of solving its fronts one after another. A thread block streams a panel
// at a small fraction of the device's bandwidth, so a front's products with L21 and U12
// (most of a tall front's bytes) are spread over its gather and scatter chunks, leaving
// one block its triangle; a level whose work sits in a few large triangles (the top of a
// nested-dissection tree) is still limited by one SM per front there; cuBLAS spreads one
// front over the whole device but costs a few microseconds of launch per call, which a
// level of thousands of small fronts cannot afford. The planner picks the subtrees
// and, per level, the split that minimize a simple time model (see kBlockBytesPerSecond
// etc.): the largest fronts go to the library as long as that shortens the level. The
// chain (plan_chain) then runs the subtrees and the bottom levels of block-path fronts as
// one launch whose blocks wait on the device for the fronts they read, instead of a
// launch per level, and the model prices the subtrees for it.
// Gathering by parent row (the inverse of the children's relative positions) lets every
// thread build its row alone — no ordering between children, no atomics, the same
// summation order as the CPU solve's child-by-child extend-add.
//
// Source: the multifrontal solve of Liu (SIAM Review 34, 1992, §6) on the level schedule
// of the factorization (DESIGN.md §1, §2).
#pragma once

#include <algorithm>
#include <cstdint>
#include <limits>
#include <numeric>
#include <utility>
#include <vector>

#include "symbolic/symbolic.hpp"

namespace strata::cuda {

/// Device view of what the solve reads (int64, tree numbering, 0-based). Pointers are
/// device pointers on the GPU, host pointers in the emulation test.
struct SolveTree {
  const std::int64_t* n_rows;        ///< per front
  const std::int64_t* n_pivots;      ///< per front
  const std::int64_t* row_offsets;   ///< per front: into rows, inv_offsets; scratch at ×nrhs
  const std::int64_t* first_pivot;   ///< per front
  const std::int64_t* rows;          ///< NumericFactor::rows (pivot rows as factored)
  const std::int64_t* inv_offsets;   ///< per front row (+1): its entries of inv_src
  const std::int64_t* inv_src;       ///< u-arena index of each child entry adding into a row
  const std::int64_t* u_offset;      ///< per front: its update vector in the u arena
  const std::int64_t* panel_offset;  ///< per front: its panel in `panels`
  const double* panels;              ///< the factor (NumericFactor::panels layout)
  const std::int64_t* pivot_row;     ///< per pivot position: the unknown it eliminated
  std::int64_t n;                    ///< unknowns
  std::int64_t u_total;              ///< doubles of the u arena per right-hand side
  /// Per front: −1, or (a tall front, SolvePlan::tall_fronts) where its chunks' partial
  /// products start in `part`, in doubles per right-hand side.
  const std::int64_t* part_offset;
  double* part;  ///< SolvePlan::part_total × nrhs doubles (the backward partial products)
};

/// The chain of a solve plan on the device (SolvePlan::chain_*, plan_chain below; device
/// arrays, tree numbering) and its synchronization words, `sync`:
/// 2·n_fronts + 3 zeros before the first launch — per front the children arrived
/// (forward) and the epoch at which its backward step ended, then the ticket, the blocks
/// finished and the epoch; each launch leaves the first of these per front, the ticket and
/// the count at zero and the epoch one higher, so the launches replay from a graph.
struct SolveChain {
  const std::int64_t* first;
  const std::int64_t* last;
  const std::int64_t* wait;
  const std::int64_t* parent;
  unsigned long long* sync;
  std::int64_t n_fronts;
  std::int64_t items;  ///< the chain's items (one block each)
};

/// Rows of one front handled by one block of the gather and scatter kernels.
constexpr std::int64_t kChunkRows = 256;

/// A launch of the block path (solve_kernels.cu: fronts_forward/backward_kernel) of at
/// most this many blocks — two per SM of a 132-SM GPU — runs the variant with 16 loads in
/// flight per thread (few blocks: latency-bound); larger ones the variant with 4 and
/// fewer registers (more blocks per SM).
constexpr std::int64_t kFewFrontBlocks = 264;

/// The chunks of a tall front (m rows, k pivots) that hold rows of L21 (rows k..m−1): the
/// first is chunk k / kChunkRows of the front; their number (0 when m = k: no L21).
/// solve_device.cuh's backward sweep computes the same.
inline std::int64_t product_chunks(std::int64_t m, std::int64_t k) {
  return m > k ? (m + kChunkRows - 1) / kChunkRows - k / kChunkRows : 0;
}

// The time model of the planner (seconds, bytes). Estimates for a Hopper GPU, not
// measured per front; they only need to be right within a factor of a few to pick the
// path.
// One 256-thread block streaming a panel: the device's ~3 TB/s over 132 SMs is ~25 GB/s
// per SM when all are busy.
constexpr double kBlockBytesPerSecond = 20e9;
// Per tile of 32 pivot columns, a block's dependent steps (a warp's triangle, two
// barriers): memory latency, not bandwidth.
constexpr double kBlockTileSeconds = 2e-6;
// Per front on a block: its gather, scatter and the barriers between them (dependent
// loads of index arrays).
constexpr double kBlockFrontSeconds = 2e-6;
// Per kernel launched from the solve's graph: the launch and the drain before the next.
constexpr double kLaunchSeconds = 3e-6;
// In the chain's launch (plan_chain), per item: from a front's end to its parent's start on
// another block (a release, an acquire that sees it, a barrier) and the item's own cost (its
// ticket, its block's start), so that tiny subtrees stay whole rather than one item a front.
constexpr double kChainSeconds = 4e-6;
// cuBLAS over one front: most of the device's bandwidth...
constexpr double kLibraryBytesPerSecond = 2e12;
// ...after two library calls' launch and enqueue cost...
constexpr double kLibraryCallSeconds = 8e-6;
// ...plus the triangular solve's sequential dependence, per pivot column (the tiled solve
// of trsv_tiles.cuh takes about 2 µs per 64 columns on an H200; cuBLAS's DTRSV, which
// several right-hand sides still use, about 2 µs per 32).
constexpr double kLibraryPivotSeconds = 3.5e-8;

/// Streams a level's library-path fronts run on side by side (cuda_solve.cu: the
/// executor's lanes), the j-th largest on stream j mod kSolveLanes.
constexpr int kSolveLanes = 8;

/// Which path the planner may choose (the tests force each one).
/// block_subtrees: every front on the block path, the subtrees of at most a quarter of the
/// largest subtree's block time solved one block each, the rest level by level.
enum class SolvePath { model, all_block, all_library, block_subtrees };

/// The solve plan of one analysis (see the file header). First the subtrees solved one
/// thread block each: subtree q is the fronts subtree_first[q]..subtree_last[q] (a front and
/// its descendants, consecutive in postorder), solved in that order forward and in the
/// reverse order backward. Then per level l (schedule order, deepest first), the fronts
/// in no subtree: block-solved fronts of at most kChunkRows rows small_fronts[small_offsets
/// [l]..] (gathered, swept and scattered by one block), taller block-solved fronts
/// tall_fronts[tall_offsets[l]..] and library-solved fronts large_fronts[large_offsets[l]..]
/// (largest first, run on kSolveLanes streams),
/// and the gather/scatter blocks of the tall and library fronts [chunk_offsets[l],
/// chunk_offsets[l+1]) of chunk_front/chunk_row (front, first row). A tall front's block
/// solves only its triangle; its L21 (and U12) products are spread over its chunks: the
/// forward scatter's blocks subtract L21's rows times the solved pivots, the backward
/// gather's blocks write partial products L21ᵀ W[k:m] (U12 W[k:m]) of their rows, k ×
/// nrhs each at part_offset[f]·nrhs (product_chunks of them), which the sweep sums in
/// chunk order.
struct SolvePlan {
  std::uint64_t analysis = 0;             ///< Analysis::id it was made for
  int n_sm = 0;                           ///< streaming multiprocessors it was made for
  std::vector<std::int64_t> u_offset;     ///< per front + 1: prefix sums of cb sizes
  std::vector<std::int64_t> inv_offsets;  ///< per front row + 1
  std::vector<std::int64_t> inv_src;
  std::vector<std::int64_t> chunk_offsets{0}, chunk_front, chunk_row;
  std::vector<std::int64_t> small_offsets{0}, small_fronts;
  std::vector<std::int64_t> large_offsets{0}, large_fronts;
  std::vector<std::int64_t> tall_offsets{0}, tall_fronts;
  std::vector<std::int64_t> subtree_first, subtree_last;
  std::vector<std::int64_t> part_offset;  ///< per front, −1 but for tall fronts
  std::int64_t part_total = 0;            ///< doubles of the partial products per rhs
  /// The subtree limit the plan was made with: seconds on one block (−1: no subtree).
  double subtree_limit = -1.0;
  /// The chain (plan_chain; none when chain_levels is 0): the subtrees and the fronts of
  /// the levels [0, chain_levels) as one launch per sweep. Item q is the fronts
  /// chain_first[q]..chain_last[q]; per front the children its forward step waits for
  /// (chain_wait) and the parent it signals (chain_parent, −1: none).
  std::int64_t chain_levels = 0;
  std::vector<std::int64_t> chain_first, chain_last, chain_wait, chain_parent;
};

/// The update vectors' offsets and the inverse extend-add map of `p` (SolvePlan::u_offset,
/// inv_offsets, inv_src): for each parent row, the child entries adding into it, in child
/// order (a child contributes at most once to a row).
inline void plan_inverse_extend_add(const symbolic::AssemblyTree& t,
                                    const symbolic::ChildRowMap& child_rows, SolvePlan& p) {
  const index_t nf = t.n_fronts();
  p.u_offset.assign(child_rows.offsets.begin(), child_rows.offsets.end());  // cb sizes' sums
  const std::size_t nrows = t.rows.size();
  std::vector<std::int64_t> count(nrows + 1, 0), target(p.u_offset[nf]);
  for (index_t f = 0; f < nf; ++f)
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      const index_t* rel = child_rows.of(c);
      for (index_t e = 0; e < t.cb_size(c); ++e) {
        const std::int64_t row = t.row_offsets[f] + rel[e];
        target[p.u_offset[c] + e] = row;
        ++count[row + 1];
      }
    }
  p.inv_offsets.assign(nrows + 1, 0);
  std::partial_sum(count.begin(), count.end(), p.inv_offsets.begin());
  p.inv_src.assign(p.inv_offsets[nrows], 0);
  std::vector<std::int64_t> fill(p.inv_offsets.begin(), p.inv_offsets.end() - 1);
  for (index_t f = 0; f < nf; ++f)  // children in order, so each row's list is in child order
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      for (index_t e = 0; e < t.cb_size(c); ++e) {
        const std::int64_t u = p.u_offset[c] + e;
        p.inv_src[fill[target[u]]++] = u;
      }
    }
}

/// The bytes of front f's panel that a sweep reads (m × k doubles).
inline double front_bytes(const symbolic::AssemblyTree& t, index_t f) {
  return 8.0 * static_cast<double>(t.n_rows(f)) * static_cast<double>(t.n_pivots(f));
}

/// The time model of each front of `t` (seconds, the constants above): on the block path
/// from its first block to its last (block_seconds) and its blocks' time summed
/// (block_work; they differ for a tall front, whose products run on its chunks side by
/// side), and on the library path.
struct FrontTimes {
  std::vector<double> block_seconds, block_work, library_seconds;
};

inline FrontTimes front_times(const symbolic::AssemblyTree& t) {
  const index_t nf = t.n_fronts();
  FrontTimes ft;
  ft.block_seconds.resize(nf);
  ft.block_work.resize(nf);
  ft.library_seconds.resize(nf);
  for (index_t f = 0; f < nf; ++f) {
    const double k = static_cast<double>(t.n_pivots(f));
    const double tiles = static_cast<double>((t.n_pivots(f) + 31) / 32) * kBlockTileSeconds;
    ft.block_work[f] = kBlockFrontSeconds + front_bytes(t, f) / kBlockBytesPerSecond + tiles;
    ft.block_seconds[f] = ft.block_work[f];
    if (t.n_rows(f) > kChunkRows) {
      const double product = 8.0 * static_cast<double>(t.n_rows(f) - t.n_pivots(f)) * k;
      const std::int64_t chunks = product_chunks(t.n_rows(f), t.n_pivots(f));
      ft.block_seconds[f] =
          kBlockFrontSeconds + 8.0 * k * k / kBlockBytesPerSecond + tiles +
          (chunks > 0 ? product / kBlockBytesPerSecond / static_cast<double>(chunks) : 0.0);
    }
    ft.library_seconds[f] =
        kLibraryCallSeconds + front_bytes(t, f) / kLibraryBytesPerSecond + k * kLibraryPivotSeconds;
  }
  return ft;
}

/// The sweeps' part of a plan (everything but u_offset, inv_offsets and inv_src, which
/// plan_inverse_extend_add makes) for tree `t` and its level schedule `s` on a device of
/// `n_sm` multiprocessors (≥ 1), into `p`. `path` forces the paths (tests); `model` picks
/// by the time model above: the subtree limit (none, or 1 µs, 2 µs, … on one block) of
/// least modelled sweep time, then each level's split between block and library. `in`:
/// when given (one entry per front), only the fronts with in[f] != 0 are planned — a part
/// of a multi-GPU split, solved where its panels live; a front outside heads no subtree
/// and lies in none. `fixed_limit`: when given, the subtree limit (SolvePlan::
/// subtree_limit) instead of the model's choice — a part takes the whole tree's, so that
/// its bottom is cut into the subtrees the whole-tree solve would use. `chain`: the model
/// prices the plan as plan_chain will run it (the subtrees and the bottom levels of block
/// fronts as one launch). Deterministic.
inline void plan_sweeps(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s, int n_sm,
                        SolvePath path, const std::vector<char>* in, SolvePlan& p,
                        const double* fixed_limit = nullptr, bool chain = false) {
  const index_t nf = t.n_fronts();
  p.n_sm = std::max(n_sm, 1);
  auto planned = [&](index_t f) { return !in || (*in)[f] != 0; };
  const FrontTimes times = front_times(t);
  auto t_block = [&](index_t f) { return times.block_seconds[f]; };
  auto t_library = [&](index_t f) { return times.library_seconds[f]; };
  // Each level's fronts, largest first; the time of each subtree on one block (its fronts
  // one after another).
  std::vector<std::vector<index_t>> by_size(s.n_levels());
  for (index_t l = 0; l < s.n_levels(); ++l) {
    auto& order = by_size[l];
    for (index_t q = s.level_offsets[l]; q < s.level_offsets[l + 1]; ++q)
      if (planned(s.fronts[q])) order.push_back(s.fronts[q]);
    std::stable_sort(order.begin(), order.end(),
                     [&](index_t a, index_t b) { return front_bytes(t, a) > front_bytes(t, b); });
  }
  std::vector<double> serial(nf, 0.0);
  std::vector<index_t> first(nf);  // the first front of f's subtree in postorder
  std::iota(first.begin(), first.end(), index_t{0});
  // a front of more than kChunkRows rows is gathered and scattered by several blocks, so it
  // is in no subtree (nor is any front above it); nor is a front outside the planned set
  for (index_t f = 0; f < nf; ++f) {  // children come before their parent
    serial[f] += t.n_rows(f) > kChunkRows || !planned(f) ? std::numeric_limits<double>::infinity()
                                                         : t_block(f);
    if (t.parent[f] >= 0) {
      serial[t.parent[f]] += serial[f];
      first[t.parent[f]] = std::min(first[t.parent[f]], first[f]);
    }
  }
  // A level's fronts outside the subtrees: the q largest on the library, the rest in one
  // launch (its longest block, or its total spread over the SMs); the q of least time.
  // tail[q]: the block work of rest[q..]; longest[q]: their longest block time.
  std::vector<index_t> rest;
  std::vector<double> tail, longest;
  auto split = [&](double* level_time) -> std::size_t {
    const std::size_t nl = rest.size();
    tail.assign(nl + 1, 0.0);
    longest.assign(nl + 1, 0.0);
    for (std::size_t q = nl; q-- > 0;) {
      tail[q] = tail[q + 1] + times.block_work[rest[q]];
      longest[q] = std::max(longest[q + 1], t_block(rest[q]));
    }
    std::size_t best = 0;
    double best_time = 0.0;
    if (path == SolvePath::all_library) {
      best = nl;
      for (index_t f : rest) best_time += t_library(f);
    } else if (path != SolvePath::model) {
      best_time = nl ? std::max(longest[0], tail[0] / p.n_sm) : 0.0;
    } else {
      double lib = 0.0;
      for (std::size_t q = 0; q <= nl; ++q) {
        const double blocks =
            q < nl ? kLaunchSeconds + std::max(longest[q], tail[q] / p.n_sm) : 0.0;
        const double time = lib + (q > 0 ? 2 * kLaunchSeconds : 0.0) + blocks;
        if (q == 0 || time < best_time) {
          best_time = time;
          best = q;
        }
        // the fronts on the library run kSolveLanes side by side, the largest first: the
        // level waits for the first lane's, and for every other front's launches
        if (q < nl) lib += q % kSolveLanes == 0 ? t_library(rest[q]) : kLaunchSeconds;
      }
    }
    if (level_time) *level_time = best_time;
    return best;
  };
  // The subtrees of at most `limit` seconds on a block (closed under descendants: a
  // subtree's time is at least its children's), and the modelled time of the whole sweep.
  auto in_subtree = [&](index_t f, double limit) { return planned(f) && serial[f] <= limit; };
  auto sweep_time = [&](double limit) {
    double most = 0.0, sum = 0.0, total = 0.0;
    bool any = false;
    for (index_t f = 0; f < nf; ++f)
      if (in_subtree(f, limit) && (t.parent[f] < 0 || !in_subtree(t.parent[f], limit))) {
        most = std::max(most, serial[f]);
        sum += serial[f];
        any = true;
      }
    if (any) total += kLaunchSeconds + std::max(most, sum / p.n_sm);
    for (index_t l = 0; l < s.n_levels(); ++l) {
      rest.clear();
      for (index_t f : by_size[l])
        if (!in_subtree(f, limit)) rest.push_back(f);
      double level_time = 0.0;
      if (!rest.empty()) split(&level_time);
      total += level_time;
    }
    return total;
  };
  // With the chain (plan_chain, chain true): the subtrees and the bottom levels of block
  // fronts in one launch, each front starting kChainSeconds after its children end, so
  // that part costs its longest path (or its work over the SMs), not a launch per level.
  std::vector<double> finish(chain ? static_cast<std::size_t>(nf) : 0);
  auto chain_time = [&](double limit) {
    double total = kLaunchSeconds, work = 0.0, path_end = 0.0;
    for (index_t f = 0; f < nf; ++f)
      if (in_subtree(f, limit) && (t.parent[f] < 0 || !in_subtree(t.parent[f], limit))) {
        finish[f] = serial[f];
        work += serial[f];
        path_end = std::max(path_end, serial[f]);
      }
    bool chained = true;
    for (index_t l = 0; l < s.n_levels(); ++l) {
      rest.clear();
      for (index_t f : by_size[l])
        if (!in_subtree(f, limit)) rest.push_back(f);
      double level_time = 0.0;
      if (chained)
        for (index_t f : rest) chained = chained && t.n_rows(f) <= kChunkRows;
      if (chained && !rest.empty()) chained = split(&level_time) == 0;
      if (!chained) {
        if (!rest.empty()) split(&level_time);
        total += level_time;
        continue;
      }
      for (index_t f : rest) {
        double start = 0.0;
        for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q)
          start = std::max(start, finish[t.children[q]] + kChainSeconds);
        finish[f] = start + t_block(f);
        work += times.block_work[f];
        path_end = std::max(path_end, finish[f]);
      }
    }
    return total + std::max(path_end, work / p.n_sm);
  };
  auto model_time = [&](double limit) { return chain ? chain_time(limit) : sweep_time(limit); };
  double limit = fixed_limit ? *fixed_limit : -1.0;  // -1: no subtree
  if (!fixed_limit && path == SolvePath::block_subtrees) {
    for (index_t f = 0; f < nf; ++f)
      if (serial[f] < std::numeric_limits<double>::infinity())
        limit = std::max(limit, serial[f] / 4);
  } else if (!fixed_limit && path == SolvePath::model) {
    double largest = 0.0;  // the largest finite subtree time: no larger limit changes the cut
    for (index_t f = 0; f < nf; ++f)
      if (serial[f] < std::numeric_limits<double>::infinity())
        largest = std::max(largest, serial[f]);
    double best = model_time(limit);
    for (double cand = 1e-6; cand < 1e-1 && cand < 2 * largest; cand *= 2) {
      const double time = model_time(cand);
      if (time < best) {
        best = time;
        limit = cand;
      }
    }
  }
  p.subtree_limit = limit;
  for (index_t f = 0; f < nf; ++f)
    if (in_subtree(f, limit) && (t.parent[f] < 0 || !in_subtree(t.parent[f], limit))) {
      p.subtree_first.push_back(first[f]);
      p.subtree_last.push_back(f);
    }
  // per level: the fronts outside the subtrees, split between block and library; the
  // tall and library fronts' gather/scatter chunks; the tall fronts' partial products
  p.part_offset.assign(nf, -1);
  for (index_t l = 0; l < s.n_levels(); ++l) {
    rest.clear();
    for (index_t f : by_size[l])
      if (!in_subtree(f, limit)) rest.push_back(f);
    const std::size_t best = split(nullptr);
    std::vector<index_t> large(rest.begin(), rest.begin() + best), small, tall;
    for (auto it = rest.begin() + best; it != rest.end(); ++it)
      (t.n_rows(*it) > kChunkRows ? tall : small).push_back(*it);
    std::sort(small.begin(), small.end());  // large: largest first (the lanes' order)
    std::sort(tall.begin(), tall.end());
    for (const auto* fronts : {&tall, &large})
      for (const index_t f : *fronts)
        for (index_t i0 = 0; i0 < t.n_rows(f); i0 += kChunkRows) {
          p.chunk_front.push_back(f);
          p.chunk_row.push_back(i0);
        }
    p.chunk_offsets.push_back(static_cast<std::int64_t>(p.chunk_front.size()));
    p.large_fronts.insert(p.large_fronts.end(), large.begin(), large.end());
    p.small_fronts.insert(p.small_fronts.end(), small.begin(), small.end());
    p.tall_fronts.insert(p.tall_fronts.end(), tall.begin(), tall.end());
    for (const index_t f : tall) {
      p.part_offset[f] = p.part_total;
      p.part_total += product_chunks(t.n_rows(f), t.n_pivots(f)) * t.n_pivots(f);
    }
    p.large_offsets.push_back(static_cast<std::int64_t>(p.large_fronts.size()));
    p.small_offsets.push_back(static_cast<std::int64_t>(p.small_fronts.size()));
    p.tall_offsets.push_back(static_cast<std::int64_t>(p.tall_fronts.size()));
  }
}

/// The chain of plan `p` (made by plan_sweeps for the whole tree `t` with schedule `s`):
/// the bottom levels whose fronts outside the subtrees are all block-path fronts of at
/// most kChunkRows rows (no tall or library front, no gather or scatter chunk), the
/// deepest chain_levels of them, solved together with the subtrees in one launch per sweep
/// (solve_kernels.cuh: launch_chain_forward/backward) instead of one launch for the
/// subtrees and one per level: the launch's blocks take the items in order from a ticket
/// and wait on the device, forward for their children's items, backward for their
/// parent's, so a front starts when what it reads is written rather than when its whole
/// level is. Items: the subtrees (SolvePlan::subtree_first/last) in their order, then
/// level by level from the deepest each level front alone, so every item comes after the
/// items it waits for forward (and before them in the reverse order the backward sweep
/// takes). chain_wait[f]: a level front's children (every one of them is the last front of
/// an earlier item), 0 for other fronts; chain_parent[f]: for an item's last front whose
/// parent is a level front of the chain, that parent, else −1. No chain (chain_levels 0)
/// when the deepest level has a tall or library front. Deterministic.
inline void plan_chain(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s,
                       SolvePlan& p) {
  const index_t nf = t.n_fronts();
  p.chain_levels = 0;
  p.chain_first.clear();
  p.chain_last.clear();
  p.chain_wait.clear();
  p.chain_parent.clear();
  std::int64_t levels = 0;
  auto none = [](const std::vector<std::int64_t>& offsets, std::int64_t l) {
    return offsets[l + 1] == offsets[l];
  };
  while (levels < s.n_levels() && none(p.tall_offsets, levels) && none(p.large_offsets, levels) &&
         none(p.chunk_offsets, levels))
    ++levels;
  if (levels == 0) return;
  p.chain_levels = levels;
  p.chain_first = p.subtree_first;
  p.chain_last = p.subtree_last;
  p.chain_wait.assign(static_cast<std::size_t>(nf), 0);
  p.chain_parent.assign(static_cast<std::size_t>(nf), -1);
  std::vector<char> level_front(static_cast<std::size_t>(nf), 0);
  for (std::int64_t q = p.small_offsets[0]; q < p.small_offsets[levels]; ++q) {
    const std::int64_t f = p.small_fronts[q];
    p.chain_first.push_back(f);
    p.chain_last.push_back(f);
    level_front[f] = 1;
  }
  for (const std::int64_t r : p.chain_last) {
    const index_t parent = t.parent[r];
    if (parent >= 0 && level_front[parent]) {
      p.chain_parent[r] = parent;
      ++p.chain_wait[parent];
    }
  }
}

/// The plan of the whole tree `t` (with its extend-add map `child_rows`, e.g.
/// Analysis::child_rows) and its level schedule `s` on a device of `n_sm` multiprocessors:
/// plan_inverse_extend_add, then plan_sweeps over every front.
inline SolvePlan make_solve_plan(const symbolic::AssemblyTree& t,
                                 const symbolic::ChildRowMap& child_rows,
                                 const symbolic::LevelSchedule& s, int n_sm,
                                 SolvePath path = SolvePath::model, bool chain = false) {
  SolvePlan p;
  plan_inverse_extend_add(t, child_rows, p);
  plan_sweeps(t, s, n_sm, path, nullptr, p, nullptr, chain);
  if (chain) plan_chain(t, s, p);
  return p;
}

/// Ranges [begin, end) of x's rows or of the update-vector arena.
using SolveRanges = std::vector<std::pair<std::int64_t, std::int64_t>>;

/// What the solve of one part of a multi-GPU split (part_solve.cu) exchanges with the
/// other parts, for its fronts `fronts` (increasing) of tree `t` whose update vectors sit
/// at `u_offset` (per front + 1, SolvePlan::u_offset): own_rows, the pivot rows of its
/// fronts (x rows it reads and writes in both sweeps); above_rows, the pivot rows of the
/// fronts above it in other parts, which its backward sweep reads; imports, the update
/// vectors of its fronts' children in other parts, which its forward sweep reads; exports,
/// the update vectors of its fronts whose parent is in another part, which its forward
/// sweep writes. Each list increasing, adjacent ranges merged.
struct PartExchange {
  SolveRanges own_rows, above_rows, imports, exports;
};

inline PartExchange part_exchange(const symbolic::AssemblyTree& t,
                                  const std::vector<index_t>& fronts,
                                  const std::vector<std::int64_t>& u_offset) {
  const index_t nf = t.n_fronts();
  std::vector<char> in(static_cast<std::size_t>(nf), 0), above(static_cast<std::size_t>(nf), 0);
  for (const index_t f : fronts) in[f] = 1;
  auto add = [](SolveRanges& r, std::int64_t b, std::int64_t e) {
    if (b == e) return;
    if (!r.empty() && r.back().second == b)
      r.back().second = e;
    else
      r.emplace_back(b, e);
  };
  PartExchange x;
  std::vector<index_t> children;
  for (const index_t f : fronts) {
    add(x.own_rows, t.first_pivot[f], t.first_pivot[f] + t.n_pivots(f));
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q)
      if (!in[t.children[q]]) children.push_back(t.children[q]);
    if (t.parent[f] < 0 || in[t.parent[f]]) continue;
    add(x.exports, u_offset[f], u_offset[f + 1]);
    for (index_t a = t.parent[f]; a >= 0 && !above[a]; a = t.parent[a]) above[a] = 1;
  }
  std::sort(children.begin(), children.end());
  for (const index_t c : children) add(x.imports, u_offset[c], u_offset[c + 1]);
  for (index_t f = 0; f < nf; ++f)
    if (above[f] && !in[f]) add(x.above_rows, t.first_pivot[f], t.first_pivot[f] + t.n_pivots(f));
  return x;
}

// --- one large front through a BLAS ----------------------------------------------------
//
// `Ops` is cuBLAS on the device (cuda_solve.cu) or the host BLAS in the emulation test:
//   trsv(upper, trans, unit, n, A, lda, x)                 x ← op(A)⁻¹ x
//   trsm(upper, trans, unit, n, nrhs, A, lda, B, ldb)      B ← op(A)⁻¹ B   (left side)
//   gemv(trans, rows, cols, alpha, A, lda, x, beta, y)     y ← α op(A) x + β y, A rows×cols
//   gemm(trans_a, m, n, k, alpha, A, lda, B, ldb, beta, C, ldc)   C ← α op(A) B + β C
// W is the front's gathered block, m×nrhs with leading dimension m; L its panel (m×k,
// leading dimension m; LU: U11 in its upper triangle and U12 after it, k×(m−k) with
// leading dimension k — NumericFactor::panels).

/// Forward: W[0:k] ← L11⁻¹ W[0:k] (unit: LDLᵀ, LU), W[k:m] −= L21 W[0:k].
template <class Ops>
void large_front_forward(Ops& ops, const double* L, int m, int k, int nrhs, bool unit, double* W) {
  if (k == 0) return;
  const int rest = m - k;
  if (nrhs == 1) {
    ops.trsv(false, false, unit, k, L, m, W);
    if (rest > 0) ops.gemv(false, rest, k, -1.0, L + k, m, W, 1.0, W + k);
  } else {
    ops.trsm(false, false, unit, k, nrhs, L, m, W, m);
    if (rest > 0) ops.gemm(false, rest, nrhs, k, -1.0, L + k, m, W, m, 1.0, W + k, m);
  }
}

/// Backward: LLᵀ/LDLᵀ W[0:k] ← L11⁻ᵀ (W[0:k] − L21ᵀ W[k:m]); LU W[0:k] ← U11⁻¹ (W[0:k] −
/// U12 W[k:m]).
template <class Ops>
void large_front_backward(Ops& ops, const double* L, int m, int k, int nrhs, bool lu, bool unit,
                          double* W) {
  if (k == 0) return;
  const int rest = m - k;
  const double* U12 = L + static_cast<std::size_t>(m) * static_cast<std::size_t>(k);
  if (rest > 0) {
    if (lu) {
      if (nrhs == 1)
        ops.gemv(false, k, rest, -1.0, U12, k, W + k, 1.0, W);
      else
        ops.gemm(false, k, nrhs, rest, -1.0, U12, k, W + k, m, 1.0, W, m);
    } else {
      if (nrhs == 1)
        ops.gemv(true, rest, k, -1.0, L + k, m, W + k, 1.0, W);
      else
        ops.gemm(true, k, nrhs, rest, -1.0, L + k, m, W + k, m, 1.0, W, m);
    }
  }
  // LU: U11 upper, never unit; otherwise L11ᵀ
  if (nrhs == 1)
    ops.trsv(lu, !lu, lu ? false : unit, k, L, m, W);
  else
    ops.trsm(lu, !lu, lu ? false : unit, k, nrhs, L, m, W, m);
}

}  // namespace strata::cuda
