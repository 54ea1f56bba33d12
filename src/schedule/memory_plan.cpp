// strata — the memory plan: each level of the schedule cut into batches under a byte
// budget (see memory_plan.hpp).
//
// Source: DESIGN.md §2 and Jung & Bae 2018 (a level of the reverse-level traversal is a
// batch; a level that does not fit the device is cut into consecutive batches). The
// working-set model is the header's: 8 bytes per entry of the dense front, of the
// children's contribution blocks it reads and of the contribution block it writes.
//
// Batching is greedy in level order: fronts of a level are added to the open batch while
// the batch's bytes stay within the budget; a front whose working set alone exceeds the
// budget closes the open batch and forms a batch by itself, marked tiled. A budget of 0
// puts each level in one batch.
//
// Peak in-core memory is simulated over the batches in processing order: the live data
// while a batch runs are the contribution blocks produced earlier and not yet consumed
// (excluding those this batch reads, which its working set already counts) plus the
// batch's working set; afterwards the blocks it read are freed and the blocks it wrote
// become pending. The peak is the maximum of that sum. Factor panels are not counted:
// they stream out (DESIGN.md §2) and are reported as factor_bytes. For a part of the tree
// the contribution blocks it imports from children outside it are pending from the start.
//
// The contribution-block arena layout (plan_cb_layout) is a first-fit allocator run over
// the same schedule: free extents in an ordered map, adjacent free extents merged, the
// tail given back to the top of the arena.
#include "schedule/memory_plan.hpp"

#include <algorithm>
#include <iterator>
#include <map>

namespace strata::schedule {
namespace {

std::size_t square_bytes(index_t k) {
  return static_cast<std::size_t>(k) * static_cast<std::size_t>(k) * sizeof(double);
}

/// Bytes of the contribution blocks front f reads from its children.
std::size_t children_cb_bytes(const symbolic::AssemblyTree& t, index_t f) {
  std::size_t b = 0;
  for (index_t c = t.child_offsets[f]; c < t.child_offsets[f + 1]; ++c)
    b += square_bytes(t.cb_size(t.children[c]));
  return b;
}

}  // namespace

std::size_t front_working_bytes(const symbolic::AssemblyTree& t, index_t f) {
  return square_bytes(t.n_rows(f)) + children_cb_bytes(t, f) + square_bytes(t.cb_size(f));
}

MemoryPlan plan_memory(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s,
                       std::size_t budget, bool unsymmetric) {
  MemoryPlan plan;
  plan.budget = budget;

  for (index_t l = 0; l < s.n_levels(); ++l) {
    BatchInfo open{l, s.level_offsets[l], s.level_offsets[l], 0, false};
    for (index_t pos = s.level_offsets[l]; pos < s.level_offsets[l + 1]; ++pos) {
      const std::size_t w = front_working_bytes(t, s.fronts[pos]);
      if (budget != 0 && w > budget) {  // alone over the budget: a tiled batch of its own
        if (open.end > open.begin) plan.batches.push_back(open);
        plan.batches.push_back(BatchInfo{l, pos, pos + 1, w, true});
        open = BatchInfo{l, pos + 1, pos + 1, 0, false};
        continue;
      }
      if (budget != 0 && open.end > open.begin && open.bytes + w > budget) {
        plan.batches.push_back(open);
        open = BatchInfo{l, pos, pos, 0, false};
      }
      open.bytes += w;
      open.end = pos + 1;
    }
    if (open.end > open.begin) plan.batches.push_back(open);
  }

  // Peak in-core working memory (see the file header).
  std::size_t pending = 0, peak = 0;
  for (const index_t c : imported_children(t, s)) pending += square_bytes(t.cb_size(c));
  for (const BatchInfo& b : plan.batches) {
    std::size_t read = 0, written = 0;
    for (index_t pos = b.begin; pos < b.end; ++pos) {
      const index_t f = s.fronts[pos];
      read += children_cb_bytes(t, f);
      written += square_bytes(t.cb_size(f));
    }
    peak = std::max(peak, pending - read + b.bytes);
    pending = pending - read + written;
  }
  plan.peak_in_core_bytes = peak;

  std::size_t factor = 0;
  for (const index_t f : s.fronts) {
    const auto np = static_cast<std::size_t>(t.n_pivots(f));
    const auto nr = static_cast<std::size_t>(t.n_rows(f));
    factor += np * nr + (unsymmetric ? np * (nr - np) : 0);
  }
  plan.factor_bytes = factor * sizeof(double);
  return plan;
}

std::vector<index_t> imported_children(const symbolic::AssemblyTree& t,
                                       const symbolic::LevelSchedule& s) {
  std::vector<index_t> out;
  if (static_cast<index_t>(s.fronts.size()) == t.n_fronts()) return out;  // whole tree
  for (const index_t f : s.fronts)
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      if (s.level_of[c] < 0 && t.cb_size(c) > 0) out.push_back(c);
    }
  std::sort(out.begin(), out.end());
  return out;
}

CbLayout plan_cb_layout(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s) {
  CbLayout out;
  out.cb_offset.assign(t.n_fronts(), 0);
  std::map<std::size_t, std::size_t> free_list;  // offset -> size
  std::size_t top = 0;
  auto release = [&](std::size_t off, std::size_t size) {
    auto it = free_list.emplace(off, size).first;
    auto next = std::next(it);
    if (next != free_list.end() && it->first + it->second == next->first) {
      it->second += next->second;
      free_list.erase(next);
    }
    if (it != free_list.begin()) {
      auto prev = std::prev(it);
      if (prev->first + prev->second == it->first) {
        prev->second += it->second;
        free_list.erase(it);
        it = prev;
      }
    }
    if (it->first + it->second == top) {  // give the tail back
      top = it->first;
      free_list.erase(it);
    }
  };
  auto allocate = [&](std::size_t size) -> std::size_t {
    for (auto it = free_list.begin(); it != free_list.end(); ++it)
      if (it->second >= size) {
        const std::size_t off = it->first;
        const std::size_t rest = it->second - size;
        free_list.erase(it);
        if (rest) free_list.emplace(off + size, rest);
        return off;
      }
    const std::size_t off = top;
    top += size;
    out.arena_size = std::max(out.arena_size, top);
    return off;
  };
  for (const index_t c : imported_children(t, s)) {
    const auto cb = static_cast<std::size_t>(t.cb_size(c));
    out.cb_offset[c] = allocate(cb * cb);
  }
  for (index_t l = 0; l < s.n_levels(); ++l) {
    for (index_t p = s.level_offsets[l]; p < s.level_offsets[l + 1]; ++p) {
      const index_t f = s.fronts[p];
      const auto cb = static_cast<std::size_t>(t.cb_size(f));
      if (cb > 0 && t.parent[f] >= 0) out.cb_offset[f] = allocate(cb * cb);
    }
    for (index_t p = s.level_offsets[l]; p < s.level_offsets[l + 1]; ++p) {
      const index_t f = s.fronts[p];
      for (index_t k = t.child_offsets[f]; k < t.child_offsets[f + 1]; ++k) {
        const index_t c = t.children[k];
        const auto cb = static_cast<std::size_t>(t.cb_size(c));
        if (cb > 0) release(out.cb_offset[c], cb * cb);
      }
    }
  }
  return out;
}

}  // namespace strata::schedule
