// strata — the level schedule of the assembly tree (see symbolic.hpp).
//
// Source: Jung & Bae, "An improved direct linear equation solver using multi-GPU in
// multi-body dynamics", Adv. Eng. Softw. 2018 — the breadth-first reverse-level
// traversal of the elimination (assembly) tree. The depth of a front is its distance
// from its root; fronts of equal depth never include one another's ancestors, so each
// depth is a set of independent fronts. Levels are numbered so that the deepest depth is
// level 0 (processed first): level = max_depth − depth, and every child is one level
// below its parent. Fronts within a level are listed in increasing front number. One
// pass from the roots down (parents have larger numbers than their children) and a
// counting sort: O(number of fronts).
//
// The same rule applies to a part of the tree (multi-worker factorization): the depth is
// counted from the part's own roots (fronts whose parent lies outside the part), so a
// subtree is scheduled exactly as if it were the whole tree, and the top part's children
// outside it (subtree roots, factored elsewhere) simply do not appear.
#include <string>

#include "strata/errors.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::symbolic {
namespace {

// Schedules the fronts listed in `fronts` (increasing); in_part[f] says whether f is one.
LevelSchedule schedule_of(const AssemblyTree& t, const std::vector<index_t>& fronts,
                          const std::vector<char>* in_part) {
  const index_t nf = t.n_fronts();
  const index_t count = static_cast<index_t>(fronts.size());
  LevelSchedule s;
  std::vector<index_t> depth(nf, 0);
  index_t max_depth = -1;
  for (index_t i = count - 1; i >= 0; --i) {  // parents before children
    const index_t f = fronts[i];
    const index_t p = t.parent[f];
    depth[f] = (p == -1 || (in_part && !(*in_part)[p])) ? 0 : depth[p] + 1;
    if (depth[f] > max_depth) max_depth = depth[f];
  }
  const index_t n_levels = max_depth + 1;  // 0 when there are no fronts
  s.level_of.assign(nf, -1);
  s.level_offsets.assign(n_levels + 1, 0);
  for (const index_t f : fronts) {
    s.level_of[f] = max_depth - depth[f];
    ++s.level_offsets[s.level_of[f] + 1];
  }
  for (index_t l = 0; l < n_levels; ++l) s.level_offsets[l + 1] += s.level_offsets[l];
  s.fronts.resize(count);
  std::vector<index_t> next(s.level_offsets.begin(), s.level_offsets.end() - 1);
  for (const index_t f : fronts) s.fronts[next[s.level_of[f]]++] = f;
  return s;
}

}  // namespace

LevelSchedule level_schedule(const AssemblyTree& t) {
  std::vector<index_t> all(t.n_fronts());
  for (index_t f = 0; f < t.n_fronts(); ++f) all[f] = f;
  return schedule_of(t, all, nullptr);
}

LevelSchedule level_schedule(const AssemblyTree& t, const std::vector<index_t>& fronts) {
  const index_t nf = t.n_fronts();
  std::vector<char> in_part(nf, 0);
  for (std::size_t i = 0; i < fronts.size(); ++i) {
    if (fronts[i] < 0 || fronts[i] >= nf || (i > 0 && fronts[i] <= fronts[i - 1]))
      throw InvalidInput("level_schedule: the part's fronts must be increasing and in 0.." +
                         std::to_string(nf - 1));
    in_part[fronts[i]] = 1;
  }
  return schedule_of(t, fronts, &in_part);
}

}  // namespace strata::symbolic
